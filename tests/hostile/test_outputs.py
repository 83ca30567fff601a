"""Outputs: never over a file bokehfit did not write, and no temporary file left behind (issue 16)."""

from __future__ import annotations

import json
import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from bokehfit.errors import InputError
from bokehfit.output_marks import is_bokehfit_output
from bokehfit.output_paths import check_output_path
from bokehfit.outputs import (
    WRITE_PAUSE_ENV,
    write_atomic,
    write_bytes_atomic,
    write_json,
    write_kernel_image,
)

#: Longest wait for a subprocess to reach its write (interpreter start-up included).
START_TIMEOUT_S = 60.0

KERNEL = np.outer(np.hanning(9), np.hanning(7)) / np.outer(np.hanning(9), np.hanning(7)).sum()


def _write_own(path: Path) -> None:
    """An output of bokehfit's own at ``path``, by the writer for its type."""
    suffix = path.suffix
    if suffix in (".npy", ".png", ".exr"):
        write_kernel_image(path, KERNEL)
    elif suffix == ".json":
        write_json(path, {"schema_version": 1, "bokehfit_version": "test", "value": 1})
    elif suffix == ".html":
        write_bytes_atomic(path, b"<!DOCTYPE html><html><head><title>r</title></head><body>report</body></html>")
    else:
        raise AssertionError(suffix)


def _write_foreign(path: Path) -> None:
    """A file of the user's at ``path``, in the right format but not written by bokehfit."""
    suffix = path.suffix
    if suffix == ".npy":
        np.save(path, np.arange(6, dtype=np.float32))
    elif suffix == ".png":
        import cv2

        cv2.imwrite(str(path), np.full((3, 3), 7, np.uint8))
    elif suffix == ".exr":
        import OpenEXR

        with OpenEXR.File({"type": OpenEXR.scanlineimage}, {"Y": np.ones((2, 2), np.float32)}) as exr:
            exr.write(str(path))
    elif suffix == ".json":
        path.write_text('{"version": "mine", "note": "bokehfit must not touch this"}\n')
    else:
        path.write_text('<!DOCTYPE html><html><head><meta name="generator" content="my editor"></head></html>\n')


FORMATS = (".npy", ".png", ".exr", ".json", ".html")


@pytest.mark.parametrize("suffix", FORMATS)
def test_foreign_file_is_refused_and_kept(tmp_path, suffix):
    path = tmp_path / f"out{suffix}"
    _write_foreign(path)
    before = path.read_bytes()
    assert not is_bokehfit_output(path)
    with pytest.raises(InputError, match="not written by bokehfit"):
        check_output_path(path, FORMATS)
    with pytest.raises(InputError, match=r"out\%s.*move it away or choose another name" % suffix):
        _write_own(path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


@pytest.mark.parametrize("suffix", FORMATS)
def test_own_output_is_marked_and_replaced(tmp_path, suffix):
    path = tmp_path / f"out{suffix}"
    _write_own(path)
    assert is_bokehfit_output(path)
    assert check_output_path(path, FORMATS) == path
    path.touch()  # the second write must replace the file
    stamp = path.stat().st_mtime_ns
    time.sleep(0.01)
    _write_own(path)
    assert path.stat().st_mtime_ns != stamp
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


def test_marked_files_read_as_before(tmp_path):
    """The marks change nothing for readers: numpy, OpenCV, OpenEXR, json, an HTML page."""
    import cv2
    import OpenEXR

    for suffix in (".npy", ".png", ".exr", ".json", ".html"):
        _write_own(tmp_path / f"k{suffix}")
    np.testing.assert_array_equal(np.load(tmp_path / "k.npy"), KERNEL.astype(np.float32))
    assert np.load(tmp_path / "k.npy", mmap_mode="r").shape == KERNEL.shape
    png = cv2.imread(str(tmp_path / "k.png"), cv2.IMREAD_UNCHANGED)
    assert png.dtype == np.uint16 and png.max() == 65535
    with OpenEXR.File(str(tmp_path / "k.exr")) as exr:
        np.testing.assert_allclose(exr.channels()["Y"].pixels, KERNEL.astype(np.float32))
    assert json.loads((tmp_path / "k.json").read_text())["value"] == 1
    page = (tmp_path / "k.html").read_text()
    assert page.startswith("<!DOCTYPE html><html><head><meta name=\"generator\" content=\"bokehfit ")
    assert page.endswith("<body>report</body></html>")


def test_json_without_a_version_gets_the_mark_and_can_be_rewritten(tmp_path):
    path = tmp_path / "figures.json"
    write_json(path, {"rows": [1, 2]})
    write_json(path, {"rows": [3]})
    document = json.loads(path.read_text())
    assert document["rows"] == [3] and document["bokehfit_version"]


def test_a_file_of_another_type_is_never_replaced(tmp_path):
    photo = tmp_path / "holiday.jpg"
    photo.write_bytes(b"\xff\xd8\xff\xe0 a photo of the user's")
    with pytest.raises(InputError, match="holiday.jpg"):
        write_bytes_atomic(photo, b"\xff\xd8\xff\xd9")
    assert photo.read_bytes() == b"\xff\xd8\xff\xe0 a photo of the user's"


def test_failed_write_leaves_nothing_and_keeps_the_old_file(tmp_path):
    path = tmp_path / "k.npy"
    _write_own(path)
    before = path.read_bytes()

    def fail(tmp: Path) -> None:
        tmp.write_bytes(b"half a file")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        write_atomic(path, fail)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["k.npy"]


def _dead_pid() -> int:
    """The PID of a process that has finished (and been reaped)."""
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


def test_stale_temporaries_of_dead_processes_are_removed(tmp_path):
    dead = tmp_path / f".other.json.bokehfit-tmp-{_dead_pid()}-0123abcd.json"
    alive = tmp_path / f".other.json.bokehfit-tmp-{os.getpid()}-4567abcd.json"
    unrelated = tmp_path / ".other.json.tmp-99999999-notours"
    for path in (dead, alive, unrelated):
        path.write_text("{")
    write_json(tmp_path / "result.json", {"bokehfit_version": "test"})
    assert not dead.exists(), "a temporary file of a process that no longer runs must be removed"
    assert alive.exists() and unrelated.exists(), "only stale temporary files of bokehfit are removed"


def _kernel_command(out: Path) -> list[str]:
    return [sys.executable, "-m", "bokehfit", "kernel", "--size", "64", "--diameter-px", "12", "--out", str(out)]


def _start_paused_write(command: list[str], folder: Path) -> tuple[subprocess.Popen, Path]:
    """Start ``command`` with the write pause on; return it and its temporary file once that exists."""
    env = dict(os.environ, **{WRITE_PAUSE_ENV: "60"})
    process = subprocess.Popen(command, cwd=folder, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline and process.poll() is None:
        temporaries = [p for p in folder.iterdir() if ".bokehfit-tmp-" in p.name]
        if temporaries:
            time.sleep(0.2)  # the writer is now pausing before its rename
            return process, temporaries[0]
        time.sleep(0.01)
    process.kill()
    _, stderr = process.communicate()
    raise AssertionError(f"no temporary file appeared (exit {process.returncode}): {stderr.decode()[-500:]}")


def test_sigkill_during_a_write_then_rerun_leaves_nothing(tmp_path):
    out = tmp_path / "k.npy"
    process, temporary = _start_paused_write(_kernel_command(out), tmp_path)
    process.send_signal(signal.SIGKILL)
    process.communicate(timeout=30)
    assert temporary.exists() and not out.exists(), "SIGKILL cannot be caught: the temporary file stays for now"
    rerun = subprocess.run(_kernel_command(out), cwd=tmp_path, capture_output=True, timeout=120)
    assert rerun.returncode == 0, rerun.stderr.decode()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["k.npy"], "the rerun removes the stale temporary file"
    assert np.load(out).shape == (64, 64)


def test_sigterm_during_a_write_removes_the_temporary_file(tmp_path):
    out = tmp_path / "k.npy"
    _write_own(out)
    before = out.read_bytes()
    process, temporary = _start_paused_write(_kernel_command(out), tmp_path)
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=30)
    assert process.returncode == 128 + signal.SIGTERM, stderr.decode()
    assert "Traceback" not in stderr.decode()
    assert not temporary.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["k.npy"]
    assert out.read_bytes() == before, "an interrupted write leaves the old file whole"


def test_write_pause_hook_rejects_bad_values(tmp_path, monkeypatch):
    monkeypatch.setenv(WRITE_PAUSE_ENV, "soon")
    with pytest.raises(InputError, match=WRITE_PAUSE_ENV):
        write_json(tmp_path / "r.json", {"bokehfit_version": "test"})
    assert list(tmp_path.iterdir()) == []


def test_parquet_mark_is_read_from_the_footer(tmp_path):
    """A survey's Parquet export is bokehfit's (its footer metadata says so); another program's is not."""
    import pyarrow
    import pyarrow.parquet

    table = pyarrow.table({"value": [1, 2, 3]})
    ours, theirs = tmp_path / "ours.parquet", tmp_path / "theirs.parquet"
    pyarrow.parquet.write_table(table.replace_schema_metadata({b"bokehfit_version": b"0"}), ours)
    pyarrow.parquet.write_table(table, theirs)
    assert is_bokehfit_output(ours) and not is_bokehfit_output(theirs)
    assert check_output_path(ours, (".parquet",)) == ours
    before = theirs.read_bytes()
    with pytest.raises(InputError, match="not written by bokehfit"):
        check_output_path(theirs, (".parquet",))
    assert theirs.read_bytes() == before
    # A file that only claims to be Parquet, with an absurd footer length, is not ours and is read no further.
    fake = tmp_path / "fake.parquet"
    fake.write_bytes(b"PAR1" + b"bokehfit_version" + struct.pack("<i", 2**31 - 1) + b"PAR1")
    assert not is_bokehfit_output(fake)
