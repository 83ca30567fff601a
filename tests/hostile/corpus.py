"""The hostile-input corpus: damaged, crafted and absurd inputs for every subcommand, and a runner.

``generate_inputs(folder)`` writes the input files (all small: the largest is a
few MB; "huge" inputs only claim to be huge). ``build_cases()`` lists the cases:
a ``bokehfit`` command line (or a Python API call) over those inputs, the exit
codes that are right for it, the files it may write and the files of the user's
that must survive it. ``run_case`` runs one case in a fresh folder, in a
subprocess bounded in time, and sorts the outcome into one of ``OUTCOMES``:

- ``ok``: a right exit code, every stderr line bokehfit's own (one ``error:``
  line on failure), the inputs and the user's files byte-identical, no stray file;
- ``hang``: still running at the case's time limit (killed);
- ``internal error``: exit code 3, or a traceback on stderr;
- ``absurd result``: a JSON output reports an f-stop no lens has (outside f/0.5 to f/1000);
- ``file lost or overwritten``: an input or a file of the user's changed or vanished;
- ``leftovers``: a file bokehfit was not asked to write (a temporary file, an
  output beside the input) is left behind;
- ``wrong exit code``: none of the above, but not an expected exit code;
- ``noisy stderr``: right exit code, but stderr holds lines that are not
  bokehfit's (library warnings) or more than one error line.

The tests (``test_corpus.py``) run the cases not marked ``sweep``; the
benchmark ``benchmarks/hostile_corpus.py`` runs them all and counts outcomes.
Paths in a case's ``argv`` are written ``@IN/name`` (the inputs folder) and
``@OUT/name`` (the case's own folder, which is also its working directory).
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import os
import shutil
import signal
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np

from photo_factory import bayer_mosaic, exif_for, icc_para_curve, make_icc_profile

__all__ = [
    "OUTCOMES",
    "Case",
    "Outcome",
    "build_cases",
    "generate_inputs",
    "run_case",
    "run_cases",
    "snapshot",
    "WRITE_PAUSE_ENV",
]

OUTCOMES = (
    "ok",
    "hang",
    "internal error",
    "absurd result",
    "file lost or overwritten",
    "leftovers",
    "wrong exit code",
    "noisy stderr",
)

#: The test hook of ``bokehfit.outputs``: seconds to wait before renaming a finished temporary file.
WRITE_PAUSE_ENV = "BOKEHFIT_WRITE_PAUSE_S"

E0 = frozenset({0})
E01 = frozenset({0, 1})
E2 = frozenset({2})
E012 = frozenset({0, 1, 2})
E02 = frozenset({0, 2})

#: Seconds a case may run before it counts as a hang.
FAST_S = 20.0
SLOW_S = 60.0
#: Seconds for a photo of 30,000 discs: discs takes about 5 s of CPU and compare 10 s (9 and 17 s
#: of wall clock on a 2-core machine with other work); what this limit judges is a hang, so it is
#: several times that, for a machine busy with other jobs (the corpus runs two at once).
MANY_DISCS_S = 90.0

RUNNING_AS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0


@dataclasses.dataclass(frozen=True)
class Case:
    """One hostile input and what bokehfit must do with it.

    Attributes
    ----------
    name : str
        Unique, says what the case is (``kernel_size_zero``).
    group : str
        The kind of hostility: ``metadata``, ``huge``, ``damaged``, ``numeric``, ``outputs``, ``api``, ``valid``.
    argv : tuple of str
        Arguments after ``bokehfit`` (for an API case: empty).
    expect : frozenset of int
        The right exit codes: 2 for bad input or usage, 0 or 1 for odd but valid input.
    api : str or None
        A Python statement to run instead of the command line (``BokehfitError`` gives its exit code).
    outputs : tuple of str
        Paths in the case folder bokehfit may create (folders included).
    foreign : tuple of str
        Paths in the case folder that are the user's: written before the run, must be unchanged after.
    setup : tuple of tuple of str
        Commands run first (outputs of bokehfit's own that the case then meets).
    kill : bool
        SIGKILL the command while it writes, then run it again to completion.
    sweep : bool
        Slow or large: run by the benchmark only.
    """

    name: str
    group: str
    argv: tuple[str, ...]
    expect: frozenset
    timeout_s: float = FAST_S
    api: str | None = None
    outputs: tuple[str, ...] = ()
    foreign: tuple[str, ...] = ()
    setup: tuple[tuple[str, ...], ...] = ()
    kill: bool = False
    sweep: bool = False
    stale: tuple[str, ...] = ()

    # ``stale``: temporary files of bokehfit's naming (``{pid}`` is a process that has ended) put in
    # the case folder before the run; the run must remove them, even one that writes nothing.

    @property
    def writes_into_inputs(self) -> bool:
        """Whether an output option names a path in the inputs folder (such cases run one at a time)."""
        flags = ("--json", "--overlay", "--out", "--out-dir", "--html", "--db")
        return any(a in flags and b.startswith("@IN") for a, b in zip(self.argv, self.argv[1:]))


@dataclasses.dataclass(frozen=True)
class Outcome:
    """What happened to one case: its outcome class, exit code, time and a one-line detail."""

    case: str
    group: str
    outcome: str
    returncode: int | None
    time_s: float
    detail: str
    stderr: str


# --------------------------------------------------------------------------------------
# Input files
# --------------------------------------------------------------------------------------


def _png_chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)


def _insert_after_ihdr(png: bytes, chunks: bytes) -> bytes:
    ihdr_end = 8 + 8 + 13 + 4
    return png[:ihdr_end] + chunks + png[ihdr_end:]


def _jpeg_with_segment(jpeg: bytes, marker: int, payload: bytes) -> bytes:
    return jpeg[:2] + struct.pack(">BBH", 0xFF, marker, len(payload) + 2) + payload + jpeg[2:]


def _icc_with_curve(curve: bytes) -> bytes:
    """A small RGB display profile whose three tone curves are ``curve``."""
    return make_icc_profile("hostile curve", curve=curve)


def _scene(width: int, height: int) -> np.ndarray:
    """Linear grey (height, width): a few clean round discs on a dark background (no bokehfit code)."""
    rows, cols = np.mgrid[0:height, 0:width].astype(np.float64)
    image = np.full((height, width), 0.02)
    for col, row, radius in ((80, 90, 22), (200, 110, 20), (140, 190, 18)):
        distance = np.hypot(cols - col * width / 320, rows - row * height / 240)
        image += 0.6 * np.clip(radius + 0.5 - distance, 0.0, 1.0)
    return image


def _srgb8(linear: np.ndarray) -> np.ndarray:
    x = np.clip(linear, 0.0, 1.0)
    encoded = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    return np.round(encoded * 255).astype(np.uint8)


def _jpeg_bytes(rgb: np.ndarray, mode: str = "RGB", **options) -> bytes:
    from PIL import Image

    buffer = io.BytesIO()
    image = Image.fromarray(np.ascontiguousarray(rgb))
    if mode != image.mode:
        image = image.convert(mode)
    image.save(buffer, "JPEG", quality=92, **options)
    return buffer.getvalue()


def _png_bytes(pixels: np.ndarray) -> bytes:
    import cv2

    ok, encoded = cv2.imencode(".png", np.ascontiguousarray(pixels))
    assert ok
    return encoded.tobytes()


def _many_discs(count: int) -> np.ndarray:
    """uint8 grey image with about ``count`` round discs 9 px across on a 12-pixel grid."""
    yy, xx = np.mgrid[-6:6, -6:6] + 0.5
    tile = np.where(np.hypot(xx, yy) <= 4.5, 200, 8).astype(np.uint8)
    side = int(np.ceil(np.sqrt(count)))
    return np.tile(tile, (side, side))


def _xmp(body: str) -> bytes:
    return (
        "<?xpacket begin='\ufeff' id='W5M0MpCehiHzreSzNTczkc9d'?><x:xmpmeta xmlns:x='adobe:ns:meta/'>"
        "<rdf:RDF xmlns:rdf='http://www.w3.org/1999/02/22-rdf-syntax-ns#'>"
        "<rdf:Description rdf:about='' xmlns:aux='http://ns.adobe.com/exif/1.0/aux/' "
        f"xmlns:exif='http://ns.adobe.com/exif/1.0/'>{body}</rdf:Description></rdf:RDF></x:xmpmeta>"
        "<?xpacket end='w'?>"
    ).encode("utf-8")


def generate_inputs(folder: Path, sweep: bool = False) -> Path:
    """Write the corpus's input files into ``folder`` (created); returns it. Bounded: a few seconds, < 10 MB."""
    import tifffile

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    grey = _srgb8(_scene(320, 240))
    rgb = np.repeat(grey[..., None], 3, axis=2)
    good_jpeg = _jpeg_bytes(rgb, subsampling=0)
    good_png = _png_bytes(grey)
    files: dict[str, bytes] = {
        "good.jpg": good_jpeg,
        "good.png": good_png,
        "photo_named.json": good_jpeg,
        "jpeg_named.png": good_jpeg,
        "jpeg_named.txt": good_jpeg,
        "empty.jpg": b"",
        "not_image.jpg": b"This is a shopping list, not a photo.\nmilk\neggs\n",
        "truncated.jpg": good_jpeg[: len(good_jpeg) // 2],
        "truncated.png": good_png[: len(good_png) // 2],
        "unreadable.jpg": good_jpeg,
    }
    # Entropy-coded data overwritten in the middle: libjpeg decodes it with "Corrupt JPEG data" warnings.
    corrupt = bytearray(good_jpeg)
    middle = len(corrupt) * 2 // 3
    corrupt[middle : middle + 64] = b"\xff\xd0" * 32
    files["corrupt_scan.jpg"] = bytes(corrupt)
    # A PNG whose image-data checksum is wrong (libpng complains).
    idat = good_png.index(b"IDAT")
    bad_crc = bytearray(good_png)
    (length,) = struct.unpack(">I", good_png[idat - 4 : idat])
    bad_crc[idat + 4 + length] ^= 0xFF
    files["bad_crc.png"] = bytes(bad_crc)
    # Crafted XMP: an unclosed element followed by 60 kB of blanks (makes a backtracking regex quadratic).
    crafted = "<aux:ApproximateFocusDistance>" + " " * 60_000 + "1" + "<exif:FNumber" + " " * 2000
    files["xmp_backtrack.jpg"] = _jpeg_with_segment(good_jpeg, 0xE1, b"http://ns.adobe.com/xap/1.0/\x00" + _xmp(crafted))
    files["xmp_backtrack.png"] = _insert_after_ihdr(
        good_png, _png_chunk(b"iTXt", b"XML:com.adobe.xmp\x00\x00\x00\x00\x00" + _xmp(crafted))
    )
    # A PNG chunk that claims 512 MiB and holds a few bytes; a compressed iTXt that inflates to 512 MiB.
    huge_claim = struct.pack(">I", 512 << 20) + b"iTXt" + b"XML:com.adobe.xmp\x00\x00\x00\x00\x00<x:xmpmeta"
    files["png_huge_itxt_claim.png"] = good_png[:33] + huge_claim + good_png[33:]
    bomb = zlib.compressobj(9)
    blank = b" " * (1 << 20)
    inflated = b"".join(bomb.compress(blank) for _ in range(512)) + bomb.flush()
    files["png_itxt_bomb.png"] = _insert_after_ihdr(
        good_png, _png_chunk(b"iTXt", b"XML:com.adobe.xmp\x00\x01\x00\x00\x00" + inflated)
    )
    # An IHDR that claims 100000 x 100000 pixels.
    ihdr = struct.pack(">IIBBBBB", 100_000, 100_000, 8, 0, 0, 0, 0)
    files["png_huge_dimensions.png"] = good_png[:8] + _png_chunk(b"IHDR", ihdr) + good_png[33:]
    # Degenerate ICC tone curves: parametric (aX + b)^g with a = 0, and a zero gamma.
    para_a0 = icc_para_curve(1, 1.0, 0.0, 0.0)
    para_g0 = icc_para_curve(0, 0.0)
    curv_zero = b"curv\x00\x00\x00\x00" + struct.pack(">IH", 1, 0)
    files["icc_para_a0.jpg"] = _jpeg_bytes(rgb, subsampling=0, icc_profile=_icc_with_curve(para_a0))
    files["icc_para_gamma0.jpg"] = _jpeg_bytes(rgb, subsampling=0, icc_profile=_icc_with_curve(para_g0))
    files["icc_curv_gamma0.jpg"] = _jpeg_bytes(rgb, subsampling=0, icc_profile=_icc_with_curve(curv_zero))
    files["icc_garbage.jpg"] = _jpeg_bytes(rgb, subsampling=0, icc_profile=b"\x00" * 40 + b"garbage" * 30)
    # CMYK JPEG.
    files["cmyk.jpg"] = _jpeg_bytes(rgb, mode="CMYK")
    # Many small discs (the disc finder's worst case).
    files["discs_30000.png"] = _png_bytes(_many_discs(30_000))
    if sweep:
        files["discs_120000.png"] = _png_bytes(_many_discs(120_000))
    for name, data in files.items():
        (folder / name).unlink(missing_ok=True)  # the unreadable file of an earlier run
        (folder / name).write_bytes(data)
    # Float TIFFs: huge values, NaN and infinities.
    linear = _scene(96, 72).astype(np.float32)
    huge = np.full((72, 96, 3), 1e38, np.float32)
    huge[20:40, 20:40] = np.finfo(np.float32).max  # a disc at the largest float32: sums overflow
    tifffile.imwrite(folder / "float_huge.tif", huge, photometric="rgb", metadata=None)
    nan = np.repeat(linear[..., None], 3, axis=2).copy()
    nan[10:30, 10:30] = np.nan
    nan[40:50, 40:60] = np.inf
    nan[0:5, :] = -np.inf
    tifffile.imwrite(folder / "float_nan.tif", nan, photometric="rgb", metadata=None)
    all_nan = np.full((64, 64), np.nan, dtype=np.float32)
    tifffile.imwrite(folder / "float_all_nan.tif", all_nan, photometric="minisblack", metadata=None)
    # A folder with an image name; a file nobody may read.
    (folder / "folder.jpg").mkdir(exist_ok=True)
    os.chmod(folder / "unreadable.jpg", 0)
    _round3_inputs(folder, rgb, good_jpeg, good_png, sweep)
    return folder


def _replace_with(path: Path, make) -> None:
    """Remove whatever is at ``path`` (a file, a link, a FIFO, a folder) and ``make(path)``."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif os.path.lexists(path):
        path.unlink()
    make(path)


def survey_database(path: Path, rows: int = 200) -> Path:
    """A survey database of ``rows`` small rows at ``path`` (the corpus's and the tests' damaged copies start from it)."""
    from bokehfit.surveys.store import SurveyStore, row_from_record

    with SurveyStore(path) as store:
        rng = np.random.default_rng(0)
        for i in range(rows):
            record = {"sha256": f"{i:064x}", "path": f"p{i}.jpg", "status": "no_discs", "reason": "none",
                      "thumbnail": rng.bytes(4000)}
            store.put(row_from_record(record, size_bytes=1, json_path=None, html_path=None))
    return path


def _round3_inputs(folder: Path, rgb: np.ndarray, good_jpeg: bytes, good_png: bytes, sweep: bool) -> None:
    """Issue 25's inputs: files that are not files, crafted sizes, damaged databases, odd names, absurd EXIF."""
    import sqlite3

    import duckdb
    import tifffile

    fifo = hasattr(os, "mkfifo")
    # Files that are not regular files (photos, outputs, lists, databases), and a library of them with link loops.
    for name in ("fifo.jpg", "fifo_out.json", "fifo_out.npy", "fifo_list.txt", "fifo_db.duckdb"):
        if fifo:
            _replace_with(folder / name, os.mkfifo)
    if os.path.exists("/dev/zero"):
        _replace_with(folder / "zero.jpg", lambda p: os.symlink("/dev/zero", p))
    library = folder / "library"
    _replace_with(library, lambda p: (p / "sub").mkdir(parents=True))
    if fifo:
        os.mkfifo(library / "fifo.jpg")
    if os.path.exists("/dev/zero"):
        os.symlink("/dev/zero", library / "zero.jpg")
    os.symlink("..", library / "sub" / "loop")  # two loops: glob's walk through them grows exponentially
    os.symlink(".", library / "sub" / "loop2")
    files: dict[str, bytes] = {}
    # Many ICC profiles (2,500; 10,000 with sweep; each inflates to the 4 MiB cap); a small JPEG that claims
    # 15811² px; a 16×100000 PNG.
    iccp = _png_chunk(b"iCCP", b"icc\x00\x00" + zlib.compress(bytes(4 << 20), 9))
    files["iccp_many.png"] = good_png[:33] + iccp * (10_000 if sweep else 2_500) + good_png[33:]
    claim = bytearray(_jpeg_bytes((np.random.default_rng(0).random((256, 256, 3)) * 255).astype(np.uint8)))
    at = 2
    while claim[at + 1] not in (0xC0, 0xC1, 0xC2):
        at += 2 + struct.unpack(">H", claim[at + 2 : at + 4])[0]
    claim[at + 5 : at + 9] = struct.pack(">HH", 15811, 15811)
    files["claim_15811.jpg"] = bytes(claim)
    files["tall_16x100000.png"] = _png_bytes(np.zeros((100_000, 16), np.uint8))
    # Absurd EXIF geometry on a photo with discs.
    files["exif_10000mm_10.001m.jpg"] = _jpeg_bytes(rgb, subsampling=0, exif=exif_for(
        make="Canon", model="Canon EOS 50D", fnumber=(28, 10), focal=(10000, 1), subject_distance=(10001, 1000)))
    files["exif_1mm.jpg"] = _jpeg_bytes(rgb, subsampling=0, exif=exif_for(
        make="Canon", model="Canon EOS 50D", fnumber=(28, 10), focal=(1, 1), subject_distance=(2, 1)))
    files["exif_50mm.jpg"] = _jpeg_bytes(rgb, subsampling=0, exif=exif_for(
        make="Canon", model="Canon EOS 50D", fnumber=(28, 10), focal=(50, 1), subject_distance=(2, 1)))
    for name, data in files.items():
        (folder / name).write_bytes(data)
    if sys.platform != "darwin":
        (folder / os.fsdecode(b"photo_\xff.jpg")).write_bytes(good_jpeg)
    # A volume TIFF (ImageDepth 4, written under another tag number and renamed); DNGs damaged and with bad CFA tags.
    tifffile.imwrite(folder / "depth4.tif", rgb[:64, :64], extratags=[(65000, "I", 1, (4,), True)])
    data = bytearray((folder / "depth4.tif").read_bytes())
    at = data.find(struct.pack("<HHI", 65000, 4, 1))
    data[at : at + 2] = struct.pack("<H", 32997)
    (folder / "depth4.tif").write_bytes(bytes(data))
    identity = (1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1)
    mosaic = bayer_mosaic(64, 64, 64, 4000)
    for name, dim, pattern in (("cfa_good.dng", (2, 2), (0, 1, 1, 2)), ("cfa_bad.dng", (2, 2), (3, 3, 3, 3)),
                               ("cfa_16x16.dng", (16, 16), (5,) * 256)):
        tags = [(33421, "H", 2, dim, True), (33422, "B", len(pattern), pattern, True), (50706, "B", 4, (1, 4, 0, 0), True),
                (50707, "B", 4, (1, 1, 0, 0), True), (50708, "s", 0, "x", True), (50714, "H", 1, (64,), True),
                (50717, "H", 1, (4095,), True), (50721, "2i", 9, identity, True), (50778, "H", 1, (21,), True),
                (50728, "2I", 3, (1, 1, 1, 1, 1, 1), True)]
        tifffile.imwrite(folder / name, mosaic, photometric="cfa", subfiletype=0, extratags=tags, metadata=None)
    dng = (folder / "cfa_good.dng").read_bytes()
    (folder / "cut.dng").write_bytes(dng[: len(dng) // 2])
    # Survey databases: cut in half, without the photos table, with other columns, a damaged log, an SQLite file.
    for name in ("whole.duckdb", "half.duckdb", "no_photos.duckdb", "other_columns.duckdb", "bad_wal.duckdb",
                 "bad_wal.duckdb.wal", "sqlite.duckdb"):
        (folder / name).unlink(missing_ok=True)
    survey_database(folder / "whole.duckdb", 200)
    whole = (folder / "whole.duckdb").read_bytes()
    (folder / "whole.duckdb").unlink()
    (folder / "half.duckdb").write_bytes(whole[: len(whole) // 2])
    for name, other in (("no_photos.duckdb", False), ("other_columns.duckdb", True)):
        with duckdb.connect(str(folder / name)) as connection:
            connection.execute("CREATE TABLE survey_meta (key VARCHAR, value VARCHAR)")
            connection.execute("INSERT INTO survey_meta VALUES ('schema_version', '1')")
            if other:
                connection.execute("CREATE TABLE photos (sha256 VARCHAR, mine INTEGER)")
    survey_database(folder / "bad_wal.duckdb", 2)
    (folder / "bad_wal.duckdb.wal").write_bytes(np.random.default_rng(1).bytes(300))
    connection = sqlite3.connect(folder / "sqlite.duckdb")
    connection.execute("CREATE TABLE photos (x)")
    connection.commit()
    connection.close()


# --------------------------------------------------------------------------------------
# Cases
# --------------------------------------------------------------------------------------


def _cases_numeric() -> list[Case]:
    jpg = "@IN/good.jpg"
    kernel = ("kernel", "--size", "32", "--diameter-px", "10", "--out", "@OUT/k.npy")
    kout = ("k.npy",)
    render = ("render", "--size", "8x8", "--spp", "1", "--out", "@OUT/r.png")
    rout = ("r.png",)
    rows = [
        # compare: geometry and sizes
        ("compare_focal_length_negative", ("compare", jpg, "--focal-length-mm", "-50"), E2),
        ("compare_focal_length_nan", ("compare", jpg, "--focal-length-mm", "nan"), E2),
        ("compare_focal_length_1e308", ("compare", jpg, "--focal-length-mm", "1e308"), E2),
        ("compare_sensor_width_zero", ("compare", jpg, "--sensor-width-mm", "0"), E2),
        ("compare_focus_distance_negative", ("compare", jpg, "--focus-distance-m", "-3"), E2),
        ("compare_focus_distance_inf", ("compare", jpg, "--focus-distance-m", "inf"), E2),
        ("compare_light_distance_nan", ("compare", jpg, "--light-distance-m", "nan"), E2),
        ("compare_light_distance_negative", ("compare", jpg, "--light-distance-m", "-1"), E2),
        ("compare_light_before_focus", ("compare", jpg, "--focal-length-mm", "85", "--sensor-width-mm", "36",
                                        "--focus-distance-m", "3", "--light-distance-m", "0.001"), E012),
        ("compare_focus_inside_lens", ("compare", jpg, "--focal-length-mm", "85", "--sensor-width-mm", "36",
                                       "--focus-distance-m", "0.01"), E2),
        ("compare_min_diameter_nan", ("compare", jpg, "--min-diameter-px", "nan"), E2),
        ("compare_min_diameter_1e9", ("compare", jpg, "--min-diameter-px", "1e9"), E012),
        ("compare_max_diameter_inf", ("compare", jpg, "--max-diameter-px", "inf"), E012),
        ("compare_min_above_max", ("compare", jpg, "--min-diameter-px", "50", "--max-diameter-px", "10"), E2),
        ("compare_shapes_unknown", ("compare", jpg, "--shapes", "hexgon"), E2),
        ("compare_shapes_ngon_2", ("compare", jpg, "--shapes", "ngon(2)"), E2),
        ("compare_shapes_ngon_huge", ("compare", jpg, "--shapes", "ngon(100000000)"), E2),
        ("compare_shapes_empty", ("compare", jpg, "--shapes", ",,,"), E012),
        # discs
        ("discs_min_diameter_negative", ("discs", jpg, "--min-diameter-px", "-4"), E2),
        ("discs_min_diameter_nan", ("discs", jpg, "--min-diameter-px", "nan"), E2),
        ("discs_max_diameter_inf", ("discs", jpg, "--max-diameter-px", "inf"), E012),
        ("discs_max_diameter_zero", ("discs", jpg, "--max-diameter-px", "0"), E2),
        ("discs_min_above_max", ("discs", jpg, "--min-diameter-px", "40", "--max-diameter-px", "5"), E2),
        ("discs_max_discs_zero", ("discs", jpg, "--max-discs", "0"), E2),
        ("discs_max_discs_huge", ("discs", jpg, "--max-discs", str(10**30)), E012),
        ("discs_max_discs_text", ("discs", jpg, "--max-discs", "many"), E2),
        # kernel
        ("kernel_size_zero", ("kernel", "--size", "0", "--out", "@OUT/k.npy"), E2),
        ("kernel_size_negative", ("kernel", "--size", "-8", "--out", "@OUT/k.npy"), E2),
        ("kernel_size_100000", ("kernel", "--size", "100000", "--out", "@OUT/k.npy"), E2),
        ("kernel_diameter_nan", ("kernel", "--diameter-px", "nan", "--out", "@OUT/k.npy"), E2),
        ("kernel_diameter_inf", ("kernel", "--diameter-px", "inf", "--out", "@OUT/k.npy"), E2),
        ("kernel_diameter_zero", ("kernel", "--diameter-px", "0", "--out", "@OUT/k.npy"), E2),
        ("kernel_diameter_1e300", ("kernel", "--diameter-px", "1e300", "--size", "16", "--out", "@OUT/k.npy"), E012),
        ("kernel_angle_nan", (*kernel[:-2], "--angle", "nan", "--out", "@OUT/k.npy"), E2),
        ("kernel_angle_1e308", (*kernel[:-2], "--angle", "1e308", "--out", "@OUT/k.npy"), E012),
        ("kernel_samples_zero", (*kernel[:-2], "--method", "mc", "--samples", "0", "--out", "@OUT/k.npy"), E2),
        ("kernel_samples_negative", (*kernel[:-2], "--method", "raster", "--samples", "-5", "--out", "@OUT/k.npy"), E2),
        ("kernel_samples_2e63", (*kernel[:-2], "--method", "mc", "--samples", str(2**63), "--out", "@OUT/k.npy"), E2),
        ("kernel_samples_at_limit", (*kernel[:-2], "--method", "mc", "--samples", str(2**32 - 1), "--out", "@OUT/k.npy"), E012),
        ("kernel_tolerance_1e-300", (*kernel[:-2], "--tolerance", "1e-300", "--out", "@OUT/k.npy"), E2),
        ("kernel_tolerance_negative", (*kernel[:-2], "--tolerance", "-0.1", "--out", "@OUT/k.npy"), E2),
        ("kernel_tolerance_nan", (*kernel[:-2], "--tolerance", "nan", "--out", "@OUT/k.npy"), E2),
        ("kernel_raster_subpixel_disc", ("kernel", "--method", "raster", "--diameter-px", "0.01", "--size", "16",
                                         "--out", "@OUT/k.npy"), E012),
        ("kernel_mc_subpixel_disc", ("kernel", "--method", "mc", "--diameter-px", "0.001", "--size", "16",
                                     "--samples", "1000", "--out", "@OUT/k.npy"), E012),
        ("kernel_blades_two", ("kernel", "--shape", "ngon", "--blades", "2", "--out", "@OUT/k.npy"), E2),
        ("kernel_blades_huge", ("kernel", "--shape", "ngon", "--blades", "1000000000", "--out", "@OUT/k.npy"), E2),
        ("kernel_aspect_zero", ("kernel", "--shape", "slit", "--aspect", "0", "--out", "@OUT/k.npy"), E2),
        ("kernel_aspect_nan", ("kernel", "--shape", "slit", "--aspect", "nan", "--out", "@OUT/k.npy"), E2),
        ("kernel_seed_negative", (*kernel[:-2], "--method", "mc", "--samples", "1000", "--seed", "-1",
                                  "--out", "@OUT/k.npy"), E012),
        ("kernel_seed_2e70", (*kernel[:-2], "--method", "mc", "--samples", "1000", "--seed", str(2**70),
                              "--out", "@OUT/k.npy"), E012),
        # similarity
        ("similarity_angle_nan", ("similarity", "hexagon", "circle", "--angle-a", "nan"), E2),
        ("similarity_angle_inf", ("similarity", "hexagon", "circle", "--angle-b", "inf"), E2),
        ("similarity_blades_two", ("similarity", "ngon", "circle", "--blades-a", "2"), E2),
        ("similarity_blades_huge", ("similarity", "ngon", "circle", "--blades-a", "100000000"), E2),
        ("similarity_aspect_zero", ("similarity", "slit", "circle", "--aspect-a", "0"), E2),
        ("similarity_aspect_1e308", ("similarity", "slit", "circle", "--aspect-a", "1e308"), E2),
        ("similarity_unknown_shape", ("similarity", "hexgon", "circle"), E2),
        # render
        ("render_spp_16777216", ("render", "--spp", "16777216", "--out", "@OUT/r.png"), E02),
        ("render_spp_zero", (*render[:3], "--spp", "0", "--out", "@OUT/r.png"), E2),
        ("render_size_zero", ("render", "--size", "0x0", "--out", "@OUT/r.png"), E2),
        ("render_size_100000", ("render", "--size", "100000x100000", "--spp", "1", "--out", "@OUT/r.png"), E2),
        ("render_size_text", ("render", "--size", "big", "--out", "@OUT/r.png"), E2),
        ("render_fstop_zero", (*render, "--fstop", "0"), E2),
        ("render_fstop_nan", (*render, "--fstop", "nan"), E2),
        ("render_fstop_1e308", (*render, "--fstop", "1e308"), E012),
        ("render_focus_negative", (*render, "--focus-distance", "-1"), E2),
        ("render_focus_nan", (*render, "--focus-distance", "nan"), E2),
        ("render_exposure_1e308", (*render, "--exposure", "1e308"), E012),
        ("render_exposure_nan", (*render, "--exposure", "nan"), E2),
        ("render_light_depths_nan", (*render, "--scene", "points", "--light-depths", "nan"), E2),
        ("render_light_depths_negative", (*render, "--scene", "points", "--light-depths", "-1,0.2"), E2),
        ("render_light_depths_empty", (*render, "--scene", "points", "--light-depths", ","), E2),
        ("render_scene_unknown", (*render, "--scene", "kitchen"), E2),
        ("render_shape_unknown", (*render, "--shape", "hexgon"), E2),
        ("render_blades_huge", (*render, "--shape", "ngon", "--blades", "1000000000"), E2),
        # survey
        ("survey_jobs_zero", ("survey", jpg, "--db", "@OUT/s.duckdb", "--jobs", "0"), E2),
        ("survey_timeout_negative", ("survey", jpg, "--db", "@OUT/s.duckdb", "--timeout-s", "-1"), E2),
        ("survey_timeout_nan", ("survey", jpg, "--db", "@OUT/s.duckdb", "--timeout-s", "nan"), E2),
        ("survey_focal_length_nan", ("survey", jpg, "--db", "@OUT/s.duckdb", "--focal-length-mm", "nan"), E2),
        ("survey_no_photos", ("survey", "@IN/folder.jpg", "--db", "@OUT/s.duckdb"), E012),
        ("survey_db_wrong_suffix", ("survey", jpg, "--db", "@OUT/s.txt"), E2),
        # view: only refusals (a valid view serves until stopped)
        ("view_port_negative", ("view", "--no-browser", "--port", "-1"), E2),
        ("view_port_70000", ("view", "--no-browser", "--port", "70000"), E2),
        ("view_size_zero", ("view", "--no-browser", "--size", "0x0"), E2),
        ("view_size_huge", ("view", "--no-browser", "--size", "100000x100000"), E2),
        # the command line itself
        ("no_subcommand", (), E2),
        ("unknown_subcommand", ("fit",), E2),
        ("unknown_option", ("kernel", "--colour", "red", "--out", "@OUT/k.npy"), E2),
    ]
    cases = []
    for name, argv, expect in rows:
        slow = argv[:1] in (("compare",), ("survey",)) or name.startswith("render_spp")
        outputs = kout if "@OUT/k.npy" in argv else rout if "@OUT/r.png" in argv else ()
        if argv[:1] == ("survey",):
            outputs = ("s.duckdb", "s.duckdb.wal", "s_reports/")
        cases.append(Case(name, "numeric", tuple(argv), expect, SLOW_S if slow else FAST_S, outputs=outputs))
    # Large kernels: minutes on a CPU adapter when they are accepted.
    cases.append(Case("kernel_size_8192_mc", "numeric", ("kernel", "--size", "8192", "--method", "mc",
                                                         "--out", "@OUT/k.npy"), E02, 300.0, outputs=kout, sweep=True))
    return cases


def _cases_files() -> list[Case]:
    """Every damaged or crafted file through every subcommand that reads photos."""
    unreadable = E01 if RUNNING_AS_ROOT else E2  # root reads any file
    rows = [
        ("good.jpg", "valid", E0),
        ("good.png", "valid", E0),
        ("jpeg_named.png", "damaged", E012),
        ("jpeg_named.txt", "damaged", E012),
        ("empty.jpg", "damaged", E2),
        ("not_image.jpg", "damaged", E2),
        ("truncated.jpg", "damaged", E012),
        ("truncated.png", "damaged", E2),
        ("corrupt_scan.jpg", "damaged", E012),
        ("bad_crc.png", "damaged", E012),
        ("folder.jpg", "damaged", E2),
        ("missing.jpg", "damaged", E2),
        ("unreadable.jpg", "damaged", unreadable),
        ("xmp_backtrack.jpg", "metadata", E01),
        ("xmp_backtrack.png", "metadata", E01),
        ("png_huge_itxt_claim.png", "huge", E2),
        ("png_itxt_bomb.png", "huge", E012),
        ("png_huge_dimensions.png", "huge", E2),
        ("icc_para_a0.jpg", "metadata", E012),
        ("icc_para_gamma0.jpg", "metadata", E012),
        ("icc_curv_gamma0.jpg", "metadata", E012),
        ("icc_garbage.jpg", "metadata", E01),
        ("cmyk.jpg", "damaged", E012),
        ("float_huge.tif", "numeric", E012),
        ("float_nan.tif", "numeric", E012),
        ("float_all_nan.tif", "numeric", E012),
        ("discs_30000.png", "huge", E01),
    ]
    # Every file goes through discs; compare (seconds per photo) takes one file of each kind in the
    # tests and the rest in the sweep.
    compare_in_tests = {"good.jpg", "truncated.jpg", "corrupt_scan.jpg", "empty.jpg", "xmp_backtrack.jpg",
                        "png_huge_itxt_claim.png", "icc_para_a0.jpg", "cmyk.jpg", "float_huge.tif", "discs_30000.png"}
    cases = []
    for filename, group, expect in rows:
        stem = filename.replace(".", "_")
        limit = MANY_DISCS_S if filename.startswith("discs_") else SLOW_S
        cases.append(Case(f"discs_{stem}", group, ("discs", f"@IN/{filename}", "--json", "@OUT/d.json"),
                          expect, limit, outputs=("d.json",)))
        cases.append(Case(f"compare_{stem}", group, ("compare", f"@IN/{filename}", "--json", "@OUT/c.json"),
                          expect, limit, outputs=("c.json", "c.html", "report.html"),
                          sweep=filename not in compare_in_tests))
    cases.append(Case("discs_discs_120000_png", "huge", ("discs", "@IN/discs_120000.png"), E01, 300.0, sweep=True))
    return cases


def _cases_outputs() -> list[Case]:
    jpg = "@IN/good.jpg"
    kernel = ("kernel", "--size", "32", "--diameter-px", "10")
    sim = ("similarity", "hexagon", "circle")
    render = ("render", "--size", "8x8", "--spp", "1")
    survey_out = ("s.duckdb", "s.duckdb.wal", "s_reports/")
    # The report is OUT.html beside --json OUT.json (report.html in earlier versions).
    compare_out = ("c.json", "c.html", "report.html")
    rows = [
        # a file of the user's where bokehfit would write
        Case("compare_foreign_report", "outputs", ("compare", jpg, "--json", "@OUT/c.json"), E2, SLOW_S,
             outputs=compare_out, foreign=("report.html", "c.html")),
        Case("compare_foreign_report_out_dir", "outputs", ("compare", jpg, "--out-dir", "@OUT/reports"), E2, SLOW_S,
             outputs=("reports", "reports/good.json", "reports/good.html", "reports/report.html"),
             foreign=("reports/report.html", "reports/good.html")),
        Case("compare_foreign_json", "outputs", ("compare", jpg, "--json", "@OUT/c.json"), E2, SLOW_S,
             outputs=compare_out, foreign=("c.json",)),
        Case("compare_out_dir_is_a_file", "outputs", ("compare", jpg, "--json", "@OUT/c.json", "--out-dir", "@OUT/notes"),
             E2, SLOW_S, outputs=("c.json", "c.html"), foreign=("notes",)),
        Case("compare_json_is_the_input", "outputs", ("compare", "@IN/photo_named.json", "--json", "@IN/photo_named.json",
                                                       "--no-html"), E2, SLOW_S),
        Case("discs_foreign_json", "outputs", ("discs", jpg, "--json", "@OUT/d.json"), E2, SLOW_S,
             outputs=("d.json",), foreign=("d.json",)),
        Case("discs_foreign_overlay", "outputs", ("discs", jpg, "--overlay", "@OUT/o.png"), E2, SLOW_S,
             outputs=("o.png",), foreign=("o.png",)),
        Case("discs_overlay_is_the_input", "outputs", ("discs", "@IN/good.png", "--overlay", "@IN/good.png"), E2, SLOW_S),
        Case("kernel_foreign_npy", "outputs", (*kernel, "--out", "@OUT/k.npy"), E2, outputs=("k.npy",), foreign=("k.npy",)),
        Case("kernel_foreign_png", "outputs", (*kernel, "--out", "@OUT/k.png"), E2, outputs=("k.png",), foreign=("k.png",)),
        Case("kernel_foreign_exr", "outputs", (*kernel, "--out", "@OUT/k.exr"), E2, outputs=("k.exr",), foreign=("k.exr",)),
        Case("kernel_out_is_a_folder", "outputs", (*kernel, "--out", "@OUT/k.npy"), E2, foreign=("k.npy/",)),
        Case("similarity_foreign_json", "outputs", (*sim, "--json", "@OUT/s.json"), E2, outputs=("s.json",),
             foreign=("s.json",)),
        Case("render_foreign_png", "outputs", (*render, "--out", "@OUT/r.png"), E2, SLOW_S, outputs=("r.png",),
             foreign=("r.png",)),
        Case("render_foreign_json", "outputs", (*render, "--out", "@OUT/r.png", "--json", "@OUT/r.json"), E2, SLOW_S,
             outputs=("r.png", "r.json"), foreign=("r.json",)),
        Case("bench_foreign_json", "outputs", ("bench", "--quick", "--json", "@OUT/b.json"), E2, outputs=("b.json",),
             foreign=("b.json",)),
        Case("bench_foreign_html", "outputs", ("bench", "--quick", "--html", "@OUT/b.html"), E2, outputs=("b.html",),
             foreign=("b.html",)),
        # a folder that does not exist
        Case("kernel_missing_folder", "outputs", (*kernel, "--out", "@OUT/missing/k.npy"), E2),
        Case("discs_missing_folder", "outputs", ("discs", jpg, "--json", "@OUT/missing/d.json"), E2, SLOW_S),
        Case("similarity_missing_folder", "outputs", (*sim, "--json", "@OUT/missing/s.json"), E2),
        Case("render_missing_folder", "outputs", (*render, "--out", "@OUT/missing/r.png"), E2),
        Case("bench_missing_folder", "outputs", ("bench", "--quick", "--json", "@OUT/missing/b.json"), E2),
        Case("compare_creates_missing_folder", "outputs", ("compare", jpg, "--json", "@OUT/new/c.json"), E0, SLOW_S,
             outputs=("new", "new/c.json", "new/c.html", "new/report.html")),
        # wrong suffixes
        Case("kernel_out_wrong_suffix", "outputs", (*kernel, "--out", "@OUT/k.txt"), E2),
        Case("similarity_json_wrong_suffix", "outputs", (*sim, "--json", "@OUT/s.png"), E2),
        # bokehfit's own outputs are replaced on a second run
        Case("kernel_rerun_replaces_own", "outputs", (*kernel, "--out", "@OUT/k.npy"), E0, outputs=("k.npy",),
             setup=((*kernel, "--out", "@OUT/k.npy"),)),
        Case("kernel_rerun_replaces_own_png", "outputs", (*kernel, "--out", "@OUT/k.png"), E0, outputs=("k.png",),
             setup=((*kernel, "--out", "@OUT/k.png"),)),
        Case("kernel_rerun_replaces_own_exr", "outputs", (*kernel, "--out", "@OUT/k.exr"), E0, outputs=("k.exr",),
             setup=((*kernel, "--out", "@OUT/k.exr"),)),
        Case("similarity_rerun_replaces_own", "outputs", (*sim, "--json", "@OUT/s.json"), E0, outputs=("s.json",),
             setup=((*sim, "--json", "@OUT/s.json"),)),
        Case("compare_rerun_replaces_own", "outputs", ("compare", jpg, "--json", "@OUT/c.json"), E0, 2 * SLOW_S,
             outputs=compare_out, setup=(("compare", jpg, "--json", "@OUT/c.json"),), sweep=True),
        # survey: its database and reports are outputs too
        Case("survey_foreign_db", "outputs", ("survey", jpg, "--db", "@OUT/s.duckdb"), E2, SLOW_S,
             outputs=survey_out, foreign=("s.duckdb",)),
        Case("survey_foreign_report", "outputs", ("survey", jpg, "--db", "@OUT/s.duckdb", "--report", "@OUT/r.html"),
             E2, SLOW_S, outputs=survey_out + ("r.html",), foreign=("r.html",)),
        Case("survey_db_missing_folder", "outputs", ("survey", jpg, "--db", "@OUT/missing/s.duckdb"), E012, SLOW_S,
             outputs=("missing/",)),
        # SIGKILL in the middle of a write, then a second run: nothing may be left behind
        Case("kernel_killed_while_writing", "outputs", ("kernel", "--size", "1024", "--diameter-px", "8",
                                                        "--out", "@OUT/k.npy"), E0, SLOW_S, outputs=("k.npy",), kill=True),
        Case("compare_killed_while_writing", "outputs", ("compare", jpg, "--json", "@OUT/c.json"), E0, 2 * SLOW_S,
             outputs=compare_out, kill=True),
    ]
    return rows


#: What the kernel cases import: the aperture is built once, then passed whole.
_KERNEL_API = "from bokehfit.apertures import make_aperture; from bokehfit.kernels import render_kernel; "


def _cases_api() -> list[Case]:
    rows = [
        ("api_render_kernel_tolerance_1e-300",
         _KERNEL_API + "render_kernel(make_aperture('hexagon'), 10.0, 32, tolerance=1e-300)"),
        ("api_render_kernel_diameter_nan",
         _KERNEL_API + "render_kernel(make_aperture('hexagon'), float('nan'), 32)"),
        ("api_render_kernel_size_float",
         _KERNEL_API + "render_kernel(make_aperture('hexagon'), 10.0, 32.5)"),
        ("api_find_discs_empty_array",
         "import numpy as np; from bokehfit.discs import find_discs; find_discs(np.zeros((0, 0), np.float32))"),
        ("api_find_discs_nan_array",
         "import numpy as np; from bokehfit.discs import find_discs; find_discs(np.full((64, 64), np.nan, np.float32))"),
        ("api_find_discs_3d_array",
         "import numpy as np; from bokehfit.discs import find_discs; find_discs(np.zeros((8, 8, 8), np.float32))"),
        ("api_load_photo_folder", "from bokehfit.io import load_photo; load_photo('@IN/folder.jpg')"),
        ("api_load_photo_empty", "from bokehfit.io import load_photo; load_photo('@IN/empty.jpg')"),
        ("api_compare_photo_not_image", "from bokehfit.compare import compare_photo; compare_photo('@IN/not_image.jpg')"),
    ]
    return [Case(name, "api", (), E2, FAST_S, api=code) for name, code in rows]


def _cases_round3() -> list[Case]:
    """Issue 25: files that are not files, crafted sizes, the survey's inputs, odd names, absurd EXIF, leftovers."""
    jpg, kernel = "@IN/good.jpg", ("kernel", "--size", "16", "--diameter-px", "5")
    survey_out = ("s.duckdb", "s.duckdb.wal", "s_reports/")
    bad = os.fsdecode(b"\xff")
    rows = [
        # files that are not regular files, at every entry point
        Case("kernel_out_is_a_fifo", "not a file", (*kernel, "--out", "@IN/fifo_out.npy"), E2),
        Case("discs_json_is_a_fifo", "not a file", ("discs", jpg, "--json", "@IN/fifo_out.json"), E2, SLOW_S),
        Case("compare_json_is_a_fifo", "not a file", ("compare", jpg, "--json", "@IN/fifo_out.json"), E2, SLOW_S),
        Case("discs_photo_is_a_fifo", "not a file", ("discs", "@IN/fifo.jpg"), E2),
        Case("compare_photo_is_dev_zero", "not a file", ("compare", "@IN/zero.jpg"), E2),
        Case("survey_folder_of_fifos_and_link_loops", "not a file", ("survey", "@IN/library", "--db", "@OUT/s.duckdb"),
             E0, SLOW_S, outputs=survey_out),
        Case("survey_glob_through_link_loops", "not a file", ("survey", "@IN/library/**/*.jpg", "--db", "@OUT/s.duckdb"),
             E0, SLOW_S, outputs=survey_out),
        Case("survey_files_from_a_fifo", "not a file", ("survey", "--files-from", "@IN/fifo_list.txt", "--db",
                                                         "@OUT/s.duckdb"), E2),
        Case("survey_files_from_dev_zero", "not a file", ("survey", "--files-from", "/dev/zero", "--db", "@OUT/s.duckdb"), E2),
        Case("survey_db_is_a_fifo", "not a file", ("survey", jpg, "--db", "@IN/fifo_db.duckdb"), E2),
        # crafted sizes
        Case("discs_png_many_iccp_chunks", "huge", ("discs", "@IN/iccp_many.png"), E01, SLOW_S),
        Case("discs_jpeg_claims_15811_squared", "huge", ("discs", "@IN/claim_15811.jpg"), E2, SLOW_S),
        Case("compare_png_16x100000", "huge", ("compare", "@IN/tall_16x100000.png", "--json", "@OUT/c.json"), E01, SLOW_S,
             outputs=("c.json", "c.html")),
        Case("discs_tiff_image_depth_4", "damaged", ("discs", "@IN/depth4.tif"), E2),
        Case("discs_dng_bad_cfa", "damaged", ("discs", "@IN/cfa_bad.dng"), E2),
        Case("discs_dng_16x16_cfa", "damaged", ("discs", "@IN/cfa_16x16.dng"), E2),
        Case("discs_dng_cut", "damaged", ("discs", "@IN/cut.dng"), E2),
        # the survey's inputs
        Case("survey_scheduler_silent", "survey", ("survey", jpg, "--db", "@OUT/s.duckdb", "--scheduler", "@SILENT"), E2, SLOW_S),
        Case("survey_scheduler_garbage", "survey", ("survey", jpg, "--db", "@OUT/s.duckdb", "--scheduler", "@GARBAGE"), E2),
        Case("survey_scheduler_tls", "survey", ("survey", jpg, "--db", "@OUT/s.duckdb", "--scheduler", "tls://@GARBAGE"), E2),
        Case("survey_scheduler_ucx", "survey", ("survey", jpg, "--db", "@OUT/s.duckdb", "--scheduler", "ucx://127.0.0.1:1"), E2),
        Case("survey_db_cut_in_half", "survey", ("survey", "--db", "@IN/half.duckdb", "--report", "@OUT/r.html"), E2),
        Case("survey_db_without_photos", "survey", ("survey", jpg, "--db", "@IN/no_photos.duckdb"), E2),
        Case("survey_db_other_columns", "survey", ("survey", "--db", "@IN/other_columns.duckdb", "--parquet", "@OUT/p.parquet"), E2),
        Case("survey_db_damaged_wal", "survey", ("survey", jpg, "--db", "@IN/bad_wal.duckdb"), E2),
        Case("survey_db_is_sqlite", "survey", ("survey", jpg, "--db", "@IN/sqlite.duckdb"), E2),
        Case("survey_db_name_not_utf8", "names", ("survey", jpg, "--db", f"@OUT/s{bad}.duckdb"), E2),
        # names that are not UTF-8
        Case("compare_photo_name_not_utf8", "names", ("compare", os.fsdecode(b"@IN/photo_\xff.jpg"), "--json",
                                                      f"@OUT/c{bad}.json"), E01, SLOW_S, outputs=(f"c{bad}.json", f"c{bad}.html")),
        Case("kernel_out_name_not_utf8", "names", (*kernel, "--out", f"@OUT/k{bad}.npy"), E0, outputs=(f"k{bad}.npy",)),
        # absurd geometry: no f-stop outside real lenses' range
        Case("compare_exif_10000mm_focus_10.001m", "physical", ("compare", "@IN/exif_10000mm_10.001m.jpg", "--json",
                                                                 "@OUT/c.json"), E01, SLOW_S, outputs=("c.json", "c.html")),
        Case("compare_exif_focal_1mm", "physical", ("compare", "@IN/exif_1mm.jpg", "--json", "@OUT/c.json"), E01, SLOW_S,
             outputs=("c.json", "c.html")),
        Case("compare_light_distance_1e-300", "physical", ("compare", "@IN/exif_50mm.jpg", "--json", "@OUT/c.json",
                                                           "--light-distance-m", "1e-300"), E012, SLOW_S, outputs=("c.json", "c.html")),
        Case("compare_light_at_the_focus_plane", "physical", ("compare", "@IN/exif_50mm.jpg", "--json", "@OUT/c.json",
                                                              "--light-distance-m", "2.000000001"), E012, SLOW_S,
             outputs=("c.json", "c.html")),
        # leftovers
        Case("compare_refused_photo_makes_no_folder", "leftovers", ("compare", "@IN/not_image.jpg", "--json",
                                                                    "@OUT/a/b/c/r.json"), E2),
        Case("kernel_refused_removes_stale_temporary", "leftovers", (*kernel, "--out", "@OUT/k.npy", "--field-position", "0,0"),
             E2, stale=(".k.npy.bokehfit-tmp-{pid}-0a1b2c3d.npy",)),
    ]
    return rows


def build_cases(sweep: bool = False) -> list[Case]:
    """Every case of the corpus (with ``sweep``, the slow ones too), in a fixed order."""
    cases = _cases_files() + _cases_numeric() + _cases_outputs() + _cases_api() + _cases_round3()
    names = [case.name for case in cases]
    assert len(names) == len(set(names)), "case names must be unique"
    return [case for case in cases if sweep or not case.sweep]


# --------------------------------------------------------------------------------------
# Running a case
# --------------------------------------------------------------------------------------

_API_WRAPPER = """
import sys
from bokehfit.errors import BokehfitError
try:
    {statement}
except BokehfitError as error:
    print(f"bokehfit: error: {{error}}", file=sys.stderr)
    sys.exit(error.exit_code)
"""


def snapshot(folder: Path) -> dict[str, str | None]:
    """sha256 of every file under ``folder`` by relative path (folders: ``"<dir>"``; unreadable: None)."""
    import stat

    state: dict[str, str | None] = {}
    for top, folders, names in os.walk(folder):  # links to folders are not followed (the corpus has loops)
        for name in folders + names:
            path = Path(top) / name
            key = path.relative_to(folder).as_posix()
            info = os.lstat(path)
            if stat.S_ISDIR(info.st_mode):
                state[key] = "<dir>"
            elif stat.S_ISLNK(info.st_mode):
                state[key] = f"<link {os.readlink(path)}>"
            elif not stat.S_ISREG(info.st_mode):
                state[key] = f"<{stat.S_IFMT(info.st_mode):o}>"  # a FIFO: never opened
            else:
                try:
                    state[key] = hashlib.sha256(path.read_bytes()).hexdigest()
                except OSError:
                    state[key] = None
    return dict(sorted(state.items()))


def _resolve(argv, inputs: Path, folder: Path) -> list[str]:
    out = [a.replace("@IN", str(inputs)).replace("@OUT", str(folder)) for a in argv]
    if any("@SILENT" in a or "@GARBAGE" in a for a in out):
        silent, garbage = _fake_schedulers()
        out = [a.replace("@SILENT", f"tcp://127.0.0.1:{silent}").replace("tls://@GARBAGE", f"tls://127.0.0.1:{garbage}")
               .replace("@GARBAGE", f"tcp://127.0.0.1:{garbage}") for a in out]
    return out


_SCHEDULERS: list[int] = []


def _fake_schedulers() -> list[int]:
    """Ports of two servers in this process, for ``--scheduler``: one accepts and never answers, one answers garbage."""
    import socket
    import threading

    if _SCHEDULERS:
        return _SCHEDULERS[:2]
    silent = socket.create_server(("127.0.0.1", 0), backlog=64)  # the kernel accepts; nothing ever answers
    garbage = socket.create_server(("127.0.0.1", 0), backlog=64)

    def answer():
        while True:
            connection, _ = garbage.accept()
            with contextlib.suppress(OSError):
                connection.sendall(b"\xff" * 8 + b"not dask " * 100)
            threading.Timer(5.0, connection.close).start()

    threading.Thread(target=answer, daemon=True).start()
    _SCHEDULERS.extend([silent.getsockname()[1], garbage.getsockname()[1]])
    _SCHEDULERS.append(silent)  # kept open for the process's life
    return _SCHEDULERS[:2]


def _command(case: Case, inputs: Path, folder: Path, argv=None) -> list[str]:
    if case.api is not None and argv is None:
        statement = case.api.replace("@IN", str(inputs)).replace("@OUT", str(folder))
        return [sys.executable, "-c", _API_WRAPPER.format(statement=statement)]
    return [sys.executable, "-m", "bokehfit", *_resolve(case.argv if argv is None else argv, inputs, folder)]


def _environment(extra: dict[str, str] | None = None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("BOKEHFIT_DEBUG", WRITE_PAUSE_ENV)}
    env["PYTHONWARNINGS"] = "default"  # warnings are shown as they would be to a user, not raised
    env.update(extra or {})
    return env


def _run(command: list[str], folder: Path, timeout_s: float, env=None) -> tuple[int | None, str, float]:
    """(exit code or None on timeout, stderr, seconds); the process group is killed on timeout."""
    start = time.perf_counter()
    process = subprocess.Popen(command, cwd=folder, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                               env=env or _environment(), start_new_session=True)
    try:
        _, stderr = process.communicate(timeout=timeout_s)
        code = process.returncode
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        _, stderr = process.communicate()
        code = None
    return code, stderr.decode("utf-8", "replace"), time.perf_counter() - start


def _write_foreign(folder: Path, name: str) -> None:
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    if name.endswith("/"):
        path.mkdir()
        (path / "keep.txt").write_text("mine\n")
        return
    suffix = path.suffix.lower()
    if suffix == ".npy":
        np.save(path, np.arange(12, dtype=np.float32).reshape(3, 4))
    elif suffix == ".png":
        path.write_bytes(_png_bytes(np.full((4, 4), 128, np.uint8)))
    elif suffix == ".json":
        path.write_text('{"note": "my own file", "bokehfit": "please keep"}\n')
    elif suffix == ".exr":
        import OpenEXR

        with OpenEXR.File({"type": OpenEXR.scanlineimage}, {"Y": np.ones((4, 4), np.float32)}) as exr:
            exr.write(str(path))
    else:
        path.write_text("<html><body>my own notes</body></html>\n")


def _kill_while_writing(command: list[str], folder: Path, timeout_s: float, attempts: int = 4) -> str:
    """SIGKILL ``command`` as soon as a hidden (temporary) file appears in ``folder``; say how it went."""
    env = _environment({WRITE_PAUSE_ENV: "30"})
    for attempt in range(attempts):
        process = subprocess.Popen(command, cwd=folder, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                   env=env, start_new_session=True)
        deadline = time.monotonic() + timeout_s
        try:
            while process.poll() is None and time.monotonic() < deadline:
                if any(p.name.startswith(".") for p in folder.rglob("*")):
                    os.killpg(process.pid, signal.SIGKILL)
                    process.wait()
                    return f"killed during a write (attempt {attempt + 1})"
                time.sleep(0.002)
        finally:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
    return f"no write caught in {attempts} attempts"


def _stray_files(folder: Path, allowed: set[str]) -> list[str]:
    strays = []
    for path in folder.rglob("*"):
        key = path.relative_to(folder).as_posix()
        if key in allowed or any(key.startswith(a.rstrip("/") + "/") for a in allowed if a.endswith("/")):
            continue
        if path.is_dir() and any(a.startswith(key + "/") for a in allowed):
            continue
        strays.append(key)
    return sorted(strays)


#: The f-stops of real lenses: the fastest made are about f/0.7, pinhole cameras reach f/500.
FSTOP_RANGE = (0.5, 1000.0)


def _absurd_fstops(folder: Path) -> str | None:
    """The first JSON output under ``folder`` that reports an f-stop outside :data:`FSTOP_RANGE`, said in words."""
    import json

    for path in sorted(folder.rglob("*.json")):
        try:
            document = json.loads(path.read_text("utf-8"))
        except (OSError, ValueError):
            continue
        aperture = document.get("aperture") if isinstance(document, dict) else None
        value = aperture.get("fstop") if isinstance(aperture, dict) else None
        if isinstance(value, (int, float)) and not FSTOP_RANGE[0] <= value <= FSTOP_RANGE[1]:
            return f"{path.name} reports f/{value:g}"
    return None


def _stderr_problem(code: int, stderr: str) -> str | None:
    lines = [line for line in stderr.splitlines() if line.strip()]
    foreign = [line for line in lines if not line.startswith("bokehfit")]
    if foreign:
        return f"stderr line not from bokehfit: {foreign[0][:120]!r}"
    if code != 0:
        errors = [line for line in lines if "error:" in line]
        if len(errors) != 1:
            return f"{len(errors)} error lines on stderr (one expected)"
    return None


def run_case(case: Case, inputs: Path, root: Path, reference: dict | None = None) -> Outcome:
    """Run ``case`` in a fresh folder under ``root`` and sort what happened into one of ``OUTCOMES``.

    ``reference`` is ``snapshot(inputs)`` as generated; the inputs must still match it afterwards.
    """
    folder = Path(root) / case.name
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    reference = snapshot(inputs) if reference is None else reference
    for name in case.foreign:
        _write_foreign(folder, name)
    foreign_before = {k: v for k, v in snapshot(folder).items()}
    for argv in case.setup:
        code, stderr, _ = _run(_command(case, inputs, folder, argv), folder, case.timeout_s)
        if code != 0:
            return Outcome(case.name, case.group, "wrong exit code", code, 0.0,
                           f"setup {' '.join(argv[:1])} exited {code}", stderr)
    own = {k: v for k, v in snapshot(folder).items() if k not in foreign_before}
    if case.stale:
        ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
        for name in case.stale:
            (folder / name.format(pid=int(ended.stdout))).write_bytes(b"half a file")
    command = _command(case, inputs, folder)
    note = ""
    if case.kill:
        note = _kill_while_writing(command, folder, case.timeout_s) + "; then a full run. "
    code, stderr, elapsed = _run(command, folder, case.timeout_s)

    def outcome(kind: str, detail: str) -> Outcome:
        return Outcome(case.name, case.group, kind, code, round(elapsed, 2), note + detail, stderr)

    if code is None:
        return outcome("hang", f"still running after {case.timeout_s:g} s")
    if code == 3 or "Traceback" in stderr:
        last = [line for line in stderr.splitlines() if line.strip()]
        return outcome("internal error", f"exit {code}: {last[-1][:160] if last else ''}")
    absurd = _absurd_fstops(folder)
    if absurd:
        return outcome("absurd result", f"exit {code}; {absurd}")
    after_inputs = snapshot(inputs)
    changed = [k for k, v in reference.items() if after_inputs.get(k) != v]
    after = snapshot(folder)
    changed += [f"(user's) {k}" for k, v in foreign_before.items() if after.get(k) != v]
    if changed:
        return outcome("file lost or overwritten", f"exit {code}; changed or gone: {', '.join(changed[:4])}")
    strays = [f"inputs/{k}" for k in after_inputs if k not in reference]
    strays += _stray_files(folder, set(case.outputs) | set(foreign_before) | set(own) | set(case.foreign))
    if strays:
        return outcome("leftovers", f"exit {code}; left behind: {', '.join(strays[:4])}")
    if code not in case.expect:
        message = [line for line in stderr.splitlines() if line.strip()]
        return outcome("wrong exit code", f"exit {code}, expected {sorted(case.expect)}: "
                                          f"{message[-1][:160] if message else '(no message)'}")
    problem = _stderr_problem(code, stderr)
    if problem:
        return outcome("noisy stderr", f"exit {code}; {problem}")
    return outcome("ok", f"exit {code}")


def run_cases(cases: list[Case], inputs: Path, root: Path, jobs: int = 2, sweep: bool = False, report=None) -> dict:
    """Run ``cases`` (``jobs`` at a time; those that write into the inputs folder alone, last).

    The inputs are generated anew after a case that changed them. ``report(outcome)`` is
    called as each case ends. Returns ``{case name: Outcome}`` in the order of ``cases``.
    """
    from concurrent.futures import ThreadPoolExecutor

    reference = snapshot(inputs)

    def run(case: Case) -> Outcome:
        outcome = run_case(case, inputs, root, reference)
        if report is not None:
            report(outcome)
        return outcome

    shared = [case for case in cases if not case.writes_into_inputs]
    alone = [case for case in cases if case.writes_into_inputs]
    with ThreadPoolExecutor(max(1, jobs)) as pool:
        outcomes = list(pool.map(run, shared))
    for case in alone:
        outcomes.append(run(case))
        if outcomes[-1].outcome == "file lost or overwritten":
            generate_inputs(inputs, sweep=sweep)
    by_name = {outcome.case: outcome for outcome in outcomes}
    return {case.name: by_name[case.name] for case in cases}
