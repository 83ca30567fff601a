"""Fit one disc's pixels with a kernel: shape, angle, size, centre, levels and edge blur.

Notes
-----
The model of a disc's crop is

    I(x) = b + (p − b) · (G_σ ⊗ K)(x),

with K the exact pixel coverage of the aperture (``bokehfit.kernels.exact``)
at centre c, equal-area diameter d and angle a, and G_σ a Gaussian edge blur
(sensor, demosaicing, JPEG). Least squares (trust-region reflective, bounded)
fits c, d, a, σ (and the slit's aspect), solving for b and p at every step
(they enter linearly: variable projection); the starting point comes from
the disc's outline and the radial-signature screen. Crops wider than
``MAX_FIT_SIDE`` px are reduced by an integer factor first (area averaging),
which keeps the cost per disc bounded and loses nothing the shape needs.
Uncertainties are from the Jacobian at the optimum: cov = (JᵀJ)⁻¹ · RSS / (n − k).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

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


@dataclass(frozen=True)
class PixelFit:
    """One family fitted to one disc's pixels."""

    family: Family
    center_xy: tuple[float, float]  #: full-resolution (column, row)
    diameter_px: float
    angle_deg: float | None
    aspect: float | None
    plateau: float
    background: float
    blur_px: float
    rss: float  #: residual sum of squares over the crop
    pixels: int
    uncertainty: dict  #: one standard deviation of each parameter (full-resolution units)
    evaluations: int
    success: bool

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


def disc_profile(family: Family, params: np.ndarray, size: int) -> np.ndarray:
    """The blurred unit-contrast disc (size × size) for shape parameters in crop units:
    (cx, cy, d, σ[, angle][, aspect]), the centre in crop pixel coordinates."""
    cx, cy, diameter, blur = params[:4]
    angle = params[4] if family.shape != "circle" else 0.0
    aspect = params[5] if family.shape == "slit" else None
    aperture = family.aperture(float(angle), float(aspect) if aspect is not None else None)
    centre = (size - 1) / 2.0
    scale = max(diameter, 1e-3) * math.sqrt(math.pi) / 2.0
    cover = coverage(aperture, scale, size, offset_xy=(cx - centre, -(cy - centre))).astype(np.float32)
    return cv2.GaussianBlur(cover, (0, 0), max(blur, BLUR_RANGE[0]), borderType=cv2.BORDER_REPLICATE)


def _levels(profile: np.ndarray, data: np.ndarray) -> tuple[float, float]:
    """Background and plateau that fit ``data`` best for this profile (2×2 linear least squares)."""
    ones = 1.0 - profile
    a11, a12, a22 = float(ones @ ones), float(ones @ profile), float(profile @ profile)
    r1, r2 = float(ones @ data), float(profile @ data)
    det = a11 * a22 - a12 * a12
    if abs(det) < 1e-12:
        return float(data.mean()), float(data.mean())
    return (a22 * r1 - a12 * r2) / det, (a11 * r2 - a12 * r1) / det


def render_disc_model(family: Family, params: np.ndarray, size: int, data: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Model crop (flattened) with its best levels for ``data``: (model, background, plateau)."""
    profile = disc_profile(family, params, size).ravel().astype(np.float64)
    background, plateau = _levels(profile, data)
    return background + (plateau - background) * profile, background, plateau


def fit_disc_pixels(
    luminance: np.ndarray,
    disc: Disc,
    family: Family,
    angle_deg: float,
    aspect: float | None = None,
) -> PixelFit:
    """Least-squares fit of ``family`` to the disc's pixels, starting at ``angle_deg``."""
    crop, factor, (left, top) = _crop(luminance, disc)
    size = crop.shape[0]
    # Start: the outline's centre and size, a one-pixel blur. The background and
    # plateau enter linearly and are solved for at every step (variable projection).
    cx0 = (disc.center_xy[0] - left + 0.5) / factor - 0.5
    cy0 = (disc.center_xy[1] - top + 0.5) / factor - 0.5
    start = [cx0, cy0, disc.diameter_px / factor, 0.7]
    lower = [cx0 - 3, cy0 - 3, 0.5 * start[2], BLUR_RANGE[0]]
    upper = [cx0 + 3, cy0 + 3, 1.5 * start[2], BLUR_RANGE[1]]
    symmetry = family.aperture().symmetry_deg
    if family.shape != "circle":
        start.append(angle_deg)
        lower.append(angle_deg - 0.5 * symmetry)
        upper.append(angle_deg + 0.5 * symmetry)
    if family.shape == "slit":
        start.append(min(aspect, MAX_SLIT_ASPECT))
        lower.append(max(0.01, 0.5 * start[-1]))
        upper.append(min(MAX_SLIT_ASPECT, 2.0 * start[-1]))
    data = crop.ravel().astype(np.float64)

    def residuals(params):
        return render_disc_model(family, params, size, data)[0] - data

    result = least_squares(
        residuals,
        np.array(start, dtype=np.float64),
        bounds=(lower, upper),
        method="trf",
        x_scale="jac",
        max_nfev=MAX_EVALUATIONS,
        diff_step=1e-4,
    )
    params = result.x
    _, background, plateau = render_disc_model(family, params, size, data)
    rss = float(np.sum(result.fun**2))
    n, k = data.size, len(params) + 2
    names = ["cx", "cy", "diameter_px", "blur_px", "angle_deg", "aspect"][: len(params)]
    sigma = np.full(len(params), np.nan)
    try:
        covariance = np.linalg.inv(result.jac.T @ result.jac) * rss / max(n - k, 1)
        sigma = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    except np.linalg.LinAlgError:
        pass
    in_full = {"cx": factor, "cy": factor, "diameter_px": factor, "blur_px": factor}
    uncertainty = {name: float(s * in_full.get(name, 1.0)) for name, s in zip(names, sigma)}
    angle = None
    if family.shape != "circle":
        angle = float(params[4] % symmetry)
    # The area-averaging reduction adds a box blur of variance (factor² − 1)/12 px².
    blur = math.sqrt(max((params[3] * factor) ** 2 - (factor * factor - 1) / 12.0, 0.0))
    return PixelFit(
        family=family,
        center_xy=(left + (params[0] + 0.5) * factor - 0.5, top + (params[1] + 0.5) * factor - 0.5),
        diameter_px=float(params[2] * factor),
        angle_deg=angle,
        aspect=float(params[5]) if family.shape == "slit" else None,
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
    params = np.array(
        [fit.center_xy[0] - left, fit.center_xy[1] - top, fit.diameter_px, fit.blur_px]
        + ([fit.angle_deg] if fit.family.shape != "circle" else [])
        + ([fit.aspect] if fit.family.shape == "slit" else [])
    )
    profile = disc_profile(fit.family, params, size)
    return (fit.background + (fit.plateau - fit.background) * profile).astype(np.float32)
