"""Screening by radial signature: which shapes, at which angle, could a disc's outline be?

Notes
-----
An outline seen from its centroid is a radius function r(θ), sampled on
``SAMPLES`` angles and divided by the equal-area radius. Each family's
unit-area outline gives its own r(θ) at angle 0; turning the shape by a shifts
the function by a, so the best angle is the circular cross-correlation's peak
(one FFT for all shifts, refined by a parabola through the peak) and the score
is the RMS difference at that angle. It costs microseconds, ranks the families
for the pixel fit, and gives the fit its starting angle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bokehfit.apertures import Aperture, image_to_aperture
from bokehfit.fit.families import Family

__all__ = ["SAMPLES", "Screen", "outline_misfit", "radial_signature", "screen"]

#: Angles of the radial signature (0.5° apart).
SAMPLES = 720
_THETA = np.arange(SAMPLES) * (2.0 * np.pi / SAMPLES)
#: Roundness values a rounded family is screened at (the pixel fit refines from the best).
ROUNDNESS_GRID = (0.0, 0.2, 0.4, 0.6, 0.8)


@dataclass(frozen=True)
class Screen:
    """How well one family's outline matches a disc's, at its best angle."""

    family: Family
    aperture: Aperture  #: the family's aperture at the best angle (and the outline's aspect, for a slit)
    rms: float  #: RMS of (observed − model) radius, in equal-area radii

    @property
    def angle_deg(self) -> float:
        """The best angle, in [0, symmetry) (0 where the aperture has no angle)."""
        return self.aperture.angle_deg


def radial_signature(outline_xy: np.ndarray) -> np.ndarray:
    """r(θ) / r_eq of a closed outline (image (column, row) points) about its centroid, on the SAMPLES angles (y up)."""
    return _signature(image_to_aperture(np.asarray(outline_xy, dtype=np.float64)[:, ::-1]))


def _signature(points: np.ndarray) -> np.ndarray:
    """r(θ) / r_eq about the centroid of a closed polygon of (x, y) points in the aperture frame."""
    x, y = points.T
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    area = 0.5 * cross.sum()
    cx = ((x + x1) * cross).sum() / (6.0 * area)
    cy = ((y + y1) * cross).sum() / (6.0 * area)
    angles = np.arctan2(y - cy, x - cx)
    radii = np.hypot(x - cx, y - cy)
    order = np.argsort(angles)
    r = np.interp(_THETA, np.mod(angles[order], 2 * np.pi), radii[order], period=2 * np.pi)
    return r / np.sqrt(abs(area) / np.pi)


def _model_signature(aperture: Aperture) -> np.ndarray:
    """r(θ) / r_eq of the unit-area aperture at angle 0 (:meth:`Aperture.outline_radius`)."""
    return aperture.outline_radius(_THETA) * np.sqrt(np.pi)


def outline_misfit(outline_xy: np.ndarray, aperture: Aperture, field_position=None) -> float:
    """RMS misfit (equal-area radii) of a disc's outline to ``aperture`` as a disc at ``field_position``
    shows it (cut by its vignetting there), at the best rotation: the screen's score for one aperture."""
    observed = radial_signature(outline_xy)
    if aperture.vignetting is None or field_position is None:
        return _best_shift(observed, _model_signature(aperture))[1]
    # The cut outline: its largest loop, resampled evenly along its length (a straight side is one point).
    loop = max(aperture.outline(field_position).polylines(1e-4), key=len)
    closed = np.vstack([loop, loop[:1]])
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(closed, axis=0).T))])
    t = np.linspace(0.0, along[-1], 4 * SAMPLES, endpoint=False)
    dense = np.column_stack([np.interp(t, along, closed[:, 0]), np.interp(t, along, closed[:, 1])])
    return _best_shift(observed, _signature(dense))[1]


def _best_shift(observed: np.ndarray, model: np.ndarray) -> tuple[float, float]:
    """Rotation (radians) of the model that best fits, and the RMS difference there."""
    correlation = np.fft.irfft(np.fft.rfft(observed) * np.conj(np.fft.rfft(model)), SAMPLES)
    k = int(np.argmax(correlation))
    left, centre, right = correlation[k - 1], correlation[k], correlation[(k + 1) % SAMPLES]
    curvature = left - 2 * centre + right
    offset = 0.5 * (left - right) / curvature if curvature < 0 else 0.0
    shift = (k + offset) * 2 * np.pi / SAMPLES
    residual = observed - np.roll(model, k)
    return shift, float(np.sqrt(np.mean(residual * residual)))


def screen(outline_xy: np.ndarray, families: tuple[Family, ...], slit_aspect: float | None) -> list[Screen]:
    """Every family's best angle and RMS misfit for one outline, best first.

    ``slit_aspect`` (the outline's, None for none) is given to the families
    that have an ``aspect`` parameter; a family whose aperture varies its
    ``roundness`` is tried at each of :data:`ROUNDNESS_GRID` and keeps the best.
    """
    observed = radial_signature(outline_xy)
    results = []
    for family in families:
        aperture = family.at(aspect=slit_aspect) if slit_aspect is not None else family.aperture
        tries = [aperture]
        if "roundness" in aperture.parameters:
            tries = [aperture.replace(roundness=r) for r in ROUNDNESS_GRID]
        best = None
        for model in tries:
            shift, rms = _best_shift(observed, _model_signature(model))
            if best is None or rms < best[2]:
                best = (model, shift, rms)
        model, shift, rms = best
        if model.has_angle:
            model = model.replace(angle_deg=float(np.degrees(shift) % model.symmetry_deg))
        results.append(Screen(family, model, rms))
    return sorted(results, key=lambda s: s.rms)
