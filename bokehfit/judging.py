"""How sure a fit is: the stated thresholds of ``compare``'s verdict, and the doubts they raise.

:func:`judge` turns a fit's evidence (the runner-up's margin, the notes, the discs'
outlines, how many discs, their overlap with the kernel, their size and contrast) into
the doubts that make a result ``unsure`` and the reason that makes it ``no_fit``
(and, beside the thresholds, discs whose profile the model does not have: :func:`profiles_unexplained`);
:func:`short_doubts` says the same doubts in a few words each for the verdict's first
sentence. Both read the thresholds below, which the docs state.
"""

from __future__ import annotations

from bokehfit.apertures.features import MIN_RIM
from bokehfit.fit import REGULAR_OUTLINE_MISFIT, ApertureFit
from bokehfit.fit.features import FAINT_CONTRAST_REL, SMALL_DISC_PX, small_and_faint
from bokehfit.words import article

__all__ = [
    "FAINT_CONTRAST_REL",
    "MIN_ACCEPTABLE_IOU",
    "MIN_SURE_DISCS",
    "MIN_SURE_IOU",
    "SMALL_DISC_PX",
    "judge",
    "profiles_unexplained",
    "short_doubts",
]

#: A fit is acceptable when the discs match the kernel at least this well (median IoU) ...
MIN_ACCEPTABLE_IOU = 0.6
#: ... and sure when, besides a clear BIC margin, they match this well with at least MIN_SURE_DISCS discs.
MIN_SURE_IOU = 0.85
MIN_SURE_DISCS = 3
#: ... and the discs are not both small and faint (bokehfit.fit.features.small_and_faint: SMALL_DISC_PX and
#: FAINT_CONTRAST_REL, the fit's constants, read here).
# ... and the discs' outlines follow the shape: median radial misfit (in equal-area radii) at most
# bokehfit.fit.REGULAR_OUTLINE_MISFIT, the fit's "regular" outline (the fit's constant, read here).


def judge(fit: ApertureFit, metrics: dict[str, float | None]) -> tuple[list[str], str | None]:
    """Doubts about a fit, and the reason to reject it, from the evidence (stated thresholds)."""
    doubts = []
    if fit.close_runner_up:
        doubts.append(f"the runner-up ({fit.runner_up.family.aperture.display_name}) fits almost as well")
    doubts.extend(fit.notes)
    if fit.outline_misfit > REGULAR_OUTLINE_MISFIT:
        doubts.append(f"the discs' outlines are irregular (median misfit {fit.outline_misfit:.2f} of their radius to the "
                      f"best shape, {REGULAR_OUTLINE_MISFIT} for a sure fit): blobs that say little about the aperture")
    fitted, same_way = len(fit.disc_fits), _same_way_round(fit)
    if fitted < MIN_SURE_DISCS:
        doubts.append(f"only {fitted} disc{' was' if fitted == 1 else 's were'} clean enough to fit")
    elif same_way < MIN_SURE_DISCS:
        doubts.append(f"only {same_way} of the {fitted} discs fitted show the aperture the same way round"
                      " (the others turned by 180°, as discs before the focus plane do): too few to fix its angle")
    iou = metrics.get("iou")
    if iou is not None and iou < MIN_SURE_IOU:
        doubts.append(f"the discs match the kernel only loosely (median overlap IoU {iou:.2f}, {MIN_SURE_IOU} for a sure fit)")
    faint = _small_and_faint(fit)
    if faint:
        doubts.append(f"the discs are small and faint (median {faint[0]:.0f} px, {faint[1]:.0%} above their background;"
                      f" {SMALL_DISC_PX:.0f} px or {FAINT_CONTRAST_REL:.0%} for a sure fit): their outlines follow the"
                      " photo's tone curve, grain and compression as much as the aperture")
    unexplained = profiles_unexplained(fit)
    if unexplained:
        doubts.append(f"{unexplained} of the {fitted} discs fitted show a profile the model does not have (a ring's bright"
                      " rim or a bright centre) and the model has no rim: the discs disagree about the lens")
    rejection = None
    if iou is not None and iou < MIN_ACCEPTABLE_IOU:
        rejection = (
            f"the discs' outlines do not match even the best model ({fit.family.name}) "
            f"(median overlap IoU {iou:.2f}, at least {MIN_ACCEPTABLE_IOU} needed)"
        )
    return doubts, rejection


def _same_way_round(fit: ApertureFit) -> int:
    """How many of the fitted discs show the aperture as the majority does, not turned by 180°."""
    return sum(not item.turned for item in fit.disc_fits)


def _small_and_faint(fit: ApertureFit) -> tuple[float, float] | None:
    """:func:`~bokehfit.fit.features.small_and_faint` of the fitted discs."""
    return small_and_faint([item.disc for item in fit.disc_fits])


def profiles_unexplained(fit: ApertureFit) -> int:
    """How many of the fitted discs are rings (their centre a quarter of their contrast below their rim:
    ``bokehfit.discs.verdict.RING_DIP``) or have a bright centre, where the model has no rim that shows
    (``MIN_RIM``). Light spread evenly over the aperture makes neither. A lens's rim (§3b) is every disc's,
    a bright rim behind the focus and a bright centre before it (the near side turns its sign), so a
    model with a rim of either sign explains both; without one, such a disc and the model the other
    discs chose disagree about the lens."""
    if abs(fit.aperture.rim) >= MIN_RIM:  # 0 where the model has none
        return 0
    return sum(item.disc.profiled for item in fit.disc_fits)


def short_doubts(fit: ApertureFit, metrics: dict[str, float | None]) -> list[str]:
    """The doubts of :func:`judge` in a few words each, most telling first (for the verdict's first sentence)."""
    words = []
    if fit.close_runner_up:
        words.append(f"{article(fit.runner_up.family.aperture.display_name)} fits almost as well")
    fitted, same_way = len(fit.disc_fits), _same_way_round(fit)
    if fitted < MIN_SURE_DISCS:
        words.append(f"only {fitted} disc{' is' if fitted == 1 else 's are'} clean enough")
    elif same_way < MIN_SURE_DISCS:
        words.append(f"only {same_way} discs show it the same way round")
    if fit.outline_misfit > REGULAR_OUTLINE_MISFIT:
        words.append("the discs' outlines are irregular")
    iou = metrics.get("iou")
    if iou is not None and iou < MIN_SURE_IOU:
        words.append("the discs match it only loosely")
    if _small_and_faint(fit):
        words.append("the discs are small and faint")
    if profiles_unexplained(fit):
        words.append("some discs show a rim the model does not have")
    if fit.notes:
        words.append("a better-fitting shape was set aside (see the notes)")
    return words
