"""What a pixel fit minimises, and its Jacobian: the model's own slopes where it has them.

Notes
-----
The residuals of a disc are (model − data) / noise over its crop (:func:`disc_residuals`: a
clipped pixel only where the model falls below it, the light that is not the disc's not at
all), every disc's one after the other (:func:`weighted_residuals`).

**The Jacobian** (:func:`jacobian`) is built column by column. A disc's centre and size move
its coverage by the outline's chords on the pixel borders, and the aperture's angle by the flux
of the turn through them (:func:`bokehfit.fit.disc_model.profile_slopes`: exact, one pass over
the crop for the four of them); a ``rim`` profile's light moves so on its sub-pixels, its weight
with them, and is linear in the rim (:func:`bokehfit.kernels.rim.rim_coverage_slopes`: the rim's
column too). The shared angle's and rim's columns are taken as the disc shows the aperture (a
near disc: the rim's sign turned, :func:`_shown_per_unit`). The levels follow as the model solves them (variable projection: for a profile
slope ∂P, the background b and plateau p re-solved to first order, so the column is the exact
derivative of the residuals the fit sees, as a finite difference of them would be to first
order). Finite differences, with ``scipy.optimize.least_squares``' step (10⁻⁴ of the value, at
least 10⁻⁴, turned back inside the bounds), remain for what has no such slope: the aperture's
other shared parameters, and the angle where a disc's outline does not turn whole (a vignetting
cut; each a render of every disc, as before), and a disc's edge blur and saturated
plateau (a blur and the levels of its own crop, its coverage reused).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
from scipy.sparse import csr_matrix

from bokehfit.apertures import Aperture
from bokehfit.fit.crop import DiscCrop
from bokehfit.fit.disc_model import RIM, TURN, level_pixels, profile_slopes, render_disc_model
from bokehfit.fit.vector import Block, FitVector

__all__ = ["DIFF_STEP", "censored_residuals", "disc_residuals", "jacobian", "weighted_residuals"]

#: Relative step of a finite-difference column (``least_squares``' ``diff_step``).
DIFF_STEP = 1e-4


def censored_residuals(model: np.ndarray, crop: DiscCrop) -> np.ndarray:
    """model − data; where the source is clipped only a model below the recorded value is an error;
    where the light is not the disc's, none."""
    residual = model - crop.data
    if crop.censored is not None:
        residual[crop.censored] = np.minimum(residual[crop.censored], 0.0)
    if crop.ignored is not None:
        residual[crop.ignored] = 0.0
    return residual


def _shown(aperture: Aperture, crop: DiscCrop) -> Aperture:
    """The aperture as ``crop``'s disc shows it (turned by 180° where the disc is on the near side)."""
    return aperture.near() if crop.turned else aperture


def disc_residuals(aperture: Aperture, crop: DiscCrop, disc: Mapping[str, float], noise: float,
                   covers: dict | None = None) -> np.ndarray:
    """One disc's residuals over its noise level, ``aperture`` as the fit holds it, ``disc`` its values."""
    model = render_disc_model(_shown(aperture, crop), disc, crop.size, crop.data, crop.field_position,
                              crop.censored, crop.ignored, covers).model
    return censored_residuals(model, crop) / noise


def weighted_residuals(crops: Sequence[DiscCrop], vector: FitVector, noise: np.ndarray,
                       covers: dict) -> Callable[[np.ndarray], np.ndarray]:
    """What the fit minimises: every disc's residuals over its noise level, one disc after the other.
    ``covers`` is the memo of the latest coverages (:func:`bokehfit.fit.disc_model.disc_profile`)."""

    def residuals(x: np.ndarray) -> np.ndarray:
        aperture = vector.aperture_at(x)
        return np.concatenate([disc_residuals(aperture, c, d, s, covers)
                               for c, d, s in zip(crops, vector.discs_at(x), noise)])

    return residuals


def _step(value: float, lower: float, upper: float) -> float:
    """A forward difference's step as ``least_squares`` takes it: DIFF_STEP of the value (at least
    DIFF_STEP), backwards where forwards would leave the bounds, as the float sum resolves it."""
    h = DIFF_STEP * (1.0 if value >= 0.0 else -1.0) * max(1.0, abs(value))
    if not lower <= value + h <= upper:
        h = -h
    return (value + h) - value


def _model_slope(slope: np.ndarray, profile: np.ndarray, crop: DiscCrop, levels: tuple[float, float],
                 fixed_plateau: bool) -> np.ndarray:
    """∂model for a profile slope ∂P, the levels re-solved to first order as :func:`render_disc_model`
    solves them (over the pixels neither censored nor ignored)."""
    background, plateau = levels
    contrast = plateau - background
    seen = level_pixels(crop.censored, crop.ignored)
    u, q, d = 1.0 - profile[seen], profile[seen], slope[seen]
    rest = crop.data[seen] - (background * u + plateau * q)  # data − model
    moved = contrast * d  # the model's own move, the levels held
    if fixed_plateau:  # the background alone is solved for
        weight = float(u @ u)
        shift = (-(d @ rest) - u @ moved) / weight if weight > 1e-12 else 0.0
        return contrast * slope + shift * (1.0 - profile)
    a11, a12, a22 = float(u @ u), float(u @ q), float(q @ q)
    det = a11 * a22 - a12 * a12
    if abs(det) < 1e-12:
        return contrast * slope
    g1, g2 = -(d @ rest) - u @ moved, d @ rest - q @ moved
    d_background, d_plateau = (a22 * g1 - a12 * g2) / det, (a11 * g2 - a12 * g1) / det
    return contrast * slope + d_background * (1.0 - profile) + d_plateau * profile


def _disc_columns(aperture: Aperture, crop: DiscCrop, disc: dict[str, float], noise: float, block: Block,
                  covers: dict) -> dict[str, np.ndarray]:
    """One disc's own columns of the Jacobian, by name, and the shared angle's rows of it where the
    model has its slope (:data:`~bokehfit.fit.disc_model.TURN`)."""
    shown = _shown(aperture, crop)
    fitted = render_disc_model(shown, disc, crop.size, crop.data, crop.field_position, crop.censored, crop.ignored,
                               covers)
    base = censored_residuals(fitted.model, crop) / noise
    columns = {}
    slopes = profile_slopes(shown, disc, crop.size, crop.field_position, covers)
    if slopes is not None:
        live = np.ones(crop.data.size, dtype=bool)  # where the residual is the model's: not ignored, not censored above
        if crop.ignored is not None:
            live &= ~crop.ignored
        if crop.censored is not None:
            live &= ~(crop.censored & (base >= 0.0))
        for name, slope in slopes.items():
            column = _model_slope(slope, fitted.profile, crop, (fitted.background, fitted.plateau), "plateau" in disc)
            columns[name] = np.where(live, column, 0.0) / noise
    for name, lower, upper in zip(block.names, block.lower, block.upper):
        if name in columns:
            continue
        h = _step(disc[name], lower, upper)
        moved = disc_residuals(aperture, crop, {**disc, name: disc[name] + h}, noise, covers)
        columns[name] = (moved - base) / h
    return columns


def _shown_per_unit(aperture: Aperture, crop: DiscCrop, name: str) -> float:
    """How much the aperture as ``crop``'s disc shows it (:func:`_shown`) changes its parameter ``name``
    (a field of the aperture) per unit of the aperture's: 1 for the angle, −1 for a near disc's rim (the
    model's :meth:`~bokehfit.apertures.Aperture.near`, linear in both), 1 for a far disc's. Taken between 0
    and a half, where the difference of the values shown is exact."""
    def shown(value: float) -> float:
        return float(getattr(_shown(aperture.replace(**{name: value}), crop), name))

    return (shown(0.5) - shown(0.0)) / 0.5


def jacobian(crops: Sequence[DiscCrop], vector: FitVector, noise: np.ndarray, covers: dict,
             sparse: bool) -> Callable[[np.ndarray], np.ndarray | csr_matrix]:
    """The Jacobian of :func:`weighted_residuals` at a vector (the module notes); sparse (CSR) where
    ``sparse``, as ``least_squares``' iterative solver takes it: a disc's residuals hang on the shared
    parameters and its own alone."""
    residuals = weighted_residuals(crops, vector, noise, covers)
    rows = np.cumsum([0, *(c.data.size for c in crops)])
    sloped = [name for name in vector.free if name in (TURN, RIM)]  # the shared parameters the model has slopes for
    # How each disc shows them: the same for every disc turned alike, and at every vector (near() is linear in them).
    start = vector.aperture_at(np.array(vector.start, dtype=np.float64)) if sloped else None
    per_unit = {(turned, name): _shown_per_unit(start, crop, name)
                for turned, crop in {c.turned: c for c in crops}.items() for name in sloped}

    def jac(x: np.ndarray) -> np.ndarray | csr_matrix:
        matrix = np.zeros((rows[-1], vector.size))
        aperture = vector.aperture_at(x)
        shared = {name: [] for name in sloped}  # each disc's rows of their columns, where the model has them
        for i, (crop, disc, block) in enumerate(zip(crops, vector.discs_at(x), vector.discs)):
            columns = _disc_columns(aperture, crop, disc, noise[i], block, covers)
            for k, name in enumerate(block.names):
                matrix[rows[i] : rows[i + 1], block.at + k] = columns[name]
            for name in sloped:
                column = columns.get(name)
                shared[name].append(None if column is None else column * per_unit[crop.turned, name])
        differenced = list(range(len(vector.free)))
        for name, parts in shared.items():
            if all(part is not None for part in parts):
                j = vector.free.index(name)
                matrix[:, j] = np.concatenate(parts)
                differenced.remove(j)
        if differenced:
            base = residuals(x)
            for j in differenced:
                h = _step(float(x[j]), vector.lower[j], vector.upper[j])
                moved = x.copy()
                moved[j] += h
                matrix[:, j] = (residuals(moved) - base) / h
        return csr_matrix(matrix) if sparse else matrix

    return jac
