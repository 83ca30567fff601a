"""Kernels: exact against brute force, mc and raster against exact, and hard cases."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import shapely

from bokehfit.apertures import SHAPES, make_aperture
from bokehfit.kernels import METHODS, KernelClippedWarning, compute_kernel, render_kernel

#: Every shape; the slit at aspect 0.6 so that it fits the small frames used here.
SHAPE_PARAMS = [(s, {"ngon": {"blades": 9}, "slit": {"aspect": 0.6}}.get(s, {})) for s, spec in SHAPES.items() if not spec.tabulated]  # mask: test_mask.py
#: Brute-force raster: SUPERSAMPLE² points per pixel; a pixel's coverage is then
#: exact to within the share of points an edge can flip, ≤ about 2/SUPERSAMPLE.
SUPERSAMPLE = 32


def brute_force_kernel(shape, angle, diameter, size, **params):
    """Independent reference: count supersample points inside the shape (shapely)."""
    aperture = make_aperture(shape, angle, **params)
    scale = diameter * math.sqrt(math.pi) / 2
    centre = (size - 1) / 2
    offsets = (np.arange(SUPERSAMPLE) + 0.5) / SUPERSAMPLE - 0.5
    cols = (np.arange(size)[:, None] + offsets[None, :]).ravel() - centre
    rows = (np.arange(size)[:, None] + offsets[None, :]).ravel()
    x, y = np.meshgrid(cols, centre - rows)
    vertices = aperture.vertices()
    if vertices is None:
        inside = x * x + y * y <= (scale / math.sqrt(math.pi)) ** 2
    else:
        inside = shapely.contains_xy(shapely.Polygon(vertices * scale), x, y)
    counts = inside.reshape(size, SUPERSAMPLE, size, SUPERSAMPLE).sum(axis=(1, 3))
    return counts / counts.sum()


@pytest.mark.parametrize("shape,params", SHAPE_PARAMS)
def test_exact_sums_to_one_and_matches_brute_force(shape, params):
    kernel = render_kernel(make_aperture(shape, 17.0, **params), 21.0, 40)
    assert kernel.dtype == np.float32 and kernel.shape == (40, 40)
    assert kernel.sum() == pytest.approx(1.0, abs=1e-6)
    reference = brute_force_kernel(shape, 17.0, 21.0, 40, **params)
    pixel_area = 1.0 / (math.pi * 21.0**2 / 4)  # one fully covered pixel, normalised
    assert np.abs(kernel - reference).max() <= 2.0 / SUPERSAMPLE * pixel_area


#: Edge-only exact coverage against the integral on the whole grid: a pixel the outline
#: crosses is the same computation (bit-identical); any other is 0 or 1 where the whole
#: grid's second difference of F rounds: F's terms reach (frame side + disc's extent)² px²,
#: so a few eps of that.
EDGE_ONLY_ROUNDING = 4.0 * np.finfo(np.float64).eps


@pytest.mark.parametrize(
    "shape,params,diameter,size,extra",
    [
        ("pentagon", {}, 160.0, 190, {}),
        ("circle", {}, 120.0, 131, {"offset_xy": (0.37, -0.21)}),
        ("star", {}, 140.0, 200, {"flip": True}),
        ("hexagon", {"roundness": 0.4, "squeeze": 1.6}, 100.0, 181, {}),
        ("hexagon", {"vignetting": {"radius": 1.0, "shift": 0.9}}, 120.0, 140, {"field_position": (0.9, -0.6)}),
        ("square", {}, 140.0, 120, {}),  # the disc overflows the frame: the inside touches its border
        ("slit", {"aspect": 0.05}, 200.0, 240, {}),  # a thin sliver: few pixels wholly inside
    ],
)
def test_exact_edge_only_matches_the_whole_grid(monkeypatch, shape, params, diameter, size, extra):
    from bokehfit.kernels import exact

    aperture = make_aperture(shape, 23.0, **params)
    scale = diameter * math.sqrt(math.pi) / 2
    monkeypatch.setattr(exact, "_EDGE_ONLY_MIN_WORK", 0)  # always edge-only (unless it crosses most pixels)
    edge_only = exact.coverage(aperture, scale, size, **extra)
    monkeypatch.setattr(exact, "_EDGE_ONLY_MIN_WORK", math.inf)  # always the whole grid
    whole = exact.coverage(aperture, scale, size, **extra)
    crossed = (whole > 1e-9) & (whole < 1.0 - 1e-9)
    assert 0 < crossed.sum() < 0.5 * size * size  # the edge-only path ran
    np.testing.assert_array_equal(edge_only[crossed], whole[crossed])
    bound = EDGE_ONLY_ROUNDING * (size + 2.0 * aperture.extent() * scale) ** 2
    assert np.abs(edge_only - whole).max() <= bound
    rest = edge_only[~crossed]
    assert np.all(np.minimum(rest, 1.0 - rest) <= bound)  # wholly outside or inside, to rounding
    assert np.count_nonzero(rest == 1.0) > np.count_nonzero(whole == 1.0)  # the inside set, not integrated


@pytest.mark.parametrize("shape,params", SHAPE_PARAMS)
def test_near_is_far_rotated_180(shape, params):
    aperture = make_aperture(shape, 33.0, **params)
    far = render_kernel(aperture, 19.0, 31)
    near = render_kernel(aperture, 19.0, 31, side="near")
    np.testing.assert_allclose(near, np.rot90(far, 2), atol=1e-7)
    if shape in ("triangle", "pentagon", "star"):  # odd symmetry: near differs from far
        assert np.abs(near - far).sum() > 0.1


def test_light_projects_to_frame_centre():
    """The kernel's centroid is the light's projection ((size-1)/2, (size-1)/2)."""
    for size in (31, 32):
        kernel = render_kernel(make_aperture("square", 0.0), 9.0, size)
        rows, cols = np.indices(kernel.shape)
        assert (kernel * cols).sum() == pytest.approx((size - 1) / 2, abs=1e-5)
        assert (kernel * rows).sum() == pytest.approx((size - 1) / 2, abs=1e-5)


def test_triangle_at_90_points_up_on_screen():
    """y is up on screen: at 90° a vertex points to row 0 (the top), not the bottom."""
    kernel = render_kernel(make_aperture("triangle", 90.0), 40.0, 64)
    top, bottom = kernel[:24].sum(), kernel[40:].sum()
    assert top < bottom  # the vertex (narrow part) is at the top; the wide base below


def l1(kernel, reference):
    return float(np.abs(kernel.astype(np.float64) - reference).sum())


@pytest.mark.parametrize(
    "method,sampling,min_rate",
    [
        # Claimed rates: stratified N^-3/4, independent N^-1/2; asserted with margin
        # over two decades of samples (a ratio of 100^rate in L1).
        ("mc", "stratified", 0.65),
        ("mc", "independent", 0.42),
        ("raster", "stratified", 0.65),
    ],
)
def test_sampling_methods_converge_to_exact(gpu, method, sampling, min_rate):
    exact = render_kernel(make_aperture("hexagon", 20.0), 64.0, 128).astype(np.float64)
    errors = [
        l1(render_kernel(make_aperture("hexagon", 20.0), 64.0, 128, method=method, sampling=sampling, samples=n, seed=3), exact)
        for n in (10**5, 10**7)
    ]
    rate = math.log(errors[0] / errors[1]) / math.log(100.0)
    assert rate >= min_rate, f"{method}/{sampling}: L1 {errors} gives rate {rate:.2f} < {min_rate}"
    assert errors[1] < 0.02


@pytest.mark.parametrize("method", ["mc", "raster"])
@pytest.mark.parametrize("shape,params", SHAPE_PARAMS)
def test_sampling_methods_match_exact_for_every_shape(gpu, method, shape, params):
    for side in ("far", "near"):
        aperture = make_aperture(shape, 41.0, **params)
        exact = render_kernel(aperture, 24.0, 40, side=side).astype(np.float64)
        sampled = render_kernel(aperture, 24.0, 40, side=side, method=method, samples=4 * 10**6)
        assert sampled.sum() == pytest.approx(1.0, abs=1e-5)
        assert l1(sampled, exact) < 0.01, f"{method} {shape} {side}"


def test_mc_same_seed_same_kernel(gpu):
    a = render_kernel(make_aperture("star", 5.0), 30.0, 48, method="mc", samples=10**5, seed=11)
    b = render_kernel(make_aperture("star", 5.0), 30.0, 48, method="mc", samples=10**5, seed=11)
    c = render_kernel(make_aperture("star", 5.0), 30.0, 48, method="mc", samples=10**5, seed=12)
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).sum() > 0


def test_samples_reported_are_samples_drawn(gpu):
    kernel = compute_kernel(make_aperture("circle", 0.0), 20.0, 32, method="mc", samples=1000)
    assert kernel.samples == 32 * 32  # stratified: rounded up to a square, m = 32
    assert "Vulkan" in kernel.device or "OpenGL" in kernel.device or kernel.device


@pytest.mark.parametrize("method", list(METHODS))
def test_tiny_disc_half_pixel(request, method):
    if method != "exact":
        request.getfixturevalue("gpu")
    kernel = render_kernel(make_aperture("hexagon", 0.0), 0.5, 8, method=method, samples=10**5)
    assert kernel.sum() == pytest.approx(1.0, abs=1e-6)
    # Even size: the light sits on the corner of the four central pixels.
    assert kernel[3:5, 3:5].sum() == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(kernel[3:5, 3:5], 0.25, atol=0.01 if method != "exact" else 1e-6)


def test_huge_disc_1000px():
    kernel = compute_kernel(make_aperture("pentagon", 10.0), 1000.0, 1200)  # circumradius 575 px
    assert kernel.clipped_fraction == 0.0
    assert kernel.image.sum() == pytest.approx(1.0, abs=1e-5)
    assert np.all(np.isfinite(kernel.image)) and kernel.image.min() >= 0.0
    interior = kernel.image[600, 600]
    assert interior == pytest.approx(1.0 / (math.pi * 1000.0**2 / 4), rel=1e-6)


def test_huge_disc_1000px_mc(gpu):
    exact = render_kernel(make_aperture("circle", 0.0), 1000.0, 1024).astype(np.float64)
    sampled = render_kernel(make_aperture("circle", 0.0), 1000.0, 1024, method="mc", samples=2 * 10**7)
    # 25 samples a pixel; independent samples would give L1 ≈ √(pixels / N) ≈ 0.2.
    assert l1(sampled, exact) < 0.08


@pytest.mark.parametrize("method", list(METHODS))
def test_frame_smaller_than_disc_is_clipped_and_says_so(request, method):
    if method != "exact":
        request.getfixturevalue("gpu")
    with pytest.warns(KernelClippedWarning, match=r"kernel clipped: .*% of the light"):
        kernel = compute_kernel(make_aperture("square", 0.0), 40.0, 16, method=method, samples=10**5)
    assert kernel.image.sum() == pytest.approx(1.0, abs=1e-6)
    lost = 1 - 16 * 16 / (math.pi * 40.0**2 / 4)
    assert kernel.clipped_fraction == pytest.approx(lost, rel=1e-9)


def test_unclipped_kernel_gives_no_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        render_kernel(make_aperture("hexagon", 0.0), 30.0, 34)  # circumradius 16.5 px < 17


@pytest.mark.parametrize("angle_pair", [(0.0, 60.0), (-30.0, 30.0), (390.0, 30.0), (60.0 - 1e-6, -1e-6)])
def test_angles_equivalent_modulo_symmetry(angle_pair):
    a, b = (render_kernel(make_aperture("hexagon", angle), 30.0, 40) for angle in angle_pair)
    np.testing.assert_allclose(a, b, atol=1e-7)


@pytest.mark.parametrize("aspect", [0.01, 100.0])
def test_extreme_slit_aspects(aspect):
    with pytest.warns(KernelClippedWarning):
        kernel = render_kernel(make_aperture("slit", 0.0, aspect=aspect), 20.0, 64)
    assert np.all(np.isfinite(kernel)) and kernel.sum() == pytest.approx(1.0, abs=1e-6)
    # A thin slit: all light in one column (aspect 0.01) or one row (aspect 100).
    axis = 0 if aspect < 1 else 1
    profile = kernel.sum(axis=axis)
    assert profile.max() > 0.45  # centred between two pixels of an even frame: two halves


@pytest.mark.parametrize(
    "kwargs,parameter",
    [
        (dict(shape="hexgon"), "shape"),
        (dict(size=0), "size"),
        (dict(size=2.5), "size"),
        (dict(diameter_px=float("nan")), "diameter_px"),
        (dict(diameter_px=-3.0), "diameter_px"),
        (dict(diameter_px=float("inf")), "diameter_px"),
        (dict(angle_deg=float("nan")), "angle_deg"),
        (dict(side="behind"), "side"),
        (dict(method="magic"), "method"),
        (dict(samples=0), "samples"),
        (dict(shape="ngon"), "blades"),
        (dict(shape="slit", aspect=0.0), "aspect"),
    ],
)
def test_bad_parameters_raise_value_error_naming_them(kwargs, parameter):
    args = dict(shape="hexagon", angle_deg=0.0, diameter_px=20.0, size=32)
    args.update(kwargs)
    with pytest.raises(ValueError, match=parameter):  # the aperture's own, from make_aperture; the kernel's from render_kernel
        features = {name: args.pop(name) for name in ("blades", "aspect") if name in args}
        aperture = make_aperture(args.pop("shape"), args.pop("angle_deg"), **features)
        render_kernel(aperture, args.pop("diameter_px"), args.pop("size"), **args)


# --- limits: the adapter's, the sample counts', the tolerance's ---------------------------------


def test_mc_counted_in_bands_equals_one_pass(gpu):
    """A frame larger than one storage binding is counted band by band: the same samples, the same kernel."""
    from bokehfit.kernels.mc import mc_counts

    aperture = make_aperture("star", 10.0)
    whole, drawn = mc_counts(aperture, 18.0, 40, 20_000, 7, "stratified")
    banded, drawn_banded = mc_counts(aperture, 18.0, 40, 20_000, 7, "stratified", max_band_bytes=4 * 40 * 7)  # 6 bands
    assert drawn == drawn_banded and whole.sum() > 0.9 * drawn
    np.testing.assert_array_equal(banded, whole)


def test_mc_band_rows_follow_the_adapter_limits():
    """8192² u32 is 256 MiB: on an adapter with 128 MiB bindings, two bands; one row too wide is refused."""
    from bokehfit.errors import InputError
    from bokehfit.kernels.mc import band_rows

    limits = {"max-storage-buffer-binding-size": 2**27, "max-buffer-size": 2**31}
    assert band_rows(limits, 8192) == 4096
    assert band_rows(limits, 1024) == 1024
    with pytest.raises(InputError, match=r"size must be at most 1024 for method 'mc'"):
        band_rows({"max-storage-buffer-binding-size": 4096, "max-buffer-size": 2**31}, 2000)


def test_raster_sub_pixel_disc_at_the_default_sample_count(gpu):
    """2²² samples over a 0.5-px disc ask for 2·10⁷ super-samples a pixel: capped, not a crash."""
    kernel = compute_kernel(make_aperture("hexagon", 0.0), 0.5, 8, method="raster")
    assert kernel.image.sum() == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(kernel.image[3:5, 3:5], 0.25, atol=0.01)
    assert 0 < kernel.samples <= 2**22


def test_samples_beyond_the_largest_stratified_grid_are_refused_before_the_gpu():
    from bokehfit.errors import InputError

    with pytest.raises(InputError, match=r"^samples must be an integer in \[1, 2147395600\] \(got 2147483648\)"):
        render_kernel(make_aperture("hexagon", 0.0), 20.0, 32, method="mc", samples=2**31)


@pytest.mark.parametrize("method", [None, "exact"])
def test_unreachable_tolerance_names_the_smallest(method):
    from bokehfit.errors import InputError

    with pytest.raises(InputError, match=r"^tolerance must be at least 5.96e-08, the float32 rounding"):
        render_kernel(make_aperture("hexagon", 0.0), 64.0, 128, method=method, tolerance=1e-300)


def test_tolerance_beyond_a_sampling_method_names_its_smallest():
    from bokehfit.errors import InputError
    from bokehfit.kernels.accuracy import predicted_l1

    smallest = predicted_l1("mc", "stratified", 64.0, 46340**2)
    with pytest.raises(InputError, match=rf"^tolerance must be at least {smallest:.3g} for method 'mc' on a 64-px disc"):
        render_kernel(make_aperture("hexagon", 0.0), 64.0, 128, method="mc", tolerance=1e-6)


@pytest.mark.parametrize("diameter", [12.0, 60.0, 150.0, 500.0])
def test_auto_draws_a_usual_kernel_exactly_without_a_gpu(diameter):
    # A kernel drawn on its own: exact costs milliseconds, a GPU's start-up most of a second.
    size = int(diameter * 1.3) + 9
    kernel = compute_kernel(make_aperture("pentagon", 20.0), diameter, size, method="auto", tolerance=0.01)
    assert kernel.method == "exact" and kernel.samples is None and kernel.device is None
    assert kernel.setup_s < 1e-3  # nothing to start
    np.testing.assert_array_equal(kernel.image, render_kernel(make_aperture("pentagon", 20.0), diameter, size))


def test_auto_counts_the_start_up_that_a_batch_shares():
    from bokehfit.kernels.accuracy import plan_kernel

    # A large rim kernel is tabulated on 8×8 sub-pixels: costly enough that a sampling
    # method wins even with its device's start-up counted.
    rim = make_aperture("hexagon", 0.0, rim=0.3)
    alone = plan_kernel(rim, 600.0, 700, 0.01, count_startup=True)
    assert alone.method != "exact"
    # Where exact costs a few milliseconds, it wins for a kernel drawn alone; in a batch
    # (no start-up counted) the sampling methods' bare per-kernel cost is what counts.
    pentagon = make_aperture("pentagon", 0.0)
    assert plan_kernel(pentagon, 100.0, 127, 0.01, count_startup=True).method == "exact"
    shared = plan_kernel(rim, 600.0, 700, 0.01)
    assert shared.predicted_time_s < alone.predicted_time_s


def test_auto_without_tolerance_is_exact():
    kernel = compute_kernel(make_aperture("star", 0.0), 30.0, 49, method="auto")
    assert kernel.method == "exact"


def test_unknown_method_lists_auto():
    from bokehfit.errors import InputError

    with pytest.raises(InputError, match=r"^method must be one of exact, mc, raster, auto \(got 'fastest'\)"):
        compute_kernel(make_aperture("star", 0.0), 30.0, 49, method="fastest")
