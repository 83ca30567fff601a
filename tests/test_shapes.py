"""The shape registry (design.md §3) and the exact coverage kernel (design.md §6).

Outlines are checked against the numbers of design.md's table; the coverage
kernel against independent references: shapely's polygon ∩ pixel areas and a
per-pixel numerical integral of the disc's clipped chord.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from scipy import integrate

from bokehfit.apertures import CIRCLE_RADIUS, SHADER_FAMILIES, SHAPES, STAR_INNER_RADIUS, STAR_OUTER_RADIUS, make_aperture
from bokehfit.apertures.behaviours import BEHAVIOURS
from bokehfit.kernels.exact import coverage

#: Circumradii of the unit-area outlines as design.md §3 prints them (7 decimals).
DESIGN_RADII = {"triangle": 0.8773827, "pentagon": 0.6485252, "hexagon": 0.6204032}
DESIGN_STAR_RADII = (0.7884710, 0.4315445)
DESIGN_CIRCLE_RADIUS = 0.5641896
#: design.md prints 7 decimals: half a unit of the last place.
DESIGN_DIGITS_TOL = 5e-8
#: Symmetry of each named shape, degrees (design.md §3).
SYMMETRY = {"square": 90.0, "slit": 180.0, "triangle": 120.0, "pentagon": 72.0, "hexagon": 60.0, "star": 72.0}
#: Coverage kernel against shapely's polygon ∩ pixel areas, per pixel (pixel area 1).
SHAPELY_ATOL = 1e-9
#: Coverage of the disc against scipy.integrate.quad of its clipped chord, per pixel.
QUAD_ATOL = 1e-6

#: Apertures with outlines: every named shape and a few blade counts.
POLYGON_APERTURES = [
    ("square", {}),
    ("slit", {}),
    ("slit", {"aspect": 4.0}),
    ("triangle", {}),
    ("pentagon", {}),
    ("hexagon", {}),
    ("star", {}),
    *(("ngon", {"blades": n}) for n in (3, 4, 5, 7, 12, 64)),
]
ALL_APERTURES = [("circle", {}), *POLYGON_APERTURES]


def _id(param) -> str:
    shape, kwargs = param
    return shape + "".join(f"-{k}{v:g}" for k, v in kwargs.items())


def signed_area(vertices: np.ndarray) -> float:
    """Shoelace formula: positive for a counter-clockwise outline."""
    x, y = vertices[:, 0], vertices[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def assert_same_vertex_set(a: np.ndarray, b: np.ndarray, atol: float = 1e-12, message: str = "") -> None:
    assert a.shape == b.shape, f"{message}: {len(a)} vs {len(b)} vertices"
    distance = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=-1)
    assert distance.min(axis=1).max() < atol and distance.min(axis=0).max() < atol, f"{message}:\n{a}\nvs\n{b}"


def same_vertex_set(a: np.ndarray, b: np.ndarray, atol: float = 1e-9) -> bool:
    distance = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=-1)
    return a.shape == b.shape and distance.min(axis=1).max() < atol


# --- outlines ------------------------------------------------------------------------


@pytest.mark.parametrize("angle", [0.0, 37.5, -200.0, 1234.5])
@pytest.mark.parametrize("param", POLYGON_APERTURES, ids=_id)
def test_polygon_area_is_one_and_counter_clockwise(param, angle):
    shape, kwargs = param
    vertices = make_aperture(shape, angle, **kwargs).vertices()
    assert signed_area(vertices) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("blades", range(3, 65))
def test_every_ngon_has_unit_area(blades):
    assert signed_area(make_aperture("ngon", blades=blades).vertices()) == pytest.approx(1.0, abs=1e-12)


def test_every_sampler_family_has_a_behaviour_and_a_shader_id():
    """The WGSL ``SHAPE_*`` ids are the behaviours' families, in their order; every named shape uses one."""
    assert set(SHADER_FAMILIES) == set(BEHAVIOURS)
    assert SHADER_FAMILIES == tuple(BEHAVIOURS)
    assert {spec.family for spec in SHAPES.values()} == set(BEHAVIOURS)
    assert [SHADER_FAMILIES[spec.shader_id] for spec in SHAPES.values()] == [spec.family for spec in SHAPES.values()]


def test_circle_radius_and_no_outline():
    circle = make_aperture("circle", 30.0)
    assert CIRCLE_RADIUS == pytest.approx(1.0 / math.sqrt(math.pi), rel=1e-15)
    assert CIRCLE_RADIUS == pytest.approx(DESIGN_CIRCLE_RADIUS, abs=DESIGN_DIGITS_TOL)
    assert math.pi * CIRCLE_RADIUS**2 == pytest.approx(1.0, abs=1e-15)
    assert circle.vertices() is None
    assert circle.extent() == CIRCLE_RADIUS
    assert circle.symmetry_deg is None
    assert circle.canonical_angle_deg is None


@pytest.mark.parametrize("shape", ["triangle", "pentagon", "hexagon"])
def test_named_polygon_vertex_on_plus_x_with_design_radius(shape):
    vertices = make_aperture(shape).vertices()
    n = {"triangle": 3, "pentagon": 5, "hexagon": 6}[shape]
    radius = DESIGN_RADII[shape]
    assert len(vertices) == n
    np.testing.assert_allclose(np.hypot(*vertices.T), radius, atol=DESIGN_DIGITS_TOL)
    np.testing.assert_allclose(vertices[np.argmax(vertices[:, 0])], [radius, 0.0], atol=DESIGN_DIGITS_TOL)
    assert_same_vertex_set(vertices, make_aperture("ngon", blades=n).vertices(), message=f"{shape} vs ngon {n}")


@pytest.mark.parametrize("n", [3, 4, 7, 12, 64])
def test_ngon_vertex_on_plus_x_with_formula_radius(n):
    vertices = make_aperture("ngon", blades=n).vertices()
    radius = math.sqrt(2.0 / (n * math.sin(2.0 * math.pi / n)))
    assert len(vertices) == n
    np.testing.assert_allclose(np.hypot(*vertices.T), radius, rtol=1e-14)
    assert np.min(np.hypot(vertices[:, 0] - radius, vertices[:, 1])) < 1e-14
    # Regular: all sides equal.
    sides = np.linalg.norm(vertices - np.roll(vertices, -1, axis=0), axis=1)
    np.testing.assert_allclose(sides, 2.0 * radius * math.sin(math.pi / n), rtol=1e-13)


def test_star_outline():
    vertices = make_aperture("star").vertices()
    assert len(vertices) == 10
    radii = np.hypot(*vertices.T)
    outer, inner = DESIGN_STAR_RADII
    np.testing.assert_allclose(radii[0::2], outer, atol=DESIGN_DIGITS_TOL)
    np.testing.assert_allclose(radii[1::2], inner, atol=DESIGN_DIGITS_TOL)
    assert (STAR_OUTER_RADIUS, STAR_INNER_RADIUS) == pytest.approx(DESIGN_STAR_RADII, abs=DESIGN_DIGITS_TOL)
    np.testing.assert_allclose(vertices[0], [outer, 0.0], atol=DESIGN_DIGITS_TOL)
    # Flush equilateral triangles: each outer point is as far from its two inner
    # neighbours as those are from each other (the pentagon's side).
    for k in range(0, 10, 2):
        tip, left, right = vertices[k], vertices[(k + 1) % 10], vertices[(k - 1) % 10]
        side = np.linalg.norm(left - right)
        assert np.linalg.norm(tip - left) == pytest.approx(side, rel=1e-12)
        assert np.linalg.norm(tip - right) == pytest.approx(side, rel=1e-12)


def test_square_axis_aligned_side_one():
    expected = np.array([[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]])
    assert_same_vertex_set(make_aperture("square").vertices(), expected, message="square")


def test_slit_default_aspect_and_size():
    slit = make_aperture("slit")
    assert slit.aspect == 0.3
    w, h = 0.3 / 2, (1 / 0.3) / 2
    expected = np.array([[w, h], [-w, h], [-w, -h], [w, -h]])
    assert_same_vertex_set(slit.vertices(), expected, message="slit 0.3 wide by 1/0.3 tall")


@pytest.mark.parametrize(
    "shape, kwargs, symmetry",
    [*((s, {}, d) for s, d in SYMMETRY.items()), *(("ngon", {"blades": n}, 360.0 / n) for n in (3, 4, 7, 12, 64))],
)
def test_symmetry_deg(shape, kwargs, symmetry):
    assert make_aperture(shape, **kwargs).symmetry_deg == pytest.approx(symmetry, rel=1e-15)


@pytest.mark.parametrize(
    "aperture, alike",
    [
        (make_aperture("circle"), True),
        (make_aperture("circle", rim=0.4, chromatic={"red": 0.02, "blue": -0.02}), True),  # the outline is still round
        (make_aperture("circle", squeeze=1.3), False),  # an ellipse
        (make_aperture("circle", vignetting={"radius": 1.2, "shift": -0.5}), False),  # a lemon at the frame's edge
        (make_aperture("hexagon"), False),
        (make_aperture("ngon", blades=64), False),
        (make_aperture("ngon", blades=9, roundness=1.0), False),
    ],
)
def test_turns_alike_only_the_plain_uncut_circle(aperture, alike):
    assert aperture.turns_alike is alike


@pytest.mark.parametrize("angle", [0.0, 13.0, -47.25])
@pytest.mark.parametrize("param", POLYGON_APERTURES, ids=_id)
def test_outline_invariant_under_symmetry_rotation(param, angle):
    shape, kwargs = param
    aperture = make_aperture(shape, angle, **kwargs)
    symmetry = aperture.symmetry_deg
    turned = make_aperture(shape, angle + symmetry, **kwargs).vertices()
    assert_same_vertex_set(aperture.vertices(), turned, atol=1e-12, message=f"{shape} at {angle} and {angle + symmetry}")
    # Half the symmetry turn must not map the outline onto itself (the
    # vertex-set comparison can tell shapes apart).
    half = make_aperture(shape, angle + symmetry / 2, **kwargs).vertices()
    assert not same_vertex_set(aperture.vertices(), half)


@pytest.mark.parametrize("angle", [0.0, 10.0, 45.0, -73.3, 400.0])
def test_square_at_a_is_ngon4_at_a_plus_45(angle):
    assert_same_vertex_set(
        make_aperture("square", angle).vertices(),
        make_aperture("ngon", angle + 45.0, blades=4).vertices(),
        message=f"square {angle} vs ngon 4 {angle + 45}",
    )


def test_rotation_matrix_counter_clockwise():
    np.testing.assert_allclose(make_aperture("triangle", 90.0).rotation() @ [1.0, 0.0], [0.0, 1.0], atol=1e-15)
    u = np.random.default_rng(3).random((100, 2))
    rotated, _ = make_aperture("star", 30.0).sample(u)
    c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
    upright, _ = make_aperture("star").sample(u)
    np.testing.assert_allclose(rotated, upright @ np.array([[c, s], [-s, c]]), atol=1e-15)


# --- canonical angles ----------------------------------------------------------------


@pytest.mark.parametrize("param", POLYGON_APERTURES, ids=_id)
def test_canonical_angle_in_range(param):
    shape, kwargs = param
    symmetry = make_aperture(shape, **kwargs).symmetry_deg
    for angle in (0.0, symmetry - 1e-6, symmetry, -1e-20, -1e-6, -10.0, -symmetry, -725.5, 360.0, 361.0, 737.25, 1e6 + 0.3):
        canonical = make_aperture(shape, angle, **kwargs).canonical_angle_deg
        assert 0.0 <= canonical < symmetry, f"{shape}: angle {angle} -> {canonical}, not in [0, {symmetry})"
        turns = (angle - canonical) / symmetry
        assert abs(turns - round(turns)) < 1e-9, f"{shape}: {angle} -> {canonical} is not a multiple of {symmetry} away"
    assert make_aperture(shape, symmetry - 1e-6, **kwargs).canonical_angle_deg == pytest.approx(symmetry - 1e-6, abs=1e-12)
    assert make_aperture(shape, -10.0, **kwargs).canonical_angle_deg == pytest.approx(symmetry - 10.0 % symmetry)


# --- parameter validation ------------------------------------------------------------


@pytest.mark.parametrize(
    "args, kwargs, parameter",
    [
        (("hexgon",), {}, "shape"),
        ((None,), {}, "shape"),
        (("ngon",), {}, "blades"),
        (("ngon",), {"blades": 2}, "blades"),
        (("ngon",), {"blades": 65}, "blades"),
        (("ngon",), {"blades": 3.5}, "blades"),
        (("ngon",), {"blades": True}, "blades"),
        (("triangle",), {"blades": 5}, "blades"),
        (("circle",), {"blades": 6}, "blades"),
        (("hexagon",), {"aspect": 0.5}, "aspect"),
        (("circle",), {"aspect": 2.0}, "aspect"),
        (("slit",), {"aspect": 0.0}, "aspect"),
        (("slit",), {"aspect": -1.0}, "aspect"),
        (("slit",), {"aspect": float("nan")}, "aspect"),
        (("slit",), {"aspect": 1e4}, "aspect"),
        (("hexagon", float("nan")), {}, "angle_deg"),
        (("hexagon", float("inf")), {}, "angle_deg"),
        (("square", "ten"), {}, "angle_deg"),
    ],
)
def test_make_aperture_rejects_bad_parameter(args, kwargs, parameter):
    with pytest.raises(ValueError, match=parameter):
        make_aperture(*args, **kwargs)


@pytest.mark.parametrize("blades", [float("inf"), float("nan"), "abc", 5.0, True], ids=["inf", "nan", "text", "float", "bool"])
def test_make_aperture_rejects_non_integer_blades_naming_blades(blades):
    with pytest.raises(ValueError, match="blades"):
        make_aperture("ngon", blades=blades)


def test_unknown_shape_message_lists_shapes_and_echoes_input():
    with pytest.raises(ValueError) as info:
        make_aperture("hexgon")
    message = str(info.value)
    assert "'hexgon'" in message
    assert all(name in message for name in SHAPES)


def test_matching_fixed_blades_accepted():
    assert make_aperture("triangle", blades=3).blades == 3
    assert make_aperture("square", blades=4).blades == 4
    assert make_aperture("ngon", blades=64).symmetry_deg == pytest.approx(360 / 64)


# --- exact coverage kernel -----------------------------------------------------------


def frame_size(aperture, scale: float) -> int:
    """An odd frame with at least two empty pixels around the scaled shape."""
    return 2 * math.ceil(aperture.extent() * scale) + 5


@pytest.mark.parametrize("scale", [0.6, 7.3, 40.0])
@pytest.mark.parametrize("param", ALL_APERTURES, ids=_id)
def test_coverage_sums_to_area(param, scale):
    shape, kwargs = param
    aperture = make_aperture(shape, 17.0, **kwargs)
    size = frame_size(aperture, scale)
    cells = coverage(aperture, scale, size)
    assert cells.shape == (size, size) and cells.dtype == np.float64
    assert cells.min() >= -1e-12 and cells.max() <= 1.0 + 1e-12
    assert cells.sum() == pytest.approx(scale**2, rel=1e-12, abs=1e-12)
    # Empty border: the frame really is large enough, so the sum is the whole shape.
    border = np.concatenate([cells[[0, -1], :].ravel(), cells[:, [0, -1]].ravel()])
    assert np.abs(border).max() < 1e-9, f"frame border not empty: {np.abs(border).max()}"


def pixel_boxes(size: int):
    """Shapely boxes of every pixel in the aperture frame, row 0 at the top (y up)."""
    centre = (size - 1) / 2.0
    rows, cols = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")
    x = cols - centre
    y = centre - rows
    return shapely.box(x - 0.5, y - 0.5, x + 0.5, y + 0.5)


@pytest.mark.parametrize("size_extra", [0, 1])  # odd frame: centre on a pixel centre; even: on a corner
@pytest.mark.parametrize("angle", [0.0, 11.0, 33.3, 90.0, 200.0])
@pytest.mark.parametrize(
    "shape, kwargs", [("hexagon", {}), ("star", {}), ("slit", {}), ("slit", {"aspect": 2.5}), ("triangle", {})]
)
def test_coverage_matches_shapely(shape, kwargs, angle, size_extra):
    aperture = make_aperture(shape, angle, **kwargs)
    scale = 6.7
    size = frame_size(aperture, scale) + size_extra
    polygon = shapely.Polygon(aperture.vertices() * scale)
    expected = shapely.area(shapely.intersection(polygon, pixel_boxes(size)))
    got = coverage(aperture, scale, size)
    worst = np.unravel_index(np.argmax(np.abs(got - expected)), got.shape)
    assert abs(got[worst] - expected[worst]) < SHAPELY_ATOL, (
        f"{shape} {angle}°: pixel {worst} coverage {got[worst]!r}, shapely {expected[worst]!r}"
    )


def disc_pixel_area(radius: float, x0: float, x1: float, y0: float, y1: float) -> float:
    """Area of the disc inside [x0, x1] × [y0, y1]: quad of the chord clipped to [y0, y1]."""
    a, b = max(x0, -radius), min(x1, radius)
    if a >= b:
        return 0.0

    def chord(x):
        h = math.sqrt(max(radius * radius - x * x, 0.0))
        return max(0.0, min(y1, h) - max(y0, -h))

    kinks = [s * math.sqrt(radius * radius - y * y) for y in (y0, y1) if abs(y) < radius for s in (-1.0, 1.0)]
    points = sorted(k for k in kinks if a < k < b)
    value, _ = integrate.quad(chord, a, b, points=points or None, epsabs=1e-11, epsrel=1e-11, limit=200)
    return value


@pytest.mark.parametrize("scale, size", [(0.7, 3), (0.7, 4), (5.3, 9), (9.0, 22)])
def test_circle_coverage_matches_numerical_integration(scale, size):
    radius = scale * CIRCLE_RADIUS
    got = coverage(make_aperture("circle"), scale, size)
    centre = (size - 1) / 2.0
    expected = np.zeros_like(got)
    for row in range(size):
        for col in range(size):
            x, y = col - centre, centre - row
            expected[row, col] = disc_pixel_area(radius, x - 0.5, x + 0.5, y - 0.5, y + 0.5)
    np.testing.assert_allclose(got, expected, rtol=0, atol=QUAD_ATOL)
    assert expected.sum() == pytest.approx(scale**2, abs=1e-6)


def test_coverage_y_up_row_zero_at_top():
    # Triangle at 0°: its vertex on +x reaches the right; at 90° the vertex is
    # up, i.e. towards row 0. R = 0.8774 at scale 10 reaches 8.77 px, the flat
    # side lies at R/2 = 4.39 px on the other side.
    scale, size = 10.0, 25
    centre = 12
    for angle, axis, far_side in ((0.0, 0, "right"), (90.0, 1, "top")):
        cells = coverage(make_aperture("triangle", angle), scale, size)
        occupied = np.flatnonzero(cells.sum(axis=axis) > 1e-12)
        first, last = occupied[0] - centre, occupied[-1] - centre
        if far_side == "right":  # columns: vertex at +9, flat side at −4
            assert (first, last) == (-4, 9), f"triangle 0°: columns {first}..{last} from centre"
        else:  # rows (down): vertex at −9 (top), flat side at +4
            assert (first, last) == (-9, 4), f"triangle 90°: rows {first}..{last} from centre"


@pytest.mark.parametrize("angle", [0.0, 20.0, 47.0])
@pytest.mark.parametrize("param", ALL_APERTURES, ids=_id)
def test_coverage_flip_is_180_degree_rotation(param, angle):
    shape, kwargs = param
    aperture = make_aperture(shape, angle, **kwargs)
    scale = 5.9
    for size in (frame_size(aperture, scale), frame_size(aperture, scale) + 1):
        flipped = coverage(aperture, scale, size, flip=True)
        rotated = coverage(make_aperture(shape, angle + 180.0, **kwargs), scale, size)
        np.testing.assert_allclose(flipped, rotated, rtol=0, atol=1e-12, err_msg=f"{shape} {angle}° size {size}")


def test_coverage_flip_differs_for_odd_symmetry():
    # For a triangle the 180° turn is a different kernel: the flip test above can fail.
    aperture = make_aperture("triangle", 20.0)
    assert np.abs(coverage(aperture, 5.9, 15, flip=True) - coverage(aperture, 5.9, 15)).max() > 0.1
