"""Numerical stability on the hardest cases: each gives a stable, sensible result or a clear error.

Every test is named for the case it holds. None is timed (speed is the
benchmarks' job); the crowded-photo case asserts bounded work instead.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from bokehfit.apertures import SHAPES, make_aperture
from bokehfit.discs import MAX_CANDIDATES, find_discs
from bokehfit.errors import InputError
from bokehfit.kernels import KernelClippedWarning, compute_kernel, render_kernel
from bokehfit.kernels.exact import coverage
from bokehfit.optics import coc_mm, fstop_from_coc
from bokehfit.synthetic import SyntheticDisc, encode_srgb8, render_discs

#: The largest float32 below 1: the top of every sampler's domain (design.md §5).
U_TOP = 1.0 - 2.0**-24
#: A small transmission image for the tabulated (mask) aperture: a ramp with an opaque corner.
HARD_MASK = np.clip(np.add.outer(np.linspace(0.0, 1.0, 5), np.linspace(0.2, 1.0, 5)), 0.0, 1.0)
#: Every shape; the slit at aspect 0.6 so that it fits the small frames used here.
SHAPE_PARAMS = [(s, {"ngon": {"blades": 7}, "slit": {"aspect": 0.6}, "mask": {"mask": HARD_MASK}}.get(s, {})) for s in SHAPES]
#: The shapes the dispatch-by-id WGSL sampler serves (a mask needs its table bound: tests/test_mask.py).
OUTLINE_SHAPE_PARAMS = [(s, p) for s, p in SHAPE_PARAMS if not SHAPES[s].tabulated]


# --- Kernels -------------------------------------------------------------------------


def test_coc_of_a_third_of_a_pixel_is_one_sharp_kernel():
    kernel = render_kernel(make_aperture("hexagon", 0.0), 0.3, 9)  # odd frame: the light on the centre pixel
    assert kernel.sum() == pytest.approx(1.0, abs=1e-6)
    assert kernel[4, 4] == pytest.approx(1.0, abs=1e-6)


def test_coc_of_2000_px_in_a_2100_px_frame():
    kernel = compute_kernel(make_aperture("circle", 0.0), 2000.0, 2100)
    assert kernel.clipped_fraction == 0.0
    assert np.isfinite(kernel.image).all() and kernel.image.min() >= 0.0
    assert kernel.image.sum() == pytest.approx(1.0, abs=1e-5)
    assert kernel.image[1050, 1050] == pytest.approx(1.0 / (math.pi * 1000.0**2), rel=1e-6)


def test_coc_of_2000_px_clipped_by_a_small_frame_says_so():
    with pytest.warns(KernelClippedWarning):
        kernel = compute_kernel(make_aperture("star", 3.0), 2000.0, 64)
    assert kernel.clipped_fraction > 0.99 and kernel.image.sum() == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("shape,params", SHAPE_PARAMS)
def test_angles_at_the_symmetry_plus_and_minus_a_microdegree(shape, params):
    symmetry = make_aperture(shape, **params).symmetry_deg or 360.0
    for angle in (symmetry - 1e-6, symmetry + 1e-6, -1e-6, 1e-6):
        canonical = make_aperture(shape, angle, **params).canonical_angle_deg
        assert canonical is None or 0.0 <= canonical < symmetry
        np.testing.assert_allclose(
            render_kernel(make_aperture(shape, angle, **params), 24.0, 40),
            render_kernel(make_aperture(shape, 0.0, **params), 24.0, 40),
            atol=1e-6,
        )


@pytest.mark.parametrize("shape,params", SHAPE_PARAMS)
def test_top_of_the_unit_square_in_every_numpy_sampler(shape, params):
    aperture = make_aperture(shape, **params)
    corners = np.array([[U_TOP, U_TOP], [U_TOP, 0.0], [0.0, U_TOP], [0.0, 0.0], [0.5, U_TOP]])
    points, _ = aperture.sample(corners)
    assert np.isfinite(points).all()
    reach = aperture.extent()
    assert (np.hypot(points[:, 0], points[:, 1]) <= reach * (1 + 1e-9)).all()


@pytest.mark.parametrize("shape,params", OUTLINE_SHAPE_PARAMS)
def test_top_of_the_unit_square_in_every_wgsl_sampler(gpu, run_wgsl_sampler, shape, params):
    aperture = make_aperture(shape, **params)
    corners = np.array([[U_TOP, U_TOP], [U_TOP, 0.0], [0.0, U_TOP], [0.0, 0.0], [0.5, U_TOP]], dtype=np.float32)
    spec = aperture.spec
    call = f"rotate(sample_aperture({spec.shader_id}u, u, {aperture.blades or 0}u, {aperture.aspect or 1.0}), 1.0, 0.0)"
    points = run_wgsl_sampler(gpu, call, corners)
    assert np.isfinite(points).all()
    np.testing.assert_allclose(points, aperture.sample(corners.astype(np.float64))[0], atol=2e-6 * aperture.extent())


@pytest.mark.parametrize("tolerance", [3e-2, 1e-2])
@pytest.mark.parametrize("method", ["mc", "raster"])
def test_planned_sample_counts_meet_the_tolerance(gpu, method, tolerance):
    exact = render_kernel(make_aperture("star", 11.0), 48.0, 80).astype(np.float64)
    kernel = compute_kernel(make_aperture("star", 11.0), 48.0, 80, method=method, tolerance=tolerance, seed=5)
    assert np.abs(kernel.image - exact).sum() <= tolerance


# --- Optics --------------------------------------------------------------------------


def test_light_at_the_focus_distance_makes_no_disc_and_no_fstop():
    assert coc_mm(2.0, 50.0, 3.0, 3.0) == 0.0
    with pytest.raises(InputError, match="focus distance"):
        fstop_from_coc(0.1, 50.0, 3.0, 3.0)


def test_fstop_at_the_pinhole_end_stays_finite():
    for fstop in (1e3, 1e4):  # 1e4 is the largest f-stop bokehfit.validate accepts
        c = coc_mm(fstop, 50.0, 3.0, math.inf)
        assert 0.0 < c < 1e-1 and math.isfinite(c)
        assert fstop_from_coc(c, 50.0, 3.0, math.inf) == pytest.approx(fstop, rel=1e-9)


@pytest.mark.parametrize("fstop", [1e6, 1e12, math.inf, math.nan])
def test_fstop_beyond_a_pinhole_is_refused_by_name(fstop):
    with pytest.raises(InputError, match="fstop"):
        coc_mm(fstop, 50.0, 3.0, math.inf)


@pytest.mark.parametrize("focus_m", [0.05, 0.049, 0.0])
def test_focus_at_or_inside_the_focal_length_is_an_error_not_nan(focus_m):
    with pytest.raises(InputError):
        coc_mm(2.0, 50.0, focus_m, math.inf)


def test_thin_lens_in_float32_agrees_with_float64_at_extremes():
    for f, n, focus, light in ((800.0, 5.6, 1e4, 1e6), (8.0, 1.0, 0.2, 0.21), (85.0, 1.2, 3.0, math.inf)):
        exact = coc_mm(n, f, focus, light)
        f32 = np.float32
        focus_mm, light_mm = f32(focus * 1000), f32(light * 1000)
        if math.isinf(light):
            single = f32(f) * f32(f) / (f32(n) * (focus_mm - f32(f)))
        else:
            single = (f32(f) / f32(n)) * f32(f) * abs(light_mm - focus_mm) / (light_mm * (focus_mm - f32(f)))
        assert float(single) == pytest.approx(exact, rel=1e-5)


# --- Discs ---------------------------------------------------------------------------


def test_disc_touching_all_four_frame_edges():
    disc = SyntheticDisc((29.5, 29.5), 75.0, make_aperture("circle"), brightness=0.5)
    image = render_discs(60, 60, [disc], background=0.02)
    search = find_discs(image)
    assert all(d.clipped for d in search.discs)  # either none found or found and flagged
    assert not any(d.usable for d in search.discs)


def test_two_discs_overlapping_by_90_percent():
    hexagon = make_aperture("hexagon", 5.0)
    truth = [SyntheticDisc((100.0, 80.0), 60.0, hexagon), SyntheticDisc((103.0, 81.0), 60.0, hexagon, brightness=0.5)]
    search = find_discs(render_discs(200, 160, truth, noise_sigma=0.002))
    assert 1 <= len(search.discs) <= 2
    biggest = search.discs[0]
    assert abs(biggest.center_xy[0] - 101.5) < 3 and 55 < biggest.diameter_px < 70


def test_saturated_flat_topped_disc():
    """Five times over the clip: the plateau is gone, the outline is not. The disc is used by its edge,
    its clipped pixels fitted as lower bounds, and gives the shape, the angle and the size."""
    from bokehfit.fit import fit_aperture

    disc = SyntheticDisc((80.3, 79.8), 70.0, make_aperture("pentagon", 8.0), brightness=5.0)
    image = np.minimum(render_discs(160, 160, [disc],
                                    noise_sigma=0.002), 1.0)
    search = find_discs(image, image >= 1.0)
    assert len(search.discs) == 1 and search.discs[0].saturated and search.discs[0].usable
    assert search.discs[0].evidence == "edge"
    assert search.discs[0].diameter_px == pytest.approx(70.0, rel=0.05)
    fit = fit_aperture(image, search.discs, clipped=image >= 1.0)
    assert fit.family.base.name == "pentagon", fit.message
    fitted = fit.disc_fits[0].fits[fit.family.name]
    assert fitted.censored > 100 and fitted.plateau > 1.0  # (pixels of the reduced crop)
    assert min((fit.aperture.angle_deg - 8.0) % 72.0, (8.0 - fit.aperture.angle_deg) % 72.0) < 1.0
    # Its edge pixels above a fifth of the plateau read as clipped: the size is known to about a pixel.
    assert fitted.diameter_px == pytest.approx(70.0, abs=2.5)


def test_a_4_px_disc_is_found_but_too_small_to_fit():
    disc = SyntheticDisc((20.2, 19.7), 4.5, make_aperture("circle"), brightness=0.8)
    search = find_discs(render_discs(40, 40, [disc], noise_sigma=0.002))
    assert len(search.discs) == 1 and not search.discs[0].resolvable


def test_jpeg_quality_30():
    hexagon = make_aperture("hexagon", 12.0)
    truth = [SyntheticDisc((60.0 + 120 * i, 70.0), d, hexagon, brightness=0.6) for i, d in enumerate((24, 40, 64))]
    linear = render_discs(360, 140, truth, background=0.03, noise_sigma=0.003)
    _, data = cv2.imencode(".jpg", encode_srgb8(linear), [cv2.IMWRITE_JPEG_QUALITY, 30])
    decoded = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
    from bokehfit.io.colour import colour_science

    lut = colour_science().cctf_decoding(np.arange(256) / 255.0, function="sRGB").astype(np.float32)
    search = find_discs(lut[decoded])
    for t in truth:
        nearest = min(search.discs, key=lambda d: math.dist(d.center_xy, t.center_xy))
        assert math.dist(nearest.center_xy, t.center_xy) < 2.0
        assert nearest.diameter_px == pytest.approx(t.diameter_px, rel=0.08)


def test_photo_with_2000_candidate_highlights_is_bounded_work():
    rng = np.random.default_rng(8)
    image = np.full((900, 900), 0.02, dtype=np.float32)
    rows, cols = rng.integers(2, 898, 2000), rng.integers(2, 898, 2000)
    image[rows, cols] = 0.9  # 2000 in-focus point highlights
    image = cv2.GaussianBlur(image, (0, 0), 0.7)
    search = find_discs(image)
    measured = search.candidates - search.rejected.get("beyond the candidate limit", 0)
    assert measured <= MAX_CANDIDATES
    assert not any(d.resolvable for d in search.discs)  # points are not resolvable discs


def test_nan_and_inf_in_the_image_are_refused():
    for bad in (np.nan, np.inf):
        image = np.zeros((32, 32), dtype=np.float32)
        image[5, 5] = bad
        with pytest.raises(InputError, match="NaN or Inf"):
            find_discs(image)


def test_coverage_of_a_shape_far_outside_the_frame_is_zero():
    assert coverage(make_aperture("square"), 10.0, 16, offset_xy=(1e6, -1e6)).sum() == 0.0
