"""EXIF and XMP: camera, lens, aperture, focal length, focus distance and sensor width.

Tags are read with Pillow (:class:`PIL.Image.Exif`) from the raw EXIF block
of a JPEG/PNG or from a TIFF-based file's own IFDs, and from the XMP packet.
Every value is checked: zeros, infinities and nonsense become None rather
than numbers that look real.

Sensor width
------------
The width of the sensor's long side in mm, with where it came from, in this
order:

(a) the camera table (:mod:`bokehfit.io.cameras`) when the model is listed;
(b) the 35 mm-equivalent focal length: the crop factor ``f35 / f`` is taken
    on the diagonal (43.27 mm for a 36 × 24 mm frame), and the long side
    follows from the image's aspect ratio; for a 3:2 frame this is exactly
    ``36 mm · f / f35``;
(c) ``FocalPlaneXResolution`` and its unit: ``pitch = unit / resolution``,
    ``width = long side in px · pitch``. The tag describes the camera's native
    frame, so this is only right when the file still has the native pixel
    width: a photo downscaled from 5472 to 2560 px with 152 px/mm gives
    16.8 mm for a 35.8 mm sensor. It is used only without (a) and (b), and
    only when the result lies in :data:`PLAUSIBLE_SENSOR_WIDTH_MM`.

Pair ``sensor_width_mm`` with the image's long side:
``mm_per_px = sensor_width_mm / max(width, height)``, valid while the image
shows the whole frame (downscaled is fine, cropped is not).
"""

from __future__ import annotations

import html
import math
import re
import warnings
from dataclasses import asdict, dataclass, field
from typing import Any, Mapping

from bokehfit.io.cameras import lookup_camera

__all__ = [
    "Exif",
    "ExifTags",
    "FOCUS_DISTANCE_RANGE_M",
    "PLAUSIBLE_SENSOR_WIDTH_MM",
    "build_exif",
    "camera_name",
    "read_exif_tags",
    "sensor_width",
    "xmp_property",
]

#: Sensor widths (mm) accepted from FocalPlaneXResolution: from 1/2.3" compacts to 645 medium format.
PLAUSIBLE_SENSOR_WIDTH_MM = (4.0, 60.0)
#: Focus distances (m) taken as real; outside is a placeholder (0, 0xFFFFFFFF = infinity) or nonsense.
FOCUS_DISTANCE_RANGE_M = (0.01, 10_000.0)
#: Diagonal of the 36 × 24 mm frame that 35 mm-equivalent focal lengths refer to.
FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)

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

    def to_json(self) -> dict:
        """The fields as plain JSON types (keys as the field names)."""
        return asdict(self)


@dataclass(frozen=True)
class ExifTags:
    """Raw EXIF tags by number: IFD0, the EXIF sub-IFD and the interoperability IFD."""

    ifd0: Mapping[int, Any] = field(default_factory=dict)
    exif: Mapping[int, Any] = field(default_factory=dict)
    interop: Mapping[int, Any] = field(default_factory=dict)

    def get(self, tag: int) -> Any:
        """A tag from the EXIF sub-IFD, else from IFD0, else None."""
        value = self.exif.get(tag)
        return self.ifd0.get(tag) if value is None else value


def read_exif_tags(blob: bytes | None) -> ExifTags:
    """Parse an EXIF block (``b"Exif\\0\\0"`` + TIFF structure) or a whole TIFF file.

    Damaged EXIF is not an error for a photo: whatever can't be parsed is left out.
    """
    if not blob:
        return ExifTags()
    from PIL import Image

    ifd0: dict = {}
    sub: dict = {}
    interop: dict = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Pillow warns on odd but harmless EXIF
        try:
            parsed = Image.Exif()
            parsed.load(blob)
            ifd0 = dict(parsed)
        except Exception:  # noqa: BLE001 - any damage means "no EXIF", never a failed load
            return ExifTags()
        for tag, target in ((_EXIF_IFD, sub), (_INTEROP_IFD, interop)):
            try:
                target.update(parsed.get_ifd(tag))
            except Exception:  # noqa: BLE001
                pass
    return ExifTags(ifd0, sub, interop)


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
    """A clean string from an EXIF text value (NULs and padding removed), else None."""
    if isinstance(value, (bytes, bytearray)):
        value = bytes(value).decode("utf-8", "replace")
    if not isinstance(value, str):
        return None
    text = re.sub(r"\s+", " ", value.replace("\x00", " ")).strip()
    return text or None


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
) -> tuple[float | None, str | None]:
    """Sensor width (long side, mm) and its source, by the priority of the module docstring.

    Parameters
    ----------
    make, model : str or None
        EXIF ``Make`` and ``Model``.
    focal_length_mm, focal_length_35mm : float or None
        EXIF ``FocalLength`` and ``FocalLengthIn35mmFilm``.
    focal_plane_x_resolution : float or None
        EXIF ``FocalPlaneXResolution``, pixels per ``focal_plane_unit``.
    focal_plane_unit : int or None
        EXIF ``FocalPlaneResolutionUnit`` (2 inch, the default; 3 cm; 4 mm; 5 µm).
    width_px, height_px : int
        The image as stored in the file (before orientation).

    Returns
    -------
    (float, str) or (None, None)

    Examples
    --------
    >>> sensor_width(model="Canon EOS 6D", focal_plane_x_resolution=152, focal_plane_unit=4,
    ...              width_px=2560, height_px=1600)
    (35.8, 'camera table (Canon EOS 6D)')
    """
    spec = lookup_camera(model, make)
    if spec is not None:
        return spec.sensor_width_mm, f"camera table ({spec.name})"
    long_px, short_px = max(width_px, height_px), min(width_px, height_px)
    if focal_length_mm and focal_length_35mm and focal_length_mm > 0 and focal_length_35mm > 0:
        diagonal_mm = FULL_FRAME_DIAGONAL_MM * focal_length_mm / focal_length_35mm
        width_mm = diagonal_mm * long_px / math.hypot(long_px, short_px)
        if 1.0 <= width_mm <= 100.0:
            ratio = long_px / short_px
            frame = "3:2" if abs(ratio - 1.5) < 0.02 else ("4:3" if abs(ratio - 4 / 3) < 0.02 else f"{ratio:.3g}:1")
            source = (
                f"35 mm-equivalent focal length ({focal_length_35mm:g} mm for {focal_length_mm:g} mm;"
                f" crop factor on the diagonal, {frame} frame assumed uncropped)"
            )
            return round(width_mm, 2), source
    if focal_plane_x_resolution and focal_plane_x_resolution > 0:
        unit = _FOCAL_PLANE_UNITS.get(2 if focal_plane_unit is None else int(focal_plane_unit))
        if unit is not None:
            pitch_mm = unit[0] / focal_plane_x_resolution
            width_mm = long_px * pitch_mm
            low, high = PLAUSIBLE_SENSOR_WIDTH_MM
            if low <= width_mm <= high:
                source = (
                    f"focal-plane resolution ({focal_plane_x_resolution:g} px/{unit[1]} × {long_px} px;"
                    f" plausible, but right only if the file has the sensor's native pixel width)"
                )
                return round(width_mm, 2), source
    return None, None


def xmp_property(xmp: bytes | str | None, name: str) -> str | None:
    """The value of an XMP property ``prefix:Name`` (element or attribute form), or None.

    Examples
    --------
    >>> xmp_property(b"<aux:ApproximateFocusDistance>727/100</aux:ApproximateFocusDistance>",
    ...              "aux:ApproximateFocusDistance")
    '727/100'
    """
    if not xmp:
        return None
    text = xmp.decode("utf-8", "replace") if isinstance(xmp, (bytes, bytearray)) else xmp
    quoted = re.escape(name)
    match = re.search(rf"<{quoted}>\s*([^<]*?)\s*</{quoted}>", text) or re.search(
        rf"\b{quoted}\s*=\s*(?:\"([^\"]*)\"|'([^']*)')", text
    )
    if not match:
        return None
    value = next(group for group in match.groups() if group is not None)
    return html.unescape(value).strip() or None


def _focus_distance(value: Any) -> float | None:
    distance = _number(value)
    if distance is None or distance >= 0xFFFFFFFF:  # 0xFFFFFFFF/1 is EXIF's "infinity"
        return None
    return _in_range(distance, *FOCUS_DISTANCE_RANGE_M)


def build_exif(
    tags: ExifTags,
    xmp: bytes | None = None,
    *,
    width_px: int,
    height_px: int,
    fallback: Mapping[str, Any] | None = None,
) -> Exif:
    """An :class:`Exif` from parsed tags and the XMP packet.

    Parameters
    ----------
    tags : ExifTags
        From :func:`read_exif_tags`.
    xmp : bytes or None
        The XMP packet.
    width_px, height_px : int
        The image as stored (before orientation), for the sensor-width rules.
    fallback : mapping, optional
        Values to use where the tags say nothing (``lens``, ``fnumber``,
        ``focal_length_mm``, ``orientation``), e.g. from LibRaw for raw files.
    """
    fallback = dict(fallback or {})
    make = _text(tags.ifd0.get(_MAKE)) or _text(xmp_property(xmp, "tiff:Make"))
    model = _text(tags.ifd0.get(_MODEL)) or _text(xmp_property(xmp, "tiff:Model"))

    fnumber = _in_range(_number(tags.get(_FNUMBER)), 0.5, 128.0)
    if fnumber is None:
        apex = _number(tags.get(_APERTURE_VALUE))
        if apex is not None and -2.0 <= apex <= 14.0:
            fnumber = round(2.0 ** (apex / 2.0), 1)
    if fnumber is None:
        fnumber = _in_range(_number(xmp_property(xmp, "exif:FNumber")), 0.5, 128.0)
    if fnumber is None:
        fnumber = _in_range(_number(fallback.get("fnumber")), 0.5, 128.0)

    focal = _in_range(_number(tags.get(_FOCAL_LENGTH)), 0.5, 5000.0)
    if focal is None:
        focal = _in_range(_number(xmp_property(xmp, "exif:FocalLength")), 0.5, 5000.0)
    if focal is None:
        focal = _in_range(_number(fallback.get("focal_length_mm")), 0.5, 5000.0)
    focal_35 = _in_range(_number(tags.get(_FOCAL_LENGTH_35MM)), 1.0, 10000.0)
    if focal_35 is None:
        focal_35 = _in_range(_number(xmp_property(xmp, "exif:FocalLengthIn35mmFilm")), 1.0, 10000.0)

    lens = (
        _text(tags.get(_LENS_MODEL))
        or _text(xmp_property(xmp, "exifEX:LensModel"))
        or _text(xmp_property(xmp, "aux:Lens"))
        or _text(fallback.get("lens"))
    )
    focus = _focus_distance(tags.get(_SUBJECT_DISTANCE))
    if focus is None:
        focus = _focus_distance(xmp_property(xmp, "aux:ApproximateFocusDistance"))

    orientation = tags.ifd0.get(_ORIENTATION, fallback.get("orientation", 1))
    if isinstance(orientation, (tuple, list)) and orientation:
        orientation = orientation[0]
    if not isinstance(orientation, int) or not 1 <= orientation <= 8:
        orientation = 1

    unit = tags.get(_FOCAL_PLANE_UNIT)
    width_mm, source = sensor_width(
        make=make,
        model=model,
        focal_length_mm=focal,
        focal_length_35mm=focal_35,
        focal_plane_x_resolution=_number(tags.get(_FOCAL_PLANE_X_RES)),
        focal_plane_unit=unit if isinstance(unit, int) else None,
        width_px=width_px,
        height_px=height_px,
    )
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
    )
