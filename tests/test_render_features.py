"""The real-lens aperture features (design.md §3b) in the renderers: each one shows in a disc.

A single point light in a 96-px frame (the lens of tests/test_render.py: a light
at infinity makes a disc of 35.6 px) is splatted through the aperture with one
feature on, and the disc is measured: its outline against the exact model
(:meth:`bokehfit.apertures.Aperture.area`, the exact kernel), its moments, its
light. A near light (half the focus distance: the same blur) checks that the
near disc shows −rim and −chromatic. The path tracer gets the vignetting's
darkening towards the corners, the colour pick's unbiasedness and the colour's
flip across the focus plane (its probe ray). A custom mask (its CDF tables
bound as the Monte-Carlo kernel binds them) is checked in both renderers: against
its exact kernel, and as a rectangle against the slit of the same shape. Small
renders: the file runs in well under a minute on lavapipe.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bokehfit.apertures import make_aperture
from bokehfit.kernels import render_kernel
from bokehfit.scene import Material, PointLight, PointScene, Pose, Quad, Scene, build_scene, make_lens, make_settings, render
from test_mask import ring_mask

pytestmark = pytest.mark.gpu

FRAME = 96
SENSOR_WIDTH_MM = 36.0
#: 100 mm at f/1.5 focused at 0.5 m: a light at infinity (or at 0.25 m) is a 35.6 px disc.
LENS = dict(focal_length_mm=100.0, fstop=1.5, focus_distance_m=0.5)
#: The Cornell box's own focus distance (the command line's default).
CORNELL_FOCUS_M = build_scene("cornell").default_focus_m
CIRCLE = make_aperture("circle")
FAR, NEAR = math.inf, 0.25
DIAMETER_PX = (100.0**2 / 1.5) / 500.0 * FRAME / SENSOR_WIDTH_MM
SPP = 32
#: Masks are the pixels above this fraction of the disc's plateau.
MASK_LEVEL = 0.5


def render_light(x=0.5, y=0.5, depth=FAR, *, aperture=CIRCLE, spp=SPP, seed=0) -> np.ndarray:
    """Linear RGB image of one point light at (x, y) (fractions of the frame) and ``depth`` through ``aperture``."""
    scene = PointScene("point", (PointLight(x, y, depth),))
    return render(scene, make_lens(aperture, **LENS), make_settings(FRAME, FRAME, spp, seed)).image


def plateau_mask(image: np.ndarray) -> np.ndarray:
    plateau = float(np.median(image[image > 0.5 * image.max()]))
    return image > MASK_LEVEL * plateau


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.logical_and(a, b).sum() / np.logical_or(a, b).sum())


def moments(channel: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Centroid (x, y) in pixels and the standard deviations along x and y of a disc's light."""
    rows, cols = np.indices(channel.shape)
    total = channel.sum()
    cx, cy = (cols * channel).sum() / total, (rows * channel).sum() / total
    sx = math.sqrt(((cols - cx) ** 2 * channel).sum() / total)
    sy = math.sqrt(((rows - cy) ** 2 * channel).sum() / total)
    return np.array([cx, cy]), sx, sy


def radius_of_gyration(channel: np.ndarray) -> float:
    _, sx, sy = moments(channel)
    return math.hypot(sx, sy)


def field_position(x: float, y: float) -> tuple[float, float]:
    """q of a light at (x, y) (fractions of a square frame): from the centre in half-diagonals, y up."""
    half_diagonal = 0.5 * math.hypot(FRAME, FRAME)
    return ((x - 0.5) * FRAME / half_diagonal, (0.5 - y) * FRAME / half_diagonal)


def test_roundness_one_makes_a_triangle_round(gpu):
    image = render_light(aperture=make_aperture("triangle", roundness=1.0)).mean(axis=-1)
    straight = render_light(aperture=make_aperture("triangle")).mean(axis=-1)
    circle = plateau_mask(render_kernel(make_aperture("circle", 0.0), DIAMETER_PX, FRAME, method="exact"))
    assert iou(plateau_mask(image), circle) >= 0.95
    assert iou(plateau_mask(straight), circle) < 0.85, "the straight triangle must differ from the circle"


def test_rounded_blades_match_the_exact_outline(gpu):
    """A 9-blade lens at roundness 0.5, against the area coverage of the model's own outline."""
    aperture = make_aperture("ngon", 10.0, blades=9, roundness=0.5)
    image = render_light(aperture=make_aperture("ngon", 10.0, blades=9, roundness=0.5)).mean(axis=-1)
    kernel = render_kernel(aperture, diameter_px=DIAMETER_PX, size=FRAME, method="exact")
    assert iou(plateau_mask(image), plateau_mask(kernel)) >= 0.97


def test_squeeze_makes_the_disc_taller_than_wide(gpu):
    _, sx, sy = moments(render_light(aperture=make_aperture("circle", squeeze=1.5)).mean(axis=-1))
    # x/√s and y·√s: the standard deviations' ratio is the squeeze itself.
    assert sy / sx == pytest.approx(1.5, rel=0.03)


def test_vignetting_cuts_a_corner_disc_and_not_the_centre(gpu):
    vignetting = dict(radius=1.0, shift=2.0)
    centre_plain = render_light(aperture=CIRCLE)
    centre_cut = render_light(aperture=make_aperture("circle", vignetting=vignetting))
    # At the centre the barrel (radius R0, centred on the axis) is the circle itself: nothing is cut.
    assert centre_cut.sum() == pytest.approx(centre_plain.sum(), rel=1e-3)

    x, y = 0.72, 0.28  # up and to the right; the disc stays inside the frame
    corner_plain = render_light(x, y, aperture=CIRCLE)
    corner_cut = render_light(x, y, aperture=make_aperture("circle", vignetting=vignetting))
    passed = corner_cut.sum() / corner_plain.sum()
    expected = make_aperture("circle", vignetting=vignetting).area(field_position(x, y))
    assert expected < 0.9, "the case must cut the disc"
    assert passed == pytest.approx(expected, abs=0.02)
    # A far disc keeps the side towards the corner (the barrel sits at +shift·R0·q): its centroid moves out.
    plain_centre, _, _ = moments(corner_plain.mean(axis=-1))
    cut_centre, _, _ = moments(corner_cut.mean(axis=-1))
    outward = np.array([x - 0.5, y - 0.5])
    assert np.dot(cut_centre - plain_centre, outward) > 0.5


def test_vignetting_of_a_near_disc_is_turned_by_180_degrees(gpu):
    x, y = 0.72, 0.28
    vignetting = dict(radius=1.0, shift=2.0)
    plain = render_light(x, y, NEAR, aperture=CIRCLE)
    cut = render_light(x, y, NEAR, aperture=make_aperture("circle", vignetting=vignetting))
    assert cut.sum() / plain.sum() == pytest.approx(make_aperture("circle", vignetting=vignetting).area(field_position(x, y)), abs=0.02)
    shift, _, _ = moments(cut.mean(axis=-1))
    plain_centre, _, _ = moments(plain.mean(axis=-1))
    assert np.dot(shift - plain_centre, np.array([x - 0.5, y - 0.5])) < -0.5, "a near disc keeps the side towards the centre"


def ring_and_centre(channel: np.ndarray) -> tuple[float, float]:
    """Mean light of the disc's centre (ρ < 0.3) and of its outer ring (0.75 < ρ < 0.9)."""
    rows, cols = np.indices(channel.shape)
    centre, _, _ = moments(channel)
    rho = np.hypot(cols + 0.5 - centre[0] - 0.5, rows + 0.5 - centre[1] - 0.5) / (DIAMETER_PX / 2.0)
    return float(channel[rho < 0.3].mean()), float(channel[(rho > 0.75) & (rho < 0.9)].mean())


@pytest.mark.parametrize("depth,bright_rim", [(FAR, True), (NEAR, False)], ids=["far", "near"])
def test_rim_brightens_the_rim_of_a_far_disc_and_the_centre_of_a_near_one(gpu, depth, bright_rim):
    rim = 0.6
    centre, ring = ring_and_centre(render_light(depth=depth, aperture=make_aperture("circle", rim=rim)).mean(axis=-1))
    # The profile 1 + rim·(2ρ² − 1): about 0.46 at the centre and 1.3 on the ring (far); mirrored near.
    assert (ring > 2.0 * centre) if bright_rim else (centre > 2.0 * ring), (centre, ring)
    flat_centre, flat_ring = ring_and_centre(render_light(depth=depth).mean(axis=-1))
    assert flat_ring == pytest.approx(flat_centre, rel=0.1)


@pytest.mark.parametrize("depth,sign", [(FAR, 1.0), (NEAR, -1.0)], ids=["far", "near"])
def test_chromatic_scales_the_red_and_blue_discs(gpu, depth, sign):
    red, blue = 0.1, -0.1
    image = render_light(depth=depth, aperture=make_aperture("circle", chromatic=dict(red=red, blue=blue)))
    size = [radius_of_gyration(image[..., c]) for c in range(3)]
    assert size[0] / size[1] == pytest.approx(1.0 + sign * red, rel=0.01)
    assert size[2] / size[1] == pytest.approx(1.0 + sign * blue, rel=0.01)
    # Every channel keeps the light's total.
    assert image[..., 0].sum() == pytest.approx(image[..., 1].sum(), rel=1e-3)


# --- the path tracer --------------------------------------------------------------------------


def test_path_traced_vignetting_darkens_the_corners_more_than_the_centre(gpu):
    settings = make_settings(48, 48, 16)
    cut_aperture = make_aperture("circle", vignetting=dict(radius=1.0, shift=3.0))
    plain = render("cornell", make_lens(CIRCLE, fstop=1.4, focus_distance_m=CORNELL_FOCUS_M), settings).image.mean(axis=-1)
    cut = render("cornell", make_lens(cut_aperture, fstop=1.4, focus_distance_m=CORNELL_FOCUS_M), settings).image.mean(axis=-1)
    rows, cols = np.indices(plain.shape)
    q = np.hypot(cols + 0.5 - 24.0, rows + 0.5 - 24.0) / math.hypot(24.0, 24.0)
    centre, corners = q < 0.15, q > 0.8
    # Passed light at q: the circle's overlap with the barrel at 3·R0·q (radius R0 each).
    ratio_centre = cut[centre].sum() / plain[centre].sum()
    ratio_corners = cut[corners].sum() / plain[corners].sum()
    assert ratio_centre > 0.6 and ratio_corners < 0.25, (ratio_centre, ratio_corners)


def test_path_traced_colour_and_rim_keep_the_light(gpu):
    """One channel a sample (×3) and the near/far probe: the image's mean is unbiased.

    Seeds 0 to 3 came within 4.5 % per channel at this budget (the Cornell box's
    caustic-free but noisy light); the bound leaves room for that noise.
    """
    settings = make_settings(24, 24, 1024)
    featured_aperture = make_aperture("hexagon", chromatic=dict(red=0.05, blue=-0.05), rim=0.5)
    plain = render("cornell", make_lens(make_aperture("hexagon"), fstop=2.0, focus_distance_m=CORNELL_FOCUS_M), settings)
    featured = render("cornell", make_lens(featured_aperture, fstop=2.0, focus_distance_m=CORNELL_FOCUS_M), settings)
    assert featured.nonfinite_pixels == 0
    mean_plain = plain.image.reshape(-1, 3).mean(axis=0)
    mean_featured = featured.image.reshape(-1, 3).mean(axis=0)
    np.testing.assert_allclose(mean_featured, mean_plain, rtol=0.08)
    assert not np.array_equal(featured.image, plain.image)


def glowing_square(depth_m: float, side_m: float) -> Scene:
    """An emitting square facing the camera on the view axis at ``depth_m``, on black."""
    glow = Material("glow", "emitter", emission=(1.0, 1.0, 1.0))
    h = side_m / 2.0
    quad = Quad((-h, -h, depth_m), (0.0, side_m, 0.0), (side_m, 0.0, 0.0), "glow")
    return Scene("square", (glow,), quads=(quad,), pose=Pose((0.0, 0.0, 0.0)))


@pytest.mark.parametrize("depth,sign", [(2.0, 1.0), (0.3, -1.0)], ids=["far", "near"])
def test_path_traced_colour_flips_across_the_focus_plane(gpu, depth, sign):
    """A small glowing square behind and in front of the focus plane: red larger than blue behind, smaller in front.

    The square's sharp image is about 5 px; its disc about 25 px. Colours ±0.3
    make the red and blue discs 1.3 and 0.7 times green's (reversed in front),
    far beyond the noise of the disc's moments at this budget.
    """
    scene = glowing_square(depth, 0.04 * depth / 2.0)
    lens = make_lens(make_aperture("circle", chromatic=dict(red=0.3, blue=-0.3)), **LENS)
    image = render(scene, lens, make_settings(FRAME, FRAME, 256)).image
    red, green, blue = (radius_of_gyration(image[..., c]) for c in range(3))
    if sign > 0:
        assert red > 1.15 * green > 1.15**2 * blue, (red, green, blue)
    else:
        assert blue > 1.15 * green > 1.15**2 * red, (red, green, blue)


# --- the custom mask (design.md §3b) in both renderers ---------------------------------------

def grey_mask() -> np.ndarray:
    """An asymmetric grey mask: a disc of 0.9 with a dimmer centre, one corner cut off, one brighter cell."""
    return ring_mask(centre=0.6)


#: A mask of 2 × 8 equal cells is the slit of aspect 0.5 (aspect wide, 1/aspect tall; design.md §3).
RECTANGLE_MASK = np.ones((8, 2))
RECTANGLE_SLIT = dict(shape="slit", aspect=0.5)
#: L1 (kernel normalised to 1) of a 32-spp splat of a 35.6 px disc against its exact kernel:
#: the stratified noise, 0.050 for the circle and 0.058 for grey_mask() on lavapipe.
SPLAT_L1 = 0.08


def normalised(image: np.ndarray) -> np.ndarray:
    return image / image.sum()


@pytest.mark.parametrize("depth,side", [(FAR, "far"), (NEAR, "near")], ids=["far", "near"])
def test_mask_splat_matches_the_exact_mask_kernel(gpu, depth, side):
    """Points renderer: the disc of a grey, asymmetric mask at 30° is its exact kernel, turned by 180° when near."""
    mask = grey_mask()
    image = render_light(depth=depth, aperture=make_aperture("mask", 30.0, mask=mask)).mean(axis=-1)
    kernel = render_kernel(make_aperture("mask", 30.0, mask=mask), DIAMETER_PX, FRAME, side=side)
    other = render_kernel(make_aperture("mask", 30.0, mask=mask), DIAMETER_PX, FRAME, side="near" if side == "far" else "far")
    assert iou(plateau_mask(image), plateau_mask(kernel)) >= 0.95
    error = np.abs(normalised(image) - kernel).sum()
    assert error < SPLAT_L1, error
    assert np.abs(normalised(image) - other).sum() > 2.0 * error, "the other side's disc must not fit as well"


def test_rectangle_mask_splats_as_the_slit(gpu):
    """Points renderer: a mask of equal cells is its rectangle, the slit: the same image to far below the noise."""
    mask = render_light(aperture=make_aperture("mask", 20.0, mask=RECTANGLE_MASK)).mean(axis=-1)
    slit = render_light(aperture=make_aperture(angle_deg=20.0, **RECTANGLE_SLIT)).mean(axis=-1)
    reseeded = render_light(aperture=make_aperture(angle_deg=20.0, **RECTANGLE_SLIT), seed=1).mean(axis=-1)
    noise = np.abs(normalised(slit) - normalised(reseeded)).sum()
    assert noise > 0.02, "two seeds must differ"
    assert np.abs(normalised(mask) - normalised(slit)).sum() < 0.25 * noise
    assert mask.sum() == pytest.approx(slit.sum(), rel=1e-3)  # the same light


@pytest.mark.parametrize("depth", [2.0, 0.3], ids=["far", "near"])
def test_path_traced_rectangle_mask_is_the_slit(gpu, depth):
    """Path tracer: a glowing square seen through the rectangle mask and through the slit gives one image.

    The slit turned by 90° and the slit at another seed show how far apart
    two different apertures and two noise draws lie (L1 about 1.6 and 0.67
    at 64 spp).
    """
    scene = glowing_square(depth, 0.04 * depth / 2.0)
    settings, reseeding = make_settings(FRAME, FRAME, 64), make_settings(FRAME, FRAME, 64, seed=1)
    mask = render(scene, make_lens(make_aperture("mask", 20.0, mask=RECTANGLE_MASK), **LENS), settings)
    assert mask.lens.aperture.mask is not None and mask.nonfinite_pixels == 0
    slit_lens = make_lens(make_aperture(angle_deg=20.0, **RECTANGLE_SLIT), **LENS)
    slit = render(scene, slit_lens, settings).image.mean(axis=-1)
    reseeded = render(scene, slit_lens, reseeding).image.mean(axis=-1)
    turned = render(scene, make_lens(make_aperture(angle_deg=110.0, **RECTANGLE_SLIT), **LENS), settings).image.mean(axis=-1)
    image = mask.image.mean(axis=-1)
    noise = np.abs(normalised(slit) - normalised(reseeded)).sum()
    assert np.abs(normalised(image) - normalised(slit)).sum() < 0.25 * noise
    assert np.abs(normalised(image) - normalised(turned)).sum() > 1.5 * noise


def test_path_traced_grey_mask_keeps_the_light(gpu):
    """Path tracer, Cornell box: a grey mask's image has the circle's mean (unit transmitted area, radiance averaged).

    Seeds 0 to 2 came within 0.7 % per channel; that the mask is drawn, not a
    stub, is what the glowing square above shows.
    """
    settings = make_settings(24, 24, 256)
    plain = render("cornell", make_lens(CIRCLE, fstop=2.0, focus_distance_m=CORNELL_FOCUS_M), settings)
    plain = plain.image.reshape(-1, 3).mean(axis=0)
    mask_lens = make_lens(make_aperture("mask", 15.0, mask=grey_mask()), fstop=2.0, focus_distance_m=CORNELL_FOCUS_M)
    masked = render("cornell", mask_lens, settings)
    assert masked.nonfinite_pixels == 0
    np.testing.assert_allclose(masked.image.reshape(-1, 3).mean(axis=0), plain, rtol=0.03)
