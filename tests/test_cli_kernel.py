"""``bokehfit kernel`` through the installed command: files, messages, exit codes."""

from __future__ import annotations

import subprocess
import sys

import cv2
import numpy as np
import OpenEXR
import pytest

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
    expected = render_kernel("star", 12.0, 30.0, 48)
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
        (["--diameter-px", "nan"], "diameter_px"),
        (["--size", "0"], "size"),
        (["--shape", "ngon"], "blades"),
        (["--aspect", "2"], "aspect"),
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
