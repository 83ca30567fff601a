"""Fit one aperture to a photo's bokeh discs: shape family, angle, size, with model selection.

The steps (design.md §8, the simplest model the data supports):

1. **Discs.** The discs that show their shape (:attr:`Disc.usable`): resolvable
   (≥ 8 px), not cut by the frame, and most of their outline their own.
   Saturated discs are fitted with their clipped pixels as lower bounds; discs
   that overlap others with the others' light left out, discs crossed by an
   occluder with its pixels left out (:mod:`bokehfit.fit.crop`). At most ``FitOptions.max_discs``: discs on
   their own first, then clean before saturated before partial, the largest and
   clearest first.
2. **Screen.** Each disc's outline is compared with every family's radial
   signature (:mod:`bokehfit.fit.signature`); the ``FitOptions.shortlist`` families with
   the lowest mean misfit, and always the circle, go on to the pixel fit, less those whose
   outline misfits every model disc far more than the best family's (out of the race:
   ``FitOptions.out_of_race_screen``).
3. **Fit.** Each shortlisted family is fitted to the pixels of the first
   ``FitOptions.model_discs`` discs (:mod:`bokehfit.fit.pixels`), to the tolerance that
   ranking them by BIC needs (``stages.TRIAL_TOLERANCE``); the winner's fits are then
   carried on to the fit's own.
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

:func:`fit_aperture` is the list of these steps as named stages, each a function
whose result (a small dataclass) the next ones take: :mod:`bokehfit.fit.stages`
from the discs to one model, :mod:`bokehfit.fit.answer` the answer read off it.

For shapes of odd symmetry a disc in front of the focus plane shows the
aperture turned by 180°, so the aperture's angle is either the angle seen
(lights behind the focus plane: ``focus_side="far"``) or that plus 180°.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from bokehfit.clock import Clock
from bokehfit.discs import Disc
from bokehfit.errors import InputError
from bokehfit.fit.answer import aperture_fit, judge_margin, measure_colours, measure_size, rank_candidates, refit_rest
from bokehfit.fit.choice import REGULAR_OUTLINE_MISFIT, no_disc_reason
from bokehfit.fit.families import families_for
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
from bokehfit.fit.stages import (
    check_simplest,
    choose,
    find_consensus,
    fit_families,
    fit_joint,
    fit_winner,
    screen_discs,
    select_model,
    try_features,
)

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


def _checked_options(luminance: np.ndarray, focus_side: str, options: FitOptions | None,
                     clipped: np.ndarray | None) -> FitOptions:
    """The fit's options (``FitOptions()`` where None), once the arguments are checked."""
    if focus_side not in FOCUS_SIDES:
        raise InputError(f"focus_side must be one of {', '.join(FOCUS_SIDES)} (got {focus_side!r})")
    options = FitOptions() if options is None else options
    if not isinstance(options, FitOptions):
        raise InputError(f"options must be a FitOptions (got {type(options).__name__})")
    if clipped is not None and np.shape(clipped) != np.shape(luminance):
        raise InputError(f"clipped must have the luminance's shape {np.shape(luminance)} (got {np.shape(clipped)})")
    return options


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
    clock = Clock()
    options = _checked_options(luminance, focus_side, options, clipped)
    families = families_for(shapes)
    chosen = choose(discs, options, np.shape(luminance))
    clock("choose")
    if not chosen.discs:
        return FailedFit("no_discs", no_disc_reason(discs, chosen.set_aside), time_s=clock.elapsed(),
                         rejected=chosen.set_aside, timing_s=clock.timing)
    screened = screen_discs(luminance, clipped, discs, chosen, families, options)
    clock("screen")
    # Model selection on the first model_discs discs, then the winner on all of them.
    trials = fit_families(chosen, screened, options, progress, clock)
    selection = select_model(trials, screened)
    disc_fits = fit_winner(chosen, screened, trials, selection.winner, options, progress)
    clock("winner")
    # One aperture for the discs that agree: a joint fit, then the §3b features the discs ask for.
    consensus = find_consensus(disc_fits, screened, selection.winner)
    joint = fit_joint(chosen, screened, consensus, selection.winner)
    clock("joint")
    joint = try_features(joint, consensus, selection.winner)
    clock("features")
    model = check_simplest(families, screened, selection, consensus, joint)
    clock("plain")
    refit = refit_rest(disc_fits, consensus, joint, model)
    clock("refit")
    candidates = rank_candidates(selection, consensus, model, refit)
    margin = judge_margin(candidates, disc_fits, model, options)
    size = measure_size(refit)
    colours = measure_colours(rgb, chosen, consensus, model, luminance.shape)
    clock("chromatic")
    return aperture_fit(focus_side=focus_side, options=options, clock=clock, chosen=chosen, consensus=consensus,
                        joint=joint, model=model, refit=refit, candidates=candidates, margin=margin, size=size,
                        colours=colours)
