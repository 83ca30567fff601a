"""``bokehfit kernel`` through the installed command: files, messages, exit codes."""

from __future__ import annotations

import subprocess
import sys

import cv2
import numpy as np
import OpenEXR
import pytest

from bokehfit.apertures import make_aperture
from bokehfit.kernels import render_kernel


def bokehfit(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "bokehfit", *args], cwd=cwd, capture_output=True, text=True, timeout=300
    )


def test_writes_npy_png_exr(tmp_path):
    common = ["kernel", "--shape", "star", "--angle", "12", "--diameter-px", "30", "--size", "48"]
    for suffix in ("npy", "png", "exr"):
        done = bokehfit(*common, "--out", f"k.{suffix}", cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        assert "method exact" in done.stdout and "ms" in done.stdout
    expected = render_kernel(make_aperture("star", 12.0), 30.0, 48)
    np.testing.assert_array_equal(np.load(tmp_path / "k.npy"), expected)
    png = cv2.imread(str(tmp_path / "k.png"), cv2.IMREAD_UNCHANGED)
    assert png.dtype == np.uint16 and png.max() == 65535
    np.testing.assert_allclose(png / 65535.0, expected / expected.max(), atol=1 / 65535)
    with OpenEXR.File(str(tmp_path / "k.exr")) as exr:
        np.testing.assert_array_equal(exr.channels()["Y"].pixels, expected)
    assert not list(tmp_path.glob(".k.*")), "temporary files left behind"


def test_mc_prints_adapter(tmp_path, gpu):
    done = bokehfit("kernel", "--method", "mc", "--samples", "10000", "--out", "k.npy", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert gpu.adapter_name in done.stdout and "10000 samples" in done.stdout


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--shape", "hexgon"], "--shape"),
        (["--diameter-px", "nan"], "--diameter-px"),
        (["--size", "0"], "size"),
        (["--shape", "ngon"], "blades"),
        (["--aspect", "2"], "aspect"),
        (["--roundness", "1.5"], "argument --roundness: must be a finite number in [0, 1]"),
        (["--roundness", "0.3", "--shape", "star"], "roundness applies only to n-gons"),
        (["--squeeze", "-1"], "argument --squeeze: must be"),
        (["--vignetting", "0.5,0"], "argument --vignetting: must be"),
        (["--vignetting", "1.2"], "argument --vignetting: must be RADIUS,SHIFT"),
        (["--vignetting", "1.2,0", "--field-position", "20,0"], "argument --field-position: must be"),
        (["--field-position", "0.5,0.5"], "--field-position applies only with --vignetting"),
        (["--rim", "1.01"], "argument --rim: must be a finite number in [-1, 1]"),
        (["--chromatic", "0.1"], "argument --chromatic: must be RED,BLUE"),
        (["--chromatic", "0.1,0.9"], "argument --chromatic: must be"),
    ],
)
def test_bad_input_one_line_exit_2(tmp_path, args, needle):
    done = bokehfit("kernel", *args, "--out", "k.npy", cwd=tmp_path)
    assert done.returncode == 2
    assert needle in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "k.npy").exists()


def test_bad_output_path_exit_2(tmp_path):
    for out in ("k.jpg", "missing/k.npy"):
        done = bokehfit("kernel", "--out", out, cwd=tmp_path)
        assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_clipped_kernel_warns_on_one_line(tmp_path):
    done = bokehfit("kernel", "--diameter-px", "100", "--size", "32", "--out", "k.npy", cwd=tmp_path)
    assert done.returncode == 0
    assert "warning: kernel clipped" in done.stderr and "Traceback" not in done.stderr


def test_ngon_n_spelling_as_in_compare_shapes(tmp_path):
    done = bokehfit("kernel", "--shape", "ngon(9)", "--diameter-px", "20", "--size", "32", "--out", "k.npy", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "ngon(9)" in done.stdout
    np.testing.assert_array_equal(np.load(tmp_path / "k.npy"), render_kernel(make_aperture("ngon", blades=9), 20.0, 32))



def test_feature_flags_match_the_api(tmp_path):
    from bokehfit.apertures import Vignetting

    common = ["kernel", "--diameter-px", "20", "--size", "32", "--out", "k.npy"]
    cases = [
        (["--shape", "ngon(9)", "--roundness", "0.5"], make_aperture("ngon", blades=9, roundness=0.5), {}),
        (["--squeeze", "1.5", "--angle", "10"], make_aperture("hexagon", 10.0, squeeze=1.5), {}),
        (["--rim", "-0.4", "--side", "near"], make_aperture("hexagon", rim=-0.4), dict(side="near")),
        (["--vignetting", "1.1,0.9", "--field-position", "0.7,-0.2"],
         make_aperture("hexagon", vignetting=Vignetting(1.1, 0.9)), dict(field_position=(0.7, -0.2))),
    ]
    for flags, aperture, params in cases:
        done = bokehfit(*common, *flags, cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        np.testing.assert_array_equal(np.load(tmp_path / "k.npy"), render_kernel(aperture, diameter_px=20.0, size=32, **params))
    assert "% of the light passes" in done.stdout


def test_chromatic_writes_rgb_npy_png_exr(tmp_path):
    from bokehfit.apertures import Chromatic

    common = ["kernel", "--diameter-px", "20", "--size", "32", "--chromatic", "0.08,-0.06"]
    for suffix in ("npy", "png", "exr"):
        done = bokehfit(*common, "--out", f"k.{suffix}", cwd=tmp_path)
        assert done.returncode == 0, done.stderr
    expected = render_kernel(make_aperture("hexagon", chromatic=Chromatic(0.08, -0.06)), diameter_px=20.0, size=32)
    assert expected.shape == (32, 32, 3)
    np.testing.assert_array_equal(np.load(tmp_path / "k.npy"), expected)
    png = cv2.imread(str(tmp_path / "k.png"), cv2.IMREAD_UNCHANGED)[..., ::-1]  # OpenCV reads BGR
    assert png.dtype == np.uint16 and png.shape == (32, 32, 3) and png.max() == 65535
    np.testing.assert_allclose(png / 65535.0, expected / expected.max(), atol=1 / 65535)
    with OpenEXR.File(str(tmp_path / "k.exr")) as exr:
        rgb = exr.channels()["RGB"].pixels  # OpenEXR groups R, G, B into one (H, W, 3) channel
        np.testing.assert_array_equal(rgb, expected)
