"""Fit one aperture to a photo's bokeh discs: shape family, angle, size, with model selection.

The steps (design.md §8, the simplest model the data supports):

1. **Discs.** The discs that show their shape (:attr:`Disc.usable`): resolvable
   (≥ 8 px), not cut by the frame, and most of their outline their own.
   Saturated discs are fitted with their clipped pixels as lower bounds; discs
   that overlap others with the others' light left out, discs crossed by an
   occluder with its pixels left out (:mod:`bokehfit.fit.pixels`). At most ``FitOptions.max_discs``: discs on
   their own first, then clean before saturated before partial, the largest and
   clearest first.
2. **Screen.** Each disc's outline is compared with every family's radial
   signature (:mod:`bokehfit.fit.signature`); the ``FitOptions.shortlist`` families with
   the lowest mean misfit, and always the circle, go on to the pixel fit.
3. **Fit.** Each shortlisted family is fitted to the pixels of the first
   ``FitOptions.model_discs`` discs (:mod:`bokehfit.fit.pixels`).
4. **Select.** The family with the lowest total BIC over those discs wins
   (BIC = n·ln(RSS/n) + k·ln(n) per disc): a round disc is a circle, not a
   12-gon, because the 12-gon's extra parameters buy no lower residual.
   ``delta_bic`` of the runner-up says how sure the choice is.
5. **Consensus.** The winner is fitted to every chosen disc. The angle is the weighted circular mean of the discs'
   angles modulo the symmetry (weights 1/σ²); its uncertainty combines the
   spread between discs and each fit's own. The size is the median of the
   fitted equal-area diameters. The winner's candidate entry carries this
   consensus, so the aperture reported, the kernel drawn and the candidate
   table give one angle and one size.

The result is an :class:`ApertureFit` (named parameters with uncertainties,
the candidates, the per-disc fits), or a falsy :class:`FailedFit` with the reason.

For shapes of odd symmetry a disc in front of the focus plane shows the
aperture turned by 180°, so the aperture's angle is either the angle seen
(lights behind the focus plane: ``focus_side="far"``) or that plus 180°.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import cv2
import numpy as np

from bokehfit.apertures import Aperture
from bokehfit.discs import MIN_FIT_SEEN, USABLE_EVIDENCE, Disc
from bokehfit.errors import InputError
from bokehfit.fit.chromatic import measure_chromatic
from bokehfit.fit.families import FAMILIES, Family, families_for
from bokehfit.fit.pixels import FIT_BOUNDS, DiscCrop, PixelFit, crop_disc, field_position, fit_discs, render_disc_model
from bokehfit.fit.result import (
    LENS_FEATURES,
    ROUND_ENOUGH,
    ApertureFit,
    CandidateModel,
    DiscFit,
    FailedFit,
    FitFailedError,
    FitOptions,
    Parameter,
)
from bokehfit.fit.signature import Ellipse, Screen, fit_ellipse, outline_misfit, screen
from bokehfit.metrics import angle_error

__all__ = [
    "ApertureFit",
    "CandidateModel",
    "DiscFit",
    "FailedFit",
    "FitFailedError",
    "FitOptions",
    "Parameter",
    "fit_aperture",
    "FOCUS_SIDES",
    "LENS_FEATURES",
    "REGULAR_OUTLINE_MISFIT",
    "ROUND_ENOUGH",
]

FOCUS_SIDES = ("far", "near", "unknown")


#: A rounded family is fitted where its screen misfit is under this share of the straight one's on some disc ...
ROUNDER_SCREEN = 0.95
#: ... of at least this diameter (px): a smaller disc cannot show how round its blades are.
ROUNDNESS_MIN_DIAMETER_PX = 16.0
#: A §3b feature joins the model when it lowers the joint BIC by at least this (Kass & Raftery: "very strong").
FEATURE_DELTA_BIC = 10.0
#: An elongated aperture (a slit) is accepted only when at least this many discs show it ...
MIN_ELONGATED_DISCS = 3
#: ... at angles within this spread of each other ...
ELONGATED_ANGLE_SPREAD_DEG = 10.0
#: ... and aspects within this spread (the aspects' standard deviation).
ELONGATED_ASPECT_SPREAD = 0.1
#: A shape with an angle is supported only where the discs' angles spread less than this share of its symmetry.
ANGLE_AGREEMENT_SHARE = 0.125
#: Vignetting is tried only when some fitted disc lies at least this far from the centre (half-diagonals) ...
VIGNETTING_MIN_FIELD = 0.45
#: ... and those discs' outlines misfit the shape at least this many times as much as the central ones'.
VIGNETTING_MISFIT_RATIO = 1.5
#: Its starting barrel: this shift (R0 per half-diagonal; negative: the barrel's centre towards the
#: image centre, cutting a disc's outer side), and a radius that cuts the farthest disc this far inside its R0.
VIGNETTING_START_SHIFT = -1.0
VIGNETTING_START_CUT = 0.85
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
#: Least |rim| reported: a smaller one changes a disc's profile by under 5 % (below what a photo's discs show).
MIN_RIM = 0.05
#: A disc's outline is regular when some aperture shape (not an elongated one) fits it this well:
#: median radial misfit in equal-area radii. Bokeh discs of a real lens show 0.01–0.05 (noise,
#: JPEG, a little bloom); out-of-focus petals, leaves, discs cut by a blade and merged glows 0.1
#: and more. Regular discs are fitted before irregular ones, and a sure fit needs its discs'
#: median misfit at most this (bokehfit.compare).
REGULAR_OUTLINE_MISFIT = 0.08
#: A disc whose outline only an ellipse explains (to REGULAR_OUTLINE_MISFIT) is fitted where a lens
#: feature accounts for the stretch: at least MIN_ELONGATED_DISCS such discs stretched alike (angles
#: within ELONGATED_ANGLE_SPREAD_DEG, aspects within ELONGATED_ASPECT_SPREAD: a squeeze, or a slit), or
#: the cat-eye's: a disc at least VIGNETTING_MIN_FIELD from the centre whose long axis lies within
#: CATEYE_AXIS_DEG of square to the line from the centre (the barrel cuts the side away from it).
CATEYE_AXIS_DEG = 20.0
#: The discs fitted are chosen from this many times the budget (max_discs) of the clearest ones.
CHOICE_POOL = 4
#: A shape with more parameters than the circle is kept only where it fits the outlines of at least
#: this share of the jointly fitted discs better than the circle does (each against its joint fit):
#: blades are seen on the outlines, not in the light inside them or around them.
OUTLINE_SUPPORT_SHARE = 0.75
#: Most discs fitted jointly (the clearest first): the shared parameters are settled well before.
JOINT_DISCS = 8
#: A disc disagrees with the consensus when its angle is off by more than this many standard deviations ...
OUTLIER_SIGMAS = 3.0
#: ... (never less than this many degrees) ...
MIN_ANGLE_TOLERANCE_DEG = 3.0
#: ... or its outline misfits the shape by more than this many times the median misfit (and by at least MIN_OUTLIER_RMS).
OUTLIER_RMS_FACTOR = 3.0
MIN_OUTLIER_RMS = 0.05


def _order_for_fit(discs: list[Disc], max_discs: int) -> list[Disc]:
    """The clearest usable discs, at most ``max_discs``: those on their own before those beside or on
    other light (fitted with that light left out); within each, clean ones first, then edges, then
    outlines seen in part; the largest and clearest first."""
    usable = [d for d in discs if d.usable]
    usable.sort(key=lambda d: (d.overlaps, USABLE_EVIDENCE.index(d.evidence), -d.diameter_px * min(d.snr, 50.0)))
    return usable[:max_discs]


def _outline_class(screens: list[Screen], ellipse: Ellipse | None) -> tuple[int, float]:
    """How an aperture explains the outline, and the best non-elongated shape's misfit: class 0
    where a shape that is not elongated fits it to REGULAR_OUTLINE_MISFIT, 1 where only an elongated
    one does (a slit at the disc's own aspect, or an ellipse: a squeeze, a cat-eye), 2 where none does."""
    round_misfit = min((s.rms for s in screens if "aspect" not in s.family.aperture.parameters), default=math.inf)
    if round_misfit <= REGULAR_OUTLINE_MISFIT:
        return 0, round_misfit
    stretched = min([s.rms for s in screens] + ([ellipse.misfit] if ellipse is not None else []))
    return (1 if stretched <= REGULAR_OUTLINE_MISFIT else 2), round_misfit


def _stretch_explained(disc: Disc, ellipse: Ellipse, others: list[Ellipse], shape: tuple[int, int]) -> bool:
    """Whether a lens feature accounts for an elongated disc (CATEYE_AXIS_DEG's note): others
    stretched alike, or the cat-eye's cut at its place in the frame."""
    alike = sum(angle_error(ellipse.axis_deg, e.axis_deg, 180.0) <= ELONGATED_ANGLE_SPREAD_DEG
                and abs(ellipse.aspect - e.aspect) <= ELONGATED_ASPECT_SPREAD for e in others)
    if alike + 1 >= MIN_ELONGATED_DISCS:
        return True
    qx, qy = field_position(disc.center_xy, shape)
    if math.hypot(qx, qy) < VIGNETTING_MIN_FIELD:
        return False
    radial = math.degrees(math.atan2(-qy, qx))  # the line from the centre, in the image (y down)
    return angle_error(ellipse.axis_deg, radial + 90.0, 180.0) <= CATEYE_AXIS_DEG


def _choose_discs(discs: list[Disc], families: tuple[Family, ...], max_discs: int, models: dict,
                  shape: tuple[int, int]) -> tuple[list[Disc], dict[int, str]]:
    """The discs fitted, and those set aside with the reason.

    A defocused light is the aperture's image: every disc shows the same outline. So a disc is
    fitted only where an aperture explains its outline (its own points) to REGULAR_OUTLINE_MISFIT
    of its radius: some shape, or a shape stretched by what a lens does to every disc or to those
    at the frame's edge (:func:`_stretch_explained`). Lit leaves and petals, in-focus highlights,
    patches of sky between branches, discs cut by a blade and glows run together are not, and are
    set aside with the reason, whatever their clarity. They are chosen from the CHOICE_POOL ·
    ``max_discs`` clearest (:func:`_order_for_fit`): discs on their own before those beside other
    light, shapes that are not elongated before elongated ones, each group in that order. The
    straight families suffice (a rounded polygon lies between its straight one and the circle) and
    keep the screen cheap; all of them, whatever shapes the fit tries. ``models`` is the fit's memo of
    model signatures (:func:`~bokehfit.fit.signature.screen`); ``shape`` the photo's (rows, columns)."""
    pool = _order_for_fit(discs, CHOICE_POOL * max_discs)
    groups: dict[tuple[bool, int], list[Disc]] = {(False, 0): [], (False, 1): [], (True, 0): [], (True, 1): []}
    set_aside: dict[int, str] = {}
    stretched: list[tuple[Disc, Ellipse]] = []
    for disc in pool:  # discs on their own come first: once max_discs of them are regular, the rest can wait
        if len(groups[False, 0]) >= max_discs:
            break
        screens = screen(disc.outline_xy, families, _slit_aspect(disc), disc.outline_reliable, models)
        kind, misfit = _outline_class(screens, None)
        ellipse = None
        if kind != 0:
            ellipse = fit_ellipse(disc.outline_xy, disc.outline_reliable)
            kind, _ = _outline_class(screens, ellipse)
        if kind == 1 and ellipse is not None:
            stretched.append((disc, ellipse))
        elif kind == 1:
            groups[disc.overlaps, 1].append(disc)
        elif kind == 0:
            groups[disc.overlaps, 0].append(disc)
        else:
            set_aside[disc.index] = (f"no aperture shape explains its outline (misfit {misfit:.2f} of its radius, "
                                     f"at most {REGULAR_OUTLINE_MISFIT} for a disc)")
    for disc, ellipse in stretched:
        others = [e for d, e in stretched if d is not disc]
        if _stretch_explained(disc, ellipse, others, shape):
            groups[disc.overlaps, 1].append(disc)
        else:
            set_aside[disc.index] = (f"stretched (aspect {ellipse.aspect:.2f} at {ellipse.axis_deg:.0f}°) as no other "
                                     "disc is and not as a cat-eye at its place: not the aperture's image")
    order = {disc.index: i for i, disc in enumerate(pool)}
    return [disc for group in groups.values() for disc in sorted(group, key=lambda d: order[d.index])][:max_discs], set_aside


def _slit_aspect(disc: Disc) -> float:
    (_, _), (a, b), _ = cv2.minAreaRect(disc.outline_xy.astype(np.float32))
    return float(np.clip(math.sqrt(min(a, b) / max(a, b, 1e-9)), 0.02, 1.0))


def _circular_mean(angles: np.ndarray, weights: np.ndarray, period: float) -> tuple[float, float]:
    """Weighted circular mean modulo ``period`` and the spread (circular standard deviation)."""
    phase = np.radians(angles) * (360.0 / period)
    c, s = np.sum(weights * np.cos(phase)), np.sum(weights * np.sin(phase))
    mean = math.degrees(math.atan2(s, c)) * period / 360.0 % period
    resultant = math.hypot(c, s) / max(np.sum(weights), 1e-300)
    spread = math.degrees(math.sqrt(max(-2.0 * math.log(max(resultant, 1e-12)), 0.0))) * period / 360.0
    return mean, spread


def _angle_offsets(angles: np.ndarray, mean: float, period: float) -> np.ndarray:
    """Signed differences of ``angles`` from ``mean`` modulo ``period``, in (−period/2, period/2]."""
    return (np.asarray(angles) - mean + 0.5 * period) % period - 0.5 * period


def _angle_sigmas(fits: list[PixelFit]) -> np.ndarray:
    sigmas = np.array([f.uncertainty.get("angle_deg", np.nan) for f in fits])
    return np.where(np.isfinite(sigmas) & (sigmas > 0), sigmas, 1.0)


def _combine(family: Family, fits: list[PixelFit], screens: list[Screen]) -> CandidateModel:
    diameters = np.array([f.diameter_px for f in fits])
    angle = uncertainty = None
    symmetry = family.aperture.symmetry_deg
    if family.aperture.has_angle:
        angles = np.array([f.angle_deg for f in fits])
        sigmas = _angle_sigmas(fits)
        angle, spread = _circular_mean(angles, 1.0 / sigmas**2, symmetry)
        within = 1.0 / math.sqrt(np.sum(1.0 / sigmas**2))
        uncertainty = math.hypot(spread / math.sqrt(len(fits)), within)
    return CandidateModel(
        family=family,
        bic=float(sum(f.bic for f in fits)),
        delta_bic=0.0,
        angle_deg=angle,
        angle_uncertainty_deg=uncertainty,
        diameter_px=float(np.median(diameters)),
        screen_rms=float(np.median([s.rms for s in screens])),
        roundness=(float(np.median([f.aperture.roundness for f in fits]))
                   if "roundness" in family.aperture.parameters else None),
    )


def _elongation_doubt(family: Family, fits: list[PixelFit]) -> str | None:
    """Why an elongated family (a slit) is not supported by ``fits``; None when it is, or when it is not elongated.

    One blob stretched by an in-focus edge, a cat-eye at the frame's edge or
    two merged discs looks like a slit; an elongated aperture shows as the
    same elongation on several discs.
    """
    if "aspect" not in family.aperture.parameters:
        return None
    if len(fits) < MIN_ELONGATED_DISCS:
        return f"an elongated aperture needs at least {MIN_ELONGATED_DISCS} discs that agree (only {len(fits)} fitted)"
    angles = np.array([f.angle_deg for f in fits])
    _, spread = _circular_mean(angles, np.ones(len(angles)), family.aperture.symmetry_deg)
    aspects = np.array([f.aperture.aspect for f in fits])
    if spread > ELONGATED_ANGLE_SPREAD_DEG or np.std(aspects) > ELONGATED_ASPECT_SPREAD:
        return (f"the discs do not agree on one elongation (angles spread {spread:.0f}°, "
                f"aspects {aspects.min():.2f}–{aspects.max():.2f})")
    return None


def _turned(family: Family, fits: list[PixelFit]) -> list[bool]:
    """Which discs show the aperture turned by 180° from the majority (design.md §2: near and far discs).

    Only a shape of odd symmetry tells: turned by 180° it sits half its
    symmetry away. The majority is taken as seen unturned.
    """
    aperture = family.aperture
    if not aperture.has_angle or not aperture.odd_symmetry:
        return [False] * len(fits)
    period = aperture.symmetry_deg
    angles = np.array([f.angle_deg for f in fits])
    mean, _ = _circular_mean(angles, 1.0 / _angle_sigmas(fits) ** 2, 0.5 * period)
    turned = np.abs(_angle_offsets(angles, mean, period)) > 0.25 * period
    if 2 * int(turned.sum()) > len(fits):
        turned = ~turned
    return [bool(t) for t in turned]


def _unturned_angles(family: Family, fits: list[PixelFit], turned: list[bool]) -> np.ndarray:
    """The discs' angles as the unturned discs show the aperture."""
    half = 0.5 * family.aperture.symmetry_deg
    return np.array([f.angle_deg - (half if t else 0.0) for f, t in zip(fits, turned)]) % family.aperture.symmetry_deg


def _unsupported(family: Family, fits: list[PixelFit]) -> str | None:
    """Why the discs do not support ``family`` together (None when they do): an elongation they do
    not share (:func:`_elongation_doubt`), or angles that scatter (robust spread over
    ANGLE_AGREEMENT_SHARE of the symmetry, at least MIN_ANGLE_TOLERANCE_DEG) with two discs or more."""
    doubt = _elongation_doubt(family, fits)
    if doubt is not None or not family.aperture.has_angle or len(fits) < 2:
        return doubt
    period = family.aperture.symmetry_deg
    angles = _unturned_angles(family, fits, _turned(family, fits))
    mean, _ = _circular_mean(angles, np.ones(len(angles)), period)
    spread = 1.4826 * float(np.median(np.abs(_angle_offsets(angles, mean, period))))
    if spread > max(ANGLE_AGREEMENT_SHARE * period, MIN_ANGLE_TOLERANCE_DEG):
        return f"the discs put its angle in different places (spread {spread:.0f}° of its {period:.0f}° symmetry)"
    return None


def _disagreeing(family: Family, fits: list[PixelFit], screens: list[Screen], turned: list[bool]) -> dict[int, str]:
    """Discs (by position in ``fits``) whose shape or angle the others' consensus does not share, with the reason."""
    out: dict[int, str] = {}
    if len(fits) < 3:
        return out
    rms = np.array([s.rms for s in screens])
    limit = max(OUTLIER_RMS_FACTOR * float(np.median(rms)), MIN_OUTLIER_RMS)
    for i in np.flatnonzero(rms > limit):
        out[int(i)] = (f"its outline is not the shape the other discs share (misfit {rms[i]:.3f} of its radius, "
                       f"median {np.median(rms):.3f})")
    if family.aperture.has_angle:
        period = family.aperture.symmetry_deg
        sigmas = _angle_sigmas(fits)
        angles = _unturned_angles(family, fits, turned)
        mean, _ = _circular_mean(angles, 1.0 / sigmas**2, period)
        offsets = _angle_offsets(angles, mean, period)
        robust = 1.4826 * float(np.median(np.abs(offsets)))
        for i, (offset, sigma) in enumerate(zip(offsets, sigmas)):
            tolerance = max(OUTLIER_SIGMAS * math.hypot(robust, sigma), MIN_ANGLE_TOLERANCE_DEG)
            if abs(offset) > tolerance and i not in out:
                out[i] = f"its angle is {offset:+.1f}° from the other discs' ({mean:.1f}°, tolerance {tolerance:.1f}°)"
    if len(out) * 2 > len(fits):  # no majority to disagree with: keep them all, the judge will doubt
        return {}
    return out


def _consensus_start(family: Family, fits: list[PixelFit], turned: list[bool]) -> Aperture:
    """The family's aperture at the discs' consensus: circular mean of the angle (as unturned discs show it), median of the rest."""
    values = {}
    for name, parameter in fits[0].aperture.parameters.items():
        own = np.array([f.aperture.values[name] for f in fits])
        if parameter.periodic is not None:
            own = _unturned_angles(family, fits, turned)
            values[name] = _circular_mean(own, 1.0 / _angle_sigmas(fits) ** 2, parameter.periodic)[0]
        else:
            values[name] = float(np.median(own))
    return family.aperture.replace(**values) if values else family.aperture


def _misfits(discs: list[Disc], aperture: Aperture, fits: list[PixelFit]) -> np.ndarray:
    """Outline misfit (equal-area radii) of each of ``discs`` to one ``aperture``, as it shows at the disc's field position."""
    return np.array([outline_misfit(d.outline_xy, aperture, f.field_position) for d, f in zip(discs, fits)])


def _at_bound(aperture: Aperture, feature: str) -> bool:
    """Whether a feature's fitted value sits at the end of its search range: the discs pushed it
    there to absorb something else (a misfit shape, the surround), not to describe the lens."""
    parameters = aperture.parameters
    values = aperture.values
    for name in parameters:
        if not name.startswith(feature):
            continue
        low, high = FIT_BOUNDS.get(name, parameters[name].bounds)
        span = high - low
        if name != "vignetting_radius" and min(values[name] - low, high - values[name]) < 0.01 * span:
            return True
        if name == "vignetting_radius" and high - values[name] < 0.01 * span:
            return True  # a barrel at the largest radius cuts nothing the start did not
    return False


def _fit_start(aperture: Aperture) -> Aperture:
    """The pixel fit's start from a screen's aperture: a rounded one a little off its straight bound."""
    if "roundness" in aperture.parameters:
        return aperture.replace(roundness=max(aperture.roundness, 0.05))
    return aperture


def _add_feature(aperture: Aperture, feature: str, fits: list[PixelFit], discs: list[Disc]) -> Aperture:
    """``aperture`` with ``feature`` switched on at a start from which the fit can move.

    The vignetting starts as a barrel that just cuts the disc farthest from the centre; the
    squeeze at the one the discs' outlines share.
    """
    if feature == "squeeze":
        return aperture.with_features("squeeze").replace(squeeze=_squeeze_signal(discs) or 1.0)
    if feature == "vignetting":
        farthest = max(math.hypot(*f.field_position) for f in fits)
        shift = VIGNETTING_START_SHIFT
        return aperture.replace(vignetting_radius=abs(shift) * farthest + VIGNETTING_START_CUT, vignetting_shift=shift)
    if feature == "rim":
        return aperture.with_features("rim").replace(rim=0.2)
    return aperture.with_features(feature)


def _rim_signal(crop: DiscCrop, fit: PixelFit) -> float | None:
    """How much brighter the flat model leaves a disc's rim than its centre, over its contrast
    (None for a saturated disc, whose profile is clipped, or one too small to have a centre)."""
    if crop.censored is not None or fit.diameter_px / crop.factor < RIM_MIN_DIAMETER_PX / 2:
        return None
    values = crop.values_of(fit)
    model, background, plateau = render_disc_model(fit.aperture, values, crop.size, crop.data, crop.field_position,
                                                   ignored=crop.ignored)
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
    """The squeeze the discs' outlines share (module constants), or None where they share none.

    A squeezed aperture scales x by 1/√s and y by √s after its rotation, so every disc's height
    over width, from its outline's second moments about the frame's axes, is s.
    """
    if len(discs) < MIN_ELONGATED_DISCS:
        return None
    squeezes = []
    for disc in discs:
        moments = cv2.moments(disc.outline_xy.astype(np.float32))
        mu20, mu02, mu11 = moments["mu20"], moments["mu02"], moments["mu11"]
        if mu20 <= 0 or mu02 <= 0:
            return None
        axis = 0.5 * math.degrees(math.atan2(2.0 * mu11, mu20 - mu02))  # the long axis's, from x
        squeeze = math.sqrt(mu02 / mu20)
        off_axis = min(abs(axis), abs(abs(axis) - 90.0))
        if off_axis > SQUEEZE_AXIS_DEG and abs(math.log(squeeze)) > math.log(SQUEEZE_SIGNAL):
            return None  # stretched askew: not the frame-aligned squeeze of an anamorphic lens
        squeezes.append(squeeze)
    logs = np.log(squeezes)
    middle = float(np.median(logs))
    if abs(middle) < math.log(SQUEEZE_SIGNAL) or np.max(np.abs(logs - middle)) > SQUEEZE_AGREEMENT:
        return None
    return math.exp(middle)


def _feature_tests(fits: list[PixelFit], discs: list[Disc], screens: list[Screen], crops: list[DiscCrop]) -> tuple[str, ...]:
    """The §3b features worth testing on these discs: the rim where some disc is a ring (a bright rim)
    or has a bright centre, or the flat model leaves the discs' rims brighter or darker than their centres (RIM_SIGNAL of the
    contrast, median over the discs that show a profile); the vignetting where at least 3 discs were
    fitted, some lie far enough from the centre to be cut (VIGNETTING_MIN_FIELD), and those misfit
    the shape more than the central ones do (or none is central); the squeeze where the discs are
    stretched alike along the frame's axes (:func:`_squeeze_signal`)."""
    signals = [v for v in (_rim_signal(c, f) for c, f in zip(crops, fits)) if v is not None]
    profiled = bool(signals) and abs(float(np.median(signals))) >= RIM_SIGNAL
    features = ["rim"] if profiled or any(d.ring or d.bright_centre for d in discs) else []
    field = np.array([math.hypot(*f.field_position) for f in fits])
    rms = np.array([s.rms for s in screens])
    outer, inner = rms[field >= VIGNETTING_MIN_FIELD], rms[field < VIGNETTING_MIN_FIELD]
    if len(discs) >= 3 and len(outer) and (not len(inner) or np.median(outer) > VIGNETTING_MISFIT_RATIO * np.median(inner)):
        features.append("vignetting")
    if _squeeze_signal(discs) is not None:
        features.append("squeeze")
    return tuple(features)


def fit_aperture(
    luminance: np.ndarray,
    discs: list[Disc],
    *,
    shapes: list[str] | None = None,
    focus_side: str = "unknown",
    options: FitOptions | None = None,
    progress=None,
    clipped: np.ndarray | None = None,
    rgb: Callable[[slice, slice], np.ndarray] | None = None,
) -> ApertureFit | FailedFit:
    """Fit one aperture to the discs (see the module notes).

    Parameters
    ----------
    luminance : ndarray of shape (M, N), float32
        The photo in linear light (the one the discs were found in).
    discs : list of Disc
        From :func:`bokehfit.discs.find_discs`.
    shapes : list of str, optional
        Restrict the families tried (shape names, or ``ngon(N)``).
    focus_side : {"far", "near", "unknown"}
        Where the lights are relative to the focus plane, if known.
    options : FitOptions, optional
        The budget (most discs fitted) and thresholds; ``FitOptions()`` by default.
    progress : callable, optional
        Called with (done, total) after each disc.
    clipped : ndarray of shape (M, N), bool, optional
        Pixels clipped in the source (:attr:`bokehfit.io.Photo.clipped`): fitted
        as lower bounds, so saturated discs give their outlines.
    rgb : callable, optional
        ``rgb(rows, cols)``: a window of the photo in linear RGB, (h, w, 3)
        (:meth:`bokehfit.io.Photo.linear_rgb`). With it the discs' colours are
        measured for the chromatic aberration (:mod:`bokehfit.fit.chromatic`).

    Returns
    -------
    ApertureFit or FailedFit
        The fit, or a falsy failure (status ``no_discs``) naming why no disc could be fitted.

    Examples
    --------
    >>> fit = fit_aperture(luminance, discs, options=FitOptions(max_discs=6))  # doctest: +SKIP
    """
    start = time.perf_counter()
    if focus_side not in FOCUS_SIDES:
        raise InputError(f"focus_side must be one of {', '.join(FOCUS_SIDES)} (got {focus_side!r})")
    options = FitOptions() if options is None else options
    if not isinstance(options, FitOptions):
        raise InputError(f"options must be a FitOptions (got {type(options).__name__})")
    if clipped is not None and np.shape(clipped) != np.shape(luminance):
        raise InputError(f"clipped must have the luminance's shape {np.shape(luminance)} (got {np.shape(clipped)})")
    families = families_for(shapes)
    timing: dict[str, float] = {}
    lap = [time.perf_counter()]

    def clock(step: str) -> None:  # the time since the last step's end, added to ``step``
        now = time.perf_counter()
        timing[step] = timing.get(step, 0.0) + now - lap[0]
        lap[0] = now

    models: dict = {}  # the model signatures of the screens, made once for all discs
    # Whether a blob is an aperture's image does not hang on the shapes the caller lets the fit try.
    chosen, set_aside = _choose_discs(discs, FAMILIES, options.max_discs, models, np.shape(luminance))
    clock("choose")
    if not chosen:
        flagged = {
            "cut by the frame": sum(d.clipped for d in discs),
            "under 8 px": sum(not d.resolvable for d in discs),
            "seen only in part": sum(d.outline_seen < MIN_FIT_SEEN for d in discs),
            "with an outline no aperture shape explains": len(set_aside),
        }
        why = ", ".join(f"{n} {what}" for what, n in flagged.items() if n)
        found = f"{len(discs)} found: {why}" if discs else "none found"
        return FailedFit("no_discs", f"no disc is clean enough to fit ({found})", time_s=time.perf_counter() - start,
                         rejected=set_aside, timing_s=timing)

    crops = [crop_disc(luminance, d, clipped, discs) for d in chosen]
    # Every family is screened straight and, where it has blades, rounded (design.md §3b): a
    # rounded 7-gon looks more like a 12-gon than a 7-gon to a straight-only screen.
    rounded_of = {f: f.rounded for f in families if f.rounded is not None}
    screen_families = (*families, *rounded_of.values())
    screened = [screen(d.outline_xy, screen_families, _slit_aspect(d), d.outline_reliable, models) for d in chosen]
    screens_of = [{s.family: s for s in disc_screens} for disc_screens in screened]
    mean_rms = {f: np.mean([found[f].rms for found in screens_of]) for f in screen_families}
    best_rms = {f: min(mean_rms[f], mean_rms[rounded_of[f]]) if f in rounded_of else mean_rms[f] for f in families}
    shortlist = sorted(families, key=lambda f: best_rms[f])[: options.shortlist]
    if FAMILIES[0] in families and FAMILIES[0] not in shortlist:
        shortlist.append(FAMILIES[0])  # the simplest model is always a candidate
    # Each shortlisted n-gon is fitted straight and, where the screen finds its outline rounder
    # than the straight blades on some of the discs that choose the model, with its roundness free:
    # a straight polygon and the circle are the ends, the BIC says whether the discs need it.
    def rounder(family: Family) -> bool:
        return any(found[rounded_of[family]].rms < ROUNDER_SCREEN * found[family].rms
                   for disc, found in zip(chosen[: options.model_discs], screens_of)
                   if disc.diameter_px >= ROUNDNESS_MIN_DIAMETER_PX)

    candidates = [g for f in shortlist for g in (f, rounded_of.get(f) if f in rounded_of and rounder(f) else None)
                  if g is not None]
    clock("screen")

    # Model selection on the first model_discs discs, then the winner on all of them.
    model_discs = options.model_discs
    disc_fits = []
    for i, (disc, crop, disc_screens, found) in enumerate(zip(chosen[:model_discs], crops, screened, screens_of)):
        fits = {}
        for g in candidates:
            fits[g.name] = fit_discs([crop], g, _fit_start(found[g].aperture)).fits[0]
            clock(f"family {g.name}")
        disc_fits.append(DiscFit(disc, disc_screens, fits))
        if progress is not None:
            progress(i + 1, len(chosen))
    models = [
        _combine(family, [item.fits[family.name] for item in disc_fits], [found[family] for found in screens_of[: len(disc_fits)]])
        for family in candidates
    ]
    models.sort(key=lambda m: m.bic)
    # The best model the discs support together: one aperture shows the same angle (and the same
    # elongation) on every disc; a shape whose angle each disc puts elsewhere is a misfit, not a lens.
    notes = []
    winner = models[0].family
    for model in models:
        doubt = _unsupported(model.family, [item.fits[model.family.name] for item in disc_fits])
        if doubt is None:
            winner = model.family
            break
        if not notes or model is models[0]:
            notes.append(f"not a {model.family.aperture.display_name}: {doubt}")
    for i, (disc, crop, disc_screens, found) in enumerate(
        zip(chosen[model_discs:], crops[model_discs:], screened[model_discs:], screens_of[model_discs:]), model_discs
    ):
        fitted = fit_discs([crop], winner, _fit_start(found[winner].aperture)).fits[0]
        disc_fits.append(DiscFit(disc, disc_screens, {winner.name: fitted}))
        if progress is not None:
            progress(i + 1, len(chosen))
    clock("winner")

    # Consensus: discs whose shape or angle the others do not share are left out, with the reason.
    winner_fits = [item.fits[winner.name] for item in disc_fits]
    winner_screens = [found[winner] for found in screens_of]
    turned = _turned(winner, winner_fits)
    outliers = _disagreeing(winner, winner_fits, winner_screens, turned)
    rejected = {disc_fits[i].disc.index: reason for i, reason in outliers.items()}
    kept = [i for i in range(len(disc_fits)) if i not in outliers]

    # One aperture for the discs: a joint fit, then the §3b features the discs ask for.
    joint_ids = kept[:JOINT_DISCS]
    crops = [dataclasses.replace(crop, turned=t) for crop, t in zip(crops, turned)]
    joint_crops = [crops[i] for i in joint_ids]
    noise = [winner_fits[i].noise for i in joint_ids]
    disc_starts = [crops[i].values_of(winner_fits[i]) for i in joint_ids]
    aperture = _consensus_start(winner, [winner_fits[i] for i in joint_ids], [turned[i] for i in joint_ids])
    joint = fit_discs(joint_crops, winner, aperture, noise=noise, disc_starts=disc_starts)
    clock("joint")
    feature_tests: dict[str, float] = {}
    joint_discs = [chosen[i] for i in joint_ids]
    tests = _feature_tests([winner_fits[i] for i in joint_ids], joint_discs, [winner_screens[i] for i in joint_ids],
                           joint_crops)
    for feature in tests:
        trial = fit_discs(joint_crops, winner, _add_feature(joint.aperture, feature, joint.fits, joint_discs), noise=noise,
                          disc_starts=[crops[i].values_of(f) for i, f in zip(joint_ids, joint.fits)])
        feature_tests[feature] = joint.bic - trial.bic
        visible = feature != "rim" or abs(trial.aperture.rim) >= MIN_RIM
        if feature_tests[feature] >= FEATURE_DELTA_BIC and visible and not _at_bound(trial.aperture, feature):
            joint = trial
    clock("features")
    # With a feature on, the shape is chosen again between the winner and the simplest model:
    # a cat-eye cut makes round discs look like a rounded triangle until the cut is in the model,
    # and an anamorphic squeeze makes them look like a slit (whose own aspect takes the squeeze).
    added = [f for f in feature_tests if f in joint.aperture.enabled_features]
    if "squeeze" in tests and "aspect" in winner.aperture.parameters and "squeeze" not in added:
        added.append("squeeze")
    # Blades and their angle are seen on every disc: the winner, chosen on the first model_discs,
    # must show one angle (and one elongation) on all the discs kept, and fit most of their
    # outlines better than the simplest model does (each against its jointly fitted aperture);
    # otherwise the pixels chose it for something else (the surround, the light inside) and the
    # outlines do not show its blades.
    simplest = FAMILIES[0]
    if simplest in families and winner.base != simplest:
        start_values = {n: v for n, v in joint.aperture.values.items() if any(n.startswith(f) for f in added)}
        plain = simplest.aperture.with_features(*added).replace(**start_values)
        if "squeeze" in added and "squeeze" not in start_values:
            plain = _add_feature(plain, "squeeze", joint.fits, joint_discs)
        untouched = [dataclasses.replace(c, turned=False) for c in joint_crops]

        def plain_fit():
            return fit_discs(untouched, simplest, plain, noise=noise,
                             disc_starts=[crops[i].values_of(f) for i, f in zip(joint_ids, joint.fits)])

        # With no feature on, the plain circle has no parameter that changes its outline: no fit is
        # needed to measure how well it fits the outlines, only to take its place.
        trial = plain_fit() if added else None
        winner_misfits = _misfits(joint_discs, joint.aperture, joint.fits)
        plain_misfits = _misfits(joint_discs, *((trial.aperture, trial.fits) if trial else (plain, joint.fits)))
        shown = float(np.mean(plain_misfits > winner_misfits))
        switch = None
        if trial is not None and trial.bic <= joint.bic:
            switch = (f"with the {' and the '.join(added)} in the model, the {simplest.aperture.display_name} explains "
                      f"the discs better than the {winner.aperture.display_name} chosen without (ΔBIC {joint.bic - trial.bic:.0f})")
        elif (doubt := _unsupported(winner, [winner_fits[i] for i in kept])) is not None:
            switch = f"a {winner.aperture.display_name} does not hold on all {len(kept)} discs fitted: {doubt}"
        elif shown < OUTLINE_SUPPORT_SHARE:
            switch = (f"the {winner.aperture.display_name} that the discs' pixels favour fits the outlines of only "
                      f"{round(shown * len(joint_discs))} of {len(joint_discs)} discs better than the "
                      f"{simplest.aperture.display_name} (median misfit {np.median(winner_misfits):.3f} against "
                      f"{np.median(plain_misfits):.3f} of their radius): the outlines do not show its blades")
        if switch is not None:
            notes.append(switch)
            winner, joint, turned = simplest, trial if trial is not None else plain_fit(), [False] * len(turned)
            winner_screens = [found[winner] for found in screens_of]
            crops = [dataclasses.replace(c, turned=False) for c in crops]
    clock("plain")
    seen_aperture = joint.aperture
    # The discs left out of the joint fit (beyond JOINT_DISCS) are refitted with the joint aperture fixed.
    final = dict(zip(joint_ids, joint.fits))
    for i in kept[JOINT_DISCS:]:
        final[i] = fit_discs([crops[i]], winner, seen_aperture, free=(), disc_starts=[crops[i].values_of(winner_fits[i])]).fits[0]
    used_fits = [DiscFit(disc_fits[i].disc, disc_fits[i].screens, {**disc_fits[i].fits, winner.name: final[i]},
                         own=winner_fits[i], turned=turned[i]) for i in kept]
    clock("refit")

    best_bic = models[0].bic
    winner_model = _combine(winner, [final[i] for i in kept], [winner_screens[i] for i in kept])
    if winner_model.angle_deg is not None:  # every disc shares the joint aperture: its angle, not a mean of copies
        winner_model = dataclasses.replace(winner_model, angle_deg=joint.aperture.canonical_angle_deg)
    if seen_aperture.vignetting is not None:  # the outlines against the cut each disc shows, not the whole shape
        misfits = _misfits([disc_fits[i].disc for i in kept], seen_aperture, [final[i] for i in kept])
        winner_model = dataclasses.replace(winner_model, screen_rms=float(np.median(misfits)))
    models = [
        dataclasses.replace(winner_model if m.family is winner else m, bic=m.bic, delta_bic=m.bic - best_bic)
        for m in models
    ]
    models.sort(key=lambda m: (m.family is not winner, m.bic))
    # The runner-up is the best other shape (the winner straight or rounded is the same shape: its
    # roundness and that value's uncertainty say how round the blades are).
    runner_up = next((m for m in models[1:] if not models[0].same_answer(m)), None)
    margin = runner_up.bic - models[0].bic if runner_up is not None else math.inf
    selection_discs = min(len(disc_fits), model_discs)
    # Unsure only where the runner-up fits about as well; a nested model that
    # fits no better (a slit of aspect 1 against the square) loses by its penalty alone.
    runner_up_rss = (sum(item.fits[runner_up.family.name].rss for item in disc_fits[:selection_discs])
                     if runner_up is not None else math.inf)
    best_rss = sum(item.fits[winner.name].rss for item in disc_fits[:selection_discs])
    clear = margin >= options.sure_delta_bic_per_disc * selection_discs or runner_up_rss >= best_rss
    sure = clear and not notes
    # A runner-up the pixels rank above the winner was set aside by the consensus or the outlines
    # (a note says why): it is not a close runner-up.
    close = not clear and (margin >= 0 or not notes)
    best_fits = [final[i] for i in kept]
    # The size from the discs that show their whole profile where there are any: a saturated
    # disc's edge pixels above the clip read as lower bounds, so its size is known to about a pixel.
    sized = [f for f in best_fits if not f.censored] or best_fits
    diameters = np.array([f.diameter_px for f in sized])
    # The median's uncertainty: the spread between discs (over √n) with each fit's own.
    spread = 1.4826 * float(np.median(np.abs(diameters - np.median(diameters)))) / math.sqrt(len(diameters))
    own = float(np.median([f.uncertainty.get("diameter_px", 0.0) for f in sized]))
    spread = math.hypot(spread, own if math.isfinite(own) else 0.0)
    angle_uncertainty = winner_model.angle_uncertainty_deg
    if angle_uncertainty is not None and math.isfinite(joint.uncertainty.get("angle_deg", math.nan)):
        angle_uncertainty = math.hypot(angle_uncertainty, joint.uncertainty["angle_deg"])
    uncertainty = dict(joint.uncertainty)
    colours = None if rgb is None else measure_chromatic(rgb, [chosen[i] for i in kept], luminance.shape)
    if colours is not None and colours.significant:
        seen_aperture = seen_aperture.replace(chromatic=colours.chromatic)
        uncertainty.update(chromatic_red=colours.uncertainty.red, chromatic_blue=colours.uncertainty.blue)
    clock("chromatic")
    aperture = seen_aperture.near() if focus_side == "near" else seen_aperture
    seen_angle = seen_aperture.canonical_angle_deg
    edges = sum(chosen[i].evidence == "edge" for i in kept)
    described = aperture.display_name + ("" if aperture.aspect is None else f" (aspect {aperture.aspect:.2f})")
    if aperture.has_angle:
        described += f" at {aperture.canonical_angle_deg:.2f}°"
    features = [f"{name} (ΔBIC {gain:.0f})" for name, gain in feature_tests.items() if name in seen_aperture.enabled_features]
    message = (
        f"{described} from {len(kept)} discs"
        + (f" ({edges} by their edges: saturated or ringed)" if edges else "")
        + (f", {len(rejected)} left out as disagreeing" if rejected else "")
        + "; "
        + (f"ΔBIC {margin:.0f} over {runner_up.family.name}" if runner_up is not None else "one model tried")
        + (f"; with {', '.join(features)}" if features else "")
        + (f"; chromatic {colours.describe()}" if colours is not None and colours.significant else "")
        + "".join(f"; {note}" for note in notes)
        + ("" if sure or notes else " (unsure: the runner-up is close)")
    )
    return ApertureFit(
        message=message,
        aperture=aperture,
        seen_angle_deg=seen_angle,
        angle_uncertainty_deg=angle_uncertainty,
        diameter_px=float(np.median(diameters)),
        diameter_uncertainty_px=spread,
        blur_px=float(np.median([f.blur_px for f in best_fits])),
        focus_side=focus_side,
        candidates=models,
        disc_fits=used_fits,
        sure=sure,
        close_runner_up=close,
        options=options,
        time_s=time.perf_counter() - start,
        seen_aperture=seen_aperture,
        rejected={**set_aside, **rejected},
        feature_tests=feature_tests,
        feature_uncertainty=uncertainty,
        notes=tuple(notes),
        chromatic_measure=colours,
        timing_s=timing,
    )
