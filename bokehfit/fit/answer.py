"""The stages of :func:`bokehfit.fit.fit_aperture` after the model: the answer read off it, each with its result.

10. :func:`refit_rest` → :class:`Refit`: every disc kept with the model's aperture.
11. :func:`rank_candidates`: the candidate table, the winner first with the consensus over every disc kept.
12. :func:`judge_margin` → :class:`Margin`: the runner-up, and whether the choice is sure.
13. :func:`measure_size` → :class:`Size`: the disc diameter with its uncertainty, and the edge blur.
14. :func:`measure_colours` → :class:`Colours`: the chromatic aberration (:mod:`bokehfit.fit.chromatic`).
15. :func:`aperture_fit`: the :class:`~bokehfit.fit.result.ApertureFit`, with its message.

The stages before, from the discs to the model, are in :mod:`bokehfit.fit.stages`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bokehfit.apertures import Aperture
from bokehfit.clock import Clock
from bokehfit.fit.agreement import combine, outline_misfits
from bokehfit.fit.chromatic import MIN_DISCS, ChromaticMeasure, measure_chromatic
from bokehfit.fit.pixels import JointFit, PixelFit, fit_discs
from bokehfit.fit.result import ApertureFit, CandidateModel, DiscFit, FitOptions
from bokehfit.fit.stages import JOINT_DISCS, Chosen, Consensus, Joint, Model, Selection
from bokehfit.words import counted

__all__ = ["Colours", "Margin", "Refit", "Size", "aperture_fit", "judge_margin", "measure_colours", "measure_size",
           "rank_candidates", "refit_rest"]


@dataclass(frozen=True)
class Refit:
    """Every disc kept, fitted with the model's aperture, and what the fit reports of each."""

    fits: list[PixelFit]  #: the discs kept, in order: the joint fit's, then the others refitted
    used: list[DiscFit]  #: the discs kept, each with all its fits and the winner's in the joint fit


def refit_rest(disc_fits: list[DiscFit], consensus: Consensus, joint: Joint, model: Model) -> Refit:
    """Stage 10: the discs kept beyond the joint fit's JOINT_DISCS refitted with the model's aperture fixed."""
    final = dict(zip(joint.ids, model.fit.fits))
    for i in consensus.kept[JOINT_DISCS:]:
        # Weighted by the disc's noise, as in the joint fit: the same optimum, and a refit that stalls stops.
        final[i] = fit_discs([model.crops[i]], model.winner, model.fit.aperture, free=(),
                             noise=[consensus.fits[i].noise],
                             disc_starts=[model.crops[i].values_of(consensus.fits[i])]).fits[0]
    used = [DiscFit(disc_fits[i].disc, disc_fits[i].screens, {**disc_fits[i].fits, model.winner.name: final[i]},
                    own=consensus.fits[i], turned=model.turned[i]) for i in consensus.kept]
    return Refit([final[i] for i in consensus.kept], used)


def rank_candidates(selection: Selection, consensus: Consensus, model: Model, refit: Refit) -> list[CandidateModel]:
    """Stage 11: the candidates by BIC above the best's on the model discs, the winner first.

    The winner's entry carries the consensus over every disc kept: the joint aperture's angle
    (every disc shares it: not a mean of copies), the median size, and the outlines' misfit
    (against the cut each disc shows where the model has vignetting, not the whole shape).
    """
    winner = model.winner
    best_bic = selection.models[0].bic
    winner_model = combine(winner, refit.fits, [model.screens[i] for i in consensus.kept])
    if winner_model.angle_deg is not None:
        winner_model = dataclasses.replace(winner_model, angle_deg=model.fit.aperture.canonical_angle_deg)
    if model.fit.aperture.vignetting is not None:
        misfits = outline_misfits([item.disc for item in refit.used], model.fit.aperture, refit.fits)
        winner_model = dataclasses.replace(winner_model, screen_rms=float(np.median(misfits)))
    models = [
        dataclasses.replace(winner_model if m.family is winner else m, bic=m.bic, delta_bic=m.bic - best_bic)
        for m in selection.models
    ]
    models.sort(key=lambda m: (m.family is not winner, m.bic))
    return models


@dataclass(frozen=True)
class Margin:
    """The runner-up (the best other shape), the winner's BIC margin over it, and how sure the choice is."""

    runner_up: CandidateModel | None
    margin: float  #: the runner-up's BIC above the winner's (inf where none)
    sure: bool
    close: bool  #: the runner-up fits about as well, and no note set it aside


def judge_margin(candidates: list[CandidateModel], disc_fits: list[DiscFit], model: Model,
                 options: FitOptions) -> Margin:
    """Stage 12: sure where the runner-up's BIC is FitOptions.sure_delta_bic_per_disc per model disc
    above the winner's, or it fits no better (a nested model, a slit of aspect 1 against the square,
    loses by its penalty alone), and no note set a model aside.

    The runner-up is the best other shape: the winner straight or rounded is the same shape, its
    roundness and that value's uncertainty say how round the blades are.
    """
    runner_up = next((m for m in candidates[1:] if not candidates[0].same_answer(m)), None)
    margin = runner_up.bic - candidates[0].bic if runner_up is not None else math.inf
    selection_discs = min(len(disc_fits), options.model_discs)
    runner_up_rss = (sum(item.fits[runner_up.family.name].rss for item in disc_fits[:selection_discs])
                     if runner_up is not None else math.inf)
    best_rss = sum(item.fits[model.winner.name].rss for item in disc_fits[:selection_discs])
    clear = margin >= options.sure_delta_bic_per_disc * selection_discs or runner_up_rss >= best_rss
    # A runner-up the pixels rank above the winner was set aside by the consensus or the outlines
    # (a note says why): it is not a close runner-up.
    return Margin(runner_up, margin, clear and not model.notes, not clear and (margin >= 0 or not model.notes))


@dataclass(frozen=True)
class Size:
    """The discs' equal-area diameter with its uncertainty, and their edge blur."""

    diameter_px: float
    uncertainty_px: float
    blur_px: float


def measure_size(refit: Refit) -> Size:
    """Stage 13: the median diameter of the discs that show their whole profile where there are any
    (a saturated disc's edge pixels above the clip read as lower bounds, so its size is known to
    about a pixel); its uncertainty the spread between discs (over √n) with each fit's own."""
    sized = [f for f in refit.fits if not f.censored] or refit.fits
    diameters = np.array([f.diameter_px for f in sized])
    spread = 1.4826 * float(np.median(np.abs(diameters - np.median(diameters)))) / math.sqrt(len(diameters))
    own = float(np.median([f.uncertainty.get("diameter_px", 0.0) for f in sized]))
    spread = math.hypot(spread, own if math.isfinite(own) else 0.0)
    return Size(float(np.median(diameters)), spread, float(np.median([f.blur_px for f in refit.fits])))


@dataclass(frozen=True)
class Colours:
    """The aperture as the discs show it, with the chromatic aberration where their colours show one."""

    seen_aperture: Aperture
    uncertainty: dict  #: one standard deviation of each shared aperture parameter, by name
    measure: ChromaticMeasure | None  #: what the discs' colours said (None: fewer than three measured, or no colour)
    not_measured: str | None = None  #: why the colours were not measured, where the photo's were given


def measure_colours(rgb: Callable[[slice, slice], np.ndarray] | None, chosen: Chosen, consensus: Consensus,
                    model: Model, shape: tuple[int, int]) -> Colours:
    """Stage 14: the discs kept measured in the photo's red, green and blue, where ``rgb`` is given;
    a significant chromatic aberration joins the aperture."""
    seen_aperture = model.fit.aperture
    uncertainty = dict(model.fit.uncertainty)
    colours = None if rgb is None else measure_chromatic(rgb, [chosen.discs[i] for i in consensus.kept], shape)
    if colours is not None and colours.significant:
        seen_aperture = seen_aperture.replace(chromatic=colours.chromatic)
        uncertainty.update(chromatic_red=colours.uncertainty.red, chromatic_blue=colours.uncertainty.blue)
    why, kept = None, len(consensus.kept)
    if rgb is not None and colours is None:
        why = (f"{counted(kept, 'disc')} kept ({MIN_DISCS} needed)" if kept < MIN_DISCS else
               f"fewer than {MIN_DISCS} of the {kept} discs kept are clean plateaus outlined in all three colours "
               "(saturated, ringed, soft-edged and partly seen discs are not measured)")
    return Colours(seen_aperture, uncertainty, colours, why)


def _angle_uncertainty(winner: CandidateModel, fit: JointFit) -> float | None:
    """The consensus angle's uncertainty with the joint fit's own."""
    uncertainty = winner.angle_uncertainty_deg
    if uncertainty is not None and math.isfinite(fit.uncertainty.get("angle_deg", math.nan)):
        uncertainty = math.hypot(uncertainty, fit.uncertainty["angle_deg"])
    return uncertainty


def _message(aperture: Aperture, chosen: Chosen, consensus: Consensus, joint: Joint, margin: Margin, colours: Colours,
             notes: tuple[str, ...]) -> str:
    """One line: the aperture, the discs it is from, the margin, the features and the notes."""
    kept, runner_up = consensus.kept, margin.runner_up
    edges = sum(chosen.discs[i].evidence == "edge" for i in kept)
    described = aperture.display_name + ("" if aperture.aspect is None else f" (aspect {aperture.aspect:.2f})")
    if aperture.has_angle:
        described += f" at {aperture.canonical_angle_deg:.2f}°"
    features = [f"{name} (ΔBIC {gain:.0f})" for name, gain in joint.gains.items()
                if name in colours.seen_aperture.enabled_features]
    measured = colours.measure
    return (
        f"{described} from {len(kept)} discs"
        + (f" ({edges} by their edges: saturated or ringed)" if edges else "")
        + (f", {len(consensus.rejected)} left out as disagreeing" if consensus.rejected else "")
        + "; "
        + (f"ΔBIC {margin.margin:.0f} over {runner_up.family.name}" if runner_up is not None else "one model tried")
        + (f"; with {', '.join(features)}" if features else "")
        + (f"; chromatic {measured.describe()}" if measured is not None and measured.significant else "")
        + "".join(f"; {note}" for note in notes)
        + ("" if margin.sure or notes else " (unsure: the runner-up is close)")
    )


def aperture_fit(*, focus_side: str, options: FitOptions, clock: Clock, chosen: Chosen, consensus: Consensus,
                 joint: Joint, model: Model, refit: Refit, candidates: list[CandidateModel], margin: Margin, size: Size,
                 colours: Colours) -> ApertureFit:
    """Stage 15: the fit's result from the stages' results; for ``focus_side="near"`` the aperture is
    turned from what the discs show (:meth:`~bokehfit.apertures.Aperture.near`)."""
    seen_aperture = colours.seen_aperture
    aperture = seen_aperture.near() if focus_side == "near" else seen_aperture
    return ApertureFit(
        message=_message(aperture, chosen, consensus, joint, margin, colours, model.notes),
        aperture=aperture,
        seen_angle_deg=seen_aperture.canonical_angle_deg,
        angle_uncertainty_deg=_angle_uncertainty(candidates[0], model.fit),
        diameter_px=size.diameter_px,
        diameter_uncertainty_px=size.uncertainty_px,
        blur_px=size.blur_px,
        focus_side=focus_side,
        candidates=candidates,
        disc_fits=refit.used,
        sure=margin.sure,
        close_runner_up=margin.close,
        options=options,
        time_s=clock.elapsed(),
        seen_aperture=seen_aperture,
        rejected={**chosen.set_aside, **consensus.rejected},
        feature_trials=joint.trials,
        features_not_tried=joint.not_tried + ((("chromatic", colours.not_measured),) if colours.not_measured else ()),
        feature_uncertainty=colours.uncertainty,
        notes=tuple(model.notes),
        chromatic_measure=colours.measure,
        timing_s=clock.timing,
    )
