"""JPEG: the marker walk up to the first scan, the size bound, CMYK and YCCK conversion, decoding.

:func:`load_jpeg` reads the header by hand (size, EXIF, XMP, ICC profile: every segment length is
checked against the file's size first), refuses a size the file's bytes can't hold
(:data:`JPEG_MAX_PIXELS_PER_BYTE`), and decodes with OpenCV straight into the display's array
(CMYK and YCCK through Pillow and littleCMS); corrupt image data is read as far as it goes, with
a note.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np

from bokehfit.errors import InputError
from bokehfit.io.colour import icc_description, named_encoding
from bokehfit.io.decoders import damage_note, imdecode, library_messages, short
from bokehfit.io.exif import build_exif
from bokehfit.io.files import METADATA_MAX_BYTES, Meta, check_size, encoding_for
from bokehfit.io.linear import Photo, linearise_integer, make_photo, orient, progress_for
from bokehfit.io.tags import read_exif_tags

__all__ = ["JPEG_MAX_PIXELS_PER_BYTE", "load_jpeg"]

#: Most pixels a Huffman-coded JPEG may claim per byte of the file. Every 8×8 block of the luminance
#: is coded in the first (DC) scan with at least one bit (Huffman codes are 1 to 16 bits long, ITU T.81
#: Annex C), so a file of B bytes holds at most 8·B blocks, 512·B pixels, whatever the image; lossless
#: JPEG spends a bit a pixel at least. Arithmetic coding (SOF9–SOF15, rare: no camera writes it) can
#: code a flat block in less than a bit, so for it the bound is not a theorem but a photo's: a 24-MP
#: frame would have to fit in 47 kB, which only a nearly all-black frame does, and a refused file is
#: told to re-encode with Huffman coding. Without the bound, a 143 kB file claiming 15811² pixels
#: decoded for 40–117 s at 2.4 GB.
JPEG_MAX_PIXELS_PER_BYTE = 512
#: Start-of-frame markers of arithmetic-coded JPEGs (ITU T.81 Table B.1).
_ARITHMETIC_SOF = frozenset({0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF})
# Start-of-frame markers (baseline, extended, progressive, lossless; Huffman and arithmetic).
_SOF_MARKERS = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}

_XMP_JPEG = b"http://ns.adobe.com/xap/1.0/\x00"
_ICC_JPEG = b"ICC_PROFILE\x00"


def _jpeg_header(name: str, data: bytes) -> tuple[Meta, int]:
    """Parse a JPEG up to its first scan: size, EXIF, XMP, ICC profile; and the number of components."""
    meta = Meta()
    icc_chunks: dict[int, bytes] = {}
    exif_blob = None
    components = None
    i, n = 2, len(data)
    damaged = f"{name} is a damaged JPEG file (its header is corrupt); re-export it"
    truncated = f"{name} is a truncated JPEG file (it ends before the image data does); copy or export it again"
    while True:
        if i + 4 > n:
            raise InputError(truncated)
        if data[i] != 0xFF:
            raise InputError(damaged)
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker == 0x01 or 0xD0 <= marker <= 0xD8:  # markers without a length
            i += 2
            continue
        if marker == 0xD9:
            raise InputError(f"{name} is a JPEG file without image data; re-export it")
        (length,) = struct.unpack(">H", data[i + 2 : i + 4])
        if length < 2:
            raise InputError(damaged)
        if i + 2 + length > n:
            raise InputError(truncated)
        payload = data[i + 4 : i + 2 + length]
        if marker == 0xE1 and payload.startswith(b"Exif\x00\x00") and exif_blob is None:
            exif_blob = payload
        elif marker == 0xE1 and payload.startswith(_XMP_JPEG) and meta.xmp is None:
            meta.xmp = payload[len(_XMP_JPEG) :]
        elif marker == 0xE2 and payload.startswith(_ICC_JPEG) and len(payload) > 14:
            icc_chunks[payload[12]] = payload[14:]
        elif marker in _SOF_MARKERS and components is None:
            if len(payload) < 6:
                raise InputError(damaged)
            meta.height, meta.width = struct.unpack(">HH", payload[1:5])
            meta.arithmetic = marker in _ARITHMETIC_SOF
            components = payload[5]
        elif marker == 0xDA:
            break
        i += 2 + length
    if components is None:
        raise InputError(damaged)
    # Entropy-coded data stuffs every 0xFF with 0x00, so 0xFFD9 after the first scan is the end-of-image marker.
    if data.rfind(b"\xff\xd9", i) < 0:
        raise InputError(truncated)
    icc_size = sum(len(chunk) for chunk in icc_chunks.values())
    if icc_size > METADATA_MAX_BYTES:
        meta.notes.append(f"{name}: its ICC profile holds {icc_size} bytes, more than the {METADATA_MAX_BYTES} read; skipped")
    elif icc_chunks:
        meta.icc = b"".join(icc_chunks[k] for k in sorted(icc_chunks))
    meta.exif = read_exif_tags(exif_blob)
    return meta, components


def load_jpeg(path: Path, data: bytes, max_pixels: int, progress: bool) -> Photo:
    meta, components = _jpeg_header(path.name, data)
    if meta.width == 0 or meta.height == 0:
        raise InputError(f"{path.name} is a JPEG file that gives no image size; re-export it")
    check_size(path.name, meta.width, meta.height, max_pixels)
    blocks = math.ceil(meta.width / 8) * math.ceil(meta.height / 8)
    if blocks > 8 * len(data):  # a bit per 8×8 block of the luminance at least (JPEG_MAX_PIXELS_PER_BYTE)
        fix = "re-encode it with Huffman coding" if meta.arithmetic else "copy or export it again"
        raise InputError(
            f"{path.name}: its header claims {meta.width}×{meta.height} px, which {len(data)} bytes of JPEG can't hold "
            f"(at most {JPEG_MAX_PIXELS_PER_BYTE} px a byte); the file is truncated or crafted: {fix}"
        )
    if components not in (1, 3, 4):
        raise InputError(f"{path.name} is a {components}-channel JPEG; convert it to RGB")
    exif = build_exif(meta.exif, meta.xmp, width_px=meta.width, height_px=meta.height)
    notes = list(meta.notes)
    bar = progress_for(path.name, meta.width, meta.height, exif.orientation, progress)
    try:
        if components == 4:
            pixels, order, messages, encoding, note = _decode_cmyk_jpeg(path.name, data, meta.icc)
            notes.append(note)
        else:
            encoding = encoding_for(meta)
            shape = (meta.height, meta.width) if components == 1 else (meta.height, meta.width, 3)
            (pixels, messages), order = imdecode(data, path, shape), "BGR"
        if pixels is None or pixels.shape[:2] != (meta.height, meta.width):
            raise InputError(f"{path.name} could not be decoded as a JPEG; re-export it")
        if pixels.ndim == 3 and pixels.shape[2] != 3:
            raise InputError(f"{path.name} is a {pixels.shape[2]}-channel JPEG; convert it to RGB")
        if messages:
            notes.append(damage_note(path.name, "JPEG", pixels, messages))
        pixels = orient(pixels, exif.orientation)
        bar.step("decode")
        luminance, clipped, display = linearise_integer(pixels, 8, order, encoding, bar)
    finally:
        bar.close()
    return make_photo(
        path, luminance, clipped, display, False, exif, encoding.describe(), encoding.colour_space, notes,
        decoding=encoding.lut(8),
    )


def _decode_cmyk_jpeg(name: str, data: bytes, icc: bytes | None):
    """A CMYK or YCCK JPEG as 8-bit sRGB: ``(pixels, "RGB", messages, encoding, note)``.

    Pillow decodes it (libjpeg turns YCCK into CMYK; Pillow undoes Adobe's inverted
    CMYK). With a usable embedded CMYK profile, littleCMS converts to sRGB (perceptual
    intent); otherwise Pillow's naive conversion ``R = (1 − C)(1 − K)``,
    ``G = (1 − M)(1 − K)``, ``B = (1 − Y)(1 − K)``, which ignores ink and paper.
    """
    import io
    import warnings

    from PIL import Image, ImageCms

    with library_messages() as messages, warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)  # max_pixels was checked
        try:
            image = Image.open(io.BytesIO(data))
            image.load()
        except (OSError, ValueError, SyntaxError, Image.DecompressionBombError) as error:
            raise InputError(f"{name} could not be decoded as a CMYK JPEG ({short(error)}); re-export it") from None
    if image.mode != "CMYK":
        raise InputError(f"{name} is a 4-channel JPEG that decodes as {image.mode}; convert it to RGB")
    how = None
    if icc and icc[16:20] == b"CMYK":
        label = icc_description(icc) or "no description"
        try:
            source = ImageCms.ImageCmsProfile(io.BytesIO(icc))
            rgb = ImageCms.profileToProfile(image, source, ImageCms.createProfile("sRGB"), outputMode="RGB")
            how = f"with its embedded ICC profile '{label}' (littleCMS, perceptual intent)"
        except (ImageCms.PyCMSError, OSError, ValueError) as error:
            why = f"its embedded ICC profile '{label}' is not usable ({short(error)})"
    else:
        why = "no CMYK ICC profile in the file"
    if how is None:
        rgb = image.convert("RGB")
        how = f"naively, R = (1 − C)(1 − K) and so on ({why}; colours are approximate)"
    pixels = np.asarray(rgb, dtype=np.uint8)
    encoding = named_encoding("sRGB", "the conversion from CMYK")
    return pixels, "RGB", list(messages), encoding, f"{name} is a CMYK JPEG: converted to sRGB {how}"
