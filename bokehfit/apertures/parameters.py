"""The aperture's parameter types: the §3b features' values, a fit parameter, and the WGSL struct's layout.

:class:`Vignetting` and :class:`Chromatic` are the values of two features of
design.md §3b, :class:`ParameterSpec` one parameter a fit may vary;
``CHANNELS`` names the colour channels in their order (the features' names and
records are in :mod:`bokehfit.apertures.features`), and ``APERTURE_PARAM_FIELDS`` describes the WGSL
``ApertureParams`` struct that :meth:`~bokehfit.apertures.shapes.Aperture.shader_params` fills.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from bokehfit.errors import InputError

__all__ = [
    "APERTURE_PARAM_FIELDS",
    "CHANNELS",
    "VERTICES_MAX_ERROR",
    "Chromatic",
    "ParameterSpec",
    "Vignetting",
    "pair_members",
]


@dataclass(frozen=True)
class Vignetting:
    """Cat-eye vignetting (design.md §3b): the barrel's circle, radius·R0 at shift·R0·q."""

    radius: float
    shift: float = 0.0


@dataclass(frozen=True)
class Chromatic:
    """Longitudinal colour (design.md §3b): red and blue disc diameters over green's, minus 1."""

    red: float
    blue: float


@dataclass(frozen=True)
class ParameterSpec:
    """One parameter a fit may vary: its name (a keyword of :meth:`Aperture.replace`), bounds and unit.

    ``periodic`` is the period where the parameter wraps (the angle: the
    shape's symmetry, in degrees), None otherwise.
    """

    name: str
    bounds: tuple[float, float]
    unit: str = ""
    periodic: float | None = None


#: Colour channels of :meth:`Aperture.sample`, in the order of the WGSL ``CHANNEL_*`` ids
#: (generated from this tuple); green (and None) is the reference size.
CHANNELS = ("green", "red", "blue")
#: Chord error of :meth:`Aperture.vertices` where the outline has arcs (unit-area units).
VERTICES_MAX_ERROR = 1e-6

#: The one description of the WGSL ``ApertureParams`` struct (bokehfit.gpu.layout
#: builds the struct and its NumPy dtype from it; :meth:`Aperture.shader_params`
#: fills it). ``vignetting_radius`` 0 means no vignetting; ``field_position`` is the q of
#: :meth:`Aperture.sample` (half-diagonals, y up).
APERTURE_PARAM_FIELDS = (
    ("shape", "u32"),
    ("blades", "u32"),
    ("aspect", "f32"),
    ("roundness", "f32"),
    ("cos_angle", "f32"),
    ("sin_angle", "f32"),
    ("squeeze", "f32"),
    ("rim", "f32"),
    ("vignetting_radius", "f32"),
    ("vignetting_shift", "f32"),
    ("field_position", "vec2f"),
    ("chromatic_red", "f32"),
    ("chromatic_blue", "f32"),
    ("mask_width", "u32"),
    ("mask_height", "u32"),
    ("mask_cell", "f32"),
)


def pair_members(value, kind, keys: tuple[str, str], name: str) -> tuple:
    """The two members of a :class:`Vignetting`/:class:`Chromatic` given as one or as a mapping (``keys``: its fields)."""
    if isinstance(value, kind):
        return tuple(getattr(value, key) for key in keys)
    if isinstance(value, Mapping) and set(value) <= set(keys) and keys[0] in value:
        return value[keys[0]], value.get(keys[1], 0.0 if kind is Vignetting else None)
    raise InputError(f"{name} must be a {kind.__name__} or a mapping with keys {', '.join(keys)} (got {value!r})")

