"""Photos people have and hostile files, at the ``load_photo`` / ``find_discs`` boundary.

Every file is made here, in ``tmp_path``, and is small (the largest about 2 MB). Time bounds
are generous for a loaded two-core machine; the fixed code takes milliseconds where the bound
is a second, and a few seconds where it is a minute.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
from photo_factory import (
    ADOBE_COLORANTS,
    icc_para_curve,
    icc_table_curve,
    make_icc_profile,
    make_xmp,
    srgb_decode,
    write_png,
    write_tiff,
)

import bokehfit
from bokehfit.discs import MAX_CANDIDATES, find_discs
from bokehfit.errors import InputError
from bokehfit.io import load_photo
from bokehfit.io.exif import XMP_MAX_BYTES, build_exif, parse_xmp, read_exif_tags, xmp_property
from bokehfit.io.photo import FLOAT_SAMPLE_MAX

SRGB_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])
#: CPU seconds a crafted metadata block may take to read (the fixed parsers take milliseconds;
#: the old backtracking ones took half a minute). CPU time, not the wall clock: a busy machine
#: may keep this process waiting for a core, which is no cost of the parser's.
METADATA_SECONDS = 1.0
#: Seconds a photo with ten thousand small discs may take to search (measured: about 4 s).
MANY_DISCS_SECONDS = 60.0


def _run_bokehfit(*args, timeout=120):
    """``python -m bokehfit ARGS`` with the bokehfit these tests import; (returncode, stdout, stderr)."""
    env = dict(os.environ, PYTHONPATH=str(Path(bokehfit.__file__).resolve().parents[1]))
    done = subprocess.run(
        [sys.executable, "-m", "bokehfit", *map(str, args)], capture_output=True, text=True, timeout=timeout, env=env
    )
    return done.returncode, done.stdout, done.stderr


@pytest.fixture
def warm(tmp_path):
    """Load one plain file first, so that timed loads do not pay for first imports (colour-science)."""
    load_photo(write_png(tmp_path / "warm.png", np.zeros((16, 16, 3), np.uint8)))


def _discs_image(height, width, discs, background=0.05, level=0.8):
    """Float32 linear image with anti-aliased flat discs ``(x, y, radius)``."""
    image = np.full((height, width), background, np.float32)
    for x, y, radius in discs:
        cv2.circle(image, (x * 16, y * 16), radius * 16, level, -1, lineType=cv2.LINE_AA, shift=4)
    return image


# --------------------------------------------------------------------------------------
# CMYK JPEG
# --------------------------------------------------------------------------------------

PATCH_RGB = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [128, 128, 128]], np.uint8)


def _cmyk_jpeg(path, icc=None):
    """Four 32-px patches (red, green, blue, grey) saved as an Adobe CMYK JPEG by Pillow."""
    from PIL import Image

    rgb = np.repeat(np.repeat(PATCH_RGB[None], 32, axis=0), 32, axis=1)
    options = {"quality": 100}
    if icc:
        options["icc_profile"] = icc
    Image.fromarray(rgb).convert("CMYK").save(path, "JPEG", **options)
    return path


def _patch_medians(luminance):
    return np.array([np.median(luminance[8:24, 32 * i + 8 : 32 * i + 24]) for i in range(len(PATCH_RGB))])


def test_cmyk_jpeg_is_converted_to_rgb_and_says_so(tmp_path):
    photo = load_photo(_cmyk_jpeg(tmp_path / "cmyk.jpg"))
    expected = srgb_decode(PATCH_RGB / 255.0) @ SRGB_WEIGHTS
    np.testing.assert_allclose(_patch_medians(photo.luminance), expected, rtol=0.03, atol=0.003)
    assert photo.colour_space == "sRGB"
    assert len(photo.notes) == 1 and "cmyk.jpg is a CMYK JPEG: converted to sRGB naively" in photo.notes[0]
    assert photo.input_json()["notes"] == list(photo.notes)


def test_cmyk_jpeg_with_an_unusable_profile_falls_back_to_the_naive_conversion(tmp_path):
    broken = bytearray(make_icc_profile("Broken press profile"))
    broken[16:20] = b"CMYK"  # a CMYK header on an RGB body: littleCMS refuses it
    photo = load_photo(_cmyk_jpeg(tmp_path / "cmyk.jpg", icc=bytes(broken)))
    expected = srgb_decode(PATCH_RGB / 255.0) @ SRGB_WEIGHTS
    np.testing.assert_allclose(_patch_medians(photo.luminance), expected, rtol=0.03, atol=0.003)
    assert "embedded ICC profile 'Broken press profile' is not usable" in photo.notes[0]
    assert "naively" in photo.notes[0]


# --------------------------------------------------------------------------------------
# Float TIFFs: NaN/Inf, huge values
# --------------------------------------------------------------------------------------

DISCS = [(60, 60, 15), (160, 70, 15), (100, 150, 15)]


def _float_rgb(height=200, width=240):
    return np.repeat(_discs_image(height, width, DISCS)[..., None], 3, axis=2)


def test_float_tiff_nan_and_inf_pixels_are_masked_and_counted(tmp_path):
    rgb = _float_rgb()
    bad = [(5, 5, 1, np.nan), (10, 200, 0, np.inf), (120, 20, 2, -np.inf)]
    # Three bad pixels inside the first disc: that disc is found but not used.
    bad += [(60 + dy, 60 + dx, 0, np.nan) for dy, dx in ((0, 0), (2, 3), (-4, 1))]
    for row, col, channel, value in bad:
        rgb[row, col, channel] = value
    photo = load_photo(write_tiff(tmp_path / "nan.tif", rgb))
    assert np.isfinite(photo.luminance).all()
    assert [n for n in photo.notes if "NaN or Inf" in n] == [
        f"nan.tif: {len(bad)} pixels with NaN or Inf samples masked (filled from their neighbours,"
        " flagged like clipped pixels, so that no disc containing them is used)"
    ]
    expected_mask = np.zeros(photo.clipped.shape, bool)
    for row, col, _, _ in bad:
        expected_mask[row, col] = True
    np.testing.assert_array_equal(photo.clipped, expected_mask)
    assert photo.luminance[5, 5] == pytest.approx(0.05, abs=0.01)  # filled from the background around it
    search = find_discs(photo.luminance, photo.clipped)
    by_centre = {(round(d.center_xy[0]), round(d.center_xy[1])): d for d in search.discs}
    assert set(by_centre) == {(x, y) for x, y, _ in DISCS}
    assert by_centre[(60, 60)].saturated and by_centre[(60, 60)].evidence == "edge"
    assert by_centre[(160, 70)].usable and by_centre[(100, 150)].usable


@pytest.mark.parametrize("dtype,scale", [(np.float32, 1e30), (np.float64, 1e300)])
def test_float_tiff_with_huge_values_is_scaled_and_its_discs_found(tmp_path, dtype, scale):
    """Values of 1e30 are not linear light with 1.0 = white: the image is scaled so that the
    99.9th percentile is 1, and its discs come out as in the same image at normal scale."""
    rgb = _float_rgb()
    plain = load_photo(write_tiff(tmp_path / "plain.tif", rgb))
    huge = load_photo(write_tiff(tmp_path / "huge.tif", rgb.astype(dtype) * dtype(scale)))
    assert np.isfinite(huge.luminance).all() and huge.luminance.max() <= 1.0 + 1e-6
    assert "scaled by" in huge.linearisation and any("far above 1.0 = white" in n for n in huge.notes)
    expected = find_discs(plain.luminance, plain.clipped)
    found = find_discs(huge.luminance, huge.clipped)
    assert len(found) == len(expected) == len(DISCS)
    for a, b in zip(found.discs, expected.discs):
        assert a.diameter_px == pytest.approx(b.diameter_px, rel=1e-3) and a.usable
        assert math.isfinite(a.snr) and math.isfinite(a.plateau)


def test_float_tiff_isolated_huge_samples_are_clamped_and_flagged(tmp_path):
    rgb = _float_rgb()
    rgb[30, 200, :] = 1e30  # a few absurd samples do not move the robust white point
    rgb[190, 10, 1] = 3e38
    photo = load_photo(write_tiff(tmp_path / "hot.tif", rgb))
    assert "scaled" not in photo.linearisation
    assert float(photo.luminance.max()) <= FLOAT_SAMPLE_MAX
    assert photo.clipped[30, 200] and photo.clipped[190, 10] and photo.clipped.sum() == 2
    assert any(n.startswith("hot.tif: 2 pixels above") for n in photo.notes)
    assert len(find_discs(photo.luminance, photo.clipped)) == len(DISCS)


# --------------------------------------------------------------------------------------
# Metadata: XMP, PNG chunks, ICC curves
# --------------------------------------------------------------------------------------


def test_crafted_xmp_is_read_in_linear_time(warm):
    """Whitespace inside an unclosed element made the old regular expressions backtrack
    (cubic time: 4 kB took half a minute); expat reads 60 kB in milliseconds."""
    for spaces in (1500, 30_000):
        crafted = b"<aux:Lens>" + b" " * spaces + b"x" + b" " * spaces
        start = time.process_time()
        assert xmp_property(crafted, "aux:Lens") is None
        build_exif(read_exif_tags(None), crafted, width_px=600, height_px=400)
        assert time.process_time() - start < METADATA_SECONDS, f"{len(crafted)} bytes of XMP took too long"


def test_xmp_with_a_document_type_is_ignored():
    """Entities come only from a DOCTYPE: a packet that has one is not read at all."""
    laughs = (
        b'<?xml version="1.0"?><!DOCTYPE x [<!ENTITY a "ha"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;">]>'
        b"<x:xmpmeta><aux:Lens>&b;</aux:Lens><rdf:Description exif:FNumber='28/10'/></x:xmpmeta>"
    )
    assert parse_xmp(laughs) == {}
    assert xmp_property(laughs, "aux:Lens") is None


def test_xmp_parser_reads_elements_attributes_and_damaged_packets():
    packet = make_xmp({"aux:Lens": "EF 85mm f/1.8 &amp; more", "exif:FNumber": "28/10"})
    assert parse_xmp(packet)["aux:Lens"] == "EF 85mm f/1.8 & more"
    packet = make_xmp({"aux:ApproximateFocusDistance": "727/100"}, attributes=True)
    assert xmp_property(packet, "aux:ApproximateFocusDistance") == "727/100"
    cut = packet[: packet.index(b"</rdf:RDF>")] + b"<broken"  # what was read before the damage is kept
    assert xmp_property(cut, "aux:ApproximateFocusDistance") == "727/100"
    assert parse_xmp(b" " * (XMP_MAX_BYTES + 1)) == {}


def test_png_xmp_that_inflates_past_the_cap_is_skipped_with_a_note(tmp_path, warm):
    """A 50 kB compressed iTXt chunk that would inflate to 64 MiB is cut off at the cap."""
    bomb = zlib.compress(b"<x:xmpmeta>" + b"x" * (64 << 20), 9)
    path = write_png(tmp_path / "bomb.png", np.zeros((32, 32, 3), np.uint8))
    data = path.read_bytes()
    body = b"XML:com.adobe.xmp\x00\x01\x00\x00\x00" + bomb
    chunk = len(body).to_bytes(4, "big") + b"iTXt" + body + zlib.crc32(b"iTXt" + body).to_bytes(4, "big")
    path.write_bytes(data[:33] + chunk + data[33:])
    assert path.stat().st_size < 1 << 20
    start = time.process_time()
    photo = load_photo(path)
    assert time.process_time() - start < METADATA_SECONDS
    assert f"bomb.png: its XMP packet is damaged or inflates past {XMP_MAX_BYTES} bytes; ignored" in photo.notes


def test_png_metadata_chunks_over_the_cap_are_skipped_unread(tmp_path, warm):
    xmp = make_xmp({"aux:Lens": "x" * (XMP_MAX_BYTES + 10)})
    path = write_png(tmp_path / "big.png", np.zeros((32, 32, 3), np.uint8), xmp=xmp)
    start = time.process_time()
    photo = load_photo(path)
    assert time.process_time() - start < METADATA_SECONDS
    assert photo.exif.lens is None
    assert photo.notes == (
        f"big.png: its iTXt chunk holds {len(xmp) + 22} bytes, more than the {XMP_MAX_BYTES} read; skipped",
    )


def test_png_declaring_a_512_mib_chunk_is_refused_at_once(tmp_path, warm):
    path = write_png(tmp_path / "liar.png", np.zeros((32, 32, 3), np.uint8))
    data = path.read_bytes()
    path.write_bytes(data[:33] + (512 << 20).to_bytes(4, "big") + b"iTXtXML:com.adobe.xmp\x00" + data[33:])
    start = time.process_time()
    with pytest.raises(InputError, match="truncated PNG"):
        load_photo(path)
    assert time.process_time() - start < METADATA_SECONDS


@pytest.mark.parametrize(
    "curve,why",
    [
        (icc_para_curve(1, 2.2, 0.0, 0.0), "a = 0"),
        (icc_para_curve(0, 0.0), "gamma 0"),
        (icc_para_curve(3, 2.4, 1 / 1.055, 0.055 / 1.055, -12.92, 0.04045), "falls"),
        (icc_table_curve([0.0, 0.6, 0.2, 1.0]), "falls"),
        (b"curv\x00\x00\x00\x00" + (1).to_bytes(4, "big") + (0).to_bytes(2, "big"), "flat"),
    ],
    ids=["para_a_zero", "para_gamma_zero", "para_negative_slope", "table_not_monotonic", "curv_gamma_zero"],
)
def test_degenerate_icc_curves_fall_back_to_srgb_with_a_note(tmp_path, curve, why):
    profile = make_icc_profile("Odd Display", colorants=ADOBE_COLORANTS, curve=curve)
    codes = np.tile(np.arange(0, 256, 8, dtype=np.uint8)[None, :, None], (16, 1, 3))
    photo = load_photo(write_png(tmp_path / "odd.png", codes, icc=profile))
    assert photo.colour_space == "sRGB" and "assumed" in photo.linearisation
    assert "embedded ICC profile 'Odd Display' not usable" in photo.linearisation and why in photo.linearisation
    np.testing.assert_allclose(photo.luminance[0], srgb_decode(codes[0, :, 0] / 255.0), atol=1e-4)


# --------------------------------------------------------------------------------------
# Damaged JPEG: one line, no library text
# --------------------------------------------------------------------------------------


def _damaged_jpeg(tmp_path):
    rng = np.random.default_rng(7)
    codes = rng.integers(0, 256, (300, 400, 3), dtype=np.uint8)
    ok, encoded = cv2.imencode(".jpg", codes)
    assert ok
    data = encoded.tobytes()
    path = tmp_path / "damaged.jpg"
    path.write_bytes(data[: len(data) // 2] + b"\xff\xd9")  # the scan stops half way, then end-of-image
    return path


def test_damaged_jpeg_is_read_with_one_note_and_no_library_text(tmp_path, capfd):
    photo = load_photo(_damaged_jpeg(tmp_path))
    assert capfd.readouterr() == ("", "")
    assert len(photo.notes) == 1
    note = photo.notes[0]
    assert note.startswith("damaged.jpg is a damaged JPEG file (Corrupt JPEG data: premature end of data segment)")
    start = int(note.split("rows 0–")[1].split(" ")[0]) + 1
    assert 100 < start < 300 and note.count("\n") == 0
    fill = photo.display[start:]
    assert (fill == fill[-1, -1]).all() and not (photo.display[start - 1] == fill[-1, -1]).all()


def test_damaged_jpeg_on_the_command_line_says_so_in_one_line(tmp_path):
    code, out, err = _run_bokehfit("discs", _damaged_jpeg(tmp_path))
    assert "Corrupt JPEG data" not in err and "premature end" not in err
    assert code in (0, 1), err  # a result or "no disc found", never an internal error
    notes = [line for line in out.splitlines() if "is a damaged JPEG file" in line]
    assert len(notes) == 1 and "rows 0–" in notes[0]


# --------------------------------------------------------------------------------------
# find_discs: the parameter boundary
# --------------------------------------------------------------------------------------

GOOD = np.zeros((32, 32), np.float32)

BAD_CALLS = {
    "empty": (dict(luminance=np.zeros((0, 0), np.float32)), "luminance must be at least 8×8 pixels"),
    "one_pixel": (dict(luminance=np.zeros((1, 1), np.float32)), "luminance must be at least 8×8 pixels"),
    "thin": (dict(luminance=np.zeros((3, 500), np.float32)), "luminance must be at least 8×8 pixels"),
    "three_d": (dict(luminance=np.zeros((32, 32, 3), np.float32)), "luminance must be a 2-D array"),
    "one_d": (dict(luminance=np.zeros(64, np.float32)), "luminance must be a 2-D array"),
    "bool": (dict(luminance=np.zeros((32, 32), bool)), "luminance must be a 2-D array of real numbers"),
    "complex": (dict(luminance=np.zeros((32, 32), complex)), "luminance must be a 2-D array of real numbers"),
    "strings": (dict(luminance=np.full((32, 32), "a")), "luminance must be a 2-D array of real numbers"),
    "ragged": (dict(luminance=[[1.0, 2.0], [3.0]]), "luminance must be a 2-D array"),
    "float64_overflow": (dict(luminance=np.full((32, 32), 1e300)), "luminance contains NaN or Inf"),
    "huge": (dict(luminance=np.full((32, 32), 1e30, np.float32)), "luminance reaches 1e+30"),
    "clipped_shape": (dict(clipped=np.zeros((16, 16), bool)), "clipped must have the shape of luminance"),
    "min_nan": (dict(min_diameter_px=float("nan")), "min_diameter_px must be a finite number"),
    "min_inf": (dict(min_diameter_px=float("inf")), "min_diameter_px must be a finite number"),
    "min_zero": (dict(min_diameter_px=0), "min_diameter_px must be at least 1"),
    "min_text": (dict(min_diameter_px="four"), "min_diameter_px must be a finite number"),
    "max_nan": (dict(max_diameter_px=float("nan")), "max_diameter_px must be above min_diameter_px (4), or inf"),
    "max_negative": (dict(max_diameter_px=-5), "max_diameter_px must be above min_diameter_px (4), or inf"),
    "max_minus_inf": (dict(max_diameter_px=float("-inf")), "max_diameter_px must be above min_diameter_px"),
    "max_text": (dict(max_diameter_px="big"), "max_diameter_px must be a number or inf"),
    "max_bool": (dict(max_diameter_px=True), "max_diameter_px must be a number or inf"),
    "max_discs_zero": (dict(max_discs=0), "max_discs must be a whole number of at least 1"),
    "max_discs_float": (dict(max_discs=2.5), "max_discs must be a whole number of at least 1"),
    "max_discs_bool": (dict(max_discs=True), "max_discs must be a whole number of at least 1"),
}


@pytest.mark.parametrize("case", sorted(BAD_CALLS))
def test_find_discs_refuses_bad_parameters_in_one_line(case):
    kwargs, needle = BAD_CALLS[case]
    kwargs = dict(kwargs)
    luminance = kwargs.pop("luminance", GOOD)
    with pytest.raises(InputError) as caught:
        find_discs(luminance, **kwargs)
    assert needle in str(caught.value) and "\n" not in str(caught.value)


def test_max_diameter_inf_means_no_limit_in_the_api_and_on_the_command_line(tmp_path):
    """A 520-px disc is too large for the default limit of 500 px; inf finds it, in bounded time.

    Run in a child process with a time limit: an unbounded search would never return.
    """
    image = _discs_image(1000, 1000, [(500, 500, 260)], background=0.05, level=0.7)
    codes = np.round(255 * np.clip(image, 0, 1) ** (1 / 2.2)).astype(np.uint8)
    path = write_png(tmp_path / "big.png", codes)
    code, out, err = _run_bokehfit("discs", path, "--max-diameter-px", "inf", timeout=60)
    assert code == 0, err
    assert "1 discs" in out.splitlines()[-1]
    code, out, err = _run_bokehfit("discs", path, timeout=60)
    assert code == 1 and "too large" in err
    search = find_discs(image, max_diameter_px=float("inf"))
    assert len(search) == 1 and search.discs[0].diameter_px == pytest.approx(520, rel=0.01)


# --------------------------------------------------------------------------------------
# Bounded detection
# --------------------------------------------------------------------------------------


def _many_discs(per_side, pitch=12):
    """``per_side``² small discs (7 px across, ``pitch`` apart) on a grid, float32."""
    big = np.zeros((pitch * 2, pitch * 2), np.float32)
    cv2.circle(big, (pitch, pitch), 7, 1.0, -1, lineType=cv2.LINE_AA)
    tile = cv2.resize(big, (pitch, pitch), interpolation=cv2.INTER_AREA)
    return (np.tile(tile, (per_side, per_side)) * 0.6 + 0.05).astype(np.float32)


def test_ten_thousand_discs_are_searched_in_bounded_time_with_a_note():
    image = _many_discs(100)
    start = time.perf_counter()
    search = find_discs(image)
    elapsed = time.perf_counter() - start
    assert elapsed < MANY_DISCS_SECONDS
    assert search.candidates == 100 * 100
    assert search.rejected["beyond the candidate limit"] == 100 * 100 - MAX_CANDIDATES
    assert len(search) <= MAX_CANDIDATES and len(search) > 0.9 * MAX_CANDIDATES
    assert search.notes == (
        f"10000 candidates found, the {MAX_CANDIDATES} clearest measured (limit MAX_CANDIDATES);"
        " raise min_diameter_px or crop the photo to measure the others",
    )
