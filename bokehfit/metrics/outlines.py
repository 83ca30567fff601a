"""Outlines: closed simple polygons as (N, 2) arrays of (x, y) points.

The helpers here check, normalise, densify, rotate and intersect outlines for
the shape metrics of :mod:`bokehfit.metrics`. An outline may come in either
orientation, from any start point and in any units; :func:`normalise` puts it
in one frame (centroid at 0, unit area, counter-clockwise), so that every
metric compares shapes, not sizes or positions.
"""

from __future__ import annotations

import math

import numpy as np

from bokehfit.apertures import CIRCLE_RADIUS, Aperture
from bokehfit.errors import InputError

__all__ = [
    "as_outline",
    "signed_area",
    "centroid",
    "perimeter",
    "normalise",
    "densify",
    "resample",
    "rotate",
    "aperture_outline",
    "intersection_area",
    "following",
    "DistanceToOutline",
    "DEFAULT_POINTS",
]

#: Points of an aperture outline (and of the densified outlines the Hausdorff
#: distance compares): a circle of 720 points is within 1.3e-5 of unit area.
DEFAULT_POINTS = 720
#: An outline whose |area| is below this fraction of its bounding box's squared
#: diagonal encloses no area (a line, a point, or rounding noise around one).
_ZERO_AREA_FRACTION = 1e-12


def as_outline(outline, name: str = "outline") -> np.ndarray:
    """``outline`` checked and cleaned, as a float64 array of shape (N, 2).

    Accepts (N, 2) and OpenCV's contour layout (N, 1, 2). A closing point equal
    to the first and repeated consecutive points are dropped.

    Raises
    ------
    InputError
        Naming ``name``: not an (N, 2) array of numbers, fewer than 3 distinct
        points, a NaN or infinity, or zero enclosed area.
    """
    try:
        points = np.asarray(outline, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an array of (x, y) points of shape (N, 2) (got {type(outline).__name__})") from None
    if points.ndim == 3 and points.shape[1] == 1:
        points = points[:, 0, :]
    if points.ndim != 2 or points.shape[1] != 2:
        raise InputError(f"{name} must be an array of (x, y) points of shape (N, 2) (got shape {points.shape})")
    if not np.all(np.isfinite(points)):
        raise InputError(f"{name} must contain only finite numbers (found NaN or infinity)")
    if len(points) >= 2:
        # Drop repeats (they make zero-length edges) and a closing copy of the first point.
        keep = np.any(points != np.roll(points, 1, axis=0), axis=1)
        keep[0] = True
        points = points[keep]
        if len(points) > 1 and np.array_equal(points[-1], points[0]):
            points = points[:-1]
    if len(points) < 3:
        raise InputError(f"{name} must have at least 3 distinct points (got {len(points)})")
    diagonal_sq = float(np.sum(np.ptp(points, axis=0) ** 2))
    if not abs(signed_area(points)) > _ZERO_AREA_FRACTION * diagonal_sq:
        raise InputError(f"{name} encloses zero area (its points lie on a line or a point)")
    return points


def following(outline: np.ndarray) -> np.ndarray:
    """Each point's successor along the closed outline (the last's is the first)."""
    return np.concatenate((outline[1:], outline[:1]))


def signed_area(outline: np.ndarray) -> float:
    """Shoelace area: positive for counter-clockwise outlines."""
    # Subtract a point first: the sum of cross products then doesn't cancel large offsets.
    p = outline - outline[0]
    q = following(p)
    return 0.5 * float(np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))


def centroid(outline: np.ndarray) -> np.ndarray:
    """Area centroid of the polygon (not the mean of its points).

    Notes
    -----
    Cx = Σ (x_i + x_{i+1}) c_i / (6A), Cy likewise, with c_i = x_i y_{i+1} − x_{i+1} y_i.
    """
    origin = outline[0]
    p = outline - origin
    q = following(p)
    cross = p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]
    area = 0.5 * float(np.sum(cross))
    return origin + np.sum((p + q) * cross[:, None], axis=0) / (6.0 * area)


def perimeter(outline: np.ndarray) -> float:
    """Length of the closed outline."""
    return float(np.sum(np.hypot(*(following(outline) - outline).T)))


def normalise(outline, name: str = "outline") -> np.ndarray:
    """The outline with its centroid at 0, unit area and counter-clockwise.

    The centroid is the polygon's area centroid, not the mean of its points
    (which depends on how densely each side is sampled). A clockwise outline is
    reversed, keeping its first point first.

    Parameters
    ----------
    outline : array_like of shape (N, 2)
        A closed simple polygon, any orientation, start point and units.
    name : str
        The parameter's name in error messages.

    Returns
    -------
    ndarray of shape (N', 2)
        N' ≤ N: repeated points and a closing copy of the first are dropped.

    Examples
    --------
    >>> square = normalise([[0, 0], [0, 2], [2, 2], [2, 0]])
    >>> float(signed_area(square))
    1.0
    """
    points = as_outline(outline, name)
    area = signed_area(points)
    if area < 0.0:
        points = np.concatenate([points[:1], points[:0:-1]])
    return (points - centroid(points)) / math.sqrt(abs(area))


def densify(outline: np.ndarray, points: int = DEFAULT_POINTS) -> np.ndarray:
    """The outline with every side split evenly so that about ``points`` points lie on it.

    The vertices are kept; a side of length ℓ is cut into max(1, round(ℓ/step))
    equal pieces, step = perimeter / points. Sides already shorter than the
    step are left alone, so a dense outline stays as it is.
    """
    q = following(outline)
    lengths = np.hypot(*(q - outline).T)
    step = float(np.sum(lengths)) / points
    pieces = np.maximum(1, np.round(lengths / step).astype(np.int64))
    side = np.repeat(np.arange(len(outline)), pieces)
    start = np.cumsum(pieces) - pieces
    fraction = (np.arange(int(np.sum(pieces))) - start[side]) / pieces[side]
    return outline[side] + fraction[:, None] * (q[side] - outline[side])


def resample(outline: np.ndarray, points: int) -> np.ndarray:
    """``points`` points evenly spaced along the closed outline (by arc length), from its first point.

    Unlike :func:`densify` it also thins a dense outline, which bounds the cost
    of the metrics on large discs.
    """
    closed = np.concatenate((outline, outline[:1]))
    arc = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(closed, axis=0).T))))
    at = np.linspace(0.0, arc[-1], points, endpoint=False)
    return np.stack([np.interp(at, arc, closed[:, 0]), np.interp(at, arc, closed[:, 1])], axis=-1)


def rotate(outline: np.ndarray, angle_deg: float) -> np.ndarray:
    """The outline rotated counter-clockwise by ``angle_deg`` about the origin."""
    a = math.radians(angle_deg)
    c, s = math.cos(a), math.sin(a)
    return outline @ np.array([[c, s], [-s, c]])


def aperture_outline(aperture: Aperture, points: int = DEFAULT_POINTS) -> np.ndarray:
    """The unit-area outline of ``aperture``, rotated by its angle, counter-clockwise.

    Parameters
    ----------
    aperture : Aperture
        From :func:`bokehfit.apertures.make_aperture`.
    points : int
        About this many points, spread evenly along the perimeter (the
        polygon's vertices are kept). A circle is ``points`` points on the
        radius 1/√π, the first at ``aperture.angle_deg``; its area is then
        1 − O(1/points²) (1 − 1.3e-5 at 720 points).

    Examples
    --------
    >>> from bokehfit.apertures import make_aperture
    >>> aperture_outline(make_aperture("hexagon", 10), points=60).shape
    (60, 2)
    """
    if not isinstance(aperture, Aperture):
        raise InputError(f"aperture must be an Aperture from make_aperture (got {type(aperture).__name__})")
    if isinstance(points, bool) or not isinstance(points, (int, np.integer)) or points < 3:
        raise InputError(f"points must be an integer of at least 3 (got {points!r})")
    if aperture.is_circle:
        t = np.radians(aperture.angle_deg) + 2.0 * np.pi * np.arange(points) / points
        return CIRCLE_RADIUS * np.stack([np.cos(t), np.sin(t)], axis=-1)
    return densify(aperture.vertices(), int(points))


#: Passes of :func:`intersection_area` that add the crossings of the two
#: outlines' sides as slab boundaries (one or two suffice; the cap only guards
#: against rounding that keeps re-finding a crossing already cut).
_CROSSING_PASSES = 8


def intersection_area(a: np.ndarray, b: np.ndarray, lines: int = 64, *, exact: bool = True) -> float:
    """Area of the intersection of two closed simple polygons, by scanlines exact in x.

    The y range the two share is cut into slabs at every vertex of either
    outline, at ``lines`` evenly spaced lines and (``exact``) at every point
    where a side of ``a`` crosses a side of ``b``. On the centre line of each
    slab the spans inside each polygon are found exactly (even-odd rule on the
    sides' crossings), and the length inside both times the slab's height is
    summed: a 1-D rasterisation, exact across x.

    Notes
    -----
    Within a slab no outline has a vertex, so the length inside both, L(y), is
    linear except where a side of ``a`` crosses a side of ``b``. With those
    crossings cut too, the midpoint rule is exact and the area is exact up to
    rounding (shapely agrees to 1e-12). A crossing shows itself as two sides,
    neighbours in x on the centre line, whose order differs at the slab's top
    or bottom; the pass that finds them is repeated until none is left.
    ``lines`` then only keeps slabs short. Without ``exact`` each uncut
    crossing errs by up to about h²·|Δs|/8 (h the slab's height, Δs the
    difference of the sides' dx/dy): ~2e-5 of the IoU of irregular outlines at
    1024 lines. A 1024² pixel mask errs by up to 4e-3, where long sides align
    with the grid, cv2.fillPoly more (it also fills the pixels that its edges
    touch, about a third of a pixel too wide all round).
    """
    low = max(a[:, 1].min(), b[:, 1].min())
    high = min(a[:, 1].max(), b[:, 1].max())
    if not high > low:
        return 0.0
    cuts = np.concatenate([a[:, 1], b[:, 1], np.linspace(low, high, lines + 1)])
    cuts = np.unique(cuts[(cuts >= low) & (cuts <= high)])
    sides = [_sides(outline) for outline in (a, b)]
    for _ in range(_CROSSING_PASSES):
        mids = 0.5 * (cuts[:-1] + cuts[1:])
        records = [_scanline_crossings(mids, *side, tag) for tag, side in enumerate(sides)]
        slab, x, tag, x0, y0, slope = (np.concatenate(v) for v in zip(*records))
        order = np.lexsort((x, slab))
        slab, x, tag, x0, y0, slope = (v[order] for v in (slab, x, tag, x0, y0, slope))
        if not exact:
            break
        # Neighbours on the centre line (x[i] <= x[i+1]) swapped at the bottom or top cross in between.
        same = slab[1:] == slab[:-1]
        bottom, top = cuts[slab[:-1]], cuts[slab[:-1] + 1]

        def at(y, index):
            return x0[index] + (y - y0[index]) * slope[index]

        left, right = np.arange(len(x) - 1), np.arange(1, len(x))
        # A margin keeps coincident sides (a shape against itself), which cross
        # nowhere, from looking swapped by rounding.
        margin = 1e-12 * (high - low)
        swapped = same & (slope[left] != slope[right])
        swapped &= (at(bottom, right) < at(bottom, left) - margin) | (at(top, right) < at(top, left) - margin)
        if not np.any(swapped):
            break
        i, j = left[swapped], right[swapped]
        # x_i(y) = x_j(y): y = (x0_j − x0_i − y0_j s_j + y0_i s_i) / (s_i − s_j)
        y_cross = (x0[j] - x0[i] - y0[j] * slope[j] + y0[i] * slope[i]) / (slope[i] - slope[j])
        y_cross = np.clip(y_cross, bottom[swapped], top[swapped])
        cuts = np.unique(np.concatenate([cuts, y_cross]))
    height = np.diff(cuts)
    # Inside a (b) after a crossing: an odd count of a's (b's) crossings so far.
    # Every slab holds an even count of each, so the running count needs no reset.
    inside_a = np.cumsum(tag == 0) % 2 == 1
    inside_b = np.cumsum(tag == 1) % 2 == 1
    both = (inside_a & inside_b)[:-1] & (slab[1:] == slab[:-1])
    return float(np.sum((x[1:] - x[:-1])[both] * height[slab[:-1][both]]))


def _sides(outline: np.ndarray):
    """The non-horizontal sides: start x, start y, end y, dx/dy."""
    q = following(outline)
    keep = outline[:, 1] != q[:, 1]
    p, q = outline[keep], q[keep]
    return p[:, 0], p[:, 1], q[:, 1], (q[:, 0] - p[:, 0]) / (q[:, 1] - p[:, 1])


def _scanline_crossings(mids, x0, y0, y1, slope, tag):
    """Where the sides cross the slabs' centre lines: slab, x, tag, and each side's x0, y0, slope."""
    # Centre lines never pass through a vertex (every vertex is a cut), so no
    # crossing is counted twice.
    first = np.searchsorted(mids, np.minimum(y0, y1))
    count = np.searchsorted(mids, np.maximum(y0, y1)) - first
    side = np.repeat(np.arange(len(x0)), count)
    slab = first[side] + np.arange(len(side)) - np.repeat(np.cumsum(count) - count, count)
    x = x0[side] + (mids[slab] - y0[side]) * slope[side]
    return slab, x, np.full(len(side), tag), x0[side], y0[side], slope[side]


class DistanceToOutline:
    """Distances from points to the nearest point of a closed outline (its sides, not only its vertices).

    :meth:`__call__` measures each point against the sides that can be its nearest only: a side
    whose midpoint lies farther from the point than the nearest midpoint does, by more than the
    longest half-side, is farther than that midpoint (a point of a side is within half its
    length of its midpoint). Among the sides kept is always the nearest, so the distance is the
    same number as against every side, at a few sides a point on a densely sampled outline
    instead of all of them.
    """

    #: Point-side pairs evaluated at once by :meth:`__call__` (bounds its memory: ~16 MiB of float64 temporaries).
    PAIRS_PER_CHUNK = 2**18
    #: Outlines of at most this many sides are measured against every side (the search costs more).
    ALL_SIDES_UP_TO = 64
    #: Sides (the nearest by their midpoints) each point is first measured against: where every side
    #: that can be its nearest is among them, as on a densely sampled outline, no further search is made.
    NEAREST_SIDES = 6

    def __init__(self, outline: np.ndarray):
        self.start = np.asarray(outline, dtype=np.float64)
        self.side = following(self.start) - self.start
        self.length_sq = np.sum(self.side * self.side, axis=1)
        # A zero-length side (a repeated point) is its start point: its t is 0.
        self._inverse_length_sq = np.divide(1.0, self.length_sq, out=np.zeros_like(self.length_sq),
                                            where=self.length_sq > 0.0)
        self._middles = None  # (KD-tree of the sides' midpoints, the longest half-side), made on first use

    def to_sides(self, x: np.ndarray, y: np.ndarray, sides=slice(None)) -> np.ndarray:
        """Distance from the points (x, y) to the sides ``sides`` (indices), broadcast together."""
        dx, dy = x - self.start[sides, 0], y - self.start[sides, 1]
        vx, vy = self.side[sides, 0], self.side[sides, 1]
        t = np.clip((dx * vx + dy * vy) * self._inverse_length_sq[sides], 0.0, 1.0)
        ex, ey = dx - t * vx, dy - t * vy
        return np.sqrt(ex * ex + ey * ey)

    def __call__(self, points: np.ndarray) -> np.ndarray:
        points = np.atleast_2d(np.asarray(points, dtype=np.float64))
        if len(self.start) <= self.ALL_SIDES_UP_TO:
            return self._to_all_sides(points)
        if self._middles is None:
            from scipy.spatial import cKDTree

            self._middles = (cKDTree(self.start + 0.5 * self.side), 0.5 * math.sqrt(float(self.length_sq.max())))
        tree, longest_half = self._middles
        # The nearest midpoint is on its side: the nearest side lies within it plus the longest half-side.
        # The few nearest midpoints mostly hold every side that close: measured against those at once.
        nearest = min(self.NEAREST_SIDES, len(self.start))
        found, sides = tree.query(points, k=nearest)
        reach = found[:, 0] * (1.0 + 1e-12) + longest_half + 1e-12
        result = self.to_sides(points[:, 0, None], points[:, 1, None], sides).min(axis=1)
        farther = np.flatnonzero(found[:, -1] <= reach)  # sides within reach may lie beyond the few
        if len(farther):
            result[farther] = self._within(points[farther], reach[farther])
        return result

    def _within(self, points: np.ndarray, reach: np.ndarray) -> np.ndarray:
        """Distances from the points to the sides whose midpoints lie within ``reach`` of each."""
        tree, _ = self._middles
        near = tree.query_ball_point(points, reach, return_sorted=False)
        counts = np.fromiter((len(sides) for sides in near), dtype=np.intp, count=len(points))
        if counts.sum() >= len(points) * len(self.start) // 2:  # the outline's sides are too long to prune
            return self._to_all_sides(points)
        sides = np.fromiter((side for found in near for side in found), dtype=np.intp, count=int(counts.sum()))
        owner = np.repeat(np.arange(len(points)), counts)
        distances = self.to_sides(points[owner, 0], points[owner, 1], sides)
        return np.minimum.reduceat(distances, np.cumsum(counts) - counts)

    def _to_all_sides(self, points: np.ndarray) -> np.ndarray:
        result = np.empty(len(points))
        chunk = max(1, self.PAIRS_PER_CHUNK // len(self.start))
        for first in range(0, len(points), chunk):
            p = points[first : first + chunk]
            result[first : first + chunk] = self.to_sides(p[:, 0, None], p[:, 1, None]).min(axis=1)
        return result
