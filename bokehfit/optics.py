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

Every length and the f-stop must lie in its range of ``bokehfit.validate.RANGES``
(e.g. focal length 1 mm to 10 m); the error names the parameter and the range.
"""

from __future__ import annotations

import math

from bokehfit.apertures import Aperture
from bokehfit.errors import InputError
from bokehfit.validate import RANGES, check

__all__ = [
    "LENS_MODELS",
    "MAX_MAGNIFICATION",
    "check_fitted_fstop",
    "focus_problem",
    "SIZE_CONVENTIONS",
    "coc_mm",
    "fstop_from_coc",
    "circumscribed_fstop",
    "light_distance_from_coc",
    "pixel_pitch_mm",
]

LENS_MODELS = ("thin", "pinhole")
SIZE_CONVENTIONS = ("equal-area", "circumscribed")


#: Largest magnification m = f / (d_f − f) of a focused subject: the strongest camera macro lenses
#: reach 5× (Canon MP-E 65 mm); 10× leaves room. A focus distance nearer than f·(1 + 1/10) is no lens's.
MAX_MAGNIFICATION = 10.0


def focus_problem(focal_length_mm: float, focus_distance_m: float) -> str | None:
    """Why a focus distance can't go with a focal length (in words), or None when it can.

    The thin lens focuses a subject at d_f with magnification ``f / (d_f − f)``; beyond
    :data:`MAX_MAGNIFICATION` (d_f within 10 % of f) no camera lens focuses, and the
    f-stop that follows would be absurd (f/55,834,718 for 10000 mm focused at 10.001 m).
    """
    f, focus = float(focal_length_mm), float(focus_distance_m) * 1000.0
    if focus <= f:
        return (f"the focus distance ({focus / 1000:g} m) is not longer than the focal length ({f:g} mm): "
                "nothing can be focused closer")
    magnification = f / (focus - f)
    if magnification > MAX_MAGNIFICATION:
        return (f"the focus distance ({focus / 1000:g} m) with the focal length ({f:g} mm) is a magnification of "
                f"{magnification:.3g}×, beyond any camera lens (at most {MAX_MAGNIFICATION:g}×)")
    return None


def _check_geometry(focal_length_mm: float, focus_distance_m: float, light_distance_m: float) -> tuple[float, float, float]:
    f = check("focal_length_mm", focal_length_mm)
    focus = check("focus_distance_m", focus_distance_m) * 1000.0
    light = check("light_distance_m", light_distance_m)
    if focus <= f:
        raise InputError(
            f"focus distance ({focus / 1000:g} m) must be longer than the focal length ({f:g} mm): "
            "nothing can be focused closer"
        )
    return f, focus, light * 1000.0


def check_fitted_fstop(value: float) -> float:
    """``value``, an f-stop that a fit implies, or ``InputError`` saying why it can't be a lens's.

    The range is ``RANGES["fitted_fstop"]``: outside it the geometry behind the number
    (focal length, focus distance, sensor width, the lights' distance) is wrong, and the
    number must not be reported as a result.
    """
    rule = RANGES["fitted_fstop"]
    if not rule.contains(value):
        shown = f"{value:.3g}" if math.isfinite(value) else str(value)
        raise InputError(
            f"the discs' size implies f/{shown}, outside the range of real lenses (f/{rule.low:g} to f/{rule.high:g}): "
            "the focal length, focus distance, sensor width or lights' distance is wrong"
        )
    return value


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
    n = check("fstop", fstop)
    f, focus, light = _check_geometry(focal_length_mm, focus_distance_m, light_distance_m)
    return f * f / n * _defocus_factor(f, focus, light, lens_model)


def fstop_from_coc(
    coc: float, focal_length_mm: float, focus_distance_m: float, light_distance_m: float, lens_model: str = "thin"
) -> float:
    """Equal-area f-stop that makes a blur disc of diameter ``coc`` mm; inverse of :func:`coc_mm`.

    Raises ``InputError`` where the geometry leaves the f-stop undefined (the
    light at the focus distance makes no disc).
    """
    c = check("coc_mm", coc, name="coc")
    f, focus, light = _check_geometry(focal_length_mm, focus_distance_m, light_distance_m)
    if light <= f:  # a photo's lights are in front of the lens, beyond its focal length
        raise InputError(f"the lights' distance ({light / 1000:g} m) must be longer than the focal length ({f:g} mm): "
                         "a light nearer than that makes no image on the sensor")
    factor = _defocus_factor(f, focus, light, lens_model)
    if factor <= 0.0:
        raise InputError("the light is at the focus distance, where it makes no blur disc: the f-stop is undefined")
    return f * f * factor / c


def light_distance_from_coc(
    coc: float, fstop: float, focal_length_mm: float, focus_distance_m: float, side: str = "far", lens_model: str = "thin"
) -> float | None:
    """The light distance (m) that makes a blur disc of ``coc`` mm at ``fstop``; inverse of :func:`coc_mm` in d.

    Parameters
    ----------
    coc : float
        Blur-disc diameter on the sensor, mm.
    fstop : float
        Equal-area f-stop.
    focal_length_mm, focus_distance_m : float
        The lens and where it was focused.
    side : {"far", "near"}
        Whether the light is behind the focus plane (d > d_f) or in front of it.

    Returns
    -------
    float or None
        None where no light on that side makes so large a disc: behind the focus
        plane the disc grows towards ``f² / (N (d_f − f))`` at infinity and never
        reaches it.

    Notes
    -----
    With ``k = c N (d_f − f) / f²`` (thin lens; ``d_f`` for the pinhole model), the
    disc equation ``c = (f/N) f |d − d_f| / (d (d_f − f))`` gives
    ``d = d_f / (1 − k)`` behind the focus plane (for ``k < 1``) and
    ``d = d_f / (1 + k)`` in front of it.

    Examples
    --------
    >>> round(light_distance_from_coc(coc_mm(2.8, 50, 2.0, 5.0), 2.8, 50, 2.0), 6)
    5.0
    """
    c = check("coc_mm", coc, name="coc")
    n = check("fstop", fstop)
    f, focus, _ = _check_geometry(focal_length_mm, focus_distance_m, math.inf)
    if side not in ("far", "near"):
        raise InputError(f"side must be one of far, near (got {side!r})")
    k = c * n * _defocus_factor(f, focus, math.inf, lens_model) ** -1 / (f * f)
    if side == "near":
        return focus / (1.0 + k) / 1000.0
    return focus / (1.0 - k) / 1000.0 if k < 1.0 else None


def circumscribed_fstop(fstop_equal_area: float, aperture: Aperture) -> float:
    """The same aperture's f-stop in the circumscribed convention (N / (R·√π))."""
    return fstop_equal_area / (aperture.extent() * math.sqrt(math.pi))


def pixel_pitch_mm(sensor_width_mm: float, image_width_px: int, image_height_px: int) -> float:
    """Pixel pitch from the sensor's long side and the image's long side."""
    return check("sensor_width_mm", sensor_width_mm) / max(image_width_px, image_height_px)
