"""EXIF, maker notes and XMP: camera, lens, aperture, focal length, focus distance, sensor width.

EXIF tags, maker notes included, are decoded by exiv2 (python-exiv2, which
ships libexiv2) from the EXIF block of a JPEG/PNG or from a TIFF-based file's
own IFDs (:func:`read_exif_tags`); the XMP packet by :func:`parse_xmp`. Every
value is checked against its physical range: zeros, infinities and nonsense
are not used, and :attr:`Exif.ignored` says which and why. :attr:`Exif.sources`
names the tag, database or rule behind each value.

Focus distance
--------------
In this order: the maker note (Canon ``FocusDistanceLower``/``Upper``, a
range whose middle is used; Nikon lens data ``FocusDistance``; Olympus
``FocusDistance``), EXIF ``SubjectDistance``, XMP ``aux:ApproximateFocusDistance``.

Sensor width
------------
The width of the sensor's long side in mm, with where it came from, in this
order:

(a) the lensfun database (lensfunpy, whose wheel ships it): the camera's
    crop factor, taken on the diagonal (43.27 mm for a 36 × 24 mm frame), with
    a 3:2 sensor up to APS-C and a 4:3 one beyond;
(b) the 35 mm-equivalent focal length: the crop factor ``f35 / f`` on the
    diagonal, the long side following from the image's aspect ratio; for a
    3:2 frame this is exactly ``36 mm · f / f35``;
(c) ``FocalPlaneXResolution`` and its unit: ``pitch = unit / resolution``.
    The tag describes the camera's native frame: with the native width from
    the maker note (Canon ``AFCanonImageWidth``) ``width = native px · pitch``;
    without it, ``width = the file's long side · pitch``, which is only right
    for a file that still has the native width (a photo downscaled from 5472
    to 2560 px with 152 px/mm gives 16.8 mm for a 35.8 mm sensor), and only
    used when the result lies in :data:`PLAUSIBLE_SENSOR_WIDTH_MM`.

Downscaled and cropped files
----------------------------
The camera's native width comes from the maker note, or from
``FocalPlaneXResolution`` times the sensor width. A file narrower than that is
downscaled (or cropped); a file whose aspect ratio is neither 3:2 nor 4:3 is
cropped, and its long side is taken as whole. :attr:`Exif.frame` says which.
Either way the pixel pitch is ``sensor_width_mm / max(width, height)``: it
follows from the sensor size, never from the native resolution.

XMP
---
The XMP packet is untrusted text: it is read by :func:`parse_xmp` with the
expat XML parser (linear time, no regular expressions), only up to
:data:`XMP_MAX_BYTES`, and a packet that declares a document type (the only
way to define entities) is ignored.
"""

from __future__ import annotations

import contextlib
import functools
import math
import os
import re
from fractions import Fraction
from dataclasses import asdict, dataclass, field
from typing import Any, Mapping
from xml.parsers import expat

from bokehfit.validate import RANGES

__all__ = [
    "Exif",
    "ExifTags",
    "FOCUS_DISTANCE_RANGE_M",
    "PLAUSIBLE_SENSOR_WIDTH_MM",
    "EXIF_MAX_BYTES",
    "build_exif",
    "lensfun_camera",
    "lensfun_lens",
    "XMP_MAX_BYTES",
    "camera_name",
    "parse_xmp",
    "read_exif_tags",
    "read_file_tags",
    "sensor_width",
    "xmp_property",
]

#: Sensor widths (mm) accepted from FocalPlaneXResolution: from 1/2.3" compacts to 645 medium format.
PLAUSIBLE_SENSOR_WIDTH_MM = (4.0, 60.0)
#: Focus distances (m) taken as real; outside is a placeholder (0, 0xFFFFFFFF = infinity) or nonsense.
FOCUS_DISTANCE_RANGE_M = (0.01, 10_000.0)
#: Diagonal of the 36 × 24 mm frame that 35 mm-equivalent focal lengths refer to.
FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)
#: Largest XMP packet read (bytes). Camera and editor packets are a few kB; a JPEG APP1
#: segment holds at most 64 kB. Larger packets are ignored, not parsed.
XMP_MAX_BYTES = 1 << 20
#: Longest text kept from a tag (camera, lens names are under 100 characters): longer text is cut.
TEXT_MAX_CHARS = 256

# EXIF tag numbers (EXIF 2.32, CIPA DC-008).
_MAKE, _MODEL, _ORIENTATION = 0x010F, 0x0110, 0x0112
_EXIF_IFD, _INTEROP_IFD = 0x8769, 0xA005
_FNUMBER, _APERTURE_VALUE, _SUBJECT_DISTANCE, _FOCAL_LENGTH = 0x829D, 0x9202, 0x9206, 0x920A
_COLOR_SPACE, _FOCAL_PLANE_X_RES, _FOCAL_PLANE_UNIT = 0xA001, 0xA20E, 0xA210
_FOCAL_LENGTH_35MM, _LENS_MODEL, _INTEROP_INDEX = 0xA405, 0xA434, 0x0001

#: FocalPlaneResolutionUnit -> (mm per unit, name). 1 means "no absolute unit".
_FOCAL_PLANE_UNITS = {2: (25.4, "inch"), 3: (10.0, "cm"), 4: (1.0, "mm"), 5: (0.001, "µm")}


@dataclass(frozen=True)
class Exif:
    """What a photo's metadata says about the camera and lens.

    Attributes
    ----------
    camera : str or None
        ``Make`` and ``Model`` cleaned up (``"Canon EOS 6D"``, ``"SONY ILCE-7M3"``).
    lens : str or None
        ``LensModel``, else XMP ``aux:Lens``/``exifEX:LensModel``.
    fnumber : float or None
        ``FNumber``, else from ``ApertureValue`` (APEX).
    focal_length_mm : float or None
        ``FocalLength``.
    focal_length_35mm : float or None
        ``FocalLengthIn35mmFilm``.
    focus_distance_m : float or None
        ``SubjectDistance``, else XMP ``aux:ApproximateFocusDistance``.
    sensor_width_mm : float or None
        Width of the sensor's long side (module docstring).
    sensor_width_source : str or None
        Where ``sensor_width_mm`` came from.
    orientation : int
        EXIF orientation 1..8 (1 if absent or invalid).
    focus_distance_range_m : tuple of float or None
        ``(near, far)`` where the maker note gives the focus distance as a range
        (Canon ``FocusDistanceLower``/``Upper``); ``focus_distance_m`` is its middle.
    native_width_px : int or None
        The long side of the camera's own frame in pixels, where known.
    frame : str or None
        How the file's pixels relate to the sensor, for people: native, downscaled,
        cropped (module docstring).
    sources : dict
        Where each value came from: field name -> tag name, database or rule.
    ignored : tuple of str
        Values found but not used, one line each with the reason (zero, negative, absurd).
    """

    camera: str | None = None
    lens: str | None = None
    fnumber: float | None = None
    focal_length_mm: float | None = None
    focal_length_35mm: float | None = None
    focus_distance_m: float | None = None
    sensor_width_mm: float | None = None
    sensor_width_source: str | None = None
    orientation: int = 1
    focus_distance_range_m: tuple[float, float] | None = None
    native_width_px: int | None = None
    frame: str | None = None
    sources: Mapping[str, str] = field(default_factory=dict)
    ignored: tuple[str, ...] = ()

    def to_json(self) -> dict:
        """The fields as plain JSON types (keys as the field names)."""
        document = asdict(self)
        document["focus_distance_range_m"] = (
            None if self.focus_distance_range_m is None else list(self.focus_distance_range_m)
        )
        document["sources"] = dict(self.sources)
        document["ignored"] = list(self.ignored)
        return document


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


#: Largest EXIF block handed to exiv2 (bytes). A JPEG's APP1 segment holds at most 64 kB; a
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


def _number(value: Any) -> float | None:
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


def _text(value: Any) -> str | None:
    """A clean string from an EXIF text value (NULs and padding removed, at most
    :data:`TEXT_MAX_CHARS` characters), else None."""
    if isinstance(value, (bytes, bytearray)):
        value = bytes(value[: 4 * TEXT_MAX_CHARS]).decode("utf-8", "replace")
    if not isinstance(value, str):
        return None
    text = " ".join(value[: 4 * TEXT_MAX_CHARS].replace("\x00", " ").split())
    return text[:TEXT_MAX_CHARS].strip() or None


def _in_range(value: float | None, low: float, high: float) -> float | None:
    return value if value is not None and low <= value <= high else None


_CORPORATE = re.compile(
    r"[\s,]+(?:imaging\s+|camera\s+|optical\s+)?"
    r"(?:corporation|corp\.?|company,?\s+ltd\.?|co\.,?\s*ltd\.?|ag|inc\.?|ltd\.?|gmbh)$",
    re.IGNORECASE,
)


def camera_name(make: Any, model: Any) -> str | None:
    """``Make`` and ``Model`` as one name, without NULs or the make said twice.

    Examples
    --------
    >>> camera_name("Canon\\x00", "Canon EOS 6D\\x00")
    'Canon EOS 6D'
    >>> camera_name("NIKON CORPORATION", "NIKON D750")
    'NIKON D750'
    >>> camera_name("OLYMPUS IMAGING CORP.", "E-M5")
    'OLYMPUS E-M5'
    """
    make_text, model_text = _text(make), _text(model)
    if make_text:
        make_text = _CORPORATE.sub("", make_text).strip() or make_text
    if not model_text:
        return make_text
    if not make_text:
        return model_text
    first_word = make_text.split(" ")[0].lower()
    if model_text.lower().startswith(first_word):
        return model_text
    return f"{make_text} {model_text}"


@functools.cache
def _lensfun_database():
    """The lensfun database shipped inside lensfunpy's wheel (read once; works offline)."""
    import lensfunpy

    return lensfunpy.Database()


def lensfun_camera(make: str | None, model: str | None):
    """The lensfun camera for an EXIF ``Make`` and ``Model``, or None (also when ambiguous).

    The maker's name may differ between EXIF and lensfun ("OLYMPUS CORPORATION" and
    "Olympus Imaging Corp."): without a match for both, the model alone must match exactly.
    """
    model = _text(model)
    if not model:
        return None
    key = " ".join(model.lower().split())
    database = _lensfun_database()
    try:
        cameras = database.find_cameras(_text(make), model, loose_search=False) if make else []
        if not cameras:
            cameras = [c for c in database.find_cameras(None, model, loose_search=True)
                       if " ".join(c.model.lower().split()) in (key, f"{(_text(make) or '').split(' ')[0].lower()} {key}")]
    except (RuntimeError, ValueError, UnicodeError):
        return None
    return cameras[0] if len(cameras) == 1 else None


def lensfun_lens(make: str | None, model: str | None, lens: str | None) -> str | None:
    """lensfun's name for the lens EXIF names, where it knows exactly one, else None."""
    camera = lensfun_camera(make, model)
    if camera is None or not lens:
        return None
    try:
        lenses = _lensfun_database().find_lenses(camera, None, lens, loose_search=False)
    except (RuntimeError, ValueError, UnicodeError):
        return None
    return lenses[0].model if len(lenses) == 1 else None


def _crop_factor_width(crop: float) -> tuple[float, str]:
    """The long side (mm) of a sensor with this crop factor, and the aspect assumed.

    lensfun's crop factor is on the diagonal (43.27 mm over the sensor's diagonal).
    Interchangeable-lens cameras up to APS-C (crop < 1.8) have 3:2 sensors; Four
    Thirds, one-inch and smaller sensors are 4:3.
    """
    ratio, name = (1.5, "3:2") if crop < 1.8 else (4.0 / 3.0, "4:3")
    return FULL_FRAME_DIAGONAL_MM / crop * ratio / math.hypot(ratio, 1.0), name


def sensor_width(
    *,
    make: str | None = None,
    model: str | None = None,
    focal_length_mm: float | None = None,
    focal_length_35mm: float | None = None,
    focal_plane_x_resolution: float | None = None,
    focal_plane_unit: int | None = None,
    width_px: int,
    height_px: int,
    native_width_px: int | None = None,
) -> tuple[float | None, str | None]:
    """Sensor width (long side, mm) and its source, by the priority of the module docstring.

    Parameters
    ----------
    make, model : str or None
        EXIF ``Make`` and ``Model``, looked up in the lensfun database.
    focal_length_mm, focal_length_35mm : float or None
        EXIF ``FocalLength`` and ``FocalLengthIn35mmFilm``.
    focal_plane_x_resolution : float or None
        EXIF ``FocalPlaneXResolution``, pixels per ``focal_plane_unit``.
    focal_plane_unit : int or None
        EXIF ``FocalPlaneResolutionUnit`` (2 inch, the default; 3 cm; 4 mm; 5 µm).
    width_px, height_px : int
        The image as stored in the file (before orientation).
    native_width_px : int or None
        The camera's own frame's long side, where a maker note says it: the focal-plane
        resolution then gives the sensor width whatever the file's size.

    Returns
    -------
    (float, str) or (None, None)

    Examples
    --------
    >>> sensor_width(make="Canon", model="Canon EOS 6D", focal_plane_x_resolution=152,
    ...              focal_plane_unit=4, width_px=2560, height_px=1600)
    (35.82, 'lensfun database (Canon EOS 6D, crop factor 1.005, 3:2 sensor)')
    """
    camera = lensfun_camera(make, model)
    if camera is not None and camera.crop_factor and math.isfinite(camera.crop_factor) and camera.crop_factor > 0:
        width_mm, aspect = _crop_factor_width(float(camera.crop_factor))
        if RANGES["sensor_width_mm"].contains(width_mm):
            return round(width_mm, 2), f"lensfun database ({camera.model}, crop factor {camera.crop_factor:.4g}, {aspect} sensor)"
    long_px, short_px = max(width_px, height_px), min(width_px, height_px)
    if focal_length_mm and focal_length_35mm and focal_length_mm > 0 and focal_length_35mm > 0:
        diagonal_mm = FULL_FRAME_DIAGONAL_MM * focal_length_mm / focal_length_35mm
        width_mm = diagonal_mm * long_px / math.hypot(long_px, short_px)
        if 1.0 <= width_mm <= 100.0:
            ratio = long_px / short_px
            frame = "3:2" if abs(ratio - 1.5) < 0.02 else ("4:3" if abs(ratio - 4 / 3) < 0.02 else f"{ratio:.3g}:1")
            source = (
                f"35 mm-equivalent focal length (FocalLengthIn35mmFilm {focal_length_35mm:g} mm for {focal_length_mm:g} mm;"
                f" crop factor on the diagonal, {frame} frame assumed uncropped)"
            )
            return round(width_mm, 2), source
    if focal_plane_x_resolution and focal_plane_x_resolution > 0:
        unit = _FOCAL_PLANE_UNITS.get(2 if focal_plane_unit is None else int(focal_plane_unit))
        if unit is not None:
            pitch_mm = unit[0] / focal_plane_x_resolution
            native = native_width_px or long_px
            width_mm = native * pitch_mm
            low, high = PLAUSIBLE_SENSOR_WIDTH_MM
            if low <= width_mm <= high:
                if native_width_px:
                    source = (f"focal-plane resolution (FocalPlaneXResolution {focal_plane_x_resolution:g} px/{unit[1]}) × the native"
                              f" width {native_width_px} px from the maker note")
                else:
                    source = (
                        f"focal-plane resolution ({focal_plane_x_resolution:g} px/{unit[1]} × {long_px} px;"
                        f" plausible, but right only if the file has the sensor's native pixel width)"
                    )
                return round(width_mm, 2), source
    return None, None


class _DocumentTypeRefused(Exception):
    """An XMP packet declared a document type (entities): it is not read."""


def parse_xmp(xmp: bytes | str | None) -> dict[str, str]:
    """The simple properties of an XMP packet: ``{"prefix:Name": value}``, first occurrence of each.

    A property is an attribute (``aux:Lens="..."``, typically on ``rdf:Description``) or an
    element that holds only text (``<aux:Lens>...</aux:Lens>``); names are kept as written,
    prefix included. The packet is read with expat, which takes time linear in its size.
    Packets over :data:`XMP_MAX_BYTES` or with a ``<!DOCTYPE`` give ``{}``; a packet that is
    not well-formed gives what was read before the error.

    Examples
    --------
    >>> parse_xmp(b'<x:xmpmeta><rdf:Description aux:Lens="EF85mm f/1.8 USM"/></x:xmpmeta>')
    {'aux:Lens': 'EF85mm f/1.8 USM'}
    """
    if not xmp:
        return {}
    data = xmp.encode("utf-8", "replace") if isinstance(xmp, str) else bytes(xmp)
    if len(data) > XMP_MAX_BYTES:
        return {}
    properties: dict[str, str] = {}
    open_elements: list[list] = []  # [name, text pieces, has child elements]

    def start(name: str, attributes: dict) -> None:
        if open_elements:
            open_elements[-1][2] = True
        for key, value in attributes.items():
            if not key.startswith("xmlns"):
                properties.setdefault(key, value)
        open_elements.append([name, [], False])

    def end(name: str) -> None:
        _, pieces, has_children = open_elements.pop()
        if not has_children:
            properties.setdefault(name, "".join(pieces))

    def text(piece: str) -> None:
        if open_elements:
            open_elements[-1][1].append(piece)

    def document_type(*_args) -> None:
        raise _DocumentTypeRefused

    parser = expat.ParserCreate()  # no namespace processing: names keep the prefixes as written
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = text
    parser.StartDoctypeDeclHandler = document_type
    try:
        parser.Parse(data.rstrip(b"\x00"), True)
    except _DocumentTypeRefused:
        return {}
    except expat.ExpatError:
        pass  # keep what was read before the damage
    return {name: value.strip() for name, value in properties.items() if value.strip()}


def xmp_property(xmp: bytes | str | Mapping[str, str] | None, name: str) -> str | None:
    """The value of an XMP property ``prefix:Name`` (element or attribute form), or None.

    ``xmp`` is the packet, or what :func:`parse_xmp` made of it (to read several properties).

    Examples
    --------
    >>> xmp_property(b"<aux:ApproximateFocusDistance>727/100</aux:ApproximateFocusDistance>",
    ...              "aux:ApproximateFocusDistance")
    '727/100'
    """
    properties = xmp if isinstance(xmp, Mapping) else parse_xmp(xmp)
    return properties.get(name)


def _focus_distance(value: Any) -> float | None:
    distance = _number(value)
    if distance is None or distance >= 0xFFFFFFFF:  # 0xFFFFFFFF/1 is EXIF's "infinity"
        return None
    return _in_range(distance, *FOCUS_DISTANCE_RANGE_M)


def _nikon_lens_data_distance(code: Any) -> float | None:
    """Nikon lens data's FocusDistance byte: ``0.01 m · 10^(code/40)`` (ExifTool's decoding)."""
    number = _number(code)
    if number is None or not 0 < number < 255:  # 0: not recorded; 255: infinity
        return None
    return round(0.01 * 10.0 ** (number / 40.0), 3)


#: Maker-note focus distances exiv2 decodes: (key, how the raw value becomes metres).
#: Sony, Fujifilm and Panasonic maker notes carry no focus distance that exiv2 decodes:
#: their files get it from EXIF SubjectDistance or XMP, where the camera or converter wrote it.
_MAKER_FOCUS_TAGS = (
    ("Exif.NikonLd4.FocusDistance", _nikon_lens_data_distance),
    ("Exif.NikonLd3.FocusDistance", _nikon_lens_data_distance),
    ("Exif.NikonLd2.FocusDistance", _nikon_lens_data_distance),
    ("Exif.Nikon3.FocusDistance", _number),
    ("Exif.OlympusFi.FocusDistance", _number),
    ("Exif.Olympus.FocusDistance", _number),
    ("Exif.Olympus2.FocusDistance", _number),
)
#: Maker-note tags that give the camera's native image width in pixels.
_NATIVE_WIDTH_TAGS = ("Exif.Canon.AFCanonImageWidth", "Exif.Canon.AFImageWidth", "Exif.Olympus.ImageWidth",
                      "Exif.Olympus2.ImageWidth", "Exif.Panasonic.ImageWidth")
#: Maker-note lens names (the EXIF LensModel comes first).
_MAKER_LENS_TAGS = ("Exif.Canon.LensModel", "Exif.OlympusEq.LensModel")


def _canon_focus_range(maker: Mapping[str, Any]) -> tuple[float, float] | None:
    """Canon's FocusDistanceLower/Upper (cm; 0xFFFF or a negative value is infinity), in m."""
    lower, upper = _number(maker.get("Exif.CanonFi.FocusDistanceLower")), _number(maker.get("Exif.CanonFi.FocusDistanceUpper"))
    if lower is None or upper is None or lower <= 0 or upper <= 0 or upper >= 0xFFFF or upper < lower:
        return None
    return lower / 100.0, upper / 100.0


def _checked(name: str, value: float | None, low: float, high: float, tag: str, unit: str, ignored: list[str]) -> float | None:
    """``value`` when it lies in [low, high], else None with the reason added to ``ignored``."""
    if value is None:
        return None
    if low <= value <= high:
        return value
    ignored.append(f"{tag} = {value:g} {unit} ignored: {name} outside [{low:g}, {high:g}] {unit}".replace("  ", " "))
    return None


def _frame(width_px: int, height_px: int, native_long_px: int | None, how: str) -> str | None:
    """How the file's pixels relate to the sensor's frame, in words (None when unknown).

    A file narrower than the camera's frame is downscaled (or cropped); one whose aspect
    ratio is neither 3:2 nor 4:3 is cropped, and its long side is taken as whole.
    """
    if not native_long_px:
        return None
    long_px, short_px = max(width_px, height_px), min(width_px, height_px)
    ratio = long_px / short_px
    cropped = not (abs(ratio - 1.5) < 0.02 or abs(ratio - 4 / 3) < 0.02)
    if long_px > native_long_px * 1.02:
        state = f"upscaled: {long_px} px wide, the camera's frame {native_long_px} px ({how})"
    elif long_px >= native_long_px * 0.98:
        state = f"the camera's native width ({native_long_px} px, {how})"
    else:
        state = f"downscaled ×{long_px / native_long_px:.3f} from the camera's {native_long_px} px ({how})"
    if cropped:
        state += f"; cropped to {ratio:.3g}:1, its long side taken as whole"
    return state + "; pixel pitch = sensor width / the file's long side"


def build_exif(
    tags: ExifTags,
    xmp: bytes | None = None,
    *,
    width_px: int,
    height_px: int,
    fallback: Mapping[str, Any] | None = None,
) -> Exif:
    """An :class:`Exif` from parsed tags (maker notes included) and the XMP packet.

    Parameters
    ----------
    tags : ExifTags
        From :func:`read_exif_tags`.
    xmp : bytes or None
        The XMP packet (read by :func:`parse_xmp`).
    width_px, height_px : int
        The image as stored (before orientation), for the sensor-width rules.
    fallback : mapping, optional
        Values to use where the tags say nothing (``lens``, ``fnumber``,
        ``focal_length_mm``, ``orientation``), e.g. from LibRaw for raw files.

    Notes
    -----
    Every number is checked against its physical range (f-number 0.5–128, focal
    length 1 mm–10 m, focus distance 1 cm–10 km); one outside is not used, and
    ``Exif.ignored`` says which tag held what and why.
    """
    fallback = dict(fallback or {})
    xmp = parse_xmp(xmp)
    maker = tags.maker
    sources: dict[str, str] = {}
    ignored: list[str] = []

    def first(field_name: str, candidates, low: float, high: float, unit: str):
        """The first candidate (tag name, raw value, converter) in range; out-of-range ones are noted."""
        for tag, raw, convert in candidates:
            value = convert(raw) if raw is not None else None
            if value is None:
                continue
            if math.isinf(value) or value >= 0xFFFFFFFF:
                continue
            kept = _checked(field_name, value, low, high, tag, unit, ignored)
            if kept is not None:
                sources[field_name] = tag
                return kept
        return None

    make = _text(tags.ifd0.get(_MAKE)) or _text(xmp_property(xmp, "tiff:Make"))
    model = _text(tags.ifd0.get(_MODEL)) or _text(xmp_property(xmp, "tiff:Model"))
    apex = _number(tags.get(_APERTURE_VALUE))
    fnumber = first("fnumber", [
        ("EXIF FNumber", tags.get(_FNUMBER), _number),
        ("EXIF ApertureValue (APEX)", apex, lambda a: round(2.0 ** (a / 2.0), 1) if -2.0 <= a <= 30.0 else None),
        ("XMP exif:FNumber", xmp_property(xmp, "exif:FNumber"), _number),
        ("LibRaw", fallback.get("fnumber"), _number),
    ], 0.5, 128.0, "")
    focal = first("focal_length_mm", [
        ("EXIF FocalLength", tags.get(_FOCAL_LENGTH), _number),
        ("XMP exif:FocalLength", xmp_property(xmp, "exif:FocalLength"), _number),
        ("LibRaw", fallback.get("focal_length_mm"), _number),
    ], RANGES["focal_length_mm"].low, RANGES["focal_length_mm"].high, "mm")
    focal_35 = first("focal_length_35mm", [
        ("EXIF FocalLengthIn35mmFilm", tags.get(_FOCAL_LENGTH_35MM), _number),
        ("XMP exif:FocalLengthIn35mmFilm", xmp_property(xmp, "exif:FocalLengthIn35mmFilm"), _number),
    ], 1.0, 10000.0, "mm")

    lens = None
    for tag, raw in [("EXIF LensModel", tags.get(_LENS_MODEL))] + [(f"maker note {k.split('.', 1)[1]}", maker.get(k)) for k in _MAKER_LENS_TAGS] + [
        ("XMP exifEX:LensModel", xmp_property(xmp, "exifEX:LensModel")),
        ("XMP aux:Lens", xmp_property(xmp, "aux:Lens")),
        ("LibRaw", fallback.get("lens")),
    ]:
        lens = _text(raw)
        if lens:
            sources["lens"] = tag
            break
    if lens:
        named = lensfun_lens(make, model, lens)
        if named and named.lower() != lens.lower():
            sources["lens"] += f"; lensfun database: {named}"

    # Focus distance: the maker note's (the camera's own reading), then EXIF SubjectDistance, then XMP.
    focus_range = _canon_focus_range(maker)
    focus = None
    if focus_range is not None:
        for tag, end in (("maker note CanonFi.FocusDistanceLower", focus_range[0]), ("maker note CanonFi.FocusDistanceUpper", focus_range[1])):
            _checked("focus_distance_m", end, *FOCUS_DISTANCE_RANGE_M, tag, "m", ignored)
        if all(FOCUS_DISTANCE_RANGE_M[0] <= end <= FOCUS_DISTANCE_RANGE_M[1] for end in focus_range):
            focus = round((focus_range[0] + focus_range[1]) / 2.0, 3)
            sources["focus_distance_m"] = "maker note CanonFi.FocusDistanceLower/Upper (middle of the range)"
        else:
            focus_range = None
    if focus is None:
        focus = first("focus_distance_m",
                      [(f"maker note {k.split('.', 1)[1]}", maker.get(k), convert) for k, convert in _MAKER_FOCUS_TAGS]
                      + [("EXIF SubjectDistance", tags.get(_SUBJECT_DISTANCE), _number),
                         ("XMP aux:ApproximateFocusDistance", xmp_property(xmp, "aux:ApproximateFocusDistance"), _number)],
                      *FOCUS_DISTANCE_RANGE_M, "m")

    orientation = tags.ifd0.get(_ORIENTATION, fallback.get("orientation", 1))
    if isinstance(orientation, (tuple, list)) and orientation:
        orientation = orientation[0]
    if not isinstance(orientation, int) or not 1 <= orientation <= 8:
        orientation = 1

    native, native_how = None, None
    for key in _NATIVE_WIDTH_TAGS:
        value = _number(maker.get(key))
        if value is not None and 16 <= value <= 100_000:
            native, native_how = int(value), f"maker note {key.split('.', 1)[1]}"
            break
    unit = tags.get(_FOCAL_PLANE_UNIT)
    unit = unit if isinstance(unit, int) else None
    resolution = _number(tags.get(_FOCAL_PLANE_X_RES))
    width_mm, source = sensor_width(
        make=make,
        model=model,
        focal_length_mm=focal,
        focal_length_35mm=focal_35,
        focal_plane_x_resolution=resolution,
        focal_plane_unit=unit,
        width_px=width_px,
        height_px=height_px,
        native_width_px=native,
    )
    if width_mm is not None:
        sources["sensor_width_mm"] = source
    if native is None and width_mm is not None and resolution and resolution > 0 and unit in _FOCAL_PLANE_UNITS:
        estimate = width_mm / _FOCAL_PLANE_UNITS[unit][0] * resolution
        if 16 <= estimate <= 100_000:
            native, native_how = int(round(estimate)), "FocalPlaneXResolution × the sensor width"
    if native is not None:
        sources["native_width_px"] = native_how
    if width_mm is not None and source.startswith("focal-plane resolution (") and native is None:
        native_how = None  # the width came from the file's own size: nothing to compare it with
    return Exif(
        camera=camera_name(make, model),
        lens=lens,
        fnumber=fnumber,
        focal_length_mm=focal,
        focal_length_35mm=focal_35,
        focus_distance_m=focus,
        sensor_width_mm=width_mm,
        sensor_width_source=source,
        orientation=orientation,
        focus_distance_range_m=focus_range,
        native_width_px=native,
        frame=_frame(width_px, height_px, native, native_how) if native_how else None,
        sources=sources,
        ignored=tuple(ignored),
    )
