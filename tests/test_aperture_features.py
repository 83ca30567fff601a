"""The real-lens aperture features of design.md §3b: geometry, samplers, WGSL twins.

Rounded blades, anamorphic squeeze, cat-eye vignetting, the rim profile and
longitudinal colour, each checked the way test_samplers.py checks the shapes:
exact unit area (against an independent shapely construction), the defaults
reproduce §3 bit for bit, NumPy and WGSL agree on the same ``u``, a chi-square
test on an odd grid finds the density equal to the (weighted) area, and the
inverse undoes the sampler.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import shapely
from shapely import affinity

from bokehfit.apertures import (
    CIRCLE_RADIUS,
    Chromatic,
    Segment,
    Vignetting,
    aperture_to_image,
    apply_squeeze,
    image_to_aperture,
    invert_rounded_ngon_sample,
    make_aperture,
    ngon_circumradius,
    rim_radius,
    rounded_ngon_pdf,
    sample_circle,
    sample_ngon,
    sample_rounded_ngon,
    sample_slit,
    sample_square,
    sample_star,
    vignetting_weight,
)
from bokehfit.errors import InputError
from bokehfit.gpu.shaders import APERTURE_PARAMS
from chi2 import GRID, N_CHI2, SIGNIFICANCE, Chi2Result, pearson_chi2

#: Midpoint-rule points per cell side for the expected counts of weighted densities.
CELL_QUADRATURE = 24
#: Chord error of the polylines standing in for exact outlines in shapely.
POLYLINE_ERROR = 1e-9
#: Points of a buffered circle per quarter turn in the independent shapely construction.
QUAD_SEGS = 2048
#: WGSL (float32) against NumPy (float64 on the same float32 u), times the extent.
TWIN_RTOL = 2e-6
#: Largest float32 below 1, the top of u's range (design.md §5).
U_MAX = 1.0 - 2.0**-24

ROUNDED = [(3, 0.3), (4, 0.8), (5, 0.05), (6, 0.5), (7, 1.0), (9, 0.7), (64, 0.2)]


def apertures_with_features():
    """(id, aperture, field position) covering every shape × feature."""
    cases = []
    for shape, kwargs in (
        ("circle", {}),
        ("square", {}),
        ("slit", {"aspect": 0.4}),
        ("triangle", {}),
        ("hexagon", {}),
        ("star", {}),
        ("ngon", {"blades": 9}),
    ):
        base = f"{shape}-{kwargs.get('blades', '')}"
        if shape not in ("circle", "slit", "star"):
            cases.append((f"{base}-roundness", make_aperture(shape, 11.0, roundness=0.6, **kwargs), None))
        cases.append((f"{base}-squeeze", make_aperture(shape, 11.0, squeeze=1.8, **kwargs), None))
        cases.append((f"{base}-rim", make_aperture(shape, 11.0, rim=0.7, **kwargs), None))
        cases.append((f"{base}-vignetting", make_aperture(shape, 11.0, vignetting=Vignetting(1.1, 0.9), **kwargs), (0.6, -0.5)))
        cases.append((f"{base}-chromatic", make_aperture(shape, 11.0, chromatic=Chromatic(0.03, -0.02), **kwargs), None))
    cases.append(("hexagon-all", make_aperture("hexagon", 25.0, roundness=0.4, squeeze=1.4, rim=-0.6,
                                               vignetting={"radius": 1.2, "shift": 1.0}), (-0.7, 0.4)))
    return cases


CASES = apertures_with_features()
CASE_IDS = [case[0] for case in CASES]


def _polygon(aperture, field_position=None):
    loops = aperture.outline(field_position).polylines(POLYLINE_ERROR)
    return shapely.union_all([shapely.Polygon(loop) for loop in loops])


def _independent_shape(aperture):
    """The unclipped aperture built in shapely from design.md's words, not from the Outline code."""
    family = aperture.spec.family
    if family == "circle":
        shape = shapely.Point(0.0, 0.0).buffer(CIRCLE_RADIUS, quad_segs=QUAD_SEGS)
    elif aperture.roundness > 0.0:
        # The intersection of the n discs whose circles carry the blade arcs: each arc
        # (radius ρ = R/roundness) runs through two neighbouring vertices and bulges out.
        n, turn = (aperture.blades, 0.0) if family == "ngon" else (4, 45.0)
        radius = aperture.replace(squeeze=1.0).extent()  # the circumradius
        rho = radius / aperture.roundness
        angles = 2.0 * np.pi * np.arange(n) / n
        vertices = radius * np.stack([np.cos(angles), np.sin(angles)], axis=-1)
        shape = None
        for k in range(n):
            a, b = vertices[k], vertices[(k + 1) % n]
            middle, half = 0.5 * (a + b), 0.5 * np.linalg.norm(b - a)
            outward = middle / np.linalg.norm(middle)
            centre = middle - outward * math.sqrt(rho * rho - half * half)
            disc = shapely.Point(*centre).buffer(rho, quad_segs=QUAD_SEGS)
            shape = disc if shape is None else shape.intersection(disc)
        shape = affinity.rotate(shape, turn, origin=(0, 0))
    else:
        shape = shapely.Polygon(make_aperture(aperture.shape, blades=aperture.blades if family == "ngon" else None,
                                              aspect=aperture.aspect).vertices())
    shape = affinity.rotate(shape, aperture.angle_deg, origin=(0, 0))
    root = math.sqrt(aperture.squeeze)
    return affinity.scale(shape, 1.0 / root, root, origin=(0, 0))


def _barrel(aperture, q):
    centre = aperture.vignetting.shift * CIRCLE_RADIUS * np.asarray(q)
    return shapely.Point(*centre).buffer(aperture.vignetting.radius * CIRCLE_RADIUS, quad_segs=QUAD_SEGS)


# --- geometry: unit area, independent areas -------------------------------------------------


@pytest.mark.parametrize("case_id,aperture,q", CASES, ids=CASE_IDS)
def test_outline_area_is_one_and_matches_shapely(case_id, aperture, q):
    assert aperture.area() == pytest.approx(1.0, abs=1e-12), case_id
    independent = _independent_shape(aperture)
    assert independent.area == pytest.approx(1.0, abs=2e-6), case_id
    assert _polygon(aperture).symmetric_difference(independent).area < 1e-5, case_id
    if q is not None:
        clipped = aperture.area(q)
        expected = independent.intersection(_barrel(aperture, q)).area
        assert clipped < 1.0 and clipped == pytest.approx(expected, abs=2e-6), case_id


@pytest.mark.parametrize("case_id,aperture,q", CASES, ids=CASE_IDS)
def test_monte_carlo_area_of_the_sampler(case_id, aperture, q):
    # The mean weight is the light that passes: 1, or the clipped area with vignetting.
    u = np.random.default_rng(31).random((100_000, 2))
    points, weights = aperture.sample(u, field_position=q)
    expected, quadrature_error = aperture.area(q), 1e-15
    if aperture.rim != 0.0 and q is not None:  # the light that passes: ∫ pdf over the clipped outline
        half = aperture.extent() * 1.01
        m = 801
        axis = (np.arange(m) + 0.5) / m * 2 * half - half
        grid = np.stack(np.meshgrid(axis, axis), axis=-1).reshape(-1, 2)
        barrel = vignetting_weight(grid, q, aperture.vignetting.radius, aperture.vignetting.shift)
        expected, quadrature_error = float((aperture.pdf(grid) * barrel).sum() * (2 * half / m) ** 2), 4e-3
    standard_error = max(weights.std(), 1e-12) / math.sqrt(len(weights))
    assert abs(weights.mean() - expected) < 5.0 * standard_error + quadrature_error, case_id


@pytest.mark.parametrize("case_id,aperture,q", CASES, ids=CASE_IDS)
def test_no_sample_outside_the_outline(case_id, aperture, q):
    u = np.concatenate([np.random.default_rng(4).random((20_000, 2)), [[0.0, U_MAX], [U_MAX, U_MAX], [0.5, U_MAX]]])
    for channel in (None, "red", "blue"):
        points, weights = aperture.sample(u, field_position=q, channel=channel)
        scale = aperture._channel_scale(channel)
        polygon = _polygon(aperture, q)
        kept = points[weights > 0] / scale
        outside = ~shapely.intersects_xy(polygon, kept[:, 0], kept[:, 1])
        if outside.any():
            distance = shapely.distance(polygon, shapely.points(kept[outside]))
            assert distance.max() <= 2 * POLYLINE_ERROR + 1e-12, f"{case_id} {channel}: {distance.max():.2e} outside"


def test_polyline_chord_error_is_as_stated():
    outline = make_aperture("pentagon", 7.0, roundness=0.5, squeeze=1.5).outline()
    for max_error in (1e-2, 1e-4):
        polygon = shapely.Polygon(outline.polyline(max_error))
        fine = _polygon(make_aperture("pentagon", 7.0, roundness=0.5, squeeze=1.5))
        assert shapely.hausdorff_distance(polygon, fine) <= max_error * 1.01
        assert shapely.Polygon(outline.polyline(max_error)).exterior.is_ccw


# --- roundness --------------------------------------------------------------------------------


@pytest.mark.parametrize("shape,blades", [("triangle", None), ("square", None), ("pentagon", None), ("hexagon", None), ("ngon", 9)])
def test_roundness_zero_is_todays_polygon_bit_for_bit(shape, blades):
    u = np.random.default_rng(8).random((5000, 2))
    rounded = make_aperture(shape, 33.0, blades=blades, roundness=0.0)
    points, weights = rounded.sample(u)
    sampler = sample_square if shape == "square" else (lambda v: sample_ngon(v, rounded.blades))
    np.testing.assert_array_equal(points, sampler(u) @ rounded.rotation().T)
    np.testing.assert_array_equal(weights, 1.0)
    assert all(isinstance(piece, Segment) for piece in rounded.outline().pieces)


@pytest.mark.parametrize("shape,kwargs,sampler", [
    ("circle", {}, sample_circle),
    ("square", {}, sample_square),
    ("slit", {"aspect": 0.3}, lambda u: sample_slit(u, 0.3)),
    ("star", {}, sample_star),
    ("ngon", {"blades": 11}, lambda u: sample_ngon(u, 11)),
])
def test_defaults_reproduce_todays_samplers_bit_for_bit(shape, kwargs, sampler):
    u = np.random.default_rng(10).random((5000, 2))
    aperture = make_aperture(shape, 71.0, **kwargs)
    for q in (None, (0.9, -0.3)):
        points, weights = aperture.sample(u, field_position=q, channel="red")
        np.testing.assert_array_equal(points, sampler(u) @ aperture.rotation().T)
        np.testing.assert_array_equal(weights, 1.0)


def test_sample_rounded_ngon_at_roundness_zero_is_sample_ngon():
    u = np.random.default_rng(9).random((5000, 2))
    for n in (3, 5, 8):
        np.testing.assert_array_equal(sample_rounded_ngon(u, n, 0.0), sample_ngon(u, n))


@pytest.mark.parametrize("shape,blades", [("triangle", None), ("square", None), ("hexagon", None), ("ngon", 7), ("ngon", 64)])
def test_roundness_one_is_the_circle(shape, blades):
    aperture = make_aperture(shape, 19.0, blades=blades, roundness=1.0)
    for piece in aperture.outline().pieces:
        np.testing.assert_allclose(piece.centre, [0.0, 0.0], atol=1e-15)
        np.testing.assert_allclose(piece.radii, [CIRCLE_RADIUS, CIRCLE_RADIUS], rtol=1e-15)
    assert sum(piece.end - piece.start for piece in aperture.outline().pieces) == pytest.approx(2 * math.pi, rel=1e-15)
    points, _ = aperture.sample(np.random.default_rng(2).random((20_000, 2)))
    assert np.hypot(*points.T).max() <= CIRCLE_RADIUS * (1 + 1e-12)


def test_roundness_grows_the_area_at_fixed_circumradius():
    # Unit area: rounder blades bulge, so the circumradius shrinks monotonically to 1/√π.
    radii = [make_aperture("pentagon", roundness=r).extent() for r in np.linspace(0.0, 1.0, 11)]
    assert radii[0] == pytest.approx(ngon_circumradius(5), rel=1e-15)
    assert all(a > b for a, b in zip(radii, radii[1:])) and radii[-1] == pytest.approx(CIRCLE_RADIUS, rel=1e-15)


@pytest.mark.parametrize("n,roundness", ROUNDED)
def test_rounded_ngon_round_trip_and_pdf(n, roundness):
    u = np.concatenate([np.random.default_rng(n).random((50_000, 2)), [[0.0, 0.5], [U_MAX, 0.25], [0.5, U_MAX]]])
    p = sample_rounded_ngon(u, n, roundness)
    np.testing.assert_allclose(invert_rounded_ngon_sample(p, n, roundness), u, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(rounded_ngon_pdf(p, n, roundness), 1.0)
    assert rounded_ngon_pdf(p * 1.001 + 1e-3 * np.sign(p), n, roundness)[np.hypot(*p.T) > 0.999 * make_aperture(
        "ngon", blades=n, roundness=roundness).extent()].sum() == 0.0


@pytest.mark.parametrize(
    "kwargs",
    [
        {"shape": "hexagon", "roundness": 0.4, "rim": 0.6},
        {"shape": "square", "roundness": 0.7, "squeeze": 1.6},
        {"shape": "square", "rim": -0.5},
        {"shape": "slit", "aspect": 0.3, "rim": 0.9},
        {"shape": "ngon", "blades": 7, "chromatic": {"red": 0.04, "blue": -0.03}},
    ],
    ids=lambda k: "-".join(f"{v}" for v in k.values()),
)
def test_aperture_invert_undoes_sample(kwargs):
    kwargs = dict(kwargs)
    aperture = make_aperture(kwargs.pop("shape"), 41.0, **kwargs)
    u = np.random.default_rng(3).random((20_000, 2))
    for channel in (None, "red"):
        points, _ = aperture.sample(u, channel=channel)
        np.testing.assert_allclose(aperture.invert(points, channel=channel), u, rtol=0, atol=1e-11)


# --- near and far, squeeze, rim, vignetting -----------------------------------------------------


@pytest.mark.parametrize("shape,blades,odd", [("circle", None, False), ("square", None, False), ("slit", None, False),
                                              ("triangle", None, True), ("pentagon", None, True), ("hexagon", None, False),
                                              ("star", None, True), ("ngon", 7, True), ("ngon", 8, False)])
def test_odd_symmetry(shape, blades, odd):
    assert make_aperture(shape, blades=blades).odd_symmetry is odd


def test_near_disc_is_the_far_disc_turned_with_rim_and_colour_negated():
    far = make_aperture("pentagon", 12.0, roundness=0.3, squeeze=1.3, rim=0.4,
                        vignetting={"radius": 1.15, "shift": 0.8}, chromatic={"red": 0.02, "blue": -0.01})
    near = far.near()
    assert near.angle_deg == far.angle_deg + 180.0 and near.rim == -0.4
    assert near.chromatic == Chromatic(-0.02, 0.01) and near.squeeze == far.squeeze and near.roundness == far.roundness
    q = (0.5, 0.6)
    turned = affinity.rotate(_polygon(far, q), 180.0, origin=(0, 0))
    assert turned.symmetric_difference(_polygon(near, q)).area < 1e-8
    assert near.area(q) == pytest.approx(far.area(q), rel=1e-12) and far.area(q) < 0.95
    u = np.random.default_rng(5).random((1000, 2))
    (p_far, _), (p_near, _) = far.sample(u, q, "red"), near.sample(u, q, "red")
    assert np.all(np.hypot(*p_near.T) <= far.extent() * (1 - 0.02) * (1 + 1e-12))  # red shrinks near
    assert np.all(np.hypot(*p_far.T) <= far.extent() * 1.02 * (1 + 1e-12))
    assert near.near() == dataclasses.replace(far, angle_deg=far.angle_deg + 360.0, rim=far.rim)


@pytest.mark.parametrize("shape,blades", [("circle", None), ("hexagon", None), ("ngon", 9)])
@pytest.mark.parametrize("squeeze", [0.5, 1.33, 2.0])
def test_squeeze_keeps_unit_area_and_sets_the_aspect(shape, blades, squeeze):
    plain = make_aperture(shape, 0.0, blades=blades)
    squeezed = make_aperture(shape, 0.0, blades=blades, squeeze=squeeze)
    assert squeezed.area() == pytest.approx(1.0, abs=1e-12)
    x0, y0, x1, y1 = _polygon(plain).bounds
    sx0, sy0, sx1, sy1 = _polygon(squeezed).bounds
    aspect_plain, aspect_squeezed = (y1 - y0) / (x1 - x0), (sy1 - sy0) / (sx1 - sx0)
    assert aspect_squeezed == pytest.approx(squeeze * aspect_plain, rel=1e-8)  # > 1: taller than wide
    p = np.random.default_rng(1).random((10, 2))
    np.testing.assert_array_equal(apply_squeeze(p, 1.0), p)


@pytest.mark.parametrize("rim", [-1.0, -0.5, 0.3, 1.0])
@pytest.mark.parametrize("shape,kwargs", [("circle", {}), ("slit", {"aspect": 0.5}), ("star", {}), ("hexagon", {"roundness": 0.5})])
def test_rim_keeps_total_light_and_its_sign(rim, shape, kwargs):
    aperture = make_aperture(shape, 15.0, rim=rim, **kwargs)
    # ∫ pdf dA = 1 by the midpoint rule on a fine grid over the bounding box.
    half = aperture.extent() * 1.01
    m = 801
    axis = (np.arange(m) + 0.5) / m * 2 * half - half
    grid = np.stack(np.meshgrid(axis, axis), axis=-1).reshape(-1, 2)
    assert aperture.pdf(grid).sum() * (2 * half / m) ** 2 == pytest.approx(1.0, abs=4e-3)
    # The squared radial fraction has density (1 − rim) + 2·rim·x: mean ½ + rim/6.
    u = np.random.default_rng(12).random((N_CHI2, 2))
    points, _ = aperture.sample(u)
    fraction = aperture._radial_fraction_at_zero(points @ aperture.rotation())
    x = fraction**2
    assert abs(x.mean() - (0.5 + rim / 6.0)) < 5.0 * x.std() / math.sqrt(len(x))
    assert np.all(fraction <= 1.0 + 1e-12)


def test_rim_radius_is_stable_and_exact_at_zero():
    s = np.linspace(0.0, U_MAX, 1001)
    np.testing.assert_array_equal(rim_radius(s, 0.0), np.sqrt(s))
    for rim in (-1.0, -1e-12, 1e-12, 1.0):
        r = rim_radius(s, rim)
        np.testing.assert_allclose((1 - rim) * r**2 + rim * r**4, s, rtol=0, atol=1e-14)


def test_vignetting_area():
    aperture = make_aperture("hexagon", vignetting={"radius": 1000.0, "shift": 0.0})
    assert aperture.area((0.0, 0.0)) == pytest.approx(1.0, abs=1e-12)
    assert aperture.area((1.0, 0.0)) == pytest.approx(1.0, abs=1e-12)
    cat_eye = make_aperture("circle", vignetting={"radius": 1.0, "shift": 1.0})
    assert cat_eye.area((0.0, 0.0)) == pytest.approx(1.0, abs=1e-12)
    losses = [cat_eye.area((r, 0.0)) for r in (0.25, 0.5, 0.75, 1.0)]
    assert all(a > b for a, b in zip(losses, losses[1:])) and losses[-1] < 0.5
    # Two equal discs of radius R0 whose centres are R0 apart overlap in (2π/3 − √3/2)·R0².
    assert cat_eye.area((1.0, 0.0)) == pytest.approx((2 * math.pi / 3 - math.sqrt(3) / 2) / math.pi, rel=1e-12)
    w = vignetting_weight([[0.0, 0.0], [2 * CIRCLE_RADIUS, 0.0]], (1.0, 0.0), 1.0, 1.0)
    np.testing.assert_array_equal(w, [1.0, 1.0])


def test_vignetting_cuts_a_star_into_pieces():
    # A barrel crossing two points of the star leaves two loops; the area is still exact.
    star = make_aperture("star", 0.0, vignetting={"radius": 1.0, "shift": 1.5})
    q = (0.75 * math.cos(math.radians(36)), 0.75 * math.sin(math.radians(36)))
    outline = star.outline(q)
    expected = _independent_shape(star).intersection(_barrel(star, q)).area
    assert star.area(q) == pytest.approx(expected, abs=2e-6)
    assert len(outline.loops) == len(getattr(_independent_shape(star).intersection(_barrel(star, q)), "geoms", [0]))


# --- the model: parameters, validation, frames ---------------------------------------------------


def test_parameters_list_features_only_when_on():
    hexagon = make_aperture("hexagon", 10.0)
    assert list(hexagon.parameters) == ["angle_deg"]
    assert hexagon.parameters["angle_deg"].periodic == 60.0
    assert list(make_aperture("circle").parameters) == []
    assert list(make_aperture("slit").parameters) == ["angle_deg", "aspect"]
    on = hexagon.with_features("roundness", "rim", "vignetting", "chromatic")
    assert list(on.parameters) == ["angle_deg", "roundness", "rim", "vignetting_radius", "vignetting_shift",
                                   "chromatic_red", "chromatic_blue"]
    assert on.area((1.0, 0.0)) == pytest.approx(1.0, abs=1e-12)  # switched on at neutral values
    assert list(make_aperture("circle", squeeze=1.5).parameters) == ["squeeze"]
    fitted = on.replace(roundness=0.5, vignetting_shift=0.7, chromatic_red=0.01)
    assert (fitted.roundness, fitted.vignetting.shift, fitted.chromatic.red) == (0.5, 0.7, 0.01)
    assert list(fitted.parameters) == list(on.parameters)
    with pytest.raises(InputError, match="roundness"):
        on.replace(roundness=1.5)
    with pytest.raises(InputError, match="roundness applies only to n-gons"):
        make_aperture("star").with_features("roundness")


@pytest.mark.parametrize(
    "shape,kwargs,match",
    [
        ("circle", {"roundness": 0.5}, "roundness applies only to n-gons"),
        ("slit", {"roundness": 0.5}, "roundness applies only to n-gons"),
        ("star", {"roundness": 0.1}, "roundness applies only to n-gons"),
        ("hexagon", {"roundness": -0.1}, r"roundness must be a finite number in \[0, 1\]"),
        ("hexagon", {"roundness": float("nan")}, "roundness must be"),
        ("hexagon", {"squeeze": 0.0}, "squeeze must be"),
        ("hexagon", {"rim": 1.5}, r"rim must be a finite number in \[-1, 1\]"),
        ("hexagon", {"vignetting": {"radius": 0.5}}, r"vignetting.radius must be a finite number in \[1, 1000\]"),
        ("hexagon", {"vignetting": 1.2}, "vignetting must be a Vignetting or a mapping"),
        ("hexagon", {"chromatic": {"red": 0.9, "blue": 0.0}}, "chromatic.red must be"),
        ("hexagon", {"chromatic": {"red": 0.01}}, "chromatic.blue must be"),
    ],
)
def test_bad_feature_values_are_refused_with_their_name(shape, kwargs, match):
    with pytest.raises(InputError, match=match):
        make_aperture(shape, **kwargs)


def test_bad_field_position_and_channel_are_refused():
    aperture = make_aperture("hexagon", vignetting={"radius": 1.2, "shift": 1.0})
    with pytest.raises(InputError, match="field_position"):
        aperture.area((1.0, 2.0, 3.0))
    with pytest.raises(InputError, match="field_position"):
        aperture.sample(np.zeros((2, 2)), field_position=(math.inf, 0.0))
    with pytest.raises(InputError, match="channel must be one of green, red, blue"):
        aperture.sample(np.zeros((2, 2)), channel="cyan")


def test_image_to_aperture_flips_rows_only():
    offsets = np.array([[2.0, 3.0], [-1.0, 0.5]])
    np.testing.assert_array_equal(image_to_aperture(offsets), [[3.0, -2.0], [0.5, 1.0]])
    np.testing.assert_array_equal(aperture_to_image(image_to_aperture(offsets)), offsets)


# --- chi-square: the density is the (weighted) area -------------------------------------------


def expected_fractions(aperture, edges_x, edges_y, weighted: bool) -> np.ndarray:
    """Share of the (weighted) area in each cell, [y bin, x bin]."""
    if not weighted:
        x0, y0 = np.meshgrid(edges_x[:-1], edges_y[:-1])
        x1, y1 = np.meshgrid(edges_x[1:], edges_y[1:])
        return shapely.area(shapely.intersection(_polygon(aperture), shapely.box(x0, y0, x1, y1)))
    # The exact area of each cell's part of the outline times the profile's mean over
    # the quadrature points inside it (its value at a point of the part where none is).
    x0, y0 = np.meshgrid(edges_x[:-1], edges_y[:-1])
    x1, y1 = np.meshgrid(edges_x[1:], edges_y[1:])
    parts = shapely.intersection(_polygon(aperture), shapely.box(x0, y0, x1, y1))
    dx, dy = np.diff(edges_x)[0], np.diff(edges_y)[0]
    offsets = (np.arange(CELL_QUADRATURE) + 0.5) / CELL_QUADRATURE
    xs = (edges_x[:-1, None] + dx * offsets[None, :]).ravel()
    ys = (edges_y[:-1, None] + dy * offsets[None, :]).ravel()
    density = aperture.pdf(np.stack(np.meshgrid(xs, ys), axis=-1)).reshape(GRID, CELL_QUADRATURE, GRID, CELL_QUADRATURE)
    count = (density > 0).sum(axis=(1, 3))
    mean = density.sum(axis=(1, 3)) / np.maximum(count, 1)
    for i, j in zip(*np.nonzero((count == 0) & ~shapely.is_empty(parts))):
        mean[i, j] = aperture.pdf(np.array(shapely.point_on_surface(parts[i, j]).coords[0]))
    cells = shapely.area(parts) * mean
    return cells / cells.sum()


def chi2_against_area(points: np.ndarray, aperture, weighted: bool, label: str) -> Chi2Result:
    xmin, ymin, xmax, ymax = _polygon(aperture).bounds
    pad_x, pad_y = 0.02 * (xmax - xmin), 0.02 * (ymax - ymin)
    edges_x = np.linspace(xmin - pad_x, xmax + pad_x, GRID + 1)
    edges_y = np.linspace(ymin - pad_y, ymax + pad_y, GRID + 1)
    observed, _, _ = np.histogram2d(points[:, 1], points[:, 0], bins=[edges_y, edges_x])
    expected = len(points) * expected_fractions(aperture, edges_x, edges_y, weighted)
    return pearson_chi2(observed, expected, label)


CHI2_CASES = [
    *((f"rounded-{n}-{r}", ("ngon", {"blades": n, "roundness": r}), False) for n, r in ROUNDED),
    ("rounded-square", ("square", {"roundness": 0.5}), False),
    ("squeezed-pentagon", ("pentagon", {"squeeze": 1.7}), False),
    ("rim-circle", ("circle", {"rim": 0.8}), True),
    ("rim-slit", ("slit", {"aspect": 0.5, "rim": -0.7}), True),
    ("rim-star", ("star", {"rim": 0.6}), True),
    ("rim-rounded", ("hexagon", {"roundness": 0.6, "rim": -1.0, "squeeze": 0.7}), True),
]


@pytest.mark.parametrize("label,spec,weighted", CHI2_CASES, ids=[c[0] for c in CHI2_CASES])
def test_chi2_density_is_the_weighted_area(label, spec, weighted):
    shape, kwargs = spec
    aperture = make_aperture(shape, 13.0, **kwargs)
    points, _ = aperture.sample(np.random.default_rng(2024).random((N_CHI2, 2)))
    result = chi2_against_area(points, aperture, weighted, label)
    if result.p_value < SIGNIFICANCE:
        print(result.report)
    assert result.p_value >= SIGNIFICANCE, (
        f"{label}: chi-square {result.statistic:.1f} on {result.dof} dof, p = {result.p_value:.2e}\n{result.report}"
    )


def test_chi2_sees_a_rim_sampled_as_if_uniform():
    # The rim-weighted samples are not uniform: the test must reject them against the plain area.
    aperture = make_aperture("hexagon", 13.0, rim=0.5)
    points, _ = aperture.sample(np.random.default_rng(2024).random((N_CHI2, 2)))
    assert chi2_against_area(points, aperture, False, "rim as uniform").p_value < SIGNIFICANCE


# --- NumPy against WGSL ------------------------------------------------------------------------


def twin_inputs() -> np.ndarray:
    """Float32 u: a 48 × 48 stratified grid, fixed-seed points and the edges 0, ½, 1 − 2⁻²⁴."""
    m = 48
    cells = np.stack(np.meshgrid(np.arange(m), np.arange(m), indexing="ij"), axis=-1).reshape(-1, 2)
    random = np.random.default_rng(12345).random((2048, 2))
    edge_values = [0.0, 2.0**-24, 0.25, 0.5, U_MAX]
    edges = np.array([[a, b] for a in edge_values for b in edge_values])
    return np.concatenate([(cells + 0.5) / m, random, edges]).astype(np.float32)


@pytest.mark.gpu
@pytest.mark.parametrize("n,roundness", [*ROUNDED, (6, 1e-6), (5, 0.0)])
def test_wgsl_sample_rounded_ngon_matches_numpy(n, roundness, gpu, run_wgsl_sampler):
    u = twin_inputs()
    got = run_wgsl_sampler(gpu, f"sample_rounded_ngon(u, {n}u, {float(roundness)!r})", u)
    expected = sample_rounded_ngon(u.astype(np.float64), n, roundness)
    np.testing.assert_allclose(got, expected, rtol=0, atol=TWIN_RTOL * ngon_circumradius(n))


@pytest.mark.gpu
def test_wgsl_rim_squeeze_vignetting_twins(gpu, run_wgsl_sampler):
    u = twin_inputs()
    u64 = u.astype(np.float64)
    for rim in (-1.0, -0.3, 0.0, 1e-7, 0.8, 1.0):
        got = run_wgsl_sampler(gpu, f"vec2f(rim_radius(u.x, {rim!r}), 0.0)", u)[:, 0]
        np.testing.assert_allclose(got, rim_radius(u64[:, 0], rim), rtol=0, atol=2e-6, err_msg=f"rim {rim}")
    for squeeze in (0.5, 1.0, 2.0):
        got = run_wgsl_sampler(gpu, f"apply_squeeze(u - vec2f(0.5), {squeeze!r})", u)
        np.testing.assert_allclose(got, apply_squeeze(u64 - 0.5, squeeze), rtol=0, atol=1e-6)
    got = run_wgsl_sampler(gpu, "vec2f(vignetting_weight(u - vec2f(0.5), vec2f(0.7, -0.2), 1.1, 0.9), 0.0)", u)[:, 0]
    expected = vignetting_weight(u64 - 0.5, (0.7, -0.2), 1.1, 0.9)
    boundary = np.abs(np.hypot(*(u64 - 0.5 - 0.9 * CIRCLE_RADIUS * np.array([0.7, -0.2])).T) - 1.1 * CIRCLE_RADIUS) < 1e-5
    np.testing.assert_array_equal(got[~boundary], expected[~boundary])


PARAM_CASES = [
    ("circle", {}, None),
    ("square", {}, None),
    ("ngon", {"blades": 7}, None),
    ("square", {"roundness": 0.5, "rim": 0.4}, None),
    ("hexagon", {"roundness": 0.3, "squeeze": 1.5}, None),
    ("slit", {"aspect": 0.3, "rim": -0.6}, None),
    ("circle", {"rim": 0.9, "squeeze": 0.6}, None),
    ("star", {"rim": -0.4, "chromatic": {"red": 0.03, "blue": -0.02}}, None),
    ("pentagon", {"roundness": 0.8, "vignetting": {"radius": 1.05, "shift": 0.9},
                  "chromatic": {"red": 0.03, "blue": -0.02}}, (0.7, -0.3)),
]


@pytest.mark.gpu
@pytest.mark.parametrize("shape,kwargs,q", PARAM_CASES, ids=[f"{c[0]}-{'-'.join(c[1])}" for c in PARAM_CASES])
def test_wgsl_sample_aperture_params_matches_aperture_sample(shape, kwargs, q, gpu, run_wgsl_sampler):
    aperture = make_aperture(shape, 23.0, **kwargs)
    params = APERTURE_PARAMS.wgsl_value(**aperture.shader_params(q))
    u = twin_inputs()
    for channel in ("green", "red", "blue"):
        xy = run_wgsl_sampler(gpu, f"sample_aperture_params(u, {params}, CHANNEL_{channel.upper()}).xy", u)
        weight = run_wgsl_sampler(gpu, f"vec2f(sample_aperture_params(u, {params}, CHANNEL_{channel.upper()}).z, 0.0)", u)[:, 0]
        points, weights = aperture.sample(u.astype(np.float64), field_position=q, channel=channel)
        np.testing.assert_allclose(xy, points, rtol=0, atol=TWIN_RTOL * 1.1 * aperture.extent(), err_msg=f"{channel}")
        differ = weight != weights
        if differ.any():  # only float32 rounding on the barrel's circle may flip a weight
            offset = points[differ] / aperture._channel_scale(channel) - aperture.vignetting.shift * CIRCLE_RADIUS * np.asarray(q)
            assert np.abs(np.hypot(*offset.T) - aperture.vignetting.radius * CIRCLE_RADIUS).max() < 1e-5


def test_aperture_params_struct_is_generated_from_the_model():
    aperture = make_aperture("hexagon", 30.0, roundness=0.25)
    values = aperture.shader_params()
    record = np.frombuffer(APERTURE_PARAMS.pack(**values), dtype=APERTURE_PARAMS.dtype)[0]
    assert record["shape"] == aperture.spec.shader_id and record["blades"] == 6
    assert record["roundness"] == np.float32(0.25) and record["vignetting_radius"] == 0.0
    assert APERTURE_PARAMS.dtype.itemsize % 16 == 0
    assert APERTURE_PARAMS.wgsl_value(**values).startswith("ApertureParams(")
