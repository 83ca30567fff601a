"""The named shapes (design.md §3): their registry, the parser of their names and the angle's period.

A :class:`ShapeSpec` is what a name fixes: its sampler family (the class of
:mod:`bokehfit.apertures.behaviours` and the WGSL ``SHAPE_*`` id), a blade
count or aspect fixed or chosen, the symmetry. ``SHAPES`` holds them by name;
:func:`parse_shape` reads a name as people write it (``ngon(9)``), and
:func:`canonical_angle` reduces an angle to one period of the symmetry.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from bokehfit.apertures.behaviours import BEHAVIOURS
from bokehfit.errors import InputError

__all__ = [
    "DEFAULT_SLIT_ASPECT",
    "MAX_BLADES",
    "SHADER_FAMILIES",
    "SHAPES",
    "SLIT_ASPECT_RANGE",
    "ShapeSpec",
    "canonical_angle",
    "parse_shape",
]

#: Slit aspect (width / height) when none is given (design.md §3).
DEFAULT_SLIT_ASPECT = 0.3
#: Most blades an ``ngon`` may have; beyond this it is a circle for every purpose.
MAX_BLADES = 64
#: Slit aspects outside this range are refused (the shape would be a line).
SLIT_ASPECT_RANGE = (1e-3, 1e3)

#: The sampler families of shaders/apertures.wgsl, in the order of their
#: ``SHAPE_*`` constants (the constants are generated from this tuple): the
#: families that have a behaviour (:data:`~bokehfit.apertures.behaviours.BEHAVIOURS`),
#: in its order, so that a family has a WGSL id exactly when it has a behaviour.
SHADER_FAMILIES = tuple(BEHAVIOURS)


@dataclass(frozen=True)
class ShapeSpec:
    """One registry entry: how a named shape is drawn, sampled and rendered."""

    name: str
    family: str  #: sampler family in SHADER_FAMILIES
    fixed_blades: int | None = None  #: blade count fixed by the name (triangle: 3)
    takes_blades: bool = False  #: the user chooses the blade count (ngon)
    takes_aspect: bool = False  #: the user chooses the aspect (slit)
    symmetry: float | None = None  #: degrees; None: 360°/blades (n-gons) or no angle (circle)
    tabulated: bool = False  #: drawn from a transmission image (``mask``), not an outline

    @property
    def shader_id(self) -> int:
        return SHADER_FAMILIES.index(self.family)

    @property
    def rounds(self) -> bool:
        """Whether ``roundness`` applies: the blade edges of n-gons (design.md §3b)."""
        return BEHAVIOURS[self.family].rounds

    def symmetry_deg(self, blades: int | None) -> float | None:
        """Smallest rotation mapping the shape onto itself; None for the circle."""
        if self.symmetry is not None:
            return self.symmetry
        return 360.0 / blades if BEHAVIOURS[self.family].has_angle else None


SHAPES: dict[str, ShapeSpec] = {
    spec.name: spec
    for spec in (
        ShapeSpec("circle", "circle"),
        ShapeSpec("square", "square", fixed_blades=4, symmetry=90.0),
        ShapeSpec("slit", "slit", takes_aspect=True, symmetry=180.0),
        ShapeSpec("triangle", "ngon", fixed_blades=3),
        ShapeSpec("pentagon", "ngon", fixed_blades=5),
        ShapeSpec("hexagon", "ngon", fixed_blades=6),
        ShapeSpec("star", "star", symmetry=72.0),
        ShapeSpec("ngon", "ngon", takes_blades=True),
        ShapeSpec("mask", "mask", symmetry=360.0, tabulated=True),
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



def parse_shape(text: str) -> tuple[str, int | None]:
    """A shape's name as people write it → (registry shape, blade count or None).

    The one parser of shape names: ``compare --shapes``, ``kernel --shape``,
    ``similarity`` and :func:`make_aperture` all go through it. ``ngon(9)``
    (spaces and case ignored) is the ngon with 9 blades; a registry name is
    itself with no blade count.

    Examples
    --------
    >>> parse_shape("ngon(9)"), parse_shape("Hexagon")
    (('ngon', 9), ('hexagon', None))
    """
    if not isinstance(text, str):
        raise InputError(f"shape must be one of {', '.join(SHAPES)} or ngon(N) (got {text!r})")
    name = text.strip().lower()
    if name in SHAPES:
        return name, None
    match = re.fullmatch(r"ngon\s*\(\s*(\d+)\s*\)", name)
    if match is None:
        raise InputError(f"shape must be one of {', '.join(SHAPES)} or ngon(N) (got {text!r})")
    blades = int(match.group(1))
    if not 3 <= blades <= MAX_BLADES:
        raise InputError(f"blades must be an integer from 3 to {MAX_BLADES} for shape 'ngon' (got {text!r})")
    return "ngon", blades
