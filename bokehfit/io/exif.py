"""EXIF, maker notes and XMP: camera, lens, aperture, focal length, focus distance, sensor width.

EXIF tags, maker notes included, are decoded by exiv2 (python-exiv2, which
ships libexiv2) from the EXIF block of a JPEG/PNG or from a TIFF-based file's
own IFDs (:func:`read_exif_tags`, :mod:`bokehfit.io.tags`); the XMP packet by
:func:`parse_xmp`. This module makes an :class:`Exif` of them (:func:`build_exif`). Every
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
From the lensfun database, else the 35 mm-equivalent focal length, else the focal-plane
resolution: :mod:`bokehfit.io.sensor` gives the rules.

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
The XMP packet is untrusted text, read by :func:`~bokehfit.io.xmp.parse_xmp` (:mod:`bokehfit.io.xmp`).
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass, field
from typing import Any, Mapping

from bokehfit.io.sensor import FOCAL_PLANE_UNITS, PLAUSIBLE_SENSOR_WIDTH_MM, lensfun_camera, lensfun_lens, sensor_width
from bokehfit.io.tags import EXIF_MAX_BYTES, ExifTags, read_exif_tags, read_file_tags, tag_number, tag_text
from bokehfit.io.xmp import XMP_MAX_BYTES, parse_xmp, xmp_property
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

#: Focus distances (m) taken as real; outside is a placeholder (0, 0xFFFFFFFF = infinity) or nonsense.
FOCUS_DISTANCE_RANGE_M = (0.01, 10_000.0)

# EXIF tag numbers (EXIF 2.32, CIPA DC-008).
_MAKE, _MODEL, _ORIENTATION = 0x010F, 0x0110, 0x0112
_EXIF_IFD, _INTEROP_IFD = 0x8769, 0xA005
_FNUMBER, _APERTURE_VALUE, _SUBJECT_DISTANCE, _FOCAL_LENGTH = 0x829D, 0x9202, 0x9206, 0x920A
_COLOR_SPACE, _FOCAL_PLANE_X_RES, _FOCAL_PLANE_UNIT = 0xA001, 0xA20E, 0xA210
_FOCAL_LENGTH_35MM, _LENS_MODEL, _INTEROP_INDEX = 0xA405, 0xA434, 0x0001


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
        Width of the sensor's long side (:mod:`bokehfit.io.sensor`).
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
    make_text, model_text = tag_text(make), tag_text(model)
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


def _focus_distance(value: Any) -> float | None:
    distance = tag_number(value)
    if distance is None or distance >= 0xFFFFFFFF:  # 0xFFFFFFFF/1 is EXIF's "infinity"
        return None
    return _in_range(distance, *FOCUS_DISTANCE_RANGE_M)


def _nikon_lens_data_distance(code: Any) -> float | None:
    """Nikon lens data's FocusDistance byte: ``0.01 m · 10^(code/40)`` (ExifTool's decoding)."""
    number = tag_number(code)
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
    ("Exif.Nikon3.FocusDistance", tag_number),
    ("Exif.OlympusFi.FocusDistance", tag_number),
    ("Exif.Olympus.FocusDistance", tag_number),
    ("Exif.Olympus2.FocusDistance", tag_number),
)
#: Maker-note tags that give the camera's native image width in pixels.
_NATIVE_WIDTH_TAGS = ("Exif.Canon.AFCanonImageWidth", "Exif.Canon.AFImageWidth", "Exif.Olympus.ImageWidth",
                      "Exif.Olympus2.ImageWidth", "Exif.Panasonic.ImageWidth")
#: Maker-note lens names (the EXIF LensModel comes first).
_MAKER_LENS_TAGS = ("Exif.Canon.LensModel", "Exif.OlympusEq.LensModel")


def _canon_focus_range(maker: Mapping[str, Any]) -> tuple[float, float] | None:
    """Canon's FocusDistanceLower/Upper (cm; 0xFFFF or a negative value is infinity), in m."""
    lower, upper = tag_number(maker.get("Exif.CanonFi.FocusDistanceLower")), tag_number(maker.get("Exif.CanonFi.FocusDistanceUpper"))
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


class _Found:
    """Where each value came from (``sources``: field name -> tag name, database or rule), and the
    values found but not used, one line each with the reason (``ignored``)."""

    def __init__(self):
        self.sources: dict[str, str] = {}
        self.ignored: list[str] = []

    def first(self, field_name: str, candidates, low: float, high: float, unit: str):
        """The first candidate (tag name, raw value, converter) in range; out-of-range ones are noted."""
        for tag, raw, convert in candidates:
            value = convert(raw) if raw is not None else None
            if value is None:
                continue
            if math.isinf(value) or value >= 0xFFFFFFFF:
                continue
            kept = _checked(field_name, value, low, high, tag, unit, self.ignored)
            if kept is not None:
                self.sources[field_name] = tag
                return kept
        return None


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
    found = _Found()
    make = tag_text(tags.ifd0.get(_MAKE)) or tag_text(xmp_property(xmp, "tiff:Make"))
    model = tag_text(tags.ifd0.get(_MODEL)) or tag_text(xmp_property(xmp, "tiff:Model"))
    fnumber, focal, focal_35 = _aperture_and_focal_length(tags, xmp, fallback, found)
    lens = _lens(tags, xmp, fallback, make, model, found.sources)
    focus, focus_range = _focus_distance_m(tags, xmp, found)
    orientation = _orientation(tags, fallback)
    width_mm, source, native, frame = _sensor(tags, make, model, focal, focal_35, width_px, height_px, found.sources)
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
        frame=frame,
        sources=found.sources,
        ignored=tuple(found.ignored),
    )


def _aperture_and_focal_length(tags: ExifTags, xmp: Mapping[str, str], fallback: Mapping[str, Any], found: _Found):
    """The f-number, focal length and 35 mm-equivalent focal length, each from its first source in range."""
    apex = tag_number(tags.get(_APERTURE_VALUE))
    fnumber = found.first("fnumber", [
        ("EXIF FNumber", tags.get(_FNUMBER), tag_number),
        ("EXIF ApertureValue (APEX)", apex, lambda a: round(2.0 ** (a / 2.0), 1) if -2.0 <= a <= 30.0 else None),
        ("XMP exif:FNumber", xmp_property(xmp, "exif:FNumber"), tag_number),
        ("LibRaw", fallback.get("fnumber"), tag_number),
    ], 0.5, 128.0, "")
    focal = found.first("focal_length_mm", [
        ("EXIF FocalLength", tags.get(_FOCAL_LENGTH), tag_number),
        ("XMP exif:FocalLength", xmp_property(xmp, "exif:FocalLength"), tag_number),
        ("LibRaw", fallback.get("focal_length_mm"), tag_number),
    ], RANGES["focal_length_mm"].low, RANGES["focal_length_mm"].high, "mm")
    focal_35 = found.first("focal_length_35mm", [
        ("EXIF FocalLengthIn35mmFilm", tags.get(_FOCAL_LENGTH_35MM), tag_number),
        ("XMP exif:FocalLengthIn35mmFilm", xmp_property(xmp, "exif:FocalLengthIn35mmFilm"), tag_number),
    ], 1.0, 10000.0, "mm")
    return fnumber, focal, focal_35


def _lens(tags: ExifTags, xmp: Mapping[str, str], fallback: Mapping[str, Any], make, model, sources: dict) -> str | None:
    """The lens name: EXIF LensModel, the maker note's, XMP's, LibRaw's; lensfun's name added to its source."""
    maker = tags.maker
    lens = None
    for tag, raw in [("EXIF LensModel", tags.get(_LENS_MODEL))] + [(f"maker note {k.split('.', 1)[1]}", maker.get(k)) for k in _MAKER_LENS_TAGS] + [
        ("XMP exifEX:LensModel", xmp_property(xmp, "exifEX:LensModel")),
        ("XMP aux:Lens", xmp_property(xmp, "aux:Lens")),
        ("LibRaw", fallback.get("lens")),
    ]:
        lens = tag_text(raw)
        if lens:
            sources["lens"] = tag
            break
    if lens:
        named = lensfun_lens(make, model, lens)
        if named and named.lower() != lens.lower():
            sources["lens"] += f"; lensfun database: {named}"
    return lens


def _focus_distance_m(tags: ExifTags, xmp: Mapping[str, str], found: _Found):
    """The focus distance and, where the maker note gives a range, the range (module docstring's order)."""
    maker = tags.maker
    # Focus distance: the maker note's (the camera's own reading), then EXIF SubjectDistance, then XMP.
    focus_range = _canon_focus_range(maker)
    focus = None
    if focus_range is not None:
        for tag, end in (("maker note CanonFi.FocusDistanceLower", focus_range[0]), ("maker note CanonFi.FocusDistanceUpper", focus_range[1])):
            _checked("focus_distance_m", end, *FOCUS_DISTANCE_RANGE_M, tag, "m", found.ignored)
        if all(FOCUS_DISTANCE_RANGE_M[0] <= end <= FOCUS_DISTANCE_RANGE_M[1] for end in focus_range):
            focus = round((focus_range[0] + focus_range[1]) / 2.0, 3)
            found.sources["focus_distance_m"] = "maker note CanonFi.FocusDistanceLower/Upper (middle of the range)"
        else:
            focus_range = None
    if focus is None:
        focus = found.first("focus_distance_m",
                            [(f"maker note {k.split('.', 1)[1]}", maker.get(k), convert) for k, convert in _MAKER_FOCUS_TAGS]
                            + [("EXIF SubjectDistance", tags.get(_SUBJECT_DISTANCE), tag_number),
                               ("XMP aux:ApproximateFocusDistance", xmp_property(xmp, "aux:ApproximateFocusDistance"), tag_number)],
                            *FOCUS_DISTANCE_RANGE_M, "m")
    return focus, focus_range


def _orientation(tags: ExifTags, fallback: Mapping[str, Any]) -> int:
    """The EXIF orientation, 1..8 (1 if absent or invalid)."""
    orientation = tags.ifd0.get(_ORIENTATION, fallback.get("orientation", 1))
    if isinstance(orientation, (tuple, list)) and orientation:
        orientation = orientation[0]
    if not isinstance(orientation, int) or not 1 <= orientation <= 8:
        orientation = 1
    return orientation


def _sensor(tags: ExifTags, make, model, focal, focal_35, width_px: int, height_px: int, sources: dict):
    """Sensor width and its source, the camera's native width, and how the file's frame relates to it."""
    maker = tags.maker
    native, native_how = None, None
    for key in _NATIVE_WIDTH_TAGS:
        value = tag_number(maker.get(key))
        if value is not None and 16 <= value <= 100_000:
            native, native_how = int(value), f"maker note {key.split('.', 1)[1]}"
            break
    unit = tags.get(_FOCAL_PLANE_UNIT)
    unit = unit if isinstance(unit, int) else None
    resolution = tag_number(tags.get(_FOCAL_PLANE_X_RES))
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
    if native is None and width_mm is not None and resolution and resolution > 0 and unit in FOCAL_PLANE_UNITS:
        estimate = width_mm / FOCAL_PLANE_UNITS[unit][0] * resolution
        if 16 <= estimate <= 100_000:
            native, native_how = int(round(estimate)), "FocalPlaneXResolution × the sensor width"
    if native is not None:
        sources["native_width_px"] = native_how
    if width_mm is not None and source.startswith("focal-plane resolution (") and native is None:
        native_how = None  # the width came from the file's own size: nothing to compare it with
    frame = _frame(width_px, height_px, native, native_how) if native_how else None
    return width_mm, source, native, frame
