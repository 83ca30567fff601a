"""Measure one candidate blob: sub-pixel outline, size, centre, levels, and whether it is a disc.

The work is done in rooms of one job each: :mod:`bokehfit.discs.levels` (the window, the
surround's background and noise, the plateau), :mod:`bokehfit.discs.outlines` (the closed 50 %
outline, with :mod:`bokehfit.discs.contours` and :mod:`bokehfit.discs.gaps`),
:mod:`bokehfit.discs.verdict` (the :class:`Measurement`: size, shape, flags and the rejection
reasons) and :mod:`bokehfit.discs.clusters` (a blob of overlapping discs split into its discs).
This module measures one candidate with them: as a plateau disc, and where that fails as a ring
or a bright-centre disc, or as a cluster; and it exports the names the package imports from it.

Notes
-----
- **Ring discs** (soap-bubble): a thin bright rim around a darker centre. Its
  half-peak candidate is an annulus, so its equal-area size is too small and the
  centre holds no plateau. A candidate that reaches ``RING_REACH`` times farther
  than its equal-area radius, and fails as a plateau disc, is measured again
  with the rim as the plateau (``RING_PLATEAU_PERCENTILES``); the outer 50 %
  outline is the disc's. It is flagged ``ring`` by its centre's dip
  (:mod:`bokehfit.discs.verdict`).
- **Bright-centre discs** (rim < 0): the light falls from the centre to the
  rim, then steps down. Where the step's top lies under half the peak, the
  half-peak outline runs on the slope and its edge is soft; such a candidate is
  searched for the step (``BRIGHT_CENTRE_LEVELS``) and, where there is one,
  measured again at the step's middle and flagged ``bright_centre``. Found so
  down to an edge at about 15 % of the peak (rim ≈ −0.74). Limits: with the
  step's top just above half the peak the half-peak outline runs along it and
  the disc comes out up to about 6 % small (the fit's pixel model then
  measures it); below 15 % the step is lost in the slope ("soft edge").
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from bokehfit.discs.clusters import split_cluster
from bokehfit.discs.contours import _crop_gradients, _edge_gradient, _open_in_window, _outline, polygon_area_centroid
from bokehfit.discs.gaps import OCCLUSION_BRIDGE_REL, OCCLUSION_MIN_SHARE
from bokehfit.discs.levels import MIN_SNR, Window, _annulus_levels, _levelled, _percentile
from bokehfit.discs.outlines import RING_CORE_REL, Outlined, _closed_outline, _two_passes
from bokehfit.discs.reasons import NoDisc, Reason
from bokehfit.discs.verdict import MAX_ELONGATION, MIN_SOLIDITY, MIN_THICKNESS_REL, RING_DIP, Measurement, describe

__all__ = [
    "Measurement",
    "measure_candidate",
    "describe",
    "polygon_area_centroid",
    "outline_diameter",
    "split_cluster",
    "MIN_SNR",
    "MIN_SOLIDITY",
    "MAX_ELONGATION",
    "MIN_THICKNESS_REL",
    "RESOLVABLE_PX",
    "OCCLUSION_BRIDGE_REL",
    "OCCLUSION_MIN_SHARE",
    "RING_DIP",
]

#: Equal-area diameter from which a disc shows its shape.
RESOLVABLE_PX = 8.0
#: Ring mode is tried for candidates whose reach (half their bounding box) exceeds their
#: equal-area radius by this factor: an annulus's half-peak region is hollow (a disc: 1).
RING_REACH = 1.2
#: In ring mode (the plateau taken within the whole disc, RING_CORE_REL) the plateau is first the
#: rim (90th percentile there): its outer 50 % outline is the disc's edge. Where the rim is dimmer
#: in places its outline breaks into arcs; then the median, whose half takes in the rim and the
#: centre (lit too, only less): an outline a little outside the edge, but closed.
RING_PLATEAU_PERCENTILES = (90, 50)
#: Bright-centre discs (rim < 0, design.md §3b): the light falls from the centre towards the
#: edge and then steps down to the background, so the half-peak contour lies on the slope,
#: inside the disc, where the edge is soft. A "soft edge" candidate is searched for a step
#: among the iso-contours at these shares of its contrast (median gradient along each). A step
#: is steepest at its middle, and above its top only the slope of the centre is left: where the
#: steepest contour lies at most BRIGHT_CENTRE_MAX_LEVEL up and is BRIGHT_CENTRE_STEEPER times
#: steeper than every contour above the step (twice its level, plus BRIGHT_CENTRE_SHOULDER for
#: the shoulder the blur rounds), the step is the disc's edge, and it is measured again with
#: the top of the step as its plateau. A Gaussian blob's steepest contour is
#: at e^−½ = 0.61 of its peak and a cone's are all equally steep: neither passes. (Cycles'
#: bright-centre circle at rim −0.6: steepest at 0.15–0.2, 1.4–1.9 times those above the step.)
BRIGHT_CENTRE_LEVELS = (0.06, 0.09, 0.12, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.6)
BRIGHT_CENTRE_MAX_LEVEL = 0.25
BRIGHT_CENTRE_SHOULDER = 0.1
BRIGHT_CENTRE_STEEPER = 1.3
#: A cluster's plateau, for its outline: this percentile of its core, where the brightest
#: overlaps (the light of two or three discs added) are a minority.
CLUSTER_PLATEAU_PERCENTILE = 50


def measure_candidate(
    luminance: np.ndarray,
    clipped_mask: np.ndarray | None,
    center_xy: tuple[float, float],
    diameter_px: float,
    extent_px: float,
    min_noise: float,
    min_diameter_px: float,
    cluster: bool = False,
) -> Measurement | NoDisc:
    """Measure the disc around ``center_xy`` of about ``diameter_px``, reaching about
    ``extent_px`` from its centre; a :class:`NoDisc` where there is no disc to measure.

    Two passes: the first uses the candidate's size for the levels, the second
    the size it measured. A hollow candidate that fails as a plateau disc is
    measured again as a ring (the module's Notes). A ``cluster`` candidate (a blob
    that may hold overlapping discs of different brightness) is outlined at half
    its median level over the surround, so that its dimmer discs are inside the
    outline: :func:`split_cluster` then splits it.
    """
    radius = max(1.0, 0.5 * diameter_px)
    if cluster:
        found = _closed_outline(luminance, center_xy, radius, 1.3 * max(radius, extent_px) + 2.0, 0.8, CLUSTER_PLATEAU_PERCENTILE)
        if isinstance(found, NoDisc):
            return found
        return describe(luminance, clipped_mask, found, min_noise, min_diameter_px)
    levelled: dict = {}
    found = _two_passes(luminance, center_xy, radius, max(radius, extent_px), 0.8, levelled=levelled)
    hollow = extent_px > RING_REACH * radius and extent_px >= RESOLVABLE_PX  # a ring shows as one from 16 px
    if isinstance(found, NoDisc) and found.reason in (Reason.FAINT, Reason.NO_OUTLINE) and hollow:
        # A ring's half-peak region is its rim: take its reach as the radius, the rim as the plateau.
        for percentile in RING_PLATEAU_PERCENTILES:
            ring = _two_passes(luminance, center_xy, extent_px, extent_px, RING_CORE_REL, percentile, levelled)
            if not isinstance(ring, NoDisc):
                found = ring
                break
    if isinstance(found, NoDisc):
        return found
    measured = describe(luminance, clipped_mask, found, min_noise, min_diameter_px)
    if measured.reason is Reason.SOFT_EDGE:
        step = _step_share(found)
        if step is not None:  # a bright centre: measured again with the top of its edge as the plateau
            outline = found.outline
            _, cx, cy = polygon_area_centroid(outline)
            reach = float(np.max(np.hypot(outline[:, 0] - cx, outline[:, 1] - cy)))
            again = _two_passes(luminance, (cx + found.window.c0, cy + found.window.r0), reach, reach, 0.8, 90, levelled, 2.0 * step)
            if not isinstance(again, NoDisc):
                stepped = describe(luminance, clipped_mask, again, min_noise, min_diameter_px)
                if stepped.reason is None and stepped.diameter_px > measured.diameter_px:
                    return replace(stepped, bright_centre=True)
    return measured


def _step_share(found: Outlined) -> float | None:
    """The share of the contrast at the middle of a bright-centre disc's edge, or None.

    ``found`` is a closed outline whose edge is soft; the iso-contours at
    :data:`BRIGHT_CENTRE_LEVELS` around its centre are compared by their median
    gradient (module constants). None where no level is markedly steeper low down:
    no step, so no disc's edge.

    The levels up to BRIGHT_CENTRE_MAX_LEVEL are traced first (the step, if any, is the steepest of them); then
    those above, from the top, until one settles it: steeper than the step (the steepest level lies above
    BRIGHT_CENTRE_MAX_LEVEL), or above the step's shoulder and not BRIGHT_CENTRE_STEEPER times less steep. A glow,
    steepest at 0.61 of its peak, is settled by the first. The answer is the one all ten levels give.
    """
    crop, outline = found.crop, found.outline
    background, plateau = found.levels.background, found.levels.plateau
    contrast = plateau - background
    _, cx, cy = polygon_area_centroid(outline)
    gradients = _crop_gradients(crop)  # one crop, ten levels

    def steepness(share: float) -> float:
        contour = _outline(crop, background + share * contrast, background, (cy, cx))
        return 0.0 if contour is None else _edge_gradient(crop, contour, gradients)

    low = [level for level in BRIGHT_CENTRE_LEVELS if level <= BRIGHT_CENTRE_MAX_LEVEL]  # the first ones: ascending
    steep = [steepness(level) for level in low]
    best = int(np.argmax(steep))  # the first of the steepest, as over all ten: those above come after
    share, steepest = low[best], steep[best]
    shoulder = 2.0 * share + BRIGHT_CENTRE_SHOULDER - 1e-9
    if any(level >= shoulder and BRIGHT_CENTRE_STEEPER * s > steepest for level, s in zip(low, steep)):
        return None
    for level in reversed(BRIGHT_CENTRE_LEVELS[len(low):]):
        s = steepness(level)
        if s > steepest or (level >= shoulder and BRIGHT_CENTRE_STEEPER * s > steepest):
            return None
    return share


def outline_diameter(image: np.ndarray, center_xy: tuple[float, float], diameter_px: float) -> float | None:
    """Equal-area diameter of the 50 % outline of a plateau disc of about ``diameter_px`` at ``center_xy``
    in ``image`` (one channel of linear light), with the levels of the module's Notes; None where the
    disc does not stand ``MIN_SNR`` noise levels out of its surround there or has no closed outline.

    For measures of a disc already found, in another image of the same scene: the colour channels.
    """
    radius = max(1.0, 0.5 * diameter_px)
    window = Window.around(image.shape, center_xy, int(math.ceil(1.7 * radius + 4.0)))
    distance = window.distance(center_xy)
    crop = window.of(image)
    surround = _annulus_levels(crop, distance, radius)
    if surround is None:
        return None
    plane, background, noise = surround.plane, surround.background, surround.noise
    core = _levelled(crop, distance <= max(0.8 * radius, 0.75), plane)
    plateau = float(_percentile(core, 90)) if core.size else background
    if not plateau - background >= MIN_SNR * noise or plateau <= background:
        return None
    if plane is not None:
        crop = crop - plane.over(crop.shape)
    seed_rc = (center_xy[1] - window.r0, center_xy[0] - window.c0)
    outline = _outline(crop, background + 0.5 * (plateau - background), background, seed_rc)
    if outline is None or _open_in_window(outline, crop.shape, window, image.shape):
        return None
    return 2.0 * math.sqrt(polygon_area_centroid(outline)[0] / math.pi)
