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

import numpy as np

from bokehfit.apertures import Aperture
from bokehfit.discs import MIN_FIT_SEEN, Disc
from bokehfit.errors import InputError
from bokehfit.fit.agreement import combine, consensus_start, disagreeing, outline_misfits, turned_discs, unsupported
from bokehfit.fit.choice import REGULAR_OUTLINE_MISFIT, choose_discs, slit_aspect
from bokehfit.fit.chromatic import measure_chromatic
from bokehfit.fit.families import FAMILIES, Family, families_for
from bokehfit.fit.features import FEATURE_DELTA_BIC, MIN_RIM, add_feature, at_bound, features_to_test
from bokehfit.fit.pixels import crop_disc, fit_discs
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
from bokehfit.fit.signature import screen

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
#: A shape with more parameters than the circle is kept only where it fits the outlines of at least
#: this share of the jointly fitted discs better than the circle does (each against its joint fit):
#: blades are seen on the outlines, not in the light inside them or around them.
OUTLINE_SUPPORT_SHARE = 0.75
#: Most discs fitted jointly (the clearest first): the shared parameters are settled well before.
JOINT_DISCS = 8


def _fit_start(aperture: Aperture) -> Aperture:
    """The pixel fit's start from a screen's aperture: a rounded one a little off its straight bound."""
    if "roundness" in aperture.parameters:
        return aperture.replace(roundness=max(aperture.roundness, 0.05))
    return aperture


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
    chosen, set_aside = choose_discs(discs, FAMILIES, options.max_discs, models, np.shape(luminance))
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
    screened = [screen(d.outline_xy, screen_families, slit_aspect(d), d.outline_reliable, models) for d in chosen]
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
        combine(family, [item.fits[family.name] for item in disc_fits], [found[family] for found in screens_of[: len(disc_fits)]])
        for family in candidates
    ]
    models.sort(key=lambda m: m.bic)
    # The best model the discs support together: one aperture shows the same angle (and the same
    # elongation) on every disc; a shape whose angle each disc puts elsewhere is a misfit, not a lens.
    notes = []
    winner = models[0].family
    for model in models:
        doubt = unsupported(model.family, [item.fits[model.family.name] for item in disc_fits])
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
    turned = turned_discs(winner, winner_fits)
    outliers = disagreeing(winner, winner_fits, winner_screens, turned)
    rejected = {disc_fits[i].disc.index: reason for i, reason in outliers.items()}
    kept = [i for i in range(len(disc_fits)) if i not in outliers]

    # One aperture for the discs: a joint fit, then the §3b features the discs ask for.
    joint_ids = kept[:JOINT_DISCS]
    crops = [dataclasses.replace(crop, turned=t) for crop, t in zip(crops, turned)]
    joint_crops = [crops[i] for i in joint_ids]
    noise = [winner_fits[i].noise for i in joint_ids]
    disc_starts = [crops[i].values_of(winner_fits[i]) for i in joint_ids]
    aperture = consensus_start(winner, [winner_fits[i] for i in joint_ids], [turned[i] for i in joint_ids])
    joint = fit_discs(joint_crops, winner, aperture, noise=noise, disc_starts=disc_starts)
    clock("joint")
    feature_tests: dict[str, float] = {}
    joint_discs = [chosen[i] for i in joint_ids]
    tests = features_to_test([winner_fits[i] for i in joint_ids], joint_discs, [winner_screens[i] for i in joint_ids],
                           joint_crops)
    for feature in tests:
        trial = fit_discs(joint_crops, winner, add_feature(joint.aperture, feature, joint.fits, joint_discs), noise=noise,
                          disc_starts=[crops[i].values_of(f) for i, f in zip(joint_ids, joint.fits)])
        feature_tests[feature] = joint.bic - trial.bic
        visible = feature != "rim" or abs(trial.aperture.rim) >= MIN_RIM
        if feature_tests[feature] >= FEATURE_DELTA_BIC and visible and not at_bound(trial.aperture, feature):
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
            plain = add_feature(plain, "squeeze", joint.fits, joint_discs)
        untouched = [dataclasses.replace(c, turned=False) for c in joint_crops]

        def plain_fit():
            return fit_discs(untouched, simplest, plain, noise=noise,
                             disc_starts=[crops[i].values_of(f) for i, f in zip(joint_ids, joint.fits)])

        # With no feature on, the plain circle has no parameter that changes its outline: no fit is
        # needed to measure how well it fits the outlines, only to take its place.
        trial = plain_fit() if added else None
        winner_misfits = outline_misfits(joint_discs, joint.aperture, joint.fits)
        plain_misfits = outline_misfits(joint_discs, *((trial.aperture, trial.fits) if trial else (plain, joint.fits)))
        shown = float(np.mean(plain_misfits > winner_misfits))
        switch = None
        if trial is not None and trial.bic <= joint.bic:
            switch = (f"with the {' and the '.join(added)} in the model, the {simplest.aperture.display_name} explains "
                      f"the discs better than the {winner.aperture.display_name} chosen without (ΔBIC {joint.bic - trial.bic:.0f})")
        elif (doubt := unsupported(winner, [winner_fits[i] for i in kept])) is not None:
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
    winner_model = combine(winner, [final[i] for i in kept], [winner_screens[i] for i in kept])
    if winner_model.angle_deg is not None:  # every disc shares the joint aperture: its angle, not a mean of copies
        winner_model = dataclasses.replace(winner_model, angle_deg=joint.aperture.canonical_angle_deg)
    if seen_aperture.vignetting is not None:  # the outlines against the cut each disc shows, not the whole shape
        misfits = outline_misfits([disc_fits[i].disc for i in kept], seen_aperture, [final[i] for i in kept])
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
