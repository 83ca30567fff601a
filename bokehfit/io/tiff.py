"""TIFF: 8/16-bit and float, the strip and tile size bound, decoding; a DNG named .tif goes to raw.

:func:`load_tiff` reads the first page with tifffile (OpenCV's libtiff where tifffile lacks a
codec), refuses a size its strips' or tiles' bytes can't hold, and linearises; float TIFFs have
their NaN and Inf samples masked, are scaled where their white point says other units
(:data:`FLOAT_WHITE_MAX`) and clamped at :data:`FLOAT_SAMPLE_MAX`, each counted in a note.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from bokehfit.errors import InputError
from bokehfit.io.colour import linear_encoding, luminance_weights
from bokehfit.io.decoders import imdecode, short
from bokehfit.io.exif import Exif, build_exif
from bokehfit.io.files import METADATA_MAX_BYTES, Meta, check_size, encoding_for
from bokehfit.io.jpeg import JPEG_MAX_PIXELS_PER_BYTE
from bokehfit.io.linear import (
    Photo,
    Progress,
    display_from_linear,
    linearise_integer,
    make_photo,
    orient,
    progress_for,
    row_blocks,
)
from bokehfit.io.png import DEFLATE_MAX_RATIO
from bokehfit.io.raw import load_raw
from bokehfit.io.tags import read_exif_tags
from bokehfit.io.xmp import XMP_MAX_BYTES

__all__ = ["FLOAT_SAMPLE_MAX", "FLOAT_WHITE_MAX", "load_tiff"]

#: Float TIFFs whose robust white point (99.9th percentile of the luminance) is above this are
#: taken to be in other units and scaled so that it is 1 (linear float files put white at 1.0;
#: HDR merges reach a few hundred).
FLOAT_WHITE_MAX = 1e4
#: Float samples above this, after any scaling, are clamped to it and marked clipped: beyond
#: it, squares of the values overflow float32 (bokehfit.discs.MAX_LUMINANCE is the same bound).
FLOAT_SAMPLE_MAX = 1e6


def load_tiff(path: Path, data: bytes, max_pixels: int, progress: bool) -> Photo:
    import io

    import tifffile

    try:
        tif = tifffile.TiffFile(io.BytesIO(data))
    except Exception as error:  # noqa: BLE001 - tifffile raises many kinds for damaged files
        raise InputError(f"{path.name} is a damaged TIFF file ({short(error)}); re-export it") from None
    with tif:
        if not tif.pages:
            raise InputError(f"{path.name} is a TIFF file without images; re-export it")
        page = tif.pages.first
        tags = read_exif_tags(data)
        if 50706 in tags.ifd0 or page.tags.get(50706) is not None:  # DNGVersion: a DNG named .tif
            return load_raw(path, max_pixels, progress)
        width, height = int(page.imagewidth), int(page.imagelength)
        check_size(path.name, width, height, max_pixels)
        depth = int(getattr(page, "imagedepth", 1) or 1)
        if depth != 1:
            raise InputError(f"{path.name} is a volume TIFF (ImageDepth {depth}), not a photo; save one image as TIFF")
        _check_tiff_data_size(path.name, page, width, height)
        photometric = int(page.photometric)
        if photometric in (3, 5, 8, 32803, 34892) or page.bitspersample == 1:
            kind = {3: "palette", 5: "CMYK", 8: "CIELab", 32803: "raw CFA", 34892: "linear raw"}.get(
                photometric, "bilevel"
            )
            raise InputError(f"{path.name} is a {kind} TIFF; save it as an RGB or grey TIFF (8/16-bit or float)")
        icc = tags.ifd0.get(34675)
        xmp = tags.ifd0.get(700)
        meta = Meta(
            width, height, tags, xmp if isinstance(xmp, bytes) else None, icc if isinstance(icc, bytes) else None
        )
        for what, attribute, cap in (("XMP packet", "xmp", XMP_MAX_BYTES), ("ICC profile", "icc", METADATA_MAX_BYTES)):
            if getattr(meta, attribute) is not None and len(getattr(meta, attribute)) > cap:
                meta.notes.append(f"{path.name}: its {what} holds {len(getattr(meta, attribute))} bytes, more than"
                                  f" the {cap} read; skipped")
                setattr(meta, attribute, None)
        exif = build_exif(tags, meta.xmp, width_px=width, height_px=height)
        bar = progress_for(path.name, width, height, exif.orientation, progress)
        try:
            pixels, order = _decode_tiff(path.name, page, data)
            bar.step("decode")
            if pixels.shape[:2] != (height, width):
                raise InputError(f"{path.name} could not be decoded as a TIFF (damaged image data); re-export it")
            if pixels.ndim == 3:
                pixels = pixels[..., :3] if pixels.shape[2] >= 3 else pixels[..., 0]  # drop alpha
            if photometric == 0 and pixels.dtype.kind == "u":  # MINISWHITE
                pixels = np.iinfo(pixels.dtype).max - pixels
            if pixels.dtype.kind == "f":
                return _finish_float_tiff(path, pixels, order, exif, bar, meta.notes)
            if pixels.dtype not in (np.uint8, np.uint16):
                raise InputError(f"{path.name} has {pixels.dtype} samples; save it as an 8/16-bit or float32 TIFF")
            pixels = orient(np.ascontiguousarray(pixels), exif.orientation)
            encoding = encoding_for(meta)
            bits = 8 if pixels.dtype == np.uint8 else 16
            luminance, clipped, display = linearise_integer(pixels, bits, order, encoding, bar)
        finally:
            bar.close()
    return make_photo(
        path, luminance, clipped, display, False, exif, encoding.describe(), encoding.colour_space, meta.notes,
        decoding=encoding.lut(8),
    )


#: Most bytes each TIFF compression can give per byte of its data: deflate 1032 (DEFLATE_MAX_RATIO);
#: LZW 4096 bytes per code of at least 9 bits, 3641; PackBits 128 bytes per 2, 64; JPEG 512 pixels a byte
#: (JPEG_MAX_PIXELS_PER_BYTE) of at most 3 bytes each. Other compressions are not bounded here.
_TIFF_MAX_RATIO = {5: 3641, 7: 3 * JPEG_MAX_PIXELS_PER_BYTE, 8: DEFLATE_MAX_RATIO, 32946: DEFLATE_MAX_RATIO, 32773: 64}


def _check_tiff_data_size(name: str, page, width: int, height: int) -> None:
    """``InputError`` if the image a TIFF's header claims can't come out of its strips' or tiles' bytes."""
    try:
        compression = int(page.compression)
        stored = sum(int(n) for n in page.databytecounts)
        bits = int(page.bitspersample) * int(page.samplesperpixel)
        pieces = len(page.databytecounts)
    except (TypeError, ValueError, AttributeError):
        return
    ratio = 1 if compression == 1 else _TIFF_MAX_RATIO.get(compression)
    if ratio is None:
        return
    raw = height * math.ceil(width * bits / 8)
    if raw > ratio * (stored + 64 * pieces) + 4096:
        raise InputError(
            f"{name}: its header claims {width}×{height} px, which {stored} bytes of image data"
            f" (compression {compression}) can't hold; the file is truncated or crafted: copy or export it again"
        )


def _decode_tiff(name: str, page, data: bytes) -> tuple[np.ndarray, str]:
    """The first page's pixels as (H, W) or (H, W, S), and their channel order."""
    try:
        array = page.asarray()
    except Exception as error:  # noqa: BLE001 - tifffile raises many kinds for damaged files
        if "imagecodecs" not in str(error):
            raise InputError(f"{name} could not be decoded as a TIFF ({short(error)}); re-export it") from None
        array = None  # LZW or JPEG compression without imagecodecs: OpenCV's libtiff decodes those
    if array is not None:
        axes = page.axes
        array = np.asarray(array)
        if "S" in axes and axes.index("S") < axes.index("Y"):
            array = np.moveaxis(array, axes.index("S"), -1)
        array = array.reshape(array.shape[-3:] if array.ndim >= 3 and "S" in axes else array.shape[-2:])
        return array, "RGB"
    pixels, _ = imdecode(data)
    if pixels is None:
        raise InputError(f"{name} could not be decoded as a TIFF (damaged or unsupported compression); re-export it")
    return pixels, "BGR"


def _robust_white(pixels: np.ndarray) -> float:
    """The 99.9th percentile of the finite, positive luminance of a float image (0 if none).

    Taken on a sample of at most about a million pixels, in float64 (float32 overflows
    for samples near its limit).
    """
    step = max(1, round(float(np.sqrt(pixels.shape[0] * pixels.shape[1] / 1e6))))
    sample = np.asarray(pixels[::step, ::step], dtype=np.float64)
    if sample.ndim == 3:
        with np.errstate(invalid="ignore", over="ignore"):
            sample = sample[..., :3] @ np.asarray(luminance_weights("sRGB"))
    sample = sample[np.isfinite(sample) & (sample > 0)]
    return float(np.percentile(sample, 99.9)) if sample.size else 0.0


def _finish_float_tiff(path: Path, pixels: np.ndarray, order: str, exif: Exif, bar: Progress, notes: list[str]) -> Photo:
    """Luminance, mask and display of a float TIFF (module docstring: masking, scaling, clamping)."""
    import cv2

    notes = list(notes)
    if pixels.ndim == 3 and order == "BGR":
        pixels = pixels[..., ::-1]
    white = _robust_white(pixels)
    scale = 1.0 / white if white > FLOAT_WHITE_MAX else 1.0
    out = np.empty(pixels.shape, dtype=np.float32)  # our own copy: masked, scaled and clamped in place
    nonfinite = np.zeros(pixels.shape[:2], dtype=np.bool_)
    unusable = np.zeros(pixels.shape[:2], dtype=np.bool_)
    masked = negatives = clamped = 0
    for r0, r1 in row_blocks(pixels.shape[0]):
        block = np.array(pixels[r0:r1], dtype=np.float64)
        bad = ~np.isfinite(block)
        if bad.any():
            block[bad] = 0.0
            bad_pixels = bad if bad.ndim == 2 else bad.any(axis=-1)
            masked += int(np.count_nonzero(bad_pixels))
            nonfinite[r0:r1] = bad_pixels
            unusable[r0:r1] |= bad_pixels
        if scale != 1.0:
            block *= scale
        below = block < 0
        negatives += int(np.count_nonzero(below))
        block[below] = 0.0
        above = block > FLOAT_SAMPLE_MAX
        if above.any():
            above_pixels = above if above.ndim == 2 else above.any(axis=-1)
            clamped += int(np.count_nonzero(above_pixels))
            unusable[r0:r1] |= above_pixels
            block[above] = FLOAT_SAMPLE_MAX
        out[r0:r1] = block
    if masked == unusable.size:
        raise InputError(f"{path.name} has no finite sample (all are NaN or Inf); check the file")
    pixels = orient(out, exif.orientation)
    unusable = orient(unusable, exif.orientation)
    nonfinite = orient(nonfinite, exif.orientation)
    height, width = pixels.shape[:2]
    encoding = linear_encoding("float TIFF")
    luminance = np.empty((height, width), dtype=np.float32)
    if pixels.ndim == 2:
        luminance[...] = pixels
    else:
        weights = np.asarray([luminance_weights("sRGB")], dtype=np.float32)
        for r0, r1 in row_blocks(height):
            cv2.transform(pixels[r0:r1], weights, dst=luminance[r0:r1])
            bar.step("linearise")
    if masked:
        # Fill the masked pixels from their neighbours, so that they make no edges of their own.
        luminance = cv2.inpaint(luminance, nonfinite.view(np.uint8), 3, cv2.INPAINT_TELEA)
        notes.append(
            f"{path.name}: {masked} pixels with NaN or Inf samples masked (filled from their neighbours,"
            " flagged like clipped pixels, so that no disc containing them is used)"
        )
    display = display_from_linear(pixels, 1.0)
    bar.step("display")
    text = "linear float TIFF (sRGB primaries assumed, 1.0 = white)"
    if scale != 1.0:
        text += f"; scaled by {scale:.3g} so that the robust white point (99.9th percentile, {white:.3g}) is 1"
        notes.append(
            f"{path.name}: values up to {white:.3g} at the 99.9th percentile, far above 1.0 = white: scaled by"
            f" {scale:.3g}"
        )
    if negatives:
        text += f"; {negatives} negative values clamped to 0"
    if clamped:
        notes.append(f"{path.name}: {clamped} pixels above {FLOAT_SAMPLE_MAX:g} clamped there and flagged like clipped pixels")
    return make_photo(path, luminance, unusable, display, False, exif, text, encoding.colour_space, notes)
