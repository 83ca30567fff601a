"""A region's sub-pixel outline and its geometry: the iso-contour around a seed, its area and
centroid, its concavities, the gradient along it, and the circle through points of it.

Notes
-----
An outline is the sub-pixel iso-contour at a level (marching squares) around a seed: of the
contours there, the largest that holds the seed. The crop is padded with the background, so
that a contour cut by the frame closes just outside it (its points there lie outside
[0, size − 1]). Coordinates are (x, y) = (column, row) in the crop.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage
from skimage import measure

from bokehfit.discs.levels import Window, _median

__all__ = ["polygon_area_centroid"]

#: Fixed-point factor of outline points given to OpenCV (4 fractional bits).
_SUBPIXEL = 16


def _edge_gradient(crop: np.ndarray, outline: np.ndarray, gradients: tuple[np.ndarray, np.ndarray] | None = None,
                   noise: float = 0.0, smoothing_px: float = 0.0) -> float:
    """Median gradient magnitude of the image along the outline (bilinear samples); ``gradients``, the
    crop's (rows, columns) gradients where the caller has them already (:func:`_crop_gradients`).

    Where ``noise`` (the standard deviation of the crop's white pixel noise before a Gaussian smoothing of
    ``smoothing_px``, if any) is given, the noise's share is taken out of each sample's squared magnitude
    (:func:`_gradient_noise_power`) before the median: noise adds its power to the gradient's, so that
    an edge whose slope is comparable to the noise reads steeper than it is."""
    gy, gx = _crop_gradients(crop) if gradients is None else gradients
    coords = [outline[:, 1], outline[:, 0]]  # (row, col)
    gx_at = ndimage.map_coordinates(gx, coords, order=1, mode="nearest")
    gy_at = ndimage.map_coordinates(gy, coords, order=1, mode="nearest")
    if noise <= 0.0:
        return float(_median(np.hypot(gx_at, gy_at)))
    power = gx_at * gx_at + gy_at * gy_at - _gradient_noise_power(noise, smoothing_px, outline)
    return math.sqrt(max(float(_median(power)), 0.0))


def _gradient_noise_power(noise: float, smoothing_px: float, points: np.ndarray) -> np.ndarray:
    """The expected squared magnitude that white pixel noise of standard deviation ``noise`` gives the gradient
    :func:`_edge_gradient` samples at each of ``points`` ((x, y) in the crop): the crop smoothed by a Gaussian
    of ``smoothing_px`` (none: 0) and differenced as :func:`_crop_gradients` does, then interpolated
    bilinearly from four neighbouring samples, whose noise is correlated (:func:`_gradient_noise_covariances`).
    Exact for a point at least the kernel's reach inside the crop."""
    c00, c01, c10, c11, c1m = _gradient_noise_covariances(float(smoothing_px))
    fr, fc = points[:, 1] % 1.0, points[:, 0] % 1.0
    wa, wb, wc, wd = (1 - fr) * (1 - fc), (1 - fr) * fc, fr * (1 - fc), fr * fc  # (r, c), (r, c+1), (r+1, c), (r+1, c+1)
    variance = ((wa * wa + wb * wb + wc * wc + wd * wd) * c00 + 2.0 * ((wa * wb + wc * wd) * c01 + (wa * wc + wb * wd) * c10
                + wa * wd * c11 + wb * wc * c1m))
    return noise * noise * variance


@functools.lru_cache(maxsize=256)
def _gradient_noise_covariances(smoothing_px: float) -> tuple[float, float, float, float, float]:
    """The covariances, per unit noise variance and summed over the two components, of the gradient samples
    :func:`_crop_gradients` gives at a pixel and at its neighbours (0, 0), (0, 1), (1, 0), (1, 1) and (1, −1)
    (rows, columns) away, of white noise smoothed by a Gaussian of ``smoothing_px`` (0: none; then 1, 0, 0, 0,
    0): from the impulse response of the smoothing and the differences."""
    reach = int(math.ceil(4.0 * smoothing_px)) + 3
    impulse = np.zeros((2 * reach + 1, 2 * reach + 1), np.float32)
    impulse[reach, reach] = 1.0
    if smoothing_px > 0.0:
        impulse = cv2.GaussianBlur(impulse, (0, 0), smoothing_px, borderType=cv2.BORDER_REPLICATE)
    responses = [r.astype(np.float64) for r in _crop_gradients(impulse)]
    # The responses are zero beyond the kernel's reach, well inside the impulse's frame: a roll is a shift.
    return tuple(float(sum(np.sum(h * np.roll(h, shift, axis=(0, 1))) for h in responses))
                 for shift in ((0, 0), (0, 1), (1, 0), (1, 1), (1, -1)))


def _crop_gradients(crop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The crop's gradients along its rows and columns (float32), as :func:`_edge_gradient` samples them."""
    return tuple(np.gradient(crop.astype(np.float32)))


def _outline(crop: np.ndarray, level: float, background: float, seed_rc: tuple[float, float]) -> np.ndarray | None:
    """Closed 50 % contour around ``seed_rc`` (row, col in the crop), or None."""
    # Pad with the background so contours cut by the frame close just outside it.
    padded = np.pad(crop, 1, mode="constant", constant_values=min(background, level - 1e-6))
    # Trace only the regions above the level whose boxes hold the seed (the contour around the
    # seed bounds one of them): a large window over texture holds many others.
    count, labels, stats, _ = cv2.connectedComponentsWithStats((padded > level).view(np.uint8), connectivity=8)
    x0, y0 = stats[:, cv2.CC_STAT_LEFT], stats[:, cv2.CC_STAT_TOP]
    x1, y1 = x0 + stats[:, cv2.CC_STAT_WIDTH], y0 + stats[:, cv2.CC_STAT_HEIGHT]
    row, col = seed_rc[0] + 1.0, seed_rc[1] + 1.0
    hit = (x0 <= col + 1) & (col - 1 <= x1) & (y0 <= row + 1) & (row - 1 <= y1)
    hit[0] = False  # the background
    if not hit.any():
        return None
    r0, c0 = max(0, int(y0[hit].min()) - 1), max(0, int(x0[hit].min()) - 1)
    r1, c1 = int(y1[hit].max()) + 1, int(x1[hit].max()) + 1
    # The contour sought is the outer contour of a hit region (a hole's contour lies inside its
    # region's outer one), and one whose region, holes filled, comes within a pixel of the seed
    # (a contour runs between a pixel of its region and one outside). The box is traced with
    # the other regions (texture, specks) lowered below the level and the holes of those kept
    # raised above it: no pixel of either is 8-connected to the pixels on a kept outer contour,
    # so no marching-squares cell of that contour holds one (skimage joins pixels below the
    # level diagonally, as the holes are found here), and those contours stay exactly as they
    # were, without thousands of others.
    box, labels = padded[r0:r1, c0:c1], labels[r0:r1, c0:c1]
    high = hit[labels]
    _, outside = cv2.connectedComponents((~high).view(np.uint8), connectivity=8)
    filled = outside != outside[0, 0]  # the box's border lies outside every hit region
    count, regions = cv2.connectedComponents(filled.view(np.uint8), connectivity=8)
    row, col = row - r0, col - c0
    near = np.zeros(count, dtype=np.bool_)
    near[regions[max(0, math.floor(row - 1.5)) : max(0, math.floor(row + 1.5) + 1),
                 max(0, math.floor(col - 1.5)) : max(0, math.floor(col + 1.5) + 1)]] = True
    near[0] = False
    if not near.any():
        return None
    filled &= near[regions]
    below = np.float32(min(background, level - 1e-6))
    box = np.where(filled & ~high, padded.max(), np.where((labels > 0) & ~filled, below, box))
    contours = measure.find_contours(box, level)
    best, best_area = None, 0.0
    for contour in contours:
        if len(contour) < 4:
            continue
        xy = contour[:, ::-1] + np.array([c0 - 1.0, r0 - 1.0])  # (row, col) in the box → (x, y) in the crop
        area = 0.5 * abs(np.dot(xy[:, 0], np.roll(xy[:, 1], -1)) - np.dot(xy[:, 1], np.roll(xy[:, 0], -1)))
        if area > best_area and cv2.pointPolygonTest(xy.astype(np.float32), (float(seed_rc[1]), float(seed_rc[0])), False) >= 0:
            best, best_area = xy, area
    return best


def _deep_concavities(outline: np.ndarray, depth_px: float) -> int:
    """Number of concavities of the outline deeper than ``depth_px``."""
    return len(concavities(outline, depth_px))


def concavities(outline: np.ndarray, depth_px: float) -> np.ndarray:
    """The indices into ``outline`` of the deepest point of each of its concavities deeper than ``depth_px``
    (its convexity defects), in the outline's order."""
    fixed = np.round(outline * _SUBPIXEL).astype(np.int32)  # OpenCV wants integer points
    hull = cv2.convexHull(fixed, returnPoints=False)
    if len(hull) < 3:
        return np.zeros(0, dtype=int)
    try:
        defects = cv2.convexityDefects(fixed, np.sort(hull, axis=0))
    except cv2.error:  # a self-touching outline whose hull is not monotone
        return np.zeros(0, dtype=int)
    if defects is None:
        return np.zeros(0, dtype=int)
    defects = defects.reshape(-1, 4)
    depths = defects[:, 3] / (256.0 * _SUBPIXEL)  # depth is 24.8 fixed point
    return np.sort(defects[depths > depth_px, 2].astype(int))


def polygon_area_centroid(xy: np.ndarray) -> tuple[float, float, float]:
    x, y = xy[:, 0], xy[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    area = 0.5 * cross.sum()
    if abs(area) < 1e-12:
        return 0.0, float(x.mean()), float(y.mean())
    cx = ((x + x1) * cross).sum() / (6.0 * area)
    cy = ((y + y1) * cross).sum() / (6.0 * area)
    return abs(area), float(cx), float(cy)


def _open_in_window(outline: np.ndarray, shape: tuple[int, int], window: Window, frame) -> bool:
    """True when the outline reaches a side of the search window that is not the frame's edge."""
    r0, c0, r1, c1 = window.r0, window.c0, window.r1, window.c1
    height, width = frame
    x, y = outline[:, 0], outline[:, 1]
    return bool(
        (c0 > 0 and x.min() <= 0.0)
        or (r0 > 0 and y.min() <= 0.0)
        or (c1 < width and x.max() >= shape[1] - 1)
        or (r1 < height and y.max() >= shape[0] - 1)
    )


@dataclass(frozen=True)
class Circle:
    """A circle, in the coordinates of the points it was fitted to."""

    cx: float
    cy: float
    radius: float


@dataclass(frozen=True)
class SeenOutline:
    """A closed outline and, per point, whether it is seen: the disc's own edge, not filled in."""

    points: np.ndarray  #: (N, 2), (x, y) = (column, row)
    seen: np.ndarray


def _fit_circle(xy: np.ndarray) -> Circle:
    """The circle through ``xy`` (algebraic least squares, Kåsa 1976)."""
    x, y = xy[:, 0], xy[:, 1]
    design = np.column_stack([x, y, np.ones(len(x))])
    (a, b, c), *_ = np.linalg.lstsq(design, x * x + y * y, rcond=None)
    cx, cy = 0.5 * a, 0.5 * b
    return Circle(float(cx), float(cy), float(math.sqrt(max(c + cx * cx + cy * cy, 0.0))))


def _completed_outline(own: np.ndarray, circle: Circle) -> SeenOutline:
    """The own outline points with the circle filled in where they leave gaps, ordered by angle;
    seen: the own points."""
    cx, cy, radius = circle.cx, circle.cy, circle.radius
    angles = np.arctan2(own[:, 1] - cy, own[:, 0] - cx)
    step = 1.0 / max(radius, 1.0)  # about a pixel along the circle
    grid = np.arange(-math.pi, math.pi, step)
    gap = np.abs(np.angle(np.exp(1j * (grid[:, None] - angles[None, :])))).min(axis=1) > 2.0 * step
    filled = np.column_stack([cx + radius * np.cos(grid[gap]), cy + radius * np.sin(grid[gap])])
    points = np.vstack([own, filled])
    seen = np.concatenate([np.ones(len(own), bool), np.zeros(len(filled), bool)])
    order = np.argsort(np.concatenate([angles, grid[gap]]))
    return SeenOutline(points[order], seen[order])
