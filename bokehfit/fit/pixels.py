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
its own parameters and the shared ones), so finite differences cost a few
renders of every disc, not one per parameter. Each disc's residuals are
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
from scipy.optimize import least_squares

from bokehfit.apertures import Aperture, ParameterSpec
from bokehfit.discs import Disc
from bokehfit.fit.crop import DiscCrop, crop_disc
from bokehfit.fit.disc_model import BLUR_RANGE, render_disc_model
from bokehfit.fit.families import Family

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
#: Widest slit fitted: at aspect 1 the slit is the square, which has a model of its own.
MAX_SLIT_ASPECT = 0.8
#: The parameters of every disc, first in the fit's vector (crop units; the centre in crop pixel coordinates).
DISC_NAMES = ("cx", "cy", "diameter_px", "blur_px")
#: Fit bounds narrower than :attr:`ParameterSpec.bounds`, by parameter name.
FIT_BOUNDS = {"aspect": (0.01, MAX_SLIT_ASPECT), "vignetting_radius": (1.0, 4.0), "vignetting_shift": (-4.0, 4.0),
              "squeeze": (0.25, 4.0)}
#: Parameters searched within a factor of 2 of their start (scale factors, not offsets).
RELATIVE_PARAMETERS = ("aspect", "squeeze")
#: A saturated disc's plateau is searched up to this many times the clip level.
MAX_PLATEAU_OVER_CLIP = 50.0


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


def _search_bounds(parameter: ParameterSpec, start: float) -> tuple[float, float, float]:
    """(start, lower, upper) of one aperture parameter for the fit.

    A periodic parameter (the angle) is searched half a period either side of
    its start; the others within their bounds (:data:`FIT_BOUNDS` where the fit
    asks for less), scale factors only within a factor of 2 of the start.
    """
    if parameter.periodic is not None:
        return start, start - 0.5 * parameter.periodic, start + 0.5 * parameter.periodic
    low, high = FIT_BOUNDS.get(parameter.name, parameter.bounds)
    start = min(max(start, low), high)
    if parameter.name in RELATIVE_PARAMETERS:
        low, high = max(low, 0.5 * start), min(high, 2.0 * start)
    return start, low, high


def _residuals(model: np.ndarray, crop: DiscCrop) -> np.ndarray:
    """model − data; where the source is clipped only a model below the recorded value is an error;
    where the light is not the disc's, none."""
    residual = model - crop.data
    if crop.censored is not None:
        residual[crop.censored] = np.minimum(residual[crop.censored], 0.0)
    if crop.ignored is not None:
        residual[crop.ignored] = 0.0
    return residual


def _disc_vector(crop: DiscCrop) -> tuple[list[str], list[float], list[float], list[float]]:
    """One disc's names, start, lower and upper bounds (crop units)."""
    start = crop.start
    names = list(DISC_NAMES)
    x0 = [start[n] for n in DISC_NAMES]
    lower = [start["cx"] - 3, start["cy"] - 3, 0.5 * start["diameter_px"], BLUR_RANGE[0]]
    upper = [start["cx"] + 3, start["cy"] + 3, 1.5 * start["diameter_px"], BLUR_RANGE[1]]
    clip = crop.clip_level
    if clip is not None:  # a saturated disc: its plateau is somewhere above the clip
        names.append("plateau")
        x0.append(max(crop.disc.plateau, clip) * 1.5)
        lower.append(clip)
        upper.append(clip * MAX_PLATEAU_OVER_CLIP)
    return names, x0, lower, upper


def _shared_vector(start: Aperture, free: Sequence[str]) -> tuple[list[float], list[float], list[float]]:
    parameters = start.parameters
    values = start.values
    x0, lower, upper = [], [], []
    for name in free:
        first, low, high = _search_bounds(parameters[name], values[name])
        x0.append(first)
        lower.append(low)
        upper.append(high)
    return x0, lower, upper


def _wrapped(aperture: Aperture, values: Mapping[str, float]) -> Aperture:
    """``aperture`` with ``values`` set, periodic ones (the angle) reduced to [0, period)."""
    parameters = aperture.parameters
    wrapped = {n: (v % parameters[n].periodic if parameters[n].periodic is not None else v) for n, v in values.items()}
    return aperture.replace(**wrapped) if wrapped else aperture


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
) -> JointFit:
    """Least-squares fit of ``crops`` sharing one aperture.

    The vector fitted is the shared aperture parameters ``free`` (default: all
    of ``start``'s :attr:`~bokehfit.apertures.Aperture.parameters`), then each
    disc's :data:`DISC_NAMES` (and plateau where it is saturated). ``noise``
    (one per crop, default 1) divides each disc's residuals. ``disc_starts``
    (crop units) replace the outline's starting values where given.
    """
    free = tuple(start.parameters) if free is None else tuple(free)
    noise = np.ones(len(crops)) if noise is None else np.maximum(np.asarray(noise, dtype=np.float64), 1e-12)
    x0, lower, upper = _shared_vector(start, free)
    blocks = []
    for i, crop in enumerate(crops):
        names, d0, dlow, dhigh = _disc_vector(crop)
        if disc_starts is not None and disc_starts[i] is not None:
            d0 = [min(max(disc_starts[i].get(n, v), lo), hi) for n, v, lo, hi in zip(names, d0, dlow, dhigh)]
        blocks.append((len(x0), names))
        x0 += d0
        lower += dlow
        upper += dhigh
    shared = len(free)

    def split(vector):
        aperture = start.replace(**dict(zip(free, (float(v) for v in vector[:shared])))) if shared else start
        discs = [dict(zip(names, (float(v) for v in vector[at : at + len(names)]))) for at, names in blocks]
        return aperture, discs

    covers: dict = {}  # the coverages of the last steps (disc_profile)

    def residuals(vector):
        aperture, discs = split(vector)
        turned = aperture.near() if any(c.turned for c in crops) else aperture
        parts = [
            _residuals(render_disc_model(turned if c.turned else aperture, d, c.size, c.data, c.field_position,
                                         c.censored, c.ignored, covers).model, c) / s
            for c, d, s in zip(crops, discs, noise)
        ]
        return np.concatenate(parts)

    rows = [c.data.size for c in crops]
    sparsity = None
    if len(crops) > 1:
        sparsity = np.zeros((sum(rows), len(x0)), dtype=bool)
        row = 0
        for (at, names), count in zip(blocks, rows):
            sparsity[row : row + count, :shared] = True
            sparsity[row : row + count, at : at + len(names)] = True
            row += count
    result = least_squares(
        residuals,
        np.array(x0, dtype=np.float64),
        bounds=(lower, upper),
        method="trf",
        x_scale="jac",
        max_nfev=MAX_EVALUATIONS,
        diff_step=1e-4,
        ftol=TOLERANCE,
        xtol=TOLERANCE,
        jac_sparsity=sparsity,
        tr_solver="exact" if sparsity is None else "lsmr",
    )
    _, discs = split(result.x)
    aperture = _wrapped(start, {name: float(v) for name, v in zip(free, result.x[:shared])})
    jacobian = result.jac.toarray() if hasattr(result.jac, "toarray") else result.jac
    # The levels solved for at every step count too: two per disc, one where the plateau is fitted.
    n, k = sum(c.pixels for c in crops), len(x0) + sum(1 if "plateau" in names else 2 for _, names in blocks)
    total = float(np.sum(result.fun**2))
    sigma = np.full(len(x0), np.nan)
    try:
        covariance = np.linalg.pinv(jacobian.T @ jacobian) * total / max(n - k, 1)
        sigma = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    except np.linalg.LinAlgError:
        pass
    fits, row = [], 0
    for crop, values, (at, names), count, scale in zip(crops, discs, blocks, rows, noise):
        shown = aperture.near() if crop.turned else aperture
        rendered = render_disc_model(shown, values, crop.size, crop.data, crop.field_position, crop.censored,
                                     crop.ignored)
        rss = float(np.sum(_residuals(rendered.model, crop) ** 2))
        full = crop.to_full(values)
        in_full = {"cx": crop.factor, "cy": crop.factor, "diameter_px": crop.factor, "blur_px": crop.factor}
        uncertainty = {name: float(s * in_full.get(name, 1.0)) for name, s in zip(names, sigma[at : at + len(names)])}
        uncertainty.update({name: float(s) for name, s in zip(free, sigma[:shared])})
        fits.append(PixelFit(
            family=family,
            aperture=shown,
            center_xy=full.center_xy,
            diameter_px=full.diameter_px,
            plateau=float(rendered.plateau),
            background=float(rendered.background),
            blur_px=full.blur_px,
            rss=rss,
            pixels=crop.pixels,
            uncertainty=uncertainty,
            evaluations=int(result.nfev),
            success=bool(result.success),
            censored=0 if crop.censored is None else int(crop.censored.sum()),
            field_position=crop.field_position,
        ))
        row += count
    return JointFit(
        aperture=aperture,
        fits=fits,
        uncertainty={name: float(s) for name, s in zip(free, sigma[:shared])},
        rss=total,
        pixels=n,
        parameters=k,
        evaluations=int(result.nfev),
    )


def fit_disc_pixels(
    luminance: np.ndarray,
    disc: Disc,
    family: Family,
    start: Aperture,
    clipped: np.ndarray | None = None,
) -> PixelFit:
    """Least-squares fit of ``family`` to one disc's pixels, starting at the aperture ``start`` (the screen's).

    The vector fitted is the disc's :data:`DISC_NAMES` (and its plateau where
    ``clipped`` marks some of its pixels), then ``start``'s
    :attr:`~bokehfit.apertures.Aperture.parameters` by name (bounds from
    :func:`_search_bounds`); the fitted aperture keeps its angle in [0, symmetry).
    """
    return fit_discs([crop_disc(luminance, disc, clipped)], family, start).fits[0]
