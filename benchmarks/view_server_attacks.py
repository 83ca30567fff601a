"""The viewer's server under the attacks of issue 25: what each costs the server, in one table.

Usage::

    python benchmarks/view_server_attacks.py [--tree CHECKOUT] [--cap S] [--json out.json]

Starts ``python -m bokehfit view`` afresh for each attack (the bokehfit of
``--tree``, a source checkout, or else the one ``python -m bokehfit`` imports)
and measures, on 127.0.0.1 only:

- a cross-site write: the status of a ``text/plain`` POST with a foreign Origin and no token;
- a slow head: seconds until a client sending a header line every second is cut off;
- a normal GET's wait beside 64 slow clients and 220 half-open connections, and beside 500 idle ones;
- 500 concurrent GETs: how many are answered, in how long;
- one 128 KiB body of ``\\"`` escapes: seconds to its answer, and a concurrent GET's wait;
- 16 concurrent 8 MiB hostile bodies: the server's peak memory (VmHWM);
- the most server CPU any single 8 MiB hostile body costs, per MiB.

Every wait is capped at ``--cap`` seconds (default 30): a row that reads the cap
did not finish. Linux only (reads /proc). The script asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import threading
import time
from contextlib import ExitStack, contextmanager
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_view_server import compare_json, exchange, parse_answer, request  # noqa: E402
from test_view_server_hostile import HOSTILE_BODIES, collect, connect, cpu_s, open_files, peak_rss_mb, send  # noqa: E402


#: The environment of the servers started (PYTHONPATH names --tree).
SERVER_ENV = dict(os.environ)


@contextmanager
def view():
    """A fresh `bokehfit view`: (process, port)."""
    process = subprocess.Popen([sys.executable, "-m", "bokehfit", "view", "--no-browser", "--port", "0", "--size", "64x48"],
                               stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=SERVER_ENV)
    try:
        port = int(re.search(r"127\.0\.0\.1:(\d+)/", process.stdout.readline()).group(1))
        exchange(port, request(port))  # warm
        yield process, port
    finally:
        process.kill()
        process.communicate()


def timed_get(port: int, cap: float) -> float:
    start = time.monotonic()
    try:
        exchange(port, request(port, "GET", "/style.css"), timeout=cap)
    except OSError:
        return cap
    return min(time.monotonic() - start, cap)


def cross_site(cap: float) -> dict:
    with view() as (_, port):
        attack = request(port, "POST", "/matched", body=compare_json(), page=False,
                         headers=[("Origin", "http://evil.example"), ("Content-Type", "text/plain")])
        return {"cross-site POST status": exchange(port, attack, timeout=cap).status}


def slow_head(cap: float) -> dict:
    with view() as (_, port), ExitStack() as stack:
        sock = connect(port, 1, stack)[0]
        sock.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n".encode())
        sock.settimeout(1.0)
        start = time.monotonic()
        while time.monotonic() - start < cap:
            try:
                sock.recv(1024)
                break  # answered or closed
            except TimeoutError:
                try:
                    sock.sendall(b"X-Slow: 1\r\n")
                except OSError:
                    break
            except OSError:
                break
        return {"slow head cut off after (s)": round(min(time.monotonic() - start, cap), 2)}


def crowd(cap: float) -> dict:
    out = {}
    with open_files(4096), view() as (_, port), ExitStack() as stack:
        half_open = connect(port, 220, stack, cap)
        for sock in half_open[::2]:
            sock.sendall(b"GET / HTT")
        slow = connect(port, 64, stack, cap)
        for sock in slow:
            sock.sendall(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n".encode())
        time.sleep(1.0)
        out["GET wait beside 64 slow + 220 half-open (s)"] = round(timed_get(port, cap), 3)
    with open_files(4096), view() as (_, port), ExitStack() as stack:
        try:
            connect(port, 500, stack, cap)
            time.sleep(0.5)
            out["GET wait beside 500 idle (s)"] = round(timed_get(port, cap), 3)
        except AssertionError:
            out["GET wait beside 500 idle (s)"] = cap
    with open_files(4096), view() as (_, port), ExitStack() as stack:
        start = time.monotonic()
        try:
            socks = connect(port, 500, stack, cap)
        except AssertionError:
            socks = []
        for sock in socks:
            sock.sendall(request(port, "GET", "/favicon.ico"))
        data, _ = collect(socks, cap)
        answered = sum(1 for sock in socks if data[sock] and parse_answer(bytes(data[sock])).status == 204)
        out["500 concurrent GETs answered"] = answered
        out["500 concurrent GETs took (s)"] = round(time.monotonic() - start, 2)
    return out


def escaped_quotes(cap: float) -> dict:
    body = b'"' + b'\\"' * (64 * 1024)
    with view() as (_, port):
        result = {}

        def post():
            start = time.monotonic()
            try:
                exchange(port, request(port, "POST", "/matched", body=body), timeout=cap)
            except OSError:
                pass
            result["128 KiB of escaped quotes answered in (s)"] = round(min(time.monotonic() - start, cap), 3)

        poster = threading.Thread(target=post)
        poster.start()
        time.sleep(0.1)
        result["GET wait beside it (s)"] = round(timed_get(port, cap), 3)
        poster.join()
        return result


def maximal_bodies(cap: float) -> dict:
    out = {}
    with view() as (process, port), ExitStack() as stack:
        maximal = [kind for kind, (_, body, _) in HOSTILE_BODIES.items() if len(body) > (8 << 20) - 1024]
        plan = [HOSTILE_BODIES[maximal[i % len(maximal)]] for i in range(16)]
        base = peak_rss_mb(process.pid)
        socks = connect(port, 16, stack, cap)
        senders = [threading.Thread(target=send, args=(sock, request(port, "POST", path, body=body)), daemon=True)
                   for sock, (path, body, _) in zip(socks, plan)]
        start = time.monotonic()
        for sender in senders:
            sender.start()
        data, _ = collect(socks, cap)
        out["16 x 8 MiB bodies: server at rest (MB)"] = round(base)
        out["16 x 8 MiB bodies: server peak (MB)"] = round(peak_rss_mb(process.pid))
        out["16 x 8 MiB bodies: answered"] = sum(1 for sock in socks if data[sock])
        out["16 x 8 MiB bodies took (s)"] = round(time.monotonic() - start, 2)
    worst, worst_kind = 0.0, ""
    for kind, (path, body, _) in HOSTILE_BODIES.items():
        with view() as (process, port):
            before = cpu_s(process.pid)
            try:
                exchange(port, request(port, "POST", path, body=body), timeout=cap)
                spent = cpu_s(process.pid) - before
            except OSError:
                spent = cap
            per_mib = spent / (len(body) / 2**20)
            if per_mib > worst:
                worst, worst_kind = per_mib, kind
    out["most server CPU per MiB of one body (s)"] = round(worst, 4)
    out["... for the body"] = worst_kind
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tree", type=Path, help="source checkout whose server to measure (default: the importable bokehfit)")
    parser.add_argument("--cap", type=float, default=30.0, help="longest wait per measurement (s, default 30)")
    parser.add_argument("--json", metavar="OUT.json", help="also write the figures as JSON")
    args = parser.parse_args()
    if args.tree is not None:
        SERVER_ENV["PYTHONPATH"] = str(args.tree.resolve())
    where = subprocess.run([sys.executable, "-c", "import bokehfit; print(bokehfit.__file__)"], env=SERVER_ENV,
                           capture_output=True, text=True, check=True).stdout.strip()
    print(f"server: bokehfit from {Path(where).parent.parent}, Python {platform.python_version()}, {os.cpu_count()} CPUs")
    figures = {}
    for measure in (cross_site, slow_head, crowd, escaped_quotes, maximal_bodies):
        figures.update(measure(args.cap))
    width = max(map(len, figures))
    for name, value in figures.items():
        print(f"{name:<{width}}  {value}")
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=1) + "\n")


if __name__ == "__main__":
    main()
