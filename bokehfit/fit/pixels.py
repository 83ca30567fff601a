"""Fit discs' pixels with a kernel: shape, angle, size, centre, levels, edge blur and the lens's features.

Notes
-----
Least squares (trust-region reflective, bounded) fits a disc's centre c,
equal-area diameter d, edge blur σ and the aperture's own
:attr:`~bokehfit.apertures.Aperture.parameters` (the angle, the slit's aspect,
the roundness, ...) to the model of its crop, I(x) = b + (p − b) · (G_σ ⊗ K)(x)
(:mod:`bokehfit.fit.disc_model`), solving for b and p at every step (they
enter linearly: variable projection).

**Clipped pixels are censored, not lost.** A pixel clipped in the source (any
channel at the file's top value) says only that the light there was at least
what was recorded, so its residual is min(model − data, 0): the model may pass
above it, never below. A saturated disc's plateau p is then unknown above the
clip and becomes a fitted parameter; its outline still fixes the shape.

**Many discs, one aperture.** :func:`fit_discs` fits several discs at once:
each disc its own centre, size, blur and levels, all of them the shared
aperture parameters (and the vignetting, which only the discs' spread over the
frame can tell). The Jacobian is block-sparse (a disc's residuals depend on
its own parameters and the shared ones). Its columns are the model's own slopes
where it has them (a disc's centre and size) and finite differences where not
(:mod:`bokehfit.fit.objective`). Each disc's residuals are
divided by its own noise level (from its single-disc fit), so a bright disc
does not outvote the others.

Each disc is fitted on its crop (:mod:`bokehfit.fit.crop`: reduced where wide, the light that is
not the disc's left out). Uncertainties are from the Jacobian at the optimum:
cov = (JᵀJ)⁻¹ · RSS / (n − k).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from bokehfit.apertures import Aperture
from bokehfit.discs import Disc
from bokehfit.fit.crop import DiscCrop, crop_disc
from bokehfit.fit.disc_model import render_disc_model
from bokehfit.fit.families import Family
from bokehfit.fit.objective import censored_residuals, jacobian, weighted_residuals
from bokehfit.fit.vector import Block, FitVector, fit_vector

__all__ = [
    "JointFit",
    "PixelFit",
    "fit_disc_pixels",
    "fit_discs",
]

#: Most function evaluations per fit.
MAX_EVALUATIONS = 200
#: Relative change of the cost and of the parameters at which a fit stops (scipy's ftol and xtol):
#: 1e-6 of an angle of 30° is 3e-5°, far below what the discs can tell.
TOLERANCE = 1e-6
#: A weighted fit (every disc's residuals over its noise level, so that its RSS is a χ² and, near
#: RSS = n, a change of it is one of the BIC) also stops where its last STALL_STEPS steps together
#: lowered the RSS by less than STALL_RSS: a tenth of the BIC a feature must gain to join the
#: model (``bokehfit.fit.features.FEATURE_DELTA_BIC``). A disc that the shared aperture does not
#: explain, its centre held at its bound, otherwise lets the trust region crawl on in steps just
#: above TOLERANCE: 110 steps for an RSS 3.8 lower, the joint fit of photo 04's rim.
STALL_STEPS = 5
STALL_RSS = 1.0
#: scipy's status of a fit its callback stopped.
STALLED = -2


@dataclass(frozen=True)
class PixelFit:
    """One family fitted to one disc's pixels."""

    family: Family
    aperture: Aperture  #: the fitted aperture, its angle in [0, symmetry)
    center_xy: tuple[float, float]  #: full-resolution (column, row)
    diameter_px: float
    plateau: float
    background: float
    blur_px: float
    rss: float  #: residual sum of squares over the crop
    pixels: int
    uncertainty: dict  #: one standard deviation of each parameter (full-resolution units)
    evaluations: int
    success: bool
    censored: int = 0  #: pixels fitted as lower bounds (clipped in the source)
    field_position: tuple[float, float] | None = None  #: where the disc lies in the frame (design.md §3b)

    @property
    def angle_deg(self) -> float | None:
        """The fitted angle in [0, symmetry); None where the aperture has none."""
        return self.aperture.angle_deg if self.aperture.has_angle else None

    @property
    def aspect(self) -> float | None:
        """The fitted slit aspect; None for other shapes."""
        return self.aperture.aspect

    @property
    def parameter_count(self) -> int:
        """Parameters counted for the BIC: the family's, and the features switched on beyond them (roundness, rim, ...)."""
        return self.family.parameters + len(self.aperture.parameters) - len(self.family.aperture.parameters)

    @property
    def noise(self) -> float:
        """The residuals' RMS: the disc's noise level under this model."""
        return math.sqrt(max(self.rss, 1e-300) / self.pixels)

    @property
    def bic(self) -> float:
        """Bayesian information criterion: n·ln(RSS/n) + k·ln(n)."""
        n = self.pixels
        return n * math.log(max(self.rss, 1e-300) / n) + self.parameter_count * math.log(n)


@dataclass(frozen=True)
class JointFit:
    """Several discs fitted with one aperture: the aperture, each disc's fit, and the evidence."""

    aperture: Aperture
    fits: list[PixelFit]
    uncertainty: dict  #: one standard deviation of each shared parameter
    rss: float  #: weighted: each disc's residuals over its noise level
    pixels: int
    parameters: int
    evaluations: int

    @property
    def bic(self) -> float:
        n = self.pixels
        return n * math.log(max(self.rss, 1e-300) / n) + self.parameters * math.log(n)


def fit_discs(
    crops: Sequence[DiscCrop],
    family: Family,
    start: Aperture,
    free: Sequence[str] | None = None,
    noise: Sequence[float] | None = None,
    disc_starts: Sequence[Mapping[str, float]] | None = None,
    tolerance: float = TOLERANCE,
) -> JointFit:
    """Least-squares fit of ``crops`` sharing one aperture.

    The vector fitted is the shared aperture parameters ``free`` (default: all
    of ``start``'s :attr:`~bokehfit.apertures.Aperture.parameters`), then each
    disc's :data:`~bokehfit.fit.vector.DISC_NAMES` (and plateau where it is saturated). ``noise``
    (one per crop, default 1) divides each disc's residuals. ``disc_starts``
    (crop units) replace the outline's starting values where given. The fit stops where a step
    changes the cost or the parameters by less than ``tolerance`` of them (scipy's ftol and xtol), and a fit
    with ``noise`` also where it stalls (STALL_STEPS, STALL_RSS).
    """
    free = tuple(start.parameters) if free is None else tuple(free)
    weighted = noise is not None
    noise = np.ones(len(crops)) if noise is None else np.maximum(np.asarray(noise, dtype=np.float64), 1e-12)
    vector = fit_vector(crops, start, free, disc_starts)
    result = _solve(crops, vector, noise, tolerance, _Stall() if weighted else None)
    aperture = vector.wrapped_at(result.x)
    evidence = _evidence(result, crops, vector)
    fits = [
        _disc_fit(crop, values, block, aperture, family, result, evidence.sigma, vector)
        for crop, values, block in zip(crops, vector.discs_at(result.x), vector.discs)
    ]
    return JointFit(
        aperture=aperture,
        fits=fits,
        uncertainty=_shared_uncertainty(evidence.sigma, vector),
        rss=evidence.rss,
        pixels=evidence.pixels,
        parameters=evidence.parameters,
        evaluations=int(result.nfev),
    )


class _Stall:
    """scipy's callback after each step: it stops a weighted fit (StopIteration, scipy's way) whose last
    STALL_STEPS steps lowered its RSS by less than STALL_RSS (scipy's cost is half the RSS)."""

    def __init__(self) -> None:
        self.costs: list[float] = []

    def __call__(self, intermediate_result: OptimizeResult) -> None:
        self.costs.append(float(intermediate_result.cost))
        if len(self.costs) > STALL_STEPS and 2.0 * (self.costs[-1 - STALL_STEPS] - self.costs[-1]) < STALL_RSS:
            raise StopIteration


def _solve(crops: Sequence[DiscCrop], vector: FitVector, noise: np.ndarray, tolerance: float = TOLERANCE,
           stall: _Stall | None = None) -> OptimizeResult:
    """Bounded least squares (trust-region reflective) from the vector's start, with the model's own
    Jacobian (:func:`bokehfit.fit.objective.jacobian`); ``stall``, where given, may stop it early."""
    covers: dict = {}  # the coverages of the last steps (disc_profile)
    sparse = len(crops) > 1  # the Jacobian is block-sparse
    return least_squares(
        weighted_residuals(crops, vector, noise, covers),
        np.array(vector.start, dtype=np.float64),
        jac=jacobian(crops, vector, noise, covers, sparse),
        bounds=(vector.lower, vector.upper),
        method="trf",
        x_scale="jac",
        max_nfev=MAX_EVALUATIONS,
        ftol=tolerance,
        xtol=tolerance,
        tr_solver="lsmr" if sparse else "exact",
        callback=stall,
    )


@dataclass(frozen=True)
class _Evidence:
    """What a solved fit says of itself: its weighted RSS over its pixels and parameters, and its spread."""

    rss: float
    pixels: int
    parameters: int  #: the vector's and the levels solved for beside it
    sigma: np.ndarray  #: one standard deviation of each of the vector's parameters (NaN where unknown)


def _evidence(result: OptimizeResult, crops: Sequence[DiscCrop], vector: FitVector) -> _Evidence:
    """The fit's evidence, its uncertainties from the Jacobian at the optimum: cov = (JᵀJ)⁻¹ · RSS / (n − k)."""
    jacobian = result.jac.toarray() if hasattr(result.jac, "toarray") else result.jac
    # The levels solved for at every step count too: two per disc, one where the plateau is fitted.
    n, k = sum(c.pixels for c in crops), vector.size + vector.levels
    total = float(np.sum(result.fun**2))
    sigma = np.full(vector.size, np.nan)
    try:
        covariance = np.linalg.pinv(jacobian.T @ jacobian) * total / max(n - k, 1)
        sigma = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    except np.linalg.LinAlgError:
        pass
    return _Evidence(rss=total, pixels=n, parameters=k, sigma=sigma)


def _shared_uncertainty(sigma: np.ndarray, vector: FitVector) -> dict[str, float]:
    """One standard deviation of each shared aperture parameter, by name."""
    return {name: float(s) for name, s in zip(vector.free, sigma[: len(vector.free)])}


def _disc_fit(crop: DiscCrop, values: Mapping[str, float], block: Block, aperture: Aperture, family: Family,
              result: OptimizeResult, sigma: np.ndarray, vector: FitVector) -> PixelFit:
    """One disc's fit at the optimum, in full-resolution units: ``values`` its part of the vector."""
    shown = aperture.near() if crop.turned else aperture
    rendered = render_disc_model(shown, values, crop.size, crop.data, crop.field_position, crop.censored,
                                 crop.ignored)
    full = crop.to_full(values)
    in_full = {"cx": crop.factor, "cy": crop.factor, "diameter_px": crop.factor, "blur_px": crop.factor}
    own = sigma[block.at : block.at + len(block.names)]
    uncertainty = {name: float(s * in_full.get(name, 1.0)) for name, s in zip(block.names, own)}
    uncertainty.update(_shared_uncertainty(sigma, vector))
    return PixelFit(
        family=family,
        aperture=shown,
        center_xy=full.center_xy,
        diameter_px=full.diameter_px,
        plateau=float(rendered.plateau),
        background=float(rendered.background),
        blur_px=full.blur_px,
        rss=float(np.sum(censored_residuals(rendered.model, crop) ** 2)),
        pixels=crop.pixels,
        uncertainty=uncertainty,
        evaluations=int(result.nfev),
        success=bool(result.success) or result.status == STALLED,
        censored=0 if crop.censored is None else int(crop.censored.sum()),
        field_position=crop.field_position,
    )


def fit_disc_pixels(
    luminance: np.ndarray,
    disc: Disc,
    family: Family,
    start: Aperture,
    clipped: np.ndarray | None = None,
) -> PixelFit:
    """Least-squares fit of ``family`` to one disc's pixels, starting at the aperture ``start`` (the screen's).

    The vector fitted is the disc's :data:`~bokehfit.fit.vector.DISC_NAMES` (and its plateau where
    ``clipped`` marks some of its pixels), then ``start``'s
    :attr:`~bokehfit.apertures.Aperture.parameters` by name (bounds from
    :func:`bokehfit.fit.vector._search_bounds`); the fitted aperture keeps its angle in [0, symmetry).
    """
    return fit_discs([crop_disc(luminance, disc, clipped)], family, start).fits[0]
