"""The vector a pixel fit searches: its parameters, their start values and bounds, and what it says.

The vector of a fit of discs sharing one aperture (:func:`bokehfit.fit.pixels.fit_discs`) is
the aperture's parameters set free first, then each disc's :data:`DISC_NAMES` in its crop's
units (and its plateau where the disc is saturated: the fit's Notes). A disc's parameters
are searched near its outline's values; the aperture's within their bounds, narrower where
the fit asks for less (:data:`FIT_BOUNDS`), the angle half a period either side of its start.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from bokehfit.apertures import Aperture, ParameterSpec
from bokehfit.fit.crop import DiscCrop
from bokehfit.fit.disc_model import BLUR_RANGE

__all__ = [
    "DISC_NAMES",
    "FIT_BOUNDS",
    "MAX_PLATEAU_OVER_CLIP",
    "MAX_SLIT_ASPECT",
    "RELATIVE_PARAMETERS",
    "Block",
    "FitVector",
    "fit_vector",
]

#: Widest slit fitted: at aspect 1 the slit is the square, which has a model of its own.
MAX_SLIT_ASPECT = 0.8
#: The parameters of every disc, first in the fit's vector (crop units; the centre in crop pixel coordinates).
DISC_NAMES = ("cx", "cy", "diameter_px", "blur_px")
#: Fit bounds narrower than :attr:`ParameterSpec.bounds`, by parameter name.
FIT_BOUNDS = {"aspect": (0.01, MAX_SLIT_ASPECT), "vignetting_radius": (1.0, 4.0), "vignetting_shift": (-4.0, 4.0),
              "squeeze": (0.25, 4.0)}
#: Parameters searched within a factor of 2 of their start (scale factors, not offsets).
RELATIVE_PARAMETERS = ("aspect", "squeeze")
#: A saturated disc's plateau is searched up to this many times the clip level.
MAX_PLATEAU_OVER_CLIP = 50.0


@dataclass(frozen=True)
class Block:
    """Some of the vector's parameters, one after the other: their names, start values and bounds."""

    names: list[str]
    start: list[float]
    lower: list[float]
    upper: list[float]
    at: int = 0  #: where the first of them lies in the vector

    def values(self, vector: np.ndarray) -> dict[str, float]:
        """Their values in ``vector``, by name."""
        return dict(zip(self.names, (float(v) for v in vector[self.at : self.at + len(self.names)])))


@dataclass(frozen=True)
class FitVector:
    """The vector of a fit of discs sharing one aperture: the aperture's parameters set free, then each disc's."""

    aperture: Aperture  #: the aperture the fit starts at; the parameters not set free keep its values
    shared: Block  #: the aperture's parameters set free
    discs: list[Block]  #: each disc's, in the order of its crop

    @property
    def free(self) -> list[str]:
        """The names of the aperture's parameters set free."""
        return self.shared.names

    @property
    def blocks(self) -> list[Block]:
        return [self.shared, *self.discs]

    @property
    def start(self) -> list[float]:
        return [v for block in self.blocks for v in block.start]

    @property
    def lower(self) -> list[float]:
        return [v for block in self.blocks for v in block.lower]

    @property
    def upper(self) -> list[float]:
        return [v for block in self.blocks for v in block.upper]

    @property
    def size(self) -> int:
        return sum(len(block.names) for block in self.blocks)

    @property
    def levels(self) -> int:
        """The levels solved for at every step beside the vector: two per disc, one where its plateau is fitted."""
        return sum(1 if "plateau" in block.names else 2 for block in self.discs)

    def aperture_at(self, vector: np.ndarray) -> Aperture:
        """The aperture with the shared values of ``vector``, as the fit renders it."""
        shared = len(self.free)
        return self.aperture.replace(**dict(zip(self.free, (float(v) for v in vector[:shared])))) if shared else self.aperture

    def wrapped_at(self, vector: np.ndarray) -> Aperture:
        """The aperture with the shared values of ``vector``, periodic ones (the angle) reduced to [0, period)."""
        return _wrapped(self.aperture, {name: float(v) for name, v in zip(self.free, vector[: len(self.free)])})

    def discs_at(self, vector: np.ndarray) -> list[dict[str, float]]:
        """Each disc's values in ``vector`` (crop units), by name."""
        return [block.values(vector) for block in self.discs]


def fit_vector(
    crops: Sequence[DiscCrop],
    start: Aperture,
    free: Sequence[str],
    disc_starts: Sequence[Mapping[str, float] | None] | None = None,
) -> FitVector:
    """The vector of a fit of ``crops`` sharing one aperture that starts at ``start``, its ``free``
    parameters searched; ``disc_starts`` (crop units) replace the outline's starting values where given."""
    blocks, at = [], len(free)
    for i, crop in enumerate(crops):
        block = _disc_block(crop, at, None if disc_starts is None else disc_starts[i])
        blocks.append(block)
        at += len(block.names)
    return FitVector(aperture=start, shared=_shared_block(start, free), discs=blocks)


def _disc_block(crop: DiscCrop, at: int, values: Mapping[str, float] | None) -> Block:
    """One disc's names, start, lower and upper bounds (crop units), its start ``values`` where given."""
    start = crop.start
    names = list(DISC_NAMES)
    x0 = [start[n] for n in DISC_NAMES]
    lower = [start["cx"] - 3, start["cy"] - 3, 0.5 * start["diameter_px"], BLUR_RANGE[0]]
    upper = [start["cx"] + 3, start["cy"] + 3, 1.5 * start["diameter_px"], BLUR_RANGE[1]]
    clip = crop.clip_level
    if clip is not None:  # a saturated disc: its plateau is somewhere above the clip
        names.append("plateau")
        x0.append(max(crop.disc.plateau, clip) * 1.5)
        lower.append(clip)
        upper.append(clip * MAX_PLATEAU_OVER_CLIP)
    if values is not None:
        x0 = [min(max(values.get(n, v), lo), hi) for n, v, lo, hi in zip(names, x0, lower, upper)]
    return Block(names=names, start=x0, lower=lower, upper=upper, at=at)


def _shared_block(start: Aperture, free: Sequence[str]) -> Block:
    """The aperture's parameters set free: their start values and bounds (:func:`_search_bounds`)."""
    parameters = start.parameters
    values = start.values
    x0, lower, upper = [], [], []
    for name in free:
        first, low, high = _search_bounds(parameters[name], values[name])
        x0.append(first)
        lower.append(low)
        upper.append(high)
    return Block(names=list(free), start=x0, lower=lower, upper=upper, at=0)


def _search_bounds(parameter: ParameterSpec, start: float) -> tuple[float, float, float]:
    """(start, lower, upper) of one aperture parameter for the fit.

    A periodic parameter (the angle) is searched half a period either side of
    its start; the others within their bounds (:data:`FIT_BOUNDS` where the fit
    asks for less), scale factors only within a factor of 2 of the start.
    """
    if parameter.periodic is not None:
        return start, start - 0.5 * parameter.periodic, start + 0.5 * parameter.periodic
    low, high = FIT_BOUNDS.get(parameter.name, parameter.bounds)
    start = min(max(start, low), high)
    if parameter.name in RELATIVE_PARAMETERS:
        low, high = max(low, 0.5 * start), min(high, 2.0 * start)
    return start, low, high


def _wrapped(aperture: Aperture, values: Mapping[str, float]) -> Aperture:
    """``aperture`` with ``values`` set, periodic ones (the angle) reduced to [0, period)."""
    parameters = aperture.parameters
    wrapped = {n: (v % parameters[n].periodic if parameters[n].periodic is not None else v) for n, v in values.items()}
    return aperture.replace(**wrapped) if wrapped else aperture
