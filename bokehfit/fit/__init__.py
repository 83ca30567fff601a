"""Fit one aperture to a photo's bokeh discs: shape family, angle, size, with model selection.

The steps (design.md §8, the simplest model the data supports):

1. **Discs.** Only discs clean enough to show their shape are used: resolvable
   (≥ 8 px) and neither saturated, cut by the frame nor overlapping another
   (those are left out, not down-weighted: their outlines are not the
   aperture's). At most ``FitOptions.max_discs``, the largest and clearest first.
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
from dataclasses import dataclass

import cv2
import numpy as np

from bokehfit.apertures import Aperture
from bokehfit.discs import Disc
from bokehfit.errors import InputError
from bokehfit.fit.families import FAMILIES, Family, families_for
from bokehfit.fit.pixels import PixelFit, fit_disc_pixels
from bokehfit.fit.result import FailedFit, FitFailedError, FitOptions, Parameter
from bokehfit.fit.signature import Screen, screen

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
]

FOCUS_SIDES = ("far", "near", "unknown")


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
            "shape": self.family.aperture.shape,
            "blades": self.family.aperture.blades,
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
    options: FitOptions = FitOptions()
    time_s: float = 0.0
    success = True

    def __bool__(self) -> bool:
        return True

    @property
    def family(self) -> Family:
        return self.candidates[0].family

    @property
    def margin_bic(self) -> float | None:
        """The runner-up's BIC above the winner's (None when only one model was tried)."""
        return self.candidates[1].delta_bic if len(self.candidates) > 1 else None

    @property
    def parameters(self) -> dict[str, Parameter]:
        """The fitted quantities by JSON name, each with its uncertainty.

        The real-lens features of design.md §3b are not fitted yet: they are
        listed with value None, so that a reader sees they were not estimated.
        """
        aperture = self.aperture
        angle = aperture.canonical_angle_deg
        return {
            "angle_deg": Parameter("angle_deg", angle, self.angle_uncertainty_deg if angle is not None else None),
            "diameter_px": Parameter("diameter_px", self.diameter_px, self.diameter_uncertainty_px),
            "aspect": Parameter("aspect", aperture.aspect),
            "edge_blur_px": Parameter("edge_blur_px", self.blur_px),
            **{name: Parameter(name, None) for name in LENS_FEATURES},
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
        )
        return data

    def disc_fit(self, disc: Disc) -> PixelFit | None:
        """The winning family's fit of ``disc``, if it was fitted."""
        for item in self.disc_fits:
            if item.disc.index == disc.index:
                return item.fits.get(self.family.name)
        return None


#: The real-lens features of design.md §3b, reported (as null) until they are fitted.
LENS_FEATURES = ("roundness", "squeeze", "vignetting", "rim", "chromatic")
#: JSON names of uncertainties that schema 1 named before the ``<name>_uncertainty`` rule (design.md §7, §7b).
UNCERTAINTY_KEYS = {"angle_deg": "angle_uncertainty_deg", "diameter_px": "diameter_uncertainty_px"}


def _order_for_fit(discs: list[Disc], max_discs: int) -> list[Disc]:
    usable = [d for d in discs if d.usable]
    usable.sort(key=lambda d: -d.diameter_px * min(d.snr, 50.0))
    return usable[:max_discs]


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
    symmetry = family.aperture.symmetry_deg
    if family.aperture.has_angle:
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
    options: FitOptions | None = None,
    progress=None,
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
    families = families_for(shapes)
    chosen = _order_for_fit(discs, options.max_discs)
    if not chosen:
        flagged = {
            "saturated": sum(d.saturated for d in discs),
            "cut by the frame": sum(d.clipped for d in discs),
            "overlapping": sum(d.overlaps for d in discs),
            "under 8 px": sum(not d.resolvable for d in discs),
        }
        why = ", ".join(f"{n} {what}" for what, n in flagged.items() if n)
        found = f"{len(discs)} found: {why}" if discs else "none found"
        return FailedFit("no_discs", f"no disc is clean enough to fit ({found})", time_s=time.perf_counter() - start)

    screened = [screen(d.outline_xy, families, _slit_aspect(d)) for d in chosen]
    # Each disc's screens by family (a family is hashable: its aperture).
    screen_of = [{s.family: s for s in disc_screens} for disc_screens in screened]
    mean_rms = {f: np.mean([by_family[f].rms for by_family in screen_of]) for f in families}
    shortlist = sorted(families, key=lambda f: mean_rms[f])[: options.shortlist]
    if FAMILIES[0] in families and FAMILIES[0] not in shortlist:
        shortlist.append(FAMILIES[0])  # the simplest model is always a candidate

    # Model selection on the first model_discs discs, then the winner on all of them.
    model_discs = options.model_discs
    disc_fits = []
    for i, (disc, disc_screens, by_family) in enumerate(zip(chosen[:model_discs], screened, screen_of)):
        fits = {f.name: fit_disc_pixels(luminance, disc, f, by_family[f].aperture) for f in shortlist}
        disc_fits.append(DiscFit(disc, disc_screens, fits))
        if progress is not None:
            progress(i + 1, len(chosen))
    models = [
        _combine(
            family,
            [item.fits[family.name] for item in disc_fits],
            [by_family[family] for by_family in screen_of[: len(disc_fits)]],
        )
        for family in shortlist
    ]
    winner = min(models, key=lambda m: m.bic).family
    for i, (disc, disc_screens, by_family) in enumerate(
        zip(chosen[model_discs:], screened[model_discs:], screen_of[model_discs:]), model_discs
    ):
        fitted = fit_disc_pixels(luminance, disc, winner, by_family[winner].aperture)
        disc_fits.append(DiscFit(disc, disc_screens, {winner.name: fitted}))
        if progress is not None:
            progress(i + 1, len(chosen))
    winner_model = _combine(
        winner,
        [item.fits[winner.name] for item in disc_fits],
        [by_family[winner] for by_family in screen_of],
    )
    models.sort(key=lambda m: m.bic)
    best_bic = models[0].bic
    # The winner's entry carries the consensus over every fitted disc (its BIC
    # stays the selection's, comparable with the others'): one angle, one size.
    models = [
        dataclasses.replace(winner_model if m.family is winner else m, bic=m.bic, delta_bic=m.bic - best_bic)
        for m in models
    ]
    margin = models[1].delta_bic if len(models) > 1 else math.inf
    selection_discs = min(len(disc_fits), model_discs)
    # Unsure only where the runner-up fits about as well; a nested model that
    # fits no better (a slit of aspect 1 against the square) loses by its penalty alone.
    runner_up_rss = sum(item.fits[models[1].family.name].rss for item in disc_fits[:selection_discs]) if len(models) > 1 else math.inf
    best_rss = sum(item.fits[winner.name].rss for item in disc_fits[:selection_discs])
    sure = margin >= options.sure_delta_bic_per_disc * selection_discs or runner_up_rss >= best_rss
    best = winner_model
    best_fits = [item.fits[best.family.name] for item in disc_fits]
    diameters = np.array([f.diameter_px for f in best_fits])
    # The median's uncertainty: the spread between discs (over √n) with each fit's own.
    spread = 1.4826 * float(np.median(np.abs(diameters - np.median(diameters)))) / math.sqrt(len(diameters))
    own = float(np.median([f.uncertainty.get("diameter_px", 0.0) for f in best_fits]))
    spread = math.hypot(spread, own if math.isfinite(own) else 0.0)
    # The aperture's other parameters (the slit's aspect): the median over the discs.
    others = {
        name: float(np.median([f.aperture.values[name] for f in best_fits]))
        for name, parameter in best.family.aperture.parameters.items()
        if parameter.periodic is None
    }
    seen = best.angle_deg if best.angle_deg is not None else 0.0
    aperture_angle = seen + 180.0 if focus_side == "near" else seen
    aperture = best.family.at(angle_deg=aperture_angle, **others)
    described = best.family.name + ("" if aperture.aspect is None else f" (aspect {aperture.aspect:.2f})")
    if aperture.has_angle:
        described += f" at {aperture.canonical_angle_deg:.2f}°"
    message = (
        f"{described} from {len(disc_fits)} discs; "
        + (f"ΔBIC {margin:.0f} over {models[1].family.name}" if len(models) > 1 else "one model tried")
        + ("" if sure else " (unsure: the runner-up is close)")
    )
    return ApertureFit(
        message=message,
        aperture=aperture,
        seen_angle_deg=best.angle_deg,
        angle_uncertainty_deg=best.angle_uncertainty_deg,
        diameter_px=best.diameter_px,
        diameter_uncertainty_px=spread,
        blur_px=float(np.median([f.blur_px for f in best_fits])),
        focus_side=focus_side,
        candidates=models,
        disc_fits=disc_fits,
        sure=sure,
        options=options,
        time_s=time.perf_counter() - start,
    )
