"""Fit one aperture to a photo's bokeh discs: shape family, angle, size, with model selection.

The steps (design.md §8, the simplest model the data supports):

1. **Discs.** Only discs clean enough to show their shape are used: resolvable
   (≥ 8 px) and neither saturated, cut by the frame nor overlapping another
   (those are left out, not down-weighted: their outlines are not the
   aperture's). At most ``MAX_FIT_DISCS``, the largest and clearest first.
2. **Screen.** Each disc's outline is compared with every family's radial
   signature (:mod:`bokehfit.fit.signature`); the ``SHORTLIST`` families with
   the lowest mean misfit, and always the circle, go on to the pixel fit.
3. **Fit.** Each shortlisted family is fitted to the pixels of the first
   ``MODEL_DISCS`` discs (:mod:`bokehfit.fit.pixels`).
4. **Select.** The family with the lowest total BIC over those discs wins
   (BIC = n·ln(RSS/n) + k·ln(n) per disc): a round disc is a circle, not a
   12-gon, because the 12-gon's extra parameters buy no lower residual.
   ``delta_bic`` of the runner-up says how sure the choice is.
5. **Consensus.** The winner is fitted to every chosen disc. The angle is the weighted circular mean of the discs'
   angles modulo the symmetry (weights 1/σ²); its uncertainty combines the
   spread between discs and each fit's own. The size is the median of the
   fitted equal-area diameters.

For shapes of odd symmetry a disc in front of the focus plane shows the
aperture turned by 180°, so the aperture's angle is either the angle seen
(lights behind the focus plane: ``focus_side="far"``) or that plus 180°.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from bokehfit.apertures import Aperture
from bokehfit.discs import Disc
from bokehfit.errors import InputError
from bokehfit.fit.families import FAMILIES, Family, families_for
from bokehfit.fit.pixels import PixelFit, fit_disc_pixels
from bokehfit.fit.signature import Screen, screen

__all__ = ["ApertureFit", "CandidateModel", "DiscFit", "fit_aperture", "FOCUS_SIDES", "MAX_FIT_DISCS", "SHORTLIST"]

FOCUS_SIDES = ("far", "near", "unknown")
#: Most discs fitted (the largest, clearest first).
MAX_FIT_DISCS = 12
#: Families fitted to pixels after the screen (the circle is always fitted too).
SHORTLIST = 3
#: Discs on which the shortlisted families compete (the winner is then fitted to all).
MODEL_DISCS = 4
#: Below this BIC margin per disc between the best and the runner-up the choice is reported as unsure.
SURE_DELTA_BIC_PER_DISC = 10.0


@dataclass(frozen=True)
class DiscFit:
    """One disc: its screen and its pixel fits, by family name."""

    disc: Disc
    screens: list[Screen]
    fits: dict[str, PixelFit]


@dataclass(frozen=True)
class CandidateModel:
    """One family's result over all the fitted discs."""

    family: Family
    bic: float
    delta_bic: float  #: above the best family's BIC (0 for the best)
    angle_deg: float | None
    angle_uncertainty_deg: float | None
    diameter_px: float
    screen_rms: float  #: mean outline misfit in equal-area radii

    def to_json(self) -> dict:
        return {
            "shape": self.family.shape,
            "blades": self.family.blades if self.family.shape == "ngon" else self.family.aperture().blades,
            "name": self.family.name,
            "angle_deg": None if self.angle_deg is None else round(self.angle_deg, 3),
            "score": round(-self.delta_bic, 2) + 0.0,
            "delta_bic": round(self.delta_bic, 2),
            "bic": round(self.bic, 2),
            "screen_rms": round(self.screen_rms, 5),
            "diameter_px": round(self.diameter_px, 3),
        }


@dataclass(frozen=True)
class ApertureFit:
    """The fitted aperture; falsy, with ``message``, when no disc could be fitted."""

    success: bool
    message: str
    aperture: Aperture | None = None
    angle_uncertainty_deg: float | None = None
    diameter_px: float | None = None
    diameter_uncertainty_px: float | None = None
    blur_px: float | None = None
    focus_side: str = "unknown"
    candidates: list[CandidateModel] = field(default_factory=list)
    disc_fits: list[DiscFit] = field(default_factory=list)
    sure: bool = False
    time_s: float = 0.0

    def __bool__(self) -> bool:
        return self.success

    @property
    def family(self) -> Family:
        return self.candidates[0].family

    def disc_fit(self, disc: Disc) -> PixelFit | None:
        """The winning family's fit of ``disc``, if it was fitted."""
        for item in self.disc_fits:
            if item.disc.index == disc.index:
                return item.fits.get(self.family.name)
        return None


def _order_for_fit(discs: list[Disc]) -> list[Disc]:
    usable = [d for d in discs if d.usable]
    usable.sort(key=lambda d: -d.diameter_px * min(d.snr, 50.0))
    return usable[:MAX_FIT_DISCS]


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


def _combine(family: Family, fits: list[PixelFit], screens: list[Screen]) -> CandidateModel:
    diameters = np.array([f.diameter_px for f in fits])
    angle = uncertainty = None
    symmetry = family.aperture().symmetry_deg
    if symmetry is not None:
        angles = np.array([f.angle_deg for f in fits])
        sigmas = np.array([f.uncertainty.get("angle_deg", np.nan) for f in fits])
        sigmas = np.where(np.isfinite(sigmas) & (sigmas > 0), sigmas, 1.0)
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
        screen_rms=float(np.mean([s.rms for s in screens])),
    )


def fit_aperture(
    luminance: np.ndarray,
    discs: list[Disc],
    *,
    shapes: list[str] | None = None,
    focus_side: str = "unknown",
    progress=None,
) -> ApertureFit:
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
    progress : callable, optional
        Called with (done, total) after each disc.
    """
    start = time.perf_counter()
    if focus_side not in FOCUS_SIDES:
        raise InputError(f"focus_side must be one of {', '.join(FOCUS_SIDES)} (got {focus_side!r})")
    families = families_for(shapes)
    chosen = _order_for_fit(discs)
    if not chosen:
        flagged = {
            "saturated": sum(d.saturated for d in discs),
            "cut by the frame": sum(d.clipped for d in discs),
            "overlapping": sum(d.overlaps for d in discs),
            "under 8 px": sum(not d.resolvable for d in discs),
        }
        why = ", ".join(f"{n} {what}" for what, n in flagged.items() if n)
        found = f"{len(discs)} found: {why}" if discs else "none found"
        return ApertureFit(False, f"no disc is clean enough to fit ({found})")

    screened = [screen(d.outline_xy, families, _slit_aspect(d)) for d in chosen]
    mean_rms = {f.name: np.mean([next(s.rms for s in disc_screens if s.family == f) for disc_screens in screened]) for f in families}
    shortlist = sorted(families, key=lambda f: mean_rms[f.name])[:SHORTLIST]
    if FAMILIES[0] in families and FAMILIES[0] not in shortlist:
        shortlist.append(FAMILIES[0])  # the simplest model is always a candidate

    # Model selection on the first MODEL_DISCS discs, then the winner on all of them.
    disc_fits = []
    for i, (disc, disc_screens) in enumerate(zip(chosen[:MODEL_DISCS], screened)):
        by_family = {s.family.name: s for s in disc_screens}
        fits = {
            f.name: fit_disc_pixels(luminance, disc, f, by_family[f.name].angle_deg, by_family[f.name].aspect)
            for f in shortlist
        }
        disc_fits.append(DiscFit(disc, disc_screens, fits))
        if progress is not None:
            progress(i + 1, len(chosen))
    models = [
        _combine(
            family,
            [item.fits[family.name] for item in disc_fits],
            [next(s for s in item.screens if s.family == family) for item in disc_fits],
        )
        for family in shortlist
    ]
    winner = min(models, key=lambda m: m.bic).family
    for i, (disc, disc_screens) in enumerate(zip(chosen[MODEL_DISCS:], screened[MODEL_DISCS:]), MODEL_DISCS):
        s = next(s for s in disc_screens if s.family == winner)
        disc_fits.append(DiscFit(disc, disc_screens, {winner.name: fit_disc_pixels(luminance, disc, winner, s.angle_deg, s.aspect)}))
        if progress is not None:
            progress(i + 1, len(chosen))
    winner_model = _combine(
        winner,
        [item.fits[winner.name] for item in disc_fits],
        [next(s for s in item.screens if s.family == winner) for item in disc_fits],
    )
    models.sort(key=lambda m: m.bic)
    best_bic = models[0].bic
    models = [
        CandidateModel(m.family, m.bic, m.bic - best_bic, m.angle_deg, m.angle_uncertainty_deg, m.diameter_px, m.screen_rms)
        for m in models
    ]
    margin = models[1].delta_bic if len(models) > 1 else math.inf
    selection_discs = min(len(disc_fits), MODEL_DISCS)
    # Unsure only where the runner-up fits about as well; a nested model that
    # fits no better (a slit of aspect 1 against the square) loses by its penalty alone.
    runner_up_rss = sum(item.fits[models[1].family.name].rss for item in disc_fits[:selection_discs]) if len(models) > 1 else math.inf
    best_rss = sum(item.fits[winner.name].rss for item in disc_fits[:selection_discs])
    sure = margin >= SURE_DELTA_BIC_PER_DISC * selection_discs or runner_up_rss >= best_rss
    best = winner_model
    best_fits = [item.fits[best.family.name] for item in disc_fits]
    diameters = np.array([f.diameter_px for f in best_fits])
    # The median's uncertainty: the spread between discs (over √n) with each fit's own.
    spread = 1.4826 * float(np.median(np.abs(diameters - np.median(diameters)))) / math.sqrt(len(diameters))
    own = float(np.median([f.uncertainty.get("diameter_px", 0.0) for f in best_fits]))
    spread = math.hypot(spread, own if math.isfinite(own) else 0.0)
    aspect = float(np.median([f.aspect for f in best_fits])) if best.family.shape == "slit" else None
    seen = best.angle_deg if best.angle_deg is not None else 0.0
    aperture_angle = seen + 180.0 if focus_side == "near" else seen
    aperture = best.family.aperture(aperture_angle, aspect)
    message = (
        f"{aperture.describe()} from {len(disc_fits)} discs; "
        + (f"ΔBIC {margin:.0f} over {models[1].family.name}" if len(models) > 1 else "one model tried")
        + ("" if sure else " (unsure: the runner-up is close)")
    )
    return ApertureFit(
        success=True,
        message=message,
        aperture=aperture,
        angle_uncertainty_deg=best.angle_uncertainty_deg,
        diameter_px=best.diameter_px,
        diameter_uncertainty_px=spread,
        blur_px=float(np.median([f.blur_px for f in best_fits])),
        focus_side=focus_side,
        candidates=models,
        disc_fits=disc_fits,
        sure=sure,
        time_s=time.perf_counter() - start,
    )
