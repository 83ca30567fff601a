"""The §3b features of the one aperture model, one record each: what a fit and a report need to know of it.

The :class:`~bokehfit.apertures.shapes.Aperture` applies each feature's geometry (design.md
§3b); a :class:`FeatureSpec` says the rest: the names of its fit parameters and the ranges
they take, its neutral value (the feature off), where it is reported, the least value that
shows, how a fit starts it from plain numbers the discs give (:class:`FeatureEvidence`), which
ends of its range say the discs pushed it there, and its JSON value. ``FEATURE_SPECS`` holds
the records by name, in the order :attr:`Aperture.parameters` lists them; the model, the fit
and the report loop over it and compare no feature's name. Adding a feature is an entry here
(with its sampler, WGSL twin and tests), not a branch in each of them.

This module imports no other bokehfit module: the records act on an aperture through its
public methods (``with_features``, ``replace``, ``spec``).
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from bokehfit.apertures.registry import ShapeSpec
    from bokehfit.apertures.shapes import Aperture

__all__ = [
    "FEATURES",
    "FEATURE_SPECS",
    "JSON_ORDER",
    "MIN_RIM",
    "REPORTED",
    "RIM_START",
    "VIGNETTING_START_CUT",
    "VIGNETTING_START_SHIFT",
    "FeatureEvidence",
    "FeatureSpec",
]

#: Least |rim| reported: a smaller one changes a disc's profile by under 5 % (below what a photo's discs show).
MIN_RIM = 0.05
#: The rim a fit starts from (its range is [−1, 1]).
RIM_START = 0.2
#: The vignetting's starting barrel: this shift (R0 per half-diagonal; negative: the barrel's centre towards
#: the image centre, cutting a disc's outer side), and a radius that cuts the farthest disc this far inside its R0.
VIGNETTING_START_SHIFT = -1.0
VIGNETTING_START_CUT = 0.85

#: Where a feature's value is reported (:meth:`FeatureSpec.is_reported`): ``"shape"`` wherever the shape
#: takes it (its neutral value where it was not fitted), ``"tested"`` where it is on or was tested (its
#: neutral value where the discs did not need it), ``"set"`` only where it has a value (null elsewhere).
REPORTED = ("shape", "tested", "set")


@dataclass(frozen=True)
class FeatureEvidence:
    """Plain numbers the discs give, from which a fit starts a feature (:meth:`FeatureSpec.start`)."""

    farthest_field: float = 0.0  #: the fitted discs' largest distance from the image centre (half-diagonals)
    shared_squeeze: float | None = None  #: the squeeze (height over width) the discs' outlines share; None: none


def _every_shape(spec: ShapeSpec) -> bool:
    return True


def _blades(spec: ShapeSpec) -> bool:
    return spec.rounds


@dataclass(frozen=True)
class FeatureSpec:
    """One §3b feature: its fit parameters, neutral value, report, start and bounds.

    ``quantities`` are the ``bokehfit.validate.RANGES`` keys of :attr:`parameters`, in order;
    ``members`` the fields of a pair's value type (``Vignetting.radius``, ``.shift``), empty for
    a scalar. ``least_visible`` is the least |value| a photo's discs show (a fit keeps no less);
    ``upper_end_only`` names the parameters whose lower end is a value the lens may have, so that
    only their upper end says the discs pushed them there; ``read_from_outline`` says that discs
    show the feature by their outlines' shape (a cat-eye's cut, a squeeze's stretch), not by how
    their light is spread or coloured; ``taken_by_aspect`` says that a
    shape's own aspect (the slit's) takes the feature, so that a fit tries it again on a shape
    without one; ``applies`` says which shapes take it; ``starts_at`` builds a fit's start
    (None: switched on at its neutral value, :meth:`Aperture.with_features`).
    """

    name: str
    neutral: object  #: the Aperture field's value with the feature off
    quantities: tuple[str, ...]
    members: tuple[str, ...] = ()
    reported: str = "set"
    least_visible: float | None = None
    upper_end_only: tuple[str, ...] = ()
    read_from_outline: bool = False
    taken_by_aspect: bool = False
    applies: Callable[[ShapeSpec], bool] = _every_shape
    starts_at: Callable[[Aperture, FeatureEvidence], Aperture] | None = None

    def __post_init__(self):
        if self.reported not in REPORTED:
            raise ValueError(f"reported must be one of {', '.join(REPORTED)} (got {self.reported!r})")
        if len(self.quantities) != len(self.parameters):
            raise ValueError(f"quantities of {self.name} must name a range for each of {', '.join(self.parameters)}")

    @property
    def parameters(self) -> tuple[str, ...]:
        """Its names in :attr:`Aperture.parameters` (keywords of :meth:`Aperture.replace`)."""
        return tuple(f"{self.name}_{member}" for member in self.members) if self.members else (self.name,)

    def is_on(self, aperture: Aperture) -> bool:
        """Whether ``aperture`` has the feature on: switched on by ``with_features`` or away from neutral."""
        return self.name in aperture.features or getattr(aperture, self.name) != self.neutral

    def start(self, aperture: Aperture, evidence: FeatureEvidence) -> Aperture:
        """``aperture`` with the feature on at a start from which a fit can move."""
        if self.starts_at is None:
            return aperture.with_features(self.name)
        return self.starts_at(aperture, evidence)

    def shows(self, aperture: Aperture) -> bool:
        """Whether the feature's value on ``aperture`` is one a photo's discs show (``least_visible``)."""
        return self.least_visible is None or abs(getattr(aperture, self.name)) >= self.least_visible

    def is_reported(self, aperture: Aperture, tested: Collection[str]) -> bool:
        """Whether a fit's report gives the feature's value (``reported``; ``tested``: the features a fit tried)."""
        if self.reported == "shape":
            return self.applies(aperture.spec)
        if self.reported == "tested":
            return self.is_on(aperture) or self.name in tested
        return getattr(aperture, self.name) != self.neutral

    def value(self, aperture: Aperture):
        """Its JSON value on ``aperture``: a number, or a mapping of the pair's members."""
        value = getattr(aperture, self.name)
        return {member: getattr(value, member) for member in self.members} if self.members else value

    def uncertainty(self, sigma: Mapping[str, float]):
        """Its JSON uncertainty from one standard deviation of each parameter (``sigma``, by name; absent: None)."""
        if not self.members:
            return sigma.get(self.name)
        return {member: sigma.get(name) for member, name in zip(self.members, self.parameters)}


def _start_squeeze(aperture: Aperture, evidence: FeatureEvidence) -> Aperture:
    """The squeeze the discs' outlines share (1 where they share none)."""
    return aperture.with_features("squeeze").replace(squeeze=evidence.shared_squeeze or 1.0)


def _start_rim(aperture: Aperture, evidence: FeatureEvidence) -> Aperture:
    return aperture.with_features("rim").replace(rim=RIM_START)


def _start_vignetting(aperture: Aperture, evidence: FeatureEvidence) -> Aperture:
    """A barrel that just cuts the disc farthest from the centre."""
    shift = VIGNETTING_START_SHIFT
    return aperture.replace(vignetting_radius=abs(shift) * evidence.farthest_field + VIGNETTING_START_CUT,
                            vignetting_shift=shift)


#: The §3b features by name, in the order :attr:`Aperture.parameters` lists them.
FEATURE_SPECS: dict[str, FeatureSpec] = {
    spec.name: spec
    for spec in (
        # Straight blades are a value the fit tells apart: every n-gon reports its roundness.
        FeatureSpec("roundness", 0.0, ("roundness",), reported="shape", applies=_blades),
        # A slit's own aspect takes an anamorphic squeeze: the circle tries it again.
        FeatureSpec("squeeze", 1.0, ("squeeze",), reported="tested", read_from_outline=True, taken_by_aspect=True,
                    starts_at=_start_squeeze),
        FeatureSpec("rim", 0.0, ("rim",), reported="tested", least_visible=MIN_RIM, starts_at=_start_rim),
        # A barrel at its smallest radius hugs the aperture (a real cut); at its largest it cuts nothing.
        FeatureSpec("vignetting", None, ("vignetting_radius", "vignetting_shift"), members=("radius", "shift"),
                    upper_end_only=("vignetting_radius",), read_from_outline=True, starts_at=_start_vignetting),
        FeatureSpec("chromatic", None, ("chromatic", "chromatic"), members=("red", "blue")),
    )
}
#: The §3b features' names, in the order of :data:`FEATURE_SPECS`.
FEATURES = tuple(FEATURE_SPECS)
#: The features in the order of their keys in ``compare --json``'s ``aperture`` (design.md §7b).
JSON_ORDER = ("roundness", "squeeze", "vignetting", "rim", "chromatic")
