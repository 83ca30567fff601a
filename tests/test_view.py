"""``bokehfit view``: the server's shader, layout and parameters, and the page in headless Chromium.

The browser tests drive Debian's chromium (``/usr/bin/chromium``, or
``$BOKEHFIT_CHROMIUM``) through Playwright, headless, with WebGPU on
SwiftShader (``--enable-unsafe-webgpu``), against a server started in a thread
on a free port. Renders are tiny (128×128 at most, but for the one speed
measurement at 512×512) so that SwiftShader on two cores keeps up. Where
chromium or playwright is missing the browser tests skip and say why; under
CI=true they fail instead. Screenshots of both modes are kept in a temporary
folder (printed; ``$BOKEHFIT_TEST_ARTIFACTS`` names another).
"""

from __future__ import annotations

import base64
import io
import json
import math
import os
import re
import signal
import struct
import subprocess
import sys
import time
import urllib.error
import urllib.request
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from bokehfit.apertures import SHAPES, make_aperture
from bokehfit.errors import InputError
from bokehfit.gpu.shaders import shader_source
from bokehfit.scene import cornell_box, make_lens
from bokehfit.scene.renderer import RENDER_PARAMS
from bokehfit.scene.wgsl import scene_wgsl
from bokehfit.view import ViewerServer, depth_of_field, settings_from_compare

CHROMIUM = Path(os.environ.get("BOKEHFIT_CHROMIUM", "/usr/bin/chromium"))
CHROMIUM_ARGS = [
    "--enable-unsafe-webgpu",
    "--no-sandbox",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
#: Image size of the page in the browser tests.
SMALL = "128x128"
#: Longest wait for the page to compile the path tracer and finish a few samples (s).
PAGE_TIMEOUT_MS = 60_000
#: The browser's frame and the Python renderer's (lavapipe) trace the same paths; f32
#: rounding differs (SwiftShader's and llvmpipe's pow, sqrt, trigonometry), which sends a
#: few paths elsewhere, so most pixels agree to float precision and some do not.
SAME_PIXEL_TOLERANCE = 1e-4
MIN_SAME_PIXEL_FRACTION = 0.7
#: The 512×512 speed measurement runs this long (s).
SPEED_SECONDS = 6.0


# --- the server, without a browser --------------------------------------------------------


@pytest.fixture(scope="module")
def server():
    with ViewerServer(0).start() as running:
        yield running


def get(server, path, host=None):
    request = urllib.request.Request(server.url.rstrip("/") + path)
    if host is not None:
        request.add_header("Host", host)
    try:
        with urllib.request.urlopen(request, timeout=30) as response:
            return response.status, response.headers.get("Content-Type"), response.read()
    except urllib.error.HTTPError as error:
        with error:
            return error.code, error.headers.get("Content-Type"), error.read()


#: A module's relative ES imports (``import { x } from "./y.js";``, ``import "./y.js";``), the pages'
#: only way to load another.
ES_IMPORT = re.compile(r'^import\s+(?:[^;"]*?\sfrom\s+)?"\./([A-Za-z0-9_]+\.js)";', re.M)
#: The folder of the pages' files (package data).
STATIC = Path(__file__).resolve().parent.parent / "bokehfit" / "view" / "static"


def page_modules(fetch, entry: str) -> dict[str, str]:
    """Every ES module the page's script ``entry`` loads, itself included, by name: its text as
    ``fetch(path)`` answers it (status, content type, bytes), each a served JavaScript file."""
    found, todo = {}, [entry]
    while todo:
        name = todo.pop()
        if name in found:
            continue
        status, kind, body = fetch(f"/{name}")
        assert status == 200 and kind == "text/javascript; charset=utf-8", f"/{name}: {status} {kind}"
        found[name] = body.decode("utf-8")
        todo.extend(ES_IMPORT.findall(found[name]))
    return found


def post(server, path, body: bytes):
    """A POST as the viewer's page sends it: its Origin, the token of its HTML, JSON."""
    _, _, page = get(server, "/")
    token = re.search(rb'<meta name="bokehfit-token" content="([^"]+)">', page).group(1).decode()
    headers = {"Content-Type": "application/json", "Origin": server.url.rstrip("/"), "X-Bokehfit-Token": token}
    request = urllib.request.Request(server.url.rstrip("/") + path, data=body, method="POST", headers=headers)
    try:
        with urllib.request.urlopen(request, timeout=30) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as error:
        with error:
            return error.code, json.loads(error.read())


def test_server_listens_on_loopback_only(server):
    assert server.url.startswith("http://127.0.0.1:") and server.port > 0
    assert server.host == "127.0.0.1"


def test_uniform_layout_is_render_params(server):
    status, kind, body = get(server, "/config.json")
    assert status == 200 and kind.startswith("application/json")
    config = json.loads(body)
    layout = config["uniform"]
    assert [(f["name"], f["type"]) for f in layout["fields"]] == list(RENDER_PARAMS.fields)
    # The page packs each component at the offset NumPy's dtype puts it (WGSL's alignment).
    assert [f["offset"] for f in layout["fields"]] == [RENDER_PARAMS.dtype.fields[f["name"]][1] for f in layout["fields"]]
    for f in layout["fields"]:
        assert (f["scalar"], f["components"]) in {("f32", 1), ("u32", 1), ("i32", 1)} | {(s, n) for s in ("f32", "u32") for n in (2, 3)}
    assert layout["size_bytes"] == RENDER_PARAMS.dtype.itemsize == RENDER_PARAMS.buffer_size
    assert layout["wgsl"] == RENDER_PARAMS.wgsl()
    assert config["shader"]["entry_point"] == "main" and config["shader"]["workgroup_size"] == [8, 8, 1]
    display = config["display"]
    assert display["url"] == "/display.wgsl" and display["entry_point"] == "display" and display["workgroup_size"] == [8, 8, 1]
    assert set(display["bindings"]) == {"params", "accum", "rgba"}
    assert [s["name"] for s in config["shapes"]] == list(SHAPES)


def test_shader_is_the_package_wgsl_with_includes_resolved(server):
    status, kind, body = get(server, "/pathtrace.wgsl")
    assert status == 200 and kind.startswith("text/wgsl")
    source = body.decode("utf-8")
    assert "#include" not in source
    for name in ("rng.wgsl", "apertures.wgsl", "camera.wgsl", "scene.wgsl"):
        # Each run of lines between two includes stands in the served shader verbatim, in order.
        chunks = re.split(r"^// #include .*$", shader_source(name), flags=re.M)
        position = 0
        for chunk in (c.strip("\n") for c in chunks):
            found = source.find(chunk, position)
            assert found >= 0, f"{name} is not in the served shader verbatim"
            position = found + len(chunk)
    assert RENDER_PARAMS.wgsl() in source
    assert scene_wgsl(cornell_box()) in source
    assert source.count("fn camera_ray(") == 1 and source.count("struct RenderParams") == 1


def test_display_pass_is_the_package_tone_map(server):
    status, kind, body = get(server, "/display.wgsl")
    assert status == 200 and kind.startswith("text/wgsl")
    source = body.decode("utf-8")
    assert "#include" not in source and RENDER_PARAMS.wgsl() in source
    assert shader_source("tonemap.wgsl").strip() in source and source.count("fn tone_map_srgb8(") == 1
    for name, page in page_modules(lambda path: get(server, path), "viewer.js").items():
        assert "fn srgb_encode" not in page and "fn tone_map" not in page, f"{name}: a second tone map in the page"


def test_the_pages_modules_are_served_and_each_file_is_one_of_them(server):
    """The page's ES modules, followed from viewer.js through their imports, are all served (a
    missing route would stop the page); every script of ``static/`` is the Cornell-box page's or the
    photo page's (test_view_photo.py follows photo.js), and none is over 600 lines."""
    modules = page_modules(lambda path: get(server, path), "viewer.js")
    assert {"viewer.js", "viewer_renderer.js", "viewer_topdown.js", "common.js"} <= set(modules)
    for path in sorted(STATIC.glob("*.js")):
        assert path.name in modules or path.name.startswith("photo"), f"{path.name} is no module of a page"
        assert len(path.read_text(encoding="utf-8").splitlines()) <= 600, f"{path.name} is over 600 lines"
        if path.name not in modules:
            assert get(server, f"/{path.name}")[0] == 404  # the photo page's, without a photo


def f32(value) -> float:
    return float(np.float32(value))


def test_params_are_the_lens_values(server):
    status, _, body = get(server, "/params.json?shape=ngon&blades=7&angle=100&fstop=2&focus=0.9&width=96&height=64")
    assert status == 200
    answer = json.loads(body)
    values = answer["values"]
    assert set(values) == {name for name, _ in RENDER_PARAMS.fields}
    lens = make_lens(make_aperture("ngon", 100.0, blades=7), fstop=2.0, focus_distance_m=0.9)
    assert values["shape"] == SHAPES["ngon"].shader_id and values["blades"] == 7
    assert values["aperture_scale"] == f32(lens.aperture_scale_m)
    assert values["focus_distance"] == f32(0.9)
    assert values["cos_angle"] == f32(math.cos(math.radians(100))) and values["sin_angle"] == f32(math.sin(math.radians(100)))
    assert values["tan_half"] == [f32(t) for t in lens.tan_half_fov(96, 64)]
    assert (values["image_size"], values["tile_origin"], values["tile_size"]) == ([96, 64], [0, 0], [96, 64])
    assert values["sample_index"] == 0
    assert answer["describe"] == lens.describe()
    assert answer["symmetry_deg"] == pytest.approx(360 / 7)


def test_config_has_the_real_lens_feature_sliders(server):
    config = json.loads(get(server, "/config.json")[2])
    ranges, defaults = config["ranges"], config["defaults"]
    for name in ("roundness", "squeeze", "rim", "vignetting_radius", "vignetting_shift", "chromatic_red", "chromatic_blue"):
        low, high = ranges[name]
        assert low < defaults[name] < high or low <= defaults[name] <= high, name
    # The model's neutral values: straight blades, no squeeze, a flat profile; no barrel, no colour.
    assert (defaults["roundness"], defaults["squeeze"], defaults["rim"]) == (0.0, 1.0, 0.0)
    assert defaults["vignetting"] is False and (defaults["chromatic_red"], defaults["chromatic_blue"]) == (0.0, 0.0)
    assert ranges["roundness"] == [0.0, 1.0] and ranges["rim"] == [-1.0, 1.0]
    rounds = {s["name"]: s["rounds"] for s in config["shapes"]}
    assert rounds["ngon"] and rounds["hexagon"] and not rounds["circle"] and not rounds["star"]
    page = get(server, "/")[2].decode()
    for element in ("roundness", "squeeze", "rim", "vignetting", "vignetting-radius", "vignetting-shift", "chromatic-red", "chromatic-blue"):
        assert f'id="{element}"' in page, element


def test_params_carry_the_real_lens_features(server):
    query = (
        "shape=ngon&blades=9&angle=10&fstop=2&focus=0.9&width=96&height=64&roundness=0.4&squeeze=1.3&rim=0.5"
        "&vignetting_radius=1.2&vignetting_shift=0.8&chromatic_red=0.03&chromatic_blue=-0.02"
    )
    status, _, body = get(server, f"/params.json?{query}")
    assert status == 200
    answer = json.loads(body)
    values = answer["values"]
    aperture = make_aperture(
        "ngon", 10.0, blades=9, roundness=0.4, squeeze=1.3, rim=0.5,
        vignetting=dict(radius=1.2, shift=0.8), chromatic=dict(red=0.03, blue=-0.02),
    )
    lens = make_lens(aperture, fstop=2.0, focus_distance_m=0.9)
    for name, value in lens.aperture.shader_params().items():
        assert values[name] == pytest.approx(np.float32(value).tolist()), name
    assert answer["lens"]["vignetting"] == {"radius": 1.2, "shift": 0.8}
    assert answer["lens"]["chromatic"] == {"red": 0.03, "blue": -0.02}
    assert answer["describe"] == lens.describe()
    # Roundness belongs to n-gons: the page's value is left out for a circle, not refused.
    values = json.loads(get(server, "/params.json?shape=circle&roundness=0.5")[2])["values"]
    assert values["roundness"] == 0.0


@pytest.mark.parametrize(
    "query,needle",
    [
        ("vignetting_radius=1.5", "vignetting_shift must be given"),
        ("vignetting_radius=0.5&vignetting_shift=1", "vignetting.radius"),
        ("chromatic_red=0.9&chromatic_blue=0", "chromatic.red"),
        ("squeeze=0", "squeeze"),
        ("rim=2", "rim"),
    ],
)
def test_bad_feature_params_answer_400_naming_the_parameter(server, query, needle):
    status, _, body = get(server, f"/params.json?{query}")
    assert status == 400 and needle in json.loads(body)["error"]


@pytest.mark.parametrize(
    "query,needle",
    [("shape=hexgon", "shape must be one of"), ("fstop=0", "fstop"), ("focus=nan", "focus"), ("shape=ngon&blades=2", "blades"), ("width=0", "width")],
)
def test_bad_params_answer_400_naming_the_parameter(server, query, needle):
    status, _, body = get(server, f"/params.json?{query}")
    assert status == 400 and needle in json.loads(body)["error"]


def test_unknown_paths_and_hosts_are_refused(server):
    assert get(server, "/../pyproject.toml")[0] == 404
    assert get(server, "/secret")[0] == 404
    status, _, body = get(server, "/config.json", host=f"evil.example:{server.port}")
    assert status == 421 and "Host" in json.loads(body)["error"]
    status, kind, body = get(server, "/")
    assert status == 200 and kind.startswith("text/html") and b'id="render"' in body


def test_depth_of_field_limits_blur_by_the_criterion():
    lens = make_lens(make_aperture("circle"), fstop=2.8, focus_distance_m=0.7)
    dof = depth_of_field(lens, 512, 512)
    assert dof.coc_mm == pytest.approx(math.hypot(36.0, 36.0) / 1500)
    assert dof.near_m < 0.7 < dof.far_m
    assert lens.coc_mm(dof.near_m) == pytest.approx(dof.coc_mm)
    assert lens.coc_mm(dof.far_m) == pytest.approx(dof.coc_mm)
    assert lens.coc_mm(math.inf) == pytest.approx(dof.coc_mm * dof.hyperfocal_m / 0.7)
    beyond = depth_of_field(make_lens(make_aperture("circle"), fstop=16, focus_distance_m=5.0), 512, 512)
    assert beyond.far_m == math.inf and beyond.to_json()["far_m"] is None


def compare_document(**aperture) -> dict:
    base = {"shape": "hexagon", "blades": 6, "aspect": None, "angle_deg": 15.0, "fstop": 2.0, "focus_side": "far", "size_convention": "equal-area"}
    return {"schema_version": 1, "aperture": {**base, **aperture}}


def test_settings_from_compare():
    m = settings_from_compare(compare_document())
    assert (m["shape"], m["angle_deg"], m["blades"], m["aspect"], m["fstop"]) == ("hexagon", 15.0, None, None, 2.0)
    m = settings_from_compare(compare_document(shape="ngon", blades=9, angle_deg=3.0, fstop=None, fstop_reason="no EXIF"))
    assert (m["shape"], m["blades"], m["fstop"]) == ("ngon", 9, None) and "no EXIF" in m["notes"]
    m = settings_from_compare(compare_document(shape="slit", blades=None, aspect=0.4, angle_deg=30.0))
    assert (m["shape"], m["aspect"]) == ("slit", 0.4)
    m = settings_from_compare(compare_document(shape="circle", blades=None, angle_deg=None))
    assert m["angle_deg"] == 0.0
    m = settings_from_compare(compare_document(size_convention="circumscribed", fstop=2.0))
    assert m["fstop"] == pytest.approx(2.0 * make_aperture("hexagon").extent() * math.sqrt(math.pi))
    m = settings_from_compare(compare_document(shape="triangle", blades=3, focus_side="unknown"))
    assert any("modulo" in note for note in m["notes"])


def test_settings_from_compare_reads_the_real_lens_features():
    features = dict(roundness=0.3, squeeze=1.2, rim=-0.4, vignetting={"radius": 1.4, "shift": 0.9}, chromatic={"red": 0.02, "blue": -0.01})
    m = settings_from_compare({**compare_document(shape="ngon", blades=9, **features), "schema_version": 2})
    assert {key: m[key] for key in features} == features
    # Null (a feature not fitted) and schema 1 (no such keys) give the defaults.
    nulls = dict(roundness=None, squeeze=None, rim=None, vignetting=None, chromatic=None)
    for document in (compare_document(**nulls), compare_document()):
        m = settings_from_compare(document)
        assert (m["roundness"], m["squeeze"], m["rim"], m["vignetting"], m["chromatic"]) == (0.0, 1.0, 0.0, None, None)


@pytest.mark.parametrize(
    "document,needle",
    [
        ({"aperture": {"shape": "ngon", "blades": 9, "vignetting": {"radius": 1.2}}}, "aperture.vignetting must be an object"),
        ({"aperture": {"shape": "ngon", "blades": 9, "roundness": "round"}}, "aperture.roundness"),
        ({"aperture": {"shape": "circle", "roundness": 0.5}}, "roundness applies only to n-gons"),
        ({"discs": []}, "no 'aperture'"),
        ({"schema_version": 3, "aperture": {"shape": "circle"}}, "schema_version"),
        ({"aperture": {"shape": None}}, "fitted no aperture"),
        ({"aperture": {"shape": "hexgon"}}, "shape must be one of"),
        ({"aperture": {"shape": "ngon", "blades": 99}}, "blades"),
    ],
)
def test_settings_from_compare_refuses(document, needle):
    with pytest.raises(InputError, match=needle):
        settings_from_compare(document)


def test_matched_endpoint(server):
    status, answer = post(server, "/matched", json.dumps(compare_document(shape="pentagon", blades=5, angle_deg=7.5)).encode())
    assert status == 200 and answer["shape"] == "pentagon" and answer["angle_deg"] == 7.5
    status, answer = post(server, "/matched", b"{not json")
    assert status == 400 and "not JSON" in answer["error"]


#: Longest wait for `bokehfit view` to stop after Ctrl-C (s).
STOP_TIMEOUT_S = 15


def test_cli_serves_until_ctrl_c(tmp_path):
    serve_then_ctrl_c(tmp_path)


def test_cli_stops_on_ctrl_c_when_started_with_sigint_ignored(tmp_path):
    """A background job inherits SIGINT ignored; `bokehfit view` must still stop on it."""
    serve_then_ctrl_c(tmp_path, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))


def serve_then_ctrl_c(tmp_path, **popen):
    """Start `bokehfit view`, fetch its config, send SIGINT: a clean stop ("stopped", exit 0) in bounded time."""
    process = subprocess.Popen(
        [sys.executable, "-m", "bokehfit", "view", "--no-browser", "--port", "0", "--size", "64x48"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen,
    )
    try:
        line = process.stdout.readline()
        match = re.search(r"http://127\.0\.0\.1:(\d+)/", line)
        assert match, f"no URL in {line!r}; stderr: {process.stderr.read() if process.poll() is not None else ''}"
        with urllib.request.urlopen(match.group(0) + "config.json", timeout=30) as response:
            assert json.loads(response.read())["defaults"]["width"] == 64
        process.send_signal(signal.SIGINT)
        try:
            out, err = process.communicate(timeout=STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            pytest.fail(f"`bokehfit view` did not stop within {STOP_TIMEOUT_S} s of SIGINT", pytrace=False)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 0, err
    assert "stopped" in out and "Traceback" not in err


def test_cli_refuses_a_bad_port(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "bokehfit", "view", "--no-browser", "--port", "70000"], cwd=tmp_path, capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 2 and "port" in done.stderr and "Traceback" not in done.stderr


# --- the page in headless Chromium --------------------------------------------------------


def _need(reason: str):
    if os.environ.get("CI") == "true":
        pytest.fail(f"CI=true but {reason}", pytrace=False)
    pytest.skip(reason)


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    """A headless Chromium with WebGPU (SwiftShader) and a fresh profile."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _need("playwright is not installed (pip install 'bokehfit[test]')")
    if not CHROMIUM.is_file():
        _need(f"no chromium at {CHROMIUM} (apt-get install chromium, or set BOKEHFIT_CHROMIUM)")
    playwright = sync_playwright().start()
    try:
        context = playwright.chromium.launch_persistent_context(
            str(tmp_path_factory.mktemp("chromium_profile")),
            executable_path=str(CHROMIUM),
            headless=True,
            args=CHROMIUM_ARGS,
            viewport={"width": 1320, "height": 720},
            accept_downloads=True,
        )
        try:
            yield context
        finally:
            context.close()
    finally:
        playwright.stop()


@pytest.fixture(scope="module")
def artifacts(tmp_path_factory):
    folder = os.environ.get("BOKEHFIT_TEST_ARTIFACTS")
    path = Path(folder) if folder else tmp_path_factory.mktemp("view_artifacts")
    path.mkdir(parents=True, exist_ok=True)
    return path


def open_page(browser, server, options: str = ""):
    """A page of the viewer at ``options`` (URL query), its path tracer compiled."""
    page = browser.new_page()
    errors = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    page.goto(f"{server.url}?size={SMALL}&{options}")
    page.wait_for_function("document.body.dataset.ready === 'true'", timeout=PAGE_TIMEOUT_MS)
    webgpu = page.evaluate("document.body.dataset.webgpu")
    if webgpu != "ok":
        reason = page.text_content("#no-webgpu-reason") or page.text_content("#message")
        page.close()
        _need(f"headless chromium has no usable WebGPU here ({webgpu}: {reason})")
    page.errors = errors
    return page


def spp(page) -> int:
    return int(page.text_content("#spp"))


def wait_spp(page, at_least: int):
    page.wait_for_function(f"window.bokehfitViewer.spp >= {at_least}", timeout=PAGE_TIMEOUT_MS)


def pixels(png: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.float64)


def save_screenshot(page, artifacts: Path, name: str) -> np.ndarray:
    path = artifacts / name
    page.screenshot(path=str(path))
    print(f"screenshot: {path}")
    image = pixels(path.read_bytes())
    assert image.var() > 0, f"{path} is blank"
    return image


def render_pixels(page) -> np.ndarray:
    image = pixels(page.locator("#render").screenshot())
    assert image.var() > 0, "the render is blank"
    return image


CONTROLS = ("#focus-distance", "#fstop", "#shape", "#angle")


def test_view_mode_renders_progressively_without_controls(browser, server, artifacts):
    page = open_page(browser, server)
    try:
        assert page.evaluate("document.body.dataset.mode") == "view"
        wait_spp(page, 1)
        first = spp(page)
        page.wait_for_function(f"Number(document.getElementById('spp').textContent) > {first}", timeout=PAGE_TIMEOUT_MS)
        for selector in CONTROLS:
            assert not page.is_visible(selector), f"{selector} is visible in view mode"
        # the edit controls are hidden, but not their existence: the toggle shows, and a line says how
        assert float(page.evaluate("getComputedStyle(document.getElementById('mode-toggle')).opacity")) >= 0.5
        assert page.is_visible("#edit-hint") and "Edit" in page.text_content("#edit-hint")
        assert "circle, f/2.8, focus 0.7 m" in page.text_content("#settings")
        assert "sensor diagonal / 1500" in page.text_content("#dof-text")
        save_screenshot(page, artifacts, "viewer_view_mode.png")
        render_pixels(page)
        assert page.errors == []
    finally:
        page.close()


def test_first_seconds_show_a_loading_message_not_a_black_canvas(browser, server):
    page = browser.new_page()
    shader_held = []

    def hold_the_shader(route):  # the shader arrives late, as on a slow machine: the page waits on it
        shader_held.append(True)
        time.sleep(1.5)
        route.continue_()

    page.route("**/pathtrace.wgsl", hold_the_shader)
    try:
        page.goto(f"{server.url}?size={SMALL}")
        page.wait_for_selector("#loading", state="visible", timeout=PAGE_TIMEOUT_MS)
        assert "Starting the path tracer" in page.text_content("#loading")
        assert not page.is_visible("#status"), "'0 spp' on a black canvas"
        page.wait_for_function("document.body.dataset.ready === 'true'", timeout=PAGE_TIMEOUT_MS)
        if page.evaluate("document.body.dataset.webgpu") != "ok":
            _need("headless chromium has no usable WebGPU here")
        wait_spp(page, 1)
        page.wait_for_selector("#loading", state="hidden", timeout=PAGE_TIMEOUT_MS)
        assert page.is_visible("#status") and spp(page) >= 1
        assert shader_held
        assert page.is_visible("#edit-hint") and page.is_visible("#mode-toggle")
    finally:
        page.close()


def _fill_of_the_bottom_left_disc(page) -> float:
    """The bottom-left point light's disc (a light in front of the focus plane, a fifth of the image wide):
    its bright pixels over its bounding box (a square 1, a circle π/4)."""
    image = page.evaluate("window.bokehfitViewer.readImage()")
    rgb = np.asarray(image["rgb"], dtype=np.float64).reshape(image["height"], image["width"], 3)
    bright = rgb.mean(axis=2) > 0.5 * rgb.mean(axis=2).max()
    assert 0.02 < bright.mean() < 0.6 and (rgb.mean(axis=2) < 0.02).mean() > 0.3, "lights on black"
    corner = bright[image["height"] // 2:, : image["width"] // 3]
    rows, cols = np.nonzero(corner)
    return corner.sum() / ((np.ptp(rows) + 1) * (np.ptp(cols) + 1))


def test_point_lights_are_one_click_away(browser, server, artifacts):
    fills = {}
    for shape in ("square", "circle"):
        page = open_page(browser, server, f"shape={shape}&angle=0&max_spp=8")
        try:
            assert page.is_visible("#scene-toggle") and page.text_content("#scene-toggle") == "Point lights"
            before = page.evaluate("window.bokehfitViewer.restarts")
            page.click("#scene-toggle")  # in view mode: one click
            page.wait_for_function(f"window.bokehfitViewer.restarts > {before}")
            assert page.evaluate("window.bokehfitViewer.scene") == "points"
            page.wait_for_function("window.bokehfitViewer.spp >= 8", timeout=PAGE_TIMEOUT_MS)
            fills[shape] = _fill_of_the_bottom_left_disc(page)
            if shape == "square":
                save_screenshot(page, artifacts, "viewer_point_lights.png")
            page.click("#scene-toggle")
            assert page.evaluate("window.bokehfitViewer.scene") == "cornell"
            assert page.errors == []
        finally:
            page.close()
    assert fills["square"] > 0.9 and abs(fills["circle"] - math.pi / 4) < 0.08, fills


def test_corner_toggle_reveals_the_controls(browser, server, artifacts):
    page = open_page(browser, server, "shape=hexagon&angle=15")
    try:
        page.hover("#corner")
        page.wait_for_function("getComputedStyle(document.getElementById('mode-toggle')).opacity === '1'")
        page.click("#mode-toggle")
        assert page.evaluate("document.body.dataset.mode") == "edit"
        for selector in CONTROLS:
            assert page.is_visible(selector), f"{selector} is hidden in edit mode"
        assert not page.is_visible("#blades") and not page.is_visible("#aspect")
        options = page.eval_on_selector_all("#shape option", "options => options.map(o => [o.value, o.disabled])")
        # A mask shape waits for its image: the option is there, and off until a PNG is uploaded.
        assert options == [[name, spec.tabulated] for name, spec in SHAPES.items()]
        assert page.is_visible("#mask-file")
        page.select_option("#shape", "ngon")
        assert page.is_visible("#blades") and not page.is_visible("#aspect")
        page.select_option("#shape", "slit")
        assert page.is_visible("#aspect") and not page.is_visible("#blades")
        wait_spp(page, 2)
        save_screenshot(page, artifacts, "viewer_edit_mode.png")
        page.click("#mode-toggle")
        assert page.evaluate("document.body.dataset.mode") == "view"
        assert not page.is_visible("#shape")
        assert page.errors == []
    finally:
        page.close()


def test_click_in_topdown_sets_focus_and_restarts(browser, server):
    page = open_page(browser, server)
    try:
        wait_spp(page, 4)
        box = page.locator("#topdown").bounding_box()
        restarts = page.evaluate("window.bokehfitViewer.restarts")
        page.mouse.click(box["x"] + box["width"] / 2, box["y"] + 0.5 * box["height"])  # view mode: nothing happens
        assert page.evaluate("window.bokehfitViewer.restarts") == restarts
        page.keyboard.press("e")
        assert page.evaluate("document.body.dataset.mode") == "edit"

        focus = []
        for fraction in (0.3, 0.6):
            wait_spp(page, 4)
            before = spp(page)
            restarts = page.evaluate("window.bokehfitViewer.restarts")
            page.mouse.click(box["x"] + box["width"] / 2, box["y"] + fraction * box["height"])
            after = page.wait_for_function(
                f"window.bokehfitViewer.restarts > {restarts} ? {{spp: window.bokehfitViewer.spp}} : null", timeout=PAGE_TIMEOUT_MS
            ).json_value()
            assert after["spp"] < before, "accumulation did not restart"
            state = page.evaluate("window.bokehfitViewer.state")
            assert float(page.input_value("#focus-distance")) == pytest.approx(state["focus_distance_m"], abs=0.005)
            assert f"{state['focus_distance_m']:.3f} m" in page.text_content("#focus-distance-out")
            focus.append(state["focus_distance_m"])
        assert focus[0] > focus[1] > 0.0, "a click higher up the sketch must focus deeper"
        assert focus[1] != 0.7
        assert page.errors == []
    finally:
        page.close()


def test_shape_changes_the_render_and_nothing_else_does(browser, server):
    page = open_page(browser, server, "max_spp=4&mode=edit&fstop=1.4")
    try:
        def settle():
            page.wait_for_function("window.bokehfitViewer.spp === 4 && document.getElementById('rate').textContent.includes('done')", timeout=PAGE_TIMEOUT_MS)
            return render_pixels(page)

        circle = settle()
        restarts = page.evaluate("window.bokehfitViewer.restarts")
        page.select_option("#shape", "slit")
        page.wait_for_function(f"window.bokehfitViewer.restarts > {restarts}")
        slit = settle()
        page.select_option("#shape", "circle")
        page.wait_for_function(f"window.bokehfitViewer.restarts > {restarts + 1}")
        again = settle()
        assert np.abs(again - circle).mean() < 0.05, "the same settings must give the same frame"
        assert np.abs(slit - circle).mean() > 1.0, "the shape did not change the render"
        assert page.errors == []
    finally:
        page.close()


def test_browser_traces_the_same_paths_as_python(browser, server, gpu):
    """The page's linear frame against ``bokehfit.scene.render`` on lavapipe: same shader, same uniforms."""
    from bokehfit.scene import make_settings, render

    lens = make_lens(make_aperture("ngon", 10.0, blades=7), fstop=1.4, focus_distance_m=cornell_box().default_focus_m)
    page = open_page(browser, server, "max_spp=4&shape=ngon&blades=7&angle=10&fstop=1.4")
    try:
        page.wait_for_function("window.bokehfitViewer.spp === 4", timeout=PAGE_TIMEOUT_MS)
        frame = page.evaluate("window.bokehfitViewer.readImage()")
    finally:
        page.close()
    assert frame["samples"] == 4
    browser_image = np.asarray(frame["rgb"], dtype=np.float32).reshape(frame["height"], frame["width"], 3)
    python_image = render("cornell", lens, make_settings(frame["width"], frame["height"], 4)).image
    same = (np.abs(browser_image - python_image).max(axis=-1) <= SAME_PIXEL_TOLERANCE).mean()
    assert same >= MIN_SAME_PIXEL_FRACTION, f"only {same:.0%} of the pixels agree with the Python renderer"
    np.testing.assert_allclose(browser_image.mean(axis=(0, 1)), python_image.mean(axis=(0, 1)), rtol=0.05)


def test_the_page_shows_its_frame_through_the_package_tone_map(browser, server):
    """The canvas holds tone_map_srgb8 (NumPy, as `bokehfit render` writes PNGs) of the page's own linear frame."""
    from bokehfit.scene import tone_map_srgb8

    page = open_page(browser, server, "max_spp=4&shape=hexagon&fstop=1.4")
    try:
        page.wait_for_function("window.bokehfitViewer.spp === 4", timeout=PAGE_TIMEOUT_MS)
        frame = page.evaluate("window.bokehfitViewer.readImage()")
        shown = page.evaluate(
            "(() => { const c = document.getElementById('render');"
            " return Array.from(c.getContext('2d').getImageData(0, 0, c.width, c.height).data); })()"
        )
        assert page.errors == []
    finally:
        page.close()
    height, width = frame["height"], frame["width"]
    linear = np.asarray(frame["rgb"], dtype=np.float32).reshape(height, width, 3)
    rgba = np.asarray(shown, dtype=np.uint8).reshape(height, width, 4)
    assert (rgba[..., 3] == 255).all() and linear.max() > 0.05
    # The WGSL twin rounds in float32 (here on SwiftShader): one code value, at rounding boundaries only.
    diff = rgba[..., :3].astype(int) - tone_map_srgb8(linear).astype(int)
    assert np.abs(diff).max() <= 1 and np.count_nonzero(diff) <= 1e-3 * diff.size + 1


def test_uploaded_mask_traces_the_same_paths_as_python(browser, server, gpu, tmp_path):
    """A PNG in the mask input: the server builds its table, the page binds it, and the frame is Python's."""
    from bokehfit.scene import make_settings, render

    transmission = np.zeros((9, 9))
    transmission[1:8, 2:7] = 1.0
    transmission[1:4, 2:4] = 0.4  # a grey corner: the mask is neither symmetric nor binary
    path = tmp_path / "stop.png"
    Image.fromarray(np.round(transmission * 255).astype(np.uint8), "L").save(path)
    page = open_page(browser, server, "max_spp=4&mode=edit&angle=30&fstop=1.4")
    try:
        page.wait_for_function("window.bokehfitViewer.spp === 4", timeout=PAGE_TIMEOUT_MS)
        circle = page.evaluate("window.bokehfitViewer.readImage()")
        restarts = page.evaluate("window.bokehfitViewer.restarts")
        page.set_input_files("#mask-file", str(path))
        page.wait_for_function(f"window.bokehfitViewer.restarts > {restarts} && window.bokehfitViewer.spp === 4", timeout=PAGE_TIMEOUT_MS)
        state = page.evaluate("window.bokehfitViewer.state")
        assert state["shape"] == "mask" and state["mask"] == make_aperture("mask", mask=str(path)).mask.digest
        assert page.input_value("#shape") == "mask"
        assert "stop.png" in page.text_content("#message") and "mask 9×9" in page.text_content("#settings")
        frame = page.evaluate("window.bokehfitViewer.readImage()")
        saved = png_text_chunks(base64.b64decode(page.evaluate("window.bokehfitViewer.pngBase64()")))
        assert "--shape mask" in json.loads(saved["bokehfit"])["command_line"]
        assert "--mask stop.png" in json.loads(saved["bokehfit"])["command_line"]
        assert page.errors == []
    finally:
        page.close()
    assert frame["samples"] == 4
    shape = (frame["height"], frame["width"], 3)
    browser_image = np.asarray(frame["rgb"], dtype=np.float32).reshape(shape)
    lens = make_lens(make_aperture("mask", 30.0, mask=str(path)), fstop=1.4, focus_distance_m=cornell_box().default_focus_m)
    python_image = render("cornell", lens, make_settings(frame["width"], frame["height"], 4)).image
    same = (np.abs(browser_image - python_image).max(axis=-1) <= SAME_PIXEL_TOLERANCE).mean()
    assert same >= MIN_SAME_PIXEL_FRACTION, f"only {same:.0%} of the pixels agree with the Python renderer"
    before = np.asarray(circle["rgb"], dtype=np.float32).reshape(shape)
    assert (np.abs(browser_image - before).max(axis=-1) > SAME_PIXEL_TOLERANCE).mean() > 0.5, "the mask did not change the frame"


def test_matched_aperture_from_a_compare_result(browser, server, tmp_path):
    path = tmp_path / "result.json"
    path.write_text(json.dumps(compare_document(shape="ngon", blades=9, angle_deg=12.5, fstop=4.0)))
    page = open_page(browser, server, "mode=edit")
    try:
        restarts = page.evaluate("window.bokehfitViewer.restarts")
        page.set_input_files("#matched-file", str(path))
        page.wait_for_function(f"window.bokehfitViewer.restarts > {restarts}", timeout=PAGE_TIMEOUT_MS)
        state = page.evaluate("window.bokehfitViewer.state")
        assert (state["shape"], state["blades"], state["angle_deg"], state["fstop"]) == ("ngon", 9, 12.5, 4.0)
        assert page.input_value("#shape") == "ngon" and page.is_visible("#blades")
        assert "ngon(9) 12.5°, f/4" in page.text_content("#settings")
        assert "result.json" in page.text_content("#message")

        # Schema 2: the real-lens features set their sliders.
        features = dict(roundness=0.35, squeeze=1.25, rim=0.5, vignetting={"radius": 1.4, "shift": 0.9}, chromatic={"red": 0.02, "blue": -0.03})
        path.write_text(json.dumps({**compare_document(shape="ngon", blades=9, angle_deg=12.5, **features), "schema_version": 2}))
        restarts = page.evaluate("window.bokehfitViewer.restarts")
        page.set_input_files("#matched-file", str(path))
        page.wait_for_function(f"window.bokehfitViewer.restarts > {restarts}", timeout=PAGE_TIMEOUT_MS)
        state = page.evaluate("window.bokehfitViewer.state")
        assert (state["roundness"], state["squeeze"], state["rim"]) == (0.35, 1.25, 0.5)
        assert (state["vignetting"], state["vignetting_radius"], state["vignetting_shift"]) == (True, 1.4, 0.9)
        assert (state["chromatic_red"], state["chromatic_blue"]) == (0.02, -0.03)
        assert page.input_value("#roundness") == "0.35" and page.is_checked("#vignetting")
        assert "roundness 0.35" in page.text_content("#settings")

        bad = tmp_path / "bad.json"
        bad.write_text(json.dumps({"discs": []}))
        page.set_input_files("#matched-file", str(bad))
        page.wait_for_function("document.getElementById('message').classList.contains('error')")
        assert "aperture" in page.text_content("#message")
    finally:
        page.close()


def png_text_chunks(data: bytes) -> dict[str, str]:
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    chunks, at = {}, 8
    while at < len(data):
        (length,) = struct.unpack(">I", data[at : at + 4])
        kind = data[at + 4 : at + 8]
        body = data[at + 8 : at + 8 + length]
        (crc,) = struct.unpack(">I", data[at + 8 + length : at + 12 + length])
        assert zlib.crc32(kind + body) == crc, f"bad CRC in {kind!r}"
        if kind == b"tEXt":
            key, text = body.split(b"\0", 1)
            chunks[key.decode("latin-1")] = text.decode("latin-1")
        at += 12 + length
    return chunks


def test_save_png_keeps_the_settings(browser, server, tmp_path):
    page = open_page(browser, server, "mode=edit&max_spp=3&shape=star&angle=20&fstop=2")
    try:
        page.wait_for_function("window.bokehfitViewer.spp === 3", timeout=PAGE_TIMEOUT_MS)
        with page.expect_download() as download:
            page.click("#save-png")
        name = download.value.suggested_filename
        path = tmp_path / name
        download.value.save_as(path)
    finally:
        page.close()
    assert name == "bokehfit_cornell_star_20.0deg_f2.00_focus0.700m_3spp.png"
    data = path.read_bytes()
    record = json.loads(png_text_chunks(data)["bokehfit"])
    assert record["lens"]["shape"] == "star" and record["lens"]["angle_deg"] == 20.0 and record["spp"] == 3
    assert record["command_line"].startswith("bokehfit render --scene cornell --shape star")
    image = pixels(data)
    assert image.shape == (128, 128, 3) and image.var() > 0


def test_without_webgpu_the_page_says_how_to_render(browser, server):
    page = browser.new_page()
    try:
        page.add_init_script("delete Navigator.prototype.gpu;")
        page.goto(server.url)
        page.wait_for_function("document.body.dataset.ready === 'true'", timeout=PAGE_TIMEOUT_MS)
        assert page.evaluate("document.body.dataset.webgpu") == "none"
        assert page.is_visible("#no-webgpu") and not page.is_visible("#render")
        text = page.text_content("#no-webgpu")
        assert "no WebGPU" in text and "bokehfit render --scene cornell --out frame.png" in text
        assert page.is_visible("#topdown") and "sharp from" in page.text_content("#settings")
    finally:
        page.close()


def test_samples_per_second_at_512(browser, server):
    """Prints the path tracer's speed in the page at 512×512 (samples per pixel per second)."""
    page = browser.new_page()
    try:
        page.goto(f"{server.url}?size=512x512")
        page.wait_for_function("document.body.dataset.ready === 'true'", timeout=PAGE_TIMEOUT_MS)
        if page.evaluate("document.body.dataset.webgpu") != "ok":
            _need("headless chromium has no usable WebGPU here")
        wait_spp(page, 1)
        start, first = time.perf_counter(), spp(page)
        time.sleep(SPEED_SECONDS)
        elapsed, last = time.perf_counter() - start, spp(page)
        adapter = page.text_content("#adapter").strip("· ")
    finally:
        page.close()
    rate = (last - first) / elapsed
    print(f"viewer speed at 512x512 in headless chromium ({adapter}): {rate:.2f} spp/s, {rate * 512 * 512 / 1e6:.2f} M paths/s")
    assert last > first
