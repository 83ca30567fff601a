"""Files that are not files, crafted sizes, the survey's inputs, odd names, absurd numbers, leftovers (issue 25).

Each test names the class of hostile input it covers. Hangs are judged in a subprocess
with a generous wall-clock limit (:data:`HANG_S`: the command under test takes about a
second, and two shared cores can make that ten; a hang never ends), or by CPU time where
the work is in this process.
"""

from __future__ import annotations

import math
import os
import socket
import sqlite3
import struct
import subprocess
import sys
import threading
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
from hostile.corpus import survey_database
from photo_factory import exif_for, write_jpeg, write_png

import bokehfit
from bokehfit.errors import InputError

#: Wall-clock limit of a command that must not hang (seconds); it takes about a second when fixed.
HANG_S = 90.0
#: CPU seconds a crafted file may cost to load (the bounded reader takes well under one).
LOAD_CPU_S = 20.0

needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="FIFOs are POSIX")


def _run(*args, env=None, cwd=None, timeout=HANG_S):
    """``python -m bokehfit ARGS``: (exit code, stdout, stderr); a hang fails the test at ``timeout``."""
    environment = dict(os.environ, PYTHONPATH=str(Path(bokehfit.__file__).resolve().parents[1]), **(env or {}))
    environment.pop("BOKEHFIT_DEBUG", None)
    try:
        done = subprocess.run([sys.executable, "-m", "bokehfit", *map(os.fsdecode, args)], capture_output=True,
                              timeout=timeout, env=environment, cwd=cwd)
    except subprocess.TimeoutExpired:
        pytest.fail(f"bokehfit {' '.join(map(os.fsdecode, args))} still running after {timeout:g} s (a hang)")
    return done.returncode, done.stdout.decode("utf-8", "replace"), done.stderr.decode("utf-8", "replace")


def _one_error_line(stderr: str, *words: str) -> None:
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("bokehfit: error: "), stderr
    for word in words:
        assert word in lines[0], lines[0]


def _disc_rgb(height=240, width=320):
    import cv2

    image = np.full((height, width), 0.03, np.float32)
    for x, y in ((70, 70), (180, 80), (260, 170), (90, 180)):
        cv2.circle(image, (x * 16, y * 16), 22 * 16, 0.9, -1, lineType=cv2.LINE_AA, shift=4)
    codes = (np.clip(image, 0, 1) ** (1 / 2.2) * 255).astype(np.uint8)
    return np.repeat(codes[..., None], 3, axis=2)


# --------------------------------------------------------------------------------------
# Files that are not regular files
# --------------------------------------------------------------------------------------


@needs_fifo
@pytest.mark.parametrize("command", [
    ("kernel", "--size", "16", "--diameter-px", "5", "--out", "@FIFO.npy"),
    ("discs", "@PHOTO", "--json", "@FIFO.json"),
    ("compare", "@PHOTO", "--json", "@FIFO.json"),
])
def test_output_naming_an_existing_fifo_is_refused_without_opening_it(tmp_path, command):
    photo = write_png(tmp_path / "p.png", _disc_rgb())
    fifo = tmp_path / f"out{command[-1][5:]}"
    os.mkfifo(fifo)
    args = [str(fifo) if a.startswith("@FIFO") else str(photo) if a == "@PHOTO" else a for a in command]
    code, _, stderr = _run(*args)
    assert code == 2
    _one_error_line(stderr, "FIFO, not a regular file")


@needs_fifo
def test_is_bokehfit_output_does_not_wait_on_a_fifo(tmp_path):
    from bokehfit.output_marks import is_bokehfit_output

    os.mkfifo(tmp_path / "x.json")
    result = []
    thread = threading.Thread(target=lambda: result.append(is_bokehfit_output(tmp_path / "x.json")), daemon=True)
    thread.start()
    thread.join(HANG_S)
    assert result == [False], "is_bokehfit_output waited on a FIFO"


@needs_fifo
def test_survey_folder_with_a_fifo_a_link_to_dev_zero_and_a_link_loop(tmp_path):
    library = tmp_path / "lib"
    (library / "sub").mkdir(parents=True)
    os.mkfifo(library / "fifo.jpg")
    os.symlink("/dev/zero", library / "zero.jpg")
    os.symlink("..", library / "sub" / "loop")
    os.symlink("../..", library / "sub" / "loop2")
    for i, path in enumerate((library, f"{library}/**/*.jpg")):
        db = tmp_path / f"s{i}.duckdb"
        code, stdout, stderr = _run("survey", path, "--db", db)
        assert code == 0, stderr
        import duckdb

        with duckdb.connect(str(db), read_only=True) as connection:
            rows = dict(connection.execute("SELECT path, reason FROM photos WHERE status = 'unreadable'").fetchall())
        assert {Path(p).name for p in rows} == {"fifo.jpg", "zero.jpg"}, rows
        assert all("not a regular file" in reason for reason in rows.values()), rows


def test_glob_through_folder_link_loops_ends_and_finds_each_photo_once(tmp_path):
    """Two links back up the tree make glob.glob's walk exponential; the bounded walk visits each folder once."""
    library = tmp_path / "lib"
    (library / "a" / "b").mkdir(parents=True)
    for name in ("x.jpg", "a/y.jpg", "a/b/z.jpg", "a/.hidden.jpg"):
        (library / name).write_bytes(b"\xff\xd8")
    os.symlink("..", library / "a" / "b" / "up")
    os.symlink("../..", library / "a" / "b" / "top")
    code = ("from bokehfit.surveys.files import find_photos; import sys; "
            f"print(sorted(p.name for p in find_photos([{str(library / '**' / '*.jpg')!r}])))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=HANG_S,
                          env=dict(os.environ, PYTHONPATH=str(Path(bokehfit.__file__).resolve().parents[1])))
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "['x.jpg', 'y.jpg', 'z.jpg']"


@pytest.mark.parametrize("kind", ["fifo", "dev_zero", "too_large"])
def test_files_from_that_is_not_a_bounded_regular_file_is_refused(tmp_path, kind, monkeypatch):
    from bokehfit.surveys import files

    source = tmp_path / "list.txt"
    if kind == "fifo":
        if not hasattr(os, "mkfifo"):
            pytest.skip("FIFOs are POSIX")
        os.mkfifo(source)
        code, _, stderr = _run("survey", "--files-from", source, "--db", tmp_path / "s.duckdb")
        assert code == 2
        _one_error_line(stderr, "--files-from", "FIFO")
    elif kind == "dev_zero":
        if not os.path.exists("/dev/zero"):
            pytest.skip("no /dev/zero")
        code, _, stderr = _run("survey", "--files-from", "/dev/zero", "--db", tmp_path / "s.duckdb")
        assert code == 2
        _one_error_line(stderr, "--files-from", "character device")
    else:
        monkeypatch.setattr(files, "LIST_MAX_BYTES", 1000)
        source.write_text("a.jpg\n" * 1000)
        with pytest.raises(InputError, match="larger than"):
            files.read_file_list(source)
    assert not (tmp_path / "s.duckdb").exists()


@needs_fifo
def test_db_that_is_a_fifo_is_refused(tmp_path):
    os.mkfifo(tmp_path / "s.duckdb")
    photo = write_png(tmp_path / "p.png", _disc_rgb())
    code, _, stderr = _run("survey", photo, "--db", tmp_path / "s.duckdb")
    assert code == 2
    _one_error_line(stderr, "FIFO")


def test_content_hash_refuses_what_is_not_a_regular_file(tmp_path):
    from bokehfit.surveys.files import content_hash

    with pytest.raises(OSError, match="not a regular file"):
        content_hash(tmp_path)
    if os.path.exists("/dev/zero"):
        os.symlink("/dev/zero", tmp_path / "z.jpg")
        with pytest.raises(OSError, match="character device"):
            content_hash(tmp_path / "z.jpg")


# --------------------------------------------------------------------------------------
# Crafted sizes: work bounded per file, claimed size weighed against the bytes
# --------------------------------------------------------------------------------------


def _png_chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)


def test_png_with_ten_thousand_iccp_chunks_loads_in_bounded_time(tmp_path):
    import cv2

    from bokehfit.io import load_photo

    ok, encoded = cv2.imencode(".png", _disc_rgb(64, 64))
    png = encoded.tobytes()
    body = b"icc\x00\x00" + zlib.compress(bytes(4 << 20), 9)  # 4 kB that inflate to the 4 MiB cap
    path = tmp_path / "iccp.png"
    path.write_bytes(png[:33] + _png_chunk(b"iCCP", body) * 10_000 + png[33:])
    start = time.process_time()
    photo = load_photo(path)
    assert time.process_time() - start < LOAD_CPU_S
    assert any("9999 more ICC or XMP chunks" in note for note in photo.notes), photo.notes


def _jpeg_claiming(width: int, height: int) -> bytes:
    import cv2

    noise = (np.random.default_rng(0).random((256, 256, 3)) * 255).astype(np.uint8)
    data = bytearray(cv2.imencode(".jpg", noise)[1].tobytes())
    i = 2
    while data[i + 1] not in (0xC0, 0xC1, 0xC2):
        i += 2 + struct.unpack(">H", data[i + 2 : i + 4])[0]
    data[i + 5 : i + 9] = struct.pack(">HH", height, width)
    return bytes(data)


def test_small_jpeg_claiming_250_megapixels_is_refused_before_decoding(tmp_path):
    from bokehfit.io import load_photo

    path = tmp_path / "claim.jpg"
    path.write_bytes(_jpeg_claiming(15811, 15811))
    start = time.process_time()
    with pytest.raises(InputError, match="can't hold"):
        load_photo(path)
    assert time.process_time() - start < LOAD_CPU_S


def test_jpeg_bound_holds_for_the_flattest_real_encodings(tmp_path):
    """A flat black frame, the most compressible image, with optimised Huffman tables and progressive: still read."""
    from PIL import Image

    from bokehfit.io import load_photo

    for options in ({"optimize": True}, {"progressive": True, "optimize": True}):
        path = tmp_path / "flat.jpg"
        Image.fromarray(np.zeros((2000, 3000, 3), np.uint8)).save(path, quality=50, **options)
        assert load_photo(path).width == 3000


def test_png_whose_header_claims_more_than_its_data_can_hold_is_refused(tmp_path):
    from bokehfit.io import load_photo

    ihdr = struct.pack(">IIBBBBB", 15000, 15000, 8, 2, 0, 0, 0)
    idat = zlib.compress(bytes(200_000))
    path = tmp_path / "claim.png"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", ihdr) + _png_chunk(b"IDAT", idat) + _png_chunk(b"IEND", b""))
    with pytest.raises(InputError, match="can't hold"):
        load_photo(path)


def test_tiff_whose_header_claims_more_than_its_strips_can_hold_is_refused(tmp_path):
    import tifffile

    from bokehfit.io import load_photo

    path = tmp_path / "claim.tif"
    tifffile.imwrite(path, np.zeros((64, 64, 3), np.uint8), compression="zlib")
    data = bytearray(path.read_bytes())
    for tag in (256, 257):  # ImageWidth, ImageLength: 15000 each
        for kind, form in ((3, "<H"), (4, "<I")):
            at = data.find(struct.pack("<HHI", tag, kind, 1))
            if at >= 0:
                data[at + 8 : at + 8 + struct.calcsize(form)] = struct.pack(form, 15000)
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match="can't hold"):
        load_photo(path)
    tifffile.imwrite(tmp_path / "flat.tif", np.zeros((2000, 3000, 3), np.uint8), compression="zlib",
                     compressionargs={"level": 9}, rowsperstrip=2000)  # the best deflate does: still read
    assert load_photo(tmp_path / "flat.tif").width == 3000


def test_photo_file_larger_than_any_photo_is_refused_unread(tmp_path):
    """A sparse file of 5 GiB named .jpg: refused from its size, not read into memory."""
    from bokehfit.io import load_photo
    from bokehfit.io.photo import MAX_FILE_BYTES

    path = tmp_path / "sparse.jpg"
    with open(path, "wb") as file:
        file.write(b"\xff\xd8\xff\xe0")
        file.truncate(MAX_FILE_BYTES + 1)
    start = time.process_time()
    with pytest.raises(InputError, match="more than a photo"):
        load_photo(path)
    assert time.process_time() - start < LOAD_CPU_S


def test_overlay_of_a_16_by_100000_photo_is_not_resized_to_nothing():
    from bokehfit.report import draw_disc_overlay

    canvas = draw_disc_overlay(np.zeros((100_000, 16, 3), np.uint8), [], max_side=2048)
    assert canvas.shape[0] == 2048 and canvas.shape[1] >= 1


# --------------------------------------------------------------------------------------
# The survey's inputs: scheduler, database
# --------------------------------------------------------------------------------------


class _Server:
    """A TCP port on 127.0.0.1 that accepts and then stays silent or answers garbage."""

    def __init__(self, answer: bytes | None):
        self.socket = socket.create_server(("127.0.0.1", 0))
        self.port = self.socket.getsockname()[1]
        self.answer, self.connections = answer, []
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                connection, _ = self.socket.accept()
            except OSError:
                return
            self.connections.append(connection)
            if self.answer is not None:
                connection.sendall(self.answer)

    def close(self):
        for connection in self.connections:
            connection.close()
        self.socket.close()


@pytest.mark.parametrize("answer", [None, b"\xff" * 8 + b"garbage" * 100, b"HTTP/1.1 400 Bad Request\r\n\r\n"])
def test_scheduler_that_is_not_dask_is_refused_within_the_connect_timeout(answer):
    from bokehfit.surveys.scheduler import check_scheduler

    server = _Server(answer)
    try:
        start = time.monotonic()
        with pytest.raises(InputError, match="--scheduler"):
            check_scheduler(f"tcp://127.0.0.1:{server.port}", timeout_s=2.0)
        assert time.monotonic() - start < 2.0 + 30.0  # the timeout, and a loaded machine's slack
    finally:
        server.close()


def test_scheduler_that_never_answers_is_one_line_on_the_command_line(tmp_path):
    server = _Server(None)
    try:
        photo = write_png(tmp_path / "p.png", _disc_rgb())
        code, _, stderr = _run("survey", photo, "--db", tmp_path / "s.duckdb", "--scheduler", f"tcp://127.0.0.1:{server.port}")
    finally:
        server.close()
    assert code == 2
    _one_error_line(stderr, "no Dask handshake within")
    assert not (tmp_path / "s.duckdb").exists()


@pytest.mark.parametrize("address,words", [("ucx://127.0.0.1:1", "not supported"), ("tls://127.0.0.1:1", "can't connect"),
                                           ("nonsense", "tcp://HOST:PORT")])
def test_scheduler_schemes_dask_cannot_use_here_are_one_line(address, words):
    from bokehfit.surveys.scheduler import check_scheduler

    with pytest.raises(InputError, match=words):
        check_scheduler(address, timeout_s=2.0)


def test_tls_scheduler_that_does_not_speak_tls_is_refused():
    from bokehfit.surveys.scheduler import check_scheduler

    server = _Server(b"\x00" * 64)
    try:
        with pytest.raises(InputError, match="--scheduler"):
            check_scheduler(f"tls://127.0.0.1:{server.port}", timeout_s=2.0)
    finally:
        server.close()


def _damaged(kind: str, tmp_path: Path) -> Path:
    import duckdb

    if kind == "cut_in_half":
        whole = survey_database(tmp_path / "whole.duckdb").read_bytes()
        (tmp_path / "s.duckdb").write_bytes(whole[: len(whole) // 2])
    elif kind in ("no_photos_table", "other_columns"):
        with duckdb.connect(str(tmp_path / "s.duckdb")) as connection:
            connection.execute("CREATE TABLE survey_meta (key VARCHAR, value VARCHAR)")
            connection.execute("INSERT INTO survey_meta VALUES ('schema_version', '1')")
            if kind == "other_columns":
                connection.execute("CREATE TABLE photos (sha256 VARCHAR, mine INTEGER)")
    elif kind == "corrupt_wal":
        survey_database(tmp_path / "s.duckdb", rows=2)
        (tmp_path / "s.duckdb.wal").write_bytes(np.random.default_rng(1).bytes(300))
    elif kind == "sqlite":
        with sqlite3.connect(tmp_path / "s.duckdb") as connection:
            connection.execute("CREATE TABLE photos (x)")
        connection.close()
    return tmp_path / "s.duckdb"


@pytest.mark.parametrize("kind,words", [
    ("cut_in_half", "damaged"),
    ("no_photos_table", "no photos table"),
    ("other_columns", "other columns"),
    ("corrupt_wal", "write-ahead log"),
    ("sqlite", "SQLite"),
])
def test_damaged_or_foreign_database_is_one_line(tmp_path, kind, words):
    db = _damaged(kind, tmp_path)
    for args in (("--report", tmp_path / "r.html"), (write_png(tmp_path / "p.png", _disc_rgb()),)):
        code, _, stderr = _run("survey", "--db", db, *args, env={"HOME": str(tmp_path)})
        assert code == 2
        _one_error_line(stderr, words)
    assert not (tmp_path / ".duckdb").exists(), "DuckDB fetched an extension"


def test_connections_load_and_install_no_extension():
    from bokehfit.surveys.store import CONNECTION_CONFIG

    assert CONNECTION_CONFIG["autoload_known_extensions"] is False
    assert CONNECTION_CONFIG["autoinstall_known_extensions"] is False


@pytest.mark.skipif(sys.platform == "darwin", reason="macOS file names must be valid UTF-8")
def test_database_name_that_is_not_utf8_is_one_line(tmp_path):
    photo = write_png(tmp_path / "p.png", _disc_rgb())
    code, _, stderr = _run("survey", photo, "--db", os.fsencode(tmp_path) + b"/s\xff.duckdb")
    assert code == 2
    _one_error_line(stderr, "not valid UTF-8")


# --------------------------------------------------------------------------------------
# Names that are not UTF-8
# --------------------------------------------------------------------------------------


@pytest.mark.skipif(sys.platform == "darwin", reason="macOS file names must be valid UTF-8")
def test_names_that_are_not_utf8_reach_every_output(tmp_path):
    folder = os.fsencode(tmp_path)
    photo = folder + b"/photo\xff.png"
    write_png(os.fsdecode(photo), _disc_rgb())
    strict = {"PYTHONIOENCODING": "utf-8:strict"}
    code, stdout, stderr = _run("discs", photo, "--json", folder + b"/d\xfe.json", env=strict)
    assert code in (0, 1) and "internal error" not in stderr, stderr
    code, stdout, stderr = _run("kernel", "--size", "16", "--diameter-px", "5", "--out", folder + b"/k\xfe.npy", env=strict)
    assert code == 0 and "wrote" in stdout, stderr
    # the HTML page and the survey's rows: the name's bad bytes become U+FFFD
    from bokehfit.surveys.store import row_from_record
    from bokehfit.text_encoding import encode_text

    assert encode_text(os.fsdecode(b"<p>photo\xff.png</p>")) == "<p>photo\ufffd.png</p>".encode()
    row = row_from_record({"sha256": "0" * 64, "path": os.fsdecode(photo), "status": "unreadable"},
                          size_bytes=None, json_path=None, html_path=None)
    row["path"].encode("utf-8")


# --------------------------------------------------------------------------------------
# Physical ranges of metadata and results
# --------------------------------------------------------------------------------------


class _Fit:
    """The parts of an ApertureFit that estimate_fstop reads."""

    def __init__(self, diameter_px: float):
        self.diameter_px, self.diameter_uncertainty_px = diameter_px, 0.5
        self.focus_side, self.aperture, self.disc_fits = "far", None, []


@pytest.mark.parametrize("focal,focus_m,light_m,words", [
    ((10000, 1), (10001, 1000), math.inf, "magnification"),  # f/55,834,718 before
    ((1, 1), (2, 1), math.inf, "outside the range of real lenses"),  # f/0.0 before
    ((50, 1), (2, 1), 1e-300, "longer than the focal length"),
    ((50, 1), (2, 1), 2.0, "at the focus distance"),
    ((50, 1), (2, 1), 2.0 * (1 + 1e-12), "outside the range of real lenses"),
])
def test_absurd_geometry_gives_no_fstop_but_the_reason(tmp_path, focal, focus_m, light_m, words):
    from bokehfit.io import load_photo
    from bokehfit.optics import estimate_fstop, resolve_geometry

    path = write_jpeg(tmp_path / "m.jpg", _disc_rgb(), exif=exif_for(make="Canon", model="Canon EOS 50D",
                                                                    fnumber=(28, 10), focal=focal, subject_distance=focus_m))
    photo = load_photo(path)
    geometry = resolve_geometry(photo, light_distance_m=light_m)
    fstop = estimate_fstop(_Fit(44.0), photo, geometry, "thin", "equal-area")
    assert fstop.value is None and words in fstop.reason, fstop.reason


def test_every_reported_fstop_is_in_the_range_of_real_lenses():
    from bokehfit.optics import check_fitted_fstop

    for value in (0.49, 1001.0, math.inf, math.nan, 0.0):
        with pytest.raises(InputError):
            check_fitted_fstop(value)
    assert check_fitted_fstop(2.8) == 2.8


# --------------------------------------------------------------------------------------
# Leftovers
# --------------------------------------------------------------------------------------


def test_refused_photo_leaves_no_output_folder(tmp_path):
    (tmp_path / "bad.jpg").write_bytes(b"not a photo at all")
    code, _, stderr = _run("compare", tmp_path / "bad.jpg", "--json", tmp_path / "a" / "b" / "c" / "r.json")
    assert code == 2
    assert not (tmp_path / "a").exists()


def test_next_run_removes_stale_temporaries_even_when_it_writes_nothing(tmp_path):
    """A temporary of a dead process, and one whose process number now belongs to a younger process."""
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(dead.stdout)
    stale = tmp_path / f".k.npy.bokehfit-tmp-{dead_pid}-0a1b2c3d.npy"
    stale.write_bytes(b"half")
    pid_max = Path("/proc/sys/kernel/pid_max")
    impossible = int(pid_max.read_text()) + 1 if pid_max.exists() else 2**22 + 1  # a number no process can have
    reused = tmp_path / f".k.npy.bokehfit-tmp-{impossible}-0a1b2c3d.npy"
    reused.write_bytes(b"half")
    young = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        renamed = tmp_path / f".k.npy.bokehfit-tmp-{young.pid}-0a1b2c3d.npy"
        renamed.write_bytes(b"half")
        os.utime(renamed, (time.time() - 3600, time.time() - 3600))  # written an hour before its process started
        alive = tmp_path / f".k.npy.bokehfit-tmp-{young.pid}-99999999.npy"
        alive.write_bytes(b"being written")
        mine = tmp_path / "notes.bokehfit-tmp-1-0a1b2c3d.npy"  # not bokehfit's naming (no leading dot)
        mine.write_bytes(b"keep")
        code, _, stderr = _run("kernel", "--size", "16", "--out", tmp_path / "k.npy", "--field-position", "0,0")
        assert code == 2, stderr  # refused after the outputs were checked: nothing written
        assert not stale.exists() and not reused.exists()
        if Path("/proc/self/stat").exists():
            assert not renamed.exists(), "the process number was given to a younger process"
        assert alive.exists() and mine.exists()
    finally:
        young.kill()
        young.wait()


# --------------------------------------------------------------------------------------
# From before: render limits, TIFF depth, CFA, full disk, runtime folder, library noise
# --------------------------------------------------------------------------------------


def test_render_tone_mapping_holds_no_float_copy_of_the_image():
    """The 16384² render passed 12 GB: tone mapping made float64 copies of the whole image."""
    import tracemalloc

    from bokehfit.scene.images import tone_map_srgb8

    image = np.random.default_rng(0).random((1024, 1024, 3), dtype=np.float32)
    tracemalloc.start()
    try:
        out = tone_map_srgb8(image, bgr=True)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert out.dtype == np.uint8 and out.shape == image.shape
    assert peak < 3 * image.shape[0] * image.shape[1] + (16 << 20), f"{peak / 1e6:.0f} MB"
    expected = tone_map_srgb8(image[:64, :64])[..., ::-1]
    assert np.array_equal(out[:64, :64], expected)


def test_render_larger_than_the_memory_available_is_refused_with_its_need(monkeypatch):
    from bokehfit.cli import render

    monkeypatch.setattr(render, "available_memory_bytes", lambda: 2 << 30)
    with pytest.raises(InputError, match="16384×16384 render needs about 9.01 GB of memory"):
        render.check_render_memory(16384, 16384)
    assert render.check_render_memory(512, 512) < 2 << 30


def test_render_estimate_counts_writing_the_file(tmp_path, monkeypatch):
    """The estimate that --max-time bounds is the rendering's and the file's writing together (no timing here)."""
    from bokehfit.cli import main, render

    monkeypatch.setattr(render, "estimate_render_s", lambda *args: (60.0, 1e6))
    monkeypatch.setattr(render, "estimate_write_s", lambda width, height, suffix: 1e-6 * width * height)
    with pytest.raises(InputError, match="would take about 2.1 min .*writing the file"):
        main(["render", "--size", "8192x8192", "--spp", "4", "--out", str(tmp_path / "r.png"), "--max-time", "100"])
    assert not list(tmp_path.iterdir())


def _tiff_with_image_depth(path: Path, depth: int) -> Path:
    import tifffile

    tifffile.imwrite(path, _disc_rgb(64, 64), extratags=[(65000, "I", 1, (depth,), True)])
    data = bytearray(path.read_bytes())
    at = data.find(struct.pack("<HHI", 65000, 4, 1))
    data[at : at + 2] = struct.pack("<H", 32997)  # ImageDepth, which tifffile will not write itself
    path.write_bytes(bytes(data))
    return path


def test_tiff_with_image_depth_4_is_one_clear_line(tmp_path):
    code, _, stderr = _run("discs", _tiff_with_image_depth(tmp_path / "depth.tif", 4))
    assert code == 2
    _one_error_line(stderr, "ImageDepth 4")


@pytest.mark.parametrize("dim,pattern", [((2, 2), (3, 3, 3, 3)), ((16, 16), (5,) * 256), ((1, 1), (1,))])
def test_dng_with_a_bad_cfa_pattern_is_one_clear_line(tmp_path, dim, pattern):
    import tifffile
    from photo_factory import bayer_mosaic

    identity = (1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1)
    tags = [(33421, "H", 2, dim, True), (33422, "B", len(pattern), pattern, True), (50706, "B", 4, (1, 4, 0, 0), True),
            (50707, "B", 4, (1, 1, 0, 0), True), (50708, "s", 0, "x", True), (50714, "H", 1, (64,), True),
            (50717, "H", 1, (4095,), True), (50721, "2i", 9, identity, True), (50778, "H", 1, (21,), True),
            (50728, "2I", 3, (1, 1, 1, 1, 1, 1), True)]
    path = tmp_path / "bad.dng"
    tifffile.imwrite(path, bayer_mosaic(64, 64, 64, 4000), photometric="cfa", subfiletype=0, extratags=tags, metadata=None)
    code, _, stderr = _run("discs", path)
    assert code == 2
    _one_error_line(stderr, "raw")


def test_damaged_raw_and_tiff_files_print_nothing_of_the_libraries(tmp_path):
    import tifffile
    from photo_factory import write_dng, bayer_mosaic

    write_dng(tmp_path / "good.dng", bayer_mosaic(64, 64, 64, 4000), white=4095, black=64)
    data = (tmp_path / "good.dng").read_bytes()
    (tmp_path / "cut.dng").write_bytes(data[: len(data) // 2])
    tifffile.imwrite(tmp_path / "good.tif", _disc_rgb(64, 64))
    _tiff_with_image_depth(tmp_path / "strips.tif", 4)
    for name in ("cut.dng", "strips.tif"):
        code, _, stderr = _run("discs", tmp_path / name)
        assert code == 2
        _one_error_line(stderr)


def test_full_disk_is_one_clear_line_naming_the_output(tmp_path, monkeypatch):
    """Writers that fail for want of space (OpenEXR says so in a RuntimeError) give OSError naming the output."""
    import errno

    import OpenEXR

    from bokehfit.outputs import write_exr

    class Full:
        def __init__(self, *args):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def write(self, name):
            Path(name).write_bytes(b"part")
            raise RuntimeError(f'Failed to write pixel data to image file "{name}". No space left on device.')

    monkeypatch.setattr(OpenEXR, "File", Full)
    with pytest.raises(OSError) as caught:
        write_exr(tmp_path / "r.exr", {"Y": np.ones((4, 4), np.float32)})
    assert caught.value.errno == errno.ENOSPC and caught.value.filename == str(tmp_path / "r.exr")
    assert list(tmp_path.iterdir()) == [], "the temporary file is removed"


@pytest.mark.skipif(not hasattr(os, "getuid"), reason="POSIX ownership")
@pytest.mark.parametrize("planted", ["given", "per_user"])
def test_a_runtime_folder_others_can_write_is_not_adopted(tmp_path, planted):
    shared = tmp_path / "shared"
    shared.mkdir()
    os.chmod(shared, 0o777)
    env = dict(os.environ, PYTHONPATH=str(Path(bokehfit.__file__).resolve().parents[1]))
    if planted == "given":
        env["XDG_RUNTIME_DIR"] = str(shared)
    else:  # the per-user folder made first, open to all, by someone else
        env.pop("XDG_RUNTIME_DIR", None)
        env["TMPDIR"] = str(tmp_path)
        (tmp_path / f"bokehfit-runtime-{os.getuid()}").mkdir(mode=0o777)
        os.chmod(tmp_path / f"bokehfit-runtime-{os.getuid()}", 0o777)
    code = ("import os, stat; from bokehfit.gpu.runtime import use_headless_egl; use_headless_egl(); "
            "d = os.environ['XDG_RUNTIME_DIR']; s = os.lstat(d); "
            "print(d, stat.S_ISDIR(s.st_mode) and s.st_uid == os.getuid() and not s.st_mode & 0o077)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=HANG_S)
    folder, private = done.stdout.split()
    assert private == "True" and folder != str(shared) and "runtime" in folder, done.stdout + done.stderr
