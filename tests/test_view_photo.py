"""``bokehfit view PHOTO``: the photo's routes, their checks, and the page steering a refit in Chromium.

The server holds one photo (``examples/hexagon_85mm_f2.jpg``, a sure hexagon at
15°); its refits run in a worker process and must give what ``bokehfit compare
--discs`` gives on the same discs. The browser test drives Debian's chromium
through Playwright as ``test_view.py`` does (its fixtures), and keeps a
screenshot of the page (``viewer_photo.png``) among that module's artifacts.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from bokehfit.compare import compare_photo
from bokehfit.discs.labels import DiscLabels
from bokehfit.view import ViewerServer
from bokehfit.view.photo import MAX_REFIT_DISCS
from test_view import STATIC, page_modules
from test_view import artifacts, browser  # noqa: F401 (fixtures)
from test_view import get as get_typed

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "hexagon_85mm_f2.jpg"
#: Longest wait for one compare in the tests (s): about 2 s alone, more on two busy cores.
COMPARE_TIMEOUT_S = 180
PAGE_TIMEOUT_MS = COMPARE_TIMEOUT_S * 1000


@pytest.fixture(scope="module")
def server():
    with ViewerServer(0, photo=EXAMPLE).start() as running:
        assert running.photo.wait(running.photo.auto_job, COMPARE_TIMEOUT_S)["state"] == "done"
        yield running


def request(server, method, path, body=None, headers=None, host=None):
    headers = dict(headers or {})
    if host is not None:
        headers["Host"] = host
    data = None if body is None else (body if isinstance(body, bytes) else json.dumps(body).encode())
    request = urllib.request.Request(server.url.rstrip("/") + path, data=data, method=method, headers=headers)
    try:
        with urllib.request.urlopen(request, timeout=60) as response:
            return response.status, response.read()
    except urllib.error.HTTPError as error:
        with error:
            return error.code, error.read()


def page_headers(server) -> dict:
    """The headers of a write from the page: its Origin, the token of its HTML, JSON."""
    status, page = request(server, "GET", "/photo")
    assert status == 200
    token = re.search(rb'<meta name="bokehfit-token" content="([^"]+)">', page).group(1).decode()
    return {"Content-Type": "application/json", "Origin": server.url.rstrip("/"), "X-Bokehfit-Token": token}


def post(server, path, body, **changes):
    headers = {**page_headers(server), **changes}
    status, data = request(server, "POST", path, body, {k: v for k, v in headers.items() if v is not None})
    return status, json.loads(data)


def result(server, job) -> dict:
    status, data = request(server, "GET", f"/photo/result.json?job={job}")
    assert status == 200, data
    return json.loads(data)


def places(document, which="used"):
    return [{"center_xy": d["center_xy"], "diameter_px": d["diameter_px"]} for d in document["discs"] if d[which]]


def refit(server, body) -> dict:
    status, answer = post(server, "/photo/refit", body)
    assert status == 202, answer
    state = server.photo.wait(answer["job"], COMPARE_TIMEOUT_S)
    assert state["state"] == "done", state
    return result(server, answer["job"])


# --- the server ------------------------------------------------------------------------------


def test_automatic_result_is_the_compare_json(server):
    document = result(server, server.photo.auto_job)
    assert document["status"] == "fitted" and document["aperture"]["shape"] == "hexagon"
    alone = compare_photo(EXAMPLE).to_json("x")
    assert document["verdict"] == alone["verdict"]
    assert [d["center_xy"] for d in document["discs"]] == [d["center_xy"] for d in alone["discs"]]
    status, info = request(server, "GET", "/photo/info.json")
    info = json.loads(info)
    assert (info["width"], info["height"], info["file"]) == (1600, 1067, EXAMPLE.name)
    status, image = request(server, "GET", "/photo/image.jpg")
    assert status == 200 and image[:2] == b"\xff\xd8"
    status, html = request(server, "GET", f"/photo/report.html?job={server.photo.auto_job}")
    assert status == 200 and document["verdict"].encode() in html.replace(b"&#x27;", b"'")


def test_refit_fits_exactly_the_given_discs_as_compare_discs(server, tmp_path):
    automatic = result(server, server.photo.auto_job)
    chosen = places(automatic)[:5]
    document = refit(server, {"discs": chosen})
    assert sum(d["used"] for d in document["discs"]) == 5 == len(document["discs"])
    status, file = post(server, "/photo/discs-file", {"discs": chosen})
    assert status == 200 and file["sha256"] == server.photo.sha256 and (file["width"], file["height"]) == (1600, 1067)
    DiscLabels.from_json(file)
    path = tmp_path / "picks.discs.json"
    path.write_text(json.dumps(file))
    alone = compare_photo(EXAMPLE, discs=path).to_json("x")
    for key in ("status", "verdict"):
        assert document[key] == alone[key]
    assert document["aperture"]["angle_deg"] == alone["aperture"]["angle_deg"]
    assert document["aperture"]["diameter_px"] == alone["aperture"]["diameter_px"]


@pytest.mark.parametrize(
    ("body", "needle"),
    [
        ({"discs": []}, "at least one disc"),
        ({"discs": [{"center_xy": [5000, 10], "diameter_px": 20}]}, "outside"),
        ({"discs": [{"center_xy": [10, 10], "diameter_px": 0}]}, "diameter_px"),
        ({"discs": [{"center_xy": [10, 10], "diameter_px": "20"}]}, "finite number"),
        ({"discs": [{"center_xy": [10], "diameter_px": 20}]}, "center_xy"),
        ({"discs": [{"center_xy": [10, 10], "diameter_px": 20}] * (MAX_REFIT_DISCS + 1)}, f"at most {MAX_REFIT_DISCS}"),
        ({"discs": [{"center_xy": [10, 10], "diameter_px": 20}], "shapes": ["dodecahedron"]}, "dodecahedron"),
        ({"discs": [{"center_xy": [10, 10], "diameter_px": 20}], "path": "/etc/passwd"}, "discs and shapes only"),
        ([1, 2], "JSON object"),
    ],
)
def test_refit_refuses_bad_discs(server, body, needle):
    status, answer = post(server, "/photo/refit", body)
    assert status == 400 and needle in answer["error"], answer


def test_refit_takes_no_nan_and_no_deep_json(server):
    status, answer = post(server, "/photo/refit", b'{"discs": [{"center_xy": [NaN, 1], "diameter_px": 20}]}')
    assert status == 400
    status, answer = post(server, "/photo/refit", b'{"discs": ' + b"[" * 100 + b"]" * 100 + b"}")
    assert status == 400 and "nest" in answer["error"]


def test_photo_writes_pass_the_servers_checks(server):
    body = {"discs": [{"center_xy": [100, 100], "diameter_px": 20}]}
    for path in ("/photo/refit", "/photo/discs-file", "/photo/cancel"):
        assert post(server, path, body, Origin="http://evil.example")[0] == 403
        assert post(server, path, body, **{"X-Bokehfit-Token": "wrong"})[0] == 403
        assert post(server, path, body, **{"Content-Type": "text/plain"})[0] == 415
        assert request(server, "GET", path)[0] == 405
    assert request(server, "GET", "/photo/info.json", host="attacker.example:80")[0] == 421
    status, _ = request(server, "POST", "/photo/refit", b"x" * 10, {**page_headers(server), "Content-Length": str(2**30)})
    assert status == 413


def test_refit_can_be_cancelled_and_then_runs_again(server):
    automatic = result(server, server.photo.auto_job)
    status, answer = post(server, "/photo/refit", {"discs": places(automatic, "usable")})
    assert status == 202
    assert post(server, "/photo/refit", {"discs": places(automatic)[:3]})[0] == 400  # one at a time
    status, cancelled = post(server, "/photo/cancel", {})
    assert status == 200 and cancelled["cancelled"] == answer["job"]
    assert server.photo.status(answer["job"])["state"] == "cancelled"
    assert sum(d["used"] for d in refit(server, {"discs": places(automatic)[:4]})["discs"]) == 4


def test_refit_is_stopped_at_its_time_bound(tmp_path):
    from bokehfit.view.photo import PhotoSession

    session = PhotoSession(EXAMPLE, max_refit_s=0.05)
    try:
        state = session.wait(session.auto_job, COMPARE_TIMEOUT_S)
        assert state["state"] == "failed" and "longer than" in state["error"]
    finally:
        session.close()


def test_the_pages_modules_are_served(server):
    """photo.js and the ES modules it imports are all served, and every photo module of ``static/`` is one of them."""
    modules = page_modules(lambda path: get_typed(server, path), "photo.js")
    assert {"photo.js", "photo_kernel.js", "common.js"} <= set(modules)
    assert {path.name for path in STATIC.glob("photo*.js")} <= set(modules)


def test_without_a_photo_the_photo_routes_answer_404():
    with ViewerServer(0).start() as plain:
        assert request(plain, "GET", "/photo")[0] == 404
        assert request(plain, "GET", "/photo/info.json")[0] == 404
        assert request(plain, "GET", "/")[0] == 200


@pytest.mark.parametrize("content", [b"", b"not an image at all", None])
def test_cli_refuses_a_bad_photo_in_one_line(tmp_path, content):
    path = tmp_path / "bad.jpg"
    if content is not None:
        path.write_bytes(content)
    done = subprocess.run([sys.executable, "-m", "bokehfit", "view", "--no-browser", str(path)],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 2, done
    assert len(done.stderr.strip().splitlines()) == 1 and "Traceback" not in done.stderr and done.stdout == ""


def test_refit_on_a_persons_labels_is_compare_discs(reference_photo):
    """A reference photo: refitting on the person's usable discs answers as ``compare --discs`` with the labels."""
    from photo_factory import reference_labels

    name = "01_water-glints_canon6d_ef85.jpg"
    photo = reference_photo(name)
    labels_path, labels = reference_labels(name)
    with ViewerServer(0, photo=photo).start() as running:
        running.photo.wait(running.photo.auto_job, COMPARE_TIMEOUT_S)
        body = {"discs": [{"center_xy": list(d.center_xy), "diameter_px": d.diameter_px} for d in labels.usable][:MAX_REFIT_DISCS]}
        document = refit(running, body)
    alone = compare_photo(photo, discs=labels_path).to_json("x")
    assert (document["status"], document["aperture"]["shape"]) == (alone["status"], alone["aperture"]["shape"])


# --- the page in headless Chromium -------------------------------------------------------------


def open_photo_page(browser, server):  # noqa: F811
    page = browser.new_page()
    errors = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    page.goto(server.photo_url)
    page.wait_for_function("document.body.dataset.ready === 'true'", timeout=PAGE_TIMEOUT_MS)
    page.errors = errors
    return page


def click_photo(page, x, y, **options):
    cx, cy = page.evaluate("([x, y]) => window.photoView.clientXY(x, y)", [x, y])
    page.mouse.click(cx, cy, **options)


def wait_job(page, previous: str) -> str:
    page.wait_for_function(f"document.body.dataset.job !== '{previous}' && document.body.dataset.state === 'idle'",
                           timeout=PAGE_TIMEOUT_MS)
    return page.evaluate("document.body.dataset.job")


def saved_discs(page, tmp_path) -> Path:
    with page.expect_download() as download:
        page.click("#save-discs")
    path = tmp_path / download.value.suggested_filename
    download.value.save_as(path)
    return path


def test_page_steers_the_fit_like_compare_discs(browser, server, artifacts, tmp_path):  # noqa: F811
    page = open_photo_page(browser, server)
    automatic = result(server, server.photo.auto_job)
    assert page.text_content("#verdict") == automatic["verdict"]
    rows = page.locator("#candidates tbody tr")
    assert rows.count() == len(automatic["discs"])
    assert page.evaluate("document.body.dataset.used") == str(sum(d["used"] for d in automatic["discs"]))
    assert "hexagon" in page.text_content("#aperture-text") and page.locator("#aperture-svg svg").count() == 1

    # Drop a used disc by clicking it; add the one cut by the frame (rejected, not picked) by Shift+drag round it.
    dropped = next(d for d in automatic["discs"] if d["used"])
    click_photo(page, *dropped["center_xy"])
    assert page.evaluate("window.photoView.state.picks.length") == sum(d["usable"] for d in automatic["discs"]) - 1
    missed = next(d for d in automatic["discs"] if not d["usable"])
    (x, y), r = missed["center_xy"], missed["diameter_px"] / 2
    start = page.evaluate("([x, y]) => window.photoView.clientXY(x, y)", [x, y])
    end = page.evaluate("([x, y]) => window.photoView.clientXY(x, y)", [x - r, y])
    page.keyboard.down("Shift")
    page.mouse.move(*start)
    page.mouse.down()
    page.mouse.move(*end, steps=5)
    page.mouse.up()
    page.keyboard.up("Shift")
    picks = page.evaluate("window.photoView.state.picks")
    assert len(picks) == sum(d["usable"] for d in automatic["discs"])
    assert abs(picks[-1]["center_xy"][0] - x) < 3 and abs(picks[-1]["diameter_px"] - 2 * r) < 3

    # Shapes to try: all but the hexagon; the verdict changes as the engine's answer does.
    page.click("#shapes summary")
    page.uncheck("#shapes input[value='hexagon']")
    page.click("#refit")
    job = wait_job(page, str(server.photo.auto_job))
    document = result(server, int(job))
    assert page.text_content("#verdict") == document["verdict"] != automatic["verdict"]
    assert document["aperture"]["shape"] != "hexagon"
    assert page.evaluate("document.body.dataset.used") == str(sum(d["used"] for d in document["discs"]))
    page.click("#shapes summary")  # folds the list again
    page.click("#candidates tbody tr[data-role='used']")
    page.wait_for_function("['ready', 'fallback'].includes(document.body.dataset.kernel)", timeout=PAGE_TIMEOUT_MS)
    assert page.locator("#match canvas, #match img").count() == 3
    page.evaluate("document.getElementById('side').scrollTop = 0")
    save_screenshot(page, artifacts)

    # The saved discs file gives the same answer through the command line.
    path = saved_discs(page, tmp_path)
    shapes = [s for s in server.photo.info()["shapes"] if s != "hexagon"]
    out = tmp_path / "out.json"
    done = subprocess.run([sys.executable, "-m", "bokehfit", "compare", str(EXAMPLE), "--discs", str(path),
                           "--shapes", ",".join(shapes), "--json", str(out), "--no-html"],
                          capture_output=True, text=True, timeout=COMPARE_TIMEOUT_S, check=False)
    assert done.returncode in (0, 1), done.stderr
    cli = json.loads(out.read_text())
    assert (cli["status"], cli["verdict"], cli["aperture"]["angle_deg"]) == (document["status"], document["verdict"], document["aperture"]["angle_deg"])
    assert [d["center_xy"] for d in cli["discs"]] == [d["center_xy"] for d in document["discs"]]

    # Undo goes back to the automatic fit; the report saved is the fit shown.
    page.click("#undo")
    assert page.text_content("#verdict") == automatic["verdict"]
    assert page.get_attribute("#save-json", "href") == f"/photo/result.json?job={server.photo.auto_job}"
    page.click("#reset")
    assert page.text_content("#verdict") == automatic["verdict"]
    assert page.errors == []
    page.close()


def save_screenshot(page, artifacts: Path) -> None:
    path = artifacts / "viewer_photo.png"
    page.screenshot(path=str(path))
    print(f"screenshot: {path}")


# --- the matched kernel, drawn in the browser by the WGSL kernel renderer ---------------------------


def test_kernel_renderer_is_served_as_the_package_compiles_it(server):
    from bokehfit.gpu.shaders import APERTURE_PARAMS
    from bokehfit.kernels.mc import KERNEL_PARAMS, kernel_mc_source

    status, source = request(server, "GET", "/photo/kernel_mc.wgsl")
    assert status == 200 and source.decode() == kernel_mc_source()
    kernel = json.loads(request(server, "GET", "/photo/info.json")[1])["kernel"]
    assert kernel["params"] == KERNEL_PARAMS.layout_json() and kernel["aperture"] == APERTURE_PARAMS.layout_json()
    assert set(kernel["bindings"]) == {"params", "counts", "aperture", "mask_table"}


def _half_mask(image):
    """Pixels at or above half the disc's plateau (its 90th percentile of lit pixels)."""
    import numpy as np

    lit = image[image > 0]
    return image >= 0.5 * np.percentile(lit, 90)


def _centroid(mask):
    import numpy as np

    rows, cols = np.nonzero(mask)
    return np.array([cols.mean(), rows.mean()])


def test_page_draws_the_matched_kernel_with_the_wgsl_renderer(browser, server, artifacts):  # noqa: F811
    """The selected disc's kernel from kernel_mc.wgsl in Chromium (WebGPU) is the fitted aperture's, as
    ``render_kernel`` draws it from the compare JSON; the model and residual follow the Python ones."""
    import base64
    import io

    import cv2
    import numpy as np
    from PIL import Image

    from bokehfit.apertures import make_aperture
    from bokehfit.fit.crop import field_position
    from bokehfit.fit.disc_model import model_window
    from bokehfit.kernels import render_kernel
    from bokehfit.view import settings_from_compare
    from test_view import _need

    page = open_photo_page(browser, server)
    job = server.photo.auto_job
    document = result(server, job)
    tiles = json.loads(request(server, "GET", f"/photo/tiles.json?job={job}")[1])["tiles"]
    disc = max((d for d in document["discs"] if str(d["index"]) in tiles), key=lambda d: d["diameter_px"])
    page.click(f"#candidates tbody tr[data-index='{disc['index']}']")
    page.wait_for_function("['ready', 'fallback'].includes(document.body.dataset.kernel)", timeout=PAGE_TIMEOUT_MS)
    if page.evaluate("document.body.dataset.kernel") == "fallback":
        note = page.text_content("#match-note")
        assert page.locator("#match img").count() == 3 and "drawn in Python" in note
        page.close()
        _need(f"headless chromium has no usable WebGPU here: {note}")
    drawn = page.evaluate("window.photoView.kernel")
    tile = tiles[str(disc["index"])]["kernel"]
    size = tile["size"]
    assert drawn["index"] == disc["index"] and drawn["size"] == size
    kernel = np.asarray(drawn["kernel"], dtype=np.float64).reshape(size, size)

    # The compare JSON's aperture, at the disc's diameter and place in the frame, drawn exactly in Python.
    settings = settings_from_compare(document)
    aperture = make_aperture(settings["shape"], settings["angle_deg"], blades=settings["blades"], aspect=settings["aspect"],
                             roundness=settings["roundness"], squeeze=settings["squeeze"], rim=settings["rim"],
                             vignetting=settings["vignetting"], chromatic=settings["chromatic"])
    width, height = document["input"]["width"], document["input"]["height"]
    where = field_position(disc["center_xy"], (height, width))
    reference = render_kernel(aperture, diameter_px=tile["diameter_px"], size=size, method="exact", field_position=where)
    if reference.ndim == 3:
        reference = reference[..., 1]
    assert abs(kernel.sum() - 1) < 1e-4
    ours, theirs = _half_mask(kernel), _half_mask(reference)
    iou = (ours & theirs).sum() / (ours | theirs).sum()
    offset = np.hypot(*(_centroid(ours) - _centroid(theirs)))
    print(f"disc {disc['index']}: {size} px, D {tile['diameter_px']:.2f} px, IoU of the half masks {iou:.4f}, "
          f"centroids {offset:.3f} px apart; {drawn['samples']} samples in {drawn['ms']:.0f} ms")
    assert iou >= 0.95 and offset <= 1.0
    assert np.abs(kernel - reference).sum() < 0.1  # L1 of two unit-area kernels

    # The page's model (at the fitted centre, blur and levels) against the model drawn in Python: same disc.
    model = np.asarray(drawn["model"], dtype=np.float64).reshape(size, size)
    low, high = tile["background"], tile["plateau"]
    ours = cv2.resize((model >= 0.5 * (low + high)).astype(np.uint8), (96, 96), interpolation=cv2.INTER_NEAREST) > 0
    python = np.asarray(Image.open(io.BytesIO(base64.b64decode(tiles[str(disc["index"])]["model"].split(",", 1)[1]))).convert("L"))
    theirs = python >= round(np.sqrt(0.5) * 255)
    iou = (ours & theirs).sum() / (ours | theirs).sum()
    assert iou >= 0.9
    # ... pixel by pixel, against the fit's own model (model_window, as the tiles draw it) on the same crop.
    comparison = compare_photo(EXAMPLE)
    fitted = next(item.fits[comparison.fit.family.name] for item in comparison.fit.disc_fits if item.disc.index == disc["index"])
    factor = tile["factor"]
    python = model_window(fitted, tile["left"], tile["top"], size * factor).reshape(size, factor, size, factor).mean(axis=(1, 3))
    difference = np.abs(model - python) / (high - low)
    print(f"model against Python's: IoU of the half masks {iou:.4f}, mean |difference| {difference.mean():.4f}, "
          f"largest {difference.max():.4f} of the contrast; residual RMS {drawn['residual_rms']:.4f}")
    assert difference.mean() < 0.01 and difference.max() < 0.1 and drawn["residual_rms"] < 0.05

    # What the canvas shows is that model, through the report's grey scale.
    url = page.evaluate("document.getElementById('match-kernel').toDataURL('image/png')")
    shown = np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("L"), dtype=np.float64)
    expected = np.round(np.sqrt(np.clip((model - low) / (high - low), 0, 1)) * 255)
    assert shown.shape == (size, size) and np.abs(shown - expected).max() <= 1
    assert page.locator("#match canvas").count() == 3 and "kernel_mc.wgsl" in page.text_content("#match-note")
    page.evaluate("document.getElementById('side').scrollTop = 0")
    path = artifacts / "viewer_photo_kernel.png"
    page.screenshot(path=str(path))
    print(f"screenshot: {path}")
    assert page.errors == []
    page.close()


@pytest.mark.parametrize(
    ("shape", "features"),
    [
        ("ngon", {"blades": 7, "roundness": 0.5, "rim": 0.4, "squeeze": 1.3, "vignetting": {"radius": 1.0, "shift": 0.9}}),
        ("pentagon", {"chromatic": {"red": 0.06, "blue": -0.05}, "rim": -0.3}),
    ],
    ids=["cat-eye-rim-rounded-squeezed", "chromatic"],
)
def test_page_kernel_draws_the_real_lens_features(browser, server, shape, features):  # noqa: F811
    """The page's kernel renderer, on an aperture with the cat-eye cut at a field position, the rim,
    rounded blades, squeeze or colour, packed as the tiles are: as ``render_kernel`` draws it, per channel."""
    import math

    import numpy as np

    from bokehfit.apertures import make_aperture
    from bokehfit.kernels import render_kernel
    from test_view import _need

    page = open_photo_page(browser, server)
    aperture = make_aperture(shape, 25.0, **features)
    where, size, diameter = (0.6, -0.45), 81, 50.0
    assert aperture.vignetting is None or aperture.area(where) < 0.6  # the cat-eye cut takes more than 40 % here
    strata = math.isqrt(int(256 * math.pi * diameter**2 / 4))
    values = aperture.shader_params(where)
    tile = {"size": size, "samples": strata * strata, "strata": strata, "scale": diameter * math.sqrt(math.pi) / 2,
            "aperture": {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()},
            "chromatic": None if aperture.chromatic is None else [aperture.chromatic.red, aperture.chromatic.blue],
            "center": [(size - 1) / 2] * 2, "blur_px": 0.05}
    drawn = page.evaluate("(tile) => window.photoView.drawTile(tile)", tile)
    if "error" in drawn:
        page.close()
        _need(f"headless chromium has no usable WebGPU here: {drawn['error']}")
    reference = render_kernel(aperture, diameter_px=diameter, size=size, method="exact", field_position=where)
    reference = reference[..., None] if reference.ndim == 2 else reference
    assert len(drawn["kernels"]) == reference.shape[-1]
    rows, cols = np.mgrid[0:size, 0:size]
    for channel, kernel in enumerate(drawn["kernels"]):
        ours, theirs = np.asarray(kernel).reshape(size, size), reference[..., channel]
        l1 = np.abs(ours - theirs).sum()
        moved = [abs((ours * axis).sum() - (theirs * axis).sum()) for axis in (cols, rows)]
        print(f"{shape} channel {channel}: L1 {l1:.4f}, centroids {moved[0]:.3f}, {moved[1]:.3f} px apart")
        assert l1 < 0.1 and max(moved) < 0.25
    assert page.errors == []
    page.close()


def test_without_webgpu_the_page_shows_the_python_model_and_says_so(browser, server):  # noqa: F811
    page = browser.new_page()
    errors = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    page.add_init_script("delete Navigator.prototype.gpu")
    page.goto(server.photo_url)
    page.wait_for_function("document.body.dataset.ready === 'true'", timeout=PAGE_TIMEOUT_MS)
    page.click("#candidates tbody tr[data-role='used']")
    page.wait_for_function("document.body.dataset.kernel === 'fallback'", timeout=PAGE_TIMEOUT_MS)
    assert page.locator("#match img").count() == 3 and page.locator("#match canvas").count() == 0
    note = page.text_content("#match-note")
    assert "navigator.gpu is missing" in note and "drawn in Python" in note
    assert errors == []
    page.close()
