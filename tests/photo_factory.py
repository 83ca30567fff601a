"""Small synthetic photo files for the loader tests: JPEG, PNG, TIFF, DNG, EXIF, ICC, XMP.

Everything here is written from first principles (the sRGB formula, the EXIF
and ICC byte layouts) rather than with bokehfit's own code, so that a test
compares the loader with an independent reference.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import struct
import zlib
from fractions import Fraction
from pathlib import Path

import numpy as np

#: The folder of the reference photos (else ``reference_photos/``, where copies are git-ignored).
REFERENCE_ENV = "BOKEHFIT_REFERENCE_DIR"
#: Set to 1 to fail, not skip, where a reference photo is missing (a CI that has them).
REQUIRE_REFERENCE_ENV = "BOKEHFIT_REQUIRE_REFERENCE_PHOTOS"
MANIFEST = Path(__file__).resolve().parents[1] / "reference_photos" / "manifest.json"

# --------------------------------------------------------------------------------------
# Transfer curves (IEC 61966-2-1; Adobe RGB (1998) §4.3.1.2)
# --------------------------------------------------------------------------------------

ADOBE_GAMMA = 563 / 256


def srgb_encode(linear):
    """sRGB-encoded value in [0, 1] of linear light in [0, 1]."""
    x = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def srgb_decode(encoded):
    """Linear light of an sRGB-encoded value in [0, 1]."""
    v = np.clip(np.asarray(encoded, dtype=np.float64), 0.0, 1.0)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def to_codes(linear, bits=8, encode=srgb_encode):
    """Integer codes (uint8 or uint16) of linear values through ``encode``."""
    top = 2**bits - 1
    dtype = np.uint8 if bits == 8 else np.uint16
    return np.round(encode(linear) * top).astype(dtype)


# --------------------------------------------------------------------------------------
# EXIF (little-endian TIFF structure in an APP1 "Exif\0\0" block)
# --------------------------------------------------------------------------------------


class Long(int):
    """Force an EXIF value to type LONG."""


class SRational(tuple):
    """A signed rational (numerator, denominator)."""


def _encode(value):
    if isinstance(value, str):
        data = value.encode("latin-1")
        return 2, len(data) + 1, data + b"\x00"
    if isinstance(value, bytes):
        return 7, len(value), value
    if isinstance(value, Long):
        return 4, 1, struct.pack("<I", value)
    if isinstance(value, int):
        return (3, 1, struct.pack("<H", value)) if 0 <= value < 65536 else (4, 1, struct.pack("<I", value))
    if isinstance(value, SRational):
        return 10, 1, struct.pack("<ii", *value)
    if isinstance(value, tuple) and len(value) == 2:
        return 5, 1, struct.pack("<II", *value)
    if isinstance(value, float):
        fraction = Fraction(value).limit_denominator(100000)
        return 5, 1, struct.pack("<II", fraction.numerator, fraction.denominator)
    raise TypeError(f"can't encode {value!r} as EXIF")


def _ifd(entries: dict, start: int) -> bytes:
    items = sorted(entries.items())
    data_start = start + 2 + 12 * len(items) + 4
    table, data = struct.pack("<H", len(items)), b""
    for tag, value in items:
        kind, count, payload = _encode(value)
        if len(payload) <= 4:
            field = payload.ljust(4, b"\x00")
        else:
            field = struct.pack("<I", data_start + len(data))
            data += payload + (b"\x00" if len(payload) % 2 else b"")
        table += struct.pack("<HHI", tag, kind, count) + field
    return table + b"\x00\x00\x00\x00" + data


def make_exif(ifd0: dict | None = None, exif: dict | None = None, interop: dict | None = None) -> bytes:
    """An EXIF block (``b"Exif\\0\\0"`` + little-endian TIFF) with IFD0, EXIF and interop IFDs.

    Values: str ASCII, int SHORT (LONG if large or :class:`Long`), float or
    (num, den) RATIONAL, :class:`SRational`, bytes UNDEFINED. Keys are tag numbers.
    """
    ifd0 = dict(ifd0 or {})
    exif = dict(exif or {})
    if interop:
        exif[0xA005] = Long(0)
    if exif:
        ifd0[0x8769] = Long(0)
    # Sizes don't depend on pointer values: lay out once with zeros, then with the real offsets.
    first = _ifd(ifd0, 8)
    if exif:
        exif_at = 8 + len(first)
        ifd0[0x8769] = Long(exif_at)
        first = _ifd(ifd0, 8)
        if interop:
            second = _ifd(exif, exif_at)
            exif[0xA005] = Long(exif_at + len(second))
        second = _ifd(exif, exif_at)
        third = _ifd(interop, exif_at + len(second)) if interop else b""
    else:
        second = third = b""
    return b"Exif\x00\x00" + b"II*\x00" + struct.pack("<I", 8) + first + second + third


def exif_for(
    *,
    make=None,
    model=None,
    orientation=None,
    fnumber=None,
    focal=None,
    focal35=None,
    lens=None,
    subject_distance=None,
    fp_xres=None,
    fp_unit=None,
    colour_space=None,
    interop_index=None,
) -> bytes:
    """An EXIF block from named fields (None leaves a tag out)."""
    ifd0 = {0x010F: make, 0x0110: model, 0x0112: orientation}
    exif = {
        0x829D: fnumber,
        0x920A: focal,
        0xA405: focal35,
        0xA434: lens,
        0x9206: subject_distance,
        0xA20E: fp_xres,
        0xA210: fp_unit,
        0xA001: colour_space,
    }
    interop = {0x0001: interop_index} if interop_index else {}
    return make_exif(
        {k: v for k, v in ifd0.items() if v is not None}, {k: v for k, v in exif.items() if v is not None}, interop
    )


# --------------------------------------------------------------------------------------
# ICC profiles (ICC.1:2001-04, version 2.1 matrix/TRC display profile)
# --------------------------------------------------------------------------------------

D50 = (0.9642, 1.0, 0.8249)
#: D50-adapted colorants of Adobe RGB (1998), as in Adobe's own profile.
ADOBE_COLORANTS = ((0.6097, 0.3111, 0.0195), (0.2053, 0.6257, 0.0609), (0.1492, 0.0632, 0.7446))
#: D50-adapted colorants of sRGB.
SRGB_COLORANTS = ((0.4361, 0.2225, 0.0139), (0.3851, 0.7169, 0.0971), (0.1431, 0.0606, 0.7141))


def _s15f16(*values) -> bytes:
    return struct.pack(f">{len(values)}i", *(int(round(v * 65536)) for v in values))


def _pad4(data: bytes) -> bytes:
    return data + b"\x00" * (-len(data) % 4)


def make_icc_profile(
    description: str, gamma_u8f8: int = 563, colorants=ADOBE_COLORANTS, curve: bytes | None = None
) -> bytes:
    """A minimal valid RGB display profile: ``desc``, ``cprt``, ``wtpt``, colorants and a gamma curve.

    ``gamma_u8f8`` is the curve's exponent in units of 1/256 (563 = Adobe RGB's 2.19921875);
    ``curve`` replaces the whole tone-curve tag (see :func:`icc_para_curve`, :func:`icc_table_curve`).
    """
    ascii_text = description.encode("ascii") + b"\x00"
    desc = b"desc\x00\x00\x00\x00" + struct.pack(">I", len(ascii_text)) + ascii_text
    desc += struct.pack(">II", 0, 0) + struct.pack(">HB", 0, 0) + b"\x00" * 67  # empty Unicode and ScriptCode parts
    if curve is None:
        curve = b"curv\x00\x00\x00\x00" + struct.pack(">IH", 1, gamma_u8f8)
    tags = [
        (b"desc", desc),
        (b"cprt", b"text\x00\x00\x00\x00No copyright, use freely\x00"),
        (b"wtpt", b"XYZ \x00\x00\x00\x00" + _s15f16(*D50)),
        (b"rXYZ", b"XYZ \x00\x00\x00\x00" + _s15f16(*colorants[0])),
        (b"gXYZ", b"XYZ \x00\x00\x00\x00" + _s15f16(*colorants[1])),
        (b"bXYZ", b"XYZ \x00\x00\x00\x00" + _s15f16(*colorants[2])),
        (b"rTRC", curve),
        (b"gTRC", curve),
        (b"bTRC", curve),
    ]
    table = struct.pack(">I", len(tags))
    body = b""
    offset = 128 + 4 + 12 * len(tags)
    for signature, data in tags:
        table += struct.pack(">4sII", signature, offset + len(body), len(data))
        body += _pad4(data)
    size = 128 + len(table) + len(body)
    header = struct.pack(">I4sI4s4s4s", size, b"none", 0x02100000, b"mntr", b"RGB ", b"XYZ ")
    header += struct.pack(">6H", 2024, 1, 1, 0, 0, 0) + b"acsp" + b"\x00" * 4  # date, signature, platform
    header += struct.pack(">I4s4s", 0, b"none", b"none") + b"\x00" * 8 + struct.pack(">I", 0)  # flags..intent
    header += _s15f16(*D50) + b"none" + b"\x00" * 16 + b"\x00" * 28  # illuminant, creator, id, reserved
    assert len(header) == 128
    return header + table + body


def icc_para_curve(function: int, *params: float) -> bytes:
    """An ICC ``para`` tag (parametricCurveType): function type 0–4 and its s15Fixed16 parameters."""
    return b"para\x00\x00\x00\x00" + struct.pack(">HH", function, 0) + _s15f16(*params)


def icc_table_curve(values) -> bytes:
    """An ICC ``curv`` tag sampled at ``len(values)`` points (values in [0, 1])."""
    codes = np.round(np.clip(np.asarray(values, dtype=np.float64), 0.0, 1.0) * 65535).astype(">u2")
    return b"curv\x00\x00\x00\x00" + struct.pack(">I", codes.size) + codes.tobytes()


# --------------------------------------------------------------------------------------
# XMP
# --------------------------------------------------------------------------------------


def make_xmp(properties: dict[str, str], attributes: bool = False) -> bytes:
    """An XMP packet with ``{"aux:ApproximateFocusDistance": "727/100", ...}`` as elements or attributes."""
    namespaces = (
        "xmlns:aux='http://ns.adobe.com/exif/1.0/aux/' xmlns:photoshop='http://ns.adobe.com/photoshop/1.0/'"
        " xmlns:exif='http://ns.adobe.com/exif/1.0/' xmlns:tiff='http://ns.adobe.com/tiff/1.0/'"
        " xmlns:exifEX='http://cipa.jp/exif/1.0/'"
    )
    if attributes:
        attrs = " ".join(f'{name}="{value}"' for name, value in properties.items())
        description = f"<rdf:Description rdf:about='' {namespaces} {attrs}/>"
    else:
        elements = "".join(f"<{name}>{value}</{name}>" for name, value in properties.items())
        description = f"<rdf:Description rdf:about='' {namespaces}>{elements}</rdf:Description>"
    packet = (
        "<?xpacket begin='\ufeff' id='W5M0MpCehiHzreSzNTczkc9d'?><x:xmpmeta xmlns:x='adobe:ns:meta/'>"
        "<rdf:RDF xmlns:rdf='http://www.w3.org/1999/02/22-rdf-syntax-ns#'>"
        f"{description}</rdf:RDF></x:xmpmeta><?xpacket end='w'?>"
    )
    return packet.encode("utf-8")


# --------------------------------------------------------------------------------------
# Writers
# --------------------------------------------------------------------------------------


def write_jpeg(
    path,
    rgb: np.ndarray,
    *,
    quality: int = 95,
    exif: bytes | None = None,
    icc: bytes | None = None,
    xmp: bytes | None = None,
) -> Path:
    """8-bit RGB (H, W, 3) or grey (H, W) as a JPEG with Pillow, 4:4:4, optionally with EXIF/ICC/XMP."""
    from PIL import Image

    options = {"quality": quality, "subsampling": 0}
    if exif:
        options["exif"] = exif
    if icc:
        options["icc_profile"] = icc
    buffer = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb)).save(buffer, "JPEG", **options)
    data = buffer.getvalue()
    if xmp:
        payload = b"http://ns.adobe.com/xap/1.0/\x00" + xmp
        data = data[:2] + b"\xff\xe1" + struct.pack(">H", len(payload) + 2) + payload + data[2:]
    Path(path).write_bytes(data)
    return Path(path)


def _png_chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)


def write_png(
    path,
    pixels: np.ndarray,
    *,
    icc: bytes | None = None,
    exif: bytes | None = None,
    srgb: bool = False,
    gamma: float | None = None,
    xmp: bytes | None = None,
) -> Path:
    """uint8/uint16 grey (H, W) or RGB(A) (H, W, 3|4) as a PNG (OpenCV), with optional chunks after IHDR."""
    import cv2

    pixels = np.ascontiguousarray(pixels)
    if pixels.ndim == 3:
        pixels = cv2.cvtColor(pixels, cv2.COLOR_RGB2BGR if pixels.shape[2] == 3 else cv2.COLOR_RGBA2BGRA)
    ok, encoded = cv2.imencode(".png", pixels)
    assert ok
    data = encoded.tobytes()
    chunks = b""
    if icc:
        chunks += _png_chunk(b"iCCP", b"test profile\x00\x00" + zlib.compress(icc))
    if srgb:
        chunks += _png_chunk(b"sRGB", b"\x00")
    if gamma is not None:
        chunks += _png_chunk(b"gAMA", struct.pack(">I", round(gamma * 100000)))
    if exif:
        chunks += _png_chunk(b"eXIf", exif[6:] if exif.startswith(b"Exif\x00\x00") else exif)
    if xmp:
        chunks += _png_chunk(b"iTXt", b"XML:com.adobe.xmp\x00\x00\x00\x00\x00" + xmp)
    ihdr_end = 8 + 8 + 13 + 4
    Path(path).write_bytes(data[:ihdr_end] + chunks + data[ihdr_end:])
    return Path(path)


def write_tiff(
    path, pixels: np.ndarray, *, icc: bytes | None = None, orientation: int | None = None, **options
) -> Path:
    """An RGB/grey TIFF with tifffile (``options`` go to ``tifffile.imwrite``)."""
    import tifffile

    extratags = []
    if icc:
        extratags.append((34675, "B", len(icc), icc, True))
    if orientation:
        extratags.append((274, "H", 1, (orientation,), True))
    photometric = "rgb" if pixels.ndim == 3 and pixels.shape[-1] in (3, 4) else "minisblack"
    options.setdefault("photometric", photometric)
    tifffile.imwrite(path, pixels, extratags=extratags, metadata=None, **options)
    return Path(path)


def bayer_mosaic(height: int, width: int, black: int, level: int, patches=()) -> np.ndarray:
    """A uint16 CFA image: ``black + level`` everywhere, ``(r0, r1, c0, c1, value)`` patches on top.

    Patch values are raw (black included), so a patch at the white level is saturated.
    """
    mosaic = np.full((height, width), black + level, dtype=np.uint16)
    for r0, r1, c0, c1, value in patches:
        mosaic[r0:r1, c0:c1] = value
    return mosaic


def write_dng(
    path,
    mosaic: np.ndarray,
    *,
    white: int,
    black: int,
    orientation: int = 1,
    make: str | None = None,
    model: str | None = None,
) -> Path:
    """A Bayer (RGGB) DNG 1.4 that LibRaw accepts: a 16-bit CFA image with the DNG colour tags.

    The tags: CFARepeatPatternDim 2×2, CFAPattern RGGB, DNGVersion 1.4, UniqueCameraModel,
    BlackLevel, WhiteLevel, ColorMatrix1 (identity), CalibrationIlluminant1 D65, AsShotNeutral 1,1,1.
    """
    import tifffile

    identity = (1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1)
    extratags = [
        (33421, "H", 2, (2, 2), True),  # CFARepeatPatternDim
        (33422, "B", 4, (0, 1, 1, 2), True),  # CFAPattern: R G / G B
        (50706, "B", 4, (1, 4, 0, 0), True),  # DNGVersion
        (50707, "B", 4, (1, 1, 0, 0), True),  # DNGBackwardVersion
        (50708, "s", 0, "bokehfit synthetic", True),  # UniqueCameraModel
        (50714, "H", 1, (black,), True),  # BlackLevel
        (50717, "H", 1, (white,), True),  # WhiteLevel
        (50721, "2i", 9, identity, True),  # ColorMatrix1 (SRATIONAL)
        (50778, "H", 1, (21,), True),  # CalibrationIlluminant1: D65
        (50728, "2I", 3, (1, 1, 1, 1, 1, 1), True),  # AsShotNeutral
        (274, "H", 1, (orientation,), True),
    ]
    if make:
        extratags.append((271, "s", 0, make, True))
    if model:
        extratags.append((272, "s", 0, model, True))
    tifffile.imwrite(path, mosaic, photometric="cfa", subfiletype=0, extratags=extratags, metadata=None)
    return Path(path)


# --------------------------------------------------------------------------------------
# Test helpers
# --------------------------------------------------------------------------------------


def file_state(path) -> tuple[str, int]:
    """(sha256, mtime in ns) of a file, to show that reading it changed nothing."""
    path = Path(path)
    return hashlib.sha256(path.read_bytes()).hexdigest(), path.stat().st_mtime_ns


def reference_dir() -> Path:
    """The folder that should hold the reference photos: ``$BOKEHFIT_REFERENCE_DIR``, else ``reference_photos/``."""
    folder = os.environ.get(REFERENCE_ENV)
    return Path(folder) if folder else MANIFEST.parent


def find_reference_photo(name: str) -> tuple[Path | None, str]:
    """``(path, "")`` for a photo of the manifest present with its sha256, else ``(None, why not)``.

    ``why not`` is one line that says where to get the photos. A name that is not in the
    manifest is a mistake in the test, not a missing photo: it raises ``KeyError``.
    """
    expected = manifest_entry(name)["sha256"]
    folder = reference_dir()
    if os.environ.get(REFERENCE_ENV):
        where = f"${REFERENCE_ENV} = {folder}"
    else:
        where = f"{folder} ({REFERENCE_ENV} is not set)"
    fetch = (
        "the reference photos are not in the repository: get them from the sources in "
        f"reference_photos/manifest.json and point {REFERENCE_ENV} at their folder"
    )
    path = folder / name
    if not folder.is_dir():
        return None, f"no folder {where}; {fetch}"
    if not path.is_file():
        return None, f"{name} is not in {where}; {fetch}"
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    if digest != expected:
        return None, f"{path} has sha256 {digest}, not the manifest's {expected}; {fetch}"
    return path, ""


def reference_photo(name: str) -> Path:
    """A reference photo of the manifest, checked by sha256; the test skips where it is missing.

    The photos are not in the repository, so a missing folder, a missing photo or one with
    another sha256 skips the test with a reason that says where to get them; with
    ``BOKEHFIT_REQUIRE_REFERENCE_PHOTOS=1`` (a CI that has them) it fails instead.
    """
    import pytest

    path, why = find_reference_photo(name)
    if path is None:
        if os.environ.get(REQUIRE_REFERENCE_ENV) == "1":
            pytest.fail(f"{REQUIRE_REFERENCE_ENV}=1 but {why}", pytrace=False)
        pytest.skip(why)
    return path


def manifest_entry(name: str) -> dict:
    """The manifest's entry for a reference photo."""
    return {entry["file"]: entry for entry in json.loads(MANIFEST.read_text())["photos"]}[name]


def reference_labels(name: str):
    """``(path, DiscLabels)``: a person's disc labels of a reference photo (``discs/NAME.discs.json``
    beside the photos), checked against the manifest's sha256; the test skips where they are missing."""
    import pytest

    from bokehfit.discs.labels import read_labels

    path = reference_dir() / "discs" / f"{name}.discs.json"
    if not path.is_file():
        why = f"no disc labels {path.name} in {path.parent}"
        if os.environ.get(REQUIRE_REFERENCE_ENV) == "1":
            pytest.fail(f"{REQUIRE_REFERENCE_ENV}=1 but {why}", pytrace=False)
        pytest.skip(why)
    labels = read_labels(path)
    assert labels.sha256 == manifest_entry(name)["sha256"], f"{path.name} labels another photo"
    return path, labels
