"""Measure one candidate blob: sub-pixel outline, size, centre, levels, and whether it is a disc.

Notes
-----
Levels, around a candidate of approximate radius r: the local background ``b``
is the median of the annulus from 1.3 r to 1.7 r (plus a few pixels), the local
noise the scaled median absolute deviation of that annulus (sensor noise and
texture around the disc), and the plateau ``p`` the 90th percentile of the
pixels within 0.8 r (robust to noise, and the rim of ring-shaped
"soap-bubble" discs). The outline is the sub-pixel iso-contour at the 50 %
level ``b + (p − b)/2`` (marching squares) around the candidate's centre,
closed along the frame where the frame cuts the disc. A second pass repeats
this with the measured centre and size. Where the outline runs on into
neighbouring light (discs that touch, a bright region), the disc is cut out by
a circle of 1.3 r + 2 px and flagged ``overlaps``.

A candidate is kept as a disc when all of these hold (the rejection reasons):

``too small``       equal-area diameter below the minimum (default 4 px);
``faint``           plateau contrast ``p − b`` below ``MIN_SNR`` local noise levels,
                    below ``MIN_CONTRAST_ABS`` (linear) or below
                    ``MIN_CONTRAST_REL`` of the background;
``no outline``      no 50 % contour around the centre;
``no surround``     no background around it in the frame (it fills the frame);
``part of a larger region``  the outline, cut out of a bright region, lies
                    mostly on the cutting circle;
``soft edge``       the edge is wide for the size: the edge width, contrast over
                    the median gradient along the outline, exceeds
                    ``max(EDGE_WIDTH_MIN_PX, EDGE_WIDTH_MAX_REL · r)``. A flat disc
                    blurred by b px has 2.5 b; an in-focus glint or a smooth
                    blob (Gaussian: 1.44 r) much more. Measured on the outline,
                    it is not fooled by neighbouring discs;
``not compact``     solidity (area over convex-hull area) below ``MIN_SOLIDITY``
                    (the star has 0.68): edges, branches, texture;
``in a clipped region``  saturated, and the clipping goes on past its outline
                    (more than ``MAX_CLIPPED_RING_SHARE`` of a 2-px ring);
``elongated``       the minimum-area rectangle's sides differ by more than
                    ``MAX_ELONGATION`` (a slit of aspect 0.26 still passes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage
from skimage import measure

from bokehfit.discs.candidates import MIN_CONTRAST_ABS, MIN_CONTRAST_REL

__all__ = ["Measurement", "measure_candidate", "MIN_SNR", "MIN_SOLIDITY", "MAX_ELONGATION", "RESOLVABLE_PX"]

MIN_SNR = 4.0
#: The search window grows by these factors while the outline runs into it.
WINDOW_GROWTH = (1.0, 2.0, 4.0)
#: A disc cut out of a larger bright region whose outline lies mostly on the
#: cutting circle is a piece of that region, not a disc.
MAX_CUT_SHARE = 0.5
#: The star, the least compact aperture, has solidity 0.68.
MIN_SOLIDITY = 0.6
#: A concavity deeper than this share of the equal-area radius (and than
#: OVERLAP_DEFECT_MIN_PX) marks overlapping discs when there are 2 to 4 of them:
#: two discs make two; the star's five are its own; outline noise stays below 0.2 px.
OVERLAP_DEFECT_DEPTH = 0.04
OVERLAP_DEFECT_MIN_PX = 1.0
#: A disc whose surrounding ring has its median above its 10th percentile by
#: more than this share of the disc's contrast sits on other light (most of its
#: surround is another disc) and is flagged ``overlaps``.
MAX_RING_LIFT = 0.5
_SUBPIXEL = 16
MAX_ELONGATION = 15.0
EDGE_WIDTH_MIN_PX = 3.0
EDGE_WIDTH_MAX_REL = 0.6
#: Equal-area diameter from which a disc shows its shape.
RESOLVABLE_PX = 8.0
#: Share of a disc's pixels that may be clipped in the source before it counts as saturated.
SATURATED_SHARE = 0.002
#: A saturated "disc" whose surrounding ring is clipped beyond this share is a
#: piece of a larger clipped region (the sun, a window), not a disc.
MAX_CLIPPED_RING_SHARE = 0.3


@dataclass(frozen=True)
class Measurement:
    """A measured blob; ``reason`` is None for a disc, else why it was rejected."""

    center_xy: tuple[float, float]
    diameter_px: float
    area_px: float
    outline_xy: np.ndarray  #: (N, 2) closed sub-pixel outline, (x, y) = (column, row)
    plateau: float
    background: float
    snr: float
    solidity: float
    elongation: float
    edge_width_px: float
    saturated: bool
    clipped: bool
    overlaps: bool  #: cut out of a larger bright region, or shaped like two to four merged discs
    reason: str | None



def _annulus_levels(crop: np.ndarray, distance: np.ndarray, radius: float) -> tuple[float, float, float] | None:
    """Median, robust spread and lift (median − 10th percentile) of the annulus 1.3 r … 1.7 r (+ 2 px)."""
    ring = crop[(distance >= 1.3 * radius + 1.0) & (distance <= 1.7 * radius + 3.0)]
    if ring.size < 8:
        ring = crop[distance >= 1.3 * radius + 1.0]
    if ring.size < 8:
        return None  # the window holds no surround: the disc fills or overflows the frame
    median = float(np.median(ring))
    low = float(np.percentile(ring, 10))
    return median, 1.4826 * float(np.median(np.abs(ring - median))), median - low


def _edge_gradient(crop: np.ndarray, outline: np.ndarray) -> float:
    """Median gradient magnitude of the image along the outline (bilinear samples)."""
    gy, gx = np.gradient(crop.astype(np.float32))
    coords = [outline[:, 1], outline[:, 0]]  # (row, col)
    gx_at = ndimage.map_coordinates(gx, coords, order=1, mode="nearest")
    gy_at = ndimage.map_coordinates(gy, coords, order=1, mode="nearest")
    return float(np.median(np.hypot(gx_at, gy_at)))


def _outline(crop: np.ndarray, level: float, background: float, seed_rc: tuple[float, float]) -> np.ndarray | None:
    """Closed 50 % contour around ``seed_rc`` (row, col in the crop), or None."""
    # Pad with the background so contours cut by the frame close just outside it.
    padded = np.pad(crop, 1, mode="constant", constant_values=min(background, level - 1e-6))
    contours = measure.find_contours(padded, level)
    best, best_area = None, 0.0
    for contour in contours:
        if len(contour) < 4:
            continue
        xy = contour[:, ::-1] - 1.0  # (row, col) in the padded crop → (x, y) in the crop
        area = 0.5 * abs(np.dot(xy[:, 0], np.roll(xy[:, 1], -1)) - np.dot(xy[:, 1], np.roll(xy[:, 0], -1)))
        if area > best_area and cv2.pointPolygonTest(xy.astype(np.float32), (float(seed_rc[1]), float(seed_rc[0])), False) >= 0:
            best, best_area = xy, area
    return best


def _deep_concavities(outline: np.ndarray, depth_px: float) -> int:
    """Number of concavities of the outline deeper than ``depth_px``."""
    fixed = np.round(outline * _SUBPIXEL).astype(np.int32)  # OpenCV wants integer points
    hull = cv2.convexHull(fixed, returnPoints=False)
    if len(hull) < 3:
        return 0
    try:
        defects = cv2.convexityDefects(fixed, np.sort(hull, axis=0))
    except cv2.error:  # a self-touching outline whose hull is not monotone
        return 0
    if defects is None:
        return 0
    depths = defects.reshape(-1, 4)[:, 3] / (256.0 * _SUBPIXEL)  # depth is 24.8 fixed point
    return int((depths > depth_px).sum())


def _polygon_area_centroid(xy: np.ndarray) -> tuple[float, float, float]:
    x, y = xy[:, 0], xy[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    area = 0.5 * cross.sum()
    if abs(area) < 1e-12:
        return 0.0, float(x.mean()), float(y.mean())
    cx = ((x + x1) * cross).sum() / (6.0 * area)
    cy = ((y + y1) * cross).sum() / (6.0 * area)
    return abs(area), float(cx), float(cy)


def _window(luminance: np.ndarray, center_xy: tuple[float, float], half: int):
    height, width = luminance.shape
    col, row = int(round(center_xy[0])), int(round(center_xy[1]))
    r0, c0 = max(0, row - half), max(0, col - half)
    r1, c1 = min(height, row + half + 1), min(width, col + half + 1)
    rows, cols = np.ogrid[r0 - center_xy[1] : r1 - center_xy[1], c0 - center_xy[0] : c1 - center_xy[0]]
    return (r0, c0, r1, c1), np.sqrt(rows * rows + cols * cols)


def _closed_outline(luminance, center_xy, radius, reach):
    """Levels and the closed 50 % outline around ``center_xy``, growing the window
    while the outline runs into it; the last window masks beyond ``reach`` instead
    (the disc then touches a neighbour). Returns (window, crop, levels, outline, merged)."""
    height, width = luminance.shape
    for grow in WINDOW_GROWTH:
        half = int(math.ceil(grow * max(1.7 * radius + 4.0, reach)))
        window, distance = _window(luminance, center_xy, half)
        r0, c0, r1, c1 = window
        crop = luminance[r0:r1, c0:c1]
        levels = _annulus_levels(crop, distance, radius)
        if levels is None:
            return "no surround"
        background, noise, ring_lift = levels
        core = crop[distance <= max(0.8 * radius, 0.75)]
        plateau = float(np.percentile(core, 90)) if core.size else background
        level = background + 0.5 * (plateau - background)
        if not _contrast_ok(plateau - background, noise, background):
            return "faint"
        seed_rc = (center_xy[1] - r0, center_xy[0] - c0)
        outline = _outline(crop, level, background, seed_rc)
        if outline is None:
            return "no outline"
        if not _open_in_window(outline, crop.shape, window, (height, width)):
            return window, crop, (background, plateau, noise, ring_lift), outline, False
    # Still open: part of a larger bright structure, or discs run together. Cut
    # the disc out of it with a circle through its neighbours' gap.
    masked = np.where(distance <= reach, crop, min(background, level - 1e-6)).astype(np.float32)
    outline = _outline(masked, level, background, seed_rc)
    if outline is None:
        return "no outline"
    on_cut = np.abs(np.hypot(outline[:, 0] - seed_rc[1], outline[:, 1] - seed_rc[0]) - reach) < 1.0
    if on_cut.mean() > MAX_CUT_SHARE:  # mostly the cutting circle: a piece of something larger
        return "part of a larger region"
    return window, crop, (background, plateau, noise, ring_lift), outline, True


def _contrast_ok(contrast: float, noise: float, background: float) -> bool:
    return contrast >= max(MIN_SNR * noise, MIN_CONTRAST_ABS, MIN_CONTRAST_REL * background)


def measure_candidate(
    luminance: np.ndarray,
    clipped_mask: np.ndarray | None,
    center_xy: tuple[float, float],
    diameter_px: float,
    extent_px: float,
    min_noise: float,
    min_diameter_px: float,
) -> Measurement | str:
    """Measure the disc around ``center_xy`` of about ``diameter_px``, reaching about
    ``extent_px`` from its centre; a rejection reason where there is no disc to measure.

    Two passes: the first uses the candidate's size for the levels, the second
    the size it measured.
    """
    height, width = luminance.shape
    radius = max(1.0, 0.5 * diameter_px)
    reach = max(radius, extent_px)
    found = None
    for _ in range(2):
        found = _closed_outline(luminance, center_xy, radius, 1.3 * reach + 2.0)
        if isinstance(found, str):
            return found
        (r0, c0, _, _), _, _, outline, merged = found
        area, cx, cy = _polygon_area_centroid(outline)
        if merged or area <= 0:
            break
        center_xy, radius = (cx + c0, cy + r0), max(1.0, math.sqrt(area / math.pi))
        reach = float(np.max(np.hypot(outline[:, 0] - cx, outline[:, 1] - cy)))
    (r0, c0, r1, c1), crop, (background, plateau, noise, ring_lift), outline, merged = found
    contrast = plateau - background
    area, cx, cy = _polygon_area_centroid(outline)
    diameter = 2.0 * math.sqrt(area / math.pi)
    hull_area = float(cv2.contourArea(cv2.convexHull(outline.astype(np.float32))))
    solidity = area / hull_area if hull_area > 0 else 0.0
    (_, _), (side_a, side_b), _ = cv2.minAreaRect(outline.astype(np.float32))
    elongation = max(side_a, side_b) / max(min(side_a, side_b), 1e-6)
    inside = np.zeros(crop.shape, dtype=np.uint8)
    cv2.fillPoly(inside, [np.round(outline).astype(np.int32)], 1)
    blob = inside.astype(bool)
    edge_width = contrast / max(_edge_gradient(crop, outline), 1e-12)
    outline_xy = outline + np.array([c0, r0], dtype=np.float64)
    # The padded contour runs outside [0, size − 1] only where the frame cuts the disc.
    clipped = bool(outline_xy.min() < 0.0 or outline_xy[:, 0].max() > width - 1 or outline_xy[:, 1].max() > height - 1)
    saturated = clipped_beyond = False
    if clipped_mask is not None:
        clipped_crop = clipped_mask[r0:r1, c0:c1]
        saturated = int(clipped_crop[blob].sum()) > max(1.0, SATURATED_SHARE * area)
        if saturated:  # a saturated disc's edge is where the clipping stops
            ring = cv2.dilate(inside, np.ones((5, 5), np.uint8)).astype(bool) & ~blob
            clipped_beyond = bool(ring.any()) and clipped_crop[ring].mean() > MAX_CLIPPED_RING_SHARE
    depth = max(OVERLAP_DEFECT_MIN_PX, OVERLAP_DEFECT_DEPTH * 0.5 * diameter)
    merged = merged or 2 <= _deep_concavities(outline, depth) <= 4
    # Most of its surround lifted above the rest by other light: the bright lens
    # where two discs overlap, or a disc sitting on another one.
    merged = merged or ring_lift > MAX_RING_LIFT * contrast
    snr = contrast / max(noise, min_noise)

    reason = None
    if diameter < min_diameter_px:
        reason = "too small"
    elif clipped_beyond:
        reason = "in a clipped region"
    elif not _contrast_ok(contrast, noise, background):
        reason = "faint"
    elif edge_width > max(EDGE_WIDTH_MIN_PX, EDGE_WIDTH_MAX_REL * 0.5 * diameter) and not saturated:
        reason = "soft edge"
    elif solidity < MIN_SOLIDITY:
        reason = "not compact"
    elif elongation > MAX_ELONGATION:
        reason = "elongated"
    return Measurement(
        center_xy=(cx + c0, cy + r0),
        diameter_px=diameter,
        area_px=area,
        outline_xy=outline_xy,
        plateau=plateau,
        background=background,
        snr=snr,
        solidity=solidity,
        elongation=elongation,
        edge_width_px=edge_width,
        saturated=saturated,
        clipped=clipped,
        overlaps=merged,
        reason=reason,
    )


def _open_in_window(outline: np.ndarray, shape: tuple[int, int], window, frame) -> bool:
    """True when the outline reaches a side of the search window that is not the frame's edge."""
    r0, c0, r1, c1 = window
    height, width = frame
    x, y = outline[:, 0], outline[:, 1]
    return bool(
        (c0 > 0 and x.min() <= 0.0)
        or (r0 > 0 and y.min() <= 0.0)
        or (c1 < width and x.max() >= shape[1] - 1)
        or (r1 < height and y.max() >= shape[0] - 1)
    )
