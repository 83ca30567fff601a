"""Sensor width: the long side of the camera's sensor in mm, from lensfun or the metadata.

The width of the sensor's long side in mm, with where it came from, in this
order (:func:`sensor_width`):

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
"""

from __future__ import annotations

import functools
import math

from bokehfit.io.tags import tag_text
from bokehfit.validate import RANGES

__all__ = [
    "FOCAL_PLANE_UNITS",
    "FULL_FRAME_DIAGONAL_MM",
    "PLAUSIBLE_SENSOR_WIDTH_MM",
    "lensfun_camera",
    "lensfun_lens",
    "sensor_width",
]

#: Sensor widths (mm) accepted from FocalPlaneXResolution: from 1/2.3" compacts to 645 medium format.
PLAUSIBLE_SENSOR_WIDTH_MM = (4.0, 60.0)
#: Diagonal of the 36 × 24 mm frame that 35 mm-equivalent focal lengths refer to.
FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)
#: FocalPlaneResolutionUnit -> (mm per unit, name). 1 means "no absolute unit".
FOCAL_PLANE_UNITS = {2: (25.4, "inch"), 3: (10.0, "cm"), 4: (1.0, "mm"), 5: (0.001, "µm")}


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
    model = tag_text(model)
    if not model:
        return None
    key = " ".join(model.lower().split())
    database = _lensfun_database()
    try:
        cameras = database.find_cameras(tag_text(make), model, loose_search=False) if make else []
        if not cameras:
            cameras = [c for c in database.find_cameras(None, model, loose_search=True)
                       if " ".join(c.model.lower().split()) in (key, f"{(tag_text(make) or '').split(' ')[0].lower()} {key}")]
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
        unit = FOCAL_PLANE_UNITS.get(2 if focal_plane_unit is None else int(focal_plane_unit))
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
