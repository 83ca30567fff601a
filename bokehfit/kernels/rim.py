"""The ``rim`` profile's light on a pixel grid: tabulated on sub-pixels, with its bound and its slopes.

The weight w = 1 + rim·(2ρ² − 1) of design.md §3b has no closed form over a pixel's share of a
rounded or clipped outline (:mod:`bokehfit.kernels.exact` integrates the plain coverage exactly):
:func:`rim_coverage` weights each sub-pixel's exact coverage by w at its centre, and
:func:`rim_coverage_slopes` gives that light's derivatives as the fit moves the disc.
"""

from __future__ import annotations

import math

import numpy as np

from bokehfit.apertures import Aperture, Outline, image_to_aperture
from bokehfit.kernels.exact import CoverageSlopes, coverage, coverage_slopes

__all__ = ["RIM_SUPERSAMPLE", "RHO_STEP", "fan_gradient", "radial_fraction", "rim_coverage", "rim_coverage_slopes"]

#: Sub-pixels a side of :func:`rim_coverage` by default.
RIM_SUPERSAMPLE = 8


def radial_fraction(points: np.ndarray, polygon: np.ndarray) -> tuple[np.ndarray, float]:
    """ρ of design.md §3b for ``points`` of a polygon star-shaped about the origin, and max |∇ρ|.

    In the fan triangle (0, a, b) whose angle holds p, ρ = (p·n)/(a·n) with n
    the normal of the edge ab: linear, with gradient n/(a·n), whose length is
    one over the distance from the origin to the edge's line. ρ is defined
    (and grows past 1) outside the polygon too.
    """
    polygon = np.asarray(polygon, dtype=np.float64)
    angles = np.arctan2(polygon[:, 1], polygon[:, 0])
    start = int(np.argmin(angles))
    polygon = np.roll(polygon, -start, axis=0)
    angles = np.unwrap(np.roll(angles, -start))
    a, b = polygon, np.roll(polygon, -1, axis=0)
    normal = np.stack([b[:, 1] - a[:, 1], a[:, 0] - b[:, 0]], axis=-1)
    support = np.sum(a * normal, axis=-1)  # a·n = b·n > 0 for a counter-clockwise fan
    theta = np.arctan2(points[..., 1], points[..., 0])
    theta = np.where(theta < angles[0], theta + 2.0 * np.pi, theta)
    k = np.clip(np.searchsorted(angles, theta, side="right") - 1, 0, len(polygon) - 1)
    rho = np.sum(points * normal[k], axis=-1) / support[k]
    return rho, fan_gradient(polygon)


def fan_gradient(polygon: np.ndarray) -> float:
    """max |∇ρ| over a polygon star-shaped about the origin: one over the least distance from the
    origin to an edge's line (:func:`radial_fraction`)."""
    polygon = np.asarray(polygon, dtype=np.float64)
    a, b = polygon, np.roll(polygon, -1, axis=0)
    normal = np.stack([b[:, 1] - a[:, 1], a[:, 0] - b[:, 0]], axis=-1)
    return float(np.max(np.hypot(normal[:, 0], normal[:, 1]) / np.abs(np.sum(a * normal, axis=-1))))


def rim_coverage(
    aperture: Aperture,
    scale: float,
    size: int,
    field_position=None,
    supersample: int = RIM_SUPERSAMPLE,
    max_chord_error: float = 1e-6,
    offset_xy: tuple[float, float] = (0.0, 0.0),
) -> tuple[np.ndarray, float]:
    """Light of an aperture with a ``rim`` profile on each pixel (tabulated), and its L1 error bound.

    Notes
    -----
    The weight w = 1 + rim·(2ρ² − 1) has no closed-form integral over the
    intersection of a pixel with a rounded or clipped outline. Each pixel is
    cut into ``supersample``² sub-pixels; a sub-pixel's exact area coverage
    (:func:`coverage` on the finer grid, clipped by the vignetting) is
    weighted by w at its centre. ρ is the radial fraction of the unclipped
    outline's polygon (arcs within ``max_chord_error`` of unit-area units).
    w is Lipschitz with constant L = 4·|rim|·max ρ·max|∇ρ| over the shape, so
    a sub-pixel of side h = 1/supersample is off by at most L·h/√2 times its
    covered area: the kernel, normalised to the light it holds, is within

        L1 ≤ (1 + |rim|)·L·h/√2 / (1 − |rim|)

    of the exact one (the last factor bounds the normalisation's share). In
    practice the error is far smaller: inside the outline w is smooth and the
    midpoint rule is second order; only sub-pixels on the edge or a fan seam
    see first-order error.

    Returns
    -------
    image : ndarray of shape (size, size), float64
        Light per pixel in px² of unit-weight area (sums to the area for rim 0).
    bound : float
        The L1 bound above, for the kernel normalised to sum to 1.
    """
    dx, dy = offset_xy
    fine = coverage(aperture, scale * supersample, size * supersample, field_position=field_position,
                    offset_xy=(dx * supersample, dy * supersample))
    # The weight only where there is light: the sub-pixels the shape does not touch stay 0.
    rows, cols, points = _subpixel_points(fine != 0, scale, supersample, offset_xy)
    polygon = aperture.outline().polyline(max_chord_error)
    if aperture.mask is None:  # the model's own ρ: exact, and no search of the polygon's fan per point
        rho, gradient = aperture.radial_fraction(points), fan_gradient(polygon)
    else:
        rho, gradient = radial_fraction(points, polygon)
    weighted = np.zeros_like(fine)
    weighted[rows, cols] = fine[rows, cols] * (1.0 + aperture.rim * (2.0 * rho * rho - 1.0))
    image = _pixels(weighted, size, supersample)
    rho_max = 1.0 + gradient * math.sqrt(2.0) / (scale * supersample)  # sub-pixel centres just outside the edge
    lipschitz = 4.0 * abs(aperture.rim) * rho_max * gradient / scale  # per pixel
    h = 1.0 / supersample
    bound = (1.0 + abs(aperture.rim)) * lipschitz * h / math.sqrt(2.0) / max(1.0 - abs(aperture.rim), 1e-12)
    return image, bound


def _subpixel_points(where: np.ndarray, scale: float, supersample: int,
                     offset_xy: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sub-pixels of a fine grid (image rows) where ``where`` holds: their rows, columns, and centres in
    the aperture's frame from the shape's centre (unit-area units)."""
    centre = (where.shape[0] - 1) / 2.0
    coordinates = (np.arange(where.shape[0]) - centre) / (scale * supersample)  # unit-area units
    rows, cols = np.nonzero(where)
    offsets_rc = np.stack([coordinates[rows], coordinates[cols]], axis=-1)
    return rows, cols, image_to_aperture(offsets_rc) - np.array(offset_xy, dtype=np.float64) / scale


def _pixels(fine: np.ndarray, size: int, supersample: int) -> np.ndarray:
    """A fine grid's sub-pixels averaged into the size × size pixels they make up."""
    return fine.reshape(size, supersample, size, supersample).sum(axis=(1, 3)) / supersample**2


#: Step (unit-area units) of the central differences that give ρ's gradient for :func:`rim_coverage_slopes`.
RHO_STEP = 1e-6


def rim_coverage_slopes(
    aperture: Aperture,
    scale: float,
    size: int,
    offset_xy: tuple[float, float] = (0.0, 0.0),
    field_position=None,
    flow: np.ndarray | None = None,
    supersample: int = RIM_SUPERSAMPLE,
    outline: Outline | None = None,
) -> CoverageSlopes:
    """:func:`rim_coverage`'s light (its model's own ρ: no ``mask``) and its derivatives by the offset, the scale
    and, given a ``flow``, a turn, as :func:`coverage_slopes` gives them for the plain coverage.

    Notes
    -----
    :func:`rim_coverage` sums, over each pixel's sub-pixels, the sub-pixel's exact coverage C times the
    weight w = 1 + rim·(2ρ² − 1) at its centre p. When the shape moves, both move with it: C by the exact
    slopes of the coverage on the fine grid (:func:`coverage_slopes`), and w because ρ is the shape's own
    (at a fixed place, p from the shape's centre changes: by −1/s per px of offset, by −p/s per unit of
    scale, by −M·p under a flow M; ρ is carried along by every linear map of the shape, a ratio along a
    ray from its centre). So each slope is Σ (∂C·w + C·∇w·∂p) over the sub-pixels, ∇w = 4·rim·ρ·∇ρ, ∇ρ by
    central differences of the model's ρ (RHO_STEP): the exact derivative of the tabulated light the fit
    sees, up to those differences (ρ is linear in each fan triangle of a polygon, smooth on arcs). The
    light is linear in the rim: its slope by the rim is Σ C·(2ρ² − 1) (``by_rim``).
    ``outline`` is ``aperture.outline(field_position)`` where the caller has it.
    """
    if aperture.mask is not None:
        raise ValueError("rim_coverage_slopes takes the model's own ρ: an aperture without a mask")
    outline = aperture.outline(field_position) if outline is None else outline
    dx, dy = offset_xy
    fine = coverage_slopes(outline, scale * supersample, size * supersample, (dx * supersample, dy * supersample),
                           flow=flow)
    moved = [supersample * fine.by_offset_x, supersample * fine.by_offset_y, supersample * fine.by_scale]
    if flow is not None:
        moved.append(fine.by_flow)
    live = (fine.cover != 0) | np.logical_or.reduce([m != 0 for m in moved])
    rows, cols, points = _subpixel_points(live, scale, supersample, offset_xy)
    rho = aperture.radial_fraction(points)
    gradient = np.stack([(aperture.radial_fraction(points + step) - aperture.radial_fraction(points - step))
                         / (2.0 * RHO_STEP) for step in (np.array([RHO_STEP, 0.0]), np.array([0.0, RHO_STEP]))],
                        axis=-1)
    weight = 1.0 + aperture.rim * (2.0 * rho * rho - 1.0)
    by_weight = 4.0 * aperture.rim * rho[:, None] * gradient  # ∇w at the sub-pixel centres
    # How p (from the shape's centre) changes at a fixed sub-pixel: offset x, offset y, scale, flow.
    p_moves = [np.array([-1.0 / scale, 0.0]), np.array([0.0, -1.0 / scale]), -points / scale]
    if flow is not None:
        p_moves.append(-points @ np.asarray(flow, dtype=np.float64).T)
    cover = fine.cover[rows, cols]

    def pixels(values: np.ndarray) -> np.ndarray:
        grid = np.zeros_like(fine.cover)
        grid[rows, cols] = values
        return _pixels(grid, size, supersample)

    slopes = [pixels(m[rows, cols] * weight + cover * np.sum(by_weight * dp, axis=-1))
              for m, dp in zip(moved, p_moves)]
    return CoverageSlopes(pixels(cover * weight), *slopes[:3], slopes[3] if flow is not None else None,
                          by_rim=pixels(cover * (2.0 * rho * rho - 1.0)))
