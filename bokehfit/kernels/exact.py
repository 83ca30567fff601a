"""Exact area coverage of an aperture on a pixel grid (the reference kernel).

Notes
-----
Let F(X, Y) be the area of the shape inside the quadrant {x ≤ X, y ≤ Y}. A
pixel's coverage is F's second difference over its four corners, so one
evaluation of F on the (size+1)² corner grid gives every pixel at once. On
a large frame :func:`coverage` evaluates F only at the corners of the pixels
the outline crosses: every other pixel is wholly inside (1) or outside (0).

F follows from Green's theorem: for a counter-clockwise boundary split into
pieces y = f(x) that are monotone in x,

    F(X, Y) = −Σ_pieces sign · ∫ min(f(x), Y) dx   over  [x_min, clamp(X)],

with sign +1 for pieces running left to right. Each integral is closed-form:
up to the abscissa x* where f crosses Y it integrates f (antiderivative H),
beyond it the constant Y. Polygon edges are straight pieces (vertical edges
drop out). Arcs of the outline (:meth:`Aperture.outline`: the circle, rounded
blades, the vignetting cut, all made axis-aligned elliptic arcs by the
squeeze) are split at their ellipse's quadrant borders; on each quarter
∫ f = trapezoid under the chord − ½·rx·ry·(Δθ − sin Δθ). The squeeze is
thus exact, not a resampling of the grid. The result is exact up to float64
rounding (about 1e-12 per pixel for a 1000-px disc), for convex and
non-convex (star) outlines, and the several loops a vignetting cut can leave.

The ``rim`` profile has no closed form over a pixel's share of a rounded or
clipped outline; :func:`bokehfit.kernels.rim.rim_coverage` tabulates it with a stated bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from bokehfit.apertures import (
    Aperture,
    Arc,
    Outline,
    Segment,
    aperture_rows_to_image,
)
from bokehfit.apertures.samplers import x_minus_sin

__all__ = ["CoverageSlopes", "coverage", "coverage_slopes", "quadrant_area"]


#: Columns of one elliptic piece's row in :attr:`_Boundary.arcs` (see :func:`_elliptic_pieces`).
_ARC_COLUMNS = ("cx", "cy", "rx", "ry", "side", "x_left", "y_left", "theta_left", "base", "upper", "right",
                "y_low", "y_high", "x_min", "x_max", "sign", "increasing")


def _elliptic_pieces(arc: Arc) -> list[tuple[float, ...]]:
    """The arc split at its ellipse's quadrant borders into pieces monotone in x and y, one row
    of :data:`_ARC_COLUMNS` each.

    Within a quadrant y = cy ± ry·√(1 − t²), t = (x − cx)/rx (``side`` ±1). The integral of
    f from the piece's left end (``x_left``, ``y_left``, at angle ``theta_left``) is taken as the
    chord's trapezoid minus the elliptic segment ½·rx·ry·(Δθ − sin Δθ) (:func:`x_minus_sin`),
    which stays exact for the gently curved arcs of slightly rounded blades, where the
    closed-form antiderivative would cancel (:func:`_arc_integral`). ``base`` is the whole turns
    of the piece's angles, ``upper`` (1 or 0) whether it is in the upper half, ``right`` (±1)
    which side of the centre it is on, ``sign`` +1 where the boundary runs left to right and
    ``increasing`` (1 or 0) whether f rises with x.
    """
    (cx, cy), (rx, ry) = arc.centre, arc.radii
    lo, hi = sorted((arc.start, arc.end))
    forward = arc.end >= arc.start
    quarter = 0.5 * math.pi
    borders = [lo, *(k * quarter for k in range(math.floor(lo / quarter) + 1, math.ceil(hi / quarter))), hi]
    pieces = []
    for t0, t1 in zip(borders[:-1], borders[1:]):
        if t1 <= t0:
            continue
        mid = 0.5 * (t0 + t1)
        quadrant = math.floor(mid / quarter) % 4
        base = 2.0 * math.pi * math.floor(mid / (2.0 * math.pi))
        upper = quadrant in (0, 1)
        right = quadrant in (0, 3)
        x0, x1 = cx + rx * math.cos(t0), cx + rx * math.cos(t1)
        if x0 == x1:
            continue  # a vertical piece adds no area under the curve
        y0, y1 = cy + ry * math.sin(t0), cy + ry * math.sin(t1)
        # x falls as θ grows in the upper half, rises in the lower one.
        x_rises_with_theta = not upper
        sign = 1.0 if x_rises_with_theta == forward else -1.0
        theta_left = t0 if x_rises_with_theta else t1
        x_left, y_left = (x0, y0) if x_rises_with_theta else (x1, y1)
        x_min, x_max = min(x0, x1), max(x0, x1)
        y_low, y_high = min(y0, y1), max(y0, y1)
        side = 1.0 if upper else -1.0
        # f rises with x left of the centre in the upper half and right of it in the lower half.
        pieces.append((cx, cy, rx, ry, side, x_left, y_left, theta_left, base, float(upper), 1.0 if right else -1.0,
                       y_low, y_high, x_min, x_max, sign, float(upper != right)))
    return pieces


def _arc_integral(arcs: np.ndarray, x: np.ndarray) -> np.ndarray:
    """∫ f from each elliptic piece's left end to x: the trapezoid under the chord minus the elliptic
    segment (:func:`_elliptic_pieces`). ``arcs``: columns (rows of :data:`_ARC_COLUMNS`, each
    shaped to broadcast against ``x``)."""
    cx, _, rx, ry, _, x_left, y_left, theta_left, base, upper = arcs[:10]
    angle = np.arccos(np.clip((x - cx) / rx, -1.0, 1.0))
    theta = base + np.where(upper > 0.0, angle, 2.0 * math.pi - angle)
    return 0.5 * (y_left + _arc_height(arcs, x)) * (x - x_left) - 0.5 * rx * ry * x_minus_sin(theta - theta_left)


def _arc_height(arcs: np.ndarray, x: np.ndarray) -> np.ndarray:
    """f(x) of each elliptic piece (``arcs`` as for :func:`_arc_integral`)."""
    cx, cy, rx, ry, side = arcs[:5]
    t = np.clip((x - cx) / rx, -1.0, 1.0)
    return cy + side * ry * np.sqrt(np.maximum((1.0 - t) * (1.0 + t), 0.0))


def _arc_crossing(arcs: np.ndarray, y: np.ndarray) -> np.ndarray:
    """x* where each elliptic piece crosses the height y, clamped to the piece."""
    cx, cy, rx, ry = arcs[:4]
    right, y_low, y_high, x_min, x_max = arcs[10:15]
    s = (np.clip(y, y_low, y_high) - cy) / ry
    x = cx + right * rx * np.sqrt(np.maximum((1.0 - s) * (1.0 + s), 0.0))
    return np.clip(x, x_min, x_max)


@dataclass(frozen=True)
class _Boundary:
    """An outline scaled to pixels, as the pieces of the module notes: its straight sides that
    are not vertical, as rows (x0, y0, x1, y1), and its arcs' monotone pieces, as rows of
    :data:`_ARC_COLUMNS`."""

    segments: np.ndarray  #: (S, 4)
    arcs: np.ndarray  #: (A, len(_ARC_COLUMNS))


def _boundary(outline: Outline, scale: float) -> _Boundary:
    return _scaled_boundary(outline.transformed(np.diag([scale, scale])))


def _scaled_boundary(scaled: Outline) -> _Boundary:
    """The pieces of an outline already scaled to pixels."""
    segments, arcs = [], []
    for piece in scaled.pieces:
        if isinstance(piece, Segment):
            if piece.start[0] != piece.end[0]:  # vertical sides add no area under the curve
                segments.append((*piece.start, *piece.end))
        else:
            arcs.extend(_elliptic_pieces(piece))
    return _Boundary(np.array(segments, dtype=np.float64).reshape(-1, 4),
                     np.array(arcs, dtype=np.float64).reshape(-1, len(_ARC_COLUMNS)))


def quadrant_area(
    aperture: Aperture | Outline, scale: float, xs: np.ndarray, ys: np.ndarray, field_position=None
) -> np.ndarray:
    """Area of the scaled aperture inside {x ≤ X, y ≤ Y} for every (Y, X) in ys × xs.

    ``aperture`` is an :class:`Aperture` (its outline at ``field_position``,
    clipped by the vignetting there) or an :class:`Outline`. Returns an array
    of shape (len(ys), len(xs)).
    """
    outline = aperture if isinstance(aperture, Outline) else aperture.outline(field_position)
    xs = np.asarray(xs, dtype=np.float64).ravel()
    ys = np.asarray(ys, dtype=np.float64).ravel()
    return _area_below_left(_boundary(outline, scale), xs, ys)


#: Piece-point pairs :func:`_area_below_left` evaluates at once (bounds its temporaries).
_SIDE_CHUNK = 2**18


def _piece_columns(boundary: _Boundary, xs: np.ndarray, ys: np.ndarray):
    """Everything of F that hangs on X alone or on Y alone, for every piece (sides, then arc pieces):
    t = X clamped to the piece, its integral H(t), the crossing x*(Y) and H(x*), with each piece's
    left end, H there, sign and whether f rises; last, f(t), the piece's height at t."""
    sides, arcs = boundary.segments, boundary.arcs
    x0, y0, x1, y1 = sides.T[:, :, None]
    left = x0 < x1
    xa, ya, xb, yb = np.where(left, x0, x1), np.where(left, y0, y1), np.where(left, x1, x0), np.where(left, y1, y0)
    slope = (yb - ya) / (xb - xa)
    flat = slope == 0.0
    side_t = np.clip(xs[None, :], xa, xb)
    side_c = np.where(flat, np.where(ys[None, :] > ya, xb, xa),
                      np.clip(xa + (ys[None, :] - ya) / np.where(flat, 1.0, slope), xa, xb))

    def under(x):  # ∫ f from x_min to x
        return ya * (x - xa) + 0.5 * slope * (x - xa) ** 2

    columns = arcs.T[:, :, None]
    x_min = columns[13]
    arc_t = np.clip(xs[None, :], x_min, columns[14])
    arc_c = _arc_crossing(columns, ys[None, :])
    t = np.concatenate([side_t, arc_t])
    c = np.concatenate([side_c, arc_c])
    h_t = np.concatenate([under(side_t), _arc_integral(columns, arc_t)])
    h_c = np.concatenate([under(side_c), _arc_integral(columns, arc_c)])
    start = np.concatenate([xa, x_min])[:, :, None]
    h_start = np.concatenate([np.zeros_like(xa), _arc_integral(columns, x_min)])[:, :, None]
    sign = np.concatenate([np.where(left, 1.0, -1.0), columns[15]])[:, :, None]
    increasing = np.concatenate([(slope >= 0.0).ravel(), columns[16].ravel() > 0.0])
    height = np.concatenate([ya + slope * (side_t - xa), _arc_height(columns, arc_t)])
    return t, c, h_t, h_c, start, h_start, sign, increasing, height


def _area_below_left(boundary: _Boundary, xs: np.ndarray, ys: np.ndarray,
                     rows: np.ndarray | None = None, cols: np.ndarray | None = None) -> np.ndarray:
    """F(X, Y) of the module notes on the grid ys × xs (shape (len(ys), len(xs))), or, given ``rows``
    and ``cols``, at the points (xs[cols], ys[rows]).

    For a piece, F's terms hang on X alone (t = X clamped to the piece, H(t)) or on Y alone (the
    crossing x*, H(x*)), and x* ∧ t is one of the two: the integrals are taken on xs and ys
    once (:func:`_piece_columns`), and over the points only sums and products are left, for all
    the pieces at once, a chunk of the points at a time. Every point's sum runs over the pieces
    in the same order however many points there are, so a point gets the same value in a whole
    grid as among a few."""
    grid = rows is None
    shape = (len(ys), len(xs)) if grid else np.shape(rows)
    total = np.zeros(shape)
    count = len(boundary.segments) + len(boundary.arcs)
    if count == 0 or total.size == 0:
        return total
    t, c, h_t, h_c, start, h_start, sign, increasing, _ = _piece_columns(boundary, xs, ys)
    rising, falling = np.flatnonzero(increasing), np.flatnonzero(~increasing)
    if grid:
        step = max(1, _SIDE_CHUNK // (count * max(len(xs), 1)))
        chunks = [(slice(lo, lo + step), slice(None)) for lo in range(0, len(ys), step)]
    else:
        rows, cols = np.ravel(rows), np.ravel(cols)
        step = max(1, _SIDE_CHUNK // count)
        chunks = [(rows[lo : lo + step], cols[lo : lo + step]) for lo in range(0, rows.size, step)]
    out = total.reshape(-1) if not grid else total
    at = 0
    for row, col in chunks:
        if grid:  # (pieces, rows, columns)
            tt, ht = t[:, None, :], h_t[:, None, :]
            cc, hc, y = c[:, row, None], h_c[:, row, None], ys[None, row, None]
        else:  # (pieces, points)
            tt, ht, cc, hc, y = t[:, col], h_t[:, col], c[:, row], h_c[:, row], ys[None, row]
            start_p, h_start_p, sign_p = start[:, :, 0], h_start[:, :, 0], sign[:, :, 0]
        s0, hs0, sg = (start, h_start, sign) if grid else (start_p, h_start_p, sign_p)
        below = tt <= cc
        x_cross = np.where(below, tt, cc)  # min(t, x*)
        h_cross = np.where(below, ht, hc)
        values = np.empty(np.broadcast_shapes(x_cross.shape, (count, *np.shape(y)[1:])))
        if len(rising):  # f < Y left of x*
            r = rising
            values[r] = h_cross[r] - hs0[r] + y * (np.broadcast_to(tt, x_cross.shape)[r] - x_cross[r])
        if len(falling):  # f ≥ Y left of x*
            f = falling
            values[f] = y * (x_cross[f] - s0[f]) + np.broadcast_to(ht, x_cross.shape)[f] - h_cross[f]
        part = (-sg * values).sum(axis=0)
        if grid:
            out[row] = part
        else:
            out[at : at + part.size] = part
            at += part.size
    return total


#: Largest spacing (pixels of arc length) of the points :func:`_edge_pixels` puts on the outline.
_EDGE_SAMPLE_PX = 0.5
#: :func:`coverage` integrates every pixel when the outline crosses more than this share of them,
#: or when the whole grid costs at most ``_EDGE_ONLY_MIN_WORK``: its corners times its pieces and
#: ``_EDGE_FIXED_PIECES`` more (the work of the whole grid against the fixed cost of finding the
#: crossed pixels). Measured on two cores: a 64-px frame of a circle, a polygon or a rounded 9-gon
#: integrates faster whole and a 96-px one by its crossed pixels; so does a 45-px frame of a
#: vignetted circle's 38 pieces, not a 64-px one.
_EDGE_ONLY_SHARE = 0.5
_EDGE_ONLY_MIN_WORK = 110_000
_EDGE_FIXED_PIECES = 12


def _edge_pixels(scaled: Outline, size: int, origin: tuple[float, float]) -> np.ndarray:
    """Pixels of the size × size grid (rows up in y) that the outline (scaled to pixels) may touch, as a bool mask.

    ``origin`` is where the aperture's centre lies in pixel-index coordinates
    (x, y). Points are put on every piece at most ``_EDGE_SAMPLE_PX`` apart (by
    arc length), so every point of the outline is within a quarter pixel of one;
    the pixels holding them, grown by one pixel all round, hold every pixel the
    outline touches (its index is then within 0.5 + 0.25 + 0.5 < 2 of theirs).
    """
    pieces = scaled.pieces
    segments = np.array([(p.start, p.end) for p in pieces if isinstance(p, Segment)], dtype=np.float64).reshape(-1, 2, 2)
    steps = np.maximum(1, np.ceil(np.hypot(*(segments[:, 1] - segments[:, 0]).T) / _EDGE_SAMPLE_PX)).astype(np.int64)
    which = np.repeat(np.arange(len(steps)), steps + 1)
    along = (np.arange(len(which)) - np.repeat(np.cumsum(steps + 1) - (steps + 1), steps + 1)) / steps[which]
    points = [segments[which, 0] + along[:, None] * (segments[which, 1] - segments[which, 0])]
    for piece in pieces:
        if not isinstance(piece, Segment):  # the ellipse moves at most max(rx, ry) per radian
            count = max(2, math.ceil(max(piece.radii) * abs(piece.end - piece.start) / _EDGE_SAMPLE_PX) + 1)
            points.append(piece.point(np.linspace(0.0, 1.0, count)))
    xy = np.concatenate(points)
    marked = np.zeros((size + 2, size + 2), dtype=bool)  # a one-pixel border for points just outside
    cols = np.clip(np.floor(xy[:, 0] + origin[0] + 0.5), -1, size).astype(np.int64) + 1
    rows = np.clip(np.floor(xy[:, 1] + origin[1] + 0.5), -1, size).astype(np.int64) + 1
    marked[rows, cols] = True
    grown = marked.copy()
    grown[1:] |= marked[:-1]
    grown[:-1] |= marked[1:]
    wide = grown.copy()
    wide[:, 1:] |= grown[:, :-1]
    wide[:, :-1] |= grown[:, 1:]
    return wide[1:-1, 1:-1]


def coverage(
    aperture: Aperture | Outline,
    scale: float,
    size: int,
    flip: bool = False,
    offset_xy: tuple[float, float] = (0.0, 0.0),
    field_position=None,
) -> np.ndarray:
    """Area of the scaled aperture on each pixel of a size × size grid (float64).

    The aperture's centre lies at ((size−1)/2, (size−1)/2) in pixel-centre
    coordinates, moved by ``offset_xy`` (x right, y up on screen, design.md §2).
    ``flip`` shows the near side (:meth:`Aperture.near`: the shape and its
    vignetting cut turned by 180°). ``field_position`` places a vignetted
    aperture in the frame (design.md §3b); the clipped shape keeps its scale.

    Notes
    -----
    Only the pixels the outline crosses need the integral: F is evaluated at
    their corners alone (:func:`_edge_pixels` finds them). Every other pixel
    lies wholly inside or wholly outside, and so does every pixel connected to
    it through such pixels (4-connected): one exact pixel of each connected
    region says which, and the region gets 1 or 0. The crossed pixels are
    bit-identical to the integral over the whole grid; the others are the
    exact 1 or 0 that the whole-grid integral reaches to within rounding.
    """
    centre = (size - 1) / 2.0
    edges = np.arange(size + 1, dtype=np.float64) - 0.5 - centre  # pixel borders, aperture frame
    if flip:
        aperture = aperture.near() if isinstance(aperture, Aperture) else aperture.transformed(-np.eye(2))
    outline = aperture if isinstance(aperture, Outline) else aperture.outline(field_position)
    scaled = outline.transformed(np.diag([scale, scale]))
    boundary = _scaled_boundary(scaled)
    dx, dy = offset_xy
    xs, ys = edges - dx, edges - dy
    crossed = _crossed(scaled, boundary, size, (centre + dx, centre + dy))
    if crossed is None:
        cells = _cells(_area_below_left(boundary, xs, ys))
        return np.clip(aperture_rows_to_image(cells), 0.0, 1.0)  # rows of `cells` run up in y
    probed = _Probed.of(crossed)
    cumulative = np.zeros((size + 1, size + 1))
    cumulative[probed.rows, probed.cols] = _area_below_left(boundary, xs, ys, probed.rows, probed.cols)
    return np.clip(aperture_rows_to_image(probed.filled(_cells(cumulative))), 0.0, 1.0)


def _cells(f: np.ndarray) -> np.ndarray:
    """Each pixel's second difference of ``f`` over its four corners (rows up in y, as ``f``)."""
    return f[1:, 1:] - f[:-1, 1:] - f[1:, :-1] + f[:-1, :-1]


def _crossed(scaled: Outline, boundary: _Boundary, size: int, origin: tuple[float, float]) -> np.ndarray | None:
    """The pixels the outline crosses (:func:`_edge_pixels`), or None where the whole grid is integrated
    (it costs little, or the outline crosses much of it: ``_EDGE_ONLY_MIN_WORK``, ``_EDGE_ONLY_SHARE``)."""
    work = (size + 1) ** 2 * (len(boundary.segments) + len(boundary.arcs) + _EDGE_FIXED_PIECES)
    if work <= _EDGE_ONLY_MIN_WORK:
        return None
    crossed = _edge_pixels(scaled, size, origin)
    return None if crossed.sum() > _EDGE_ONLY_SHARE * size * size else crossed


@dataclass(frozen=True)
class _Probed:
    """The pixels integrated on a grid whose outline crosses few of them: the crossed pixels, and one
    pixel of each region that they enclose, to say which side it is on (each region is wholly inside
    or wholly outside); the corners (rows, cols) to evaluate for them."""

    crossed: np.ndarray  #: the crossed pixels (rows up in y)
    regions: np.ndarray  #: each pixel's region (0: the crossed ones)
    probes: np.ndarray  #: a pixel (flat index) of each region after the first
    rows: np.ndarray
    cols: np.ndarray

    @classmethod
    def of(cls, crossed: np.ndarray) -> _Probed:
        import cv2

        size = crossed.shape[0]
        count, regions = cv2.connectedComponents((~crossed).astype(np.uint8), connectivity=4)
        member = np.empty(count, dtype=np.int64)
        member[regions.ravel()] = np.arange(size * size)  # some pixel of each region (label 0: the crossed ones)
        probes = member[1:]
        evaluate = crossed.copy()
        evaluate.ravel()[probes] = True
        corners = np.zeros((size + 1, size + 1), dtype=bool)
        for dr in (0, 1):
            for dc in (0, 1):
                corners[dr : dr + size, dc : dc + size] |= evaluate
        rows, cols = np.nonzero(corners)
        return cls(crossed, regions, probes, rows, cols)

    def filled(self, cells: np.ndarray) -> np.ndarray:
        """The coverage of every pixel from ``cells`` (exact on the crossed and probed pixels): the
        crossed pixels' own, the others their region's 1 or 0."""
        inside = np.zeros(len(self.probes) + 1)
        inside[1:] = cells.ravel()[self.probes] > 0.5  # 0 or 1 up to rounding
        return np.where(self.crossed, cells, inside[self.regions])


def _quadrant_slopes(boundary: _Boundary, xs: np.ndarray, ys: np.ndarray,
                     rows: np.ndarray | None = None, cols: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """∂F/∂X and ∂F/∂Y of the module notes, and the first moments of the same chords, on the grid
    ys × xs (each of shape (len(ys), len(xs))), or, given ``rows`` and ``cols``, at the points
    (xs[cols], ys[rows]) (the same values, to rounding).

    ∂F/∂X is the length of the shape on the line x = X below Y: −Σ sign · min(f(X), Y) over the
    pieces whose span holds X; its moment ∫ y dy over that chord is −Σ sign · ½ min(f(X), Y)².
    ∂F/∂Y is its length on y = Y left of X: −Σ sign · the length of [x_min, clamp(X)] where f > Y,
    t − min(t, x*) for a piece that rises, min(t, x*) − x_min for one that falls
    (:func:`_area_below_left`'s terms, differentiated); its moment ∫ x dx is −Σ sign · ½ (t² − min(t, x*)²),
    ½ (min(t, x*)² − x_min²) likewise."""
    grid = rows is None
    shape = (len(ys), len(xs)) if grid else (np.size(rows),)
    by_x, by_y, moment_x, moment_y = (np.zeros(shape) for _ in range(4))
    count = len(boundary.segments) + len(boundary.arcs)
    if count == 0 or by_x.size == 0:
        return by_x, by_y, moment_x, moment_y
    t, c, _, _, start, _, sign, increasing, height = _piece_columns(boundary, xs, ys)
    within = (t > start[:, :, 0]) & (t == xs[None, :])  # X strictly inside the piece's span
    if grid:  # (pieces, rows, columns), a band of rows at a time
        step = max(1, _SIDE_CHUNK // (count * max(len(xs), 1)))
        chunks = [(slice(lo, lo + step), np.s_[:, None, :], np.s_[:, slice(lo, lo + step), None], slice(lo, lo + step))
                  for lo in range(0, len(ys), step)]
        rising = increasing[:, None, None]
    else:  # (pieces, points)
        rows, cols = np.ravel(rows), np.ravel(cols)
        step = max(1, _SIDE_CHUNK // count)
        chunks = [(slice(lo, lo + step), np.s_[:, cols[lo : lo + step]], np.s_[:, rows[lo : lo + step]],
                   rows[lo : lo + step]) for lo in range(0, rows.size, step)]
        start, sign, rising = start[:, :, 0], sign[:, :, 0], increasing[:, None]
    for out, at_x, at_y, y_index in chunks:
        y = ys[None, y_index, None] if grid else ys[None, y_index]
        tt = t[at_x]
        x_cross = np.minimum(tt, c[at_y])
        below = np.where(within[at_x], np.minimum(height[at_x], y), 0.0)
        by_x[out] = (-sign * below).sum(axis=0)
        moment_x[out] = (-sign * 0.5 * below * below).sum(axis=0)
        by_y[out] = (-sign * np.where(rising, tt - x_cross, x_cross - start)).sum(axis=0)
        moment_y[out] = (-sign * 0.5 * np.where(rising, tt * tt - x_cross * x_cross,
                                                x_cross * x_cross - start * start)).sum(axis=0)
    return by_x, by_y, moment_x, moment_y


class CoverageSlopes(NamedTuple):
    """A pixel grid's exact coverage and its derivatives (image rows, as :func:`coverage`)."""

    cover: np.ndarray
    by_offset_x: np.ndarray  #: ∂/∂ offset x (right)
    by_offset_y: np.ndarray  #: ∂/∂ offset y (up)
    by_scale: np.ndarray  #: ∂/∂ scale
    by_flow: np.ndarray | None = None  #: ∂/∂t as the outline's points move by dp/dt = M·p (``flow`` M), if asked
    by_rim: np.ndarray | None = None  #: ∂/∂rim of a ``rim`` profile's light (:mod:`bokehfit.kernels.rim`)


def coverage_slopes(
    aperture: Aperture | Outline,
    scale: float,
    size: int,
    offset_xy: tuple[float, float] = (0.0, 0.0),
    field_position=None,
    flow: np.ndarray | None = None,
) -> CoverageSlopes:
    """:func:`coverage` on the whole size × size grid and its exact derivatives by the offset and the scale,
    and, given a 2×2 ``flow`` M, by a parameter t that moves the outline's points by dp/dt = M·p (from
    the shape's centre: a turn of the shape, for one).

    Notes
    -----
    Moving the shape by (dx, dy) is F evaluated at (X − dx, Y − dy), so a pixel's derivative by
    the offset is minus the second difference of ∂F/∂X (∂F/∂Y) over its corners: the shape's
    chords on the pixel's left and right (lower and upper) borders. The shape at scale s has
    F_s(X, Y) = s² F_1(X/s, Y/s), so ∂F_s/∂s = (2F − X ∂F/∂X − Y ∂F/∂Y) / s, X and Y taken
    from the shape's centre (:func:`_quadrant_slopes`). A flow v = M·p changes a pixel's coverage
    by the flux of v through the outline inside it, which is tr(M) times its coverage (the flux
    through the boundary of its share of the shape, by the divergence theorem) less the flux of v
    through the pixel's own borders inside the shape: on a border x = X, ∫ (M₀₀ X + M₀₁ y) dy over
    the chord, from ∂F/∂X and its moment; on y = Y, ∫ (M₁₀ x + M₁₁ Y) dx likewise (the scale is
    the flow M = I/s, and gives the same column). Every term is the closed form of the module
    notes: exact up to rounding, for the pieces :func:`coverage` takes (no ``rim``, no ``mask``).
    On a grid that :func:`coverage` integrates by its crossed pixels alone, so does this: the
    others keep their coverage and do not move.
    """
    centre = (size - 1) / 2.0
    edges = np.arange(size + 1, dtype=np.float64) - 0.5 - centre
    outline = aperture if isinstance(aperture, Outline) else aperture.outline(field_position)
    scaled = outline.transformed(np.diag([scale, scale]))
    boundary = _scaled_boundary(scaled)
    xs, ys = edges - offset_xy[0], edges - offset_xy[1]
    crossed = _crossed(scaled, boundary, size, (centre + offset_xy[0], centre + offset_xy[1]))
    if crossed is None:
        area = _area_below_left(boundary, xs, ys)
        by_x, by_y, moment_x, moment_y = _quadrant_slopes(boundary, xs, ys)
    else:  # only the crossed pixels move with the outline: the others' slopes are 0
        probed = _Probed.of(crossed)
        rows, cols = probed.rows, probed.cols
        grids = [np.zeros((size + 1, size + 1)) for _ in range(5)]
        values = (_area_below_left(boundary, xs, ys, rows, cols), *_quadrant_slopes(boundary, xs, ys, rows, cols))
        for grid, value in zip(grids, values):
            grid[rows, cols] = value
        area, by_x, by_y, moment_x, moment_y = grids

    def cells(f: np.ndarray) -> np.ndarray:  # rows of `f` run up in y
        return aperture_rows_to_image(_cells(f) if crossed is None else np.where(crossed, _cells(f), 0.0))

    by_scale = (2.0 * area - xs[None, :] * by_x - ys[:, None] * by_y) / scale
    by_flow = None
    if flow is not None:
        (m00, m01), (m10, m11) = np.asarray(flow, dtype=np.float64)
        across_x = m00 * xs[None, :] * by_x + m01 * moment_x  # ∫ v_x dy on x = X, below Y
        across_y = m10 * moment_y + m11 * ys[:, None] * by_y  # ∫ v_y dx on y = Y, left of X
        by_flow = cells((m00 + m11) * area - across_x - across_y)
    cover = _cells(area) if crossed is None else probed.filled(_cells(area))
    return CoverageSlopes(np.clip(aperture_rows_to_image(cover), 0.0, 1.0), -cells(by_x), -cells(by_y),
                          cells(by_scale), by_flow)
