"""What a fit returns: its options, the aperture with its parameters and evidence, or the failure object.

A fit returns one object (lmfit ``ModelResult``, scipy ``OptimizeResult``): the
parameters, each with its value and uncertainty, and the evidence (:class:`ApertureFit`:
the candidate models tried, :class:`CandidateModel`, and the discs fitted, :class:`DiscFit`). When nothing
could be fitted it returns a :class:`FailedFit` instead (scikit-image's
``FailedEstimation``): falsy, it carries the reason, converts to JSON with its
status, and raises :class:`FitFailedError` naming that reason when a fitted
field is read, rather than an ``IndexError`` or ``AttributeError`` far from the cause.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from bokehfit.apertures import FEATURE_SPECS, Aperture
from bokehfit.apertures.features import JSON_ORDER
from bokehfit.discs import Disc
from bokehfit.errors import InputError, NoResultError
from bokehfit.fit.chromatic import ChromaticMeasure
from bokehfit.fit.families import Family
from bokehfit.fit.pixels import PixelFit
from bokehfit.fit.signature import Screen

__all__ = ["ApertureFit", "CandidateModel", "DiscFit", "FitOptions", "Parameter", "FailedFit", "FitFailedError",
           "STATUSES", "LENS_FEATURES", "ROUND_ENOUGH"]

#: The outcomes of ``compare`` (design.md §7b), best first.
STATUSES = ("fitted", "unsure", "no_fit", "no_discs")


class FitFailedError(NoResultError):
    """A field of a failed fit was read; the message says why the fit failed."""


@dataclass(frozen=True)
class FitOptions:
    """The fit's budget and thresholds, passed explicitly to :func:`bokehfit.fit.fit_aperture`.

    Parameters
    ----------
    max_discs : int
        Most discs fitted, the largest and clearest first (the time budget: the
        fit's time grows about linearly with it).
    shortlist : int
        Families fitted to pixels after the outline screen (the circle always is too).
    model_discs : int
        Discs on which the shortlisted families compete; the winner is then fitted to all.
    sure_delta_bic_per_disc : float
        Below this BIC margin per disc between the best and the runner-up the choice is unsure.
    out_of_race_screen : float
        A shortlisted shape whose outline misfits every model disc more than this many times the
        best shape's is out of the race: not fitted to pixels (the circle always is). ``math.inf``
        fits every shortlisted shape.
    """

    max_discs: int = 12
    shortlist: int = 3
    model_discs: int = 4
    sure_delta_bic_per_disc: float = 10.0
    out_of_race_screen: float = 3.0

    def __post_init__(self):
        for name in ("max_discs", "shortlist", "model_discs"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise InputError(f"{name} must be an integer of at least 1 (got {value!r})")
        value = self.sure_delta_bic_per_disc
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
            raise InputError(f"sure_delta_bic_per_disc must be a finite number of at least 0 (got {value!r})")
        value = self.out_of_race_screen
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= 1:
            raise InputError(f"out_of_race_screen must be a number of at least 1, or inf (got {value!r})")


@dataclass(frozen=True)
class Parameter:
    """One fitted quantity: its value and its standard uncertainty (None where not estimated).

    A feature with members (``vignetting``) has a dict of values and a dict of uncertainties.
    """

    name: str
    value: float | dict | None
    uncertainty: float | dict | None = None

    def to_json(self, digits: int = 3) -> dict:
        return {"value": _round(self.value, digits), "uncertainty": _round(self.uncertainty, digits)}


def _round(value, digits: int):
    if isinstance(value, dict):  # a feature with members (vignetting: radius and shift)
        return {key: _round(member, digits) for key, member in value.items()}
    if value is None or not math.isfinite(value):
        return None
    return round(float(value), digits)


@dataclass(frozen=True)
class FailedFit:
    """A fit that found nothing to fit: falsy, with ``status`` and ``reason``.

    Reading a fitted field (``aperture``, ``family``, ``diameter_px``, ...) raises
    :class:`FitFailedError` with the reason.

    Examples
    --------
    >>> fit = FailedFit("no_discs", "no disc is clean enough to fit (none found)")
    >>> bool(fit)
    False
    >>> fit.to_json()["status"]
    'no_discs'
    """

    status: str
    reason: str
    candidates: list = field(default_factory=list)  #: the models tried (none)
    disc_fits: list = field(default_factory=list)
    time_s: float = 0.0
    #: Seconds by step of the fit (``ApertureFit.timing_s``'s keys, those reached).
    timing_s: dict = field(default_factory=dict)
    success = False
    sure = False

    def __post_init__(self):
        if self.status not in STATUSES[2:]:
            raise InputError(f"status of a failed fit must be one of {', '.join(STATUSES[2:])} (got {self.status!r})")

    def __bool__(self) -> bool:
        return False

    @property
    def message(self) -> str:
        return self.reason

    def __getattr__(self, name: str):
        # Only reached for names the failure does not have: the fitted fields.
        if name.startswith("_"):
            raise AttributeError(name)
        raise FitFailedError(f"no aperture was fitted, so it has no {name}: {self.reason}")

    def disc_fit(self, disc):
        """No disc was fitted."""
        return None

    def disc_item(self, disc):
        """No disc was fitted."""
        return None

    rejected: dict = field(default_factory=dict)  #: discs set aside (index → reason): outlines no aperture explains

    def to_json(self) -> dict:
        return {"status": self.status, "reason": self.reason, "candidates": []}


#: The real-lens features of design.md §3b in the JSON's order (their registry's); those not estimated are null.
LENS_FEATURES = JSON_ORDER
#: JSON names of uncertainties that schema 1 named before the ``<name>_uncertainty`` rule (design.md §7, §7b).
UNCERTAINTY_KEYS = {"angle_deg": "angle_uncertainty_deg", "diameter_px": "diameter_uncertainty_px"}
#: Blades this round (roundness) give the same answer as the circle: round discs.
ROUND_ENOUGH = 0.8


@dataclass(frozen=True)
class DiscFit:
    """One disc: its screen and its pixel fits, by family name.

    The winner's entry is the disc in the joint fit (the shared aperture);
    ``own`` is the winner fitted to this disc alone (its own angle, for the
    spread between discs), and ``turned`` whether it shows the aperture turned by 180°.
    """

    disc: Disc
    screens: list[Screen]
    fits: dict[str, PixelFit]
    own: PixelFit | None = None
    turned: bool = False


@dataclass(frozen=True)
class CandidateModel:
    """One family's result over all the fitted discs."""

    family: Family
    bic: float
    delta_bic: float  #: above the best family's BIC (0 for the best)
    angle_deg: float | None
    angle_uncertainty_deg: float | None
    diameter_px: float
    screen_rms: float  #: median outline misfit over the discs, in equal-area radii
    roundness: float | None = None  #: median fitted roundness over the discs (families that fit it)

    def same_answer(self, other: CandidateModel) -> bool:
        """Whether ``other`` says what this model says: the same shape straight or rounded, or, beside
        the circle, blades so rounded that they are round too (roundness ≥ ROUND_ENOUGH)."""
        if other.family.base == self.family.base:
            return True
        rounds = [m for m in (self, other) if m.roundness is not None]
        circles = [m for m in (self, other) if m.family.aperture.is_circle]
        return len(rounds) == 1 and len(circles) == 1 and rounds[0].roundness >= ROUND_ENOUGH

    def to_json(self) -> dict:
        return {
            "shape": self.family.aperture.shape,
            "blades": self.family.aperture.blades,
            "name": self.family.name,
            "display_name": self.family.aperture.display_name,
            "angle_deg": None if self.angle_deg is None else round(self.angle_deg, 3),
            "score": round(-self.delta_bic, 2) + 0.0,
            "delta_bic": round(self.delta_bic, 2),
            "bic": round(self.bic, 2),
            "screen_rms": round(self.screen_rms, 5),
            "diameter_px": round(self.diameter_px, 3),
        }


@dataclass(frozen=True)
class ApertureFit:
    """The fitted aperture, with the evidence (lmfit ``ModelResult``-like).

    ``aperture`` is the aperture itself (for ``focus_side="near"`` turned by
    180° from what the discs show); ``seen_angle_deg`` is the angle the discs
    show, the one a kernel must be drawn at to match them. ``candidates`` are
    the models tried, best first; the first is the winner with the consensus
    angle and size over every fitted disc. :attr:`parameters` names each fitted
    quantity with its uncertainty. A fit that found nothing to fit is a
    :class:`FailedFit` instead.
    """

    message: str
    aperture: Aperture
    seen_angle_deg: float | None
    angle_uncertainty_deg: float | None
    diameter_px: float
    diameter_uncertainty_px: float
    blur_px: float
    focus_side: str
    candidates: list[CandidateModel]
    disc_fits: list[DiscFit]
    sure: bool
    #: The runner-up fits about as well (a BIC margin under FitOptions.sure_delta_bic_per_disc per disc),
    #: and was not set aside by a note.
    close_runner_up: bool = False
    options: FitOptions = FitOptions()
    time_s: float = 0.0
    #: The aperture as the discs show it (``aperture`` turned back for near discs: 180°, −rim, ...).
    seen_aperture: Aperture | None = None
    #: Discs set aside, index → reason: outlines no aperture shape explains, and discs fitted and then
    #: left out because the others' consensus does not share them.
    rejected: dict = dataclasses.field(default_factory=dict)
    #: Each §3b feature tried on the joint fit: the BIC it gained, and why it joined the model or did not
    #: (:class:`bokehfit.fit.features.FeatureTrial`).
    feature_trials: tuple = ()
    #: Each §3b feature the discs did not ask for, and why: (feature, reason) pairs.
    features_not_tried: tuple = ()
    #: One standard deviation of each shared aperture parameter of the joint fit, by name.
    feature_uncertainty: dict = dataclasses.field(default_factory=dict)
    notes: tuple = ()  #: models set aside and why (an elongation the discs do not share)
    #: What the discs' colours said (None where fewer than three could be measured, or no colour given).
    chromatic_measure: ChromaticMeasure | None = None
    #: Seconds by step of the fit (perf_counter): ``choose`` (the discs that show a shape), ``screen``
    #: (crops and outline screens), ``family <name>`` (each candidate's pixel fit on the model discs),
    #: ``winner`` (the winner on the other discs), ``joint``, ``features`` (the §3b feature trials),
    #: ``plain`` (the simplest model against the winner), ``refit`` (discs beyond the joint fit),
    #: ``chromatic``; ``time_s`` is their sum with the bookkeeping between them.
    timing_s: dict = dataclasses.field(default_factory=dict)
    success = True

    def __bool__(self) -> bool:
        return True

    @property
    def family(self) -> Family:
        return self.candidates[0].family

    @property
    def feature_tests(self) -> dict[str, float]:
        """Each §3b feature tried on the joint fit → the BIC it gained (kept where :attr:`feature_trials` says)."""
        return {trial.feature: trial.gain for trial in self.feature_trials}

    @property
    def outline_misfit(self) -> float:
        """Median over the used discs of their outlines' misfit to the winning shape (equal-area radii):
        about 0.01–0.05 for discs that show an aperture, 0.1 and more for blobs that show none."""
        return self.candidates[0].screen_rms if self.candidates else math.nan

    @property
    def runner_up(self) -> CandidateModel | None:
        """The best model that gives another answer (:meth:`CandidateModel.same_answer`); None if none."""
        return next((m for m in self.candidates[1:] if not self.candidates[0].same_answer(m)), None)

    @property
    def others_screened(self) -> bool:
        """Whether the outlines were screened against shapes other than those fitted (their misfit put
        them out of the race, :func:`bokehfit.fit.stages._out_of_race`, or off the shortlist)."""
        screened = {s.family for item in self.disc_fits for s in item.screens}
        return bool(screened - {m.family for m in self.candidates})

    @property
    def margin_bic(self) -> float | None:
        """The runner-up's BIC above the winner's (None when no other shape was tried)."""
        runner_up = self.runner_up
        return None if runner_up is None else runner_up.bic - self.candidates[0].bic

    @property
    def parameters(self) -> dict[str, Parameter]:
        """The fitted quantities by JSON name, each with its uncertainty.

        A §3b feature that was fitted has its value; one that was tested and
        not needed its neutral value (roundness 0 for a straight n-gon, rim 0,
        no vignetting); one that was not estimated None. Which is which, and
        the value's form, is each feature's record (:class:`~bokehfit.apertures.FeatureSpec`).
        """
        aperture = self.aperture
        angle = aperture.canonical_angle_deg
        sigma = self.feature_uncertainty
        features = {f.name: Parameter(f.name, f.value(aperture), f.uncertainty(sigma))
                    for f in FEATURE_SPECS.values() if f.is_reported(aperture, self.feature_tests)}
        return {
            "angle_deg": Parameter("angle_deg", angle, self.angle_uncertainty_deg if angle is not None else None),
            "diameter_px": Parameter("diameter_px", self.diameter_px, self.diameter_uncertainty_px),
            "aspect": Parameter("aspect", aperture.aspect),
            "edge_blur_px": Parameter("edge_blur_px", self.blur_px),
            **{name: features.get(name) or Parameter(name, None) for name in LENS_FEATURES},
        }

    def to_json(self) -> dict:
        """The fit as plain JSON data: shape, the parameters, the candidates tried."""
        aperture = self.aperture
        data = {"shape": aperture.shape, "blades": aperture.blades, "symmetry_deg": aperture.symmetry_deg}
        for name, parameter in self.parameters.items():
            rounded = parameter.to_json(3)
            data[name] = rounded["value"]
            data[UNCERTAINTY_KEYS.get(name, f"{name}_uncertainty")] = rounded["uncertainty"]
        data.update(
            focus_side=self.focus_side,
            sure=self.sure,
            margin_bic=None if self.margin_bic is None else round(self.margin_bic, 2),
            discs_fitted=len(self.disc_fits),
            message=self.message,
            candidates=[c.to_json() for c in self.candidates],
            feature_trials=[t.to_json() for t in self.feature_trials]
            + ([self.chromatic_measure.to_json()] if self.chromatic_measure is not None else []),
            features_not_tried=[{"feature": feature, "reason": why} for feature, why in self.features_not_tried],
        )
        return data

    def disc_fit(self, disc: Disc) -> PixelFit | None:
        """The winning family's fit of ``disc`` (in the joint fit), if it was used."""
        item = self.disc_item(disc)
        return None if item is None else item.fits.get(self.family.name)

    def disc_item(self, disc: Disc) -> DiscFit | None:
        """Everything fitted to ``disc``, if it was used."""
        return next((item for item in self.disc_fits if item.disc.index == disc.index), None)
