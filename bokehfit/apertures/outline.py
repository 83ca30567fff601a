"""Exact aperture outlines: straight segments and elliptic arcs (design.md §3, §3b).

An :class:`Outline` is one or more closed counter-clockwise loops of pieces. A
:class:`Segment` is a straight edge; an :class:`Arc` is part of an axis-aligned
ellipse ``centre + (rx cos θ, ry sin θ)`` for the parametric angle θ running
from ``start`` to ``end`` (counter-clockwise when ``end > start``). Rounded
blades are circular arcs; the anamorphic squeeze turns them (and the circle)
into axis-aligned elliptic arcs; the vignetting cut adds circular arcs. The
area is exact (Green's theorem per piece); :meth:`Outline.polyline` gives a
dense polygon with a stated chord error for code that needs vertices.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bokehfit.apertures.samplers import x_minus_sin

__all__ = ["Arc", "Outline", "Segment", "clip_by_circle"]

#: Parameter samples per arc when looking for its crossings with a circle; an
#: arc and a circle cross at most 4 times, and the pieces of an aperture are
#: at most a quarter turn of their ellipse, so 64 samples separate the roots.
_CROSSING_SAMPLES = 64


@dataclass(frozen=True)
class Segment:
    """Straight edge from ``start`` to ``end`` (each an (x, y) tuple)."""

    start: tuple[float, float]
    end: tuple[float, float]

    def point(self, tau):
        """Point at fraction ``tau`` in [0, 1] along the edge."""
        tau = np.asarray(tau, dtype=np.float64)[..., None]
        return (1.0 - tau) * np.asarray(self.start) + tau * np.asarray(self.end)

    def area_term(self) -> float:
        """½(x₀y₁ − x₁y₀): this edge's share of the enclosed area (Green's theorem)."""
        (x0, y0), (x1, y1) = self.start, self.end
        return 0.5 * (x0 * y1 - x1 * y0)

    def polyline(self, max_error: float) -> np.ndarray:
        """The start point (a straight edge has no chord error); the end is the next piece's start."""
        return np.asarray([self.start], dtype=np.float64)

    def piece(self, tau0: float, tau1: float) -> Segment:
        return Segment(tuple(self.point(tau0)), tuple(self.point(tau1)))

    def transformed(self, matrix: np.ndarray) -> Segment:
        """The edge mapped by the 2×2 ``matrix``."""
        return Segment(tuple(matrix @ np.asarray(self.start)), tuple(matrix @ np.asarray(self.end)))


@dataclass(frozen=True)
class Arc:
    """Arc of the axis-aligned ellipse ``centre + (rx cos θ, ry sin θ)``, θ from ``start`` to ``end``."""

    centre: tuple[float, float]
    radii: tuple[float, float]
    start: float  #: parametric angle, radians
    end: float

    def point(self, tau):
        theta = self.start + np.asarray(tau, dtype=np.float64) * (self.end - self.start)
        (cx, cy), (rx, ry) = self.centre, self.radii
        return np.stack([cx + rx * np.cos(theta), cy + ry * np.sin(theta)], axis=-1)

    def area_term(self) -> float:
        """Chord term ½(p₀ × p₁) plus the elliptic segment ½·rx·ry·(Δθ − sin Δθ).

        The segment is the affine image of a circular one; :func:`x_minus_sin`
        keeps it exact for tiny Δθ (gently rounded blades), where the usual
        ½∫(x dy − y dx) would cancel.
        """
        p0, p1 = self.point(0.0), self.point(1.0)
        rx, ry = self.radii
        return 0.5 * float(p0[0] * p1[1] - p1[0] * p0[1]) + 0.5 * rx * ry * float(x_minus_sin(self.end - self.start))

    def polyline(self, max_error: float) -> np.ndarray:
        """Points from the start (excluded end): chords within ``max_error`` of the arc.

        A chord of angle δ on a circle of radius r is at most r(1 − cos(δ/2))
        from it; the ellipse is the affine image of the unit circle, so r =
        max(rx, ry) bounds its error.
        """
        radius = max(self.radii)
        ratio = max(-1.0, 1.0 - max_error / radius) if radius > 0 else -1.0
        step = 2.0 * math.acos(ratio) if ratio > -1.0 else math.pi
        count = max(1, math.ceil(abs(self.end - self.start) / max(step, 1e-12)))
        return self.point(np.arange(count) / count)

    def piece(self, tau0: float, tau1: float) -> Arc:
        span = self.end - self.start
        return Arc(self.centre, self.radii, self.start + tau0 * span, self.start + tau1 * span)

    def transformed(self, matrix: np.ndarray) -> Arc:
        """The arc mapped by ``matrix``: a rotation (of a circular arc) or an axis scaling."""
        matrix = np.asarray(matrix, dtype=np.float64)
        centre = tuple(matrix @ np.asarray(self.centre))
        if matrix[0, 1] == 0.0 and matrix[1, 0] == 0.0:  # axis scaling
            return Arc(centre, (self.radii[0] * matrix[0, 0], self.radii[1] * matrix[1, 1]), self.start, self.end)
        if self.radii[0] != self.radii[1]:
            raise ValueError("only circular arcs may be rotated (rotate before the squeeze)")
        turn = math.atan2(matrix[1, 0], matrix[0, 0])
        return Arc(centre, self.radii, self.start + turn, self.end + turn)


Piece = Segment | Arc


@dataclass(frozen=True)
class Outline:
    """Closed counter-clockwise loops of exact pieces (usually one loop; none when empty)."""

    loops: tuple[tuple[Piece, ...], ...]

    @property
    def pieces(self) -> tuple[Piece, ...]:
        return tuple(piece for loop in self.loops for piece in loop)

    def area(self) -> float:
        """Enclosed area, exact (Green's theorem per piece)."""
        return float(sum(piece.area_term() for piece in self.pieces))

    def polylines(self, max_error: float = 1e-4) -> list[np.ndarray]:
        """One dense counter-clockwise polygon (M, 2) per loop, every chord within ``max_error``."""
        if not max_error > 0.0:
            raise ValueError(f"max_error must be positive (got {max_error!r})")
        return [np.concatenate([piece.polyline(max_error) for piece in loop]) for loop in self.loops]

    def polyline(self, max_error: float = 1e-4) -> np.ndarray:
        """The dense counter-clockwise polygon (M, 2) of a one-loop outline, chords within ``max_error``."""
        if len(self.loops) != 1:
            raise ValueError(f"the outline has {len(self.loops)} loops; use polylines()")
        return self.polylines(max_error)[0]

    def transformed(self, matrix: np.ndarray) -> Outline:
        """The outline mapped by the 2×2 ``matrix`` (a loop of straight edges all at once)."""
        matrix = np.asarray(matrix, dtype=np.float64)
        loops = []
        for loop in self.loops:
            if all(isinstance(piece, Segment) for piece in loop):
                ends = np.array([(piece.start, piece.end) for piece in loop], dtype=np.float64) @ matrix.T
                loops.append(tuple(Segment(tuple(a), tuple(b)) for a, b in ends.tolist()))
            else:
                loops.append(tuple(piece.transformed(matrix) for piece in loop))
        return Outline(tuple(loops))


def _crossings(piece: Piece, centre: np.ndarray, radius: float) -> list[float]:
    """Fractions τ in (0, 1) where ``piece`` crosses the circle (sign changes of |P(τ) − C|² − r²)."""
    def g(tau):
        offset = piece.point(tau) - centre
        return offset[..., 0] ** 2 + offset[..., 1] ** 2 - radius * radius

    if isinstance(piece, Segment):  # |a + τd|² = r²: a quadratic, solved exactly
        a = np.asarray(piece.start) - centre
        d = np.asarray(piece.end) - np.asarray(piece.start)
        qa, qb, qc = d @ d, 2.0 * a @ d, a @ a - radius * radius
        disc = qb * qb - 4.0 * qa * qc
        if qa == 0.0 or disc <= 0.0:
            return []
        root = math.sqrt(disc)
        q = -0.5 * (qb + math.copysign(root, qb))
        roots = sorted({q / qa, qc / q} if q != 0.0 else {0.0})
        return [t for t in roots if 0.0 < t < 1.0]
    taus = np.linspace(0.0, 1.0, _CROSSING_SAMPLES + 1)
    values = g(taus)
    found = []
    for i in range(_CROSSING_SAMPLES):
        if values[i] == 0.0 and 0 < i:
            found.append(float(taus[i]))
        elif values[i] * values[i + 1] < 0.0:
            from scipy.optimize import brentq  # on first use: scipy.optimize takes ~0.3 s to import

            found.append(brentq(g, taus[i], taus[i + 1], xtol=1e-15, rtol=1e-15))
    return found


def _inside_polygon(point: np.ndarray, polygon: np.ndarray) -> bool:
    """Even-odd test of one point against a closed polygon."""
    x, y = point
    xs, ys = polygon[:, 0], polygon[:, 1]
    xn, yn = np.roll(xs, -1), np.roll(ys, -1)
    crosses = (ys > y) != (yn > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        at = xs + (y - ys) * (xn - xs) / (yn - ys)
    return bool(np.sum(crosses & (x < at)) % 2)


def clip_by_circle(outline: Outline, centre, radius: float) -> Outline:
    """``outline`` ∩ the disc (``centre``, ``radius``), still exact pieces.

    The outline's pieces are split where they cross the circle and the parts
    inside are kept; from each exit the boundary follows the circle
    counter-clockwise to the nearest entry (for a non-convex outline such as
    the star this can close several loops).
    """
    centre = np.asarray(centre, dtype=np.float64)
    parts: list[tuple[Piece, bool]] = []
    for piece in outline.pieces:
        cuts = [0.0, *_crossings(piece, centre, radius), 1.0]
        for tau0, tau1 in zip(cuts[:-1], cuts[1:]):
            middle = piece.point(0.5 * (tau0 + tau1)) - centre
            parts.append((piece.piece(tau0, tau1), bool(middle @ middle <= radius * radius)))
    if all(inside for _, inside in parts):
        return outline
    circle = Arc(tuple(centre), (radius, radius), 0.0, 2.0 * math.pi)
    if not any(inside for _, inside in parts):
        probe = np.asarray(circle.point(0.0))
        polygon = np.concatenate(outline.polylines(1e-9 + 1e-9 * radius))
        return Outline(((circle,),)) if _inside_polygon(probe, polygon) else Outline(())
    # Runs of consecutive inside parts, starting just after an outside part.
    first_out = next(i for i, (_, inside) in enumerate(parts) if not inside)
    order = parts[first_out + 1:] + parts[: first_out + 1]
    runs: list[list[Piece]] = []
    current: list[Piece] = []
    for piece, inside in order:
        if inside:
            current.append(piece)
        elif current:
            runs.append(current)
            current = []
    if current:
        runs.append(current)

    def angle_of(point) -> float:
        offset = np.asarray(point) - centre
        return math.atan2(offset[1], offset[0])

    entries = [angle_of(run[0].point(0.0)) for run in runs]
    loops, used = [], set()
    for first in range(len(runs)):
        if first in used:
            continue
        loop: list[Piece] = []
        index = first
        while index not in used:
            used.add(index)
            loop.extend(runs[index])
            exit_angle = angle_of(runs[index][-1].point(1.0))
            gaps = [((entry - exit_angle) % (2.0 * math.pi), j) for j, entry in enumerate(entries)]
            gap, index = min(gaps)
            loop.append(Arc(tuple(centre), (radius, radius), exit_angle, exit_angle + gap))
        loops.append(tuple(loop))
    return Outline(tuple(loops))
