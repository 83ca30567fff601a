"""Kernels of the real-lens apertures (design.md §3b): exact against shapely, mc and raster against exact."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from shapely import affinity

from bokehfit.apertures import Chromatic, Vignetting, make_aperture
from bokehfit.errors import InputError
from bokehfit.kernels import compute_kernel, render_kernel
from bokehfit.kernels.exact import coverage
from bokehfit.kernels.rim import rim_coverage
from test_mask import ring_mask

#: Chords per arc of the independent shapely outlines: each polygon lies inside
#: its arcs, so a pixel's coverage can be short by at most the total area the
#: chords cut off, which the tests measure and use as the bound.
ARC_CHORDS = 4000
#: Radius of the circle with unit area (design.md §3).
R0 = 1.0 / math.sqrt(math.pi)
FIELD = (0.6, -0.45)


def shapely_aperture(blades=None, roundness=0.0, angle_deg=0.0, squeeze=1.0, vignetting=None, field=FIELD, side="far"):
    """The §3b aperture built from its definition with shapely (an n-gon, or the circle when blades is None)."""
    if blades is None:
        shape = shapely.Point(0.0, 0.0).buffer(R0, quad_segs=ARC_CHORDS // 4)
    else:
        corners = [(math.cos(2 * math.pi * k / blades), math.sin(2 * math.pi * k / blades)) for k in range(blades)]
        if roundness == 0.0:
            shape = shapely.Polygon(corners)
        else:  # each edge an arc of radius R/roundness through its two corners, bulging outward
            rho = 1.0 / roundness
            half_chord = math.sin(math.pi / blades)
            alpha = math.asin(half_chord / rho)
            points = []
            for k in range(blades):
                mid = 2 * math.pi * (k + 0.5) / blades
                offset = math.cos(math.pi / blades) - rho * math.cos(alpha)  # arc centre on the bisector
                phis = np.linspace(mid - alpha, mid + alpha, ARC_CHORDS // blades, endpoint=False)
                points += [(offset * math.cos(mid) + rho * math.cos(p), offset * math.sin(mid) + rho * math.sin(p)) for p in phis]
            shape = shapely.Polygon(points)
        # Unit area from the exact area: the polygon of the corners plus a circular segment per blade.
        area = 0.5 * blades * math.sin(2 * math.pi / blades)
        if roundness != 0.0:
            area += blades * 0.5 * rho * rho * (2 * alpha - math.sin(2 * alpha))
        shape = affinity.scale(shape, 1 / math.sqrt(area), 1 / math.sqrt(area), origin=(0, 0))
    shape = affinity.rotate(shape, angle_deg + (180.0 if side == "near" else 0.0), origin=(0, 0))
    shape = affinity.scale(shape, 1 / math.sqrt(squeeze), math.sqrt(squeeze), origin=(0, 0))
    if vignetting is not None:
        radius, shift = vignetting
        sign = -1.0 if side == "near" else 1.0
        centre = (sign * shift * R0 * field[0], sign * shift * R0 * field[1])
        shape = shape.intersection(shapely.Point(centre).buffer(radius * R0, quad_segs=ARC_CHORDS // 4))
    return shape


def shapely_coverage(shape, scale, size):
    """Area of ``shape`` scaled to pixels on each pixel of the frame (light at ((size−1)/2, (size−1)/2))."""
    shape = affinity.scale(shape, scale, scale, origin=(0, 0))
    centre = (size - 1) / 2
    rows, cols = np.indices((size, size))
    x, y = cols - centre, centre - rows
    boxes = shapely.box(x - 0.5, y - 0.5, x + 0.5, y + 0.5)
    return shapely.area(shapely.intersection(boxes, shape)), shape.area


EXACT_CASES = {
    "rounded_9_blades": dict(blades=9, roundness=0.5, angle_deg=7.0),
    "rounded_triangle_full": dict(blades=3, roundness=1.0, angle_deg=20.0),
    "rounded_5_gentle": dict(blades=5, roundness=0.05, angle_deg=3.0),
    "squeezed_hexagon": dict(blades=6, angle_deg=10.0, squeeze=1.8),
    "squeezed_circle": dict(squeeze=0.55),
    "squeezed_rounded_7": dict(blades=7, roundness=0.7, angle_deg=31.0, squeeze=1.33),
    "vignetted_pentagon": dict(blades=5, angle_deg=13.0, vignetting=(1.1, 0.9)),
    "vignetted_rounded_squeezed": dict(blades=9, roundness=0.5, squeeze=1.4, vignetting=(1.05, 1.2)),
    "vignetted_circle_near": dict(vignetting=(1.0, 1.5), side="near"),
    "vignetted_pentagon_near": dict(blades=5, angle_deg=13.0, vignetting=(1.1, 0.9), side="near"),
}


def _make(blades=None, roundness=0.0, angle_deg=0.0, squeeze=1.0, vignetting=None, side="far"):
    shape = "circle" if blades is None else "ngon"
    return make_aperture(shape, angle_deg, blades=blades, roundness=roundness, squeeze=squeeze,
                         vignetting=None if vignetting is None else Vignetting(*vignetting))


@pytest.mark.parametrize("name", list(EXACT_CASES))
def test_exact_coverage_matches_shapely(name):
    params = EXACT_CASES[name]
    aperture = _make(**params)
    scale, size = 13.0, 36
    side = params.get("side", "far")
    exact = coverage(aperture, scale, size, flip=side == "near", field_position=FIELD)
    reference, reference_area = shapely_coverage(shapely_aperture(**params), scale, size)
    # The chords lie inside the arcs: no pixel can be short by more than all they cut off.
    seen = aperture if side == "far" else aperture.near()
    cut_off = seen.area(FIELD) * scale * scale - reference_area
    assert -1e-9 <= cut_off < 1e-3
    assert np.abs(exact - reference).max() <= cut_off + 1e-9


@pytest.mark.parametrize("name", ["vignetted_pentagon", "vignetted_rounded_squeezed", "vignetted_circle_near"])
def test_vignetting_renormalised_and_light_loss_reported(name):
    params = EXACT_CASES[name]
    side = params.get("side", "far")
    kernel = compute_kernel(_make(**params), diameter_px=20.0, size=36, side=side, field_position=FIELD)
    assert kernel.image.sum() == pytest.approx(1.0, abs=1e-5)
    transmitted = shapely_aperture(**params).area  # the unclipped aperture has unit area
    assert 0.2 < kernel.transmitted < 0.99
    assert kernel.transmitted == pytest.approx(transmitted, abs=1e-5)


def test_vignetting_depends_on_field_position_not_at_centre():
    aperture = make_aperture("hexagon", 0.0, vignetting=Vignetting(1.2, 1.0))
    centre = compute_kernel(aperture, diameter_px=20.0, size=32, field_position=(0.0, 0.0))
    corner = compute_kernel(aperture, diameter_px=20.0, size=32, field_position=(0.8, 0.6))
    assert centre.transmitted == pytest.approx(1.0)
    assert corner.transmitted < 0.95
    assert np.abs(centre.image - corner.image).sum() > 0.05


def test_near_vignetted_disc_is_far_turned_180():
    aperture = make_aperture("pentagon", 11.0, roundness=0.0, vignetting=Vignetting(1.1, 0.9))
    far = render_kernel(aperture, diameter_px=19.0, size=31, field_position=FIELD)
    near = render_kernel(aperture, diameter_px=19.0, size=31, side="near", field_position=FIELD)
    np.testing.assert_allclose(near, np.rot90(far, 2), atol=1e-7)
    assert np.abs(near - far).sum() > 0.1


def independent_rim_kernel(rim, scale, size, per_pixel=48):
    """Hexagon with a rim profile, by brute force: ρ as the hexagon's gauge max_k p·n_k / apothem."""
    circumradius = math.sqrt(2 / (6 * math.sin(2 * math.pi / 6)))
    apothem = circumradius * math.cos(math.pi / 6) * scale
    normals = np.array([(math.cos(math.pi * (2 * k + 1) / 6), math.sin(math.pi * (2 * k + 1) / 6)) for k in range(6)])
    centre = (size - 1) / 2
    offsets = (np.arange(per_pixel) + 0.5) / per_pixel - 0.5
    axis = (np.arange(size)[:, None] + offsets).ravel() - centre
    x, y = np.meshgrid(axis, -axis)
    rho = np.max(x[..., None] * normals[:, 0] + y[..., None] * normals[:, 1], axis=-1) / apothem
    weight = np.where(rho <= 1.0, 1.0 + rim * (2.0 * rho * rho - 1.0), 0.0)
    image = weight.reshape(size, per_pixel, size, per_pixel).sum(axis=(1, 3))
    return image / image.sum()


def test_rim_tabulated_within_stated_bound_and_converging():
    aperture = make_aperture("hexagon", 0.0, rim=0.7)
    scale, size = 14.0, 32
    reference = independent_rim_kernel(0.7, scale, size)
    errors = []
    for supersample in (2, 8):
        image, bound = rim_coverage(aperture, scale, size, supersample=supersample)
        assert image.sum() == pytest.approx(scale * scale, rel=0.01)  # the profile keeps the total light
        errors.append(np.abs(image / image.sum() - reference).sum())
        assert errors[-1] <= bound
    # Sub-pixel error falls at least linearly with the sub-pixel side (second order inside);
    # the brute-force reference itself is good to about 1e-4 here.
    assert errors[1] < 0.5 * errors[0]
    kernel = compute_kernel(aperture, diameter_px=2 * scale / math.sqrt(math.pi), size=size)
    assert kernel.error_bound is not None and np.abs(kernel.image - reference).sum() <= kernel.error_bound
    assert np.abs(kernel.image - reference).sum() < 2e-3


def test_rim_flips_on_near_side():
    aperture = make_aperture("circle", rim=0.6)
    far = render_kernel(aperture, diameter_px=20.0, size=28)
    near = render_kernel(aperture, diameter_px=20.0, size=28, side="near")
    centre = slice(12, 16)
    assert far[centre, centre].mean() < near[centre, centre].mean()  # bright rim far, bright centre near
    flipped = render_kernel(make_aperture("circle", rim=-0.6), diameter_px=20.0, size=28)
    np.testing.assert_allclose(near, flipped, atol=1e-7)


def test_chromatic_three_channels_scaled_discs():
    aperture = make_aperture("hexagon", 15.0, chromatic=Chromatic(0.1, -0.08))
    kernel = render_kernel(aperture, diameter_px=20.0, size=32)
    assert kernel.shape == (32, 32, 3) and kernel.dtype == np.float32
    np.testing.assert_allclose(kernel.sum(axis=(0, 1)), 1.0, atol=1e-5)
    for channel, factor in ((0, 1.1), (1, 1.0), (2, 0.92)):
        plain = render_kernel(make_aperture("hexagon", 15.0), 20.0 * factor, 32)
        np.testing.assert_allclose(kernel[..., channel], plain, atol=1e-7)
    near = render_kernel(aperture, diameter_px=20.0, size=32, side="near")
    np.testing.assert_allclose(near[..., 0], render_kernel(make_aperture("hexagon", 195.0), 20.0 * 0.9, 32), atol=1e-7)


def test_the_kernel_takes_the_aperture_whole():
    with pytest.raises(TypeError, match="roundness"):  # a feature travels inside the Aperture only
        render_kernel(make_aperture("hexagon"), diameter_px=10.0, size=16, roundness=0.5)
    with pytest.raises(InputError, match="^aperture must be an Aperture"):
        render_kernel("hexagon", 10.0, 16)
    with pytest.raises(InputError, match="field_position"):
        render_kernel(make_aperture("hexagon"), 10.0, 16, field_position=(1.0, 2.0, 3.0))


def l1(kernel, reference):
    return float(np.abs(kernel.astype(np.float64) - reference).sum())


#: One aperture per §3b feature, small enough for lavapipe.
FEATURE_APERTURES = {
    "rounded": dict(shape="ngon", blades=9, roundness=0.5, angle_deg=10.0),
    "squeezed": dict(shape="hexagon", squeeze=1.6, angle_deg=10.0),
    "vignetted": dict(shape="pentagon", vignetting=Vignetting(1.15, 0.9)),
    "rim": dict(shape="hexagon", rim=0.6, angle_deg=5.0),
    "chromatic": dict(shape="hexagon", chromatic=Chromatic(0.06, -0.05)),
    "mask": dict(shape="mask", mask=ring_mask(), angle_deg=30.0, squeeze=1.3),
    "mask_chromatic": dict(shape="mask", mask=ring_mask(), chromatic=Chromatic(0.06, -0.05)),
}


@pytest.mark.parametrize("method,min_rate", [("mc", 0.6), ("raster", 0.6)])
@pytest.mark.parametrize("feature", list(FEATURE_APERTURES))
def test_sampling_methods_converge_to_exact_per_feature(gpu, method, min_rate, feature):
    """L1 to exact falls at about N^-3/4 (stratified), as the bench reports; asserted with margin over 1.5 decades."""
    params = dict(FEATURE_APERTURES[feature])
    aperture = make_aperture(params.pop("shape"), **params)
    exact = compute_kernel(aperture, diameter_px=18.0, size=28, side="near", field_position=FIELD)
    counts = (2**14, 2**19)
    errors = []
    for n in counts:
        kernel = compute_kernel(aperture, diameter_px=18.0, size=28, side="near", field_position=FIELD,
                                method=method, samples=n, seed=4)
        assert kernel.transmitted == pytest.approx(exact.transmitted)
        errors.append(l1(kernel.image, exact.image.astype(np.float64)))
    rate = math.log(errors[0] / errors[1]) / math.log(counts[1] / counts[0])
    assert rate >= min_rate, f"{method} {feature}: L1 {errors}, rate {rate:.2f}"
    assert errors[1] < 0.01


@pytest.mark.parametrize("shape, angle, extra", [
    ("circle", 0.0, {}), ("hexagon", 17.0, {}), ("ngon", 33.0, {"blades": 9, "roundness": 0.6}),
    ("square", 10.0, {"squeeze": 1.6}), ("star", 5.0, {}), ("slit", 20.0, {"aspect": 0.4}),
    ("pentagon", 3.0, {"roundness": 0.3, "squeeze": 0.7}), ("triangle", 40.0, {}),
])
def test_the_models_radial_fraction_is_the_outline_polygons(shape, angle, extra):
    """The rim's ρ (design.md §3b) from the aperture model, which ``rim_coverage`` uses, and from the
    fan of its outline's polygon (arcs within 1e-9), at points inside, on and outside the outline."""
    from bokehfit.kernels.rim import radial_fraction

    aperture = make_aperture(shape, angle, rim=0.5, **extra)
    points = np.random.default_rng(7).uniform(-1.2, 1.2, (4000, 2))
    by_polygon, _ = radial_fraction(points, aperture.outline().polyline(1e-9))
    assert np.allclose(aperture.radial_fraction(points), by_polygon, rtol=0, atol=1e-6)
