"""The lens's §3b features that the joint fit tries: which the discs ask for, and where each starts.

The rim where discs show a profile, the vignetting where outer discs misfit the shape more than
central ones, the squeeze where the discs are stretched alike along the frame's axes
(:func:`feature_asks`). A feature joins the model where it lowers the joint BIC by at least
``FEATURE_DELTA_BIC``, and by as much with any one disc left out (:func:`gain_without_one_disc`: the
lens's, not one disc's), shows (a rim of at least ``MIN_RIM``) and does not sit at the end of its
range (:func:`at_bound`). What each feature is (its parameters, start, bounds, least visible value)
is its record in :data:`bokehfit.apertures.FEATURE_SPECS`; this module measures the discs' evidence.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from bokehfit.apertures import FEATURE_SPECS, Aperture, FeatureEvidence
from bokehfit.apertures.features import MIN_RIM, VIGNETTING_START_CUT, VIGNETTING_START_SHIFT  # noqa: F401  (re-exported)
from bokehfit.discs import Disc
from bokehfit.fit.agreement import MIN_ELONGATED_DISCS
from bokehfit.fit.crop import DiscCrop
from bokehfit.fit.disc_model import render_disc_model
from bokehfit.fit.pixels import JointFit, PixelFit
from bokehfit.fit.vector import FIT_BOUNDS
from bokehfit.fit.signature import Screen
from bokehfit.words import counted

__all__ = ["add_feature", "at_bound", "feature_asks", "feature_evidence", "FeatureTrial", "gain_without_one_disc",
           "small_and_faint", "FAINT_CONTRAST_REL", "FEATURE_DELTA_BIC", "MIN_RIM", "SMALL_DISC_PX",
           "VIGNETTING_MIN_FIELD"]

#: A §3b feature joins the model when it lowers the joint BIC by at least this (Kass & Raftery: "very strong"),
#: and still by this much with any one of the jointly fitted discs left out (:func:`gain_without_one_disc`).
FEATURE_DELTA_BIC = 10.0
#: Vignetting is tried only when some fitted disc lies at least this far from the centre (half-diagonals) ...
VIGNETTING_MIN_FIELD = 0.45
#: ... and those discs' outlines misfit the shape at least this many times as much as the central ones'.
VIGNETTING_MISFIT_RATIO = 1.5
#: The rim is tried where discs of at least this diameter (px; smaller ones show no profile) ...
RIM_MIN_DIAMETER_PX = 20.0
#: ... leave their rims brighter or darker than their centres under the flat model by this share of the contrast.
RIM_SIGNAL = 0.04
#: The squeeze (an anamorphic lens: design.md §3b) is tried where at least MIN_ELONGATED_DISCS discs
#: are stretched along the frame's axes alike: their outlines' second moments put the long axis
#: within SQUEEZE_AXIS_DEG of the frame's, the height over width (the squeeze) of their median at
#: least SQUEEZE_SIGNAL from 1 in ratio, and every disc within SQUEEZE_AGREEMENT of it.
SQUEEZE_AXIS_DEG = 10.0
SQUEEZE_SIGNAL = 1.03
SQUEEZE_AGREEMENT = 0.06
#: Discs under SMALL_DISC_PX (median) that stand less than FAINT_CONTRAST_REL of their background above it
#: (median) are small and faint: an outline of a few hundred pixels is set by a few code values of the photo's
#: tone curve, grain and compression as much as by the aperture. Their outlines fix neither a sure shape
#: (``bokehfit.judging``) nor a feature read from the outlines' shape (:func:`feature_asks`).
SMALL_DISC_PX = 64.0
FAINT_CONTRAST_REL = 0.5


def small_and_faint(discs: Sequence[Disc]) -> tuple[float, float] | None:
    """The discs' median diameter and median contrast over their background (a share of it), where both are
    under SMALL_DISC_PX and FAINT_CONTRAST_REL; else None (and for no discs)."""
    if not discs:
        return None
    diameter = float(np.median([d.diameter_px for d in discs]))
    contrast = float(np.median([(d.plateau - d.background) / max(d.background, 1e-6) for d in discs]))
    return (diameter, contrast) if diameter < SMALL_DISC_PX and contrast < FAINT_CONTRAST_REL else None


def at_bound(aperture: Aperture, feature: str) -> bool:
    """Whether a feature's fitted value sits at the end of its search range: the discs pushed it
    there to absorb something else (a misfit shape, the surround), not to describe the lens.

    Both ends count, but for the parameters whose lower end the lens may have (the record's
    ``upper_end_only``: a barrel at the largest radius cuts nothing the start did not).
    """
    spec = FEATURE_SPECS[feature]
    parameters = aperture.parameters
    values = aperture.values
    for name in spec.parameters:
        if name not in parameters:
            continue
        low, high = FIT_BOUNDS.get(name, parameters[name].bounds)
        span = high - low
        at_low = name not in spec.upper_end_only and values[name] - low < 0.01 * span
        if at_low or high - values[name] < 0.01 * span:
            return True
    return False


def gain_without_one_disc(before: JointFit, after: JointFit, noise: Sequence[float]) -> float:
    """The least BIC that a feature's fit ``after`` gains over ``before`` (the same discs, the same noise levels)
    with any one disc left out: the discs' weighted residual sums taken over the others, the fits as they stand
    (not refitted); -inf for a single disc.

    A lens's feature is every disc's: its rim is in every disc's light, its cat-eye in every disc the barrel
    reaches. A gain that one disc carries is that disc's quirk, not the lens's: its neighbour's light, a glow,
    a rim of its own (a JPEG-60 copy of reference photo 05 gained a rim and a vignetting, a mirrored copy of
    11 a vignetting, each from one disc whose own gain exceeded the whole).
    """
    gains = gains_without_each_disc(before, after, noise)
    return float(gains.min()) if len(gains) else -math.inf


def gains_without_each_disc(before: JointFit, after: JointFit, noise: Sequence[float]) -> np.ndarray:
    """The BIC that ``after`` gains over ``before`` with each disc left out in turn, by the discs' order
    (:func:`gain_without_one_disc`); empty for a single disc."""
    if len(after.fits) < 2:
        return np.zeros(0)
    weight = np.maximum(np.asarray(noise, dtype=np.float64), 1e-12) ** 2
    rss_before = np.array([f.rss for f in before.fits]) / weight
    rss_after = np.array([f.rss for f in after.fits]) / weight
    pixels = np.array([f.pixels for f in after.fits], dtype=np.float64)
    added = after.parameters - before.parameters
    gains = np.empty(len(pixels))
    for left_out in range(len(pixels)):
        others = np.arange(len(pixels)) != left_out
        n = float(pixels[others].sum())
        gain = n * math.log(max(rss_before[others].sum(), 1e-300) / max(rss_after[others].sum(), 1e-300))
        gains[left_out] = gain - added * math.log(n)
    return gains


@dataclass(frozen=True)
class FeatureTrial:
    """A §3b feature tried on the joint fit: what it gained, and whether it joined the model (the module's rule)."""

    feature: str
    gain: float  #: the BIC it gained over the joint fit without it
    least_gain: float  #: the least it gained with any one disc left out (:func:`gain_without_one_disc`)
    shows: bool  #: its fitted value is one a photo's discs show (its record's ``least_visible``)
    at_bound: bool  #: its fitted value sits at the end of its range (:func:`at_bound`)
    value: object  #: its fitted value in the trial (a number, or a mapping of the pair's members)
    carried_by: int | None = None  #: the index of the disc whose leaving out leaves the least gain (None: one disc)
    asked: str = ""  #: why the discs asked for it (:func:`feature_asks`)
    #: A second trial: the features that joined the model since its first, which it was tried again with ...
    again_with: tuple[str, ...] = ()
    first_gain: float | None = None  #: ... and what it gained the first time

    @classmethod
    def of(cls, feature: str, before: JointFit, after: JointFit, noise: Sequence[float],
           discs: Sequence[Disc], asked: str = "", again: FeatureTrial | None = None,
           again_with: Sequence[str] = ()) -> FeatureTrial:
        """The trial of ``feature``: ``after``, the joint fit of ``discs`` with it on, against ``before``, without;
        ``again``, its first trial where this one is a second with the features ``again_with`` in the model."""
        spec = FEATURE_SPECS[feature]
        gains = gains_without_each_disc(before, after, noise)
        least, carried_by = (float(gains.min()), discs[int(np.argmin(gains))].index) if len(gains) else (-math.inf, None)
        return cls(feature, before.bic - after.bic, least, spec.shows(after.aperture), at_bound(after.aperture, feature),
                   spec.value(after.aperture), carried_by, asked, tuple(again_with),
                   None if again is None else again.gain)

    @property
    def is_second(self) -> bool:
        """Whether this is a feature's second trial (:func:`bokehfit.fit.stages.try_features`)."""
        return self.first_gain is not None

    @property
    def kept(self) -> bool:
        """It joins the model: FEATURE_DELTA_BIC gained, with any one disc left out too, shown, not at its bound."""
        return (self.gain >= FEATURE_DELTA_BIC and self.shows and not self.at_bound
                and self.least_gain >= FEATURE_DELTA_BIC)

    @property
    def reason(self) -> str:
        """Why it joined the model or did not, in words (the first test it fails, in the order of :attr:`kept`),
        after the first trial's gain where this is a second."""
        if self.is_second:
            return (f"tried again with {' and '.join(self.again_with)} in the model (ΔBIC {self.first_gain:.0f} "
                    f"before), {self._outcome()}")
        return self._outcome()

    def _outcome(self) -> str:
        gain = f"ΔBIC {self.gain:.0f}"
        if self.gain < FEATURE_DELTA_BIC:
            return f"not kept: {gain} ({FEATURE_DELTA_BIC:.0f} needed)"
        if not self.shows:
            return f"not kept: {gain}, but its value ({_value_text(self.value)}) is too small for discs to show"
        if self.at_bound:
            return (f"not kept: {gain}, but its value ({_value_text(self.value)}) is at the end of its range: "
                    "the discs pushed it there to absorb something else")
        if self.least_gain < FEATURE_DELTA_BIC:
            alone = ("from a single disc" if self.carried_by is None
                     else f"{self.least_gain:.0f} without disc {self.carried_by}")
            return f"not kept: {gain}, but {alone}: one disc's, not the lens's"
        return f"kept: {gain}, at least {self.least_gain:.0f} with any one disc left out"

    def to_json(self) -> dict:
        value = ({k: round(float(v), 3) for k, v in self.value.items()} if isinstance(self.value, dict)
                 else round(float(self.value), 3))
        one_out = None if self.carried_by is None else {"least": round(self.least_gain, 2), "disc": self.carried_by}
        return {"feature": self.feature, "kept": self.kept, "delta_bic": round(self.gain, 2),
                "delta_bic_one_disc_out": one_out, "value": value, "reason": self.reason, "asked_because": self.asked,
                "tried_again_with": list(self.again_with),
                "first_delta_bic": None if self.first_gain is None else round(self.first_gain, 2)}


def _value_text(value) -> str:
    """A feature's value in words: a number, or the pair's members."""
    if isinstance(value, dict):
        return ", ".join(f"{member} {float(v):+.2f}" for member, v in value.items())
    return f"{float(value):+.2f}"


def feature_evidence(fits: list[PixelFit], discs: list[Disc]) -> FeatureEvidence:
    """The numbers a feature's start is built from: the farthest fitted disc's distance from the
    centre, the squeeze the discs' outlines share (:func:`_squeeze_signal`)."""
    return FeatureEvidence(max((math.hypot(*f.field_position) for f in fits), default=0.0), _squeeze_signal(discs))


def add_feature(aperture: Aperture, feature: str, fits: list[PixelFit], discs: list[Disc]) -> Aperture:
    """``aperture`` with ``feature`` switched on at a start from which the fit can move (its record's
    :meth:`~bokehfit.apertures.FeatureSpec.start` from :func:`feature_evidence`): the vignetting as a
    barrel that just cuts the disc farthest from the centre, the squeeze at the one the discs' outlines share.
    """
    return FEATURE_SPECS[feature].start(aperture, feature_evidence(fits, discs))


def _rim_signal(crop: DiscCrop, fit: PixelFit) -> float | None:
    """How much brighter the flat model leaves a disc's rim than its centre, over its contrast
    (None for a saturated disc, whose profile is clipped, or one too small to have a centre)."""
    if crop.censored is not None or fit.diameter_px / crop.factor < RIM_MIN_DIAMETER_PX / 2:
        return None
    values = crop.values_of(fit)
    model, background, plateau, _ = render_disc_model(fit.aperture, values, crop.size, crop.data,
                                                      crop.field_position, ignored=crop.ignored)
    rows, cols = np.indices((crop.size, crop.size))
    radius = np.hypot(cols - values["cx"], rows - values["cy"]).ravel() / (0.5 * values["diameter_px"])
    if crop.ignored is not None:
        radius[crop.ignored] = np.inf  # not the disc's light: in neither ring
    residual = crop.data - model
    inner, rim = residual[radius < 0.5], residual[(radius > 0.65) & (radius < 0.9)]
    contrast = plateau - background
    if not len(inner) or not len(rim) or abs(contrast) < 1e-12:
        return None
    return float((rim.mean() - inner.mean()) / contrast)


def _squeeze_signal(discs: list[Disc]) -> float | None:
    """The squeeze the discs' outlines share (module constants), or None where they share none."""
    return _shared_squeeze(discs)[0]


def _shared_squeeze(discs: list[Disc]) -> tuple[float | None, str]:
    """The squeeze the discs' outlines share, or None, and why in words.

    A squeezed aperture scales x by 1/√s and y by √s after its rotation, so every disc's height
    over width, from its outline's second moments about the frame's axes, is s.
    """
    if len(discs) < MIN_ELONGATED_DISCS:
        return None, f"{counted(len(discs), 'disc')} fitted jointly ({MIN_ELONGATED_DISCS} needed to share a stretch)"
    squeezes = []
    for disc in discs:
        moments = cv2.moments(disc.outline_xy.astype(np.float32))
        mu20, mu02, mu11 = moments["mu20"], moments["mu02"], moments["mu11"]
        if mu20 <= 0 or mu02 <= 0:
            return None, f"disc {disc.index} has no outline to measure"
        axis = 0.5 * math.degrees(math.atan2(2.0 * mu11, mu20 - mu02))  # the long axis's, from x
        squeeze = math.sqrt(mu02 / mu20)
        off_axis = min(abs(axis), abs(abs(axis) - 90.0))
        if off_axis > SQUEEZE_AXIS_DEG and abs(math.log(squeeze)) > math.log(SQUEEZE_SIGNAL):
            # stretched askew: not the frame-aligned squeeze of an anamorphic lens
            return None, f"disc {disc.index} is stretched askew ({off_axis:.0f}° from the frame's axes)"
        squeezes.append(squeeze)
    logs = np.log(squeezes)
    middle = float(np.median(logs))
    if abs(middle) < math.log(SQUEEZE_SIGNAL):
        return None, (f"the discs' median height over width is {math.exp(middle):.3f} "
                      f"({SQUEEZE_SIGNAL:g} or {1 / SQUEEZE_SIGNAL:.3f} asks for a squeeze)")
    if np.max(np.abs(logs - middle)) > SQUEEZE_AGREEMENT:
        return None, (f"the discs are stretched differently (height over width {math.exp(logs.min()):.2f}–"
                      f"{math.exp(logs.max()):.2f})")
    return math.exp(middle), f"the discs share a height over width of {math.exp(middle):.3f}"


def feature_asks(fits: list[PixelFit], discs: list[Disc], screens: list[Screen],
                 crops: list[DiscCrop]) -> dict[str, tuple[bool, str]]:
    """Each §3b feature the joint fit may try → whether these discs ask for it, and why or why not, in words: the rim
    where some disc is a ring (a bright rim) or has a bright centre, or the flat model leaves the discs' rims brighter
    or darker than their centres (RIM_SIGNAL of the contrast, median over the discs that show a profile); the
    vignetting where at least 3 discs were fitted, some lie far enough from the centre to be cut (VIGNETTING_MIN_FIELD),
    and those misfit the shape more than the central ones do (or none is central); the squeeze where the discs are
    stretched alike along the frame's axes (:func:`_shared_squeeze`). A feature the discs show by their outlines'
    shape (its record's ``read_from_outline``: the vignetting, the squeeze) is not asked for by small and faint
    discs (:func:`small_and_faint`)."""
    asks = {}
    signals = [v for v in (_rim_signal(c, f) for c, f in zip(crops, fits)) if v is not None]
    ringed = [d.index for d in discs if d.profiled]
    signal = float(np.median(signals)) if signals else None
    if ringed:
        asks["rim"] = True, f"disc {ringed[0]} is a ring or has a bright centre"
    elif signal is not None and abs(signal) >= RIM_SIGNAL:
        asks["rim"] = True, f"the flat model leaves the rims {100 * signal:+.1f} % of the contrast from the centres"
    else:
        shown = "no disc can show its profile (saturated, or too small)" if signal is None else (
            f"the flat model leaves the rims {100 * signal:+.1f} % of the contrast from the centres "
            f"(median of {counted(len(signals), 'disc')}; ±{100 * RIM_SIGNAL:g} % asks for a rim)")
        asks["rim"] = False, f"no disc is a ring or has a bright centre, and {shown}"
    field = np.array([math.hypot(*f.field_position) for f in fits])
    rms = np.array([s.rms for s in screens])
    outer, inner = rms[field >= VIGNETTING_MIN_FIELD], rms[field < VIGNETTING_MIN_FIELD]
    if len(discs) < 3:
        asks["vignetting"] = False, f"{counted(len(discs), 'disc')} fitted jointly (3 needed)"
    elif not len(outer):
        asks["vignetting"] = False, (f"no disc lies {VIGNETTING_MIN_FIELD:g} of the half-diagonal or more from the "
                                     "centre, where a barrel cuts")
    elif len(inner) and not np.median(outer) > VIGNETTING_MISFIT_RATIO * np.median(inner):
        ratio = float(np.median(outer) / max(float(np.median(inner)), 1e-12))
        asks["vignetting"] = False, (f"the outer discs misfit the shape {ratio:.2f} times as much as the central ones "
                                     f"({VIGNETTING_MISFIT_RATIO:g} asks for a cat-eye)")
    else:
        asks["vignetting"] = True, "the outer discs misfit the shape more than the central ones"
    squeeze, why = _shared_squeeze(discs)
    asks["squeeze"] = squeeze is not None, why
    faint = small_and_faint(discs)
    if faint:
        for name, (asked, _) in list(asks.items()):
            if asked and FEATURE_SPECS[name].read_from_outline:
                asks[name] = False, (f"the discs are small and faint (median {faint[0]:.0f} px, {faint[1]:.0%} above "
                                     f"their background; {SMALL_DISC_PX:.0f} px or {FAINT_CONTRAST_REL:.0%} to read it "
                                     "from their outlines): their outlines follow the photo's grain and compression "
                                     "as much as the lens")
    return asks
