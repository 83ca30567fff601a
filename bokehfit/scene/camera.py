"""The renderer's lens and the render settings, validated at the public boundary.

The camera is design.md §4's "renderer camera (seed)": a pinhole ray through a
point of the pixel meets the focus plane (perpendicular to the view axis at the
focus distance), and the lens ray goes from a sampled aperture point to that
hit. The sensor is ``sensor_width_mm`` wide behind a lens of
``focal_length_mm`` (defaults 36 mm and 35 mm: a full-frame 35 mm lens, a
horizontal field of view of 54.4°); the image's width spans the sensor's width
and pixels are square.

Notes
-----
Equal-area convention (design.md §4): at f-stop N every shape has the area of
a circle of diameter A = f/N, so the unit-area samplers are scaled by
A·√π/2. A point at depth d (along the view axis) blurs into the aperture's
shape, of equal-area diameter on the sensor

    c = A · f · |d − d_f| / (d · d_f) = (f²/N) · |1/d_f − 1/d|,

upright behind the focus plane and turned by 180° in front of it
(``bokehfit.optics.coc_mm`` with ``lens_model="pinhole"``); in pixels
c · width_px / sensor_width_mm.

Image values are radiance averaged over the aperture, as in Mitsuba's and
Cycles' thin-lens cameras: the f-stop changes the blur, not the exposure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bokehfit.apertures import Aperture
from bokehfit.errors import InputError
from bokehfit.optics import coc_mm
from bokehfit.validate import RANGES, check

__all__ = [
    "Lens",
    "RenderSettings",
    "make_lens",
    "make_settings",
    "FOCAL_LENGTH_MM",
    "SENSOR_WIDTH_MM",
    "MAX_IMAGE_SIDE",
]

#: Default focal length and sensor width (full frame).
FOCAL_LENGTH_MM = 35.0
SENSOR_WIDTH_MM = 36.0
#: Accepted f-stops and focus distances (m); bokehfit.validate.RANGES gives the reasons.
FSTOP_RANGE = (RANGES["fstop"].low, RANGES["fstop"].high)
FOCUS_RANGE_M = (RANGES["focus_distance_m"].low, RANGES["focus_distance_m"].high)
#: Longest image side and most samples per pixel (see bokehfit.validate.RANGES).
MAX_IMAGE_SIDE = int(RANGES["image_side_px"].high)
MAX_SPP = int(RANGES["spp"].high)


@dataclass(frozen=True)
class Lens:
    """Aperture, f-stop and focus of the renderer camera (see the module notes)."""

    aperture: Aperture
    fstop: float
    focus_distance_m: float
    focal_length_mm: float = FOCAL_LENGTH_MM
    sensor_width_mm: float = SENSOR_WIDTH_MM

    @property
    def aperture_diameter_mm(self) -> float:
        """Diameter of the circle with the aperture's area, f/N (mm)."""
        return self.focal_length_mm / self.fstop

    @property
    def aperture_scale_m(self) -> float:
        """Scale of the unit-area samplers, (f/N)·√π/2, in metres."""
        return self.aperture_diameter_mm / 1000.0 * math.sqrt(math.pi) / 2.0

    def tan_half_fov(self, width_px: int, height_px: int) -> tuple[float, float]:
        """Tangents of the half fields of view, horizontal and vertical."""
        tan_x = self.sensor_width_mm / (2.0 * self.focal_length_mm)
        return tan_x, tan_x * height_px / width_px

    def coc_mm(self, depth_m: float) -> float:
        """Equal-area blur diameter on the sensor (mm) of a point at ``depth_m`` (may be inf)."""
        return coc_mm(self.fstop, self.focal_length_mm, self.focus_distance_m, depth_m, lens_model="pinhole")

    def coc_px(self, depth_m: float, width_px: int) -> float:
        """The same blur diameter in pixels of an image ``width_px`` wide."""
        return self.coc_mm(depth_m) * width_px / self.sensor_width_mm

    def describe(self) -> str:
        return f"{self.aperture.describe()}, f/{self.fstop:g}, focus {self.focus_distance_m:g} m, {self.focal_length_mm:g} mm"

    def to_json(self) -> dict:
        a = self.aperture
        return dict(
            shape=a.shape,
            angle_deg=a.angle_deg,
            blades=a.blades,
            aspect=a.aspect,
            roundness=a.roundness,
            squeeze=a.squeeze,
            vignetting=None if a.vignetting is None else dict(radius=a.vignetting.radius, shift=a.vignetting.shift),
            rim=a.rim,
            chromatic=None if a.chromatic is None else dict(red=a.chromatic.red, blue=a.chromatic.blue),
            mask=None if a.mask is None else dict(width=a.mask.shape[1], height=a.mask.shape[0], sha256=a.mask.digest),
            fstop=self.fstop,
            focus_distance_m=self.focus_distance_m,
            focal_length_mm=self.focal_length_mm,
            sensor_width_mm=self.sensor_width_mm,
            aperture_diameter_mm=self.aperture_diameter_mm,
            size_convention="equal-area",
        )


def make_lens(
    aperture: Aperture,
    *,
    fstop: float,
    focus_distance_m: float,
    focal_length_mm: float = FOCAL_LENGTH_MM,
    sensor_width_mm: float = SENSOR_WIDTH_MM,
) -> Lens:
    """Validate the lens parameters and build a :class:`Lens` around ``aperture``.

    The aperture (its shape, angle and the real-lens features of design.md §3b)
    is one :class:`~bokehfit.apertures.Aperture`, built and checked by
    :func:`bokehfit.apertures.make_aperture`. The numbers must lie in the ranges
    of ``bokehfit.validate.RANGES``, and the focus distance beyond the focal length.

    Raises
    ------
    InputError
        Naming the parameter and what was expected.

    Examples
    --------
    >>> from bokehfit.apertures import make_aperture
    >>> lens = make_lens(make_aperture("hexagon", 20), fstop=1.4, focus_distance_m=0.7)
    >>> round(lens.aperture_diameter_mm, 2)
    25.0
    """
    if not isinstance(aperture, Aperture):
        raise InputError(
            f"aperture must be an Aperture, built once by bokehfit.apertures.make_aperture (got {aperture!r:.60})"
        )
    fstop = check("fstop", fstop)
    focus = check("focus_distance_m", focus_distance_m)
    focal = check("focal_length_mm", focal_length_mm)
    sensor = check("sensor_width_mm", sensor_width_mm)
    if focus * 1000.0 <= focal:
        raise InputError(
            f"focus_distance_m must be longer than the focal length ({focal:g} mm): nothing can be focused closer "
            f"(got {focus_distance_m!r})"
        )
    return Lens(aperture, fstop, focus, focal, sensor)


@dataclass(frozen=True)
class RenderSettings:
    """Image size, samples per pixel, seed, path length and tiling. Build with :func:`make_settings`."""

    width: int
    height: int
    spp: int
    seed: int = 0
    #: Longest path (vertices); Russian roulette ends most paths long before.
    max_depth: int = 64
    #: First vertex at which Russian roulette may end a path.
    rr_depth: int = 3
    #: Most pixels per tile (None: what the adapter's limits allow, at most 2²²).
    max_tile_pixels: int | None = None
    #: Next-event estimation also reaches the lights through planar mirrors (virtual
    #: lights). Off by default: on the Cornell box it lowers the noise per sample by
    #: about 16 % but costs three times the time per sample on lavapipe, so it loses
    #: at equal time (benchmarks/render_speed.py).
    mirror_nee: bool = False


def _check_int(name: str, value, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not low <= value <= high:
        raise InputError(f"{name} must be an integer from {low} to {high} (got {value!r})")
    return int(value)


def make_settings(
    width: int,
    height: int,
    spp: int,
    seed: int = 0,
    *,
    max_depth: int = 64,
    rr_depth: int = 3,
    max_tile_pixels: int | None = None,
    mirror_nee: bool = False,
) -> RenderSettings:
    """Validate and build :class:`RenderSettings` (``InputError`` names a bad parameter)."""
    width = check("image_side_px", width, name="width")
    height = check("image_side_px", height, name="height")
    spp = check("spp", spp)
    seed = check("seed", seed)
    max_depth = _check_int("max_depth", max_depth, 1, 1024)
    rr_depth = _check_int("rr_depth", rr_depth, 1, 1024)
    if max_tile_pixels is not None:
        max_tile_pixels = _check_int("max_tile_pixels", max_tile_pixels, 1, 2**31)
    if not isinstance(mirror_nee, bool):
        raise InputError(f"mirror_nee must be True or False (got {mirror_nee!r})")
    return RenderSettings(width, height, spp, seed, max_depth, rr_depth, max_tile_pixels, mirror_nee)
