"""Defocus geometry: circle of confusion and f-stop, for photos and for renderers (design.md §4).

Notes
-----
Thin lens (photos): a point at distance d, with the lens focused at d_f, makes
a blur disc on the sensor of diameter

    c = (f/N) · f · |d − d_f| / (d · (d_f − f)),     and for d → ∞:  c = f² / (N (d_f − f)).

Pinhole camera with a shaped aperture (Blender Cycles, Mitsuba, pbrt, and
bokehfit's own renderer): the ray through the aperture point meets the focus
plane, so c = (f/N) · f · |d − d_f| / (d · d_f), smaller by the factor (1 − f/d_f).

``N`` here is the equal-area f-stop: the aperture's area is that of a circle
of diameter f/N, so every shape passes the same light. The circumscribed
convention (the shape's circumscribed circle has diameter f/N) gives a larger
number for polygons: N_circ = N_eq / (R·√π), with R the circumradius of the
unit-area shape.
"""

from __future__ import annotations

import math

from bokehfit.apertures import Aperture
from bokehfit.errors import InputError, check_positive

__all__ = ["LENS_MODELS", "SIZE_CONVENTIONS", "coc_mm", "fstop_from_coc", "circumscribed_fstop", "pixel_pitch_mm"]

LENS_MODELS = ("thin", "pinhole")
SIZE_CONVENTIONS = ("equal-area", "circumscribed")


def _check_geometry(focal_length_mm: float, focus_distance_m: float, light_distance_m: float) -> tuple[float, float, float]:
    f = check_positive("focal_length_mm", focal_length_mm)
    focus = check_positive("focus_distance_m", focus_distance_m) * 1000.0
    light = float(light_distance_m)
    if math.isnan(light) or light <= 0.0:
        raise InputError(f"light_distance_m must be greater than 0 or inf (got {light_distance_m!r})")
    if focus <= f:
        raise InputError(
            f"focus distance ({focus / 1000:g} m) must be longer than the focal length ({f:g} mm): "
            "nothing can be focused closer"
        )
    return f, focus, light * 1000.0


def _defocus_factor(f: float, focus: float, light: float, lens_model: str) -> float:
    """c · N / f² (mm⁻¹): the blur diameter per unit of f²/N."""
    if lens_model not in LENS_MODELS:
        raise InputError(f"lens_model must be one of {', '.join(LENS_MODELS)} (got {lens_model!r})")
    denominator = focus - f if lens_model == "thin" else focus
    if math.isinf(light):
        return 1.0 / denominator
    return abs(light - focus) / (light * denominator)


def coc_mm(fstop: float, focal_length_mm: float, focus_distance_m: float, light_distance_m: float, lens_model: str = "thin") -> float:
    """Blur-disc diameter on the sensor (mm) of a point light; see the module notes."""
    n = check_positive("fstop", fstop)
    f, focus, light = _check_geometry(focal_length_mm, focus_distance_m, light_distance_m)
    return f * f / n * _defocus_factor(f, focus, light, lens_model)


def fstop_from_coc(
    coc: float, focal_length_mm: float, focus_distance_m: float, light_distance_m: float, lens_model: str = "thin"
) -> float:
    """Equal-area f-stop that makes a blur disc of diameter ``coc`` mm; inverse of :func:`coc_mm`.

    Raises ``InputError`` where the geometry leaves the f-stop undefined (the
    light at the focus distance makes no disc).
    """
    c = check_positive("coc", coc)
    f, focus, light = _check_geometry(focal_length_mm, focus_distance_m, light_distance_m)
    factor = _defocus_factor(f, focus, light, lens_model)
    if factor <= 0.0:
        raise InputError("the light is at the focus distance, where it makes no blur disc: the f-stop is undefined")
    return f * f * factor / c


def circumscribed_fstop(fstop_equal_area: float, aperture: Aperture) -> float:
    """The same aperture's f-stop in the circumscribed convention (N / (R·√π))."""
    return fstop_equal_area / (aperture.extent() * math.sqrt(math.pi))


def pixel_pitch_mm(sensor_width_mm: float, image_width_px: int, image_height_px: int) -> float:
    """Pixel pitch from the sensor's long side and the image's long side."""
    return check_positive("sensor_width_mm", sensor_width_mm) / max(image_width_px, image_height_px)
