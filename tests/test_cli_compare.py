"""``bokehfit compare`` end to end on the default photo, and its failures.

``examples/hexagon_85mm_f2.jpg`` is rendered by ``examples/make_default_photo.py``
with a known answer: a hexagon turned by 15°, 85 mm at f/2 (equal-area), focused
at 3 m, lights at infinity, a 36 mm wide sensor (all in its EXIF). Each run is
a fresh ``python -m bokehfit`` process in a folder of its own, with a private,
empty ``TMPDIR`` (and no ``XDG_RUNTIME_DIR``, as on a server), so that
anything left behind shows.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
import os
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import cv2
import numpy as np
import pytest
from photo_factory import file_state

import bokehfit
from bokehfit.apertures import make_aperture
from bokehfit.synthetic import SyntheticDisc, encode_srgb8, render_discs

PHOTO = Path(__file__).resolve().parents[1] / "examples" / "hexagon_85mm_f2.jpg"
#: The default photo's truth (examples/make_default_photo.py).
FSTOP, ANGLE_DEG, FOCAL_LENGTH_MM, FOCUS_DISTANCE_MM = 2.0, 15.0, 85.0, 3000.0
#: Circumradius of the unit-area hexagon (design.md §3).
HEXAGON_R = 0.6204032
FSTOP_TOL_REL = 0.03
ANGLE_TOL_DEG = 0.5
#: The f-stops in the JSON are rounded to 3 decimals.
ROUNDING_REL = 1e-3


def bokehfit_cli(*args, cwd: Path):
    """Run ``python -m bokehfit ARGS`` in ``cwd`` with a private TMPDIR: (CompletedProcess, TMPDIR)."""
    tmpdir = cwd / ".tmpdir"
    tmpdir.mkdir(exist_ok=True)
    env = {k: v for k, v in os.environ.items() if k != "XDG_RUNTIME_DIR"}
    env["TMPDIR"] = str(tmpdir)
    done = subprocess.run(
        [sys.executable, "-m", "bokehfit", *map(str, args)], cwd=cwd, env=env, capture_output=True, text=True, timeout=600
    )
    return done, tmpdir


def listing(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def written(folder: Path) -> set[str]:
    """What a run left in its folder, its private TMPDIR aside."""
    return {name for name in listing(folder) if name.split(os.sep)[0] != ".tmpdir"}


def one_line(text: str) -> str:
    lines = text.strip().splitlines()
    assert len(lines) == 1, text
    return lines[0]


def strict_json(path: Path) -> dict:
    """The JSON file, refusing NaN and Infinity (not JSON)."""
    def refuse(name):
        raise AssertionError(f"{path.name} holds {name}")

    return json.loads(path.read_text(encoding="utf-8"), parse_constant=refuse)


@pytest.fixture(scope="module")
def runs(tmp_path_factory, gpu):
    """Runs of ``compare`` on the default photo, once each, by their extra arguments."""
    cache = {}

    def run(*extra):
        if extra not in cache:
            folder = tmp_path_factory.mktemp("compare")
            before, examples = file_state(PHOTO), listing(PHOTO.parent)
            done, tmpdir = bokehfit_cli("compare", PHOTO, "--json", "out.json", *extra, cwd=folder)
            cache[extra] = {
                "done": done,
                "folder": folder,
                "tmpdir": tmpdir,
                "photo_unchanged": file_state(PHOTO) == before,
                "examples_unchanged": listing(PHOTO.parent) == examples,
            }
        return cache[extra]

    return run


@pytest.fixture(scope="module")
def default(runs):
    result = runs()
    assert result["done"].returncode == 0, result["done"].stderr
    return result


@pytest.fixture(scope="module")
def document(default):
    return strict_json(default["folder"] / "out.json")


# --------------------------------------------------------------------------------------
# The default photo
# --------------------------------------------------------------------------------------


def test_exit_0_and_summary_names_hexagon(default):
    out = default["done"].stdout
    aperture_line = next(line for line in out.splitlines() if line.startswith("aperture:"))
    assert "hexagon" in aperture_line
    assert "f-stop: at most f/" in out  # no --light-distance-m: the value for lights at infinity is a bound
    assert "wrote out.json" in out and "wrote out.html" in out
    assert out.splitlines()[0].startswith("Sure: hexagon"), "the verdict comes first"


def test_json_follows_design_section_7(document):
    assert {"schema_version", "bokehfit_version", "command_line", "input", "aperture", "discs", "metrics",
            "timing_s", "device", "status", "reason"} <= set(document)
    assert document["schema_version"] == 2
    assert document["status"] == "fitted" and document["reason"] is None
    assert document["bokehfit_version"] == bokehfit.__version__
    assert document["command_line"].startswith("bokehfit compare ") and "--json out.json" in document["command_line"]

    source = document["input"]
    assert {"path", "width", "height", "raw", "exif", "linearisation"} <= set(source)
    assert Path(source["path"]).name == PHOTO.name
    assert (source["width"], source["height"]) == (1600, 1067)
    assert source["raw"] is False
    assert isinstance(source["exif"], dict) and source["exif"]["focal_length_mm"] == FOCAL_LENGTH_MM
    assert isinstance(source["linearisation"], str) and source["linearisation"]

    aperture = document["aperture"]
    assert {"shape", "blades", "angle_deg", "symmetry_deg", "angle_uncertainty_deg", "diameter_px", "fstop",
            "fstop_uncertainty", "focus_side", "candidates"} <= set(aperture)
    assert aperture["shape"] == "hexagon" and aperture["blades"] == 6 and aperture["symmetry_deg"] == 60
    assert 0 <= aperture["angle_deg"] < aperture["symmetry_deg"]
    assert aperture["angle_uncertainty_deg"] >= 0 and aperture["fstop_uncertainty"] >= 0
    assert aperture["diameter_px"] > 0
    assert aperture["focus_side"] == "unknown"
    candidates = aperture["candidates"]
    assert len(candidates) >= 2
    for candidate in candidates:
        assert {"shape", "blades", "angle_deg", "score"} <= set(candidate)
    assert candidates[0]["shape"] == "hexagon" and candidates[0]["blades"] == 6
    scores = [c["score"] for c in candidates]
    assert scores == sorted(scores, reverse=True), "candidates must come best first"

    discs = document["discs"]
    assert len(discs) >= 20
    for disc in discs:
        assert {"center_xy", "diameter_px", "angle_deg", "iou", "hausdorff_rel", "saturated", "clipped", "used"} <= set(disc)
        assert len(disc["center_xy"]) == 2
        assert all(isinstance(v, (int, float)) for v in disc["center_xy"])
        assert 0 <= disc["center_xy"][0] < 1600 and 0 <= disc["center_xy"][1] < 1067
        assert isinstance(disc["used"], bool) and isinstance(disc["saturated"], bool) and isinstance(disc["clipped"], bool)
        if disc["used"]:
            assert not (disc["saturated"] or disc["clipped"]), disc["index"]
            assert 0 <= disc["angle_deg"] < 60
            assert 0 < disc["iou"] <= 1 and disc["hausdorff_rel"] >= 0
    assert any(d["used"] for d in discs)
    assert any(d["saturated"] for d in discs), "the photo has two saturated discs"
    assert any(d["clipped"] for d in discs), "the photo has a disc cut by the frame"

    metrics = document["metrics"]
    assert {"iou", "hausdorff_rel", "efd_distance", "hu_distance"} <= set(metrics)
    assert all(isinstance(v, float) for v in metrics.values())
    assert metrics["iou"] > 0.95

    timing = document["timing_s"]
    assert {"load", "detect", "fit", "render", "total"} <= set(timing)
    assert all(v >= 0 for v in timing.values())
    assert timing["total"] >= timing["load"] + timing["fit"] + timing["render"]

    # The matched kernel is drawn by the cheapest method, a GPU's start-up included:
    # for these discs, exact on the CPU, and the JSON says so.
    kernel, device = document["kernel"], document["device"]
    assert kernel["method"] == "exact" and kernel["samples"] is None
    assert device == {"adapter": None, "backend": None}


def test_fstop_and_angle_match_the_default_photo(document):
    aperture = document["aperture"]
    assert aperture["lens_model"] == "thin" and aperture["size_convention"] == "equal-area"
    assert document["geometry"]["light_distance_m"] is None  # infinity, the default
    assert aperture["fstop"] == pytest.approx(FSTOP, rel=FSTOP_TOL_REL)
    assert abs(aperture["angle_deg"] - ANGLE_DEG) < ANGLE_TOL_DEG


def test_pinhole_lens_model_scales_the_fstop(runs, document):
    """The same disc read with the pinhole CoC (design.md §4): N_pinhole = N_thin · (1 − f/d_f)."""
    result = runs("--lens-model", "pinhole", "--no-html")
    assert result["done"].returncode == 0, result["done"].stderr
    pinhole = strict_json(result["folder"] / "out.json")["aperture"]
    assert pinhole["lens_model"] == "pinhole"
    factor = 1 - FOCAL_LENGTH_MM / FOCUS_DISTANCE_MM  # 0.971667
    assert pinhole["fstop"] == pytest.approx(document["aperture"]["fstop"] * factor, rel=ROUNDING_REL)
    assert pinhole["fstop"] == pytest.approx(FSTOP * factor, rel=FSTOP_TOL_REL)


def test_circumscribed_convention_divides_by_r_sqrt_pi(runs, document):
    result = runs("--size-convention", "circumscribed", "--no-html")
    assert result["done"].returncode == 0, result["done"].stderr
    circumscribed = strict_json(result["folder"] / "out.json")["aperture"]
    assert circumscribed["size_convention"] == "circumscribed"
    expected = document["aperture"]["fstop"] / (HEXAGON_R * math.sqrt(math.pi))  # f/2 → f/1.819
    assert circumscribed["fstop"] == pytest.approx(expected, rel=ROUNDING_REL)


def test_no_html_writes_no_html(runs):
    result = runs("--lens-model", "pinhole", "--no-html")
    assert result["done"].returncode == 0, result["done"].stderr
    assert ".html" not in result["done"].stdout
    assert not list(result["folder"].rglob("*.html"))


class _Page(HTMLParser):
    """Checks that tags balance and collects the images."""

    VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr"}

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.open: list[str] = []
        self.errors: list[str] = []
        self.images: list[str] = []
        self.text: list[str] = []

    def handle_starttag(self, tag, attrs):
        if tag == "img":
            self.images.append(dict(attrs).get("src") or "")
        if tag not in self.VOID:
            self.open.append(tag)

    def handle_startendtag(self, tag, attrs):
        if tag == "img":
            self.images.append(dict(attrs).get("src") or "")

    def handle_endtag(self, tag):
        if tag in self.VOID:
            return
        if not self.open or self.open[-1] != tag:
            self.errors.append(f"</{tag}> closes {self.open[-1] if self.open else 'nothing'} at {self.getpos()}")
            return
        self.open.pop()

    def handle_data(self, data):
        self.text.append(data)


def test_report_html_parses_and_shows_images(default):
    path = default["folder"] / "out.html"
    assert path.is_file()
    page = _Page()
    page.feed(path.read_text(encoding="utf-8"))
    page.close()
    assert not page.errors, page.errors[:5]
    assert page.open == [], f"unclosed tags: {page.open}"
    assert "hexagon" in " ".join(page.text)
    assert len(page.images) >= 2
    for src in page.images:
        match = re.fullmatch(r"data:image/(png|jpeg);base64,([A-Za-z0-9+/=\s]+)", src)
        assert match, src[:60]
        try:
            data = base64.b64decode(match.group(2), validate=True)
        except binascii.Error as error:
            pytest.fail(f"bad base64 in {src[:40]}: {error}")
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        assert image is not None and image.size > 0 and min(image.shape[:2]) > 0


def test_input_photo_unchanged_and_nothing_left_beside_it(runs, default):
    for result in (default, runs("--lens-model", "pinhole", "--no-html")):
        assert result["photo_unchanged"]
        assert result["examples_unchanged"]


def test_only_the_requested_files_are_written(default):
    assert written(default["folder"]) == {"out.json", "out.html"}
    assert "Traceback" not in default["done"].stderr and "warning" not in default["done"].stderr


def test_no_temporary_files_left(default):
    # Only the one private runtime folder that every bokehfit process reuses (see use_headless_egl).
    assert listing(default["tmpdir"]) <= {f"bokehfit-runtime-{os.getuid()}"}


# --------------------------------------------------------------------------------------
# Failures: exit 1 for no result, 2 for bad input, always one line
# --------------------------------------------------------------------------------------


def write_jpeg(path: Path, discs, width=200, height=120):
    linear = render_discs(width, height, discs, background=0.03, noise_sigma=0.002, seed=4)
    path.write_bytes(cv2.imencode(".jpg", encode_srgb8(linear), [cv2.IMWRITE_JPEG_QUALITY, 92])[1].tobytes())
    return path


def test_flat_image_exits_1_on_one_line(tmp_path):
    path = tmp_path / "flat.png"
    cv2.imwrite(str(path), np.full((64, 64, 3), 40, np.uint8))
    done, tmpdir = bokehfit_cli("compare", path, "--json", "out.json", cwd=tmp_path)
    assert done.returncode == 1, done.stderr
    assert "no bokeh disc found" in one_line(done.stderr)
    assert written(tmp_path) == {"flat.png", "out.json", "out.html"}
    document = strict_json(tmp_path / "out.json")
    assert document["schema_version"] == 2 and document["status"] == "no_discs"
    assert document["reason"].startswith("no bokeh disc found") and document["aperture"]["shape"] is None


def test_saturated_discs_are_used_by_their_outlines(tmp_path):
    """Clipped plateaus do not hide the shape: both discs are used, their clipped pixels as lower bounds,
    and two discs are too few for a sure answer."""
    hexagon = make_aperture("hexagon", 10)
    path = write_jpeg(tmp_path / "sat.jpg", [SyntheticDisc((60, 60), 50, hexagon, brightness=2.5),
                                             SyntheticDisc((150, 60), 40, hexagon, brightness=3.0)])
    done, _ = bokehfit_cli("compare", path, "--no-html", "--json", tmp_path / "out.json", cwd=tmp_path)
    document = json.loads((tmp_path / "out.json").read_text())
    assert document["status"] == "unsure", document["reason"]
    assert "only 2 discs" in document["reason"]
    assert document["aperture"]["shape"] == "hexagon"
    used = [d for d in document["discs"] if d["used"]]
    assert len(used) == 2 and all(d["saturated"] and "saturated" in d["used_as"] for d in used)


def test_missing_file_exits_2_on_one_line(tmp_path):
    done, _ = bokehfit_cli("compare", tmp_path / "nothing.jpg", cwd=tmp_path)
    assert done.returncode == 2
    assert "nothing.jpg" in one_line(done.stderr)


def test_text_file_exits_2_on_one_line(tmp_path):
    path = tmp_path / "notes.jpg"
    path.write_text("not an image at all\n")
    done, _ = bokehfit_cli("compare", path, cwd=tmp_path)
    assert done.returncode == 2
    one_line(done.stderr)
    assert "Traceback" not in done.stderr


def test_json_over_the_input_photo_exits_2_and_leaves_it(tmp_path):
    before = file_state(PHOTO)
    done, _ = bokehfit_cli("compare", PHOTO, "--json", PHOTO, cwd=tmp_path)
    assert done.returncode == 2
    one_line(done.stderr)
    assert file_state(PHOTO) == before


def test_json_naming_the_input_exits_2_and_leaves_it(tmp_path):
    """A JPEG named ``.json`` passes the suffix check: the overwrite guard must stop it."""
    photo = tmp_path / "photo.json"
    shutil.copyfile(PHOTO, photo)
    before = file_state(photo)
    done, _ = bokehfit_cli("compare", photo, "--json", "photo.json", cwd=tmp_path)
    assert done.returncode == 2
    assert "overwrite the input" in one_line(done.stderr)
    assert file_state(photo) == before
    assert written(tmp_path) == {"photo.json"}


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--shapes", "hexagon,hexgon"], "hexgon"),
        (["--lens-model", "fisheye"], "lens-model"),
        (["--light-distance-m", "-3"], "light-distance-m"),
    ],
    ids=["unknown-shape", "unknown-lens-model", "negative-light-distance"],
)
def test_usage_errors_exit_2_on_one_line(tmp_path, args, needle):
    done, _ = bokehfit_cli("compare", PHOTO, "--no-html", *args, cwd=tmp_path)
    assert done.returncode == 2, done.stdout + done.stderr
    assert needle in one_line(done.stderr)


def test_reader_that_leaves_early_loses_no_file(tmp_path):
    """``bokehfit compare photo --out-dir D | head -1``: the reader closes the pipe after the summary's first
    line, and the run still writes its JSON and its report and ends with its own exit code."""
    env = {k: v for k, v in os.environ.items() if k != "XDG_RUNTIME_DIR"}
    run = subprocess.Popen([sys.executable, "-m", "bokehfit", "compare", str(PHOTO), "--out-dir", "out"],
                           cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = run.stdout.readline()
    run.stdout.close()  # the reader leaves, as head -1 does
    try:
        _, stderr = run.communicate(timeout=600)
    finally:
        run.kill()
    assert first.decode().startswith("Sure: hexagon"), first
    assert run.returncode == 0, stderr.decode()
    assert stderr.decode().strip() == ""
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["hexagon_85mm_f2.html", "hexagon_85mm_f2.json"]
    assert strict_json(tmp_path / "out" / "hexagon_85mm_f2.json")["status"] == "fitted"
    assert (tmp_path / "out" / "hexagon_85mm_f2.html").read_text(encoding="utf-8").rstrip().endswith("</html>")


def test_console_guard_sends_the_rest_to_the_null_device():
    """:class:`ReaderMayLeave` on a pipe whose reader has gone: the write goes on, to the null device."""
    from bokehfit.cli.console import ReaderMayLeave

    read_end, write_end = os.pipe()
    os.close(read_end)
    with open(write_end, "w", buffering=1, encoding="utf-8") as stream:
        guard = ReaderMayLeave(stream)
        assert guard.write("a line\n") == len("a line\n")
        guard.flush()
        assert guard.reader_left
        assert os.path.samestat(os.fstat(stream.fileno()), os.stat(os.devnull))
