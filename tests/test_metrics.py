"""Shape similarity metrics (bokehfit.metrics) against independent computations.

IoU against shapely's exact polygon intersection and the analytic disc ∩ square;
the Hausdorff distance against its closed form for a circle and a square; the
elliptic Fourier coefficients against a numerical Fourier transform of the
outline; Hu distances against OpenCV called directly.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
import shapely

from bokehfit.apertures import CIRCLE_RADIUS, make_aperture
from bokehfit.errors import InputError
from bokehfit.metrics import (
    METRICS,
    MetricOptions,
    angle_error,
    aperture_outline,
    best_rotation_deg,
    compare_outlines,
    efd_distance,
    hausdorff_rel,
    hu_distance,
    iou,
    normalise,
)
from bokehfit.metrics.efd import efd_coefficients, normalise_efd
from bokehfit.metrics.outlines import centroid, densify, intersection_area, rotate, signed_area

#: IoU against shapely's exact polygon intersection. The brief asked for 2e-3
#: (a rasterised IoU); the scanline integration is exact up to rounding
#: (~1e-15 seen), so the tests hold it to this, which a 1024² pixel mask
#: (up to 4e-3 off on aligned slits) or the same scanlines without the
#: outlines' crossings cut (~2e-5 off on the random outlines) would fail.
IOU_SHAPELY_ATOL = 1e-9
#: An outline against itself after the best rotation.
IOU_SELF_ATOL = 1e-3
HAUSDORFF_SELF_ATOL = 1e-2
#: Same shape moved, scaled, rotated, restarted and reversed: EFD distance.
EFD_INVARIANCE_TOL = 1e-6
#: Hausdorff of the 720-point circle against the analytic value (its sides lie
#: r·(1 − cos(π/720)) ≈ 1e-5·r inside the true circle), relative.
HAUSDORFF_CIRCLE_RTOL = 1e-4
#: The best rotation against the rotation applied, degrees (the search refines to 0.01°).
ROTATION_ATOL_DEG = 0.05
#: Hu distance of the normalised float32 outlines against cv2 on the raw ones
#: (float32 rounding of the moments), relative.
HU_RAW_RTOL = 1e-4

#: Apertures to compare with themselves: every family, odd and even symmetry.
SELF_SHAPES = [("circle", {}), ("square", {}), ("slit", {}), ("triangle", {}), ("hexagon", {}), ("star", {}), ("ngon", {"blades": 7})]


def outline(shape: str, angle_deg: float = 0.0, **kwargs) -> np.ndarray:
    return aperture_outline(make_aperture(shape, angle_deg, **kwargs))


def blob(seed: int = 7, points: int = 48) -> np.ndarray:
    """An irregular star-shaped outline without symmetry (a fixed seed), counter-clockwise."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0.0, 2.0 * np.pi, points))
    r = 1.0 + 0.3 * rng.uniform(-1.0, 1.0, points)
    return np.stack([r * np.cos(t), r * np.sin(t)], axis=-1)


def shapely_iou(a: np.ndarray, b: np.ndarray) -> float:
    pa, pb = shapely.Polygon(normalise(a)), shapely.Polygon(normalise(b))
    return pa.intersection(pb).area / pa.union(pb).area


def _id(param) -> str:
    shape, kwargs = param
    return shape + "".join(f"-{k}{v:g}" for k, v in kwargs.items())


# ---------------------------------------------------------------------------
# Outlines


def test_normalise_uses_area_centroid_unit_area_and_counter_clockwise():
    # A 2 × 1 rectangle, clockwise, with 50 extra points on its right side: the
    # mean of the points is pulled right, the area centroid is not.
    right = np.stack([np.full(50, 3.0), np.linspace(1.0, 2.0, 52)[1:-1]], axis=-1)
    rect = np.concatenate([[[1.0, 1.0], [1.0, 2.0], [3.0, 2.0]], right[::-1], [[3.0, 1.0]]])
    assert signed_area(rect) < 0  # clockwise
    assert not np.allclose(rect.mean(axis=0), [2.0, 1.5], atol=0.1)
    out = normalise(rect)
    assert signed_area(out) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(centroid(out), [0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(out[0], (rect[0] - [2.0, 1.5]) / math.sqrt(2.0), atol=1e-12)  # start kept
    np.testing.assert_allclose(shapely.Polygon(out).centroid.coords[0], [0.0, 0.0], atol=1e-12)


def test_normalise_drops_closing_and_repeated_points():
    square = np.array([[0, 0], [1, 0], [1, 0], [1, 1], [0, 1], [0, 0]], dtype=float)
    assert len(normalise(square)) == 4


@pytest.mark.parametrize("param", SELF_SHAPES, ids=_id)
def test_aperture_outline_unit_area_and_points(param):
    shape, kwargs = param
    out = outline(shape, 10.0, **kwargs)
    assert abs(len(out) - 720) <= 12
    # The polygons are exact; the 720-gon circle lacks (2π²/3)/720² = 1.27e-5.
    expected = 1.0 - 2.0 * math.pi**2 / (3.0 * 720**2) if shape == "circle" else 1.0
    assert signed_area(out) == pytest.approx(expected, abs=1e-7)
    np.testing.assert_allclose(centroid(out), [0.0, 0.0], atol=1e-12)


def test_aperture_outline_is_rotated():
    vertices = make_aperture("triangle", 30.0).vertices()
    out = outline("triangle", 30.0)
    assert math.degrees(math.atan2(out[0, 1], out[0, 0])) == pytest.approx(30.0)
    assert all(np.min(np.hypot(*(out - v).T)) < 1e-12 for v in vertices)  # corners kept
    circle = aperture_outline(make_aperture("circle", 20.0), points=36)
    np.testing.assert_allclose(np.hypot(*circle.T), CIRCLE_RADIUS)
    assert math.degrees(math.atan2(circle[0, 1], circle[0, 0])) == pytest.approx(20.0)


def test_intersection_area_matches_shapely_on_aligned_rectangles():
    # Long sides parallel to the scanlines and across them: where pixel masks err most.
    a = normalise(outline("slit", aspect=0.5))
    b = normalise(outline("slit", 90.0, aspect=2.2))
    expected = shapely.Polygon(a).intersection(shapely.Polygon(b)).area
    assert intersection_area(a, b) == pytest.approx(expected, abs=1e-12)
    assert intersection_area(a, a + [10.0, 0.0]) == 0.0


# ---------------------------------------------------------------------------
# Identical shapes


@pytest.mark.parametrize("param", SELF_SHAPES, ids=_id)
def test_identical_shapes(param):
    shape, kwargs = param
    a = outline(shape, **kwargs)
    values = compare_outlines(a, a)
    assert values["iou"] == pytest.approx(1.0, abs=IOU_SELF_ATOL)
    assert values["hausdorff_rel"] == pytest.approx(0.0, abs=HAUSDORFF_SELF_ATOL)
    assert values["efd_distance"] < EFD_INVARIANCE_TOL
    assert values["hu_distance"] < 1e-6


@pytest.mark.parametrize("shape,angle_deg", [("triangle", 47.3), ("star", 23.9), ("slit", 131.0), ("blob", 201.7)])
def test_rotated_copy(shape, angle_deg):
    a = blob() if shape == "blob" else outline(shape)
    b = rotate(a, angle_deg)
    assert iou(a, b, align=True) == pytest.approx(1.0, abs=IOU_SELF_ATOL)
    assert hausdorff_rel(a, b, align=True) == pytest.approx(0.0, abs=HAUSDORFF_SELF_ATOL)
    unaligned = iou(a, b, align=False)
    assert unaligned < 0.99
    assert unaligned == pytest.approx(shapely_iou(a, b), abs=IOU_SHAPELY_ATOL)


@pytest.mark.parametrize("shape,symmetry", [("hexagon", 60.0), ("star", 72.0), ("blob", 360.0)])
def test_best_rotation_undoes_a_rotation(shape, symmetry):
    a = blob() if shape == "blob" else outline(shape)
    b = rotate(a, 123.4)
    assert angle_error(best_rotation_deg(a, b), -123.4, symmetry) < ROTATION_ATOL_DEG
    assert -180.0 <= best_rotation_deg(a, b) < 180.0


# ---------------------------------------------------------------------------
# Analytic pairs


def test_iou_circle_square_exact():
    # Unit disc (radius r = 1/√π) ∩ unit square (half side ½), both centred:
    # the disc less four circular segments beyond |x| = ½ or |y| = ½.
    r, h = CIRCLE_RADIUS, 0.5
    segment = r * r * math.acos(h / r) - h * math.sqrt(r * r - h * h)
    intersection = 1.0 - 4.0 * segment
    exact = intersection / (2.0 - intersection)
    # against the 720-gon, renormalised to unit area: its sides' sagitta
    # r·(1 − cos(π/720)) moves the IoU by ~1e-6.
    assert iou(outline("circle"), outline("square", 17.0)) == pytest.approx(exact, abs=5e-6)
    # and shapely on a 4096-gon agrees
    t = 2.0 * np.pi * np.arange(4096) / 4096
    disc = np.stack([np.cos(t), np.sin(t)], axis=-1)
    assert shapely_iou(disc, outline("square")) == pytest.approx(exact, abs=1e-6)


@pytest.mark.parametrize(
    "a,b",
    [
        (("hexagon", 0.0, {}), ("hexagon", 30.0, {})),
        (("square", 0.0, {}), ("slit", 0.0, {})),
        (("slit", 0.0, {"aspect": 0.5}), ("slit", 90.0, {"aspect": 2.2})),
        (("star", 0.0, {}), ("pentagon", 36.0, {})),
        (("circle", 0.0, {}), ("triangle", 11.0, {})),
    ],
    ids=["hexagon-30", "square-slit", "slits-aligned", "star-pentagon", "circle-triangle"],
)
def test_iou_unaligned_against_shapely(a, b):
    oa, ob = outline(a[0], a[1], **a[2]), outline(b[0], b[1], **b[2])
    assert iou(oa, ob, align=False) == pytest.approx(shapely_iou(oa, ob), abs=IOU_SHAPELY_ATOL)


def test_iou_random_outlines_against_shapely():
    rng = np.random.default_rng(20240611)
    for seed in rng.integers(0, 2**31, size=8):
        a, b = blob(int(seed)), blob(int(seed) + 1, points=31) * 2.5 + [4.0, -1.0]
        assert iou(a, b, align=False) == pytest.approx(shapely_iou(a, b), abs=IOU_SHAPELY_ATOL)


def test_hausdorff_circle_square_closed_form():
    # The square's corner (half-diagonal √2/2) is farthest from the circle; the
    # circle's farthest point from the square is only r − ½ away.
    r = CIRCLE_RADIUS
    expected = (math.sqrt(2.0) / 2.0 - r) / r
    got = hausdorff_rel(outline("circle"), outline("square", 12.0))
    assert got == pytest.approx(expected, rel=HAUSDORFF_CIRCLE_RTOL)
    assert hausdorff_rel(outline("square", 12.0), outline("circle")) == pytest.approx(expected, rel=HAUSDORFF_CIRCLE_RTOL)


def test_hausdorff_between_samples():
    # Two squares, one turned 45°: the octagram's farthest points are the
    # corners, (√2/2 − ½)/r: found exactly though neither outline is dense.
    square = np.array([[0.5, -0.5], [0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5]])
    expected = (math.sqrt(2.0) / 2.0 - 0.5) / CIRCLE_RADIUS
    assert hausdorff_rel(square, rotate(square, 45.0), align=False) == pytest.approx(expected, rel=1e-9)


#: The vectorised refinement of the Hausdorff distance against a bounded scalar
#: search per side (the way it was computed before): the same value to 5 digits.
HAUSDORFF_REFINE_RTOL = 1e-5


def _scalar_search_hausdorff(samples: np.ndarray, target: np.ndarray) -> float:
    """The reference: the directed distance refined with scipy's bounded search, one side at a time."""
    from scipy import optimize

    from bokehfit.metrics.outlines import DistanceToOutline, following

    distance_to = DistanceToOutline(target)
    distances = distance_to(samples)
    best = float(distances.max())
    count = len(samples)
    step = np.hypot(*(following(samples) - samples).T)
    for index in np.argsort(-distances)[:8]:
        for neighbour, length in (((index - 1) % count, step[index - 1]), ((index + 1) % count, step[index])):
            if distances[index] + length <= best:
                continue
            p, q = samples[index], samples[neighbour]
            result = optimize.minimize_scalar(
                lambda s: -distance_to(p + s * (q - p))[0], bounds=(0.0, 1.0), method="bounded", options={"xatol": 1e-4}
            )
            best = max(best, -float(result.fun))
    return best


@pytest.mark.parametrize(
    "a,b,samples",
    [
        pytest.param(lambda: blob(3), lambda: blob(4, points=31), 720, id="blobs"),
        pytest.param(lambda: outline("hexagon", 7.0), lambda: outline("circle"), 720, id="hexagon-circle"),
        pytest.param(lambda: outline("star", 3.0), lambda: outline("pentagon", 20.0), 720, id="star-pentagon"),
        pytest.param(lambda: blob(11, points=256), lambda: outline("pentagon", 21.0), 256, id="disc-like-256"),
        pytest.param(lambda: outline("square"), lambda: rotate(outline("square"), 30.0), 40, id="sparse-squares"),
    ],
)
def test_hausdorff_refinement_matches_scalar_search(a, b, samples):
    from bokehfit.metrics import _directed_hausdorff

    a, b = normalise(a()), normalise(b())
    for source, target in ((a, b), (b, a)):
        points = densify(source, samples)
        got = _directed_hausdorff(points, target)
        assert got == pytest.approx(_scalar_search_hausdorff(points, target), rel=HAUSDORFF_REFINE_RTOL)


def test_hausdorff_refinement_finds_the_maximum_between_samples():
    # The star's tips as the samples: each is on the star (distance 0), and the pentagon's
    # sides between them pass over the star's notches, so only the refinement finds the distance.
    from bokehfit.metrics import _directed_hausdorff
    from bokehfit.metrics.outlines import DistanceToOutline

    star = make_aperture("star", 0.0).vertices()
    radius = np.hypot(*star.T)
    tips = star[radius > radius.mean()]
    assert len(tips) == 5
    assert float(DistanceToOutline(star)(tips).max()) == pytest.approx(0.0, abs=1e-12)
    refined = _directed_hausdorff(tips, star)
    assert refined > 0.1 * radius.max()
    assert refined == pytest.approx(_scalar_search_hausdorff(tips, star), rel=HAUSDORFF_REFINE_RTOL)


def test_hexagon_closer_to_circle_than_triangle_for_every_metric():
    circle, hexagon, triangle = outline("circle"), outline("hexagon", 10.0), outline("triangle", 70.0)
    near = compare_outlines(hexagon, circle)
    far = compare_outlines(triangle, circle)
    for name, metric in METRICS.items():
        if metric.better == "higher":
            assert near[name] > far[name], name
        else:
            assert near[name] < far[name], name


# ---------------------------------------------------------------------------
# Elliptic Fourier descriptors


def test_efd_coefficients_match_numerical_fourier_series():
    # x(t), y(t) sampled at equal arc length, then a plain discrete Fourier sum.
    shape = blob(3)
    samples = 1 << 15
    dense = densify(shape, samples * 4)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*(np.roll(dense, -1, axis=0) - dense).T))])
    t = np.arange(samples) * arc[-1] / samples
    closed = np.concatenate([dense, dense[:1]])
    x, y = np.interp(t, arc, closed[:, 0]), np.interp(t, arc, closed[:, 1])
    phase = 2.0 * np.pi * np.outer(np.arange(1, 11), np.arange(samples)) / samples
    expected = np.stack(
        [2.0 / samples * np.cos(phase) @ x, 2.0 / samples * np.sin(phase) @ x, 2.0 / samples * np.cos(phase) @ y, 2.0 / samples * np.sin(phase) @ y],
        axis=1,
    )
    np.testing.assert_allclose(efd_coefficients(shape, 10), expected, atol=1e-6)


def transformed(shape: np.ndarray) -> np.ndarray:
    """Translated, scaled ×3.7, rotated 33°, started 17 points on, reversed."""
    moved = rotate(shape, 33.0) * 3.7 + [12.5, -7.25]
    return np.roll(moved, -17, axis=0)[::-1]


@pytest.mark.parametrize("name", ["blob", "hexagon", "star", "slit", "circle"])
def test_efd_invariance(name):
    shape = blob() if name == "blob" else outline(name)
    assert efd_distance(shape, transformed(shape)) < EFD_INVARIANCE_TOL
    assert efd_distance(transformed(shape), shape) < EFD_INVARIANCE_TOL


def test_efd_kuhl_giardina_normal_form():
    # A shape without symmetry has a well-defined first-harmonic ellipse: the
    # K&G normal form itself is invariant, up to their 180° ambiguity, which
    # flips the sign of the even harmonics.
    shape = normalise(blob())
    other = normalise(transformed(blob()))
    a, b = normalise_efd(efd_coefficients(shape, 12)), normalise_efd(efd_coefficients(other, 12))
    np.testing.assert_allclose(a[0, :3], [1.0, 0.0, 0.0], atol=1e-12)
    flip = np.where(np.arange(1, 13) % 2 == 0, -1.0, 1.0)[:, None]
    assert min(np.abs(a - b).max(), np.abs(a - flip * b).max()) < 1e-9


@pytest.mark.parametrize("pair", [("blob", "hexagon"), ("blob8", "blob"), ("pentagon", "hexagon"), ("star", "slit")])
def test_efd_aligned_distance_is_the_least_over_start_point_and_rotation(pair):
    """The distance after the residual start point τ and rotation ψ are resolved is the least over
    them: against a brute-force search (τ on a grid of 20,000, each τ's best ψ by 2-D Procrustes on
    the coefficient matrices), never above it and above it by no more than the grid's step allows."""
    from bokehfit.metrics.efd import efd_aligned_distance

    def shape(name):
        return blob(8) if name == "blob8" else blob() if name == "blob" else outline(name, 11.0)

    harmonics = 12
    a, b = (normalise_efd(efd_coefficients(normalise(shape(name)), harmonics)) for name in pair)
    distance, _, _ = efd_aligned_distance(a, b)
    n = np.arange(1, harmonics + 1)
    target = np.concatenate([a[:, :2], a[:, 2:]], axis=1).reshape(harmonics, 2, 2)  # [[a, b], [c, d]] per harmonic
    moving = np.concatenate([b[:, :2], b[:, 2:]], axis=1).reshape(harmonics, 2, 2)
    best = math.inf
    for tau in np.linspace(0.0, 2.0 * np.pi, 20_000, endpoint=False):
        c, s = np.cos(n * tau), np.sin(n * tau)
        started = np.einsum("nij,njk->nik", moving, np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2))
        columns_a = target.transpose(1, 0, 2).reshape(2, -1)
        columns_b = started.transpose(1, 0, 2).reshape(2, -1)
        psi = math.atan2(float(np.sum(columns_b[0] * columns_a[1] - columns_b[1] * columns_a[0])),
                         float(np.sum(columns_b[0] * columns_a[0] + columns_b[1] * columns_a[1])))
        turned = np.array([[math.cos(psi), -math.sin(psi)], [math.sin(psi), math.cos(psi)]]) @ columns_b
        best = min(best, float(np.linalg.norm(columns_a - turned)))
    assert distance <= best + 1e-12
    assert distance >= best - 5e-3


def test_efd_not_mirror_invariant():
    shape = blob()
    assert efd_distance(shape, shape * [-1.0, 1.0]) > 0.05


# ---------------------------------------------------------------------------
# Hu moments


@pytest.mark.parametrize("pair", [("hexagon", "circle"), ("triangle", "square"), ("star", "slit")])
def test_hu_distance_against_cv2(pair):
    a = outline(pair[0], 10.0) * 50.0 + [300.0, 200.0]
    b = outline(pair[1], 3.0) * 80.0 + [10.0, 900.0]
    got = hu_distance(a, b)
    direct = cv2.matchShapes(normalise(a).astype(np.float32), normalise(b).astype(np.float32), cv2.CONTOURS_MATCH_I2, 0)
    assert got == direct
    raw = cv2.matchShapes(a.astype(np.float32), b.astype(np.float32), cv2.CONTOURS_MATCH_I2, 0)
    assert got == pytest.approx(raw, rel=HU_RAW_RTOL)
    assert got > 1e-3


# ---------------------------------------------------------------------------
# Angles


@pytest.mark.parametrize(
    "a,b,symmetry,expected",
    [
        (59.0, 1.0, 60.0, 2.0),  # wrap-around
        (1.0, 59.0, 60.0, 2.0),
        (119.0, 1.0, 120.0, 2.0),
        (10.0, 370.0, 90.0, 0.0),
        (0.0, 45.0, 90.0, 45.0),  # the largest possible
        (-30.0, 100.0, 72.0, 14.0),
        (3.0, 250.0, None, 0.0),  # circle
    ],
)
def test_angle_error_examples(a, b, symmetry, expected):
    assert angle_error(a, b, symmetry) == pytest.approx(expected, abs=1e-12)


def test_angle_error_range():
    rng = np.random.default_rng(5)
    for a, b, symmetry in zip(rng.uniform(-720, 720, 200), rng.uniform(-720, 720, 200), rng.choice([60.0, 72.0, 90.0, 120.0, 180.0], 200)):
        error = angle_error(a, b, symmetry)
        assert 0.0 <= error <= symmetry / 2.0
        assert error == pytest.approx(angle_error(b, a, symmetry))


# ---------------------------------------------------------------------------
# Registry and validation


def test_registry_and_dispatcher():
    assert list(METRICS) == ["iou", "hausdorff_rel", "efd_distance", "hu_distance"]
    for name, metric in METRICS.items():
        assert metric.name == name and metric.better in ("higher", "lower") and metric.description and metric.range
    a, b = outline("pentagon"), outline("square", 5.0)
    everything = compare_outlines(a, b)
    assert list(everything) == list(METRICS)
    assert compare_outlines(a, b, ["hu_distance", "iou"]) == {"hu_distance": hu_distance(a, b), "iou": iou(a, b)}
    assert everything["efd_distance"] == efd_distance(a, b)
    assert everything["hausdorff_rel"] == hausdorff_rel(a, b)


def test_iou_does_not_depend_on_an_earlier_narrow_alignment():
    # The sequence of the bug report: a narrow search of the same pair must not
    # change what a later full search returns.
    a, b = outline("triangle", 0.0), outline("triangle", 40.0)
    before = iou(a, b)
    narrow = compare_outlines(a, b, rotation_within_deg=1)
    after = iou(a, b)
    assert before == pytest.approx(1.0, abs=IOU_SELF_ATOL)
    assert narrow["iou"] < 0.6  # 40° off (= 80° of 120°) cannot be undone within ±1°
    assert after == before


def test_compare_outlines_same_answer_whatever_came_before():
    a, b = outline("hexagon", 0.0), outline("hexagon", 25.0)
    full = compare_outlines(a, b)
    narrow = compare_outlines(a, b, options=MetricOptions(rotation_within_deg=2.0))
    assert compare_outlines(a, b) == full
    assert compare_outlines(a, b, options=MetricOptions(rotation_within_deg=2.0)) == narrow
    assert full["iou"] == pytest.approx(1.0, abs=IOU_SELF_ATOL) and narrow["iou"] < full["iou"] - 0.05
    assert hausdorff_rel(a, b) == full["hausdorff_rel"]


def test_metric_options_reach_every_metric():
    a, b = outline("pentagon", 0.0), outline("square", 10.0)
    options = MetricOptions(rotation_within_deg=1.5, harmonics=8)
    values = compare_outlines(a, b, options=options)
    assert values["iou"] == iou(a, b, rotation_within_deg=1.5)
    assert values["hausdorff_rel"] == hausdorff_rel(a, b, rotation_within_deg=1.5)
    assert values["efd_distance"] == efd_distance(a, b, harmonics=8)
    unaligned = compare_outlines(a, b, ["iou"], options=MetricOptions(align=False))
    assert unaligned["iou"] == iou(a, b, align=False) == pytest.approx(shapely_iou(a, b), abs=IOU_SHAPELY_ATOL)


GOOD = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])


@pytest.mark.parametrize(
    "call,name",
    [
        (lambda: iou([[0, 0], [1, 1]], GOOD), "a"),
        (lambda: iou(GOOD, [[0, 0], [1, 0], [np.nan, 1]]), "b"),
        (lambda: hausdorff_rel(GOOD, [[0, 0], [1, 1], [2, 2]]), "b"),  # zero area
        (lambda: efd_distance(np.ones((5, 3)), GOOD), "a"),
        (lambda: efd_distance(GOOD, GOOD, harmonics=0), "harmonics"),
        (lambda: hu_distance(GOOD, [[0, 0], [np.inf, 0], [0, 1]]), "b"),
        (lambda: best_rotation_deg("square", GOOD), "a"),
        (lambda: compare_outlines(GOOD, GOOD, ["iou", "area"]), "metrics"),
        (lambda: compare_outlines(GOOD, [[1, 1], [1, 1], [1, 1], [1, 1]]), "b"),
        (lambda: compare_outlines(GOOD, GOOD, rotation_within_deg=0.0), "rotation_within_deg"),
        (lambda: compare_outlines(GOOD, GOOD, options={"align": False}), "options"),
        (lambda: compare_outlines(GOOD, GOOD, options=MetricOptions(), rotation_within_deg=1.0), "rotation_within_deg"),
        (lambda: MetricOptions(rotation_within_deg=float("nan")), "rotation_within_deg"),
        (lambda: MetricOptions(harmonics=0), "harmonics"),
        (lambda: MetricOptions(align="yes"), "align"),
        (lambda: iou(GOOD, GOOD, rotation_within_deg=-1.0), "rotation_within_deg"),
        (lambda: normalise([[0, 0], [0, 0], [1, 1]]), "outline"),
        (lambda: angle_error(float("nan"), 1.0, 60.0), "angle_a_deg"),
        (lambda: angle_error(1.0, 2.0, 0.0), "symmetry_deg"),
        (lambda: aperture_outline("hexagon"), "aperture"),
        (lambda: aperture_outline(make_aperture("circle"), points=2), "points"),
    ],
)
def test_bad_input_names_the_parameter(call, name):
    with pytest.raises(InputError) as raised:
        call()
    assert isinstance(raised.value, ValueError)
    assert str(raised.value).startswith(f"{name} "), str(raised.value)


@pytest.mark.parametrize("seed", range(6))
def test_distance_to_an_outline_against_its_near_sides_is_the_distance_against_all(seed):
    """DistanceToOutline measures each point against the sides that can be nearest only: the same
    numbers as against every side, on wavy outlines of many sides, with a few long sides (which
    make the pruning keep more) and points inside, on and far outside."""
    from bokehfit.metrics.outlines import DistanceToOutline

    rng = np.random.default_rng(seed)
    count = int(rng.integers(100, 900))
    angles = np.sort(rng.uniform(0.0, 2.0 * np.pi, count))
    radius = 1.0 + 0.3 * np.sin(int(rng.integers(1, 9)) * angles) + rng.uniform(0.0, 0.05, count)
    target = np.column_stack([radius * np.cos(angles), radius * np.sin(angles)])
    if seed % 2:
        target = np.vstack([target[: count // 2], target[-3:]])  # a chord across: a few long sides
    points = np.vstack([rng.uniform(-2.0, 2.0, (500, 2)), target[::7], 10.0 * rng.normal(size=(20, 2))])
    distance_to = DistanceToOutline(target)
    assert len(target) > DistanceToOutline.ALL_SIDES_UP_TO  # the pruned path is the one tested
    every_side = distance_to.to_sides(points[:, 0, None], points[:, 1, None]).min(axis=1)
    np.testing.assert_array_equal(distance_to(points), every_side)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_narrow_alignment_finds_the_best_iou_within_its_reach(seed):
    """compare's alignment within ±ALIGNMENT_SEARCH_DEG (searched on simplified outlines) turns a noisy
    disc to the IoU's maximum there: the full outlines' exact IoU at its angle is the best on a grid of
    0.1° refined to 0.002° around the grid's best, to 1e-5."""
    from bokehfit.compare import ALIGNMENT_SEARCH_DEG, METRIC_POINTS, _half_outline
    from bokehfit.kernels.exact import coverage
    from bokehfit.metrics import _iou_of_normalised, _local_rotation
    from bokehfit.metrics.outlines import resample

    hexagon = make_aperture("hexagon", 20.0)
    diameter = 33.0
    drawn = _half_outline(coverage(hexagon, diameter * math.sqrt(math.pi) / 2.0, 45), diameter)
    kernel = normalise(drawn)
    rng = np.random.default_rng(seed)
    turned = rotate(resample(drawn - centroid(drawn), 400), rng.uniform(-6.0, 6.0))  # px, about its centre
    disc = normalise(resample(turned + rng.normal(0.0, 0.25, (400, 2)), METRIC_POINTS))
    angle = _local_rotation(kernel, disc, ALIGNMENT_SEARCH_DEG)

    def overlap(angle_deg):
        return _iou_of_normalised(kernel, rotate(disc, angle_deg))

    grid = np.arange(-ALIGNMENT_SEARCH_DEG, ALIGNMENT_SEARCH_DEG + 1e-9, 0.1)
    coarse = grid[int(np.argmax([overlap(g) for g in grid]))]
    fine = max(overlap(g) for g in np.arange(coarse - 0.1, coarse + 0.1 + 1e-9, 0.002))
    assert abs(angle) <= ALIGNMENT_SEARCH_DEG
    assert overlap(angle) >= fine - 1e-5


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_round_kernel_needs_no_alignment(seed):
    """compare's disc metrics skip the rotation search where the aperture's outline turns alike
    (a plain circle: :attr:`Aperture.turns_alike`). Against the 50 % outline of a drawn circular
    kernel (a polygon on the pixel grid, within δ of a circle), a noisy disc's IoU at its best
    rotation within ±10° is the unturned one to a thousandth; its Hausdorff distance differs by no
    more than 2δ (a turned copy of the kernel's outline lies within 2δ of it), the rotation search
    chasing the pixel grid's wiggles; the descriptors do not depend on the rotation."""
    from bokehfit.compare import ALIGNMENT_SEARCH_DEG, METRIC_POINTS, _half_outline
    from bokehfit.kernels.exact import coverage
    from bokehfit.metrics.outlines import resample

    circle = make_aperture("circle")
    diameter = 37.0
    kernel = _half_outline(coverage(circle, diameter * math.sqrt(math.pi) / 2.0, 47), diameter)
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 2.0 * math.pi, 400, endpoint=False)
    circle_xy = np.column_stack([60 + 18.5 * np.cos(t), 40 + 18.5 * np.sin(t)])
    disc = resample(circle_xy + rng.normal(0, 0.3, (400, 2)), METRIC_POINTS)
    turned = compare_outlines(disc, kernel, options=MetricOptions(rotation_within_deg=ALIGNMENT_SEARCH_DEG))
    as_given = compare_outlines(disc, kernel, options=MetricOptions(align=False))
    assert circle.turns_alike
    assert as_given["iou"] == pytest.approx(turned["iou"], abs=1e-3)
    normal = normalise(kernel, "kernel")
    radii = np.hypot(*normal.T)
    departure = float(np.max(np.abs(radii - radii.mean()))) / CIRCLE_RADIUS  # δ, in the metric's unit
    assert departure < 0.01  # a tenth of a pixel at this size
    assert abs(as_given["hausdorff_rel"] - turned["hausdorff_rel"]) <= 2.0 * departure + 1e-9
    assert as_given["efd_distance"] == turned["efd_distance"] and as_given["hu_distance"] == turned["hu_distance"]
