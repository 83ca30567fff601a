"""Split a blob of overlapping discs into its discs (:func:`split_cluster`)."""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np
from scipy import ndimage
from skimage import feature, segmentation

from bokehfit.discs.contours import _SUBPIXEL, _completed_outline, _fit_circle
from bokehfit.discs.verdict import Measurement

__all__ = ["split_cluster"]

#: Splitting a blob of overlapping discs: the peaks of its distance transform (the discs'
#: centres) must reach this share of the highest (a neck between two discs is lower) and
#: lie this share of it apart; a part keeps at least SPLIT_MIN_POINTS outline points of its own
#: (a circle through fewer follows the noise), and points within SPLIT_JUNCTION_PX of another
#: part are the junction, not its own edge.
SPLIT_MIN_PEAK_REL = 0.5
SPLIT_MIN_DISTANCE_REL = 0.5
SPLIT_MIN_POINTS = 12
SPLIT_JUNCTION_PX = 2.0
#: Each part must look like a disc for the blob to be split (else it is a streak, an edge
#: or a blob of another shape): its own points within SPLIT_MAX_MISFIT_REL of the radius of
#: their circle (rms; a polygon's outline is within 0.05 of its equal-area circle for six
#: blades or more, a pentagon's within 0.07), seen over SPLIT_MIN_ARC of the turn, and that
#: circle SPLIT_MIN_INSIDE inside the blob.
SPLIT_MAX_MISFIT_REL = 0.08
SPLIT_MIN_ARC = 0.35
SPLIT_MIN_INSIDE = 0.85


def split_cluster(m: Measurement) -> list[Measurement]:
    """The discs of a blob of overlapping discs, or an empty list where it is one disc.

    The blob's distance transform peaks at each disc's centre (a disc's centre is
    farthest from the blob's edge); a watershed from those peaks splits the blob,
    and each outline point goes to the part it bounds. A part's own points (those
    not at a junction) give its centre and size (a circle through them: the discs
    of a cluster share one aperture, which the fit then models); its outline is
    that circle where the disc is hidden by its neighbours, marked not seen.
    """
    origin = np.floor(m.outline_xy.min(axis=0)) - 2.0
    local = m.outline_xy - origin
    shape = (int(math.ceil(local[:, 1].max())) + 3, int(math.ceil(local[:, 0].max())) + 3)
    mask = np.zeros(shape, dtype=np.uint8)
    cv2.fillPoly(mask, [np.round(local * _SUBPIXEL).astype(np.int32)], 1, shift=4)
    depth = ndimage.distance_transform_edt(mask)
    peaks = feature.peak_local_max(
        depth,
        min_distance=max(2, int(SPLIT_MIN_DISTANCE_REL * depth.max())),
        threshold_abs=SPLIT_MIN_PEAK_REL * depth.max(),
        exclude_border=False,
    )
    if len(peaks) < 2:
        return []
    markers = np.zeros(shape, dtype=np.int32)
    markers[peaks[:, 0], peaks[:, 1]] = np.arange(1, len(peaks) + 1)
    labels = segmentation.watershed(-depth, markers, mask=mask.astype(bool))
    _, (near_r, near_c) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
    rows = np.clip(np.round(local[:, 1]).astype(int), 0, shape[0] - 1)
    cols = np.clip(np.round(local[:, 0]).astype(int), 0, shape[1] - 1)
    owner = labels[near_r[rows, cols], near_c[rows, cols]]
    seen_before = m.outline_reliable if m.outline_reliable is not None else np.ones(len(local), bool)
    parts = []
    for k in range(1, len(peaks) + 1):
        others = ndimage.distance_transform_edt(~((labels != k) & (labels > 0)))
        junction = ndimage.map_coordinates(others, [local[:, 1], local[:, 0]], order=1, mode="nearest") <= SPLIT_JUNCTION_PX
        own = (owner == k) & seen_before & ~junction
        if own.sum() < SPLIT_MIN_POINTS:
            continue
        fitted = _fit_circle(local[own])
        cx, cy, radius = fitted.cx, fitted.cy, fitted.radius
        inscribed = float(depth[peaks[k - 1][0], peaks[k - 1][1]])
        if not 0.5 * inscribed <= radius <= 2.0 * inscribed:
            return []  # the own points do not bound a disc around this peak: not a cluster of discs
        misfit = np.sqrt(np.mean((np.hypot(local[own, 0] - cx, local[own, 1] - cy) - radius) ** 2))
        turns = np.arctan2(local[own, 1] - cy, local[own, 0] - cx)
        arc = len(np.unique(((turns + math.pi) / (2 * math.pi) * 32).astype(int) % 32)) / 32
        rows, cols = np.ogrid[: shape[0], : shape[1]]
        circle = np.hypot(cols - cx, rows - cy) <= radius
        inside = float(mask[circle].mean()) if circle.any() else 0.0
        if misfit > SPLIT_MAX_MISFIT_REL * radius or arc < SPLIT_MIN_ARC or inside < SPLIT_MIN_INSIDE:
            return []  # a streak or a blob of another shape, not round discs run together
        completed = _completed_outline(local[own], fitted)
        parts.append(
            replace(
                m,
                center_xy=(cx + origin[0], cy + origin[1]),
                diameter_px=2.0 * radius,
                area_px=math.pi * radius * radius,
                outline_xy=completed.points + origin,
                overlaps=True,
                outline_reliable=completed.seen,
            )
        )
    return parts if len(parts) >= 2 else []
