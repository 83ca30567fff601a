"""Aperture samplers: NumPy twins against WGSL, containment, uniformity (design.md §3, §5).

Every sampler is checked the way pbrt's ``sampling_test.cpp`` and Mitsuba's
``chi2.py`` check warps: the WGSL function and its NumPy twin agree on the
same ``u`` to float32 precision, no sample leaves the shape, and a chi-square
test on an odd grid finds the density uniform over the area.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pytest
import shapely

from bokehfit.apertures import (
    CIRCLE_RADIUS,
    SHAPES,
    invert_uniform_triangle_sample,
    make_aperture,
    ngon_circumradius,
    sample_circle,
    sample_hexagon,
    sample_ngon,
    sample_pentagon,
    sample_slit,
    sample_square,
    sample_star,
    sample_triangle,
    sample_uniform_triangle,
    uniform_triangle_pdf,
)
from bokehfit.kernels.exact import coverage
from chi2 import GRID, N_CHI2, SIGNIFICANCE, Chi2Result, pearson_chi2

#: The bounding box is widened by this fraction of its size on each side, so
#: the outline's extreme edges lie inside cells, not on the grid's border.
BOX_PADDING = 0.02
#: WGSL (float32) against NumPy (float64 on the same float32 u): points may
#: differ by this many times the shape's extent (its largest radius). Float32
#: rounding of √, sin and cos gives a few 1e-7 on lavapipe.
TWIN_RTOL = 2e-6
#: NumPy samples may lie outside the exact polygon by this times the extent.
INSIDE_RTOL_NUMPY = 1e-12
#: Largest float32 below 1, the top of u's range (design.md §5).
U_MAX = 1.0 - 2.0**-24


@dataclass(frozen=True)
class Case:
    """One sampler: its WGSL call, NumPy twin and the aperture it samples."""

    id: str
    wgsl: str
    numpy: Callable[[np.ndarray], np.ndarray]
    aperture_args: tuple[str, dict]
    given_polygon: object = None  #: compare with this polygon instead of the aperture's

    @property
    def aperture(self):
        shape, kwargs = self.aperture_args
        return make_aperture(shape, **kwargs)

    @property
    def polygon(self):
        if self.given_polygon is not None:
            return self.given_polygon
        vertices = self.aperture.vertices()
        return None if vertices is None else shapely.Polygon(vertices)

    @property
    def extent(self) -> float:
        return self.aperture.extent()


def _slit(aspect: float) -> Case:
    return Case(f"slit-{aspect:g}", f"sample_slit(u, {aspect!r})", lambda u: sample_slit(u, aspect), ("slit", {"aspect": aspect}))


def _ngon(n: int) -> Case:
    return Case(f"ngon-{n}", f"sample_ngon(u, {n}u)", lambda u: sample_ngon(u, n), ("ngon", {"blades": n}))


CASES = [
    Case("circle", "sample_circle(u)", sample_circle, ("circle", {})),
    Case("square", "sample_square(u)", sample_square, ("square", {})),
    _slit(0.3),
    _slit(0.01),
    _slit(100.0),
    Case("triangle", "sample_triangle(u)", sample_triangle, ("triangle", {})),
    Case("pentagon", "sample_pentagon(u)", sample_pentagon, ("pentagon", {})),
    Case("hexagon", "sample_hexagon(u)", sample_hexagon, ("hexagon", {})),
    Case("star", "sample_star(u)", sample_star, ("star", {})),
    *(_ngon(n) for n in (3, 4, 7, 12, 64)),
]
CASE_IDS = [case.id for case in CASES]


def twin_inputs() -> np.ndarray:
    """Float32 u: a stratified 64 × 64 grid, fixed-seed random points, and the edges 0, ½, 1 − 2⁻²⁴."""
    m = 64
    cells = np.stack(np.meshgrid(np.arange(m), np.arange(m), indexing="ij"), axis=-1).reshape(-1, 2)
    grid = (cells + 0.5) / m
    random = np.random.default_rng(12345).random((4096, 2))
    edge_values = [0.0, 2.0**-24, 0.25, 0.5, 0.75, U_MAX]
    edges = np.array([[a, b] for a in edge_values for b in edge_values])
    return np.concatenate([grid, random, edges]).astype(np.float32)


def assert_inside(case: Case, points: np.ndarray, tolerance: float, where: str) -> None:
    """No point of ``points`` lies farther than ``tolerance`` outside the case's shape."""
    assert np.all(np.isfinite(points)), f"{where}: non-finite sample"
    x, y = points[:, 0].astype(np.float64), points[:, 1].astype(np.float64)
    if case.polygon is None:
        excess = np.hypot(x, y) - CIRCLE_RADIUS
        worst = int(np.argmax(excess))
        assert excess[worst] <= tolerance, (
            f"{where}: point {points[worst]} lies {excess[worst]:.3e} outside the disc of radius 1/√π"
        )
        return
    outside = ~shapely.intersects_xy(case.polygon, x, y)
    if not outside.any():
        return
    distance = shapely.distance(case.polygon, shapely.points(x[outside], y[outside]))
    worst = int(np.argmax(distance))
    assert distance[worst] <= tolerance, (
        f"{where}: {int(np.sum(distance > tolerance))} points outside; worst "
        f"{points[outside][worst]} is {distance[worst]:.3e} outside {case.id}"
    )


# --- NumPy against WGSL --------------------------------------------------------------


@pytest.mark.gpu
@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_wgsl_sampler_matches_numpy_twin(case, gpu, run_wgsl_sampler):
    u = twin_inputs()
    got = run_wgsl_sampler(gpu, case.wgsl, u)
    expected = case.numpy(u.astype(np.float64))
    tolerance = TWIN_RTOL * case.extent
    difference = np.max(np.abs(got - expected), axis=1)
    worst = int(np.argmax(difference))
    assert difference[worst] <= tolerance, (
        f"{case.wgsl}: WGSL {got[worst]} vs NumPy {expected[worst]} at u = {u[worst]} "
        f"(difference {difference[worst]:.3e} > {tolerance:.3e})"
    )
    assert_inside(case, got, tolerance, f"WGSL {case.wgsl}")


@pytest.mark.gpu
# The mask samples from its CDF tables in a storage buffer: its twin test is in test_mask.py.
@pytest.mark.parametrize("shape", [name for name, spec in SHAPES.items() if not spec.tabulated])
def test_wgsl_sample_aperture_dispatch_matches_aperture_sample(shape, gpu, run_wgsl_sampler):
    # The generated SHAPE_* ids, the WGSL switch and rotate() against Aperture.sample.
    kwargs = {"blades": 9} if shape == "ngon" else {"aspect": 0.4} if shape == "slit" else {}
    aperture = make_aperture(shape, 23.0, **kwargs)
    angle = math.radians(aperture.angle_deg)
    expr = (
        f"rotate(sample_aperture({aperture.spec.shader_id}u, u, {aperture.blades or 0}u, "
        f"{float(aperture.aspect or 1.0)!r}), {math.cos(angle)!r}, {math.sin(angle)!r})"
    )
    u = twin_inputs()
    got = run_wgsl_sampler(gpu, expr, u)
    expected, _ = aperture.sample(u.astype(np.float64))
    np.testing.assert_allclose(got, expected, rtol=0, atol=TWIN_RTOL * aperture.extent(), err_msg=f"{shape}: {expr}")


# --- containment and shape ------------------------------------------------------------


@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_numpy_samples_inside_shape(case):
    u = np.concatenate([twin_inputs().astype(np.float64), np.random.default_rng(99).random((50_000, 2))])
    points = case.numpy(u)
    assert points.shape == u.shape
    assert_inside(case, points, INSIDE_RTOL_NUMPY * case.extent, f"NumPy {case.id}")


@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_sampler_reaches_the_outline(case):
    # u near the top of its range reaches the outline: the sampler is not
    # uniform over some smaller shape that the containment test would pass.
    u = np.stack([np.linspace(0.0, U_MAX, 4001), np.full(4001, U_MAX)], axis=-1)
    radius = np.hypot(*case.numpy(u).T)
    assert radius.max() == pytest.approx(case.extent, rel=1e-6)


def test_sample_triangle_is_ngon_3():
    u = twin_inputs().astype(np.float64)
    np.testing.assert_array_equal(sample_triangle(u), sample_ngon(u, 3))
    np.testing.assert_array_equal(sample_pentagon(u), sample_ngon(u, 5))
    np.testing.assert_array_equal(sample_hexagon(u), sample_ngon(u, 6))


def test_sampler_rejects_u_of_wrong_shape():
    with pytest.raises(ValueError, match="u"):
        sample_ngon(np.zeros((4, 3)), 5)


# --- uniformity: chi-square on an odd grid ------------------------------------------


def _cell_edges(case: Case) -> tuple[np.ndarray, np.ndarray]:
    if case.polygon is None:
        half = CIRCLE_RADIUS * (1.0 + 2.0 * BOX_PADDING)
        edges = np.linspace(-half, half, GRID + 1)
        return edges, edges
    xmin, ymin, xmax, ymax = case.polygon.bounds
    px, py = BOX_PADDING * (xmax - xmin), BOX_PADDING * (ymax - ymin)
    return np.linspace(xmin - px, xmax + px, GRID + 1), np.linspace(ymin - py, ymax + py, GRID + 1)


def expected_fractions(case: Case, x_edges: np.ndarray, y_edges: np.ndarray) -> np.ndarray:
    """Exact area of shape ∩ cell over the shape's area, indexed [y bin, x bin] with y increasing."""
    if case.polygon is None:
        # The disc's cells from the exact coverage kernel: GRID pixels of width
        # 2·half/GRID centred on the disc; rows of `coverage` run down in y.
        pixels_per_unit = GRID / (x_edges[-1] - x_edges[0])
        cells = coverage(case.aperture, pixels_per_unit, GRID)[::-1, :]
        return cells / pixels_per_unit**2
    x0, y0 = np.meshgrid(x_edges[:-1], y_edges[:-1])
    x1, y1 = np.meshgrid(x_edges[1:], y_edges[1:])
    boxes = shapely.box(x0, y0, x1, y1)
    return shapely.area(shapely.intersection(case.polygon, boxes)) / case.polygon.area


def chi2_uniformity(points: np.ndarray, case: Case) -> Chi2Result:
    """Pearson's chi-square of the samples' histogram against the exact areas."""
    x_edges, y_edges = _cell_edges(case)
    observed, _, _ = np.histogram2d(points[:, 1], points[:, 0], bins=[y_edges, x_edges])
    expected = len(points) * expected_fractions(case, x_edges, y_edges)
    return pearson_chi2(observed, expected, case.id)


def test_expected_fractions_sum_to_one():
    # The exact cell areas cover the whole shape: the padded grid loses nothing.
    for case in CASES:
        x_edges, y_edges = _cell_edges(case)
        assert expected_fractions(case, x_edges, y_edges).sum() == pytest.approx(1.0, abs=1e-9), case.id


@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_sampler_chi2_uniform(case):
    u = np.random.default_rng(2024).random((N_CHI2, 2))
    result = chi2_uniformity(case.numpy(u), case)
    if result.p_value < SIGNIFICANCE:
        print(result.report)
    assert result.p_value >= SIGNIFICANCE, (
        f"{case.id}: chi-square {result.statistic:.1f} on {result.dof} dof, p = {result.p_value:.2e} "
        f"< {SIGNIFICANCE:g}\n{result.report}"
    )


def test_chi2_rejects_polar_hexagon_map():
    # The polar map p = R(θ)·√u₁·(cos θ, sin θ), θ = 2πu₀, stays inside the
    # hexagon but is not uniform (design.md §3 forbids it): the test must see it.
    case = next(c for c in CASES if c.id == "hexagon")
    u = np.random.default_rng(2024).random((N_CHI2, 2))
    theta = 2.0 * np.pi * u[:, 0]
    sector = np.pi / 3.0
    boundary = ngon_circumradius(6) * math.cos(sector / 2) / np.cos((theta % sector) - sector / 2)
    points = (boundary * np.sqrt(u[:, 1]))[:, None] * np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    assert_inside(case, points, 1e-12, "polar hexagon")
    assert chi2_uniformity(points, case).p_value < SIGNIFICANCE


# --- moments ------------------------------------------------------------------------


def polygon_moments(vertices: np.ndarray) -> tuple[float, float, float, float, float]:
    """Area, centroid (x, y) and second moments ∫x², ∫y² per unit area of a counter-clockwise polygon."""
    x, y = vertices[:, 0], vertices[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = cross.sum() / 2.0
    cx = np.sum((x + xn) * cross) / (6.0 * area)
    cy = np.sum((y + yn) * cross) / (6.0 * area)
    ixx = np.sum(cross * (x * x + x * xn + xn * xn)) / 12.0
    iyy = np.sum(cross * (y * y + y * yn + yn * yn)) / 12.0
    return area, cx, cy, ixx / area, iyy / area


@pytest.mark.parametrize("case", CASES, ids=CASE_IDS)
def test_sample_moments_match_shape(case):
    u = np.random.default_rng(77).random((N_CHI2, 2))
    p = case.numpy(u)
    vertices = case.aperture.vertices()
    if vertices is None:
        exact_x2 = exact_y2 = CIRCLE_RADIUS**2 / 4.0  # ∫x² over the disc / area = r²/4
    else:
        area, cx, cy, exact_x2, exact_y2 = polygon_moments(vertices)
        assert area == pytest.approx(1.0, abs=1e-12) and abs(cx) < 1e-12 and abs(cy) < 1e-12
    n = len(p)
    for value, exact, name in (
        (p[:, 0], 0.0, "mean x"),
        (p[:, 1], 0.0, "mean y"),
        (p[:, 0] ** 2, exact_x2, "mean x²"),
        (p[:, 1] ** 2, exact_y2, "mean y²"),
    ):
        standard_error = value.std() / math.sqrt(n)
        assert abs(value.mean() - exact) < 5.0 * standard_error + 1e-15, (
            f"{case.id}: {name} {value.mean():.6g}, exact {exact:.6g} (5 standard errors {5 * standard_error:.2g})"
        )


# --- the one triangle sampler, its pdf and its inverse ------------------------------

TRIANGLE = (np.array([-0.3, -0.2]), np.array([0.9, 0.1]), np.array([0.1, 0.7]))  # scalene, counter-clockwise
TRIANGLE_AREA = 0.5 * abs((0.9 + 0.3) * (0.7 + 0.2) - (0.1 + 0.2) * (0.1 + 0.3))


def test_uniform_triangle_round_trip():
    u = np.random.default_rng(5).random((100_000, 2))
    u = np.concatenate([u, [[0.0, 0.5], [0.5, U_MAX], [U_MAX, U_MAX], [0.25, 1e-6]]])
    p = sample_uniform_triangle(u, *TRIANGLE)
    back = invert_uniform_triangle_sample(p, *TRIANGLE)
    np.testing.assert_allclose(back, u, rtol=0, atol=1e-9)


def test_uniform_triangle_vertices_and_apex():
    a, b, c = TRIANGLE
    corners = sample_uniform_triangle(np.array([[0.3, 0.0], [0.0, 1.0], [1.0, 1.0]]), a, b, c)
    np.testing.assert_allclose(corners, [a, b, c], atol=1e-15)
    np.testing.assert_allclose(invert_uniform_triangle_sample(a, a, b, c), [0.0, 0.0], atol=1e-15)


def test_uniform_triangle_pdf_integrates_to_one():
    # Monte Carlo over the bounding box [-0.3, 0.9] × [-0.2, 0.7]: ∫ pdf = box area · mean(pdf).
    low, high = np.array([-0.3, -0.2]), np.array([0.9, 0.7])
    box_area = float(np.prod(high - low))
    n = 1_000_000
    p = low + (high - low) * np.random.default_rng(11).random((n, 2))
    values = uniform_triangle_pdf(p, *TRIANGLE) * box_area
    standard_error = values.std() / math.sqrt(n)
    assert values.mean() == pytest.approx(1.0, abs=5.0 * standard_error)


def test_uniform_triangle_pdf_values():
    u = np.random.default_rng(6).random((1000, 2))
    inside = sample_uniform_triangle(u, *TRIANGLE)
    np.testing.assert_allclose(uniform_triangle_pdf(inside, *TRIANGLE), 1.0 / TRIANGLE_AREA, rtol=1e-12)
    outside = np.array([[-0.31, -0.2], [0.0, 0.8], [1.0, 0.0], [0.5, 0.5], [-0.3, 0.7]])
    np.testing.assert_array_equal(uniform_triangle_pdf(outside, *TRIANGLE), 0.0)


def test_uniform_triangle_chi2():
    case = Case("scalene-triangle", "", lambda u: sample_uniform_triangle(u, *TRIANGLE), ("triangle", {}),
                given_polygon=shapely.Polygon(TRIANGLE))
    points = case.numpy(np.random.default_rng(8).random((N_CHI2, 2)))
    result = chi2_uniformity(points, case)
    assert result.p_value >= SIGNIFICANCE, f"chi-square p = {result.p_value:.2e}\n{result.report}"
