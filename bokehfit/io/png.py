"""PNG: the chunk walk, the metadata inflate budget, iTXt (XMP), the size bound, decoding.

:func:`load_png` reads the chunks by hand (size, ICC profile, sRGB, gAMA, eXIf, XMP: every length
checked against the file's size first, metadata inflated within :data:`METADATA_INFLATE_BUDGET_BYTES`),
refuses a size the image data can't hold (:data:`DEFLATE_MAX_RATIO`), and decodes with OpenCV
(libpng); damaged image data is refused, libpng's warnings about other chunks become a note.
"""

from __future__ import annotations

import math
import struct
import zlib
from pathlib import Path

import numpy as np

from bokehfit.errors import InputError
from bokehfit.io.decoders import imdecode, short
from bokehfit.io.exif import build_exif
from bokehfit.io.files import METADATA_MAX_BYTES, Meta, check_size, encoding_for
from bokehfit.io.linear import Photo, linearise_integer, make_photo, orient, progress_for
from bokehfit.io.tags import read_exif_tags
from bokehfit.io.xmp import XMP_MAX_BYTES

__all__ = ["DEFLATE_MAX_RATIO", "METADATA_INFLATE_BUDGET_BYTES", "PNG_SIGNATURE", "load_png"]

#: Most bytes inflated from all the metadata chunks of one file together (ICC profile, XMP): a file of
#: ten thousand compressed chunks costs no more than a few legitimate ones; past it, the rest is skipped.
METADATA_INFLATE_BUDGET_BYTES = 4 * METADATA_MAX_BYTES
#: Largest ratio of deflate: one length code (≥ 1 bit) and one distance code (≥ 1 bit) repeat at
#: most 258 bytes, so 2 bits give at most 258 bytes (RFC 1951 §3.2.5): 1032 bytes per byte.
DEFLATE_MAX_RATIO = 1032
#: The eight bytes every PNG file starts with.
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_header(name: str, data: bytes) -> Meta:
    """Parse a PNG's chunks: size, ICC profile, sRGB, gAMA, eXIf, XMP."""
    meta = Meta()
    exif_blob = None
    truncated = f"{name} is a truncated PNG file (it ends before its IEND chunk); copy or export it again"
    i, n = 8, len(data)
    first = True
    budget = _InflateBudget(METADATA_INFLATE_BUDGET_BYTES)
    icc_seen = False
    while True:
        if i + 8 > n:
            raise InputError(truncated)
        length, kind = struct.unpack(">I4s", data[i : i + 8])
        if i + 12 + length > n:  # checked before anything is read
            raise InputError(truncated)
        wanted = kind in (b"IHDR", b"iCCP", b"sRGB", b"gAMA", b"eXIf", b"iTXt")
        cap = XMP_MAX_BYTES if kind == b"iTXt" else METADATA_MAX_BYTES
        if wanted and length > cap:
            meta.notes.append(
                f"{name}: its {kind.decode('latin-1')} chunk holds {length} bytes, more than the {cap} read; skipped"
            )
            wanted = False
        body = data[i + 8 : i + 8 + length] if wanted else b""
        if first:
            if kind != b"IHDR" or length < 13:
                raise InputError(f"{name} is a damaged PNG file (no IHDR chunk); re-export it")
            meta.width, meta.height = struct.unpack(">II", body[:8])
            meta.bits_per_pixel = body[8] * _PNG_CHANNELS.get(body[9], 4)
            first = False
        elif kind == b"IDAT":
            meta.image_data_bytes += length
        elif kind == b"iCCP" and wanted and icc_seen:
            budget.skipped += 1  # the PNG standard allows one; the first counts
        elif kind == b"iCCP" and wanted:
            icc_seen = True
            try:
                separator = body.index(b"\x00")
                meta.icc = budget.inflate(body[separator + 2 :], METADATA_MAX_BYTES)
            except (ValueError, zlib.error):
                meta.icc = None
            if meta.icc is None and length:
                meta.notes.append(f"{name}: its ICC profile is damaged or inflates past {METADATA_MAX_BYTES} bytes; ignored")
        elif kind == b"sRGB":
            meta.png_srgb = True
        elif kind == b"gAMA" and length == 4:
            meta.png_gamma = struct.unpack(">I", body)[0] / 100000.0 or None
        elif kind == b"eXIf" and wanted:
            exif_blob = body
        elif kind == b"iTXt" and body.startswith(b"XML:com.adobe.xmp\x00") and meta.xmp is not None:
            budget.skipped += 1
        elif kind == b"iTXt" and body.startswith(b"XML:com.adobe.xmp\x00"):
            meta.xmp = _itxt_text(body, XMP_MAX_BYTES, budget)
            if meta.xmp is None:
                meta.notes.append(f"{name}: its XMP packet is damaged or inflates past {XMP_MAX_BYTES} bytes; ignored")
        elif kind == b"IEND":
            break
        i += 12 + length
    if budget.skipped:
        meta.notes.append(f"{name}: {budget.skipped} more ICC or XMP chunks than the one of each a PNG may hold, or past the"
                          f" {METADATA_INFLATE_BUDGET_BYTES} bytes inflated per file; skipped")
    meta.exif = read_exif_tags(exif_blob)
    return meta


#: Channels of each PNG colour type (grey, RGB, palette, grey + alpha, RGBA).
_PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}


class _InflateBudget:
    """The bytes that one file's metadata chunks may inflate to, all together."""

    def __init__(self, total: int):
        self.left, self.skipped = total, 0

    def inflate(self, data: bytes, cap: int) -> bytes | None:
        """:func:`_inflate` within what is left; a chunk past the budget is skipped (None) and counted."""
        if self.left <= 0:
            self.skipped += 1
            return None
        out = _inflate(data, min(cap, self.left))
        self.left -= min(cap, self.left) if out is None else len(out)
        return out


def _check_png_data_size(name: str, meta: "Meta") -> None:
    """``InputError`` if the image data claimed by the header can't come out of the file's IDAT bytes.

    Unfiltered rows are ``height × (1 + ⌈width × bits per pixel / 8⌉)`` bytes, and deflate gives at most
    :data:`DEFLATE_MAX_RATIO` bytes per byte; the zlib header and Adam7's extra filter bytes get a margin.
    """
    raw = meta.height * (1 + math.ceil(meta.width * meta.bits_per_pixel / 8))
    if raw > DEFLATE_MAX_RATIO * (meta.image_data_bytes + 64) + 16 * meta.height:
        raise InputError(
            f"{name}: its header claims {meta.width}×{meta.height} px, which {meta.image_data_bytes} bytes of PNG image"
            f" data can't hold (deflate packs at most {DEFLATE_MAX_RATIO} bytes a byte); the file is truncated or crafted:"
            " copy or export it again"
        )


def _inflate(data: bytes, cap: int) -> bytes | None:
    """zlib-decompressed ``data``, or None when it would be longer than ``cap`` bytes.

    At most ``cap + 1`` bytes are ever produced: a small chunk that inflates to
    gigabytes costs no more than a legitimate one.
    """
    inflater = zlib.decompressobj()
    out = inflater.decompress(data, cap + 1)
    return None if len(out) > cap else out


def _itxt_text(body: bytes, cap: int, budget: "_InflateBudget | None" = None) -> bytes | None:
    """The text of an iTXt chunk (decompressed up to ``cap`` bytes), or None."""
    try:
        keyword_end = body.index(b"\x00")
        compressed = body[keyword_end + 1]
        rest = body[keyword_end + 3 :]
        rest = rest[rest.index(b"\x00") + 1 :]  # language tag
        rest = rest[rest.index(b"\x00") + 1 :]  # translated keyword
        if not compressed:
            return rest
        return budget.inflate(rest, cap) if budget is not None else _inflate(rest, cap)
    except (ValueError, IndexError, zlib.error):
        return None


def load_png(path: Path, data: bytes, max_pixels: int, progress: bool) -> Photo:
    meta = _png_header(path.name, data)
    check_size(path.name, meta.width, meta.height, max_pixels)
    _check_png_data_size(path.name, meta)
    exif = build_exif(meta.exif, meta.xmp, width_px=meta.width, height_px=meta.height)
    encoding = encoding_for(meta)
    bar = progress_for(path.name, meta.width, meta.height, exif.orientation, progress)
    try:
        pixels, messages = imdecode(data)
        if pixels is None or pixels.shape[:2] != (meta.height, meta.width):
            said = f": {short(Exception(messages[0]))}" if messages else ""
            raise InputError(f"{path.name} could not be decoded as a PNG (damaged image data{said}); re-export it")
        if messages:  # libpng stops at errors in the image data: these are warnings about other chunks
            said = short(Exception(" ".join(messages[0].split()).removeprefix("libpng warning: ")))
            more = f" (+{len(messages) - 1} more)" if len(messages) > 1 else ""
            meta.notes.append(f"{path.name}: the PNG decoder warned ({said}{more}); the image data decoded in full")
        bits = 16 if pixels.dtype == np.uint16 else 8
        if pixels.ndim == 3:
            pixels = pixels[..., :3] if pixels.shape[2] >= 3 else pixels[..., 0]  # drop alpha
        pixels = orient(np.ascontiguousarray(pixels), exif.orientation)
        bar.step("decode")
        luminance, clipped, display = linearise_integer(pixels, bits, "BGR", encoding, bar)
    finally:
        bar.close()
    return make_photo(
        path, luminance, clipped, display, False, exif, encoding.describe(), encoding.colour_space, meta.notes,
        decoding=encoding.lut(8),
    )
