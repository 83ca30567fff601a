"""The aperture shapes of design.md §3, in one registry.

A shape is named (``circle``, ``square``, ``slit``, ``triangle``, ``pentagon``,
``hexagon``, ``star``, ``ngon``); an :class:`Aperture` is a shape with its
parameters (angle, blade count, slit aspect). At scale 1 every aperture has
area exactly 1. Adding a shape is one :class:`ShapeSpec` entry in ``SHAPES``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
import numpy as np

from bokehfit.apertures import samplers
from bokehfit.errors import InputError, check_finite

__all__ = ["Aperture", "ShapeSpec", "SHAPES", "SHADER_FAMILIES", "make_aperture", "canonical_angle"]

#: Slit aspect (width / height) when none is given (design.md §3).
DEFAULT_SLIT_ASPECT = 0.3
#: Most blades an ``ngon`` may have; beyond this it is a circle for every purpose.
MAX_BLADES = 64
#: Slit aspects outside this range are refused (the shape would be a line).
SLIT_ASPECT_RANGE = (1e-3, 1e3)

#: The sampler families of shaders/apertures.wgsl, in the order of their
#: ``SHAPE_*`` constants (the constants are generated from this tuple).
SHADER_FAMILIES = ("circle", "square", "slit", "ngon", "star")


@dataclass(frozen=True)
class ShapeSpec:
    """One registry entry: how a named shape is drawn, sampled and rendered."""

    name: str
    family: str  #: sampler family in SHADER_FAMILIES
    fixed_blades: int | None = None  #: blade count fixed by the name (triangle: 3)
    takes_blades: bool = False  #: the user chooses the blade count (ngon)
    takes_aspect: bool = False  #: the user chooses the aspect (slit)

    @property
    def shader_id(self) -> int:
        return SHADER_FAMILIES.index(self.family)


SHAPES: dict[str, ShapeSpec] = {
    spec.name: spec
    for spec in (
        ShapeSpec("circle", "circle"),
        ShapeSpec("square", "square", fixed_blades=4),
        ShapeSpec("slit", "slit", takes_aspect=True),
        ShapeSpec("triangle", "ngon", fixed_blades=3),
        ShapeSpec("pentagon", "ngon", fixed_blades=5),
        ShapeSpec("hexagon", "ngon", fixed_blades=6),
        ShapeSpec("star", "star"),
        ShapeSpec("ngon", "ngon", takes_blades=True),
    )
}


def canonical_angle(angle_deg: float, symmetry_deg: float | None) -> float | None:
    """``angle_deg`` reduced to [0, symmetry); None where the angle is meaningless."""
    if symmetry_deg is None:
        return None
    reduced = math.fmod(angle_deg, symmetry_deg)
    if reduced < 0.0:
        reduced += symmetry_deg
    return 0.0 if reduced >= symmetry_deg else reduced


@dataclass(frozen=True)
class Aperture:
    """A shape with its parameters, at unit area. Build it with :func:`make_aperture`."""

    shape: str
    angle_deg: float = 0.0
    blades: int | None = None
    aspect: float | None = None

    @property
    def spec(self) -> ShapeSpec:
        return SHAPES[self.shape]

    @property
    def symmetry_deg(self) -> float | None:
        """Smallest rotation that maps the shape onto itself; None for the circle."""
        family = self.spec.family
        if family == "circle":
            return None
        if family == "square":
            return 90.0
        if family == "slit":
            return 180.0
        if family == "star":
            return 72.0
        return 360.0 / self.blades

    @property
    def canonical_angle_deg(self) -> float | None:
        """The angle reduced to [0, symmetry); None for the circle."""
        return canonical_angle(self.angle_deg, self.symmetry_deg)

    def vertices(self) -> np.ndarray | None:
        """Counter-clockwise outline vertices at unit area, rotated; None for the circle."""
        family = self.spec.family
        if family == "circle":
            return None
        if family == "square":
            base = np.array([[0.5, -0.5], [0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5]])
        elif family == "slit":
            w, h = 0.5 * self.aspect, 0.5 / self.aspect
            base = np.array([[w, -h], [w, h], [-w, h], [-w, -h]])
        else:
            radii = _fan_radii(self)
            angles = 2.0 * np.pi * np.arange(len(radii)) / len(radii)
            base = np.stack([radii * np.cos(angles), radii * np.sin(angles)], axis=-1)
        return base @ self.rotation().T

    def rotation(self) -> np.ndarray:
        """2×2 matrix R(angle): p' = R·p (design.md §3)."""
        a = math.radians(self.angle_deg)
        return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])

    def sample(self, u: np.ndarray) -> np.ndarray:
        """Points uniform over the rotated unit-area aperture, from ``u`` in [0, 1)²."""
        family = self.spec.family
        if family == "slit":
            p = samplers.sample_slit(u, self.aspect)
        elif family == "ngon":
            p = samplers.sample_ngon(u, self.blades)
        else:
            p = getattr(samplers, f"sample_{family}")(u)
        return p @ self.rotation().T

    def extent(self) -> float:
        """Largest distance of the unit-area outline from the centre."""
        verts = self.vertices()
        if verts is None:
            return samplers.CIRCLE_RADIUS
        return float(np.max(np.hypot(verts[:, 0], verts[:, 1])))

    def describe(self) -> str:
        """Short human name, e.g. ``hexagon 20°`` or ``ngon(9) 3.5°``."""
        name = f"ngon({self.blades})" if self.spec.takes_blades else self.shape
        if self.spec.takes_aspect:
            name += f"(aspect {self.aspect:g})"
        angle = self.canonical_angle_deg
        return name if angle is None else f"{name} {round(angle, 2):g}°"


def _fan_radii(aperture: Aperture) -> np.ndarray:
    if aperture.spec.family == "star":
        return np.tile([samplers.STAR_OUTER_RADIUS, samplers.STAR_INNER_RADIUS], 5)
    return np.full(aperture.blades, samplers.ngon_circumradius(aperture.blades))


def make_aperture(
    shape: str,
    angle_deg: float = 0.0,
    *,
    blades: int | None = None,
    aspect: float | None = None,
) -> Aperture:
    """Validate parameters and build an :class:`Aperture`.

    Parameters
    ----------
    shape : str
        One of ``SHAPES`` (circle, square, slit, triangle, pentagon, hexagon, star, ngon).
    angle_deg : float
        Counter-clockwise rotation from +x, degrees; any finite value.
    blades : int, optional
        Blade count: required for ``ngon`` (3 to 64); for triangle, pentagon,
        hexagon and square it may be given only with the shape's own count.
    aspect : float, optional
        Width over height of a ``slit`` (default 0.3).

    Raises
    ------
    ValueError
        Naming the parameter and what was expected.

    Examples
    --------
    >>> make_aperture("hexagon", 20).describe()
    'hexagon 20°'
    """
    if not isinstance(shape, str) or shape not in SHAPES:
        raise InputError(f"shape must be one of {', '.join(SHAPES)} (got {shape!r})")
    spec = SHAPES[shape]
    angle_deg = check_finite("angle_deg", angle_deg)
    if spec.takes_blades:
        if isinstance(blades, bool) or not isinstance(blades, (int, np.integer)) or not 3 <= blades <= MAX_BLADES:
            raise InputError(f"blades must be an integer from 3 to {MAX_BLADES} for shape 'ngon' (got {blades!r})")
        blades = int(blades)
    elif blades is not None and blades != spec.fixed_blades:
        expected = f"{spec.fixed_blades} or omitted" if spec.fixed_blades else "omitted"
        raise InputError(f"blades must be {expected} for shape {shape!r} (got {blades!r})")
    else:
        blades = spec.fixed_blades
    if spec.takes_aspect:
        aspect = DEFAULT_SLIT_ASPECT if aspect is None else check_finite("aspect", aspect)
        low, high = SLIT_ASPECT_RANGE
        if not low <= aspect <= high:
            raise InputError(f"aspect must be between {low:g} and {high:g} (got {aspect!r})")
    elif aspect is not None:
        raise InputError(f"aspect applies only to shape 'slit' (got aspect={aspect!r} for {shape!r})")
    return Aperture(shape, angle_deg, blades, aspect)

