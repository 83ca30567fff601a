"""Whether the discs agree on one aperture: the angle and elongation they share, and the discs that disagree.

The angles' weighted circular mean modulo the shape's symmetry, the discs that show the aperture
turned by 180° (:func:`turned_discs`), whether the discs support a family together
(:func:`unsupported`), the discs the others' consensus does not share (:func:`disagreeing`), the
joint fit's start at their consensus, and a family's candidate model over them (:func:`combine`).
One aperture shows the same angle (modulo its symmetry, and turned by 180° on discs before the
focus plane) and the same elongation on every disc; a shape whose angle each disc puts
elsewhere is a misfit, not a lens.
"""

from __future__ import annotations

import math

import numpy as np

from bokehfit.apertures import Aperture
from bokehfit.discs import Disc
from bokehfit.fit.families import Family
from bokehfit.fit.pixels import PixelFit
from bokehfit.fit.result import CandidateModel
from bokehfit.fit.signature import Screen, outline_misfit

__all__ = ["combine", "consensus_start", "disagreeing", "outline_misfits", "turned_discs", "unsupported",
           "MIN_ELONGATED_DISCS", "ELONGATED_ANGLE_SPREAD_DEG", "ELONGATED_ASPECT_SPREAD", "ANGLE_AGREEMENT_SHARE"]

#: An elongated aperture (a slit) is accepted only when at least this many discs show it ...
MIN_ELONGATED_DISCS = 3
#: ... at angles within this spread of each other ...
ELONGATED_ANGLE_SPREAD_DEG = 10.0
#: ... and aspects within this spread (the aspects' standard deviation).
ELONGATED_ASPECT_SPREAD = 0.1
#: A shape with an angle is supported only where the discs' angles spread less than this share of its symmetry.
ANGLE_AGREEMENT_SHARE = 0.125
#: A disc disagrees with the consensus when its angle is off by more than this many standard deviations ...
OUTLIER_SIGMAS = 3.0
#: ... (never less than this many degrees) ...
MIN_ANGLE_TOLERANCE_DEG = 3.0
#: ... or its outline misfits the shape by more than this many times the median misfit (and by at least MIN_OUTLIER_RMS).
OUTLIER_RMS_FACTOR = 3.0
MIN_OUTLIER_RMS = 0.05


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


def combine(family: Family, fits: list[PixelFit], screens: list[Screen]) -> CandidateModel:
    """``family``'s candidate model over the discs' fits: their BICs summed, the angles' weighted circular
    mean with its uncertainty, the median diameter, outline misfit and roundness."""
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
                   if family.aperture.has_roundness else None),
    )


def _elongation_doubt(family: Family, fits: list[PixelFit]) -> str | None:
    """Why an elongated family (a slit) is not supported by ``fits``; None when it is, or when it is not elongated.

    One blob stretched by an in-focus edge, a cat-eye at the frame's edge or
    two merged discs looks like a slit; an elongated aperture shows as the
    same elongation on several discs.
    """
    if not family.aperture.has_aspect:
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


def turned_discs(family: Family, fits: list[PixelFit]) -> list[bool]:
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


def unsupported(family: Family, fits: list[PixelFit]) -> str | None:
    """Why the discs do not support ``family`` together (None when they do): an elongation they do
    not share (:func:`_elongation_doubt`), or angles that scatter (robust spread over
    ANGLE_AGREEMENT_SHARE of the symmetry, at least MIN_ANGLE_TOLERANCE_DEG) with two discs or more."""
    doubt = _elongation_doubt(family, fits)
    if doubt is not None or not family.aperture.has_angle or len(fits) < 2:
        return doubt
    period = family.aperture.symmetry_deg
    angles = _unturned_angles(family, fits, turned_discs(family, fits))
    mean, _ = _circular_mean(angles, np.ones(len(angles)), period)
    spread = 1.4826 * float(np.median(np.abs(_angle_offsets(angles, mean, period))))
    if spread > max(ANGLE_AGREEMENT_SHARE * period, MIN_ANGLE_TOLERANCE_DEG):
        return f"the discs put its angle in different places (spread {spread:.0f}° of its {period:.0f}° symmetry)"
    return None


def disagreeing(family: Family, fits: list[PixelFit], screens: list[Screen], turned: list[bool]) -> dict[int, str]:
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
                out[i] = (f"its angle is not the other discs' ({offset:+.1f}° from their {mean:.1f}°, "
                          f"tolerance {tolerance:.1f}°)")
    if len(out) * 2 > len(fits):  # no majority to disagree with: keep them all, the judge will doubt
        return {}
    return out


def consensus_start(family: Family, fits: list[PixelFit], turned: list[bool]) -> Aperture:
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


def outline_misfits(discs: list[Disc], aperture: Aperture, fits: list[PixelFit]) -> np.ndarray:
    """Outline misfit (equal-area radii) of each of ``discs`` to one ``aperture``, as it shows at the disc's field position."""
    return np.array([outline_misfit(d.outline_xy, aperture, f.field_position) for d, f in zip(discs, fits)])
