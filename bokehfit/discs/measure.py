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
                    ``MAX_ELONGATION`` (a slit of aspect 0.26 still passes);
``line-like``       the widest circle inside the blob has a radius below
                    ``MIN_THICKNESS_REL`` of the equal-area radius: a thin streak,
                    straight or curved (a glint on water, a lit stem), which a
                    minimum-area rectangle does not call elongated when it bends.

What a kept disc offers (for the fit that comes later):

- **Saturated discs** keep their outline: the 50 % level lies between the
  background and the clipped plateau, where the disc meets the background,
  so the clipping moves it little. ``clipped_share`` is the share of the disc's
  area clipped in the source. Outline points whose outside (2 px out) is
  clipped too are not reliable: bloom joins the disc to other clipped light.
- **Occluded discs**: a thin occluder in front of a disc (a branch, a grass
  blade) cuts a notch or a gap into the region above the 50 % level. A
  morphological closing of that region with a disc of radius
  ``OCCLUSION_BRIDGE_REL`` · r bridges gaps up to that width; where the
  bridged pixels exceed ``OCCLUSION_MIN_SHARE`` of the area, they are given the
  plateau level, the outline is drawn over them, and the outline points next to
  them are marked not seen (``outline_reliable``).
- **Ring discs** (soap-bubble): a thin bright rim around a darker centre. Its
  half-peak candidate is an annulus, so its equal-area size is too small and the
  centre holds no plateau. A candidate that reaches ``RING_REACH`` times farther
  than its equal-area radius, and fails as a plateau disc, is measured again
  with the rim as the plateau (``RING_PLATEAU_PERCENTILES``); the outer 50 %
  outline is the disc's. A disc is flagged ``ring`` when the
  median of its centre (within ``RING_CENTRE_REL`` of the radius) lies below the
  plateau by more than ``RING_DIP`` of the contrast.
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
from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy import ndimage
from skimage import feature, measure, segmentation

from bokehfit.discs.candidates import LARGE_DISC_PX, MIN_CONTRAST_ABS, contrast_floor_rel

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

MIN_SNR = 4.0
#: The search window grows by these factors while the outline runs into it.
WINDOW_GROWTH = (1.0, 2.0, 4.0)
#: ... but for a window from LARGE_DISC_PX across on only to the second: one 4 times larger
#: would hold millions of pixels, and an outline that runs out of ±3.4 radii is a
#: piece of something larger, or touches its neighbours, either way.
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
#: Faint discs' outlines: the crop is smoothed until the noise moves the 50 % contour by about this
#: much (px), with a Gaussian of at most OUTLINE_SMOOTH_REL of the disc's radius.
OUTLINE_JITTER_PX = 0.2
OUTLINE_SMOOTH_REL = 0.08
#: Equal-area diameter from which a disc shows its shape.
RESOLVABLE_PX = 8.0
#: Share of a disc's pixels that may be clipped in the source before it counts as saturated.
SATURATED_SHARE = 0.002
#: A saturated "disc" whose surrounding ring is clipped beyond this share is a
#: piece of a larger clipped region (the sun, a window), not a disc.
MAX_CLIPPED_RING_SHARE = 0.3
#: Line-like: the largest inscribed circle's radius over the equal-area radius. A disc has
#: about 1, the slit of aspect 0.3 (the thinnest aperture) 0.27, a rectangle of sides 1:a
#: 0.886/√a, so 0.2 refuses streaks longer than about 20 times their width.
MIN_THICKNESS_REL = 0.2
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
#: Outline points within this distance (px) of bridged or cut-off pixels are not seen.
UNSEEN_MARGIN_PX = 1.5
#: Ring mode is tried for candidates whose reach (half their bounding box) exceeds their
#: equal-area radius by this factor: an annulus's half-peak region is hollow (a disc: 1).
RING_REACH = 1.2
#: A disc is a ring when its centre lies below the rim by this share of the contrast.
RING_DIP = 0.25
#: The centre of a disc, for the ring test: this share of its equal-area radius; its rim, this
#: band (the blurred edge beyond it would make every disc look darker at the rim, not brighter).
RING_CENTRE_REL = 0.5
RING_RIM_REL = (0.7, 0.95)
#: In ring mode the plateau is taken within the whole disc (plus a pixel): the rim is its edge.
RING_CORE_REL = 1.05
#: ... and the plateau is first the rim (90th percentile there): its outer 50 % outline is the
#: disc's edge. Where the rim is dimmer in places its outline breaks into arcs; then the
#: median, whose half takes in the rim and the centre (lit too, only less): an outline a
#: little outside the edge, but closed.
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
#: The background plane: fitted where the surround has at least this many pixels (a
#: plane through a handful of pixels would follow their noise), from the pixels within
#: this many robust deviations of a first fit.
PLANE_MIN_PIXELS = 200
PLANE_INLIER_MAD = 3.0
#: ... and only where the frame holds at least this share of the annulus: a plane fitted to
#: a surround cut by the frame on two sides is extrapolated across the disc and tilts its plateau.
PLANE_MIN_ANNULUS_SHARE = 0.6
#: ... using at most this many of them (evenly spread): the plane's three numbers are then
#: known to well below the noise, at a fraction of the cost.
PLANE_MAX_PIXELS = 1000
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
#: A cluster's plateau, for its outline: this percentile of its core, where the brightest
#: overlaps (the light of two or three discs added) are a minority.
CLUSTER_PLATEAU_PERCENTILE = 50


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
    #: Per outline point: True where the outline is the disc's own edge and reliable (not the
    #: frame, a cutting circle, an occluder or clipped bloom).
    outline_reliable: np.ndarray | None = None
    clipped_share: float = 0.0  #: share of the disc's area clipped in the source
    ring: bool = False  #: rim brighter than the centre (soap-bubble disc)
    bright_centre: bool = False  #: centre brighter than the rim, edge a step below it (rim < 0)
    occluded: bool = False  #: a thin occluder bridged across the disc
    thickness: float = 1.0  #: largest inscribed radius over the equal-area radius
    #: The outline was traced along rays as the disc's own step down (:mod:`bokehfit.discs.rays`): light
    #: adds, so its seen points are the disc's edge inside other discs' light too.
    own_step: bool = False


@dataclass(frozen=True)
class Window:
    """A search window of the photo: rows ``r0`` to ``r1`` − 1, columns ``c0`` to ``c1`` − 1."""

    r0: int
    c0: int
    r1: int
    c1: int

    @classmethod
    def around(cls, shape: tuple[int, int], center_xy: tuple[float, float], half: int) -> Window:
        """The window of ``half`` pixels each side of the pixel at ``center_xy``, within a frame of ``shape``."""
        height, width = shape
        col, row = int(round(center_xy[0])), int(round(center_xy[1]))
        return cls(max(0, row - half), max(0, col - half), min(height, row + half + 1), min(width, col + half + 1))

    def of(self, image: np.ndarray) -> np.ndarray:
        """The window's pixels of ``image`` (a view)."""
        return image[self.r0 : self.r1, self.c0 : self.c1]

    def distance(self, center_xy: tuple[float, float]) -> np.ndarray:
        """Distance of each of the window's pixels from ``center_xy`` (photo coordinates)."""
        rows, cols = np.ogrid[self.r0 - center_xy[1] : self.r1 - center_xy[1], self.c0 - center_xy[0] : self.c1 - center_xy[0]]
        return np.sqrt(rows * rows + cols * cols)


@dataclass(frozen=True)
class Surround:
    """The levels of a candidate's surround (the annulus of the module's Notes)."""

    plane: _Plane | None  #: the background's gradient across the window, or None (a flat background)
    background: float  #: median of the annulus, less the plane
    noise: float  #: its scaled median absolute deviation
    lift: float  #: its median less its 10th percentile (other light in part of the surround)


@dataclass(frozen=True)
class Levels:
    """The levels a disc's outline was drawn with (the module's Notes); the outline lies halfway
    between ``background`` and ``plateau``."""

    background: float
    plateau: float
    noise: float
    ring_lift: float  #: the surround's lift (:attr:`Surround.lift`)


@dataclass(frozen=True)
class Outlined:
    """A closed outline around a candidate, with what it was drawn from: what :func:`describe` judges."""

    window: Window  #: where ``crop`` lies in the photo
    crop: np.ndarray  #: the pixels the outline was drawn on: the window's, less the background plane if any
    levels: Levels
    outline: np.ndarray  #: (N, 2) closed sub-pixel outline in the crop, (x, y) = (column, row)
    merged: bool  #: cut out of a larger bright region by a circle
    #: Pixels raised to the plateau before the outline was drawn (a bridged occluder, a ring's closed
    #: gaps): the outline next to them is not the disc's own; None where there are none.
    bridged: np.ndarray | None
    on_cut: np.ndarray  #: per outline point: on the cutting circle, or otherwise not the disc's own edge


def _median(values: np.ndarray):
    """``np.median`` of a 1-D array without NaN, the same number in the array's type, without
    its general machinery (a candidate's levels take a dozen medians and percentiles)."""
    half = values.size // 2
    if values.size % 2:
        return np.partition(values, half)[half]
    part = np.partition(values, (half - 1, half))
    return (part[half - 1] + part[half]) / 2


def _percentile(values: np.ndarray, q: float):
    """``np.percentile(values, q)`` (its default, linear method) of a 1-D array without NaN,
    the same number in the array's type."""
    virtual = (values.size - 1) * (q / 100)
    lower = math.floor(virtual)
    if virtual >= values.size - 1:
        return np.partition(values, -1)[-1]
    part = np.partition(values, (lower, lower + 1))
    below, above = part[lower], part[lower + 1]
    gamma = virtual - lower
    step = above - below
    return above - step * (1 - gamma) if gamma >= 0.5 else below + step * gamma


@dataclass(frozen=True)
class _Plane:
    """A background plane over a crop, ``slope_row · row + slope_col · col − offset`` (float32)."""

    slope_row: float
    slope_col: float
    offset: float

    def at(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Its values at the pixels (rows, cols)."""
        return (self.slope_row * rows + self.slope_col * cols - self.offset).astype(np.float32)

    def over(self, shape: tuple[int, int]) -> np.ndarray:
        """Its values over a crop of ``shape``."""
        rows, cols = np.ogrid[: shape[0], : shape[1]]
        return (self.slope_row * rows + self.slope_col * cols - self.offset).astype(np.float32)


def _background_plane(crop: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> _Plane | None:
    """A plane fitted to the crop's pixels (rows, cols), robustly (least squares on the pixels
    within PLANE_INLIER_MAD scaled deviations of a first fit, so that a neighbouring disc in
    the surround does not tilt it), less its median over them; None where too few pixels fit."""
    step = max(1, len(rows) // PLANE_MAX_PIXELS)  # a plane needs a few hundred pixels, not all of them
    rows, cols = rows[::step], cols[::step]
    values = crop[rows, cols].astype(np.float64)
    design = np.column_stack([np.ones(len(rows)), rows, cols]).astype(np.float64)
    inliers = np.ones(len(values), dtype=bool)
    for _ in range(2):
        coefficients, *_ = np.linalg.lstsq(design[inliers], values[inliers], rcond=None)
        residual = values - design @ coefficients
        deviation = np.abs(residual - _median(residual))
        spread = 1.4826 * float(_median(deviation))
        inliers = deviation <= PLANE_INLIER_MAD * max(spread, 1e-12)
        if inliers.sum() < 8:
            return None
    return _Plane(float(coefficients[1]), float(coefficients[2]), float(_median(design[:, 1:] @ coefficients[1:])))


def _annulus_levels(crop: np.ndarray, distance: np.ndarray, radius: float) -> Surround | None:
    """The :class:`Surround`: the plane of the surround's gradient (or None), and the median, robust
    spread and lift (median − 10th percentile) of the annulus 1.3 r … 1.7 r (+ 2 px) less that plane;
    None where the window holds no surround.

    The background model at the disc's scale is a plane fitted to the annulus: a
    smooth gradient across a large disc's surround (haze, vignetting) can exceed
    the contrast of a faint disc, and no one level would then outline it. Texture
    and grain stay in the spread. The plane is taken out of the pixels used here only:
    most candidates are found faint on these levels, and need no more of the crop.
    """
    where = (distance >= 1.3 * radius + 1.0) & (distance <= 1.7 * radius + 3.0)
    inside = int(where.sum())
    if inside < 8:
        where = distance >= 1.3 * radius + 1.0
        inside = int(where.sum())
    if inside < 8:
        return None  # the window holds no surround: the disc fills or overflows the frame
    annulus_px = math.pi * ((1.7 * radius + 3.0) ** 2 - (1.3 * radius + 1.0) ** 2)
    rows, cols = np.nonzero(where)
    plane = None
    if inside >= max(PLANE_MIN_PIXELS, PLANE_MIN_ANNULUS_SHARE * annulus_px):
        plane = _background_plane(crop, rows, cols)
    ring = crop[rows, cols] if plane is None else crop[rows, cols] - plane.at(rows, cols)
    median = float(_median(ring))
    low = float(_percentile(ring, 10))
    return Surround(plane, median, 1.4826 * float(_median(np.abs(ring - median))), median - low)


def _levelled(crop: np.ndarray, where: np.ndarray, plane: _Plane | None) -> np.ndarray:
    """``crop[where]`` less the background plane."""
    return crop[where] if plane is None else crop[where] - plane.at(*np.nonzero(where))


def _edge_gradient(crop: np.ndarray, outline: np.ndarray) -> float:
    """Median gradient magnitude of the image along the outline (bilinear samples)."""
    gy, gx = np.gradient(crop.astype(np.float32))
    coords = [outline[:, 1], outline[:, 0]]  # (row, col)
    gx_at = ndimage.map_coordinates(gx, coords, order=1, mode="nearest")
    gy_at = ndimage.map_coordinates(gy, coords, order=1, mode="nearest")
    return float(_median(np.hypot(gx_at, gy_at)))



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


def _bridge_occluders(crop, distance, level, plateau, radius):
    """``crop`` with thin occluders across the disc raised to the plateau, and the
    bridged pixels; ``(crop, None)`` where nothing was bridged.

    The region above ``level`` (holes filled: a hole inside the disc leaves the
    outline alone) is closed with a square of half-side ``OCCLUSION_BRIDGE_REL`` · r
    (a closing leaves every convex shape as it is, whatever the convex element, and a
    square's is separable, so fast); only pixels within the disc's reach from the
    centre count, so the gap to a neighbouring disc is not bridged.
    """
    if radius < OCCLUSION_MIN_RADIUS_PX:
        return crop, None
    side = 2 * max(2, int(round(OCCLUSION_BRIDGE_REL * radius))) + 1
    box = _box(distance, 1.05 * radius + 1.0 + side)
    raised, bridged = _bridge_in_box(crop[box], distance[box], level, plateau, radius, side)
    if bridged is None:
        return crop, None
    crop, mask = crop.copy(), np.zeros(crop.shape, dtype=bool)
    crop[box], mask[box] = raised, bridged
    return crop, mask


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


def _ring_arc(crop, level, seed_rc, radius):
    """The outer arcs of a ring's broken rim and the circle through them: ``(outline,
    seen)`` with the circle filled in where the rim is not seen, or None.

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
        cx, cy, fitted = _fit_circle(rim)
        rim = rim[np.abs(np.hypot(rim[:, 0] - cx, rim[:, 1] - cy) - fitted) <= RING_ARC_TOLERANCE * fitted]
    if len(rim) < RING_MIN_ARC * RING_ARC_BINS:
        return None
    cx, cy, fitted = _fit_circle(rim)
    order = np.argsort(np.arctan2(rim[:, 1] - cy, rim[:, 0] - cx))
    return _completed_outline(rim[order], cx, cy, fitted)


def _close_ring(crop, distance, level, plateau, radius):
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
        return raised, None
    mask = np.zeros(crop.shape, dtype=bool)
    mask[box] = gaps
    return raised, mask


def _closed_outline(luminance, center_xy, radius, reach, core_rel=0.8, percentile=90, levelled=None, edge_rel=1.0):
    """Levels and the closed 50 % outline around ``center_xy``, growing the window
    while the outline runs into it; the last window masks beyond ``reach`` instead
    (the disc then touches a neighbour). The plateau is the ``percentile`` within
    ``core_rel`` · r. Returns the :class:`Outlined`, or why there is none. ``levelled`` keeps the
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
            return "no surround"
        surround = levelled[key]
        plane, background, noise, ring_lift = surround.plane, surround.background, surround.noise, surround.lift
        core = _levelled(crop, distance <= max(core_rel * radius, 0.75), plane)
        plateau = float(_percentile(core, percentile)) if core.size else background
        plateau = background + edge_rel * (plateau - background)  # a bright centre's: the top of its edge
        level = background + 0.5 * (plateau - background)
        if not _contrast_ok(plateau - background, noise, background, 2.0 * radius):
            return "faint"
        if plane is not None:
            crop = crop - plane.over(crop.shape)
        seed_rc = (center_xy[1] - window.r0, center_xy[0] - window.c0)
        if core_rel == RING_CORE_REL:
            bridged_crop, bridged = _close_ring(crop, distance, level, plateau, radius)
        else:
            bridged_crop, bridged = _bridge_occluders(crop, distance, level, plateau, radius)
        outline = _outline(_quieted(bridged_crop, plateau - background, noise, radius), level, background, seed_rc)
        if outline is None and core_rel == RING_CORE_REL:
            arc = _ring_arc(crop, level, seed_rc, radius)
            if arc is not None:  # a rim that breaks: its arcs, and the circle through them
                return Outlined(window, crop, Levels(background, plateau, noise, ring_lift), arc[0], False, None, ~arc[1])
        if outline is None:
            return "no outline"
        if not _open_in_window(outline, crop.shape, window, (height, width)):
            levels = Levels(background, plateau, noise, ring_lift)
            return Outlined(window, crop, levels, outline, False, bridged, np.zeros(len(outline), dtype=bool))
    # Still open: part of a larger bright structure, or discs run together. Cut
    # the disc out of it with a circle through its neighbours' gap.
    masked = np.where(distance <= reach, crop, min(background, level - 1e-6)).astype(np.float32)
    outline = _outline(masked, level, background, seed_rc)
    if outline is None:
        return "no outline"
    on_cut = np.abs(np.hypot(outline[:, 0] - seed_rc[1], outline[:, 1] - seed_rc[0]) - reach) < 1.0
    if on_cut.mean() > MAX_CUT_SHARE:  # mostly the cutting circle: a piece of something larger
        return "part of a larger region"
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


def _contrast_ok(contrast: float, noise: float, background: float, diameter_px: float) -> bool:
    return contrast >= max(MIN_SNR * noise, MIN_CONTRAST_ABS, float(contrast_floor_rel(diameter_px)) * background)


def _near(mask: np.ndarray | None, outline: np.ndarray, margin_px: float) -> np.ndarray:
    """Per outline point (crop coordinates): True within ``margin_px`` of a pixel of ``mask``.

    The distances are interpolated between the four pixels around each point, which lie within
    √2 of one another: only distances up to ``margin_px`` + 2√2 decide it, and those of pixels
    ``pad`` or more inside a box are the same as over the whole crop. So the distance
    transform is taken over the outline's box and that margin, not the crop."""
    if mask is None or not mask.any():
        return np.zeros(len(outline), dtype=bool)
    height, width = mask.shape
    rows, cols = np.clip(outline[:, 1], 0, height - 1), np.clip(outline[:, 0], 0, width - 1)
    pad = math.ceil(margin_px + 2.0 * math.sqrt(2.0)) + 2
    r0, c0 = max(0, int(rows.min()) - pad), max(0, int(cols.min()) - pad)
    r1, c1 = min(height, int(rows.max()) + pad + 1), min(width, int(cols.max()) + pad + 1)
    box = mask[r0:r1, c0:c1]
    if not box.any():  # none within pad of the outline
        return np.zeros(len(outline), dtype=bool)
    distance = ndimage.distance_transform_edt(~box)
    return ndimage.map_coordinates(distance, [rows - r0, cols - c0], order=1, mode="nearest") <= margin_px


def _thickness(blob: np.ndarray, radius: float) -> float:
    """Radius of the largest circle inside ``blob`` over the equal-area radius ``radius``."""
    if not blob.any():
        return 0.0
    inscribed = float(cv2.distanceTransform(np.pad(blob, 1).view(np.uint8), cv2.DIST_L2, 5).max())
    return inscribed / max(radius, 1e-6)


def measure_candidate(
    luminance: np.ndarray,
    clipped_mask: np.ndarray | None,
    center_xy: tuple[float, float],
    diameter_px: float,
    extent_px: float,
    min_noise: float,
    min_diameter_px: float,
    cluster: bool = False,
) -> Measurement | str:
    """Measure the disc around ``center_xy`` of about ``diameter_px``, reaching about
    ``extent_px`` from its centre; a rejection reason where there is no disc to measure.

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
        return found if isinstance(found, str) else describe(luminance, clipped_mask, found, min_noise, min_diameter_px)
    levelled: dict = {}
    found = _two_passes(luminance, center_xy, radius, max(radius, extent_px), 0.8, levelled=levelled)
    hollow = extent_px > RING_REACH * radius and extent_px >= RESOLVABLE_PX  # a ring shows as one from 16 px
    if isinstance(found, str) and found in ("faint", "no outline") and hollow:
        # A ring's half-peak region is its rim: take its reach as the radius, the rim as the plateau.
        for percentile in RING_PLATEAU_PERCENTILES:
            ring = _two_passes(luminance, center_xy, extent_px, extent_px, RING_CORE_REL, percentile, levelled)
            if not isinstance(ring, str):
                found = ring
                break
    if isinstance(found, str):
        return found
    measured = describe(luminance, clipped_mask, found, min_noise, min_diameter_px)
    if measured.reason == "soft edge":
        step = _step_share(found)
        if step is not None:  # a bright centre: measured again with the top of its edge as the plateau
            outline = found.outline
            _, cx, cy = polygon_area_centroid(outline)
            reach = float(np.max(np.hypot(outline[:, 0] - cx, outline[:, 1] - cy)))
            again = _two_passes(luminance, (cx + found.window.c0, cy + found.window.r0), reach, reach, 0.8, 90, levelled, 2.0 * step)
            if not isinstance(again, str):
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
    """
    crop, outline = found.crop, found.outline
    background, plateau = found.levels.background, found.levels.plateau
    contrast = plateau - background
    _, cx, cy = polygon_area_centroid(outline)
    steepness = []
    for share in BRIGHT_CENTRE_LEVELS:
        contour = _outline(crop, background + share * contrast, background, (cy, cx))
        steepness.append(0.0 if contour is None else _edge_gradient(crop, contour))
    best = int(np.argmax(steepness))
    share, steepest = BRIGHT_CENTRE_LEVELS[best], steepness[best]
    if share > BRIGHT_CENTRE_MAX_LEVEL:
        return None
    above = max(s for level, s in zip(BRIGHT_CENTRE_LEVELS, steepness) if level >= 2.0 * share + BRIGHT_CENTRE_SHOULDER - 1e-9)
    return share if steepest >= BRIGHT_CENTRE_STEEPER * above else None


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


def _two_passes(luminance, center_xy, radius, reach, core_rel, percentile=90, levelled=None, edge_rel=1.0):
    """:func:`_closed_outline` with the candidate's size, then with the measured one."""
    found = None
    for _ in range(2):
        found = _closed_outline(luminance, center_xy, radius, 1.3 * reach + 2.0, core_rel, percentile, levelled, edge_rel)
        if isinstance(found, str):
            return found
        outline = found.outline
        area, cx, cy = polygon_area_centroid(outline)
        if found.merged or area <= 0:
            break
        center_xy, radius = (cx + found.window.c0, cy + found.window.r0), max(1.0, math.sqrt(area / math.pi))
        reach = float(np.max(np.hypot(outline[:, 0] - cx, outline[:, 1] - cy)))
    return found


def describe(luminance, clipped_mask, found: Outlined, min_noise, min_diameter_px) -> Measurement:
    """The :class:`Measurement` of a closed outline: size, shape, flags, what is seen, and the verdict."""
    height, width = luminance.shape
    r0, c0, r1, c1 = found.window.r0, found.window.c0, found.window.r1, found.window.c1
    crop, outline, merged, bridged, on_cut = found.crop, found.outline, found.merged, found.bridged, found.on_cut
    background, plateau, noise, ring_lift = found.levels.background, found.levels.plateau, found.levels.noise, found.levels.ring_lift
    contrast = plateau - background
    area, cx, cy = polygon_area_centroid(outline)
    diameter = 2.0 * math.sqrt(area / math.pi)
    hull_area = float(cv2.contourArea(cv2.convexHull(outline.astype(np.float32))))
    solidity = area / hull_area if hull_area > 0 else 0.0
    (_, _), (side_a, side_b), _ = cv2.minAreaRect(outline.astype(np.float32))
    elongation = max(side_a, side_b) / max(min(side_a, side_b), 1e-6)
    inside = np.zeros(crop.shape, dtype=np.uint8)
    cv2.fillPoly(inside, [np.round(outline).astype(np.int32)], 1)
    blob = inside.astype(bool)
    # The edge is measured where it is seen: not along a cutting circle or a filled-in arc.
    edge_points = outline[~on_cut] if (~on_cut).sum() >= 4 else outline
    edge_width = contrast / max(_edge_gradient(crop, edge_points), 1e-12)
    outline_xy = outline + np.array([c0, r0], dtype=np.float64)
    # The padded contour runs outside [0, size − 1] only where the frame cuts the disc.
    off_frame = (outline_xy[:, 0] < 0.0) | (outline_xy[:, 1] < 0.0)
    off_frame |= (outline_xy[:, 0] > width - 1) | (outline_xy[:, 1] > height - 1)
    clipped = bool(off_frame.any())
    unseen = off_frame | on_cut | _near(bridged, outline, UNSEEN_MARGIN_PX)
    saturated = clipped_beyond = False
    clipped_share = 0.0
    if clipped_mask is not None:
        clipped_crop = clipped_mask[r0:r1, c0:c1]
        clipped_share = float(clipped_crop[blob].sum()) / max(float(blob.sum()), 1.0)
        saturated = int(clipped_crop[blob].sum()) > max(1.0, SATURATED_SHARE * area)
        if saturated:  # a saturated disc's edge is where the clipping stops
            ring = cv2.dilate(inside, np.ones((5, 5), np.uint8)).astype(bool) & ~blob
            clipped_beyond = bool(ring.any()) and clipped_crop[ring].mean() > MAX_CLIPPED_RING_SHARE
            # Bloom: where the clipping runs on past the outline, that stretch is not the disc's edge.
            unseen |= _near(ring & clipped_crop, outline, UNSEEN_MARGIN_PX)
    from_centre = _window_distance(crop.shape, cx, cy) / max(0.5 * diameter, 1e-6)
    centre, rim = crop[from_centre <= RING_CENTRE_REL], crop[(from_centre >= RING_RIM_REL[0]) & (from_centre <= RING_RIM_REL[1])]
    is_ring = bool(centre.size and rim.size) and float(_median(rim) - _median(centre)) > RING_DIP * contrast
    thickness = _thickness(blob, 0.5 * diameter)
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
    elif not _contrast_ok(contrast, noise, background, diameter):
        reason = "faint"
    elif edge_width > max(EDGE_WIDTH_MIN_PX, EDGE_WIDTH_MAX_REL * 0.5 * diameter) and not saturated:
        reason = "soft edge"
    elif elongation > MAX_ELONGATION:
        reason = "elongated"
    elif thickness < MIN_THICKNESS_REL:
        reason = "line-like"
    elif solidity < MIN_SOLIDITY:
        reason = "not compact"
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
        outline_reliable=~unseen,
        clipped_share=clipped_share,
        ring=is_ring,
        occluded=bridged is not None,
        thickness=thickness,
    )


def _window_distance(shape: tuple[int, int], cx: float, cy: float) -> np.ndarray:
    """Distance of every pixel of a crop of ``shape`` from (cx, cy)."""
    rows, cols = np.ogrid[: shape[0], : shape[1]]
    return np.hypot(cols - cx, rows - cy)


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


def _fit_circle(xy: np.ndarray) -> tuple[float, float, float]:
    """Centre and radius of the circle through ``xy`` (algebraic least squares, Kåsa 1976)."""
    x, y = xy[:, 0], xy[:, 1]
    design = np.column_stack([x, y, np.ones(len(x))])
    (a, b, c), *_ = np.linalg.lstsq(design, x * x + y * y, rcond=None)
    cx, cy = 0.5 * a, 0.5 * b
    return float(cx), float(cy), float(math.sqrt(max(c + cx * cx + cy * cy, 0.0)))


def _completed_outline(own: np.ndarray, cx: float, cy: float, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """The own outline points with the circle filled in where they leave gaps, ordered by angle,
    and per point whether it is one of the own points."""
    angles = np.arctan2(own[:, 1] - cy, own[:, 0] - cx)
    step = 1.0 / max(radius, 1.0)  # about a pixel along the circle
    grid = np.arange(-math.pi, math.pi, step)
    gap = np.abs(np.angle(np.exp(1j * (grid[:, None] - angles[None, :])))).min(axis=1) > 2.0 * step
    filled = np.column_stack([cx + radius * np.cos(grid[gap]), cy + radius * np.sin(grid[gap])])
    points = np.vstack([own, filled])
    seen = np.concatenate([np.ones(len(own), bool), np.zeros(len(filled), bool)])
    order = np.argsort(np.concatenate([angles, grid[gap]]))
    return points[order], seen[order]


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
        cx, cy, radius = _fit_circle(local[own])
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
        outline, seen = _completed_outline(local[own], cx, cy, radius)
        parts.append(
            replace(
                m,
                center_xy=(cx + origin[0], cy + origin[1]),
                diameter_px=2.0 * radius,
                area_px=math.pi * radius * radius,
                outline_xy=outline + origin,
                overlaps=True,
                outline_reliable=seen,
            )
        )
    return parts if len(parts) >= 2 else []
