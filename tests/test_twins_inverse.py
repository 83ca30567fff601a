"""Densities and inverses beside the samplers: NumPy round trips and their WGSL twins.

pbrt-v4 (``util/sampling.h``) keeps each sampler, its pdf and its inverse side by
side; so do ``bokehfit/apertures/samplers.py`` and ``shaders/apertures.wgsl``.
Here every ``invert_<shape>_sample`` undoes its sampler (``invert(sample(u)) ≈ u``),
every ``<shape>_pdf`` integrates to 1, and each WGSL function of the same name and
arguments agrees with its NumPy twin on the same points.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import pytest

from bokehfit.apertures import samplers
from conftest import run_wgsl

#: NumPy round trips: |invert(sample(u)) − u| below this (float64 rounding, with margin).
ROUND_TRIP_ATOL_NUMPY = 1e-9
#: WGSL (float32) against NumPy on the same float32 points, and the WGSL round trip: u may
#: differ by this much. u.x is an angle's share of the fan, read back through atan2 and, for
#: rounded blades, the arc's sector area; u.y is a squared length. Lavapipe is off by up to
#: 2e-6 (the circle's atan); the margin is tenfold.
TWIN_ATOL_U = 2e-5
#: Points closer to the centre than this radial fraction are left out of the inverse twins:
#: there u.x is the direction of a vector of float32-rounded length, ill-conditioned.
MIN_FRACTION = 0.1
#: Pdf twins are compared on points inside up to this radial fraction ...
INSIDE_FRACTION = 0.97
#: ... and outside from this one, so that float32 rounding at the outline decides nothing.
OUTSIDE_FRACTION = 1.03
#: Side of the stratified u grid of each test (its cell centres).
GRID = 48
#: Cells a side of the grid over which the pdfs are integrated.
PDF_GRID = 801

TRIANGLE = ((0.1, -0.2), (0.9, 0.3), (-0.4, 0.7))


def _wgsl_vec(v) -> str:
    return f"vec2f({float(v[0])!r}, {float(v[1])!r})"


@dataclass(frozen=True)
class Warp:
    """A sampler with its pdf and inverse, in NumPy and as WGSL calls (templates of ``{u}`` / ``{p}``)."""

    name: str
    sample: Callable[[np.ndarray], np.ndarray]
    pdf: Callable[[np.ndarray], np.ndarray]
    invert: Callable[[np.ndarray], np.ndarray]
    wgsl_sample: str
    wgsl_pdf: str
    wgsl_invert: str
    area: float = 1.0

    def __str__(self) -> str:
        return self.name


def _triangle_warp() -> Warp:
    args = ", ".join(_wgsl_vec(v) for v in TRIANGLE)
    a, b, c = (np.array(v) for v in TRIANGLE)
    (ab_x, ab_y), (ac_x, ac_y) = b - a, c - a
    area = 0.5 * abs(ab_x * ac_y - ab_y * ac_x)
    return Warp(
        "uniform_triangle",
        lambda u: samplers.sample_uniform_triangle(u, *TRIANGLE),
        lambda p: samplers.uniform_triangle_pdf(p, *TRIANGLE),
        lambda p: samplers.invert_uniform_triangle_sample(p, *TRIANGLE),
        f"sample_uniform_triangle({{u}}, {args})",
        f"uniform_triangle_pdf({{p}}, {args})",
        f"invert_uniform_triangle_sample({{p}}, {args})",
        area,
    )


def _rounded_warp(n: int, roundness: float) -> Warp:
    args = f"{n}u, {roundness!r}"
    return Warp(
        f"rounded_ngon({n}, {roundness})",
        lambda u: samplers.sample_rounded_ngon(u, n, roundness),
        lambda p: samplers.rounded_ngon_pdf(p, n, roundness),
        lambda p: samplers.invert_rounded_ngon_sample(p, n, roundness),
        f"sample_rounded_ngon({{u}}, {args})",
        f"rounded_ngon_pdf({{p}}, {args})",
        f"invert_rounded_ngon_sample({{p}}, {args})",
    )


WARPS = [
    _triangle_warp(),
    Warp("circle", samplers.sample_circle, samplers.circle_pdf, samplers.invert_circle_sample,
         "sample_circle({u})", "circle_pdf({p})", "invert_circle_sample({p})"),
    Warp("star", samplers.sample_star, samplers.star_pdf, samplers.invert_star_sample,
         "sample_star({u})", "star_pdf({p})", "invert_star_sample({p})"),
    _rounded_warp(6, 0.0),
    _rounded_warp(5, 0.5),
    _rounded_warp(3, 1.0),
    _rounded_warp(9, 0.2),
]


def _grid_u(low: float = 0.0, high: float = 1.0) -> np.ndarray:
    """Cell centres of a GRID × GRID grid over [0, 1) × [low, high)."""
    centres = (np.arange(GRID) + 0.5) / GRID
    u0, u1 = np.meshgrid(centres, low + (high - low) * centres, indexing="ij")
    return np.stack([u0, u1], axis=-1).reshape(-1, 2)


def _u_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a − b| per component, u.x taken on the circle (the fans' +x edge is both 0 and 1)."""
    d = np.abs(np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64))
    d[..., 0] = np.minimum(d[..., 0], 1.0 - d[..., 0])
    return d


@pytest.mark.parametrize("warp", WARPS, ids=str)
def test_numpy_round_trip(warp):
    u = np.random.default_rng(5).random((20_000, 2))
    u = u[u[:, 1] > 1e-6]  # the centre has no direction
    assert np.max(_u_distance(warp.invert(warp.sample(u)), u)) < ROUND_TRIP_ATOL_NUMPY


@pytest.mark.parametrize("warp", WARPS, ids=str)
def test_numpy_pdf_integrates_to_one(warp):
    points = warp.sample(np.random.default_rng(6).random((4000, 2)))
    extent = 1.05 * np.max(np.abs(points))
    centres = (np.arange(PDF_GRID) + 0.5) / PDF_GRID * 2.0 * extent - extent
    x, y = np.meshgrid(centres, centres)
    integral = warp.pdf(np.stack([x, y], axis=-1)).sum() * (2.0 * extent / PDF_GRID) ** 2
    assert integral == pytest.approx(1.0, abs=0.01)
    assert np.all(warp.pdf(points) == pytest.approx(1.0 / warp.area))


def test_numpy_inverses_send_the_centre_to_the_middle_of_u():
    assert samplers.invert_circle_sample(np.zeros(2)).tolist() == [0.5, 0.5]
    assert samplers.invert_star_sample(np.zeros(2))[1] == 0.0


@pytest.mark.parametrize("warp", WARPS, ids=str)
def test_wgsl_inverse_matches_numpy_twin(warp, gpu):
    p = warp.sample(_grid_u(MIN_FRACTION**2, 1.0)).astype(np.float32)
    got = run_wgsl(gpu, warp.wgsl_invert.format(p="p"), p, "vec2f", "vec2f", name="p")
    expected = warp.invert(p.astype(np.float64))
    assert np.max(_u_distance(got, expected)) < TWIN_ATOL_U


@pytest.mark.parametrize("warp", WARPS, ids=str)
def test_wgsl_round_trip(warp, gpu):
    u = _grid_u(MIN_FRACTION**2, 1.0).astype(np.float32)
    expr = warp.wgsl_invert.format(p=warp.wgsl_sample.format(u="u"))
    got = run_wgsl(gpu, expr, u, "vec2f", "vec2f", name="u")
    assert np.max(_u_distance(got, u)) < TWIN_ATOL_U


@pytest.mark.parametrize("warp", WARPS, ids=str)
def test_wgsl_pdf_matches_numpy_twin(warp, gpu):
    inside = warp.sample(_grid_u(0.0, INSIDE_FRACTION**2))
    rim = warp.sample(_grid_u(0.999, 1.0))
    outside = rim * (OUTSIDE_FRACTION / np.sqrt(0.999 + 0.001 * 0.5 / GRID))  # beyond the outline
    points = np.concatenate([inside, outside]).astype(np.float32)
    got = run_wgsl(gpu, warp.wgsl_pdf.format(p="p"), points, "vec2f", "f32", name="p")
    expected = warp.pdf(points.astype(np.float64))
    assert np.count_nonzero(expected) == len(inside)
    np.testing.assert_allclose(got, expected, rtol=1e-6)


@pytest.mark.parametrize(
    "shape, features",
    [("circle", {}), ("circle", {"rim": 0.7, "squeeze": 1.4}), ("star", {}), ("star", {"rim": -0.5})],
    ids=["circle", "circle-rim-squeeze", "star", "star-rim"],
)
def test_aperture_invert_undoes_sample_for_circle_and_star(shape, features):
    from bokehfit.apertures import make_aperture

    aperture = make_aperture(shape, 23.0, **features)
    u = np.random.default_rng(8).random((20_000, 2))
    u = u[u[:, 1] > 1e-6]  # the centre has no direction
    points, _ = aperture.sample(u)
    assert np.max(_u_distance(aperture.invert(points), u)) < 1e-9
