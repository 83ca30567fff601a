"""Measure one candidate blob: sub-pixel outline, size, centre, levels, and whether it is a disc.

Notes
-----
Levels: the local background ``b`` is the median of a ring of pixels around the
blob that belong to no blob; the plateau ``p`` is the 90th percentile of the
blob (robust to noise, and the rim level of ring-shaped "soap-bubble" discs).
The outline is the sub-pixel iso-contour at the 50 % level ``b + (p − b)/2``
(marching squares), closed along the frame where the disc is cut by it.

A blob is kept as a disc when all of these hold (the rejection reasons):

``too small``       equal-area diameter below the minimum (default 4 px);
``faint``           plateau contrast ``p − b`` below ``MIN_SNR`` noise levels;
``soft edge``       the edge is wide for the size: the radii of the filled regions
                    above 25 % and 75 % differ by more than
                    ``max(EDGE_WIDTH_MIN_PX, EDGE_WIDTH_MAX_REL · r)``; a flat
                    disc has a narrow edge, an in-focus glint or a smooth blob
                    (Gaussian: 0.77·r) does not;
``not compact``     solidity (area over convex-hull area) below ``MIN_SOLIDITY``
                    (the star has 0.68): edges, branches, texture;
``elongated``       the minimum-area rectangle's sides differ by more than
                    ``MAX_ELONGATION`` (a slit of aspect 0.26 still passes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from skimage import measure

__all__ = ["Measurement", "measure_blob", "MIN_SNR", "MIN_SOLIDITY", "MAX_ELONGATION", "RESOLVABLE_PX"]

MIN_SNR = 8.0
#: The star, the least compact aperture, has solidity 0.68.
MIN_SOLIDITY = 0.6
#: A concavity deeper than this share of the equal-area radius marks overlapping discs
#: when there are 2 to 4 of them (two discs make two; the star's five are its own).
OVERLAP_DEFECT_DEPTH = 0.12
MAX_ELONGATION = 15.0
EDGE_WIDTH_MIN_PX = 1.6
EDGE_WIDTH_MAX_REL = 0.45
#: Equal-area diameter from which a disc shows its shape.
RESOLVABLE_PX = 8.0
#: Share of a disc's pixels that may be clipped in the source before it counts as saturated.
SATURATED_SHARE = 0.002


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
    overlaps: bool
    reason: str | None


def _dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    element = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    return cv2.dilate(mask.view(np.uint8), element).view(bool)


def _levels(crop: np.ndarray, blob: np.ndarray, others: np.ndarray) -> tuple[float, float]:
    ring_width = max(2, int(math.sqrt(blob.sum()) * 0.25))
    distance = cv2.distanceTransform((~blob).view(np.uint8), cv2.DIST_L2, 3)
    ring = (distance > 1.5) & (distance <= ring_width + 1.5) & ~others
    background = float(np.median(crop[ring])) if ring.any() else float(crop[~blob].min(initial=0.0))
    plateau = float(np.percentile(crop[blob], 90))
    return background, plateau


def _filled_radius(crop: np.ndarray, blob: np.ndarray, level: float) -> float:
    """Equal-area radius of the blob's pixels at or above ``level``, holes filled."""
    above = ((crop >= level) & blob).view(np.uint8)
    contours, _ = cv2.findContours(above, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    filled = np.zeros_like(above)
    cv2.drawContours(filled, contours, -1, 1, thickness=cv2.FILLED)
    return math.sqrt(float(filled.sum()) / math.pi)


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
    points = outline.astype(np.float32)
    hull = cv2.convexHull(points, returnPoints=False)
    if len(hull) < 3:
        return 0
    try:
        defects = cv2.convexityDefects(points, np.sort(hull, axis=0))
    except cv2.error:  # self-intersecting outlines (a hull that is not monotone)
        return 0
    return 0 if defects is None else int((defects[:, 0, 3] / 256.0 > depth_px).sum())


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


def measure_blob(
    luminance: np.ndarray,
    clipped_mask: np.ndarray | None,
    labels: np.ndarray,
    label: int,
    box: tuple[int, int, int, int],
    noise_sigma: float,
    min_diameter_px: float,
) -> Measurement | None:
    """Measure blob ``label`` whose bounding box is (left, top, width, height)."""
    height, width = luminance.shape
    left, top, box_w, box_h = box
    margin = max(3, int(0.35 * max(box_w, box_h)))
    r0, c0 = max(0, top - margin), max(0, left - margin)
    r1, c1 = min(height, top + box_h + margin), min(width, left + box_w + margin)
    crop = luminance[r0:r1, c0:c1]
    crop_labels = labels[r0:r1, c0:c1]
    blob = crop_labels == label
    others = (crop_labels != 0) & ~blob
    background, plateau = _levels(crop, blob, others)
    contrast = plateau - background
    if not contrast > 0:
        return None
    level = background + 0.5 * contrast
    seed = np.argwhere(blob & (crop >= level))
    if len(seed) == 0:
        return None
    seed_rc = tuple(seed[len(seed) // 2])
    outline = _outline(crop, level, background, seed_rc)
    if outline is None:
        return None
    area, cx, cy = _polygon_area_centroid(outline)
    diameter = 2.0 * math.sqrt(area / math.pi)
    hull = cv2.convexHull(outline.astype(np.float32))
    hull_area = float(cv2.contourArea(hull))
    solidity = area / hull_area if hull_area > 0 else 0.0
    (_, _), (side_a, side_b), _ = cv2.minAreaRect(outline.astype(np.float32))
    elongation = max(side_a, side_b) / max(min(side_a, side_b), 1e-6)
    r25 = _filled_radius(crop, blob, background + 0.25 * contrast)
    r75 = _filled_radius(crop, blob, background + 0.75 * contrast)
    edge_width = r25 - r75
    outline_xy = outline + np.array([c0, r0], dtype=np.float64)
    # The padded contour runs outside [0, size − 1] only where the frame cuts the disc.
    clipped = bool(outline_xy.min() < 0.0 or outline_xy[:, 0].max() > width - 1 or outline_xy[:, 1].max() > height - 1)
    inside = np.zeros(crop.shape, dtype=np.uint8)
    cv2.fillPoly(inside, [np.round(outline).astype(np.int32)], 1)
    saturated = False
    if clipped_mask is not None:
        clipped_pixels = int(clipped_mask[r0:r1, c0:c1][inside.astype(bool)].sum())
        saturated = clipped_pixels > max(1.0, SATURATED_SHARE * area)
    overlaps = bool((others & _dilate(inside.astype(bool), 2)).any())
    overlaps = overlaps or 2 <= _deep_concavities(outline, OVERLAP_DEFECT_DEPTH * 0.5 * diameter) <= 4
    snr = contrast / noise_sigma

    reason = None
    if diameter < min_diameter_px:
        reason = "too small"
    elif snr < MIN_SNR:
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
        overlaps=overlaps,
        reason=reason,
    )
