"""The photo's search for its discs: :func:`find_discs`, in named steps.

1. The candidates (:func:`_candidates`): bright blobs above the local background
   (:mod:`bokehfit.discs.candidates`), one per place and size (:func:`_distinct`), within the limits
   (MAX_CLUSTER_CANDIDATES, MAX_CANDIDATES: the clearest first), largest first.
2. Each candidate measured (:func:`_measure_candidates`; a large one on the photo area-averaged,
   :mod:`bokehfit.discs.scales`), a larger disc first claiming the candidates
   inside it (:class:`_OutlineGrid`): a cluster as a whole, split into its discs
   (:func:`_measure_cluster`); a blob by its contour and, where that calls it faint or soft-edged,
   by its own step along rays (:func:`_measure_blob`), and where its edge is still soft, in its colours
   (:mod:`bokehfit.discs.colours`).
3. The circles through the photo's edges that no candidate measured (:func:`_circle_discs`),
   measured as places (:mod:`bokehfit.discs.places`); one the contour calls faint or cannot outline,
   kept where its own step along rays shows a ring all round (:func:`_ring_by_rays`).
4. The circles of the sizes measured so far that cross a measured disc's outline (:func:`_sized_discs`):
   discs at one depth are one size, and a disc of a chain shows its own edge over part of its outline,
   enough to vote for its centre at a size known (:func:`bokehfit.discs.circles.find_sized_circles`).
5. The discs whose contour runs into their neighbours' light measured again by their own step
   (:func:`bokehfit.discs.places._by_own_steps`).
6. The result (:func:`bokehfit.discs.disc._discs_of`): one per disc, largest first, each with
   what it offers. The blobs and places refused only for an edge too soft for a sharp disc's that are
   soft-edged discs (:func:`bokehfit.discs.verdict.soft_edged`: a bright-centred disc's light falls to its
   edge, and so does a glow's) were kept apart through steps 2–5, claiming no candidate and seeding no
   chain; those clear of every sharp disc join the result flagged ``soft_edge``, the fit's second tier.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial

import cv2
import numpy as np
from scipy.spatial import cKDTree

from bokehfit.clock import Clock
from bokehfit.discs.candidates import LARGE_DISC_PX, MIN_NOISE, Candidate, find_candidates
from bokehfit.discs.circles import SIZE_STEP, find_circles, find_sized_circles
from bokehfit.discs.colours import sharp_in_a_colour
from bokehfit.discs.disc import (
    SAME_DISC_CENTRE_REL,
    DiscSearch,
    Rejection,
    _check_image,
    _check_parameters,
    _discs_of,
    _same_size,
)
from bokehfit.discs.measure import (
    RESOLVABLE_PX,
    Measurement,
    measure_candidate,
    split_cluster,
)
from bokehfit.discs.places import (
    _by_own_steps,
    _by_rays_after,
    _measure_place,
    _near_place,
    _nearer_the_asked,
)
from bokehfit.discs.rays import measure_rays
from bokehfit.discs.reasons import NoDisc, Reason
from bokehfit.discs.scales import PhotoScales
from bokehfit.discs.verdict import light_ends, rim_above_centre, ring_all_round, soft_edged
from bokehfit.errors import InputError

#: Smallest disc the detector seeks by default (``bokehfit discs``): glints from 4 px are counted.
DEFAULT_MIN_DIAMETER_PX = 4.0
#: Smallest disc ``compare`` seeks by default: the smallest that shows its shape (RESOLVABLE_PX).
#: Smaller glints say nothing of the aperture, and seeking them is most of the search's work on
#: a large photo (their band is searched at full resolution, and there are thousands of them).
COMPARE_MIN_DIAMETER_PX = RESOLVABLE_PX
DEFAULT_MAX_DIAMETER_PX = 500.0
#: Most candidates measured per photo (the clearest first); the rest are counted as rejected.
#: A measurement takes about 1–3 ms, so this bounds the measuring to a few seconds.
MAX_CANDIDATES = 2000
#: Of those, up to this many candidates of LARGE_DISC_PX or more are measured first whatever
#: their clarity: a large faint disc has a low peak over the noise, yet thousands of small
#: glints must not crowd it out. Large candidates are few (one per disc area of the frame).
MAX_LARGE_CANDIDATES = MAX_CANDIDATES // 10
#: Most cluster candidates measured (the clearest first): each is measured as a whole and split,
#: a few times the work of a disc, and most blobs of a busy photo are one disc with its glow.
MAX_CLUSTER_CANDIDATES = MAX_CANDIDATES // 20
#: A circle through edges found by the search itself (no person vouching for it) is measured along
#: rays only where the contour found too little contrast there: where the contour finds no outline or a
#: soft one, the rays' closed path in a photo's own search took merged glows and lit texture for discs
#: (the reference photos' labels: 5 of 8 such discs used by the fit were not discs).
RAYS_AFTER = (Reason.FAINT,)
#: ... and from this size (px): the step's sides are then 5 px or more (under 64 px, at their 3-px floor,
#: JPEG's 8-px blocks and texture make steps as clear as a small faint disc's).
RAYS_MIN_DIAMETER_PX = 64.0
#: A circle whose contour the measurement calls faint or cannot draw, where the rays were not tried
#: after that (a smaller one, or one without an outline), is measured along rays all the same, and
#: kept only where the rays find a ring there, its rim above its centre all round
#: (:attr:`Measurement.ring`, :func:`bokehfit.discs.verdict.ring_all_round`): a soap-bubble disc over
#: lit foliage, whose thin rim stands only a noise level or two above the texture around it pixel by
#: pixel, yet is followed by the edges all round. Texture and JPEG's blocks make steps, not a closed
#: rim around a dimmer centre; a drop's crescent of light is a rim on one side only.
RING_RAYS_AFTER = (Reason.FAINT, Reason.NO_OUTLINE)
#: A blob (light above its surround) whose contour the measurement draws but calls faint or soft-edged
#: is measured again by its own step along rays: a bright-centre disc, or one over its own glow or its
#: neighbours' light, has a step at its edge that no one level between its peak and its surround
#: follows. Not where the contour draws no outline: there the rays' closed path took broad glows for
#: discs (the reference photos' labels: two glows of 350 px used by the fit, one photo's answer wrong).
#: Unlike a circle through edges, a blob is light standing out of its surround, so its step is sought from ...
BLOB_RAYS_AFTER = (Reason.FAINT, Reason.SOFT_EDGE)
#: ... this size (px): the step's sides (3 px, beginning 1.5 px from the edge) then lie inside the disc.
BLOB_RAYS_MIN_DIAMETER_PX = 2.0 * RESOLVABLE_PX
#: Most circles through edges measured per photo (module bokehfit.discs.circles; the clearest first).
MAX_CIRCLES = MAX_CANDIDATES // 10
#: Most circles of the sizes found measured per photo (:func:`bokehfit.discs.circles.find_sized_circles`;
#: those of the largest share of their length voting first). Each is measured in about 6 ms.
MAX_SIZED_CIRCLES = MAX_CANDIDATES // 20
#: Most circles of the sizes found on no chain measured per photo, as rings (:func:`_lone_ring`; those whose rim
#: stands above their centre all round, the clearest first).
MAX_LONE_RINGS = MAX_CANDIDATES // 20


def find_discs(
    luminance: np.ndarray,
    clipped: np.ndarray | None = None,
    *,
    min_diameter_px: float = DEFAULT_MIN_DIAMETER_PX,
    max_diameter_px: float = DEFAULT_MAX_DIAMETER_PX,
    max_discs: int | None = None,
    progress: bool = False,
    rgb: Callable[[slice, slice], np.ndarray] | None = None,
) -> DiscSearch:
    """Find the bokeh discs of a linear-light image.

    Parameters
    ----------
    luminance : ndarray of shape (M, N), float32
        Linear light (1.0 = white).
    clipped : ndarray of shape (M, N), bool, optional
        Pixels clipped in the source; discs containing them are flagged ``saturated``.
    min_diameter_px, max_diameter_px : float
        Range of equal-area diameters sought.
    max_discs : int, optional
        Keep the largest ``max_discs`` discs.
    progress : bool
        Show a progress bar while measuring many candidates.
    rgb : callable, optional
        ``rgb(rows, cols)``: a window of the same photo in linear RGB, (h, w, 3) (:meth:`bokehfit.io.Photo.linear_rgb`).
        Where given, a blob whose luminance edge is soft is measured again in its colours: a lens's colour error
        spreads a disc's edge in luminance (:mod:`bokehfit.discs.colours`).

    Returns
    -------
    DiscSearch
        Discs sorted by diameter, largest first; falsy with ``reason`` if none.
    """
    start = time.perf_counter()
    luminance = _check_image(luminance)
    clipped, min_diameter_px, max_diameter_px, max_discs = _check_parameters(
        luminance.shape, clipped, min_diameter_px, max_diameter_px, max_discs
    )
    if rgb is not None and not callable(rgb):
        raise InputError(f"rgb must be a function of (rows, cols) giving the photo's linear RGB (got {type(rgb).__name__})")
    # No disc is larger than the frame's diagonal: that is also what max_diameter_px=inf means.
    search_max_px = min(max_diameter_px, max(math.hypot(*luminance.shape), 2.0 * min_diameter_px))
    rejected: Counter = Counter()
    notes: list[str] = []
    rejections: list[Rejection] = []
    soft: list[tuple[Measurement, Rejection]] = []  # soft-edged discs, kept apart (step 6)
    clock = Clock()
    candidates, found = _candidates(luminance, min_diameter_px, search_max_px, rejected, notes)
    clock("candidates")
    measurements = _measure_candidates(luminance, clipped, candidates, min_diameter_px, max_diameter_px, progress,
                                       rejected, rejections, rgb, soft)
    clock("measure")
    found += _circle_discs(luminance, clipped, measurements, min_diameter_px, min(max_diameter_px, search_max_px),
                           rejected, rejections, soft)
    clock("edge circles")
    found += _sized_discs(luminance, clipped, measurements, min_diameter_px, min(max_diameter_px, search_max_px),
                          rejected, rejections, soft)
    clock("sized circles")
    measurements = _by_own_steps(luminance, clipped, measurements, min_diameter_px)
    soft = [(m, rejection) for m, rejection in soft if light_ends(luminance, m)]  # a glow's tail goes on
    clock("own steps")
    return _discs_of(measurements, found, rejected, start, notes, rejections, max_discs, soft=soft, clock=clock)


def _candidates(luminance, min_diameter_px: float, search_max_px: float, rejected: Counter,
                notes: list[str]) -> tuple[list[Candidate], int]:
    """The blob candidates to measure, largest first, and how many were found within the cluster limit:
    one per place and size (:func:`_distinct`), at most MAX_CLUSTER_CANDIDATES clusters and
    MAX_CANDIDATES in all; those beyond a limit are counted in ``rejected`` and told in ``notes``."""
    candidates = _distinct(find_candidates(luminance, min_diameter_px, search_max_px))
    candidates = _within_cluster_limit(candidates, rejected, notes)
    found = len(candidates)
    if found > MAX_CANDIDATES:
        candidates = _within_candidate_limit(candidates, rejected, notes)
    candidates.sort(key=lambda c: -c.diameter_px)  # a larger disc claims the candidates inside it
    return candidates, found


def _within_cluster_limit(candidates: list[Candidate], rejected: Counter, notes: list[str]) -> list[Candidate]:
    """The candidates with, of the clusters, only the MAX_CLUSTER_CANDIDATES clearest."""
    clusters = [c for c in candidates if c.cluster]
    if len(clusters) > MAX_CLUSTER_CANDIDATES:
        dropped = {id(c) for c in clusters[MAX_CLUSTER_CANDIDATES:]}  # clearest first, as _distinct sorts them
        candidates = [c for c in candidates if id(c) not in dropped]
        rejected[str(Reason.BEYOND_CLUSTER_LIMIT)] = len(dropped)
        notes.append(
            f"{len(clusters)} possible clusters of overlapping discs, the {MAX_CLUSTER_CANDIDATES} clearest split"
            " (limit MAX_CLUSTER_CANDIDATES)"
        )
    return candidates


def _within_candidate_limit(candidates: list[Candidate], rejected: Counter, notes: list[str]) -> list[Candidate]:
    """The MAX_CANDIDATES candidates measured of more: up to MAX_LARGE_CANDIDATES large ones, then the
    clearest."""
    found = len(candidates)
    rejected[str(Reason.BEYOND_CANDIDATE_LIMIT)] = found - MAX_CANDIDATES
    # _distinct sorts them clearest first; the large ones go first, up to their quota, then
    # those large enough to show their shape (RESOLVABLE_PX), then the smaller ones.
    large = [c for c in candidates if c.diameter_px >= LARGE_DISC_PX][:MAX_LARGE_CANDIDATES]
    taken = {id(c) for c in large}
    rest = sorted((c for c in candidates if id(c) not in taken), key=lambda c: c.diameter_px < RESOLVABLE_PX)
    notes.append(
        f"{found} candidates found, the {MAX_CANDIDATES} clearest measured (limit MAX_CANDIDATES);"
        " raise min_diameter_px or crop the photo to measure the others"
    )
    return large + rest[: MAX_CANDIDATES - len(large)]


def _distinct(candidates: list[Candidate]) -> list[Candidate]:
    """Strongest first; drop a candidate that repeats a stronger one (same place, similar size).
    Cluster candidates repeat only each other: a cluster and its brightest disc are both kept."""
    kinds = [[c for c in candidates if c.cluster == cluster] for cluster in (False, True)]
    if all(kinds):
        return sorted(_distinct(kinds[0]) + _distinct(kinds[1]), key=lambda c: -c.strength)
    kept: list[Candidate] = []
    if not candidates:
        return kept
    order = sorted(candidates, key=lambda c: -c.strength)
    centres = np.array([c.center_xy for c in order])
    tree = cKDTree(centres)
    taken = np.zeros(len(order), dtype=bool)
    for i, c in enumerate(order):
        if taken[i]:
            continue
        kept.append(c)
        for j in tree.query_ball_point(c.center_xy, 0.5 * c.diameter_px + 1.0):
            if 0.4 <= order[j].diameter_px / c.diameter_px <= 2.5:
                taken[j] = True
    return kept



@dataclass(frozen=True)
class _Measured:
    """A candidate measured as one disc or more: the outline it claims (a candidate inside it is its
    light) and the discs kept of it."""

    outline_xy: np.ndarray
    discs: list[Measurement]


def _measure_candidates(luminance, clipped, candidates: list[Candidate], min_diameter_px: float,
                        max_diameter_px: float, progress: bool, rejected: Counter,
                        rejections: list[Rejection], rgb: Callable | None = None,
                        soft: list | None = None) -> list[Measurement]:
    """The discs of the candidates, measured largest first: a candidate inside the outline of one
    measured before is its light, a cluster is measured as its discs (:func:`_measure_cluster`), a
    blob by its contour and its own step (:func:`_measure_blob`). Each that is no disc is counted in
    ``rejected`` and listed in ``rejections`` with the reason; a blob refused only for its soft edge that
    is a soft-edged disc is also put in ``soft`` with its rejection (it claims no candidate)."""
    iterator = candidates
    if progress and len(candidates) > 200:
        from tqdm import tqdm

        iterator = tqdm(candidates, desc="measuring discs", unit="candidate", leave=False)
    grid = _OutlineGrid(max(16.0, 4.0 * min_diameter_px))
    scales = PhotoScales(luminance, clipped)
    measurements: list[Measurement] = []
    for candidate in iterator:
        if grid.contains(candidate.center_xy):
            measured = Rejection.of(candidate.center_xy, candidate.diameter_px, Reason.INSIDE_LARGER_DISC)
        elif candidate.cluster:
            measured = _measure_cluster(scales, candidate, min_diameter_px, max_diameter_px)
        else:
            measured = _measure_blob(scales, candidate, min_diameter_px, max_diameter_px, rgb)
        if isinstance(measured, tuple):  # a soft-edged disc: rejected here, kept apart
            m, measured = measured
            if soft is not None:
                soft.append((m, measured))
        if isinstance(measured, Rejection):
            rejected[measured.rejected_because] += 1
            rejections.append(measured)
        else:
            measurements.extend(measured.discs)
            grid.add(measured.outline_xy)
    return measurements


class _OutlineGrid:
    """Measured outlines filed by the grid cells their bounding boxes cover, for point look-ups."""

    def __init__(self, cell_px: float):
        self._cell = float(cell_px)
        self._cells: dict[tuple[int, int], list[tuple[np.ndarray, tuple[float, float, float, float]]]] = {}

    def add(self, outline: np.ndarray) -> None:
        x0, y0 = outline.min(axis=0)
        x1, y1 = outline.max(axis=0)
        entry = (outline.astype(np.float32), (float(x0), float(y0), float(x1), float(y1)))
        for gx in range(math.floor(x0 / self._cell), math.floor(x1 / self._cell) + 1):
            for gy in range(math.floor(y0 / self._cell), math.floor(y1 / self._cell) + 1):
                self._cells.setdefault((gx, gy), []).append(entry)

    def contains(self, point: tuple[float, float]) -> bool:
        """True when ``point`` lies inside (or on) one of the outlines."""
        x, y = point
        for outline, (x0, y0, x1, y1) in self._cells.get((math.floor(x / self._cell), math.floor(y / self._cell)), ()):
            if x0 <= x <= x1 and y0 <= y <= y1 and cv2.pointPolygonTest(outline, (float(x), float(y)), False) >= 0:
                return True
        return False



def _measured_at_scale(scales: PhotoScales, candidate: Candidate, min_diameter_px: float,
                       cluster: bool = False) -> Measurement | NoDisc:
    """The candidate measured by its contour (:func:`bokehfit.discs.measure.measure_candidate`) at the scale
    its size needs (:mod:`bokehfit.discs.scales`), in the photo's pixels."""
    factor = scales.factor(candidate.diameter_px)
    luminance, clipped = scales.at(factor)
    m = measure_candidate(luminance, clipped, scales.to_copy(candidate.center_xy, factor), candidate.diameter_px / factor,
                          candidate.extent_px / factor, MIN_NOISE, min_diameter_px / factor, cluster=cluster)
    return m if factor == 1 or isinstance(m, NoDisc) else m.enlarged(factor)


def _measure_cluster(scales: PhotoScales, candidate: Candidate, min_diameter_px: float,
                     max_diameter_px: float) -> _Measured | Rejection:
    """A cluster candidate measured as a whole and split into its discs of the sizes sought; a
    rejection (``Reason.NOT_A_CLUSTER``) where it has none."""
    m = _measured_at_scale(scales, candidate, min_diameter_px, cluster=True)
    parts = [] if isinstance(m, NoDisc) else split_cluster(m, cluster=True)
    parts = [p for p in parts if min_diameter_px <= p.diameter_px <= max_diameter_px]
    if parts:
        return _Measured(m.outline_xy, parts)
    # One disc with its glow: its own candidate measures it.
    return Rejection.of(candidate.center_xy, candidate.diameter_px, Reason.NOT_A_CLUSTER)


def _measure_blob(scales: PhotoScales, candidate: Candidate, min_diameter_px: float,
                  max_diameter_px: float, rgb: Callable | None = None
                  ) -> _Measured | Rejection | tuple[Measurement, Rejection]:
    """A blob candidate measured by its contour (at the scale its size needs) and, from
    BLOB_RAYS_MIN_DIAMETER_PX where the contour calls it one of BLOB_RAYS_AFTER, by its own step along rays
    (:func:`bokehfit.discs.places._by_rays_after`); where its edge is still soft, in its colours (``rgb``, where
    given: :func:`bokehfit.discs.colours.sharp_in_a_colour`); a rejection, where it was measured, where it is
    no disc of the sizes sought: with its measurement, (measurement, rejection), where it is a soft-edged disc
    of those sizes (:func:`bokehfit.discs.verdict.soft_edged`)."""
    m = _measured_at_scale(scales, candidate, min_diameter_px)
    if isinstance(m, Measurement) and candidate.diameter_px >= BLOB_RAYS_MIN_DIAMETER_PX:
        m = _by_rays_after(scales.luminance, scales.clipped, m, candidate.center_xy, candidate.diameter_px,
                           min_diameter_px, BLOB_RAYS_AFTER)
    if isinstance(m, NoDisc):
        return Rejection.of(candidate.center_xy, candidate.diameter_px, m)
    if m.reason is Reason.SOFT_EDGE and rgb is not None and not m.own_step and \
            sharp_in_a_colour(rgb, scales.luminance.shape, m, min_diameter_px, scales.factor(candidate.diameter_px)):
        m = replace(m, reason=None)  # a lens's colour error spread its edge in luminance (bokehfit.discs.colours)
    reason = m.reason if m.reason is not None else (Reason.TOO_LARGE if m.diameter_px > max_diameter_px else None)
    if reason is not None:
        rejection = Rejection.of(m.center_xy, m.diameter_px, reason)
        return (m, rejection) if _soft_disc(m, max_diameter_px) else rejection
    # A blob of overlapping discs is measured as its discs, each with the outline it shows.
    parts = split_cluster(m) if m.diameter_px >= 2.0 * RESOLVABLE_PX else []
    if not parts:
        return _Measured(m.outline_xy, [m])
    return _Measured(m.outline_xy, [p for p in parts if min_diameter_px <= p.diameter_px <= max_diameter_px])


def _circle_discs(luminance, clipped, measurements, min_diameter_px, max_diameter_px, rejected, rejections,
                  soft=None) -> int:
    """Measure the circles through the photo's edges (:mod:`bokehfit.discs.circles`: overlapping, faint
    and ring discs that no blob shows) that the blob search did not measure already, as places
    (:func:`_measure_place`), the clearest MAX_CIRCLES; kept where they pass the measurement's tests
    of a disc (the soft-edged discs among the others put in ``soft``). Returns how many were measured."""
    places = find_circles(luminance, min_diameter_px, max_diameter_px)[:MAX_CIRCLES]
    seen = [(m.center_xy, m.diameter_px) for m in measurements] + [(r.center_xy, r.diameter_px) for r in rejections]

    def measure(xy, diameter):
        rays_after = RAYS_AFTER if diameter >= RAYS_MIN_DIAMETER_PX else ()
        return _place_or_ring(luminance, clipped, xy, diameter, min_diameter_px, rays_after)

    return _new_places(places, seen, measure, measurements, (min_diameter_px, max_diameter_px), rejected, rejections,
                       soft)


def _place_or_ring(luminance, clipped, xy, diameter: float, min_diameter_px: float,
                   rays_after: tuple[Reason, ...] = ()) -> Measurement | NoDisc:
    """A circle's place measured (:func:`_measure_place`, along rays after ``rays_after``), or, where the contour
    calls it faint or draws no outline there and the rays were not tried after that, the ring its own step along
    rays shows there (:func:`_ring_by_rays`: RING_RAYS_AFTER)."""
    m = _measure_place(luminance, clipped, xy, diameter, min_diameter_px, rays_after=rays_after)
    if m.reason in RING_RAYS_AFTER and m.reason not in rays_after:
        m = _ring_by_rays(luminance, clipped, m, xy, diameter, min_diameter_px)
    return m


def _sized_discs(luminance, clipped, measurements, min_diameter_px, max_diameter_px, rejected, rejections,
                 soft=None) -> int:
    """Measure the circles of the sizes measured so far (:func:`bokehfit.discs.circles.find_sized_circles`)
    that are discs of a chain: each circle's outline crosses a measured disc's (:class:`_Chain`), where the
    blob search sees the chain as one blob and a disc shows its own edge over part of its outline. The
    clearest MAX_SIZED_CIRCLES of them that no disc measured is are measured as places of that size: by the
    contour; by their own step along rays where it calls them faint, as a circle through edges is
    (RAYS_AFTER, from RAYS_MIN_DIAMETER_PX; from 16 px, the rays added as many bright blobs that are not
    discs to those the fit used as they found discs: RESULTS.md); and by that step where the contour's size is off the circle's
    (:func:`_nearer_the_asked`). Kept where they pass the measurement's tests of a disc and are the circle
    voted for (:func:`_the_circle_voted`: another measurement there is another light, its neighbours' merged
    or a glow) and still a disc of the chain (the soft-edged discs of a chain put in ``soft``). A place a
    candidate was rejected at is measured again: the blob there was measured at its own size, not the circle's.
    Then the circles on no chain, as rings only (:func:`_lone_ring`). Returns how many were measured."""
    seen = [(m.center_xy, m.diameter_px) for m in measurements]
    chain = _Chain(seen)
    found = [(xy, d) for xy, d, _ in find_sized_circles(luminance, seen) if min_diameter_px <= d <= max_diameter_px]

    def measure(xy, diameter):
        rays_after = RAYS_AFTER if diameter >= RAYS_MIN_DIAMETER_PX else ()
        m = _measure_place(luminance, clipped, xy, diameter, min_diameter_px, rays_after=rays_after)
        m = _nearer_the_asked(luminance, clipped, m, xy, diameter)
        if isinstance(m, Measurement) and not (_the_circle_voted(m, xy, diameter)
                                               and chain.crosses(m.center_xy, m.diameter_px)):
            return NoDisc(Reason.NOT_THE_DISC_ASKED, f"the disc measured there ({m.diameter_px:.0f} px at"
                          f" {m.center_xy[0]:.0f}, {m.center_xy[1]:.0f}) is not the circle of a chain sought"
                          f" ({diameter:.0f} px)")
        return m

    sizes = (min_diameter_px, max_diameter_px)
    places = [(xy, d) for xy, d in found if chain.crosses(xy, d)]
    measured = _new_places(places[:MAX_SIZED_CIRCLES], seen, measure, measurements, sizes, rejected, rejections, soft)
    # Those on no chain whose rim stands above their centre all round, where one was measured (a cheap look first).
    lone = [(xy, d) for xy, d in found if not chain.crosses(xy, d) and rim_above_centre(luminance, xy, d)]
    seen = [(m.center_xy, m.diameter_px) for m in measurements]
    return measured + _new_places(lone[:MAX_LONE_RINGS], seen, partial(_lone_ring, luminance, clipped,
                                  min_diameter_px=min_diameter_px), measurements, sizes, rejected, rejections)


def _the_circle_voted(m: Measurement, xy, diameter: float) -> bool:
    """The measurement is the circle of a size voted for at ``xy``: its centre within SAME_DISC_CENTRE_REL
    of the diameter, its size within SIZE_STEP."""
    return abs(math.log(m.diameter_px / diameter)) <= math.log(SIZE_STEP) and \
        math.dist(m.center_xy, xy) <= SAME_DISC_CENTRE_REL * diameter


def _lone_ring(luminance, clipped, xy, diameter: float, min_diameter_px: float) -> Measurement | NoDisc:
    """A circle of a size found that crosses no disc of a chain, kept only as a ring all round (the rule of the
    circles through edges, RING_RAYS_AFTER): a soap-bubble disc whose centre is no brighter than the lit ground
    around it is no blob, and beside no other disc it is no chain's; what else a circle of a disc's size
    through edges could be, a glow, a lit leaf or the ground's texture, shows no rim above a dimmer centre all
    round. Measured by the contour, and by its own step along rays where that finds it faint or draws no outline;
    kept where that is a ring all round and the circle voted for (:func:`_the_circle_voted`)."""
    m = _place_or_ring(luminance, clipped, xy, diameter, min_diameter_px)
    if isinstance(m, Measurement) and m.reason is None and not (
            m.ring and ring_all_round(luminance, m) and _the_circle_voted(m, xy, diameter)):
        return NoDisc(Reason.NOT_THE_DISC_ASKED, f"the disc measured there ({m.diameter_px:.0f} px at"
                      f" {m.center_xy[0]:.0f}, {m.center_xy[1]:.0f}) is not a ring all round of the circle sought"
                      f" ({diameter:.0f} px), as one on no chain must be")
    return m


class _Chain:
    """The discs measured ((xy, diameter) each), asked whether a circle's outline crosses one of theirs: the
    two circles overlap, neither inside the other (light adds, so each disc of a chain keeps its own edge)."""

    def __init__(self, discs):
        self._discs = discs
        self._tree = cKDTree(np.array([xy for xy, _ in discs])) if discs else None
        self._largest = max((d for _, d in discs), default=0.0)

    def crosses(self, xy, diameter: float) -> bool:
        if self._tree is None:
            return False
        near = self._tree.query_ball_point(xy, 0.5 * (diameter + self._largest))
        return any(0.5 * abs(diameter - self._discs[j][1]) < math.dist(xy, self._discs[j][0])
                   < 0.5 * (diameter + self._discs[j][1]) for j in near)


def _new_places(places, seen, measure, measurements, sizes, rejected, rejections, soft=None) -> int:
    """Measure (``measure(xy, diameter)``) each place that is not one of the ``seen`` ((xy, diameter):
    the same disc), appending to ``measurements`` the discs of the ``sizes`` (least, most) that pass the
    measurement's tests, and counting the others in ``rejected`` and ``rejections``; those of the sizes that
    are soft-edged discs also in ``soft`` (where given) with their rejections. Returns how many were
    measured."""
    known = cKDTree(np.array([xy for xy, _ in seen])) if seen else None
    measured = 0
    for xy, diameter in places:
        if known is not None and any(_same_size(seen[j][1], diameter)
                                     for j in known.query_ball_point(xy, SAME_DISC_CENTRE_REL * diameter)):
            continue  # measured already (a disc, or not one)
        measured += 1
        m = measure(xy, diameter)
        why = m if isinstance(m, NoDisc) else m.reason
        if why is None and not sizes[0] <= m.diameter_px <= sizes[1]:
            why = Reason.TOO_LARGE
        if why is None:
            measurements.append(m)
        else:
            rejection = Rejection.of(xy, diameter, why)
            rejected[rejection.rejected_because] += 1
            rejections.append(rejection)
            if soft is not None and isinstance(m, Measurement) and _soft_disc(m, sizes[1]):
                soft.append((m, rejection))
    return measured


def _soft_disc(m: Measurement, max_diameter_px: float) -> bool:
    """A measurement refused that is a soft-edged disc (:func:`bokehfit.discs.verdict.soft_edged`) no larger than
    the discs sought (none is smaller: the size is tested before the edge)."""
    return soft_edged(m) and m.diameter_px <= max_diameter_px


def _ring_by_rays(luminance, clipped, m: Measurement | NoDisc, xy, diameter: float,
                  min_diameter_px: float) -> Measurement | NoDisc:
    """The ring disc measured at a circle's place by its own step along rays, where that finds a disc
    of about ``diameter`` there and it is a ring all round (RING_RAYS_AFTER); else the contour's ``m``."""
    stepped = measure_rays(luminance, clipped, xy, diameter, MIN_NOISE, min_diameter_px)
    if isinstance(stepped, Measurement) and stepped.reason is None and stepped.ring \
            and _near_place(stepped, xy, diameter) and ring_all_round(luminance, stepped):
        return stepped
    return m
