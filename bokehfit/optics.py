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

A photo's f-stop (``compare``): :func:`resolve_geometry` takes each length from the
command line or EXIF, with its source (:class:`Geometry`), and :func:`estimate_fstop`
turns the fitted disc diameter into the f-stop or the bound it implies (:class:`FStop`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from bokehfit.apertures import Aperture
from bokehfit.errors import InputError
from bokehfit.uncertainty import measurable, unmeasurable_reason
from bokehfit.validate import RANGES, check

if TYPE_CHECKING:
    from bokehfit.fit import ApertureFit
    from bokehfit.io import Photo

__all__ = [
    "FAR_AS_INFINITY",
    "FStop",
    "Geometry",
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
    "estimate_fstop",
    "resolve_geometry",
]

LENS_MODELS = ("thin", "pinhole")
SIZE_CONVENTIONS = ("equal-area", "circumscribed")


#: Largest magnification m = f / (d_f − f) of a focused subject: the strongest camera macro lenses
#: reach 5× (Canon MP-E 65 mm); 10× leaves room. A focus distance nearer than f·(1 + 1/10) is no lens's.
MAX_MAGNIFICATION = 10.0
#: A light this many focus distances away or farther makes a disc within 1 % of a light's at infinity
#: (the disc grows as 1 − d_f/d, design.md §4): no photo tells them apart, so people read "≈ ∞".
FAR_AS_INFINITY = 100.0


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


@dataclass(frozen=True)
class Geometry:
    """What the f-stop needs, with where each value came from."""

    focal_length_mm: float | None
    sensor_width_mm: float | None
    focus_distance_m: float | None
    light_distance_m: float
    sources: dict[str, str]
    frame: str | None = None  #: how the file's pixels relate to the sensor (downscaled, cropped)
    pixel_pitch_mm: float | None = None  #: sensor width over the image's long side

    def to_json(self) -> dict:
        return {
            "focal_length_mm": self.focal_length_mm,
            "sensor_width_mm": self.sensor_width_mm,
            "focus_distance_m": self.focus_distance_m,
            "light_distance_m": None if math.isinf(self.light_distance_m) else self.light_distance_m,
            "sources": self.sources,
            "frame": self.frame,
            "pixel_pitch_mm": None if self.pixel_pitch_mm is None else round(self.pixel_pitch_mm, 6),
        }


@dataclass(frozen=True)
class FStop:
    """The f-stop estimate (or the bound it implies), or None with the reason.

    ``bound`` is None when ``value`` is the f-stop itself (the lights' distance is
    known) and ``"upper"`` when it is the largest f-stop the discs allow (the lights'
    distance is unknown: lights behind the focus plane at any finite distance give a
    smaller f-stop than lights at infinity). ``exif_fnumber`` is EXIF's FNumber;
    ``light_distances_m`` the distance of each disc's light that EXIF's FNumber implies
    (by disc index; None where no light on that side of the focus plane makes so large
    a disc); ``consistency`` says, when not None, that EXIF's FNumber, the focus
    distance and the fitted size disagree with every light distance.
    """

    value: float | None
    uncertainty: float | None
    reason: str | None
    convention: str
    lens_model: str
    bound: str | None = None
    meaning: str | None = None
    exif_fnumber: float | None = None
    light_distances_m: dict[int, float | None] = field(default_factory=dict)
    consistency: str | None = None


def resolve_geometry(
    photo: Photo,
    *,
    focal_length_mm: float | None = None,
    sensor_width_mm: float | None = None,
    focus_distance_m: float | None = None,
    light_distance_m: float = math.inf,
) -> Geometry:
    """The geometry from the command line where given, else from EXIF."""
    exif = photo.exif
    sources = {}

    def pick(name, given, from_exif, exif_source):
        if given is not None:
            sources[name] = "command line"
            return float(given)
        if from_exif is not None:
            sources[name] = exif_source
            return float(from_exif)
        sources[name] = "unknown"
        return None

    known = exif.sources
    focal = pick("focal_length_mm", focal_length_mm, exif.focal_length_mm, known.get("focal_length_mm", "EXIF FocalLength"))
    sensor = pick("sensor_width_mm", sensor_width_mm, exif.sensor_width_mm, exif.sensor_width_source)
    focus = pick("focus_distance_m", focus_distance_m, exif.focus_distance_m, known.get("focus_distance_m", "EXIF"))
    sources["light_distance_m"] = "command line" if not math.isinf(light_distance_m) else "unknown (f-stop given as a bound)"
    frame = exif.frame if sensor_width_mm is None else "sensor width from the command line: taken as the file's long side"
    pitch = None if sensor is None else pixel_pitch_mm(sensor, photo.width, photo.height)
    return Geometry(focal, sensor, focus, light_distance_m, sources, frame, pitch)


def estimate_fstop(
    fit: ApertureFit, photo: Photo, geometry: Geometry, lens_model: str, convention: str, focus_side: str | None = None
) -> FStop:
    """The aperture's f-stop from the fitted diameter, or the bound it implies, or None with the reason.

    With the lights' distance known the value is the f-stop. Without it, ``value`` is
    the f-stop for lights at infinity and ``bound`` is ``"upper"``: lights behind the
    focus plane at a finite distance d make the same disc at the smaller f-stop
    ``N_inf · (1 − d_f/d)``. Lights in front of the focus plane (``focus_side="near"``)
    allow any f-stop up to ``f / c`` (a light at the lens). With EXIF's FNumber known,
    each fitted disc's light distance follows from it (:func:`light_distance_from_coc`),
    and where none can make the discs so large, ``consistency`` says so.
    """
    if lens_model not in LENS_MODELS:
        raise InputError(f"lens model must be one of {', '.join(LENS_MODELS)} (got {lens_model!r})")
    if convention not in SIZE_CONVENTIONS:
        raise InputError(f"size convention must be one of {', '.join(SIZE_CONVENTIONS)} (got {convention!r})")
    side = focus_side or getattr(fit, "focus_side", "unknown")
    exif_n = photo.exif.fnumber
    unknown = _geometry_problem(geometry)
    if unknown:
        return FStop(None, None, unknown, convention, lens_model, exif_fnumber=exif_n)
    pitch = pixel_pitch_mm(geometry.sensor_width_mm, photo.width, photo.height)
    relative = fit.diameter_uncertainty_px / fit.diameter_px if fit.diameter_px else 0.0
    coc = fit.diameter_px * pitch
    try:
        value, bound, meaning = _fstop_of_coc(coc, geometry, side, lens_model)
    except InputError as error:
        return FStop(None, None, str(error), convention, lens_model, exif_fnumber=exif_n)
    relative, meaning = _with_focus_range(photo, geometry, side, lens_model, coc, value, relative, meaning)
    equal_area = value
    if convention == "circumscribed":
        value = circumscribed_fstop(value, fit.aperture)
    distances: dict[int, float | None] = {}
    consistency = None
    if exif_n is not None:
        distances = _exif_light_distances(fit, geometry, side, lens_model, pitch, exif_n)
        consistency = _exif_disagreement(fit, geometry, side, exif_n, equal_area, relative)
    if not measurable(value, value * relative):
        return FStop(None, None, unmeasurable_reason(f"f/{value:.2f}", value * relative, "the discs' sizes disagree"),
                     convention, lens_model, exif_fnumber=exif_n, light_distances_m=distances)
    return FStop(value, value * relative, None, convention, lens_model, bound, meaning, exif_n, distances, consistency)


def _geometry_problem(geometry: Geometry) -> str | None:
    """Why the geometry gives no f-stop (a length unknown, or a focus distance no lens has in the
    metadata), or None when it gives one; ``InputError`` for such a focus distance given on the command line."""
    missing = [name for name in ("focal_length_mm", "sensor_width_mm", "focus_distance_m") if getattr(geometry, name) is None]
    if missing:
        flags = ", ".join("--" + name.replace("_", "-") for name in missing)
        return f"unknown {', '.join(missing)} (give {flags})"
    problem = focus_problem(geometry.focal_length_mm, geometry.focus_distance_m)
    if problem:
        if "command line" in (geometry.sources.get("focus_distance_m"), geometry.sources.get("focal_length_mm")):
            raise InputError(f"--focus-distance-m: {problem}")
        return (f"{problem} ({geometry.sources.get('focus_distance_m')}, "
                f"{geometry.sources.get('focal_length_mm')}): the metadata is ignored; give --focus-distance-m")
    return None


def _fstop_of_coc(coc: float, geometry: Geometry, side: str, lens_model: str) -> tuple[float, str | None, str | None]:
    """The equal-area f-stop that makes discs of ``coc`` mm, with its ``bound`` and ``meaning``;
    ``InputError`` where the geometry gives none or one that no lens has."""
    f, focus, light = geometry.focal_length_mm, geometry.focus_distance_m, geometry.light_distance_m
    bound = meaning = None
    if math.isinf(light) and side == "near":
        value = f / coc  # a light at the lens: the largest aperture number that makes the disc
        bound, meaning = "upper", "lights in front of the focus plane at an unknown distance: any smaller f-stop fits"
    else:
        value = fstop_from_coc(coc, f, focus, light, lens_model)
        if math.isinf(light):
            bound = "upper"
            meaning = ("the lights' distance is unknown: this is the f-stop for lights at infinity; lights behind the "
                       "focus plane at any finite distance give a smaller f-stop (give --light-distance-m)")
    check_fitted_fstop(value)  # an f-stop no lens has is not a result: the geometry behind it is wrong
    return value, bound, meaning


def _with_focus_range(
    photo: Photo, geometry: Geometry, side: str, lens_model: str, coc: float, value: float, relative: float,
    meaning: str | None,
) -> tuple[float, str | None]:
    """The relative uncertainty and the meaning, widened by a focus distance that EXIF records as a range.

    A focus distance recorded as a range (Canon): its ends bracket the f-stop; half the spread
    joins the size's uncertainty (independent errors, added in quadrature).
    """
    focus_range = photo.exif.focus_distance_range_m
    if not focus_range or geometry.sources.get("focus_distance_m") == "command line" or (
            math.isinf(geometry.light_distance_m) and side == "near"):
        return relative, meaning
    try:
        ends = [fstop_from_coc(coc, geometry.focal_length_mm, end, geometry.light_distance_m, lens_model)
                for end in focus_range]
    except InputError:
        ends = None
    if ends:
        relative = math.hypot(relative, abs(ends[1] - ends[0]) / (2.0 * value))
        range_note = (f"the focus distance is a range, {focus_range[0]:g}–{focus_range[1]:g} m, which alone spans "
                      f"f/{min(ends):.2f}–f/{max(ends):.2f} (in the uncertainty)")
        meaning = range_note if meaning is None else f"{meaning}; {range_note}"
    return relative, meaning


def _exif_light_distances(
    fit: ApertureFit, geometry: Geometry, side: str, lens_model: str, pitch: float, exif_n: float
) -> dict[int, float | None]:
    """Each fitted disc's light distance (m) that EXIF's FNumber implies, by disc index (None where no light makes it)."""
    wanted = "near" if side == "near" else "far"
    distances: dict[int, float | None] = {}
    for item in fit.disc_fits:
        fitted = fit.disc_fit(item.disc)
        if fitted is None or not fitted.diameter_px > 0:
            continue
        distances[item.disc.index] = light_distance_from_coc(
            fitted.diameter_px * pitch, exif_n, geometry.focal_length_mm, geometry.focus_distance_m, wanted, lens_model)
    return distances


def _exif_disagreement(
    fit: ApertureFit, geometry: Geometry, side: str, exif_n: float, equal_area: float, relative: float
) -> str | None:
    """Why EXIF's FNumber, the geometry and the fitted (equal-area) f-stop disagree, or None where they agree."""
    f, focus, light = geometry.focal_length_mm, geometry.focus_distance_m, geometry.light_distance_m
    if side != "near" and math.isinf(light) and exif_n > equal_area * (1.0 + 2.0 * relative):
        return (
            f"EXIF's f/{exif_n:g} cannot make discs of {fit.diameter_px:.1f} px at {f:g} mm focused at {focus:g} m "
            f"from lights behind the focus plane at any distance (at most f/{equal_area:.2f}); lights in front of it, "
            "wrong metadata (focus distance, sensor width), a crop, a teleconverter or a lens far from thin would explain it"
        )
    if not math.isinf(light) and abs(exif_n - equal_area) > 2.0 * equal_area * relative + 0.15 * exif_n:
        return (
            f"EXIF's f/{exif_n:g} and the fitted f/{equal_area:.2f} for lights at {light:g} m disagree: "
            "check the light distance, the focus distance and the sensor width (a crop, a teleconverter or a lens far "
            "from thin would also explain it)"
        )
    return None
