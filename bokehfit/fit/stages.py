"""The stages of :func:`bokehfit.fit.fit_aperture` from the discs to one model, each with its result.

Each stage is a function that takes the results of the stages before it and returns its own, a
small frozen dataclass (or the :class:`~bokehfit.fit.result.DiscFit` list of the pixel fits):

1. :func:`choose` → :class:`Chosen`: the discs fitted and those set aside (:mod:`bokehfit.fit.choice`).
2. :func:`screen_discs` → :class:`Screened`: each disc's crop and outline screens, the families shortlisted.
3. :func:`fit_families`: each shortlisted family fitted to the model discs.
4. :func:`select_model` → :class:`Selection`: the candidates by BIC, the best the discs support together.
5. :func:`fit_winner`: the winner fitted to the other discs.
6. :func:`find_consensus` → :class:`Consensus`: the turned discs and those left out as disagreeing.
7. :func:`fit_joint` → :class:`Joint`: one aperture fitted to the discs kept.
8. :func:`try_features` → :class:`Joint`: the §3b features the discs ask for (:mod:`bokehfit.fit.features`).
9. :func:`check_simplest` → :class:`Model`: the winner or, where the outlines do not show its blades, the circle.

The stages after the model (the answer read off it) are in :mod:`bokehfit.fit.answer`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bokehfit.apertures import FEATURE_SPECS, Aperture
from bokehfit.clock import Clock
from bokehfit.discs import Disc
from bokehfit.fit.agreement import combine, consensus_start, disagreeing, outline_misfits, turned_discs, unsupported
from bokehfit.fit.choice import choose_discs, slit_aspect
from bokehfit.fit.families import FAMILIES, Family
from bokehfit.fit.features import FeatureTrial, add_feature, feature_asks
from bokehfit.fit.crop import DiscCrop, crop_disc
from bokehfit.fit.pixels import TOLERANCE, JointFit, PixelFit, fit_discs
from bokehfit.fit.result import CandidateModel, DiscFit, FitOptions
from bokehfit.fit.signature import Screen, screen

__all__ = [
    "Chosen", "Consensus", "Joint", "Model", "Screened", "Selection",
    "check_simplest", "choose", "find_consensus", "fit_families", "fit_joint", "fit_winner", "screen_discs",
    "select_model", "try_features", "JOINT_DISCS", "OUTLINE_SUPPORT_SHARE", "OUTLINE_DEPARTURE_RATIO",
]

#: A rounded family is fitted where its screen misfit is under this share of the straight one's and the
#: circle's on some disc ...
ROUNDER_SCREEN = 0.95
#: ... of at least this diameter (px): a smaller disc cannot show how round its blades are.
ROUNDNESS_MIN_DIAMETER_PX = 16.0
#: A shape with more parameters than the circle is kept only where it fits the outlines of at least
#: this share of the jointly fitted discs better than the circle does (each against its joint fit):
#: blades are seen on the outlines, not in the light inside them or around them.
OUTLINE_SUPPORT_SHARE = 0.75
#: ... and only where it departs from the circle by more than the outlines' own irregularity: an outline's
#: misfit to the circle is the shape's departure from it and the outline's irregularity added in quadrature,
#: its misfit to the shape the irregularity alone, so the departure exceeds the irregularity where the
#: shape's misfit is under 1/√2 of the circle's (the median over the discs). Blades a disc's outline wanders
#: from by as much as they depart from a circle are not seen on it (independent renders of 3 to 12 blades,
#: rounded up to 0.8: 0.06–0.50).
OUTLINE_DEPARTURE_RATIO = 1.0 / math.sqrt(2.0)
#: Most discs fitted jointly (the clearest first): the shared parameters are settled well before.
JOINT_DISCS = 8
#: A family's trial fit on a model disc (stage 3) stops where a step changes its cost or parameters by
#: less than this share (scipy's ftol and xtol): the trials only rank the families, by BIC =
#: n·ln(RSS/n) + k·ln(n), which a relative change δ of the cost moves by n·δ, at most
#: crop.MAX_FIT_SIDE² · 1e-4 = 0.13 on a crop (the choices it makes are 10 or more apart). A family whose
#: shape the disc does not show (a hexagon on a round disc, its angle free to turn) otherwise crawls
#: along the flat valley of its angle for a hundred steps, each a millionth better. The winner's
#: trials are then carried on to the fit's own tolerance (:func:`fit_winner`).
TRIAL_TOLERANCE = 1e-4


@dataclass(frozen=True)
class Chosen:
    """The discs fitted, the clearest first, and those set aside (index → reason)."""

    discs: list[Disc]
    set_aside: dict[int, str]
    signatures: dict  #: the model signatures the outline screens made, kept for the next screens


def choose(discs: list[Disc], options: FitOptions, shape: tuple[int, int]) -> Chosen:
    """Stage 1: the discs whose outlines an aperture explains (:func:`~bokehfit.fit.choice.choose_discs`).

    Whether a blob is an aperture's image does not hang on the shapes the caller lets the fit try:
    every family screens it.
    """
    signatures: dict = {}
    fitted, set_aside = choose_discs(discs, FAMILIES, options.max_discs, signatures, shape)
    return Chosen(fitted, set_aside, signatures)


@dataclass(frozen=True)
class Screened:
    """Each chosen disc's crop and outline screens, and the families its pixels are fitted with."""

    crops: list[DiscCrop]
    screens: list[list[Screen]]  #: by disc, every family screened
    by_family: list[dict[Family, Screen]]  #: the same screens by disc, by family
    candidates: list[Family]  #: the shortlisted families, each straight and, where its outlines look rounder, rounded

    @property
    def trial_tolerance(self) -> float:
        """The tolerance of the families' fits on the model discs (stage 3): TRIAL_TOLERANCE where they
        rank several candidates; the fit's own where one candidate is left, which has no rank to win
        and is the winner already (its fits then need no carrying on: :func:`fit_winner`)."""
        return TRIAL_TOLERANCE if len(self.candidates) > 1 else TOLERANCE


def _shortlist(families: tuple[Family, ...], rounded_of: dict[Family, Family], by_family: list[dict[Family, Screen]],
               size: int) -> list[Family]:
    """The ``size`` families whose outlines (straight or rounded) misfit the discs' least on average, and the circle."""
    mean_rms = {f: np.mean([found[f].rms for found in by_family]) for f in (*families, *rounded_of.values())}
    best_rms = {f: min(mean_rms[f], mean_rms[rounded_of[f]]) if f in rounded_of else mean_rms[f] for f in families}
    shortlist = sorted(families, key=lambda f: best_rms[f])[:size]
    if FAMILIES[0] in families and FAMILIES[0] not in shortlist:
        shortlist.append(FAMILIES[0])  # the simplest model is always a candidate
    return shortlist


def _looks_rounder(family: Family, rounded: Family, discs: list[Disc], by_family: list[dict[Family, Screen]]) -> bool:
    """Whether the screen finds the outline rounder than ``family``'s straight blades, and less round than
    the circle (where the circle is screened), on some of ``discs`` large enough to show it
    (ROUNDER_SCREEN, ROUNDNESS_MIN_DIAMETER_PX). Blades rounded all the way are the circle: an outline
    the circle fits as well as any rounding of the blades shows no blades to round, and a round disc
    needs no blade count (its rounded trials ran their roundness to the bound, the circle by another
    name, and stood as the runner-up that made a round answer look unsure)."""
    def rounder(found: dict[Family, Screen]) -> bool:
        others = [found[f].rms for f in (family, FAMILIES[0]) if f in found]
        return found[rounded].rms < ROUNDER_SCREEN * min(others)

    return any(rounder(found) for disc, found in zip(discs, by_family) if disc.diameter_px >= ROUNDNESS_MIN_DIAMETER_PX)


def screen_discs(luminance: np.ndarray, clipped: np.ndarray | None, discs: list[Disc], chosen: Chosen,
                 families: tuple[Family, ...], options: FitOptions) -> Screened:
    """Stage 2: crop the chosen discs, screen their outlines and shortlist the families to fit.

    Every family is screened straight and, where it has blades, rounded (design.md §3b): a rounded
    7-gon looks more like a 12-gon than a 7-gon to a straight-only screen. Each shortlisted n-gon
    is fitted straight and, where the screen finds its outline rounder than the straight blades on
    some of the discs that choose the model, with its roundness free: a straight polygon and the
    circle are the ends, the BIC says whether the discs need it. ``discs`` are all the photo's
    discs (their light is left out of each other's crops).
    """
    crops = [crop_disc(luminance, d, clipped, discs) for d in chosen.discs]
    rounded_of = {f: f.rounded for f in families if f.rounded is not None}
    screen_families = (*families, *rounded_of.values())
    screens = [screen(d.outline_xy, screen_families, slit_aspect(d), d.outline_reliable, chosen.signatures)
               for d in chosen.discs]
    by_family = [{s.family: s for s in disc_screens} for disc_screens in screens]
    shortlist = _shortlist(families, rounded_of, by_family, options.shortlist)
    model_discs = chosen.discs[: options.model_discs]
    candidates = []
    for rank, family in enumerate(shortlist):
        tried = [family]
        if family in rounded_of and _looks_rounder(family, rounded_of[family], model_discs, by_family):
            tried.append(rounded_of[family])
        # The best on average always runs (the circle too, where it is among the shapes).
        if rank == 0 or not _out_of_race(tried, by_family[: len(model_discs)], options.out_of_race_screen):
            candidates += tried
    return Screened(crops, screens, by_family, candidates)


def _out_of_race(tried: list[Family], by_family: list[dict[Family, Screen]], ratio: float) -> bool:
    """Whether a family, as it would be tried (straight, and rounded where it looks rounder), misfits the
    outline of every model disc more than ``ratio`` (``FitOptions.out_of_race_screen``) times the best
    family there. The best of those that are not elongated, where there are any: an elongated aperture
    must be seen on several discs, and a streak's outline is a slit's. The circle is never out of the race.

    The outline screen is the pixel fit's misfit seen along the edge, where the shape is. A family three
    times further than another from every disc's outline is no lens the discs show: on the independent
    renders and the reference photos every such family trailed the winner by a BIC of hundreds or
    thousands (a 12-gon on round discs: the circle's parameters, and the blades' angle free to no use),
    yet its fit cost as much as a contender's (a third of the fit of a survey of round discs)."""
    if FAMILIES[0] in tried or not by_family:
        return False
    for found in by_family:
        plain = [s.rms for f, s in found.items() if not f.aperture.has_aspect]
        best = min(plain or [s.rms for s in found.values()])
        if min(found[f].rms for f in tried) <= ratio * best:
            return False
    return True


def _fit_start(aperture: Aperture) -> Aperture:
    """The pixel fit's start from a screen's aperture: a rounded one a little off its straight bound."""
    if aperture.has_roundness:
        return aperture.replace(roundness=max(aperture.roundness, 0.05))
    return aperture


def fit_families(chosen: Chosen, screened: Screened, options: FitOptions,
                 progress: Callable[[int, int], None] | None, clock: Clock) -> list[DiscFit]:
    """Stage 3: each candidate family fitted alone to each of the first ``options.model_discs`` discs
    (timed by family), from its screen's aperture, to ``screened.trial_tolerance``."""
    trials = []
    for i, (disc, crop, disc_screens, found) in enumerate(
        zip(chosen.discs[: options.model_discs], screened.crops, screened.screens, screened.by_family)
    ):
        fits = {}
        for g in screened.candidates:
            fits[g.name] = fit_discs([crop], g, _fit_start(found[g].aperture), tolerance=screened.trial_tolerance).fits[0]
            clock(f"family {g.name}")
        trials.append(DiscFit(disc, disc_screens, fits))
        if progress is not None:
            progress(i + 1, len(chosen.discs))
    return trials


@dataclass(frozen=True)
class Selection:
    """The candidates' models over the model discs by BIC, and the winner: the best the discs support together."""

    models: list[CandidateModel]  #: best BIC first
    winner: Family
    notes: tuple[str, ...]  #: the better models set aside, and why


def select_model(trials: list[DiscFit], screened: Screened) -> Selection:
    """Stage 4: the candidate with the lowest BIC that the discs support together.

    One aperture shows the same angle (and the same elongation) on every disc; a shape whose angle
    each disc puts elsewhere is a misfit, not a lens (:func:`~bokehfit.fit.agreement.unsupported`).
    """
    models = [
        combine(family, [item.fits[family.name] for item in trials],
                [found[family] for found in screened.by_family[: len(trials)]])
        for family in screened.candidates
    ]
    models.sort(key=lambda m: m.bic)
    notes = []
    winner = models[0].family
    for model in models:
        doubt = unsupported(model.family, [item.fits[model.family.name] for item in trials])
        if doubt is None:
            winner = model.family
            break
        if not notes or model is models[0]:
            notes.append(f"not a {model.family.aperture.display_name}: {doubt}")
    return Selection(models, winner, tuple(notes))


def fit_winner(chosen: Chosen, screened: Screened, trials: list[DiscFit], winner: Family, options: FitOptions,
               progress: Callable[[int, int], None] | None) -> list[DiscFit]:
    """Stage 5: every chosen disc's fits: ``trials``, the winner's carried on from where its trial stopped
    (TRIAL_TOLERANCE) to the fit's own tolerance where the trials ranked several candidates, then the
    winner alone on each disc after the model discs."""
    if screened.trial_tolerance < TRIAL_TOLERANCE:  # the trials were fitted to the fit's own tolerance
        disc_fits = list(trials)
    else:
        disc_fits = [
            dataclasses.replace(item, fits={**item.fits, winner.name: _carried_on(crop, winner, item.fits[winner.name])})
            for item, crop in zip(trials, screened.crops)
        ]
    start = options.model_discs
    for i, (disc, crop, disc_screens, found) in enumerate(
        zip(chosen.discs[start:], screened.crops[start:], screened.screens[start:], screened.by_family[start:]), start
    ):
        fitted = fit_discs([crop], winner, _fit_start(found[winner].aperture)).fits[0]
        disc_fits.append(DiscFit(disc, disc_screens, {winner.name: fitted}))
        if progress is not None:
            progress(i + 1, len(chosen.discs))
    return disc_fits


def _carried_on(crop: DiscCrop, family: Family, trial: PixelFit) -> PixelFit:
    """``family``'s trial fit of a disc carried on to the fit's own tolerance, from where it stopped."""
    return fit_discs([crop], family, trial.aperture, disc_starts=[crop.values_of(trial)]).fits[0]


@dataclass(frozen=True)
class Consensus:
    """The winner on each disc alone, the discs turned by 180°, and those the others' consensus does not share."""

    fits: list[PixelFit]  #: the winner fitted to each disc alone, by position in the disc fits
    screens: list[Screen]  #: the winner's screen of each disc
    turned: list[bool]  #: the discs that show the aperture turned by 180° (before the focus plane)
    rejected: dict[int, str]  #: disc index → why it is left out
    kept: list[int]  #: positions of the discs kept, in order


def find_consensus(disc_fits: list[DiscFit], screened: Screened, winner: Family) -> Consensus:
    """Stage 6: discs whose shape or angle the others do not share are left out, with the reason."""
    fits = [item.fits[winner.name] for item in disc_fits]
    screens = [found[winner] for found in screened.by_family]
    turned = turned_discs(winner, fits)
    outliers = disagreeing(winner, fits, screens, turned)
    rejected = {disc_fits[i].disc.index: reason for i, reason in outliers.items()}
    kept = [i for i in range(len(disc_fits)) if i not in outliers]
    return Consensus(fits, screens, turned, rejected, kept)


@dataclass(frozen=True)
class Joint:
    """One aperture fitted to the first JOINT_DISCS discs kept, and the §3b features tried on it."""

    ids: list[int]  #: positions of the jointly fitted discs
    crops: list[DiscCrop]  #: every chosen disc's crop, turned where it shows the aperture turned
    discs: list[Disc]  #: the jointly fitted discs
    noise: list[float]  #: each jointly fitted disc's noise level (from its own fit)
    fit: JointFit
    trials: tuple[FeatureTrial, ...] = ()  #: each feature tried, what it gained and whether it was kept
    not_tried: tuple[tuple[str, str], ...] = ()  #: each feature the discs did not ask for, and why

    @property
    def tests(self) -> tuple[str, ...]:
        """The features tried (those the discs asked for: :func:`~bokehfit.fit.features.feature_asks`)."""
        return tuple(trial.feature for trial in self.trials)

    @property
    def gains(self) -> dict[str, float]:
        """Each feature tried → the BIC it gained."""
        return {trial.feature: trial.gain for trial in self.trials}

    @property
    def joint_crops(self) -> list[DiscCrop]:
        return [self.crops[i] for i in self.ids]

    def disc_starts(self) -> list[dict[str, float]]:
        """Each jointly fitted disc's values in the joint fit, to start the next fit from."""
        return [self.crops[i].values_of(f) for i, f in zip(self.ids, self.fit.fits)]


def fit_joint(chosen: Chosen, screened: Screened, consensus: Consensus, winner: Family) -> Joint:
    """Stage 7: the winner fitted jointly to the first JOINT_DISCS discs kept (one aperture, each
    disc its own centre, size, blur and levels), from the discs' consensus."""
    ids = consensus.kept[:JOINT_DISCS]
    fits = consensus.fits
    crops = [dataclasses.replace(crop, turned=t) for crop, t in zip(screened.crops, consensus.turned)]
    joint_crops = [crops[i] for i in ids]
    noise = [fits[i].noise for i in ids]
    disc_starts = [crops[i].values_of(fits[i]) for i in ids]
    aperture = consensus_start(winner, [fits[i] for i in ids], [consensus.turned[i] for i in ids])
    fit = fit_discs(joint_crops, winner, aperture, noise=noise, disc_starts=disc_starts)
    return Joint(ids, crops, [chosen.discs[i] for i in ids], noise, fit)


def try_features(joint: Joint, consensus: Consensus, winner: Family) -> Joint:
    """Stage 8: the §3b features the discs ask for, each tried on the joint fit and kept where it
    gains FEATURE_DELTA_BIC, with any one disc left out too (every disc's, not one disc's quirk), shows
    (its record's least visible value: a rim of at least MIN_RIM) and is not at its bound; one not kept is tried
    once more after another joins, with it in the model; those not asked for are kept with the reason."""
    ids = joint.ids
    asks = feature_asks([consensus.fits[i] for i in ids], joint.discs, [consensus.screens[i] for i in ids],
                        joint.joint_crops)
    trials: list[FeatureTrial] = []
    best = joint
    queue = [(feature, None) for feature, (asked, _) in asks.items() if asked]
    while queue:
        feature, first = queue.pop(0)
        start = add_feature(best.fit.aperture, feature, best.fit.fits, joint.discs)
        fit = fit_discs(joint.joint_crops, winner, start, noise=joint.noise, disc_starts=best.disc_starts())
        # A second trial is tried with the features kept since its first: those after it in the trials' order.
        since = [] if first is None else [t.feature for t in trials[trials.index(first) + 1:] if t.kept]
        trial = FeatureTrial.of(feature, best.fit, fit, joint.noise, joint.discs, asks[feature][1], first, since)
        trials = [t for t in trials if t.feature != feature] + [trial]
        if trial.kept:
            best = dataclasses.replace(best, fit=fit)
            # A feature not kept before this one joined may have been masked by what this one explains (a cat-eye's
            # cut misfit as a rim's light): each is tried once more, with it in the model.
            queued = {name for name, _ in queue}
            queue += [(t.feature, t) for t in trials if not (t.kept or t.is_second or t.feature in queued)]
    not_tried = tuple((feature, why) for feature, (asked, why) in asks.items() if not asked)
    return dataclasses.replace(best, trials=tuple(trials), not_tried=not_tried)


@dataclass(frozen=True)
class Model:
    """The model the answer is read from: the winning family, its joint fit, and how the discs show it."""

    winner: Family
    fit: JointFit
    turned: list[bool]  #: by disc position, as in :class:`Consensus`
    screens: list[Screen]  #: the winner's screen of each disc
    crops: list[DiscCrop]  #: each disc's crop, turned as the winner sees it
    notes: tuple[str, ...]  #: models set aside and why


def _features_added(joint: Joint, winner: Family) -> list[str]:
    """The features in the joint fit, and those tried on a shape whose own aspect took them (a squeeze
    on a slit: its record's ``taken_by_aspect``)."""
    added = [f for f in joint.gains if f in joint.fit.aperture.enabled_features]
    if winner.aperture.has_aspect:
        added += [f for f in joint.tests if FEATURE_SPECS[f].taken_by_aspect and f not in added]
    return added


def _plain_start(simplest: Family, added: list[str], joint: Joint) -> Aperture:
    """The simplest model with the features added, at the joint fit's values of them (a feature the
    joint fit does not have, from the discs' evidence, as when it was tried)."""
    specs = [FEATURE_SPECS[f] for f in added]
    start_values = {n: v for n, v in joint.fit.aperture.values.items() if any(n in s.parameters for s in specs)}
    plain = simplest.aperture.with_features(*added).replace(**start_values)
    for spec in specs:
        if not any(n in start_values for n in spec.parameters):
            plain = add_feature(plain, spec.name, joint.fit.fits, joint.discs)
    return plain


def _fit_plain(simplest: Family, plain: Aperture, joint: Joint) -> JointFit:
    """The simplest model fitted jointly to the same discs, none of them turned."""
    untouched = [dataclasses.replace(c, turned=False) for c in joint.joint_crops]
    return fit_discs(untouched, simplest, plain, noise=joint.noise, disc_starts=joint.disc_starts())


def _switch_reason(simplest: Family, winner: Family, added: list[str], plain: Aperture, trial: JointFit | None,
                   joint: Joint, consensus: Consensus) -> str | None:
    """Why the simplest model replaces the winner, or None where the winner holds.

    With a feature on (``trial``: the simplest model with it), the simplest may explain the discs
    better. Otherwise the winner, chosen on the first model discs, must show one angle (and one
    elongation) on all the discs kept, and fit at least OUTLINE_SUPPORT_SHARE of their outlines
    better than the simplest does, each against its jointly fitted aperture, and depart from the
    simplest by more than the outlines wander (OUTLINE_DEPARTURE_RATIO). With no feature on,
    the plain circle has no parameter that changes its outline: no fit is needed to measure how
    well it fits the outlines.
    """
    winner_misfits = outline_misfits(joint.discs, joint.fit.aperture, joint.fit.fits)
    plain_misfits = outline_misfits(joint.discs, *((trial.aperture, trial.fits) if trial else (plain, joint.fit.fits)))
    shown = float(np.mean(plain_misfits > winner_misfits))
    if trial is not None and trial.bic <= joint.fit.bic:
        return (f"with the {' and the '.join(added)} in the model, the {simplest.aperture.display_name} explains "
                f"the discs better than the {winner.aperture.display_name} chosen without "
                f"(ΔBIC {joint.fit.bic - trial.bic:.0f})")
    if (doubt := unsupported(winner, [consensus.fits[i] for i in consensus.kept])) is not None:
        return f"a {winner.aperture.display_name} does not hold on all {len(consensus.kept)} discs fitted: {doubt}"
    if shown < OUTLINE_SUPPORT_SHARE:
        return (f"the {winner.aperture.display_name} that the discs' pixels favour fits the outlines of only "
                f"{round(shown * len(joint.discs))} of {len(joint.discs)} discs better than the "
                f"{simplest.aperture.display_name} (median misfit {np.median(winner_misfits):.3f} against "
                f"{np.median(plain_misfits):.3f} of their radius): the outlines do not show its blades")
    departure = float(np.median(winner_misfits / np.maximum(plain_misfits, 1e-12)))
    if departure > OUTLINE_DEPARTURE_RATIO:
        return (f"the {winner.aperture.display_name} that the discs' pixels favour departs from the "
                f"{simplest.aperture.display_name} by less than the discs' outlines wander (its misfit "
                f"{departure:.2f} of the {simplest.aperture.display_name}'s, the median over {len(joint.discs)} discs; "
                f"at most {OUTLINE_DEPARTURE_RATIO:.2f} where the blades show): the outlines do not show its blades")
    return None


def check_simplest(families: tuple[Family, ...], screened: Screened, selection: Selection, consensus: Consensus,
                   joint: Joint) -> Model:
    """Stage 9: the winner, or the simplest model (the circle) where the discs do not show the winner.

    With a feature on, the shape is chosen again between the winner and the simplest model: a
    cat-eye cut makes round discs look like a rounded triangle until the cut is in the model, and
    an anamorphic squeeze makes them look like a slit (whose own aspect takes the squeeze). Blades
    and their angle are seen on every disc: where the outlines do not show them, the pixels chose
    the winner for something else (the surround, the light inside) (:func:`_switch_reason`).
    """
    winner = selection.winner
    held = Model(winner, joint.fit, consensus.turned, consensus.screens, joint.crops, selection.notes)
    simplest = FAMILIES[0]
    if simplest not in families or winner.base == simplest:
        return held
    added = _features_added(joint, winner)
    plain = _plain_start(simplest, added, joint)
    trial = _fit_plain(simplest, plain, joint) if added else None
    switch = _switch_reason(simplest, winner, added, plain, trial, joint, consensus)
    if switch is None:
        return held
    fit = trial if trial is not None else _fit_plain(simplest, plain, joint)
    return Model(simplest, fit, [False] * len(consensus.turned), [found[simplest] for found in screened.by_family],
                 [dataclasses.replace(c, turned=False) for c in joint.crops], (*selection.notes, switch))
