"""Uniform-area aperture samplers: the NumPy twins of ``shaders/apertures.wgsl``.

Every ``sample_<shape>(u)`` maps uniform variates ``u`` in [0, 1)² (an array of
shape (..., 2)) to points ``p`` of the unit-area shape at angle 0 (design.md §3).
Each WGSL function of the same name does the same maths in float32; the tests
run both on the same ``u``.

Polygons are fans of equal-area triangles around the centre. The fan is chosen
with ``u[..., 0]`` and the position along the triangle's outer edge is the
fractional part of ``u[..., 0] · n``, so the map is continuous across triangles
and stratified ``u`` stays stratified on the aperture. The radial coordinate is
``√u[..., 1]``, which makes each triangle uniform (its Jacobian is linear in the
distance from the centre).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "CIRCLE_RADIUS",
    "STAR_INNER_RADIUS",
    "STAR_OUTER_RADIUS",
    "ngon_circumradius",
    "circle_pdf",
    "invert_circle_sample",
    "invert_star_sample",
    "sample_circle",
    "star_pdf",
    "sample_hexagon",
    "sample_ngon",
    "sample_pentagon",
    "sample_slit",
    "sample_square",
    "sample_star",
    "sample_triangle",
    "sample_uniform_triangle",
    "invert_uniform_triangle_sample",
    "uniform_triangle_pdf",
    "ROUNDED_NGON_NEWTON_STEPS",
    "ROUNDNESS_POLYGON",
    "RoundedNgon",
    "apply_squeeze",
    "invert_rounded_ngon_sample",
    "rim_radius",
    "rim_weight",
    "rounded_ngon_pdf",
    "sample_rounded_ngon",
    "vignetting_weight",
    "x_minus_sin",
]

#: Radius of the unit-area disc, 1/√π.
CIRCLE_RADIUS = 1.0 / math.sqrt(math.pi)


def ngon_circumradius(n: int) -> float:
    """Circumradius of the unit-area regular n-gon, √(2 / (n·sin(2π/n))).

    The n-gon is n isosceles triangles of apex angle 2π/n and legs R, each of
    area ½R²·sin(2π/n); setting their sum to 1 gives R.
    """
    return math.sqrt(2.0 / (n * math.sin(2.0 * math.pi / n)))


def _star_radii() -> tuple[float, float]:
    """Outer and inner radius of the unit-area star (design.md §3).

    The star is a regular pentagon of circumradius r with an equilateral
    triangle flush on each side. Side s = 2r·sin 36°, apothem r·cos 36°, the
    triangle's height s·√3/2, so the outer point lies at r·(cos 36° + √3·sin 36°).
    Area = pentagon (5/2)·r²·sin 72° + five triangles 5·(√3/4)·s² = 1.
    """
    s36, c36, s72 = math.sin(math.pi / 5), math.cos(math.pi / 5), math.sin(2 * math.pi / 5)
    area_per_r2 = 2.5 * s72 + 5.0 * math.sqrt(3.0) / 4.0 * (2.0 * s36) ** 2
    inner = 1.0 / math.sqrt(area_per_r2)
    return inner * (c36 + math.sqrt(3.0) * s36), inner


STAR_OUTER_RADIUS, STAR_INNER_RADIUS = _star_radii()


def _split(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u = np.asarray(u, dtype=np.float64)
    if u.shape[-1:] != (2,):
        raise ValueError(f"u must have shape (..., 2) (got {u.shape})")
    return u[..., 0], u[..., 1]


def sample_uniform_triangle(u: np.ndarray, a, b, c) -> np.ndarray:
    """Uniform point of triangle (a, b, c): √u₁ runs from a to edge bc, u₀ along it.

    Barycentric weights: (1 − √u₁, √u₁·(1 − u₀), √u₁·u₀) for (a, b, c).
    """
    u0, u1 = _split(u)
    s = np.sqrt(u1)[..., None]
    t = u0[..., None]
    a, b, c = (np.asarray(v, dtype=np.float64) for v in (a, b, c))
    return a + s * ((1.0 - t) * (b - a) + t * (c - a))


def uniform_triangle_pdf(p: np.ndarray, a, b, c) -> np.ndarray:
    """Density of :func:`sample_uniform_triangle`: 1/area inside, 0 outside."""
    bary = _barycentric(p, a, b, c)
    area = 0.5 * abs(_cross(np.subtract(b, a, dtype=float), np.subtract(c, a, dtype=float)))
    inside = np.all(bary >= -1e-12, axis=-1)
    return np.where(inside, 1.0 / area, 0.0)


def invert_uniform_triangle_sample(p: np.ndarray, a, b, c) -> np.ndarray:
    """The ``u`` that :func:`sample_uniform_triangle` maps to ``p``."""
    bary = _barycentric(p, a, b, c)
    s = 1.0 - bary[..., 0]
    safe = np.where(s > 0.0, s, 1.0)
    u0 = np.where(s > 0.0, bary[..., 2] / safe, 0.0)
    return np.stack([u0, s * s], axis=-1)


def _cross(v, w):
    return v[..., 0] * w[..., 1] - v[..., 1] * w[..., 0]


def _barycentric(p, a, b, c) -> np.ndarray:
    p, a, b, c = (np.asarray(v, dtype=np.float64) for v in (p, a, b, c))
    ab, ac, ap = b - a, c - a, p - a
    d = _cross(ab, ac)
    wb, wc = _cross(ap, ac) / d, _cross(ab, ap) / d
    return np.stack([1.0 - wb - wc, wb, wc], axis=-1)


def _sample_radial_fan(u: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Uniform point of a star-shaped polygon given as an equal-area fan.

    Vertex k sits at angle 2πk/len(radii) and distance radii[k]; every
    triangle (centre, v_k, v_k+1) must have the same area.
    """
    u0, u1 = _split(u)
    n = len(radii)
    scaled = u0 * n
    k = np.minimum(np.floor(scaled), n - 1).astype(np.int64)
    t = scaled - k
    angle0 = 2.0 * np.pi * k / n
    angle1 = 2.0 * np.pi * (k + 1) / n
    r0, r1 = radii[k], radii[(k + 1) % n]
    edge_x = (1.0 - t) * r0 * np.cos(angle0) + t * r1 * np.cos(angle1)
    edge_y = (1.0 - t) * r0 * np.sin(angle0) + t * r1 * np.sin(angle1)
    s = np.sqrt(u1)
    return np.stack([s * edge_x, s * edge_y], axis=-1)


def sample_ngon(u: np.ndarray, n: int) -> np.ndarray:
    """Unit-area regular n-gon, a vertex on +x."""
    return _sample_radial_fan(u, np.full(n, ngon_circumradius(n)))


def sample_triangle(u: np.ndarray) -> np.ndarray:
    """Unit-area equilateral triangle, a vertex on +x (ngon 3)."""
    return sample_ngon(u, 3)


def sample_pentagon(u: np.ndarray) -> np.ndarray:
    """Unit-area regular pentagon, a vertex on +x (ngon 5)."""
    return sample_ngon(u, 5)


def sample_hexagon(u: np.ndarray) -> np.ndarray:
    """Unit-area regular hexagon, a vertex on +x (ngon 6)."""
    return sample_ngon(u, 6)


def sample_star(u: np.ndarray) -> np.ndarray:
    """Unit-area five-pointed star, an outer point on +x (10-triangle fan)."""
    return _sample_radial_fan(u, _star_fan_radii())


def sample_square(u: np.ndarray) -> np.ndarray:
    """Axis-aligned unit square centred on the origin."""
    u0, u1 = _split(u)
    return np.stack([u0 - 0.5, u1 - 0.5], axis=-1)


def sample_slit(u: np.ndarray, aspect: float) -> np.ndarray:
    """Rectangle ``aspect`` wide by ``1/aspect`` tall, unit area."""
    u0, u1 = _split(u)
    return np.stack([(u0 - 0.5) * aspect, (u1 - 0.5) / aspect], axis=-1)


def sample_circle(u: np.ndarray) -> np.ndarray:
    """Unit-area disc by Shirley and Chiu's concentric map.

    The concentric map is area-preserving and keeps strata compact (the polar
    √u map stretches them near the centre). Division is guarded by the branch:
    |a| > |b| implies a ≠ 0, and b = 0 in the other branch means a = b = 0.
    """
    u0, u1 = _split(u)
    a, b = 2.0 * u0 - 1.0, 2.0 * u1 - 1.0
    use_a = np.abs(a) > np.abs(b)
    zero = (a == 0.0) & (b == 0.0)
    safe_a = np.where(use_a, a, 1.0)
    safe_b = np.where(use_a | zero, 1.0, b)
    r = np.where(use_a, a, b)
    phi = np.where(use_a, (np.pi / 4.0) * (b / safe_a), np.pi / 2.0 - (np.pi / 4.0) * (a / safe_b))
    r = np.where(zero, 0.0, r) * CIRCLE_RADIUS
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)


def circle_pdf(p: np.ndarray) -> np.ndarray:
    """Density of :func:`sample_circle`: 1 inside the unit-area disc, 0 outside."""
    p = np.asarray(p, dtype=np.float64)
    return np.where(np.hypot(p[..., 0], p[..., 1]) <= CIRCLE_RADIUS * (1.0 + 1e-12), 1.0, 0.0)


def invert_circle_sample(p: np.ndarray) -> np.ndarray:
    """The ``u`` that :func:`sample_circle` maps to ``p`` (the concentric map's inverse).

    Where |x| > |y| the map took its first branch: a = ±|p|/R with the sign of
    x and φ = atan(y/x) = (π/4)·b/a; elsewhere b = ±|p|/R with the sign of y
    and π/2 − φ = atan(x/y) = (π/4)·a/b. Divisions are guarded as in the
    sampler: |y| ≥ |x| with y = 0 means p = 0, which maps back to u = (½, ½).
    """
    p = np.asarray(p, dtype=np.float64)
    x, y = p[..., 0], p[..., 1]
    r = np.hypot(x, y) / CIRCLE_RADIUS
    use_a = np.abs(x) > np.abs(y)
    safe_x = np.where(use_a, x, 1.0)
    safe_y = np.where(use_a | (y == 0.0), 1.0, y)
    a = np.where(use_a, np.copysign(r, x), np.copysign(r, y) * np.arctan(x / safe_y) * (4.0 / np.pi))
    b = np.where(use_a, np.copysign(r, x) * np.arctan(y / safe_x) * (4.0 / np.pi), np.copysign(r, y))
    return np.stack([0.5 * (a + 1.0), 0.5 * (b + 1.0)], axis=-1)


def _invert_radial_fan(p: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ``u`` that :func:`_sample_radial_fan` maps to ``p``, and p's radial fraction.

    The ray through p meets the outer edge v_k → v_k+1 of its fan triangle at
    v_k + t·(v_k+1 − v_k), t = (v_k × p) / ((v_k − v_k+1) × p); p is the fraction
    s of that edge point, so u = ((k + t)/n, s²).
    """
    p = np.asarray(p, dtype=np.float64)
    n = len(radii)
    theta = np.mod(np.arctan2(p[..., 1], p[..., 0]), 2.0 * np.pi)
    k = np.minimum(np.floor(theta * n / (2.0 * np.pi)), n - 1).astype(np.int64)
    angle0, angle1 = 2.0 * np.pi * k / n, 2.0 * np.pi * (k + 1) / n
    v0 = radii[k][..., None] * np.stack([np.cos(angle0), np.sin(angle0)], axis=-1)
    v1 = radii[(k + 1) % n][..., None] * np.stack([np.cos(angle1), np.sin(angle1)], axis=-1)
    denominator = _cross(v0 - v1, p)
    safe = np.where(denominator != 0.0, denominator, 1.0)  # 0 only at p = 0
    t = np.clip(np.where(denominator != 0.0, _cross(v0, p) / safe, 0.0), 0.0, 1.0)
    edge = v0 + t[..., None] * (v1 - v0)
    fraction = np.sqrt(np.sum(p * p, axis=-1) / np.sum(edge * edge, axis=-1))
    u0 = (k + t) / n
    return np.stack([np.where(u0 >= 1.0, u0 - 1.0, u0), fraction * fraction], axis=-1), fraction


def _star_fan_radii() -> np.ndarray:
    return np.tile([STAR_OUTER_RADIUS, STAR_INNER_RADIUS], 5)


def star_pdf(p: np.ndarray) -> np.ndarray:
    """Density of :func:`sample_star`: 1 inside the unit-area star, 0 outside."""
    _, fraction = _invert_radial_fan(p, _star_fan_radii())
    return np.where(fraction <= 1.0 + 1e-12, 1.0, 0.0)


def invert_star_sample(p: np.ndarray) -> np.ndarray:
    """The ``u`` that :func:`sample_star` maps to ``p`` (p inside the star): the fan's inverse."""
    return _invert_radial_fan(p, _star_fan_radii())[0]


# --- rounded blades, rim profile, squeeze, vignetting (design.md §3b) -----------------

#: Safeguarded Newton steps of :func:`sample_rounded_ngon` (the WGSL twin takes the
#: same number). The sector area is nearly linear in the arc angle (it is exactly
#: linear at roundness 1), so from the linear first guess Newton converges
#: quadratically: 4 steps reach float64 rounding, 6 leave a margin.
ROUNDED_NGON_NEWTON_STEPS = 6
#: Below this roundness an edge's sagitta is under 4e-8 of the circumradius
#: (½·roundness·sin²(π/n)·R), which float32 cannot resolve: the rounded samplers
#: use the straight-edged polygon there, in both twins, so roundness 0 is
#: today's polygon bit for bit and no 1/roundness overflows float32.
ROUNDNESS_POLYGON = 1e-7
#: Below this |x|, x − sin x is evaluated by its Taylor series (cancellation).
_SERIES_BELOW = 1.0


#: The series' coefficients: x − sin x = x³ (1/3! − x²/5! + x⁴/7! − … + x¹²/15!) (the WGSL twin
#: writes them out, in the same Horner order).
_SERIES = tuple((-1) ** k / math.factorial(2 * k + 3) for k in range(7))


def x_minus_sin(x):
    """x − sin x without cancellation near 0: Taylor series for |x| < 1 (terms to x¹⁵, by Horner).

    Twice a circular segment's area over r² is ``x − sin x`` for the arc angle x.
    The truncation error below 1 is under x¹⁷/17! ≈ 3e-15 of x³/6.
    """
    x = np.asarray(x, dtype=np.float64)
    x2 = x * x
    series = _SERIES[-1]
    for coefficient in _SERIES[-2::-1]:
        series = series * x2 + coefficient
    return np.where(np.abs(x) < _SERIES_BELOW, x * x2 * series, x - np.sin(x))


@dataclass(frozen=True)
class RoundedNgon:
    """Geometry of the unit-area rounded n-gon at angle 0 (design.md §3b).

    Vertex k sits at angle 2πk/n and distance ``circumradius`` R; each edge is
    a circular arc of radius ρ = R/roundness through its two vertices, bulging
    outward. In the frame of edge k turned so that its middle lies on +x
    (``mid_angle(k)`` = 2π(k + ½)/n), the arc's centre is (``centre_offset``, 0)
    and its points are (c + ρ cos ψ, ρ sin ψ) for ψ in [−α, α].

    Notes
    -----
    With the half chord h = R sin(π/n), the apothem a = R cos(π/n) and the arc's
    half angle α = asin(h/ρ) = asin(roundness·sin(π/n)), each blade's sector
    (centre, arc) is the triangle h·a plus the circular segment ½ρ²(2α − sin 2α):

        area = n·R²·[sin(π/n)cos(π/n) + (2α − sin 2α)/(2·roundness²)] = 1,

    which gives R. At roundness 0 the segment vanishes (the polygon,
    R = √(2/(n·sin(2π/n)))); at roundness 1, α = π/n, ρ = R, c = 0 and the
    area is πR²: the circle of radius 1/√π.
    """

    n: int
    roundness: float

    @property
    def circumradius(self) -> float:
        if self.roundness < ROUNDNESS_POLYGON:
            return ngon_circumradius(self.n)
        s, c = math.sin(math.pi / self.n), math.cos(math.pi / self.n)
        segment = float(x_minus_sin(2.0 * self.half_angle)) / (2.0 * self.roundness**2)
        return 1.0 / math.sqrt(self.n * (s * c + segment))

    @property
    def half_angle(self) -> float:
        """α, half the angle of each arc seen from its centre."""
        return math.asin(self.roundness * math.sin(math.pi / self.n))

    @property
    def arc_radius(self) -> float:
        """ρ = R/roundness (inf at roundness 0)."""
        return math.inf if self.roundness == 0.0 else self.circumradius / self.roundness

    @property
    def centre_offset(self) -> float:
        """c = a − ρ cos α ≤ 0, written as R·cos(π/n) − ρ·cos α without the cancellation."""
        if self.roundness == 0.0:
            return -math.inf
        rho = self.arc_radius
        return (self.circumradius * math.cos(math.pi / self.n) + 2.0 * rho * math.sin(0.5 * self.half_angle) ** 2) - rho

    def mid_angle(self, k):
        return 2.0 * np.pi * (np.asarray(k) + 0.5) / self.n


def _arc_x(geometry: RoundedNgon, psi):
    """x of the arc point at ψ in the edge frame: c + ρ cos ψ = a + 2ρ·sin((α+ψ)/2)·sin((α−ψ)/2) (no cancellation)."""
    alpha, radius = geometry.half_angle, geometry.circumradius
    apothem = radius * math.cos(math.pi / geometry.n)
    rho = radius / geometry.roundness
    return apothem + 2.0 * rho * np.sin(0.5 * (alpha + psi)) * np.sin(0.5 * (alpha - psi))


def _arc_sector_area(geometry: RoundedNgon, psi):
    """Area between the centre, the edge's first vertex and the arc up to ψ, with its derivative.

    Triangle (0, v_start, q(ψ)) = ½(a·q_y + h·q_x) plus the circular segment
    between v_start and q(ψ), ½ρ²(2β − sin 2β), β = (ψ + α)/2. The derivative
    is ½ρ·[ρ(1 − cos α cos ψ) + a cos ψ], positive on [−α, α].
    """
    alpha, radius = geometry.half_angle, geometry.circumradius
    s, c = math.sin(math.pi / geometry.n), math.cos(math.pi / geometry.n)
    half_chord, apothem = radius * s, radius * c
    rho = radius / geometry.roundness
    qx, qy = _arc_x(geometry, psi), rho * np.sin(psi)
    area = 0.5 * (apothem * qy + half_chord * qx) + 0.5 * rho * rho * x_minus_sin(psi + alpha)
    one_minus = 2.0 * math.sin(0.5 * alpha) ** 2 + 2.0 * math.cos(alpha) * np.sin(0.5 * psi) ** 2
    slope = 0.5 * rho * (rho * one_minus + apothem * np.cos(psi))
    return area, slope, qx, qy


def sample_rounded_ngon(u: np.ndarray, n: int, roundness: float) -> np.ndarray:
    """Uniform point of the unit-area rounded n-gon at angle 0 (design.md §3b).

    ``u[..., 0]·n`` picks the blade's sector (centre, arc) and its fractional
    part t the arc point q(ψ) whose sector area is t/n, solved by
    :data:`ROUNDED_NGON_NEWTON_STEPS` safeguarded Newton steps (bisection where
    a step leaves the bracket); the point is √u₁·q (uniform over the sector, as
    for the straight fans). Continuous in ``u``. Roundness below
    :data:`ROUNDNESS_POLYGON` is :func:`sample_ngon` exactly.
    """
    if roundness < ROUNDNESS_POLYGON:
        return sample_ngon(u, n)
    u0, u1 = _split(u)
    geometry = RoundedNgon(n, roundness)
    scaled = u0 * n
    k = np.minimum(np.floor(scaled), n - 1)
    t = scaled - k
    alpha = geometry.half_angle
    target = t / n
    low, high = np.full_like(t, -alpha), np.full_like(t, alpha)
    psi = -alpha + 2.0 * alpha * t
    for _ in range(ROUNDED_NGON_NEWTON_STEPS):
        area, slope, _, _ = _arc_sector_area(geometry, psi)
        f = area - target
        high = np.where(f > 0.0, psi, high)
        low = np.where(f > 0.0, low, psi)
        step = psi - f / slope
        psi = np.where((step >= low) & (step <= high), step, 0.5 * (low + high))
    _, _, qx, qy = _arc_sector_area(geometry, psi)
    phi = geometry.mid_angle(k)
    cos_phi, sin_phi = np.cos(phi), np.sin(phi)
    s = np.sqrt(u1)
    return np.stack([s * (cos_phi * qx - sin_phi * qy), s * (sin_phi * qx + cos_phi * qy)], axis=-1)


def _rounded_ngon_polar(p: np.ndarray, n: int, roundness: float):
    """Sector k, arc angle ψ of p's direction and p's radial fraction |p|/outline distance."""
    p = np.asarray(p, dtype=np.float64)
    geometry = RoundedNgon(n, roundness)
    theta = np.mod(np.arctan2(p[..., 1], p[..., 0]), 2.0 * np.pi)
    k = np.minimum(np.floor(theta * n / (2.0 * np.pi)), n - 1)
    local = theta - geometry.mid_angle(k)  # in [−π/n, π/n]
    if roundness < ROUNDNESS_POLYGON:
        apothem = ngon_circumradius(n) * math.cos(math.pi / n)
        distance = apothem / np.cos(local)
        return k, None, np.hypot(p[..., 0], p[..., 1]) / distance
    radius, alpha = geometry.circumradius, geometry.half_angle
    rho = radius / roundness
    apothem = radius * math.cos(math.pi / n)
    plus = apothem + 2.0 * rho * math.sin(0.5 * alpha) ** 2  # ρ + c, no cancellation
    minus = 2.0 * rho - plus  # ρ − c
    # The ray t·(cos, sin) meets the arc's circle (centre (c, 0)) at
    # t = (ρ² − c²) / (√(ρ² − c² sin²) − c cos): both denominator terms positive.
    c = plus - rho
    distance = plus * minus / (np.sqrt(rho * rho - (c * np.sin(local)) ** 2) - c * np.cos(local))
    qy = distance * np.sin(local)
    psi = np.arcsin(np.clip(qy / rho, -1.0, 1.0))
    return k, psi, np.hypot(p[..., 0], p[..., 1]) / distance


def rounded_ngon_pdf(p: np.ndarray, n: int, roundness: float) -> np.ndarray:
    """Density of :func:`sample_rounded_ngon`: 1 inside the unit-area shape, 0 outside."""
    _, _, fraction = _rounded_ngon_polar(p, n, roundness)
    return np.where(fraction <= 1.0 + 1e-12, 1.0, 0.0)


def invert_rounded_ngon_sample(p: np.ndarray, n: int, roundness: float) -> np.ndarray:
    """The ``u`` that :func:`sample_rounded_ngon` maps to ``p`` (p inside the shape)."""
    k, psi, fraction = _rounded_ngon_polar(p, n, roundness)
    if psi is None:  # the straight fan: the position along the edge is linear in u₀
        theta = np.arctan2(p[..., 1], p[..., 0])
        local = np.mod(theta, 2.0 * np.pi) - 2.0 * np.pi * k / n
        # Edge from v_k to v_k+1 in the frame of v_k: tan of the angle over tan of the span.
        half = math.pi / n
        t = 0.5 * (1.0 + np.tan(local - half) / math.tan(half))
    else:
        area, _, _, _ = _arc_sector_area(RoundedNgon(n, roundness), psi)
        t = area * n
    u0 = (k + t) / n
    return np.stack([np.where(u0 >= 1.0, u0 - 1.0, u0), fraction * fraction], axis=-1)  # the +x edge wraps to 0


def rim_radius(s: np.ndarray, rim: float) -> np.ndarray:
    """Radial fraction ρ in [0, 1) importance-sampling the rim profile, from a uniform ``s``.

    Over a star-shaped aperture the squared radial fraction of a uniform point
    is uniform; weighting by w = 1 + rim·(2ρ² − 1) (design.md §3b) gives ρ the
    CDF (1 − rim)ρ² + rim·ρ⁴. With x = ρ², rim·x² + (1 − rim)·x = s is solved by
    x = 2s / ((1 − rim) + √((1 − rim)² + 4·rim·s)), stable at rim → 0 (where it
    is s, so rim 0 gives ρ = √s exactly) and at rim = ±1.
    """
    s = np.asarray(s, dtype=np.float64)
    a = 1.0 - rim
    denominator = a + np.sqrt(a * a + 4.0 * rim * s)  # 0 only at rim = 1 and s = 0, where ρ = 0
    positive = denominator > 0.0
    return np.where(positive, np.sqrt(2.0 * s / np.where(positive, denominator, 1.0)), 0.0)


def rim_weight(fraction: np.ndarray, rim: float) -> np.ndarray:
    """The rim profile w = 1 + rim·(2ρ² − 1) at radial fraction ρ; its mean over the area is 1."""
    fraction = np.asarray(fraction, dtype=np.float64)
    return 1.0 + rim * (2.0 * fraction * fraction - 1.0)


def apply_squeeze(p: np.ndarray, squeeze: float) -> np.ndarray:
    """Anamorphic squeeze at unit area: (x, y) → (x/√squeeze, y·√squeeze).

    x ← x/squeeze divides the area by squeeze; rescaling both axes by √squeeze
    restores it, so x is divided by √squeeze and y multiplied by it (the map has
    determinant 1). Squeeze 1 is the identity bit for bit.
    """
    p = np.asarray(p, dtype=np.float64)
    root = math.sqrt(squeeze)
    return np.stack([p[..., 0] / root, p[..., 1] * root], axis=-1)


def vignetting_weight(p: np.ndarray, field_position, radius: float, shift: float) -> np.ndarray:
    """1 where ``p`` is inside the barrel's circle at field position q, else 0 (design.md §3b).

    The circle has radius ``radius``·R0 and centre ``shift``·R0·q, R0 = 1/√π the
    radius of the unit-area disc. Samples of the unclipped aperture outside it
    are absorbed: the light the barrel stops.
    """
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(field_position, dtype=np.float64)
    centre = shift * CIRCLE_RADIUS * q
    offset = p - centre
    return np.where(offset[..., 0] ** 2 + offset[..., 1] ** 2 <= (radius * CIRCLE_RADIUS) ** 2, 1.0, 0.0)
