"""``bokehfit discs`` end to end: a synthetic JPEG in, the table, JSON and overlay out."""

from __future__ import annotations

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest
from photo_factory import file_state

from bokehfit.apertures import make_aperture
from bokehfit.synthetic import SyntheticDisc, encode_srgb8, render_discs

TRUTH = [
    SyntheticDisc((80.3, 90.6), 60, make_aperture("hexagon", 12)),
    SyntheticDisc((230.8, 80.2), 40, make_aperture("circle")),
    SyntheticDisc((330.1, 170.4), 30, make_aperture("star", 40)),
    SyntheticDisc((120.5, 200.5), 50, make_aperture("pentagon"), brightness=2.5),  # saturated in the JPEG
]


@pytest.fixture(scope="module")
def photo(tmp_path_factory):
    folder = tmp_path_factory.mktemp("discs")
    linear = render_discs(400, 260, TRUTH, background=0.03, noise_sigma=0.002, seed=4)
    rgb = np.repeat(encode_srgb8(linear)[..., None], 3, axis=2)
    path = folder / "bokeh.jpg"
    path.write_bytes(cv2.imencode(".jpg", rgb, [cv2.IMWRITE_JPEG_QUALITY, 92])[1].tobytes())
    return path


def bokehfit(*args, cwd):
    return subprocess.run([sys.executable, "-m", "bokehfit", *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def test_table_json_and_overlay(photo, tmp_path):
    before = file_state(photo)
    done = bokehfit("discs", str(photo), "--json", "d.json", "--overlay", "d.png", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "4 discs" in done.stdout and "saturated" in done.stdout
    data = json.loads((tmp_path / "d.json").read_text())
    assert data["schema_version"] == 1 and data["bokehfit_version"] and data["command_line"].startswith("bokehfit discs")
    assert data["input"]["width"] == 400 and data["input"]["height"] == 260 and data["input"]["raw"] is False
    assert {"path", "exif", "linearisation"} <= set(data["input"])
    discs = data["discs"]
    assert len(discs) == len(TRUTH)
    for disc in discs:
        assert {"center_xy", "diameter_px", "angle_deg", "iou", "hausdorff_rel", "saturated", "clipped", "usable",
                "outline_xy", "plateau"} <= set(disc)
        assert len(disc["outline_xy"]) >= 8
    for truth in TRUTH:
        nearest = min(discs, key=lambda d: np.hypot(*np.subtract(d["center_xy"], truth.center_xy)))
        assert np.hypot(*np.subtract(nearest["center_xy"], truth.center_xy)) < 1.0
        assert abs(nearest["diameter_px"] - truth.diameter_px) < 0.06 * truth.diameter_px
        assert nearest["saturated"] == (truth.brightness > 1)
    # Every candidate measured and rejected is listed with its place and reason; the counts are theirs (and those
    # of candidates past the limits, counted only).
    detection = data["detection"]
    listed = {}
    for rejection in detection["rejections"]:
        assert len(rejection["center_xy"]) == 2 and rejection["diameter_px"] > 0
        listed[rejection["rejected_because"]] = listed.get(rejection["rejected_because"], 0) + 1
    assert listed and listed == {k: n for k, n in detection["rejected"].items() if "beyond the" not in k}
    assert "not discs: " in done.stdout and "detection.rejections" in done.stdout  # counted by reason on the terminal
    overlay = cv2.imread(str(tmp_path / "d.png"))
    assert overlay.shape == (260, 400, 3)
    assert (np.abs(overlay.astype(int) - overlay[..., ::-1].astype(int)).sum(axis=2) > 60).sum() > 200  # coloured outlines
    assert file_state(photo) == before


def test_no_discs_exits_1(tmp_path):
    path = tmp_path / "flat.png"
    cv2.imwrite(str(path), np.full((64, 64, 3), 40, np.uint8))
    done = bokehfit("discs", str(path), cwd=tmp_path)
    assert done.returncode == 1
    assert "no bokeh disc found" in done.stderr and len(done.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(
    "content,needle",
    [(None, "does not exist"), (b"", "empty"), (b"not an image at all", "")],
    ids=["missing", "empty", "text"],
)
def test_bad_input_exits_2_on_one_line(tmp_path, content, needle):
    path = tmp_path / "photo.jpg"
    if content is not None:
        path.write_bytes(content)
    done = bokehfit("discs", str(path), "--json", "out.json", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "Traceback" not in done.stderr
    assert needle in done.stderr
    assert not (tmp_path / "out.json").exists()


def test_refuses_to_overwrite_the_input(photo, tmp_path):
    before = file_state(photo)
    done = bokehfit("discs", str(photo), "--overlay", str(photo.with_suffix(".png")), cwd=tmp_path)
    assert done.returncode == 0
    copy = tmp_path / "in.png"
    copy.write_bytes(photo.with_suffix(".png").read_bytes())
    done = bokehfit("discs", str(copy), "--overlay", str(copy), cwd=tmp_path)
    assert done.returncode == 2 and "overwrite the input" in done.stderr
    assert file_state(photo) == before
