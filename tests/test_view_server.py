"""The viewer's server answers every request: bad Host headers, methods, bodies and JSON, many at once.

Requests are written by hand on raw sockets (loopback only), so that what a
browser or urllib would never send (two Host headers, no Host, odd methods,
lying Content-Lengths) reaches the server. Every exchange has a timeout; each
test asserts a status line, a one-line JSON error and no traceback.
"""

from __future__ import annotations

import io
import json
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import pytest
from PIL import Image

from bokehfit.apertures import SHAPES, MaskTable, make_aperture
from bokehfit.apertures.mask import MAX_MASK_SIDE
from bokehfit.errors import InputError
from bokehfit.view import ViewerServer
from bokehfit.view.masks import MaskStore

#: Longest wait for one answer (s).
ANSWER_TIMEOUT_S = 15.0
#: Concurrent connections of the load test, and its time budget (s).
CONNECTIONS = 200
LOAD_BUDGET_S = 20.0
#: A refusal's message is one short line.
MAX_MESSAGE_CHARS = 300


@dataclass(frozen=True)
class Answer:
    status: int
    headers: dict[str, str]
    body: bytes

    def error(self) -> str:
        return json.loads(self.body)["error"]


def parse_answer(data: bytes) -> Answer:
    head, _, body = data.partition(b"\r\n\r\n")
    lines = head.decode("iso-8859-1").split("\r\n")
    match = re.fullmatch(r"HTTP/1\.[01] (\d{3}) .*", lines[0])
    assert match, f"no status line in {data[:200]!r}"
    headers = {}
    for line in lines[1:]:
        name, _, value = line.partition(":")
        headers[name.strip().lower()] = value.strip()
    return Answer(int(match.group(1)), headers, body)


def exchange(port: int, request: bytes, *, end_request: bool = False, timeout: float = ANSWER_TIMEOUT_S) -> Answer:
    """Send ``request`` on a fresh loopback connection and read the answer to the end."""
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as sock:
        sock.sendall(request)
        if end_request:
            sock.shutdown(socket.SHUT_WR)
        data = b""
        while chunk := sock.recv(1 << 16):
            data += chunk
    return parse_answer(data)


#: Content type of each write route.
WRITE_TYPES = {"/matched": "application/json", "/mask": "image/png"}


def page_token(port: int) -> str:
    """The write token that the server's page carries (as the browser gets it); empty where it has none."""
    page = exchange(port, request(port, "GET", "/")).body.decode()
    match = re.search(r'<meta name="bokehfit-token" content="([^"]+)">', page)
    return match.group(1) if match else ""


def request(port: int, method: str = "GET", path: str = "/config.json", *, hosts=None, headers=(), body: bytes | None = None, page=None) -> bytes:
    """An HTTP/1.1 request's bytes: ``hosts`` None means the server's own; Content-Length set for a body.

    A POST is sent as the viewer's page sends it (its Origin, token and content
    type) unless ``headers`` names them or ``page`` is False.
    """
    lines = [f"{method} {path} HTTP/1.1"]
    lines += [f"Host: {host}" for host in ([f"127.0.0.1:{port}"] if hosts is None else hosts)]
    named = {name.lower() for name, _ in headers}
    if method == "POST" and page is not False and path in WRITE_TYPES:
        own = {"origin": f"http://127.0.0.1:{port}", "x-bokehfit-token": page_token(port), "content-type": WRITE_TYPES[path]}
        headers = [*headers, *((name, value) for name, value in own.items() if name not in named)]
    lines += [f"{name}: {value}" for name, value in headers]
    if body is not None and not any(name.lower() == "content-length" for name, _ in headers):
        lines.append(f"Content-Length: {len(body)}")
    return ("\r\n".join(lines) + "\r\n\r\n").encode("iso-8859-1") + (body or b"")


def assert_refused(answer: Answer, status: int, needle: str) -> str:
    assert answer.status == status, (answer.status, answer.body[:300])
    assert answer.headers["content-type"].startswith("application/json")
    message = answer.error()
    assert needle in message and "\n" not in message and len(message) <= MAX_MESSAGE_CHARS, message
    return message


@pytest.fixture(scope="module")
def server():
    with ViewerServer(0, size=(64, 48)).start() as running:
        yield running


@pytest.fixture(autouse=True)
def no_traceback(capfd):
    """Whatever a test sends, the server writes no traceback."""
    yield
    assert "Traceback" not in capfd.readouterr().err


def compare_json(**aperture) -> bytes:
    base = {"shape": "hexagon", "blades": 6, "angle_deg": 15.0, "fstop": 2.0, "focus_side": "far"}
    return json.dumps({"schema_version": 1, "aperture": {**base, **aperture}}).encode()


# --- Host -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "hosts,status",
    [
        (["OWN", "evil.example:PORT"], 400),  # its own first, a foreign one second
        (["evil.example:PORT", "OWN"], 400),
        (["OWN", "OWN"], 400),
        ([], 400),
        (["evil.example:PORT"], 421),
        (["127.0.0.1"], 421),  # no port
        (["127.0.0.1:PORT.evil.example"], 421),
        (["localhost:PORT"], 200),
        (["LOCALHOST:PORT"], 200),
    ],
)
def test_exactly_one_host_header_naming_the_server(server, hosts, status):
    named = [h.replace("OWN", f"127.0.0.1:{server.port}").replace("PORT", str(server.port)) for h in hosts]
    answer = exchange(server.port, request(server.port, hosts=named))
    if status == 200:
        assert answer.status == 200 and json.loads(answer.body)["defaults"]["width"] == 64
    else:
        assert_refused(answer, status, "Host")


def test_foreign_host_is_refused_before_the_route_runs(server):
    # A body that would fail the route: the Host is refused first, the body never parsed.
    answer = exchange(server.port, request(server.port, "POST", "/matched", hosts=["evil.example"], body=b"[" * 5000))
    assert_refused(answer, 421, "Host")


# --- methods --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "method,path,allow",
    [
        ("PUT", "/config.json", "GET, HEAD"),
        ("DELETE", "/", "GET, HEAD"),
        ("POST", "/params.json", "GET, HEAD"),
        ("GET", "/matched", "POST"),
        ("HEAD", "/matched", "POST"),
        ("BREW", "/", "GET, HEAD"),
        ("OPTIONS", "/nowhere", "GET, HEAD, POST"),
        ("TRACE", "/nowhere", "GET, HEAD, POST"),
    ],
)
def test_methods_not_served_answer_405_with_allow(server, method, path, allow):
    answer = exchange(server.port, request(server.port, method, path))
    assert answer.status == 405 and answer.headers["allow"] == allow
    if method != "HEAD":
        assert method in answer.error()


def test_head_answers_headers_only(server):
    answer = exchange(server.port, request(server.port, "HEAD", "/"))
    assert answer.status == 200 and int(answer.headers["content-length"]) > 0 and answer.body == b""


def test_unknown_path_and_absolute_target(server):
    assert_refused(exchange(server.port, request(server.port, "GET", "/secret")), 404, "/secret")
    answer = exchange(server.port, request(server.port, "GET", "http://evil.example/config.json"))
    assert_refused(answer, 400, "path")


# --- sizes and bodies -----------------------------------------------------------------------


@pytest.mark.parametrize(
    "raw,status",
    [
        (b"GARBAGE\r\n\r\n", 400),
        (b"\r\n\r\n", 400),
        (b"GET /\r\n\r\n", 400),  # HTTP/0.9: still answered with a status line
        (b"GET / HTTP/2.0\r\n\r\n", 505),
        (b"GET / HTTP/1.1 extra\r\n\r\n", 400),
        (b"GET / HTTP/1.1", 400),  # no line break before the client stopped sending
    ],
)
def test_unreadable_request_lines_get_a_status_line(server, raw, status):
    answer = exchange(server.port, raw, end_request=True)
    assert answer.status == status and "error" in json.loads(answer.body)


def test_request_line_and_headers_are_capped(server):
    answer = exchange(server.port, request(server.port, "GET", "/params.json?shape=" + "a" * 10_000))
    assert_refused(answer, 414, "request line")
    answer = exchange(server.port, request(server.port, headers=[(f"X-Pad-{i}", "b" * 1000) for i in range(60)]))
    assert_refused(answer, 431, "headers")


@pytest.mark.parametrize(
    "headers,body,status,needle",
    [
        ([], None, 411, "Content-Length"),
        ([("Content-Length", str(10**9))], None, 413, "MiB"),
        ([("Content-Length", "99999999999999999999999")], None, 413, "MiB"),
        ([("Content-Length", "abc")], b"{}", 400, "Content-Length"),
        ([("Content-Length", "-5")], b"{}", 400, "Content-Length"),
        ([("Content-Length", "2"), ("Content-Length", "2")], b"{}", 400, "Content-Length"),
        ([("Content-Length", "0")], b"", 400, "empty"),
        ([("Transfer-Encoding", "chunked")], b"2\r\n{}\r\n0\r\n\r\n", 411, "Content-Length"),
    ],
)
def test_post_needs_one_bounded_content_length(server, headers, body, status, needle):
    answer = exchange(server.port, request(server.port, "POST", "/matched", headers=headers, body=body))
    assert_refused(answer, status, needle)


def test_body_shorter_than_its_length(server):
    raw = request(server.port, "POST", "/matched", headers=[("Content-Length", "100")], body=b'{"aperture"')
    assert_refused(exchange(server.port, raw, end_request=True), 400, "ended after 11 of 100 bytes")


def test_a_silent_client_is_answered_408():
    with ViewerServer(0, size=(64, 48), request_timeout_s=0.5).start() as quick:
        start = time.monotonic()
        answer = exchange(quick.port, b"GET /config.json HTTP/1.1\r\nHost: ")
        assert_refused(answer, 408, "0.5 s")
        assert time.monotonic() - start < 5.0
        body = request(quick.port, "POST", "/matched", headers=[("Content-Length", "50")], body=b"{")
        assert_refused(exchange(quick.port, body), 408, "did not arrive")
        # A connection that never asks anything (a browser's preconnect) is closed, not answered.
        with socket.create_connection(("127.0.0.1", quick.port), timeout=ANSWER_TIMEOUT_S) as idle:
            assert idle.recv(1024) == b""
        assert exchange(quick.port, request(quick.port)).status == 200


DEEP = 100_000


@pytest.mark.parametrize(
    "body,needle",
    [
        (compare_json(shape=["hexagon"]), "aperture.shape"),
        (compare_json(shape={"name": "hexagon"}), "aperture.shape"),
        (compare_json(shape=None), "fitted no aperture"),
        (b"[" * DEEP + b"]" * DEEP, "nests 100000 deep"),
        (b'{"aperture": {"shape": ' + b"[" * DEEP + b"]" * DEEP + b"}}", "nests 100002 deep"),
        (b'{"aperture": ' + b"{" * DEEP, "nests"),
        (b'{"aperture": {"shape": "circle", "angle_deg": 1' + b"0" * DEEP + b"}}", "an integer of 100001 digits"),
        (b'{"aperture": {"shape": "circle", "angle_deg": -1' + b"0" * 4400 + b"}}", "digits"),
        (b'{"aperture": {"shape": "ngon", "blades": 7' + b"0" * 40 + b"}}", "digits"),
        (b'{"aperture": {"shape": "circle", "fstop": 1e999}}', "float range"),
        (b'{"aperture": {"shape": "circle", "fstop": NaN}}', "NaN"),
        (b'{"aperture": {"shape": "circle", "fstop": -Infinity}}', "Infinity"),
        (compare_json(fstop=True), "aperture.fstop"),
        (compare_json(fstop="2.8"), "aperture.fstop"),
        (compare_json(angle_deg=[1, 2]), "aperture.angle_deg"),
        (compare_json(shape="ngon", blades=[7]), "aperture.blades"),
        (compare_json(shape="ngon", blades=7.0), "aperture.blades"),
        (compare_json(shape="ngon", blades=2**70), "aperture.blades"),
        (compare_json(shape="slit", blades=None, aspect={"x": 1}), "aperture.aspect"),
        (compare_json(fstop=None, fstop_reason=["no EXIF"]), "aperture.fstop_reason"),
        (compare_json(focus_side=1), "aperture.focus_side"),
        (json.dumps({"schema_version": [1], "aperture": {"shape": "circle"}}).encode(), "schema_version"),
        (b"[1, 2, 3]", "aperture"),
        (b'"aperture"', "aperture"),
        (b"\xff\xfe{}", "UTF-8"),
        (b"{not json", "not JSON"),
        (b'{"aperture": {"shape": "circle"}} trailing', "not JSON"),
    ],
    ids=lambda value: value[:40].decode("latin-1") if isinstance(value, bytes) else str(value),
)
def test_odd_json_bodies_answer_400_naming_the_problem(server, body, needle):
    answer = exchange(server.port, request(server.port, "POST", "/matched", headers=[("Content-Type", "application/json")], body=body))
    assert_refused(answer, 400, needle)


def test_brackets_inside_strings_are_not_nesting(server):
    body = compare_json(shape="circle", blades=None, fstop=None, fstop_reason="[{" * 1000 + '"\\"[[[')
    answer = exchange(server.port, request(server.port, "POST", "/matched", body=body))
    assert answer.status == 200, answer.body[:300]
    assert json.loads(answer.body)["shape"] == "circle"


def test_json_depth_counts_outside_strings_only():
    from bokehfit.view.bodies import json_depth

    assert json_depth(b"1") == 0
    assert json_depth(b'{"a": [1, {"b": "[[[\\"]]"}], "c": {}}') == 3
    assert json_depth(b"[" * 50 + b"]" * 50) == 50


def test_an_unexpected_failure_answers_500_in_one_line(server, monkeypatch, capfd):
    def broken(*args):
        raise RuntimeError("simulated fault")

    monkeypatch.setattr("bokehfit.view.handler.viewer_config", broken)
    assert_refused(exchange(server.port, request(server.port)), 500, "internal error")
    monkeypatch.undo()
    assert exchange(server.port, request(server.port)).status == 200
    err = capfd.readouterr().err
    lines = [line for line in err.splitlines() if "internal error" in line]
    assert len(lines) == 1 and "simulated fault" in lines[0] and "Traceback" not in err


# --- many at once, through `bokehfit view` ---------------------------------------------------


def test_200_concurrent_connections_are_all_answered(tmp_path):
    """Good, foreign-Host, bad-method and odd-JSON requests at once: each answered, the server still serves."""
    process = subprocess.Popen(
        [sys.executable, "-m", "bokehfit", "view", "--no-browser", "--port", "0", "--size", "64x48"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        line = process.stdout.readline()
        match = re.search(r"http://127\.0\.0\.1:(\d+)/", line)
        assert match, f"no URL in {line!r}"
        port = int(match.group(1))
        kinds = {
            "good": (request(port), 200),
            "foreign host": (request(port, hosts=["rebound.example:80"]), 421),
            "two hosts": (request(port, hosts=[f"127.0.0.1:{port}", "rebound.example"]), 400),
            "bad method": (request(port, "DELETE", "/config.json"), 405),
            "deep JSON": (request(port, "POST", "/matched", body=b"[" * 20_000 + b"]" * 20_000), 400),
            "list shape": (request(port, "POST", "/matched", body=compare_json(shape=["circle"])), 400),
            "huge integer": (request(port, "POST", "/matched", body=b'{"aperture": {"shape": "circle", "fstop": 9' + b"9" * 5000 + b"}}"), 400),
            "matched": (request(port, "POST", "/matched", body=compare_json()), 200),
        }
        plan = [list(kinds)[i % len(kinds)] for i in range(CONNECTIONS)]
        everyone_connected = threading.Barrier(CONNECTIONS)

        def one(kind: str) -> tuple[str, int | str]:
            try:
                with socket.create_connection(("127.0.0.1", port), timeout=ANSWER_TIMEOUT_S) as sock:
                    everyone_connected.wait(timeout=ANSWER_TIMEOUT_S)
                    sock.sendall(kinds[kind][0])
                    data = b""
                    while chunk := sock.recv(1 << 16):
                        data += chunk
                return kind, parse_answer(data).status
            except (OSError, AssertionError, threading.BrokenBarrierError) as error:
                return kind, f"{type(error).__name__}: {error}"

        start = time.monotonic()
        with ThreadPoolExecutor(CONNECTIONS) as pool:
            results = list(pool.map(one, plan))
        elapsed = time.monotonic() - start
        wrong = [(kind, status) for kind, status in results if status != kinds[kind][1]]
        assert not wrong, f"{len(wrong)} of {CONNECTIONS} answered wrongly, e.g. {wrong[:5]}"
        assert elapsed < LOAD_BUDGET_S, f"{CONNECTIONS} requests took {elapsed:.1f} s"
        after = exchange(port, request(port))
        assert after.status == 200 and json.loads(after.body)["defaults"]["width"] == 64
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 0, err
    assert "Traceback" not in err and "internal error" not in err, err[-2000:]
    print(f"{CONNECTIONS} concurrent connections answered in {elapsed:.2f} s")


# --- the custom mask: POST /mask, GET /mask_table, /params.json?shape=mask ---------------------


def png_bytes(transmission: np.ndarray) -> bytes:
    """An 8-bit greyscale PNG of ``transmission`` in [0, 1]."""
    out = io.BytesIO()
    Image.fromarray(np.round(transmission * 255).astype(np.uint8), "L").save(out, "PNG")
    return out.getvalue()


def test_mask_entry_is_served(server):
    config = json.loads(exchange(server.port, request(server.port)).body)
    entries = {entry["name"]: entry for entry in config["shapes"]}
    assert list(entries) == list(SHAPES)
    assert entries["mask"]["tabulated"] and entries["mask"]["has_angle"]
    assert not any(entry["tabulated"] for name, entry in entries.items() if name != "mask")
    assert config["defaults"]["mask"] is None and config["mask_upload"]["url"] == "/mask"
    assert config["shader"]["bindings"]["mask_table"] == {"group": 0, "binding": 2, "space": "storage"}


def test_uploaded_mask_gives_its_table_and_the_lens_values(server):
    """The upload is read by the command line's code: the same table, digest, tables and uniform values as ``--mask``."""
    transmission = np.round(np.outer(np.hanning(11)[1:-1], np.hanning(7)[1:-1]) * 255) / 255
    transmission[0, 0] = 1.0
    answer = exchange(server.port, request(server.port, "POST", "/mask", headers=[("Content-Type", "image/png")], body=png_bytes(transmission)))
    assert answer.status == 200, answer.body[:300]
    upload = json.loads(answer.body)
    table = MaskTable.from_array(transmission)
    assert (upload["mask"], upload["width"], upload["height"], upload["table_floats"]) == (table.digest, 5, 9, table.gpu_table().size)

    answer = exchange(server.port, request(server.port, "GET", upload["table_url"]))
    assert answer.status == 200 and answer.headers["content-type"] == "application/octet-stream"
    np.testing.assert_array_equal(np.frombuffer(answer.body, dtype="<f4"), table.gpu_table())

    answer = exchange(server.port, request(server.port, "GET", f"/params.json?shape=mask&mask={table.digest}&angle=25&width=64&height=48"))
    assert answer.status == 200, answer.body[:300]
    params = json.loads(answer.body)
    expected = make_aperture("mask", 25.0, mask=table).shader_params()
    for name in ("shape", "mask_width", "mask_height", "mask_cell", "cos_angle"):
        assert params["values"][name] == pytest.approx(float(np.float32(expected[name]))), name
    assert params["lens"]["mask"] == {"width": 5, "height": 9, "sha256": table.digest}
    assert params["describe"].startswith(f"mask 5×9 {table.digest[:8]} 25°")


@pytest.mark.parametrize(
    "path,body,needle",
    [
        ("/mask", b"not a png at all", "mask must be a readable image file (PNG)"),
        ("/mask", png_bytes(np.zeros((4, 4))), "mask must transmit some light"),
        ("/mask", png_bytes(np.ones((3, MAX_MASK_SIDE + 1))), f"at most {MAX_MASK_SIDE}"),
        ("/params.json?shape=mask", None, "upload a PNG"),
        ("/params.json?shape=mask&mask=0123abcd", None, "upload the PNG again"),
        ("/mask_table?mask=" + "f" * 64, None, "upload the PNG again"),
        ("/mask_table", None, "mask must name an uploaded mask"),
    ],
    ids=["garbage", "black", "too-wide", "no-mask", "unknown-mask", "unknown-table", "no-table"],
)
def test_bad_mask_uploads_and_names_answer_400(server, path, body, needle):
    method = "POST" if body is not None else "GET"
    assert_refused(exchange(server.port, request(server.port, method, path, body=body)), 400, needle)


def test_empty_mask_body_names_what_to_send(server):
    answer = exchange(server.port, request(server.port, "POST", "/mask", headers=[("Content-Length", "0")], body=b""))
    assert_refused(answer, 400, "send an image file (PNG)")


def test_mask_store_keeps_the_most_recently_used():
    store = MaskStore(capacity=2)
    tables = [MaskTable.from_array(np.full((2, 2), v)) for v in (0.25, 0.5, 0.75)]
    store.add(tables[0])
    store.add(tables[1])
    assert store.get(tables[0].digest) == tables[0]  # now the most recent: tables[1] goes first
    store.add(tables[2])
    assert store.get(tables[0].digest) == tables[0] and store.get(tables[2].digest) == tables[2]
    with pytest.raises(InputError, match="upload the PNG again"):
        store.get(tables[1].digest)
