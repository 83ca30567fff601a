"""``--scene points``: point lights at chosen depths on black, to see kernels in context.

Each light is drawn by splatting (``shaders/points.wgsl``): aperture samples
are sent through the light to the focus plane and counted in the pixel their
pinhole projection falls in. So every disc is exactly the aperture's
coverage kernel (design.md §6) at the blur the camera formula gives, upright
behind the focus plane and turned by 180° in front of it; a light at the
focus distance is a single sharp pixel.

A light is placed by its pinhole projection (``x``, ``y`` as fractions of the
frame's width and height from the top-left corner) and its depth along the
view axis (``inf`` allowed). Its ``color`` is the value of its disc's plateau:
a visualisation choice (a physical point light of fixed power would grow
dimmer per pixel as its disc grows), so that near, far and focused lights
are all visible at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from bokehfit.errors import InputError
from bokehfit.validate import check

__all__ = ["PointLight", "PointScene", "points_scene", "parse_depths", "DEFAULT_DEPTHS_M"]

#: Default light depths (m) and focus: two lights in front of the focus plane,
#: one on it, two behind (the last at infinity).
DEFAULT_DEPTHS_M = (0.15, 0.2, 0.3, 0.6, math.inf)
DEFAULT_FOCUS_M = 0.3

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class PointLight:
    """A point light by its pinhole projection (fractions of the frame) and depth."""

    x: float
    y: float
    depth_m: float
    color: Vec3 = (1.0, 1.0, 1.0)

    def __post_init__(self):
        for name in ("x", "y"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise InputError(f"point light {name} must be a finite number (got {value!r})")
        if math.isnan(self.depth_m) or not self.depth_m > 0.0:
            raise InputError(f"point light depth must be greater than 0 or inf (got {self.depth_m!r})")
        if not all(math.isfinite(c) and c >= 0.0 for c in self.color):
            raise InputError(f"point light color must be finite and ≥ 0 (got {self.color!r})")


@dataclass(frozen=True)
class PointScene:
    """Point lights on black."""

    name: str
    lights: tuple[PointLight, ...]
    default_focus_m: float = DEFAULT_FOCUS_M


def points_scene(depths_m=DEFAULT_DEPTHS_M, *, y: float = 0.5) -> PointScene:
    """Lights at ``depths_m``, spread evenly left to right along the row ``y``."""
    depths = tuple(float(d) for d in depths_m)
    if not depths:
        raise InputError("points scene needs at least one light depth")
    n = len(depths)
    lights = tuple(PointLight((i + 0.5) / n, y, d) for i, d in enumerate(depths))
    return PointScene("points", lights)


def parse_depths(text: str) -> tuple[float, ...]:
    """``"0.15,0.3,inf"`` → (0.15, 0.3, inf); ``InputError`` for anything else."""
    depths = []
    for part in text.split(","):
        try:
            value = float(part)
        except ValueError:
            raise InputError(f"light depths must be numbers in metres or inf, comma-separated (got {text!r})") from None
        depths.append(check("light_distance_m", value, name="light depths"))
    return tuple(depths)
