"""EXIF tags as the file stores them, read by exiv2, and their values as clean numbers and text.

exiv2 (python-exiv2, which ships libexiv2) decodes the standard IFDs and the maker notes from
the EXIF block of a JPEG/PNG (:func:`read_exif_tags`) or from a whole file, camera raw formats
included (:func:`read_file_tags`); damaged EXIF gives what could be read. :func:`tag_number`
and :func:`tag_text` turn a tag's value into a finite float or a clean string, or None.
"""

from __future__ import annotations

import contextlib
import math
import os
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any, Mapping

from bokehfit.io.xmp import XMP_MAX_BYTES

__all__ = ["EXIF_MAX_BYTES", "TEXT_MAX_CHARS", "ExifTags", "read_exif_tags", "read_file_tags", "tag_number", "tag_text"]

#: Longest text kept from a tag (camera, lens names are under 100 characters): longer text is cut.
TEXT_MAX_CHARS = 256


@dataclass(frozen=True)
class ExifTags:
    """Raw EXIF tags by number (IFD0, the EXIF sub-IFD, the interoperability IFD), and the
    maker-note tags by their exiv2 key (``"Exif.CanonFi.FocusDistanceUpper"``)."""

    ifd0: Mapping[int, Any] = field(default_factory=dict)
    exif: Mapping[int, Any] = field(default_factory=dict)
    interop: Mapping[int, Any] = field(default_factory=dict)
    maker: Mapping[str, Any] = field(default_factory=dict)

    def get(self, tag: int) -> Any:
        """A tag from the EXIF sub-IFD, else from IFD0, else None."""
        value = self.exif.get(tag)
        return self.ifd0.get(tag) if value is None else value


#: TIFF's own IFDs are read from the whole file, which exiv2 walks by offsets without copying.
EXIF_MAX_BYTES = 1 << 30
#: exiv2 groups of the standard IFDs (the rest are maker notes).
_STANDARD_GROUPS = {"Image": "ifd0", "Photo": "exif", "Iop": "interop"}
#: Longest value kept from one tag (elements): maker notes hold tables of thousands of numbers.
_VALUE_MAX_COUNT = 4096


def _exiv2_value(datum) -> Any:
    """A tag's value in plain Python: str (ASCII), int, Fraction (rational), bytes (undefined),
    or a tuple of those when the tag holds several."""
    import exiv2

    type_id, count = datum.typeId(), datum.count()
    if type_id in (exiv2.TypeId.asciiString, exiv2.TypeId.string):
        return datum.toString()
    if type_id in (exiv2.TypeId.undefined, exiv2.TypeId.unsignedByte, exiv2.TypeId.signedByte) and count > 8:
        return bytes(datum.value().data())  # an ICC profile or an XMP packet in a TIFF: the caller caps its size
    if count == 0 or count > _VALUE_MAX_COUNT:
        return None
    if type_id in (exiv2.TypeId.unsignedRational, exiv2.TypeId.signedRational):
        items = []
        for i in range(count):
            numerator, denominator = datum.toRational(i)
            items.append(Fraction(numerator, denominator) if denominator else float("nan"))
    elif type_id in (exiv2.TypeId.tiffFloat, exiv2.TypeId.tiffDouble):
        items = [datum.toFloat(i) for i in range(count)]
    else:
        items = [datum.toInt64(i) for i in range(count)]
    return items[0] if count == 1 else tuple(items)


@contextlib.contextmanager
def _exiv2_quiet():
    """exiv2 with its log muted meanwhile (it prints warnings on odd files), the level restored after."""
    import exiv2

    level = exiv2.LogMsg.level()
    exiv2.LogMsg.setLevel(exiv2.LogMsg.Level.mute)
    try:
        yield exiv2
    finally:
        exiv2.LogMsg.setLevel(level)


def read_exif_tags(blob: bytes | None) -> ExifTags:
    """Parse an EXIF block (``b"Exif\\0\\0"`` + TIFF structure) or a whole TIFF file, with exiv2.

    exiv2 decodes the standard IFDs and the maker notes of the major makers (Canon,
    Nikon, Sony, Fujifilm, Olympus, Panasonic, Pentax, ...). Damaged EXIF is not an
    error for a photo: whatever can't be parsed is left out. A block over
    :data:`EXIF_MAX_BYTES` is not parsed at all.
    """
    if not blob or len(blob) > EXIF_MAX_BYTES:
        return ExifTags()
    data = bytes(blob[6:]) if blob[:6] == b"Exif\x00\x00" else bytes(blob)
    if data[:4] not in (b"II*\x00", b"MM\x00*"):
        return ExifTags()
    return _read_with_exiv2(data)[0]


def read_file_tags(path) -> tuple[ExifTags, bytes | None]:
    """EXIF tags (maker notes included) and the XMP packet of a whole file, camera raw
    formats included (CR2, CR3, NEF, ARW, ORF, RW2, RAF, DNG, ...), read by exiv2.

    Files over :data:`EXIF_MAX_BYTES` and files exiv2 does not know give empty tags.
    """
    try:
        if os.path.getsize(path) > EXIF_MAX_BYTES:
            return ExifTags(), None
    except OSError:
        return ExifTags(), None
    return _read_with_exiv2(str(path))


def _read_with_exiv2(source: bytes | str) -> tuple[ExifTags, bytes | None]:
    """Tags and raw XMP packet of an image in memory (bytes) or on disk (a path)."""
    found: dict[str, dict] = {"ifd0": {}, "exif": {}, "interop": {}, "maker": {}}
    xmp = None
    with _exiv2_quiet() as exiv2:
        try:
            image = exiv2.ImageFactory.open(source)
            image.readMetadata()
            packet = image.xmpPacket()
            if packet and len(packet) <= XMP_MAX_BYTES:
                xmp = packet.encode("utf-8", "replace")
            for datum in image.exifData():
                group = datum.groupName()
                try:
                    value = _exiv2_value(datum)
                except (exiv2.Exiv2Error, ValueError, OverflowError, ZeroDivisionError):
                    continue
                if value is None:
                    continue
                if group in _STANDARD_GROUPS:
                    found[_STANDARD_GROUPS[group]].setdefault(datum.tag(), value)
                elif group not in ("MakerNote", "Thumbnail", "GPSInfo") and not group.startswith(("SubImage", "Image")):
                    found["maker"].setdefault(datum.key(), value)
        except (exiv2.Exiv2Error, ValueError, MemoryError, OverflowError, UnicodeError):
            pass  # damage means "no more EXIF", never a failed load: keep what was read
    return ExifTags(found["ifd0"], found["exif"], found["interop"], found["maker"]), xmp


def tag_number(value: Any) -> float | None:
    """A finite float from an EXIF value (rational, int, float, 1-tuple, "a/b" text), else None."""
    if isinstance(value, (tuple, list)):
        if len(value) == 2 and all(isinstance(v, int) for v in value):
            value = value[0] / value[1] if value[1] else float("nan")
        elif len(value) >= 1:
            value = value[0]
    if isinstance(value, (bytes, bytearray)):
        return None
    if isinstance(value, str):
        text = value.strip("\x00 ")
        try:
            if "/" in text:
                numerator, denominator = text.split("/", 1)
                value = float(numerator) / float(denominator) if float(denominator) else float("nan")
            else:
                value = float(text)
        except ValueError:
            return None
    try:
        number = float(value)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return number if math.isfinite(number) else None


def tag_text(value: Any) -> str | None:
    """A clean string from an EXIF text value (NULs and padding removed, at most
    :data:`TEXT_MAX_CHARS` characters), else None."""
    if isinstance(value, (bytes, bytearray)):
        value = bytes(value[: 4 * TEXT_MAX_CHARS]).decode("utf-8", "replace")
    if not isinstance(value, str):
        return None
    text = " ".join(value[: 4 * TEXT_MAX_CHARS].replace("\x00", " ").split())
    return text[:TEXT_MAX_CHARS].strip() or None
