"""Screening by radial signature: which shapes, at which angle, could a disc's outline be?

Notes
-----
An outline seen from its centroid is a radius function r(θ), sampled on
``SAMPLES`` angles and divided by the equal-area radius. Each family's
unit-area outline gives its own r(θ) at angle 0; turning the shape by a shifts
the function by a, so the best angle is the circular cross-correlation's peak
(one FFT for all shifts, of all the families' models at once, refined by a
parabola through the peak) and the score
is the RMS difference at that angle. A disc that shows only part of its
outline as its own (it overlaps another) is scored on those angles alone,
with its scale free (its equal-area radius includes the part it does not
show): each term of the weighted least squares over the shifts is again a
circular correlation, so it costs a few more FFTs. It costs microseconds, ranks the families
for the pixel fit, and gives the fit its starting angle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bokehfit.apertures import Aperture, image_to_aperture
from bokehfit.fit.families import Family
from bokehfit.metrics import angle_error

__all__ = ["SAMPLES", "Ellipse", "Screen", "fit_ellipse", "misalignment_deg", "outline_misfit", "radial_signature", "screen"]

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


def partial_signature(outline_xy: np.ndarray, reliable: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """r(θ) of an outline seen only in part, and the weights (1 where seen) on the SAMPLES angles.

    Where part of the outline is not the disc's own (it runs along a neighbour), the centroid
    and the equal-area radius are not the disc's either. The centre is then the circle fitted
    to the points it shows (Kåsa's least squares), which a regular shape's sides keep near its
    centre, and the scale is left to the comparison (:func:`_best_shifts` with weights).
    """
    points = image_to_aperture(np.asarray(outline_xy, dtype=np.float64)[:, ::-1])
    seen = np.asarray(reliable, dtype=bool)
    x, y = points[seen].T
    design = np.column_stack([x, y, np.ones_like(x)])
    (a, b, _), *_ = np.linalg.lstsq(design, x * x + y * y, rcond=None)
    cx, cy = 0.5 * a, 0.5 * b
    angles = np.mod(np.arctan2(points[:, 1] - cy, points[:, 0] - cx), 2 * np.pi)
    radii = np.hypot(points[:, 0] - cx, points[:, 1] - cy)
    order = np.argsort(angles)
    r = np.interp(_THETA, angles[order], radii[order], period=2 * np.pi)
    weights = np.interp(_THETA, angles[order], seen[order].astype(np.float64), period=2 * np.pi) > 0.5
    return r / max(float(np.median(radii[seen])), 1e-12), weights.astype(np.float64)


@dataclass(frozen=True)
class Ellipse:
    """The ellipse that best fits an outline's own points, and how well."""

    aspect: float  #: short axis over long, 0–1
    axis_deg: float  #: the long axis's direction in the image, degrees from x (y down), in [0, 180)
    misfit: float  #: RMS radial misfit of the points, in equal-area radii


def fit_ellipse(outline_xy: np.ndarray, reliable: np.ndarray | None = None) -> Ellipse | None:
    """The ellipse through an outline's own points (``reliable``; OpenCV's direct least squares,
    Fitzgibbon et al. 1999), or None where fewer than 6 points are seen or none fits.

    The misfit is the points' distance from the ellipse's centre against the ellipse's radius at
    their angle, RMS, over the equal-area radius √(ab): the measure of :func:`screen`, for the
    elongations an aperture shape's own outline does not hold (a squeezed circle, a cat-eye)."""
    import cv2

    points = np.asarray(outline_xy, dtype=np.float64)
    if reliable is not None:
        points = points[np.asarray(reliable, dtype=bool)]
    if len(points) < 6:
        return None
    (cx, cy), (width, height), angle = cv2.fitEllipseDirect(points.astype(np.float32))
    a, b = 0.5 * width, 0.5 * height  # along the ellipse's first axis (at ``angle``) and across it
    if not (a > 0 and b > 0 and math.isfinite(a * b)):
        return None
    turn = math.radians(angle)
    dx, dy = points[:, 0] - cx, points[:, 1] - cy
    u, v = dx * math.cos(turn) + dy * math.sin(turn), -dx * math.sin(turn) + dy * math.cos(turn)
    phi = np.arctan2(v, u)
    model = a * b / np.sqrt((b * np.cos(phi)) ** 2 + (a * np.sin(phi)) ** 2)
    misfit = float(np.sqrt(np.mean((np.hypot(u, v) - model) ** 2)) / math.sqrt(a * b))
    axis = angle if a >= b else angle + 90.0
    return Ellipse(min(a, b) / max(a, b), axis % 180.0, misfit)


def radial_signature(outline_xy: np.ndarray) -> np.ndarray:
    """r(θ) / r_eq of a closed outline (image (column, row) points) about its centroid, on the SAMPLES angles (y up)."""
    return _signature(image_to_aperture(np.asarray(outline_xy, dtype=np.float64)[:, ::-1]))


def _signature(points: np.ndarray) -> np.ndarray:
    """r(θ) / r_eq about the centroid of a closed polygon of (x, y) points in the aperture frame."""
    x, y = points.T
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    area = 0.5 * (x * y1 - x1 * y).sum()
    cx, cy = _centroid(x, y)
    angles = np.arctan2(y - cy, x - cx)
    radii = np.hypot(x - cx, y - cy)
    order = np.argsort(angles)
    r = np.interp(_THETA, np.mod(angles[order], 2 * np.pi), radii[order], period=2 * np.pi)
    return r / np.sqrt(abs(area) / np.pi)


def _model_signature(aperture: Aperture) -> np.ndarray:
    """r(θ) / r_eq of the unit-area aperture at angle 0 (:meth:`Aperture.outline_radius`)."""
    return aperture.outline_radius(_THETA) * np.sqrt(np.pi)


def _centroid(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    area = 0.5 * cross.sum()
    return ((x + x1) * cross).sum() / (6.0 * area), ((y + y1) * cross).sum() / (6.0 * area)


def outline_misfit(outline_xy: np.ndarray, aperture: Aperture, field_position=None) -> float:
    """RMS misfit (equal-area radii) of a disc's outline to ``aperture`` as a disc at ``field_position``
    shows it (cut by its vignetting there), at the best rotation: the screen's score for one aperture.
    A squeeze or a vignetting cut is fixed in the frame, so a squeezed or cut aperture is compared
    as the frame shows it (turned by its angle, then squeezed and cut), not turned whole."""
    observed = radial_signature(outline_xy)
    if aperture.squeeze == 1.0 and (aperture.vignetting is None or field_position is None):
        return _best_shift(observed, _model_signature(aperture))[1]
    # The outline in the frame: its largest loop, resampled evenly along its length (a straight side is one point).
    loop = max(aperture.outline(field_position).polylines(1e-4), key=len)
    closed = np.vstack([loop, loop[:1]])
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(closed, axis=0).T))])
    t = np.linspace(0.0, along[-1], 4 * SAMPLES, endpoint=False)
    dense = np.column_stack([np.interp(t, along, closed[:, 0]), np.interp(t, along, closed[:, 1])])
    return _best_shift(observed, _signature(dense))[1]


def misalignment_deg(aperture: Aperture, other: Aperture) -> float:
    """The least rotation (degrees) between ``aperture``'s outline and ``other``'s, whatever angle
    convention each shape has (the square is the 4-gon turned by 45°, design.md §3): the rotation
    that best lays their outlines at angle 0 on each other (:func:`_best_shift`), with their
    angles, folded by ``aperture``'s symmetry (:func:`bokehfit.metrics.angle_error`); 0 where
    ``aperture`` has no angle (the circle). For apertures without a squeeze.

    Examples
    --------
    >>> from bokehfit.apertures import make_aperture
    >>> round(misalignment_deg(make_aperture("square", 20.0), make_aperture("ngon", 65.3, blades=4)), 2)
    0.3
    """
    if not aperture.has_angle:
        return 0.0
    # other's outline at 0 ≈ aperture's at 0 turned by ``zero``: aperture at α lies on other at β where α = β + zero.
    zero = math.degrees(_best_shift(_model_signature(other), _model_signature(aperture))[0])
    other_angle = other.angle_deg if other.has_angle else 0.0
    return angle_error(aperture.angle_deg - other_angle - zero, 0.0, aperture.symmetry_deg)


def _best_shift(observed: np.ndarray, model: np.ndarray) -> tuple[float, float]:
    """Rotation (radians) of the model that best fits, and the RMS difference there
    (:func:`_best_shifts` of one model, the whole outline seen)."""
    spectrum, squares = _model_spectra(model)
    shifts, rms = _best_shifts(observed, model[None], None, (spectrum[None], squares[None]))
    return float(shifts[0]), float(rms[0])


def _best_shifts(observed: np.ndarray, models: np.ndarray, weights: np.ndarray | None,
                 spectra: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Rotations (radians) of each model signature (rows of ``models``) that best fit, and the RMS
    difference there, all models' correlations taken in one FFT call.

    With ``weights`` (1 where the outline is seen, 0 elsewhere) only the seen angles count, and
    the model's scale k is free: the cost over shifts s, Σw·o² − (Σw·o·mₛ)² / Σw·mₛ², is made of
    circular correlations. ``spectra`` are the models' :func:`_model_spectra`, row by row.
    """
    spectrum, squares = spectra
    rows = np.arange(len(models))
    if weights is not None:
        cross = np.fft.irfft(np.fft.rfft(weights * observed) * spectrum, SAMPLES, axis=-1)
        power = np.fft.irfft(np.fft.rfft(weights) * squares, SAMPLES, axis=-1)
        cost = np.sum(weights * observed**2) - cross**2 / np.maximum(power, 1e-12)
        k = np.argmin(cost, axis=-1)
        return k * 2 * np.pi / SAMPLES, np.sqrt(np.maximum(cost[rows, k], 0.0) / max(weights.sum(), 1.0))
    correlation = np.fft.irfft(np.fft.rfft(observed) * spectrum, SAMPLES, axis=-1)
    k = np.argmax(correlation, axis=-1)
    left, centre, right = correlation[rows, k - 1], correlation[rows, k], correlation[rows, (k + 1) % SAMPLES]
    curvature = left - 2 * centre + right
    offset = np.where(curvature < 0, 0.5 * (left - right) / np.where(curvature < 0, curvature, -1.0), 0.0)
    shift = (k + offset) * 2 * np.pi / SAMPLES
    residual = observed - models[rows[:, None], (np.arange(SAMPLES) - k[:, None]) % SAMPLES]  # each model rolled by its k
    return shift, np.sqrt(np.mean(residual * residual, axis=-1))


def _model_spectra(model: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The conjugate spectra of a model signature and of its square (the correlations' factors)."""
    return np.conj(np.fft.rfft(model)), np.conj(np.fft.rfft(model * model))


def screen(outline_xy: np.ndarray, families: tuple[Family, ...], slit_aspect: float | None,
           reliable: np.ndarray | None = None, models: dict | None = None) -> list[Screen]:
    """Every family's best angle and RMS misfit for one outline, best first.

    ``slit_aspect`` (the outline's, None for none) is given to the families
    that have an ``aspect`` parameter; a family whose aperture varies its
    ``roundness`` is tried at each of :data:`ROUNDNESS_GRID` and keeps the best.
    ``reliable`` (per outline point) limits the score to the outline's own points.
    ``models``, where given, is the caller's dict of the model apertures' signatures
    and spectra, filled as they are first needed: one fit screens many outlines
    against the same models.
    """
    if reliable is None or np.all(reliable) or np.sum(reliable) < 8:
        observed, weights = radial_signature(outline_xy), None
    else:
        observed, weights = partial_signature(outline_xy, reliable)
    models = {} if models is None else models
    tries, (signatures, spectra, squares), aspect_rows = _tries(models, families)
    shifts, rms = _best_shifts(observed, signatures, weights, (spectra, squares))
    if slit_aspect is not None and len(aspect_rows):  # those rows again, their models at the outline's aspect
        tries, (signatures, spectra, squares) = _at_aspect(models, tries, aspect_rows, slit_aspect)
        shifts[aspect_rows], rms[aspect_rows] = _best_shifts(observed, signatures, weights, (spectra, squares))
    best: dict[Family, int] = {}
    for i, (family, _) in enumerate(tries):  # a family's best roundness: the first of its least misfits
        if family not in best or rms[i] < rms[best[family]]:
            best[family] = i
    results = []
    for family, i in best.items():
        model = tries[i][1]
        if model.has_angle:
            model = model.replace(angle_deg=float(np.degrees(shifts[i]) % model.symmetry_deg))
        results.append(Screen(family, model, float(rms[i])))
    return sorted(results, key=lambda s: s.rms)


def _family_models(family: Family, slit_aspect: float | None) -> list[Aperture]:
    """The model apertures a family is screened with: at the outline's aspect where the family has one, a
    rounded family at each of :data:`ROUNDNESS_GRID`."""
    aperture = family.at(aspect=slit_aspect) if slit_aspect is not None else family.aperture
    return [aperture.replace(roundness=r) for r in ROUNDNESS_GRID] if aperture.has_roundness else [aperture]


def _tries(models: dict, families: tuple[Family, ...]):
    """``(family, model aperture)`` in the families' order (:func:`_family_models`), the models' signatures
    and spectra stacked (:func:`_stacked`), and the rows of the families that take an aspect (the slit's):
    made once per ``families`` and kept in ``models``."""
    key = ("tries", families)
    if key not in models:
        tries = [(family, model) for family in families for model in _family_models(family, None)]
        aspect_rows = np.array([i for i, (family, _) in enumerate(tries) if family.aperture.spec.takes_aspect], int)
        models[key] = (tries, _stacked(models, [model for _, model in tries]), aspect_rows)
    return models[key]


def _at_aspect(models: dict, tries: list, aspect_rows: np.ndarray, slit_aspect: float):
    """``tries`` with the rows ``aspect_rows`` at the outline's aspect, and those rows' models stacked."""
    tries = list(tries)  # a family's rows are together, in _family_models' order
    at_aspect = [model for family in dict.fromkeys(tries[i][0] for i in aspect_rows)
                 for model in _family_models(family, slit_aspect)]
    for i, model in zip(aspect_rows, at_aspect, strict=True):
        tries[i] = (tries[i][0], model)
    return tries, _stacked(models, at_aspect)


def _stacked(models: dict, apertures: list[Aperture]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The signatures of ``apertures`` and their two spectra (:func:`_model_spectra`), stacked row by
    row; ``models`` keeps each aperture's, and each list's stack, as they are first needed."""
    key = tuple(apertures)
    if key not in models:
        for model in apertures:
            if model not in models:
                signature = _model_signature(model)
                models[model] = (signature, _model_spectra(signature))
        rows = [models[model] for model in apertures]
        models[key] = (np.stack([r[0] for r in rows]), np.stack([r[1][0] for r in rows]), np.stack([r[1][1] for r in rows]))
    return models[key]
