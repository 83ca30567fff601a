"""Discs measured at given places: a person's picks, and the places the photo's search hands over.

:func:`measure_discs_at` measures the discs at a person's places, and only those. The photo's
search (:mod:`bokehfit.discs.search`) measures here the circles through its edges and, where the
contour calls a blob faint or soft-edged, the blob again. At a place and about a size a disc is
measured as a candidate is, by the contour (:func:`bokehfit.discs.measure.measure_candidate`;
where it overlaps others, the part of its cluster closest to the place), and where that finds no
disc, by its own step along rays (:func:`bokehfit.discs.rays.measure_rays`). Both searches then
measure again by its own step a disc whose contour runs into its neighbours' light
(:func:`_by_own_steps`).
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import replace

import numpy as np

from bokehfit.discs.candidates import MIN_NOISE
from bokehfit.discs.disc import (
    MIN_FIT_SEEN,
    MIN_OUTLINE_SEEN,
    DiscSearch,
    Rejection,
    _check_image,
    _check_parameters,
    _discs_of,
    _distinct_measurements,
    _own_outlines,
    _same_size,
)
from bokehfit.discs.labels import MATCH_DIAMETER_REL
from bokehfit.discs.measure import RESOLVABLE_PX, Measurement, measure_candidate, split_cluster
from bokehfit.discs.rays import measure_rays
from bokehfit.discs.reasons import NoDisc, Reason

#: A person's disc whose contour comes out more than this factor off the size they read (the labels' own
#: match: a diameter within 25 %) is measured again by its own step, and the measurement nearer that size is
#: kept: a ring's contour outlines the light inside its rim, a disc of a chain the brightest overlap.
ASKED_SIZE_RATIO = 1.25


def measure_discs_at(
    luminance: np.ndarray,
    clipped: np.ndarray | None = None,
    places=(),
) -> DiscSearch:
    """Measure the discs at given places (a person's picks), and only those.

    Parameters
    ----------
    luminance, clipped : as :func:`find_discs`.
    places : iterable of ((x, y), diameter_px)
        Each disc's centre (full-resolution pixels, y down) and about how large it is.

    Returns
    -------
    DiscSearch
        Each place measured afresh as :func:`find_discs` measures a candidate (outline, levels,
        evidence), whatever the finder's own tests of a disc would say: the person vouches that
        it is one. A place that overlaps others is measured as the part of its cluster closest to
        it. A place where no outline of about that size can be drawn is listed in ``rejections``
        with the reason; the others are the discs (not usable ones keep their reasons).
    """
    start = time.perf_counter()
    luminance = _check_image(luminance)
    clipped, _, _, _ = _check_parameters(luminance.shape, clipped, 1.0, math.inf, None)
    places = [((float(x), float(y)), float(d)) for (x, y), d in places]
    rejected: Counter = Counter()
    rejections: list[Rejection] = []
    measurements: list[Measurement] = []
    for xy, diameter in places:
        m = _nearer_the_asked(luminance, clipped, _measure_place(luminance, clipped, xy, diameter, read=True), xy,
                              diameter, read=True)
        if isinstance(m, NoDisc):
            rejection = Rejection.of(xy, diameter, m)
            rejected[rejection.rejected_because] += 1
            rejections.append(rejection)
        else:
            measurements.append(replace(m, reason=None))
    measurements = [replace(m, reason=None) for m in _by_own_steps(luminance, clipped, measurements, 1.0)]
    return _discs_of(measurements, len(places), rejected, start, [], rejections, None, given=True)


def asked_band(diameter: float) -> tuple[float, float]:
    """The radii (px) between which a person's disc of ``diameter`` has its edge, where measured by its own step:
    the size they read, within the labels' own match (:data:`bokehfit.discs.labels.MATCH_DIAMETER_REL` either way).
    The rays' own band (:data:`bokehfit.discs.rays.BAND_REL`, half to 1.55 times the radius) would take a
    neighbour's bright rim crossing the disc well inside its edge for the disc's own step (reference photo 14's
    strings of discs)."""
    return 0.5 * diameter * (1.0 - MATCH_DIAMETER_REL), 0.5 * diameter * (1.0 + MATCH_DIAMETER_REL)


def _measure_place(luminance, clipped, xy, diameter: float, min_diameter_px: float = 1.0,
                   rays_after: tuple[Reason, ...] | None = None, read: bool = False) -> Measurement | NoDisc:
    """The disc at a place and about a size (a person's pick, ``read``; a circle through an edge): measured as a
    candidate there; where it overlaps others, the part of its cluster closest to the place. A
    :class:`NoDisc` where no outline of about that size can be drawn there. The measurement's own ``reason`` (its
    tests of a disc) is left for the caller to weigh."""
    height, width = luminance.shape
    if not (0 <= xy[0] < width and 0 <= xy[1] < height):
        return NoDisc(Reason.OUTSIDE_PHOTO)
    m = _contour_at_place(luminance, clipped, xy, diameter, min_diameter_px)
    return _by_rays_after(luminance, clipped, m, xy, diameter, min_diameter_px, rays_after, read)


def _by_rays_after(luminance, clipped, m: Measurement | NoDisc, xy, diameter: float, min_diameter_px: float,
                   rays_after: tuple[Reason, ...] | None, read: bool = False) -> Measurement | NoDisc:
    """The contour's measurement ``m`` at a place, or, where it finds no disc there for one of the reasons
    ``rays_after`` (any reason: None), the disc measured there by its own step along rays (:func:`_stepped`; ``read``:
    ``diameter`` is a person's reading), where that finds a disc of about ``diameter`` at the place (a measurement
    that draws an outline, over a reason)."""
    if isinstance(m, Measurement) and m.reason is None:
        return m
    if rays_after is not None and m.reason not in rays_after:
        return m
    # Where one level does not outline it (a faint disc over haze and its neighbours' light, discs
    # that overlap, a bright centre), the disc's own edge along rays from the place may.
    stepped = _stepped(luminance, clipped, xy, diameter, min_diameter_px, read)
    if isinstance(stepped, Measurement) and _near_place(stepped, xy, diameter) and \
            (stepped.reason is None or isinstance(m, NoDisc)):
        return stepped
    return m


def _nearer_the_asked(luminance, clipped, m: Measurement | NoDisc, xy, diameter: float,
                      read: bool = False) -> Measurement | NoDisc:
    """A disc asked for at a place and size (a person's pick, a circle of a size the search found) ``m``
    measured there by its contour, or, where that size is more than ASKED_SIZE_RATIO off the ``diameter``
    asked, by its own step along rays (:func:`_stepped`; ``read``: ``diameter`` is a person's reading) if that
    comes out nearer it."""
    if not isinstance(m, Measurement) or m.own_step or abs(math.log(m.diameter_px / diameter)) <= math.log(ASKED_SIZE_RATIO):
        return m
    stepped = _stepped(luminance, clipped, xy, diameter, 1.0, read)
    if isinstance(stepped, Measurement) and stepped.reason is None and _near_place(stepped, xy, diameter) and \
            abs(math.log(stepped.diameter_px / diameter)) < abs(math.log(m.diameter_px / diameter)):
        return stepped
    return m


def _stepped(luminance, clipped, xy, diameter: float, min_diameter_px: float, read: bool) -> Measurement | NoDisc:
    """The disc at a place measured by its own step along rays, within the rays' own band; where ``diameter`` is a
    person's reading (``read``), also within :func:`asked_band` of it, and that disc kept where it comes out nearer
    the size read and sees its step on as many rays. The narrow band keeps a neighbour's bright rim crossing the
    disc well inside its edge from being taken for the edge. Where the edge lies outside it (the corners of a
    triangle or a slit read a little small, a soap bubble read larger than its step) the rays there find no step
    in it, or no disc at all, and the wide band's disc is kept."""
    wide = _split_steps(measure_rays(luminance, clipped, xy, diameter, MIN_NOISE, min_diameter_px), xy, diameter)
    if not read:
        return wide
    narrow = _split_steps(measure_rays(luminance, clipped, xy, diameter, MIN_NOISE, min_diameter_px,
                                       asked_band(diameter)), xy, diameter)
    if not isinstance(narrow, Measurement) or narrow.reason is not None:
        return wide
    if not isinstance(wide, Measurement) or wide.reason is not None:
        return narrow
    nearer = abs(math.log(narrow.diameter_px / diameter)) < abs(math.log(wide.diameter_px / diameter))
    return narrow if nearer and narrow.outline_reliable.mean() >= wide.outline_reliable.mean() else wide


def _split_steps(m: Measurement | NoDisc, xy, diameter: float) -> Measurement | NoDisc:
    """A disc measured by its own step along rays, or where that step runs round its neighbours too (the outer edge
    of discs that overlap, each a step down to the ground), the one of their discs nearest the place
    (:func:`_nearest_part`)."""
    return _nearest_part(m, xy, diameter) if isinstance(m, Measurement) and m.reason is None else m


def _near_place(m: Measurement, xy, diameter: float) -> bool:
    """The measurement is of a disc of about ``diameter`` at ``xy`` (within twice or half the size,
    its centre within half the diameter)."""
    return abs(math.log(m.diameter_px / diameter)) <= math.log(2.0) and \
        math.hypot(m.center_xy[0] - xy[0], m.center_xy[1] - xy[1]) <= 0.5 * diameter


def _contour_at_place(luminance, clipped, xy, diameter: float, min_diameter_px: float) -> Measurement | NoDisc:
    """The contour measurement at a place (:func:`bokehfit.discs.measure.measure_candidate`), the part
    of its cluster closest to the place, or why there is none."""
    m = measure_candidate(luminance, clipped, xy, diameter, 0.5 * diameter, MIN_NOISE, min_diameter_px)
    if isinstance(m, NoDisc):
        return m
    m = _nearest_part(m, xy, diameter)
    if not _near_place(m, xy, diameter):
        return NoDisc(Reason.NOT_THE_DISC_ASKED,
                      f"the outline measured there ({m.diameter_px:.0f} px at {m.center_xy[0]:.0f},"
                      f" {m.center_xy[1]:.0f}) is not a disc of about {diameter:.0f} px")
    return m


def _nearest_part(m: Measurement, xy, diameter: float) -> Measurement:
    """``m``, or where it is a blob of overlapping discs (:func:`bokehfit.discs.measure.split_cluster`), the one of its
    discs nearest a disc of ``diameter`` at ``xy`` (or ``m`` itself, where it is nearer)."""
    parts = [m] + (split_cluster(m) if m.diameter_px >= 2.0 * RESOLVABLE_PX else [])
    return min(parts, key=lambda p: math.hypot(p.center_xy[0] - xy[0], p.center_xy[1] - xy[1]) / diameter
               + abs(math.log(p.diameter_px / diameter)))


def _by_own_steps(luminance, clipped, measurements: list[Measurement], min_diameter_px: float) -> list[Measurement]:
    """The measurements, those whose contour runs into other discs' light over more than MIN_FIT_SEEN
    of it (but shows MIN_OUTLINE_SEEN of it as its own: a disc, not a merged glow) measured again by
    their own step along rays (:func:`bokehfit.discs.rays.measure_rays`), where
    that finds the same disc and sees more of its edge (light adds: the step of a disc's edge is its
    own inside a neighbour's light, where a contour through the sum of both is neither's)."""
    measurements = _distinct_measurements(measurements)
    own, _ = _own_outlines(measurements)
    again = list(measurements)
    for i, (m, reliable) in enumerate(zip(measurements, own)):
        if m.own_step or not len(reliable) or not MIN_OUTLINE_SEEN <= reliable.mean() < MIN_FIT_SEEN \
                or m.diameter_px < RESOLVABLE_PX:
            continue  # only a disc whose contour shows at least half its outline as its own
        stepped = _split_steps(measure_rays(luminance, clipped, m.center_xy, m.diameter_px, MIN_NOISE, min_diameter_px),
                               m.center_xy, m.diameter_px)
        if isinstance(stepped, Measurement) and stepped.reason is None and _near_place(stepped, m.center_xy, m.diameter_px) \
                and _same_size(stepped.diameter_px, m.diameter_px) and stepped.outline_reliable.mean() > reliable.mean():
            again[i] = stepped
    return again
