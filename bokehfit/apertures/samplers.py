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

import numpy as np

__all__ = [
    "CIRCLE_RADIUS",
    "STAR_INNER_RADIUS",
    "STAR_OUTER_RADIUS",
    "ngon_circumradius",
    "sample_circle",
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
    radii = np.tile([STAR_OUTER_RADIUS, STAR_INNER_RADIUS], 5)
    return _sample_radial_fan(u, radii)


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
