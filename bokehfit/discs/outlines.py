"""Draw a candidate's closed 50 % outline: its levels, the contour around its centre in a
window grown while the outline runs into it, and the disc cut out of other light it runs on into.

Notes
-----
The outline is the sub-pixel iso-contour at the 50 % level ``b + (p − b)/2``
(:mod:`bokehfit.discs.levels`; marching squares, :mod:`bokehfit.discs.contours`) around the
candidate's centre, closed along the frame where the frame cuts the disc. A second pass
repeats this with the measured centre and size. Where the outline runs on into
neighbouring light (discs that touch, a bright region), the disc is cut out by
a circle of 1.3 r + 2 px and flagged ``overlaps``. Thin occluders and a ring's
broken rim are closed first (:mod:`bokehfit.discs.gaps`).

Where no outline is drawn, the reason (a :class:`bokehfit.discs.reasons.NoDisc`; the rest are
:mod:`bokehfit.discs.verdict`'s):

``no surround``     no background around it in the frame (it fills the frame);
``faint``           the plateau does not stand out of the surround (the test of
                    :mod:`bokehfit.discs.verdict`'s Notes);
``no outline``      no 50 % contour around the centre;
``part of a larger region``  the outline, cut out of a bright region, lies
                    mostly on the cutting circle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from bokehfit.discs.candidates import LARGE_DISC_PX
from bokehfit.discs.contours import _open_in_window, _outline, polygon_area_centroid
from bokehfit.discs.gaps import _bridge_occluders, _close_ring, _ring_arc
from bokehfit.discs.levels import Levels, Window, _annulus_levels, _contrast_ok, _levelled, _percentile
from bokehfit.discs.reasons import NoDisc, Reason

__all__ = ["Outlined"]

#: The search window grows by these factors while the outline runs into it.
WINDOW_GROWTH = (1.0, 2.0, 4.0)
#: ... but for a window from LARGE_DISC_PX across on only to the second: one 4 times larger
#: would hold millions of pixels, and an outline that runs out of ±3.4 radii is a
#: piece of something larger, or touches its neighbours, either way.
#: A disc cut out of a larger bright region whose outline lies mostly on the
#: cutting circle is a piece of that region, not a disc.
MAX_CUT_SHARE = 0.5
#: The width of a sharp disc's edge (px): the noise's jitter of the outline is reckoned with it,
#: and the verdict's soft-edge test allows at least this much (:mod:`bokehfit.discs.verdict`).
EDGE_WIDTH_MIN_PX = 3.0
#: Faint discs' outlines: the crop is smoothed until the noise moves the 50 % contour by about this
#: much (px), with a Gaussian of at most OUTLINE_SMOOTH_REL of the disc's radius.
OUTLINE_JITTER_PX = 0.2
OUTLINE_SMOOTH_REL = 0.08
#: In ring mode the plateau is taken within the whole disc (plus a pixel): the rim is its edge.
RING_CORE_REL = 1.05


@dataclass(frozen=True)
class Outlined:
    """A closed outline around a candidate, with what it was drawn from: what :func:`bokehfit.discs.verdict.describe` judges."""

    window: Window  #: where ``crop`` lies in the photo
    crop: np.ndarray  #: the pixels the outline was drawn on: the window's, less the background plane if any
    levels: Levels
    outline: np.ndarray  #: (N, 2) closed sub-pixel outline in the crop, (x, y) = (column, row)
    merged: bool  #: cut out of a larger bright region by a circle
    #: Pixels raised to the plateau before the outline was drawn (a bridged occluder, a ring's closed
    #: gaps): the outline next to them is not the disc's own; None where there are none.
    bridged: np.ndarray | None
    on_cut: np.ndarray  #: per outline point: on the cutting circle, or otherwise not the disc's own edge
    #: The Gaussian (σ, px) the crop was smoothed with (0: none), and the standard deviation of the white pixel
    #: noise before it (None: read off the crop, :func:`bokehfit.discs.levels.pixel_noise`): the noise's share of
    #: the edge's gradient (:func:`bokehfit.discs.contours._edge_gradient`).
    smoothing_px: float = 0.0
    pixel_noise: float | None = None


def _closed_outline(luminance, center_xy, radius, reach, core_rel=0.8, percentile=90, levelled=None, edge_rel=1.0):
    """Levels and the closed 50 % outline around ``center_xy``, growing the window
    while the outline runs into it; the last window masks beyond ``reach`` instead
    (the disc then touches a neighbour). The plateau is the ``percentile`` within
    ``core_rel`` · r. Returns the :class:`Outlined`, or why there is none (a :class:`NoDisc`). ``levelled`` keeps the
    :class:`Surround` of each window (a dict kept by the caller for one candidate)."""
    height, width = luminance.shape
    levelled = {} if levelled is None else levelled
    large = max(1.7 * radius + 4.0, reach) >= LARGE_DISC_PX
    for grow in WINDOW_GROWTH[:2] if large else WINDOW_GROWTH:
        half = int(math.ceil(grow * max(1.7 * radius + 4.0, reach)))
        window = Window.around(luminance.shape, center_xy, half)
        distance = window.distance(center_xy)
        crop = window.of(luminance)
        key = (center_xy, radius, half)
        if key not in levelled:  # the ring mode's second plateau percentile has the same window
            levelled[key] = _annulus_levels(crop, distance, radius)
        if levelled[key] is None:
            return NoDisc(Reason.NO_SURROUND)
        surround = levelled[key]
        plane, background, noise, ring_lift = surround.plane, surround.background, surround.noise, surround.lift
        core = _levelled(crop, distance <= max(core_rel * radius, 0.75), plane)
        plateau = float(_percentile(core, percentile)) if core.size else background
        plateau = background + edge_rel * (plateau - background)  # a bright centre's: the top of its edge
        level = background + 0.5 * (plateau - background)
        if not _contrast_ok(plateau - background, noise, background, 2.0 * radius):
            return NoDisc(Reason.FAINT)
        if plane is not None:
            crop = crop - plane.over(crop.shape)
        seed_rc = (center_xy[1] - window.r0, center_xy[0] - window.c0)
        # The gaps, and a broken rim's arcs, are sought in the light the outline is drawn on, its noise quieted:
        # a faint disc's 50 % region frays at the edge pixel by pixel, and a closing of the raw region took the
        # fraying all round for an occluder's gap or a rim's breaks, and the disc's whole outline for not its own.
        quiet = _quieted(crop, plateau - background, noise, radius)
        close_gaps = _close_ring if core_rel == RING_CORE_REL else _bridge_occluders
        raised = close_gaps(quiet, distance, level, plateau, radius)
        outline = _outline(raised.crop, level, background, seed_rc)
        if outline is None and core_rel == RING_CORE_REL:
            arc = _ring_arc(quiet, level, seed_rc, radius)
            if arc is not None:  # a rim that breaks: its arcs, and the circle through them
                return Outlined(window, crop, Levels(background, plateau, noise, ring_lift), arc.points, False, None, ~arc.seen)
        if outline is None:
            return NoDisc(Reason.NO_OUTLINE)
        if not _open_in_window(outline, crop.shape, window, (height, width)):
            levels = Levels(background, plateau, noise, ring_lift)
            return Outlined(window, crop, levels, outline, False, raised.pixels, np.zeros(len(outline), dtype=bool))
    # Still open: part of a larger bright structure, or discs run together. Cut
    # the disc out of it with a circle through its neighbours' gap.
    masked = np.where(distance <= reach, crop, min(background, level - 1e-6)).astype(np.float32)
    outline = _outline(masked, level, background, seed_rc)
    if outline is None:
        return NoDisc(Reason.NO_OUTLINE)
    on_cut = np.abs(np.hypot(outline[:, 0] - seed_rc[1], outline[:, 1] - seed_rc[0]) - reach) < 1.0
    if on_cut.mean() > MAX_CUT_SHARE:  # mostly the cutting circle: a piece of something larger
        return NoDisc(Reason.PART_OF_LARGER_REGION)
    return Outlined(window, crop, Levels(background, plateau, noise, ring_lift), outline, True, None, on_cut)


def _quieted(crop: np.ndarray, contrast: float, noise: float, radius: float) -> np.ndarray:
    """``crop`` smoothed where the noise would make its 50 % contour jitter: the contour moves by
    about noise / gradient = (noise / contrast) · EDGE_WIDTH_MIN_PX px, and a Gaussian of σ px
    lowers white noise 2√π·σ times; σ is the least that brings the jitter to OUTLINE_JITTER_PX,
    at most OUTLINE_SMOOTH_REL of the radius (a blade's corner is rounded by about σ)."""
    jitter = noise / max(contrast, 1e-12) * EDGE_WIDTH_MIN_PX
    if jitter <= OUTLINE_JITTER_PX:
        return crop
    sigma = min(jitter / OUTLINE_JITTER_PX / (2.0 * math.sqrt(math.pi)), OUTLINE_SMOOTH_REL * radius)
    if sigma < 0.5:
        return crop
    return cv2.GaussianBlur(np.ascontiguousarray(crop, dtype=np.float32), (0, 0), sigma, borderType=cv2.BORDER_REPLICATE)


def _two_passes(luminance, center_xy, radius, reach, core_rel, percentile=90, levelled=None, edge_rel=1.0):
    """:func:`_closed_outline` with the candidate's size, then with the measured one."""
    found = None
    for _ in range(2):
        found = _closed_outline(luminance, center_xy, radius, 1.3 * reach + 2.0, core_rel, percentile, levelled, edge_rel)
        if isinstance(found, NoDisc):
            return found
        outline = found.outline
        area, cx, cy = polygon_area_centroid(outline)
        if found.merged or area <= 0:
            break
        center_xy, radius = (cx + found.window.c0, cy + found.window.r0), max(1.0, math.sqrt(area / math.pi))
        reach = float(np.max(np.hypot(outline[:, 0] - cx, outline[:, 1] - cy)))
    return found
