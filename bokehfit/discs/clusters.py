"""Split a blob of overlapping discs into its discs (:func:`split_cluster`)."""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np
from scipy import ndimage
from skimage import feature, segmentation

from bokehfit.discs.contours import _SUBPIXEL, _completed_outline, _fit_circle, concavities
from bokehfit.discs.verdict import OVERLAP_DEFECT_DEPTH, OVERLAP_DEFECT_MIN_PX, Measurement

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
#: Discs whose centres lie closer than half their radius, or a small disc on a large one's edge (its centre's
#: depth, its own radius, under half the large one's), make no peak of their own in their union's distance
#: transform; their union's outline is still their arcs, meeting where it turns inward (a concavity
#: deeper than the blob's outline noise: :data:`bokehfit.discs.verdict.OVERLAP_DEFECT_DEPTH`, as a blob of
#: overlapping discs is told). Between two such cusps the outline is one disc's edge; arcs of one disc on
#: both sides of another (the middle disc of a chain, a disc notched by a stem) are joined where one circle
#: fits their points within ARC_JOIN_MISFIT_REL of its radius (rms; a polygon's sides stay within 0.05 of
#: their equal-area circle's, so a polygon's arcs may stay apart and the split then fails its tests), or within
#: ARC_JOIN_RATIO times the worse of their own circles' misfits: the arcs between the dents of one disc's
#: wandering edge fit one circle about as well as each its own (drawn outlines wandering by 8 % of the radius:
#: 0.8–1.7 times), two discs' arcs several times worse (3–10 times on photo 12's and drawn unions). The
#: points within ARC_JUNCTION_REL of the blob's radius (and SPLIT_JUNCTION_PX) of a cusp are the junction,
#: blurred by the edge. At most ARC_MAX_CUSPS cusps (a chain of five discs has eight). An arc is a disc's edge
#: where it passes a part's tests (SPLIT_MAX_MISFIT_REL, SPLIT_MIN_ARC, SPLIT_MIN_INSIDE) and lies inside no
#: other part's circle (at most ARC_MAX_INSIDE_SHARE of it): the others are the outline cutting through light.
#: The discs' arcs must be ARC_MIN_OUTLINE_SHARE of the outline seen, two discs or more, and their circles cover
#: ARC_MIN_COVER of the blob: the dents of one disc's wandering outline (a real disc's edge wanders by several
#: per cent of its radius) cut it into arcs of smaller circles that leave its middle out; the circles of discs
#: run together cover their union (beyond it only where the outline cut through a neighbour's light).
ARC_JOIN_MISFIT_REL = 0.03
ARC_JOIN_RATIO = 2.0
ARC_JUNCTION_REL = 0.03
ARC_MAX_CUSPS = 8
ARC_MAX_INSIDE_SHARE = 0.2
ARC_MIN_OUTLINE_SHARE = 0.5
ARC_MIN_COVER = 0.9


def split_cluster(m: Measurement, cluster: bool = False) -> list[Measurement]:
    """The discs of a blob of overlapping discs, or an empty list where it is one disc.

    The blob's distance transform peaks at each disc's centre (a disc's centre is
    farthest from the blob's edge); a watershed from those peaks splits the blob,
    and each outline point goes to the part it bounds. A part's own points (those
    not at a junction) give its centre and size (a circle through them: the discs
    of a cluster share one aperture, which the fit then models); its outline is
    that circle where the disc is hidden by its neighbours, marked not seen.
    Where discs overlap too much for a peak each, the outline's arcs between the
    cusps where it turns inward are the discs' edges (:func:`_parts_by_arcs`). The
    watershed is tried where the measurement flags the blob ``overlaps`` or the search
    found it a ``cluster`` (:attr:`bokehfit.discs.candidates.Candidate.cluster`); the arcs
    wherever its outline has two to ARC_MAX_CUSPS cusps (``overlaps`` counts two to four
    concavities, not to take a star's five for discs: a chain of three or more discs has
    more, and a star's arcs are no circles).
    """
    origin = np.floor(m.outline_xy.min(axis=0)) - 2.0
    local = m.outline_xy - origin
    cusps = concavities(local, max(OVERLAP_DEFECT_MIN_PX, OVERLAP_DEFECT_DEPTH * 0.5 * m.diameter_px))
    arcs = 2 <= len(cusps) <= ARC_MAX_CUSPS
    watershed = m.overlaps or cluster
    if not (watershed or arcs):
        return []
    shape = (int(math.ceil(local[:, 1].max())) + 3, int(math.ceil(local[:, 0].max())) + 3)
    mask = np.zeros(shape, dtype=np.uint8)
    cv2.fillPoly(mask, [np.round(local * _SUBPIXEL).astype(np.int32)], 1, shift=4)
    seen_before = m.outline_reliable if m.outline_reliable is not None else np.ones(len(local), bool)
    circles = ((_parts_by_depth(local, mask, seen_before) if watershed else [])
               or (_parts_by_arcs(local, cusps, mask, seen_before, 0.5 * m.diameter_px) if arcs else []))
    parts = []
    for own, fitted in circles:
        completed = _completed_outline(local[own], fitted)
        parts.append(
            replace(
                m,
                center_xy=(fitted.cx + origin[0], fitted.cy + origin[1]),
                diameter_px=2.0 * fitted.radius,
                area_px=math.pi * fitted.radius * fitted.radius,
                outline_xy=completed.points + origin,
                overlaps=True,
                outline_reliable=completed.seen,
            )
        )
    return parts


def _parts_by_depth(local: np.ndarray, mask: np.ndarray, seen_before: np.ndarray) -> list:
    """The discs of the blob ``mask`` (outline ``local``, in its coordinates) split by a watershed of its
    distance transform from its peaks (:func:`split_cluster`): per disc, its own outline points (a mask) and
    their circle; an empty list where it is one disc or the parts are not discs."""
    depth = ndimage.distance_transform_edt(mask)
    peaks = feature.peak_local_max(
        depth,
        min_distance=max(2, int(SPLIT_MIN_DISTANCE_REL * depth.max())),
        threshold_abs=SPLIT_MIN_PEAK_REL * depth.max(),
        exclude_border=False,
    )
    if len(peaks) < 2:
        return []
    shape = mask.shape
    markers = np.zeros(shape, dtype=np.int32)
    markers[peaks[:, 0], peaks[:, 1]] = np.arange(1, len(peaks) + 1)
    labels = segmentation.watershed(-depth, markers, mask=mask.astype(bool))
    _, (near_r, near_c) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
    rows = np.clip(np.round(local[:, 1]).astype(int), 0, shape[0] - 1)
    cols = np.clip(np.round(local[:, 0]).astype(int), 0, shape[1] - 1)
    owner = labels[near_r[rows, cols], near_c[rows, cols]]
    parts = []
    for k in range(1, len(peaks) + 1):
        others = ndimage.distance_transform_edt(~((labels != k) & (labels > 0)))
        junction = ndimage.map_coordinates(others, [local[:, 1], local[:, 0]], order=1, mode="nearest") <= SPLIT_JUNCTION_PX
        own = (owner == k) & seen_before & ~junction
        if own.sum() < SPLIT_MIN_POINTS:
            continue
        fitted = _round_part(local, own, mask)
        inscribed = float(depth[peaks[k - 1][0], peaks[k - 1][1]])
        if fitted is None or not 0.5 * inscribed <= fitted.radius <= 2.0 * inscribed:
            return []  # a streak or a blob of another shape, or own points that bound no disc around this peak
        parts.append((own, fitted))
    return parts if len(parts) >= 2 else []


def _parts_by_arcs(local: np.ndarray, cusps: np.ndarray, mask: np.ndarray, seen_before: np.ndarray,
                   radius: float) -> list:
    """The discs of the blob ``mask`` (outline ``local``, its equal-area ``radius``) as the circles of its outline's
    arcs between the ``cusps`` where it turns inward (indices into ``local``: ARC_JOIN_MISFIT_REL's note), as
    :func:`_parts_by_depth` gives them; an empty list where its arcs are not the edges of two discs or more that
    make it."""
    near_cusp = np.zeros(len(local), bool)
    for c in cusps:
        near_cusp |= np.hypot(*(local - local[c]).T) <= max(SPLIT_JUNCTION_PX, ARC_JUNCTION_REL * radius)
    arc_of = np.searchsorted(cusps, np.arange(len(local)), side="right") % len(cusps)  # between cusps k-1 and k
    groups = [np.flatnonzero((arc_of == k) & ~near_cusp & seen_before) for k in range(len(cusps))]
    groups = [g for g in groups if len(g) >= SPLIT_MIN_POINTS]
    alone = [_misfit(local[g])[1] for g in groups]
    while len(groups) > 1:  # join the two arcs that one circle fits best, while it fits them
        best = None
        for i in range(len(groups)):
            for j in range(i + 1, len(groups)):
                joined = np.concatenate([groups[i], groups[j]])
                rel = _misfit(local[joined])[1]
                if rel <= max(ARC_JOIN_MISFIT_REL, ARC_JOIN_RATIO * max(alone[i], alone[j])) and (best is None or rel < best[0]):
                    best = (rel, i, j, joined)
        if best is None:
            break
        rel, i, j, joined = best
        groups[i], alone[i] = joined, rel
        del groups[j], alone[j]
    if len(groups) < 2:
        return []
    parts = []
    for g in groups:
        own = np.zeros(len(local), bool)
        own[g] = True
        fitted = _round_part(local, own, mask)
        if fitted is not None:  # else no disc's edge: the contour cut through other light
            parts.append((own, fitted))
    # Where discs overlap, their union's outline lies on each one's circle and outside the others': an arc
    # inside another's circle is the outline cutting through that disc's light, not a disc's own edge.
    parts = [(own, fitted) for i, (own, fitted) in enumerate(parts)
             if not any(_inside_share(local[own], other) > ARC_MAX_INSIDE_SHARE for j, (_, other) in enumerate(parts) if j != i)]
    if len(parts) < 2 or sum(own.sum() for own, _ in parts) < ARC_MIN_OUTLINE_SHARE * seen_before.sum():
        return []  # the arcs left are not most of the blob's outline: not discs run together
    union = np.zeros(mask.shape, bool)
    for _, fitted in parts:
        union |= _circle_pixels(mask.shape, fitted)
    blob = mask.astype(bool)
    if (union & blob).sum() < ARC_MIN_COVER * blob.sum():
        return []  # the circles leave the blob's light unexplained: the dents of one disc's wandering outline
    return parts


def _inside_share(xy: np.ndarray, circle) -> float:
    """The share of the points ``xy`` inside ``circle`` by more than the junction's margin (ARC_JUNCTION_REL of its
    radius, SPLIT_JUNCTION_PX)."""
    margin = max(SPLIT_JUNCTION_PX, ARC_JUNCTION_REL * circle.radius)
    return float(np.mean(np.hypot(xy[:, 0] - circle.cx, xy[:, 1] - circle.cy) < circle.radius - margin))


def _round_part(local: np.ndarray, own: np.ndarray, mask: np.ndarray):
    """The circle through a part's own outline points (``own`` of ``local``) where they are a disc's edge: within
    SPLIT_MAX_MISFIT_REL of its radius, over SPLIT_MIN_ARC of the turn, the circle SPLIT_MIN_INSIDE inside the blob
    ``mask``; else None."""
    fitted, misfit = _misfit(local[own])
    turns = np.arctan2(local[own, 1] - fitted.cy, local[own, 0] - fitted.cx)
    arc = len(np.unique(((turns + math.pi) / (2 * math.pi) * 32).astype(int) % 32)) / 32
    circle = _circle_pixels(mask.shape, fitted)
    inside = float(mask[circle].mean()) if circle.any() else 0.0
    if misfit > SPLIT_MAX_MISFIT_REL or arc < SPLIT_MIN_ARC or inside < SPLIT_MIN_INSIDE:
        return None
    return fitted


def _misfit(xy: np.ndarray):
    """The circle through ``xy`` and the rms distance of the points from it over its radius."""
    fitted = _fit_circle(xy)
    rms = math.sqrt(float(np.mean((np.hypot(xy[:, 0] - fitted.cx, xy[:, 1] - fitted.cy) - fitted.radius) ** 2)))
    return fitted, rms / max(fitted.radius, 1e-9)


def _circle_pixels(shape: tuple[int, int], circle) -> np.ndarray:
    """The pixels of an image of ``shape`` whose centres lie inside ``circle``."""
    rows, cols = np.ogrid[: shape[0], : shape[1]]
    return np.hypot(cols - circle.cx, rows - circle.cy) <= circle.radius
