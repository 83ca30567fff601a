"""Close the gaps in a disc's bright region before its outline is drawn: a thin occluder
bridged, a ring's broken rim closed, or the circle through the arcs of a rim broken beyond that.

Notes
-----
- **Occluded discs**: a thin occluder in front of a disc (a branch, a grass
  blade) cuts a notch or a gap into the region above the 50 % level (of the light the
  outline is drawn on, its pixel noise quieted: a faint disc's raw region frays all round). A
  morphological closing of that region with a disc of radius
  ``OCCLUSION_BRIDGE_REL`` · r bridges gaps up to that width; where the
  bridged pixels exceed ``OCCLUSION_MIN_SHARE`` of the area, they are given the
  plateau level, the outline is drawn over them, and the outline points next to
  them are marked not seen (``outline_reliable``).
- **Ring discs** (measured with the rim as the plateau, :mod:`bokehfit.discs.measure`): the rim's
  gaps up to ``RING_GAP_REL`` · r on each side are closed and its darker centre raised to the
  plateau, so that its outer outline closes; the outline next to the closed gaps is not seen. A
  rim broken beyond that is outlined by the circle through its outer arcs (``RING_ARC_BINS``
  directions), not seen where the rim is not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from skimage import measure

from bokehfit.discs.contours import SeenOutline, _completed_outline, _fit_circle

__all__ = ["OCCLUSION_BRIDGE_REL", "OCCLUSION_MIN_SHARE"]

#: Gaps bridged as occlusion: up to this share of the disc's radius on each side (a closing
#: with a disc this large leaves convex shapes, and so every aperture, unchanged but for a
#: pixel in the star's notches; a branch in front of a disc is thinner).
OCCLUSION_BRIDGE_REL = 0.15
#: Bridged pixels count as an occlusion when they exceed this share of the disc's area
#: (pixel noise along an outline fills a few isolated pixels, far below it).
OCCLUSION_MIN_SHARE = 0.05
#: Pieces of a disc that an occluder leaves, as a share of its area: smaller specks (noise
#: above the level around a faint disc) are not joined to it.
OCCLUSION_PIECE_SHARE = 0.05
#: Discs smaller than this radius (px) are not searched for occluders: their notches are
#: a pixel or two, the size of noise and JPEG blocks.
OCCLUSION_MIN_RADIUS_PX = 15.0
#: Gaps in a ring's rim up to this share of its radius on each side are closed (the rim of a
#: real soap-bubble disc dims in places: a droplet's highlight is uneven).
RING_GAP_REL = 0.15
#: A rim broken beyond that: its outer edge is looked for in RING_ARC_BINS directions between
#: RING_ARC_BAND times the radius, must be found in RING_MIN_ARC of them, and lie within
#: RING_ARC_TOLERANCE of the radius of the circle through it.
RING_ARC_BINS = 64
RING_ARC_BAND = (0.6, 1.3)
RING_MIN_ARC = 0.5
RING_ARC_TOLERANCE = 0.1


@dataclass(frozen=True)
class Raised:
    """A crop with a disc's gaps raised to its plateau, and the pixels that closed a gap (the outline
    next to them is not the disc's own), or None where none did."""

    crop: np.ndarray
    pixels: np.ndarray | None


def _bridge_occluders(crop, distance, level, plateau, radius) -> Raised:
    """``crop`` with thin occluders across the disc raised to the plateau, and the
    bridged pixels; ``crop`` as it is where nothing was bridged.

    The region above ``level`` (holes filled: a hole inside the disc leaves the
    outline alone) is closed with a square of half-side ``OCCLUSION_BRIDGE_REL`` · r
    (a closing leaves every convex shape as it is, whatever the convex element, and a
    square's is separable, so fast); only pixels within the disc's reach from the
    centre count, so the gap to a neighbouring disc is not bridged.
    """
    if radius < OCCLUSION_MIN_RADIUS_PX:
        return Raised(crop, None)
    side = 2 * max(2, int(round(OCCLUSION_BRIDGE_REL * radius))) + 1
    box = _box(distance, 1.05 * radius + 1.0 + side)
    raised, bridged = _bridge_in_box(crop[box], distance[box], level, plateau, radius, side)
    if bridged is None:
        return Raised(crop, None)
    crop, mask = crop.copy(), np.zeros(crop.shape, dtype=bool)
    crop[box], mask[box] = raised, bridged
    return Raised(crop, mask)


def _fill_holes(mask: np.ndarray) -> np.ndarray:
    """``mask`` with its holes filled: the pixels outside it that no 4-connected path outside it
    joins to the border (``scipy.ndimage.binary_fill_holes`` with its default cross)."""
    if mask.size == 0:
        return mask.copy()
    count, labels = cv2.connectedComponents((~mask).view(np.uint8), connectivity=4)
    open_ = np.zeros(count, dtype=np.bool_)
    for border in (labels[0], labels[-1], labels[:, 0], labels[:, -1]):
        open_[border] = True
    return mask | ~open_[labels]


def _box(distance: np.ndarray, reach: float) -> tuple[slice, slice]:
    """The bounding box of the pixels within ``reach`` of the centre."""
    rows = np.nonzero((distance <= reach).any(axis=1))[0]
    cols = np.nonzero((distance <= reach).any(axis=0))[0]
    if not len(rows):
        return slice(0, 0), slice(0, 0)
    return slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)


def _bridge_in_box(crop, distance, level, plateau, radius, side):
    """:func:`_bridge_occluders` within the disc's box."""
    if crop.size == 0:
        return crop, None
    above = _fill_holes(crop > level)
    # Only the disc's pieces are joined, not the noise specks around a faint one.
    count, labels, stats, _ = cv2.connectedComponentsWithStats(above.view(np.uint8), connectivity=8)
    pieces = np.nonzero(stats[:, cv2.CC_STAT_AREA] >= OCCLUSION_PIECE_SHARE * math.pi * radius * radius)[0]
    above = np.isin(labels, pieces[pieces > 0])
    element = cv2.getStructuringElement(cv2.MORPH_RECT, (side, side))
    closed = cv2.morphologyEx(above.view(np.uint8), cv2.MORPH_CLOSE, element).astype(bool)
    bridged = closed & ~above & (distance <= 1.05 * radius + 1.0)
    # An occluder leaves one wide bridged piece; noise along a faint disc's edge, many small ones.
    count, labels, stats, _ = cv2.connectedComponentsWithStats(bridged.view(np.uint8), connectivity=8)
    pieces = np.nonzero(stats[:, cv2.CC_STAT_AREA] >= side * side)[0]
    bridged = np.isin(labels, pieces[pieces > 0])
    if bridged.sum() <= OCCLUSION_MIN_SHARE * math.pi * radius * radius:
        return crop, None
    return np.where(bridged, np.float32(max(plateau, level)), crop), bridged


def _ring_arc(crop, level, seed_rc, radius) -> SeenOutline | None:
    """The outer arcs of a ring's broken rim and the circle through them: the outline, with
    the circle filled in where the rim is not seen, or None.

    Around the seed, in RING_ARC_BINS directions, the farthest point of the 50 %
    contours between RING_ARC_BAND times the radius is the rim's outer edge; a
    circle is fitted to them (twice: points off the first circle by more than
    RING_ARC_TOLERANCE of its radius are dropped). The rim must be seen over
    RING_MIN_ARC of the directions.
    """
    r0 = max(0, int(seed_rc[0] - RING_ARC_BAND[1] * radius - 2))
    c0 = max(0, int(seed_rc[1] - RING_ARC_BAND[1] * radius - 2))
    r1, c1 = int(seed_rc[0] + RING_ARC_BAND[1] * radius + 3), int(seed_rc[1] + RING_ARC_BAND[1] * radius + 3)
    contours = [c[:, ::-1] for c in measure.find_contours(crop[r0:r1, c0:c1], level) if len(c) >= 2]
    if not contours:
        return None
    points = np.vstack(contours) + np.array([c0, r0])  # (x, y) in the crop
    dx, dy = points[:, 0] - seed_rc[1], points[:, 1] - seed_rc[0]
    reach = np.hypot(dx, dy)
    band = (reach >= RING_ARC_BAND[0] * radius) & (reach <= RING_ARC_BAND[1] * radius)
    if not band.any():
        return None
    bins = ((np.arctan2(dy, dx) + math.pi) / (2 * math.pi) * RING_ARC_BINS).astype(int) % RING_ARC_BINS
    outer = []
    for b in np.unique(bins[band]):
        here = np.nonzero(band & (bins == b))[0]
        outer.append(here[np.argmax(reach[here])])
    rim = points[outer]
    for _ in range(2):
        if len(rim) < RING_MIN_ARC * RING_ARC_BINS:
            return None
        circle = _fit_circle(rim)
        off = np.abs(np.hypot(rim[:, 0] - circle.cx, rim[:, 1] - circle.cy) - circle.radius)
        rim = rim[off <= RING_ARC_TOLERANCE * circle.radius]
    if len(rim) < RING_MIN_ARC * RING_ARC_BINS:
        return None
    circle = _fit_circle(rim)
    order = np.argsort(np.arctan2(rim[:, 1] - circle.cy, rim[:, 0] - circle.cx))
    return _completed_outline(rim[order], circle)


def _close_ring(crop, distance, level, plateau, radius) -> Raised:
    """``crop`` with a ring's rim closed where it breaks and its darker centre raised to the
    plateau, so that its outer outline closes; and the pixels that closed the rim (their
    outline is not seen), or None.

    The rim's region above ``level`` is closed with a square of half-side
    ``RING_GAP_REL`` · r (at least 1 px), then its hole filled: the hole is the
    centre, not a gap.
    """
    side = 2 * max(1, int(round(RING_GAP_REL * radius))) + 1
    box = _box(distance, 1.05 * radius + 1.0 + side)
    above = crop[box] > level
    element = cv2.getStructuringElement(cv2.MORPH_RECT, (side, side))
    closed = cv2.morphologyEx(above.view(np.uint8), cv2.MORPH_CLOSE, element).astype(bool)
    near = distance[box] <= 1.05 * radius + 1.0
    filled = _fill_holes(closed & near)
    gaps = closed & near & ~_fill_holes(above & near)
    raised = crop.copy()
    raised[box] = np.where(filled & ~above, np.float32(max(plateau, level)), crop[box])
    if not gaps.any():
        return Raised(raised, None)
    mask = np.zeros(crop.shape, dtype=bool)
    mask[box] = gaps
    return Raised(raised, mask)
