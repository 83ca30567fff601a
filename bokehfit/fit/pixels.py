"""Fit one disc's pixels with a kernel: shape, angle, size, centre, levels and edge blur.

Notes
-----
The model of a disc's crop is

    I(x) = b + (p − b) · (G_σ ⊗ K)(x),

with K the exact pixel coverage of the aperture (``bokehfit.kernels.exact``)
at centre c and equal-area diameter d, and G_σ a Gaussian edge blur
(sensor, demosaicing, JPEG). Least squares (trust-region reflective, bounded)
fits c, d, σ and the aperture's own :attr:`~bokehfit.apertures.Aperture.parameters`
(the angle, the slit's aspect), solving for b and p at every step
(they enter linearly: variable projection); the starting point comes from
the disc's outline and the radial-signature screen. Crops wider than
``MAX_FIT_SIDE`` px are reduced by an integer factor first (area averaging),
which keeps the cost per disc bounded and loses nothing the shape needs.
Uncertainties are from the Jacobian at the optimum: cov = (JᵀJ)⁻¹ · RSS / (n − k).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

from bokehfit.apertures import Aperture, ParameterSpec, image_to_aperture
from bokehfit.discs import Disc
from bokehfit.fit.families import Family
from bokehfit.kernels.exact import coverage

__all__ = ["PixelFit", "disc_profile", "fit_disc_pixels", "model_window", "render_disc_model", "MAX_FIT_SIDE"]

#: Largest crop side fitted at full resolution; larger discs are reduced first.
MAX_FIT_SIDE = 36
#: Most function evaluations per fit.
MAX_EVALUATIONS = 200
#: Widest slit fitted: at aspect 1 the slit is the square, which has a model of its own.
MAX_SLIT_ASPECT = 0.8
#: Edge-blur bounds, crop pixels.
BLUR_RANGE = (0.05, 6.0)
#: The parameters of every disc, first in the fit's vector (crop units; the centre in crop pixel coordinates).
DISC_NAMES = ("cx", "cy", "diameter_px", "blur_px")
#: Fit bounds narrower than :attr:`ParameterSpec.bounds`, by parameter name.
FIT_BOUNDS = {"aspect": (0.01, MAX_SLIT_ASPECT)}
#: Parameters searched within a factor of 2 of their start (scale factors, not offsets).
RELATIVE_PARAMETERS = ("aspect", "squeeze")


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

    @property
    def angle_deg(self) -> float | None:
        """The fitted angle in [0, symmetry); None where the aperture has none."""
        return self.aperture.angle_deg if self.aperture.has_angle else None

    @property
    def aspect(self) -> float | None:
        """The fitted slit aspect; None for other shapes."""
        return self.aperture.aspect

    @property
    def bic(self) -> float:
        """Bayesian information criterion: n·ln(RSS/n) + k·ln(n)."""
        n = self.pixels
        return n * math.log(max(self.rss, 1e-300) / n) + self.family.parameters * math.log(n)


def _crop(luminance: np.ndarray, disc: Disc):
    """Square crop around the disc (reduced if wide): image, its factor, and its top-left corner."""
    reach = float(np.max(np.hypot(*(disc.outline_xy - disc.center_xy).T)))
    half = int(math.ceil(reach * 1.25 + 3))
    factor = max(1, int(math.ceil((2 * half + 1) / MAX_FIT_SIDE)))
    half = int(math.ceil((half + 1) / factor)) * factor  # a whole number of reduced pixels
    col, row = int(round(disc.center_xy[0])), int(round(disc.center_xy[1]))
    height, width = luminance.shape
    top, left = row - half, col - half
    side = 2 * half
    if top < 0 or left < 0 or top + side > height or left + side > width:
        pad = ((max(0, -top), max(0, top + side - height)), (max(0, -left), max(0, left + side - width)))
        crop = np.pad(luminance[max(0, top) : top + side, max(0, left) : left + side], pad, mode="edge")
    else:
        crop = luminance[top : top + side, left : left + side]
    if factor > 1:
        crop = cv2.resize(crop, (side // factor, side // factor), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(crop, dtype=np.float32), factor, (left, top)


def disc_profile(aperture: Aperture, disc: Mapping[str, float], size: int) -> np.ndarray:
    """The blurred unit-contrast disc (size × size) of ``aperture``; ``disc`` holds the :data:`DISC_NAMES`
    in crop units, the centre in crop pixel coordinates."""
    centre = (size - 1) / 2.0
    scale = max(disc["diameter_px"], 1e-3) * math.sqrt(math.pi) / 2.0
    (offset_xy,) = image_to_aperture([[disc["cy"] - centre, disc["cx"] - centre]])
    cover = coverage(aperture, scale, size, offset_xy=tuple(offset_xy)).astype(np.float32)
    return cv2.GaussianBlur(cover, (0, 0), max(disc["blur_px"], BLUR_RANGE[0]), borderType=cv2.BORDER_REPLICATE)


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


def _split(aperture: Aperture, names: tuple[str, ...], vector: np.ndarray) -> tuple[Aperture, dict[str, float]]:
    """The fit's vector, named: the aperture with its parameters set, and the disc's :data:`DISC_NAMES` values."""
    values = dict(zip(names, (float(v) for v in vector)))
    disc = {name: values.pop(name) for name in DISC_NAMES}
    return (aperture.replace(**values) if values else aperture), disc


def _levels(profile: np.ndarray, data: np.ndarray) -> tuple[float, float]:
    """Background and plateau that fit ``data`` best for this profile (2×2 linear least squares)."""
    ones = 1.0 - profile
    a11, a12, a22 = float(ones @ ones), float(ones @ profile), float(profile @ profile)
    r1, r2 = float(ones @ data), float(profile @ data)
    det = a11 * a22 - a12 * a12
    if abs(det) < 1e-12:
        return float(data.mean()), float(data.mean())
    return (a22 * r1 - a12 * r2) / det, (a11 * r2 - a12 * r1) / det


def render_disc_model(
    aperture: Aperture, disc: Mapping[str, float], size: int, data: np.ndarray
) -> tuple[np.ndarray, float, float]:
    """Model crop (flattened) with its best levels for ``data``: (model, background, plateau)."""
    profile = disc_profile(aperture, disc, size).ravel().astype(np.float64)
    background, plateau = _levels(profile, data)
    return background + (plateau - background) * profile, background, plateau


def fit_disc_pixels(
    luminance: np.ndarray,
    disc: Disc,
    family: Family,
    start: Aperture,
) -> PixelFit:
    """Least-squares fit of ``family`` to the disc's pixels, starting at the aperture ``start`` (the screen's).

    The vector fitted is the disc's :data:`DISC_NAMES`, then ``start``'s
    :attr:`~bokehfit.apertures.Aperture.parameters` by name (bounds from
    :func:`_search_bounds`); the fitted aperture keeps its angle in [0, symmetry).
    """
    crop, factor, (left, top) = _crop(luminance, disc)
    size = crop.shape[0]
    # Start: the outline's centre and size, a one-pixel blur. The background and
    # plateau enter linearly and are solved for at every step (variable projection).
    cx0 = (disc.center_xy[0] - left + 0.5) / factor - 0.5
    cy0 = (disc.center_xy[1] - top + 0.5) / factor - 0.5
    diameter0 = disc.diameter_px / factor
    x0 = [cx0, cy0, diameter0, 0.7]
    lower = [cx0 - 3, cy0 - 3, 0.5 * diameter0, BLUR_RANGE[0]]
    upper = [cx0 + 3, cy0 + 3, 1.5 * diameter0, BLUR_RANGE[1]]
    parameters = start.parameters
    for name, value in start.values.items():
        first, low, high = _search_bounds(parameters[name], value)
        x0.append(first)
        lower.append(low)
        upper.append(high)
    names = DISC_NAMES + tuple(start.values)
    data = crop.ravel().astype(np.float64)

    def residuals(vector):
        return render_disc_model(*_split(start, names, vector), size, data)[0] - data

    result = least_squares(
        residuals,
        np.array(x0, dtype=np.float64),
        bounds=(lower, upper),
        method="trf",
        x_scale="jac",
        max_nfev=MAX_EVALUATIONS,
        diff_step=1e-4,
    )
    _, found = _split(start, names, result.x)
    fitted = {name: float(value) for name, value in zip(names[len(DISC_NAMES):], result.x[len(DISC_NAMES):])}
    for name, value in fitted.items():
        if parameters[name].periodic is not None:
            fitted[name] = value % parameters[name].periodic
    aperture = start.replace(**fitted) if fitted else start
    _, background, plateau = render_disc_model(aperture, found, size, data)
    rss = float(np.sum(result.fun**2))
    n, k = data.size, len(names) + 2
    sigma = np.full(len(names), np.nan)
    try:
        covariance = np.linalg.inv(result.jac.T @ result.jac) * rss / max(n - k, 1)
        sigma = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    except np.linalg.LinAlgError:
        pass
    in_full = {"cx": factor, "cy": factor, "diameter_px": factor, "blur_px": factor}
    uncertainty = {name: float(s * in_full.get(name, 1.0)) for name, s in zip(names, sigma)}
    # The area-averaging reduction adds a box blur of variance (factor² − 1)/12 px².
    blur = math.sqrt(max((found["blur_px"] * factor) ** 2 - (factor * factor - 1) / 12.0, 0.0))
    return PixelFit(
        family=family,
        aperture=aperture,
        center_xy=(left + (found["cx"] + 0.5) * factor - 0.5, top + (found["cy"] + 0.5) * factor - 0.5),
        diameter_px=found["diameter_px"] * factor,
        plateau=float(plateau),
        background=float(background),
        blur_px=blur,
        rss=rss,
        pixels=n,
        uncertainty=uncertainty,
        evaluations=int(result.nfev),
        success=bool(result.success),
    )


def model_window(fit: PixelFit, left: int, top: int, size: int) -> np.ndarray:
    """The fitted model of a disc on a full-resolution window (size × size, top-left at (left, top))."""
    disc = {"cx": fit.center_xy[0] - left, "cy": fit.center_xy[1] - top, "diameter_px": fit.diameter_px,
            "blur_px": fit.blur_px}
    profile = disc_profile(fit.aperture, disc, size)
    return (fit.background + (fit.plateau - fit.background) * profile).astype(np.float32)
