"""``load_photo``: linear light from JPEG, PNG, TIFF and DNG files, orientation, clipping, bad input.

Reference values come from :mod:`photo_factory` (the sRGB formula of IEC 61966-2-1 and Adobe
RGB's gamma 563/256 written out by hand), not from the loader's own tables.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from photo_factory import (
    ADOBE_GAMMA,
    SRGB_COLORANTS,
    bayer_mosaic,
    exif_for,
    file_state,
    make_icc_profile,
    manifest_entry,
    reference_photo,
    srgb_decode,
    srgb_encode,
    to_codes,
    write_dng,
    write_jpeg,
    write_png,
    write_tiff,
)

import bokehfit.io.linear as linear_module
from bokehfit.errors import InputError
from bokehfit.io import MIN_SIDE_PX, Exif, load_photo

SRGB_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])
ADOBE_WEIGHTS = np.array([0.29734, 0.62736, 0.07529])  # Y row of colour-science's Adobe RGB (1998) matrix
#: float32 luminance against a float64 reference: a few ulps of values <= 1.
EXACT = 2e-6


def grey_patches(levels, size=32, bits=8, encode=srgb_encode):
    """Side-by-side square grey patches of the given linear levels, encoded as integer RGB."""
    codes = to_codes(np.asarray(levels), bits, encode)
    strip = np.repeat(codes, size)[None, :].repeat(size, axis=0)
    return np.repeat(strip[..., None], 3, axis=2)


def patch_medians(luminance, count, size=32, margin=8):
    return np.array(
        [
            np.median(luminance[margin : size - margin, i * size + margin : (i + 1) * size - margin])
            for i in range(count)
        ]
    )


def random_codes(shape, bits, seed):
    """Random integer RGB with about 5 % of samples at the maximum code."""
    rng = np.random.default_rng(seed)
    top = 2**bits - 1
    codes = rng.integers(0, top, size=shape, endpoint=True)
    codes[rng.random(shape) < 0.05] = top
    return codes.astype(np.uint8 if bits == 8 else np.uint16)


def expected_luminance(codes, bits, decode=srgb_decode, weights=SRGB_WEIGHTS):
    linear = decode(codes.astype(np.float64) / (2**bits - 1))
    return linear @ weights if linear.ndim == 3 else linear


# --------------------------------------------------------------------------------------
# Round trips
# --------------------------------------------------------------------------------------

LEVELS = [0.0, 0.002, 0.01, 0.05, 0.18, 0.5, 0.8, 1.0]


def test_srgb_jpeg_round_trip_within_two_codes(tmp_path):
    """Linear levels through the sRGB curve into an 8-bit JPEG (quality 95, 4:4:4) come back linear.

    Tolerance: the decoded level of the written code ±2 codes (rounding plus JPEG error on a
    flat patch). At 0.002 (the sRGB curve's linear toe) a plain gamma 2.2 would fall outside.
    """
    path = write_jpeg(tmp_path / "levels.jpg", grey_patches(LEVELS))
    photo = load_photo(path)
    assert (photo.width, photo.height) == (32 * len(LEVELS), 32)
    assert photo.colour_space == "sRGB" and not photo.raw
    assert "assumed" in photo.linearisation
    codes = to_codes(np.asarray(LEVELS)).astype(np.float64)
    low = srgb_decode((codes - 2) / 255)
    high = srgb_decode((codes + 2) / 255)
    measured = patch_medians(photo.luminance, len(LEVELS))
    assert np.all((measured >= low) & (measured <= high)), (measured, LEVELS)
    assert not (low[1] <= (7 / 255) ** 2.2 <= high[1])  # the test can tell sRGB from gamma 2.2
    assert photo.clipped[:, -32:].all() and not photo.clipped[:, :-32].any()


def test_photo_arrays_on_plain_pages_are_the_same(tmp_path, monkeypatch):
    """Large photo arrays are mapped without transparent huge pages (linear.photo_array); a photo
    read so has the same pixels, luminance and clipped mask as one read on NumPy's own arrays."""
    path = write_jpeg(tmp_path / "levels.jpg", grey_patches(LEVELS))
    monkeypatch.setattr(linear_module, "PLAIN_PAGES_BYTES", 1 << 62)  # NumPy's arrays
    plain = load_photo(path)
    monkeypatch.setattr(linear_module, "PLAIN_PAGES_BYTES", 0)  # every array mapped by photo_array
    mapped = load_photo(path)
    for name in ("luminance", "clipped", "display"):
        a, b = getattr(plain, name), getattr(mapped, name)
        assert a.dtype == b.dtype and np.array_equal(a, b) and not b.flags.writeable, name
    fresh = linear_module.photo_array((3, 5), np.float32)
    fresh[...] = 7.0  # writable until frozen
    assert fresh.shape == (3, 5) and fresh.dtype == np.float32 and float(fresh.sum()) == 105.0


@pytest.mark.parametrize("bits", [8, 16])
def test_png_round_trip_exact_with_clipped_mask(tmp_path, bits):
    codes = random_codes((40, 56, 3), bits, seed=bits)
    photo = load_photo(write_png(tmp_path / f"random{bits}.png", codes))
    np.testing.assert_allclose(photo.luminance, expected_luminance(codes, bits), rtol=0, atol=EXACT)
    np.testing.assert_array_equal(photo.clipped, (codes == 2**bits - 1).any(axis=2))
    expected_display = codes if bits == 8 else np.round(codes / 257.0).astype(np.uint8)
    np.testing.assert_array_equal(photo.display, expected_display)


@pytest.mark.parametrize("bits", [8, 16])
def test_grey_png_round_trip(tmp_path, bits):
    codes = random_codes((24, 30), bits, seed=10 + bits)
    photo = load_photo(write_png(tmp_path / "grey.png", codes))
    np.testing.assert_allclose(photo.luminance, srgb_decode(codes / (2**bits - 1)), rtol=0, atol=EXACT)
    np.testing.assert_array_equal(photo.clipped, codes == 2**bits - 1)
    assert photo.display.shape == (24, 30, 3)


def test_png_alpha_is_dropped(tmp_path):
    codes = random_codes((20, 20, 4), 8, seed=3)
    photo = load_photo(write_png(tmp_path / "rgba.png", codes))
    np.testing.assert_allclose(photo.luminance, expected_luminance(codes[..., :3], 8), rtol=0, atol=EXACT)
    np.testing.assert_array_equal(photo.clipped, (codes[..., :3] == 255).any(axis=2))


@pytest.mark.parametrize("bits", [8, 16])
def test_tiff_round_trip_exact(tmp_path, bits):
    codes = random_codes((33, 47, 3), bits, seed=20 + bits)
    photo = load_photo(write_tiff(tmp_path / "rgb.tif", codes))
    np.testing.assert_allclose(photo.luminance, expected_luminance(codes, bits), rtol=0, atol=EXACT)
    np.testing.assert_array_equal(photo.clipped, (codes == 2**bits - 1).any(axis=2))


def test_planar_tiff(tmp_path):
    codes = random_codes((3, 20, 24), 16, seed=5)
    photo = load_photo(write_tiff(tmp_path / "planar.tif", codes, planarconfig="separate", photometric="rgb"))
    pixels = np.moveaxis(codes, 0, -1)
    np.testing.assert_allclose(photo.luminance, expected_luminance(pixels, 16), rtol=0, atol=EXACT)


def test_lzw_tiff_falls_back_to_opencv(tmp_path):
    """tifffile needs imagecodecs for LZW; OpenCV's libtiff decodes it (in BGR order)."""
    from PIL import Image

    codes = random_codes((20, 28, 3), 8, seed=24)
    Image.fromarray(codes).save(tmp_path / "lzw.tif", compression="tiff_lzw")
    photo = load_photo(tmp_path / "lzw.tif")
    np.testing.assert_allclose(photo.luminance, expected_luminance(codes, 8), rtol=0, atol=EXACT)
    np.testing.assert_array_equal(photo.display, codes)


def test_tiff_orientation_tag(tmp_path):
    codes = random_codes((20, 28, 3), 16, seed=25)
    photo = load_photo(write_tiff(tmp_path / "o8.tif", codes, orientation=8))
    assert (photo.width, photo.height) == (20, 28) and photo.exif.orientation == 8
    np.testing.assert_allclose(photo.luminance, np.rot90(expected_luminance(codes, 16), 1), rtol=0, atol=EXACT)


def test_float_tiff_is_linear(tmp_path):
    rng = np.random.default_rng(7)
    linear = rng.random((30, 40, 3), dtype=np.float32) * 1.5
    photo = load_photo(write_tiff(tmp_path / "linear.tif", linear))
    assert photo.colour_space == "linear" and photo.linearisation.startswith("linear float TIFF")
    np.testing.assert_allclose(photo.luminance, linear.astype(np.float64) @ SRGB_WEIGHTS, rtol=1e-6, atol=EXACT)
    assert not photo.clipped.any()
    expected_display = np.round(srgb_encode(np.clip(linear, 0, 1)) * 255)
    assert np.abs(photo.display.astype(int) - expected_display).max() <= 1


def test_float_tiff_negative_values_are_clamped_and_said(tmp_path):
    linear = np.full((20, 20), 0.25, dtype=np.float32)
    linear[:5, :5] = -0.1
    photo = load_photo(write_tiff(tmp_path / "negative.tif", linear))
    assert "25 negative values clamped to 0" in photo.linearisation
    assert photo.luminance[:5, :5].max() == 0.0 and photo.luminance[10, 10] == pytest.approx(0.25)


def test_luminance_weights_on_pure_colours(tmp_path):
    """Pure R, G, B at code 255 have the luminance of sRGB's weights (PNG exact, JPEG within 1 %)."""
    colours = np.zeros((32, 96, 3), dtype=np.uint8)
    for channel in range(3):
        colours[:, 32 * channel : 32 * (channel + 1), channel] = 255
    png = load_photo(write_png(tmp_path / "rgb.png", colours))
    jpeg = load_photo(write_jpeg(tmp_path / "rgb.jpg", colours))
    np.testing.assert_allclose(patch_medians(png.luminance, 3), SRGB_WEIGHTS, rtol=0, atol=EXACT)
    np.testing.assert_allclose(patch_medians(jpeg.luminance, 3), SRGB_WEIGHTS, rtol=0.01)


def test_colour_jpeg_display_is_the_decoded_rgb_over_many_blocks(tmp_path):
    """The display is the decoded image with its channels put in RGB order, block by block:
    the image is taller than several blocks, and every row is swapped exactly once."""
    codes = random_codes((4 * linear_module.BLOCK_ROWS + 7, 48, 3), 8, seed=31)
    path = write_jpeg(tmp_path / "tall.jpg", codes)
    photo = load_photo(path)
    decoded = cv2.imread(str(path), cv2.IMREAD_UNCHANGED | cv2.IMREAD_IGNORE_ORIENTATION)
    np.testing.assert_array_equal(photo.display, decoded[..., ::-1])
    assert photo.display.flags.c_contiguous and not photo.display.flags.writeable
    np.testing.assert_allclose(photo.luminance, expected_luminance(decoded[..., ::-1], 8), rtol=0, atol=EXACT)
    np.testing.assert_array_equal(photo.clipped, (decoded == 255).any(axis=2))


def test_jpeg_whose_name_opencv_cannot_take_is_decoded_from_its_bytes(tmp_path):
    """A name that is not valid text (bytes a file system accepts) makes OpenCV's file read fail:
    the bytes already read are decoded instead, to the same photo."""
    import os

    codes = random_codes((30, 40, 3), 8, seed=32)
    plain = write_jpeg(tmp_path / "plain.jpg", codes)
    odd = os.path.join(os.fsencode(tmp_path), b"odd-\xff.jpg")
    with open(odd, "wb") as file:
        file.write(plain.read_bytes())
    photo, reference = load_photo(os.fsdecode(odd)), load_photo(plain)
    np.testing.assert_array_equal(photo.luminance, reference.luminance)
    np.testing.assert_array_equal(photo.display, reference.display)


def test_all_black_and_all_white_are_not_errors(tmp_path):
    black = load_photo(write_png(tmp_path / "black.png", np.zeros((20, 20, 3), np.uint8)))
    white = load_photo(write_png(tmp_path / "white.png", np.full((20, 20, 3), 255, np.uint8)))
    assert black.luminance.max() == 0.0 and not black.clipped.any()
    assert np.allclose(white.luminance, 1.0) and white.clipped.all()


# --------------------------------------------------------------------------------------
# Colour spaces
# --------------------------------------------------------------------------------------


def adobe_decode(v):
    return np.clip(v, 0, 1) ** ADOBE_GAMMA


def test_adobe_rgb_icc_uses_gamma_563_over_256(tmp_path):
    """An embedded Adobe RGB (1998) profile (built here: photo 01's embedded profile is sRGB)."""
    import io

    from PIL import ImageCms

    icc = make_icc_profile("Adobe RGB (1998)")
    littlecms = ImageCms.ImageCmsProfile(io.BytesIO(icc))  # the hand-built profile is valid for LittleCMS
    assert ImageCms.getProfileDescription(littlecms).strip() == "Adobe RGB (1998)"
    codes = random_codes((24, 32, 3), 8, seed=30)
    photo = load_photo(write_png(tmp_path / "adobe.png", codes, icc=icc))
    assert photo.colour_space == "Adobe RGB (1998)"
    assert photo.linearisation == "Adobe RGB (1998) from embedded ICC profile 'Adobe RGB (1998)': gamma 563/256"
    expected = expected_luminance(codes, 8, adobe_decode, ADOBE_WEIGHTS)
    np.testing.assert_allclose(photo.luminance, expected, rtol=0, atol=EXACT)
    srgb_reading = expected_luminance(codes, 8)
    assert np.abs(srgb_reading - expected).max() > 100 * EXACT  # the test can tell the two apart


def test_adobe_rgb_icc_in_jpeg(tmp_path):
    icc = make_icc_profile("Adobe RGB (1998)")
    photo = load_photo(
        write_jpeg(tmp_path / "adobe.jpg", grey_patches([0.18], encode=lambda x: x ** (1 / ADOBE_GAMMA)), icc=icc)
    )
    assert photo.colour_space == "Adobe RGB (1998)"
    code = round(0.18 ** (1 / ADOBE_GAMMA) * 255)
    assert patch_medians(photo.luminance, 1)[0] == pytest.approx(
        adobe_decode(code / 255), abs=adobe_decode((code + 1) / 255) - adobe_decode(code / 255)
    )


def test_exif_interop_r03_means_adobe_rgb(tmp_path):
    codes = random_codes((20, 20, 3), 8, seed=31)
    exif = exif_for(colour_space=0xFFFF, interop_index="R03")
    photo = load_photo(write_png(tmp_path / "dcf.png", codes, exif=exif))
    assert photo.colour_space == "Adobe RGB (1998)" and "InteropIndex R03" in photo.linearisation
    np.testing.assert_allclose(photo.luminance, expected_luminance(codes, 8, adobe_decode, ADOBE_WEIGHTS), atol=EXACT)


@pytest.mark.parametrize(
    "exif,needle",
    [
        (exif_for(colour_space=1), "sRGB from EXIF ColorSpace 1"),
        (exif_for(colour_space=0xFFFF), "assumed: EXIF ColorSpace says Uncalibrated"),
        (None, "sRGB transfer (assumed: the file states no colour space)"),
    ],
)
def test_exif_colour_space(tmp_path, exif, needle):
    photo = load_photo(write_jpeg(tmp_path / "cs.jpg", grey_patches([0.5]), exif=exif))
    assert photo.colour_space == "sRGB" and needle in photo.linearisation


def test_unknown_icc_profile_uses_its_own_curve_and_colorants(tmp_path):
    icc = make_icc_profile("bokehfit test gamma 1.8", gamma_u8f8=461, colorants=SRGB_COLORANTS)
    codes = random_codes((16, 24, 3), 8, seed=32)
    photo = load_photo(write_png(tmp_path / "g18.png", codes, icc=icc))
    ys = np.round(np.array([c[1] for c in SRGB_COLORANTS]) * 65536) / 65536  # as stored: s15Fixed16
    expected = expected_luminance(codes, 8, lambda v: v ** (461 / 256), ys / ys.sum())
    np.testing.assert_allclose(photo.luminance, expected, rtol=0, atol=EXACT)
    assert "gamma 461/256" in photo.linearisation and "not a known space" in photo.linearisation


@pytest.mark.parametrize(
    "name,space", [("Display P3", "Display P3"), ("ProPhoto RGB", "ProPhoto RGB"), ("sRGB IEC61966-2.1", "sRGB")]
)
def test_icc_profiles_recognised_by_name(tmp_path, name, space):
    from bokehfit.io.colour import colour_science

    colour = colour_science()

    codes = random_codes((16, 16, 3), 8, seed=33)
    photo = load_photo(write_png(tmp_path / "named.png", codes, icc=make_icc_profile(name)))
    assert photo.colour_space == space
    model = colour.RGB_COLOURSPACES[space]
    expected = model.cctf_decoding(codes / 255.0) @ np.asarray(model.matrix_RGB_to_XYZ)[1]
    np.testing.assert_allclose(photo.luminance, expected, rtol=0, atol=EXACT)


def test_png_chunks_srgb_and_gamma(tmp_path):
    codes = random_codes((16, 16, 3), 8, seed=34)
    srgb = load_photo(write_png(tmp_path / "srgb.png", codes, srgb=True, gamma=0.45455))
    assert srgb.colour_space == "sRGB" and "PNG sRGB chunk" in srgb.linearisation
    linear = load_photo(write_png(tmp_path / "linear.png", codes, gamma=1.0))
    assert "PNG gAMA chunk 1" in linear.linearisation
    np.testing.assert_allclose(linear.luminance, (codes / 255.0) @ SRGB_WEIGHTS, rtol=0, atol=EXACT)


# --------------------------------------------------------------------------------------
# Orientation
# --------------------------------------------------------------------------------------


def marked_image():
    """40×24 mid grey, a saturated 8×8 square at the stored top-left corner."""
    image = np.full((24, 40, 3), 128, dtype=np.uint8)
    image[:8, :8] = 255
    return image


@pytest.mark.parametrize("orientation,corner", [(6, "top-right"), (8, "bottom-left")])
def test_jpeg_orientation_6_and_8(tmp_path, orientation, corner):
    path = write_jpeg(tmp_path / f"o{orientation}.jpg", marked_image(), exif=exif_for(orientation=orientation))
    photo = load_photo(path)
    assert (photo.width, photo.height) == (24, 40) and photo.exif.orientation == orientation
    rows, cols = (slice(2, 6), slice(18, 22)) if corner == "top-right" else (slice(34, 38), slice(2, 6))
    for image in (photo.luminance, photo.clipped, photo.display[..., 1]):
        assert image.shape == (40, 24)
    assert photo.clipped[rows, cols].all() and photo.clipped.sum() <= 8 * 8
    assert photo.luminance[rows, cols].min() > 0.98 and photo.display[rows, cols].min() >= 250
    assert photo.luminance[20, 12] == pytest.approx(srgb_decode(128 / 255), abs=0.01)


@pytest.mark.parametrize("orientation", range(1, 9))
def test_every_orientation_matches_pillow(tmp_path, orientation):
    from PIL import Image, ImageOps

    codes = random_codes((20, 36, 3), 8, seed=40)
    path = write_png(tmp_path / "o.png", codes, exif=exif_for(orientation=orientation))
    photo = load_photo(path)
    with Image.open(path) as image:
        expected = np.asarray(ImageOps.exif_transpose(image).convert("RGB"))
    np.testing.assert_array_equal(photo.display, expected)
    np.testing.assert_allclose(photo.luminance, expected_luminance(expected, 8), atol=EXACT)
    np.testing.assert_array_equal(photo.clipped, (expected == 255).any(axis=2))


# --------------------------------------------------------------------------------------
# Camera raw (a synthetic DNG through LibRaw)
# --------------------------------------------------------------------------------------

BLACK, WHITE, GREY = 256, 4095, 1000
# (r0, r1, c0, c1, raw value); even bounds so each patch holds whole RGGB quads.
PATCH_DOUBLE = (10, 22, 10, 22, BLACK + 2 * GREY)
PATCH_HALF = (40, 56, 60, 76, BLACK + GREY // 2)
PATCH_SATURATED = (10, 22, 40, 52, WHITE)


def dng(tmp_path, name="synthetic.dng", orientation=1, **tags):
    mosaic = bayer_mosaic(64, 96, BLACK, GREY, [PATCH_DOUBLE, PATCH_HALF, PATCH_SATURATED])
    return write_dng(tmp_path / name, mosaic, white=WHITE, black=BLACK, orientation=orientation, **tags)


def interior(image, patch, margin=3):
    r0, r1, c0, c1, _ = patch
    return image[r0 + margin : r1 - margin, c0 + margin : c1 - margin]


def test_dng_is_linear_with_white_level_one(tmp_path):
    """Patch ratios survive within 1 %; the grey field is (1000 above black) / (4095 − 256)."""
    photo = load_photo(dng(tmp_path, make="Bokehfit", model="Test Body"))
    assert photo.raw and photo.colour_space == "camera raw → sRGB primaries (linear)"
    assert "white level 4095" in photo.linearisation and "gamma 1" in photo.linearisation
    assert (photo.width, photo.height) == (96, 64)
    grey = np.median(photo.luminance[30:60, 4:50])
    assert grey == pytest.approx(GREY / (WHITE - BLACK), rel=0.01)
    assert np.median(interior(photo.luminance, PATCH_DOUBLE)) / grey == pytest.approx(2.0, rel=0.01)
    assert np.median(interior(photo.luminance, PATCH_HALF)) / grey == pytest.approx(0.5, rel=0.01)
    assert np.median(interior(photo.luminance, PATCH_SATURATED)) == pytest.approx(1.0, rel=0.01)
    assert photo.exif.camera == "Bokehfit Test Body"


def test_dng_clipped_mask_covers_the_saturated_patch_only(tmp_path):
    photo = load_photo(dng(tmp_path))
    r0, r1, c0, c1, _ = PATCH_SATURATED
    assert photo.clipped[r0:r1, c0:c1].all()
    grown = np.zeros_like(photo.clipped)
    grown[r0 - 1 : r1 + 1, c0 - 1 : c1 + 1] = True  # the 3×3 demosaicing neighbourhood
    assert not (photo.clipped & ~grown).any()


def test_dng_orientation_6_is_portrait(tmp_path):
    photo = load_photo(dng(tmp_path, orientation=6))
    assert (photo.width, photo.height) == (64, 96) and photo.exif.orientation == 6
    upright = load_photo(dng(tmp_path, name="upright.dng"))
    np.testing.assert_array_equal(photo.luminance, np.rot90(upright.luminance, -1))
    np.testing.assert_array_equal(photo.clipped, np.rot90(upright.clipped, -1))


# --------------------------------------------------------------------------------------
# Bad input: one-line InputError, the file untouched
# --------------------------------------------------------------------------------------


def _small_jpeg(tmp_path, name="small.jpg", shape=(32, 48, 3)):
    return write_jpeg(tmp_path / name, np.full(shape, 100, np.uint8))


def _huge_jpeg_header(tmp_path):
    data = bytearray(_small_jpeg(tmp_path, "huge.jpg").read_bytes())
    sof = data.index(b"\xff\xc0")
    data[sof + 5 : sof + 9] = (30000).to_bytes(2, "big") * 2
    (tmp_path / "huge.jpg").write_bytes(bytes(data))
    return tmp_path / "huge.jpg"


def _huge_png_header(tmp_path):
    data = bytearray(write_png(tmp_path / "huge.png", np.zeros((20, 20), np.uint8)).read_bytes())
    data[16:24] = (30000).to_bytes(4, "big") * 2
    (tmp_path / "huge.png").write_bytes(bytes(data))
    return tmp_path / "huge.png"


def _truncated(tmp_path, source, fraction=0.6):
    data = source.read_bytes()
    target = source.with_name("cut_" + source.name)
    target.write_bytes(data[: int(len(data) * fraction)])
    return target


def _pillow_file(tmp_path, name, fmt, mode="RGB"):
    from PIL import Image

    Image.new(mode, (32, 32)).save(tmp_path / name, fmt)
    return tmp_path / name


def _write(path, data: bytes | str):
    path.write_bytes(data.encode() if isinstance(data, str) else data)
    return path


BAD_INPUTS = {
    "missing": (lambda t: t / "nope.jpg", "does not exist"),
    "folder": (lambda t: t, "is a folder"),
    "empty": (lambda t: _write(t / "empty.jpg", b""), "is empty (0 bytes)"),
    "truncated_jpeg": (
        lambda t: _truncated(t, write_jpeg(t / "r.jpg", random_codes((64, 64, 3), 8, 1))),
        "truncated JPEG",
    ),
    "truncated_tiff": (
        lambda t: _truncated(t, write_tiff(t / "r.tif", random_codes((64, 64, 3), 16, 1))),
        "could not be decoded as a TIFF",
    ),
    "truncated_png": (
        lambda t: _truncated(t, write_png(t / "r.png", random_codes((64, 64, 3), 8, 1))),
        "truncated PNG",
    ),
    "damaged_jpeg": (lambda t: _write(t / "d.jpg", b"\xff\xd8\xff\xe0\x00\x04ab" + b"garbage" * 9), "damaged JPEG"),
    "text_named_jpg": (
        lambda t: _write(t / "notes.jpg", "hello, not a photo\n"),
        "is not a JPEG, PNG, TIFF or camera raw file",
    ),
    "gif": (lambda t: _pillow_file(t, "a.gif", "GIF", "P"), "is a GIF file"),
    "bmp": (lambda t: _pillow_file(t, "a.bmp", "BMP"), "is a BMP file"),
    "webp": (lambda t: _pillow_file(t, "a.webp", "WEBP"), "is a WebP file"),
    "one_pixel": (
        lambda t: write_png(t / "dot.png", np.zeros((1, 1, 3), np.uint8)),
        "image is 1×1 px; bokehfit needs at least 16 px a side",
    ),
    "thin": (
        lambda t: _small_jpeg(t, "thin.jpg", (15, 100, 3)),
        "image is 100×15 px; bokehfit needs at least 16 px a side",
    ),
    "huge_jpeg_header": (_huge_jpeg_header, "30000×30000 px (900 megapixels), more than the limit of 250 megapixels"),
    "huge_png_header": (_huge_png_header, "30000×30000 px (900 megapixels)"),
    "all_nan_tiff": (lambda t: write_tiff(t / "nan.tif", np.full((20, 20), np.nan, np.float32)), "no finite sample"),
    "palette_tiff": (lambda t: _pillow_file(t, "p.tif", "TIFF", "P"), "palette TIFF"),
    "garbage_raw": (
        lambda t: _write(t / "x.cr2", np.random.default_rng(0).bytes(5000)),
        "could not be read as camera raw",
    ),
    "text_named_dng": (lambda t: _write(t / "x.dng", "not raw\n" * 100), "could not be read as camera raw"),
}


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_input_is_a_one_line_input_error(tmp_path, monkeypatch, capfd, case):
    make, needle = BAD_INPUTS[case]
    path = make(tmp_path)
    before = file_state(path) if path.is_file() else None

    def no_decoding(*args, **kwargs):
        raise AssertionError("the image was decoded before its header was checked")

    if case.startswith("huge"):
        monkeypatch.setattr(cv2, "imdecode", no_decoding)
    with pytest.raises(InputError) as caught:
        load_photo(path)
    message = str(caught.value)
    assert needle in message
    assert "\n" not in message and caught.value.exit_code == 2
    assert capfd.readouterr() == ("", ""), "decoders must not print: the message is the one line"
    if before is not None:
        assert file_state(path) == before


def test_max_pixels_is_checked_before_decoding(tmp_path, monkeypatch):
    import tifffile

    tiff = write_tiff(tmp_path / "t.tif", random_codes((64, 64, 3), 8, 2))
    monkeypatch.setattr(tifffile.TiffPage, "asarray", lambda *a, **k: pytest.fail("decoded before the size check"))
    with pytest.raises(InputError, match="more than the limit of 0.001 megapixels"):
        load_photo(tiff, max_pixels=1000)
    with pytest.raises(InputError, match="more than the limit"):
        load_photo(dng(tmp_path), max_pixels=1000)


@pytest.mark.parametrize("value", [0, -5, 1.5, True, "many"])
def test_max_pixels_must_be_a_positive_whole_number(tmp_path, value):
    with pytest.raises(InputError, match="max_pixels must be a positive whole number"):
        load_photo(_small_jpeg(tmp_path), max_pixels=value)


def test_min_side_constant_is_used(tmp_path):
    side = MIN_SIDE_PX
    assert load_photo(write_png(tmp_path / "ok.png", np.zeros((side, side), np.uint8))).width == side


# --------------------------------------------------------------------------------------
# The Photo object, progress
# --------------------------------------------------------------------------------------


def test_photo_arrays_and_json(tmp_path):
    photo = load_photo(write_jpeg(tmp_path / "p.jpg", random_codes((24, 40, 3), 8, 50)))
    assert photo.luminance.dtype == np.float32 and photo.luminance.shape == (24, 40)
    assert photo.clipped.dtype == np.bool_ and photo.clipped.shape == (24, 40)
    assert photo.display.dtype == np.uint8 and photo.display.shape == (24, 40, 3)
    for array in (photo.luminance, photo.clipped, photo.display):
        assert not array.flags.writeable
    document = photo.input_json()
    assert set(document) == {"path", "width", "height", "raw", "exif", "linearisation", "colour_space", "notes"}
    assert document["notes"] == []
    assert set(document["exif"]) == set(Exif.__dataclass_fields__)
    assert json.loads(json.dumps(document)) == document


def test_progress_bar_only_when_asked_and_big(tmp_path, monkeypatch, capsys):
    path = write_png(tmp_path / "p.png", random_codes((300, 300, 3), 8, 51))
    load_photo(path, progress=True)  # 90 000 px: below the threshold
    assert capsys.readouterr().err == ""
    monkeypatch.setattr(linear_module, "PROGRESS_MIN_PIXELS", 10_000)
    load_photo(path, progress=False)
    assert capsys.readouterr() == ("", "")
    load_photo(path, progress=True)
    captured = capsys.readouterr()
    assert "loading p.png" in captured.err and captured.out == ""


# --------------------------------------------------------------------------------------
# Real photos (BOKEHFIT_REFERENCE_DIR)
# --------------------------------------------------------------------------------------


def test_reference_photo_01_colour_space():
    """Photo 01's embedded ICC profile is sRGB IEC61966-2.1 (GIMP re-saved it), though its XMP
    still names Adobe RGB (1998): the profile in the file decides, and the note says so."""
    photo = load_photo(reference_photo("01_water-glints_canon6d_ef85.jpg"))
    assert (photo.width, photo.height) == (2560, 1600)
    assert photo.colour_space == "sRGB"
    assert photo.linearisation.startswith("sRGB from embedded ICC profile 'sRGB IEC61966-2.1'")
    assert "XMP photoshop:ICCProfile names 'Adobe RGB (1998)'" in photo.linearisation


@pytest.mark.parametrize(
    "name,assumed",
    [
        ("02_dew-glints_aaron-burden.jpg", False),  # embedded sRGB profile and EXIF ColorSpace 1
        ("03_frosted-grass_pixabay-1358926.jpg", True),
        ("04_juniper-droplet-rings_pablo-garcia-saldana.jpg", True),
        ("05_backlit-grass_unsplash-522b53fb137bb.jpg", True),
    ],
)
def test_reference_photos_02_to_05(name, assumed):
    photo = load_photo(reference_photo(name))
    entry = manifest_entry(name)
    assert (photo.width, photo.height) == (entry["width"], entry["height"])
    assert photo.colour_space == "sRGB" and ("assumed" in photo.linearisation) == assumed
    assert photo.exif.camera is None and photo.exif.sensor_width_mm is None
    assert 0.0 <= float(photo.luminance.min()) and float(photo.luminance.max()) <= 1.0
