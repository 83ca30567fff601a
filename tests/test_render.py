"""The WGSL renderer: the camera's defocus against the exact kernels, the path tracer, tiling, the CLI.

Every render here is tiny (lavapipe on two CPU cores runs the whole file in
about a minute). Shapes are checked against ``bokehfit.kernels.render_kernel``
(method ``exact``) at the blur diameter that ``bokehfit.optics.coc_mm`` with
``lens_model="pinhole"`` predicts, converted to pixels with the sensor width.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys

import cv2
import numpy as np
import OpenEXR
import pytest

from bokehfit.apertures import make_aperture
from bokehfit.errors import InputError
from bokehfit.kernels import render_kernel
from bokehfit.optics import coc_mm
from bokehfit.scene import (
    Material,
    PointLight,
    PointScene,
    Pose,
    Quad,
    Scene,
    build_scene,
    make_lens,
    make_settings,
    render,
    tile_plan,
)

pytestmark = pytest.mark.gpu

SENSOR_WIDTH_MM = 36.0
#: Masks are the pixels above this fraction of the disc's plateau (design: half).
MASK_LEVEL = 0.5
MIN_IOU = 0.95

#: Far-light test: a 100 mm lens at f/1.5 focused at 0.5 m makes a light at infinity
#: a disc of (100²/1.5)·(1/500 mm) = 13.3 mm on the sensor, 35.6 px in a 96-px frame.
POINT_FRAME = 96
POINT_LENS = dict(focal_length_mm=100.0, fstop=1.5, focus_distance_m=0.5)
#: The focus distances of the named scenes (their own, which the command line uses unless told).
CORNELL_FOCUS_M = build_scene("cornell").default_focus_m
POINTS_FOCUS_M = build_scene("points").default_focus_m

#: Every shape, at angles that no symmetry maps back onto 0 (the slit at aspect 0.4 so that it fits the frame).
SHAPE_CASES = [
    ("circle", 0.0, {}),
    ("square", 10.0, {}),
    ("slit", 25.0, {"aspect": 0.4}),
    ("triangle", 15.0, {}),
    ("pentagon", 5.0, {}),
    ("hexagon", 20.0, {}),
    ("star", 12.0, {}),
    ("ngon", 8.0, {"blades": 7}),
]


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.logical_and(a, b).sum() / np.logical_or(a, b).sum())


def plateau_mask(image: np.ndarray) -> np.ndarray:
    """Pixels above MASK_LEVEL of the plateau (the median of the pixels above half the peak)."""
    plateau = float(np.median(image[image > 0.5 * image.max()]))
    return image > MASK_LEVEL * plateau


def expected_diameter_px(lens: dict, depth_m: float, width_px: int) -> float:
    c = coc_mm(lens["fstop"], lens["focal_length_mm"], lens["focus_distance_m"], depth_m, lens_model="pinhole")
    return c * width_px / SENSOR_WIDTH_MM


def render_point(shape, angle, params, depth_m, *, spp=64, seed=0):
    scene = PointScene("point", (PointLight(0.5, 0.5, depth_m),))
    lens = make_lens(make_aperture(shape, angle, **params), **POINT_LENS)
    result = render(scene, lens, make_settings(POINT_FRAME, POINT_FRAME, spp, seed))
    return result.image.mean(axis=-1)


@pytest.mark.parametrize("shape,angle,params", SHAPE_CASES, ids=[c[0] for c in SHAPE_CASES])
def test_far_point_light_shows_the_aperture(gpu, shape, angle, params):
    image = render_point(shape, angle, params, math.inf)
    diameter = expected_diameter_px(POINT_LENS, math.inf, POINT_FRAME)
    assert 35.0 < diameter < 36.0  # the geometry stated above
    kernel = render_kernel(make_aperture(shape, angle, **params), diameter, POINT_FRAME, method="exact")
    score = iou(plateau_mask(image), plateau_mask(kernel))
    assert score >= MIN_IOU, f"{shape} {angle}°: IoU {score:.3f} against the exact kernel of {diameter:.2f} px"


def test_near_point_light_is_turned_by_180_degrees(gpu):
    # At half the focus distance the blur equals that at infinity (|1/d − 1/d_f| = 1/d_f).
    depth = POINT_LENS["focus_distance_m"] / 2.0
    diameter = expected_diameter_px(POINT_LENS, depth, POINT_FRAME)
    assert diameter == pytest.approx(expected_diameter_px(POINT_LENS, math.inf, POINT_FRAME))
    mask = plateau_mask(render_point("triangle", 15.0, {}, depth))
    triangle = make_aperture("triangle", 15.0)
    near = plateau_mask(render_kernel(triangle, diameter, POINT_FRAME, method="exact", side="near"))
    far = plateau_mask(render_kernel(triangle, diameter, POINT_FRAME, method="exact", side="far"))
    assert iou(mask, near) >= MIN_IOU
    assert iou(mask, far) < 0.8, "a triangle and its 180° turn must be told apart"


def test_disc_diameters_follow_the_blur_formula(gpu):
    """Two lights, at 1 m and at infinity, focus 0.5 m: |1/d − 1/d_f| is 1 and 2 m⁻¹."""
    lens = dict(focal_length_mm=100.0, fstop=2.0, focus_distance_m=0.5)
    width, height = 192, 96
    scene = PointScene("pair", (PointLight(0.25, 0.5, 1.0), PointLight(0.75, 0.5, math.inf)))
    image = render(scene, make_lens(make_aperture("circle"), **lens), make_settings(width, height, 64)).image.mean(axis=-1)
    measured = []
    for half in (image[:, : width // 2], image[:, width // 2 :]):
        area = plateau_mask(half).sum()
        measured.append(math.sqrt(4.0 * area / math.pi))
    expected = [expected_diameter_px(lens, d, width) for d in (1.0, math.inf)]
    assert measured[1] / measured[0] == pytest.approx(expected[1] / expected[0], rel=0.05)
    for got, want in zip(measured, expected):
        assert got == pytest.approx(want, rel=0.05)


def edge_scene(depth_m: float) -> Scene:
    """An emitting half-plane (the right half of the view) at ``depth_m``, facing the camera, on black.

    The camera stands at the origin looking along +z with y up, so its right is −x.
    """
    reach = 100.0 * depth_m  # the other edges lie far outside the view
    glow = Material("glow", "emitter", emission=(1.0, 1.0, 1.0))
    quad = Quad((-reach, -reach, depth_m), (0.0, 2.0 * reach, 0.0), (reach, 0.0, 0.0), "glow")
    return Scene("edge", (glow,), quads=(quad,), pose=Pose((0.0, 0.0, 0.0)))


def edge_profile(depth_m, *, width, height=8, spp=256, aperture=None, **lens) -> np.ndarray:
    aperture = make_aperture("circle") if aperture is None else aperture
    result = render(edge_scene(depth_m), make_lens(aperture, **lens), make_settings(width, height, spp))
    assert result.nonfinite_pixels == 0
    return result.image.mean(axis=(0, 2))


def expected_edge_profile(shape, angle, diameter, side, width, oversample=8) -> np.ndarray:
    """Pixel values of a half-plane's edge (at the frame's centre) blurred by the exact kernel.

    The edge spread is the kernel's cumulative column sum; it is evaluated on
    an ``oversample``× finer kernel and averaged over each pixel.
    """
    size = 2 * int(math.ceil(diameter)) + 8
    fine = render_kernel(make_aperture(shape, angle), oversample * diameter, oversample * size, method="exact", side=side)
    cdf = np.concatenate([[0.0], np.cumsum(fine.sum(axis=0, dtype=np.float64))])
    centre = oversample * size / 2.0  # the kernel's centre, in fine columns from the left
    x = np.arange(width)[:, None] + (np.arange(oversample)[None, :] + 0.5) / oversample
    offset = x - width / 2.0  # from the edge, pixels
    return np.interp(offset * oversample + centre, np.arange(len(cdf)), cdf).mean(axis=1)


@pytest.mark.parametrize("depth_m,side", [(0.4, "far"), (0.3, "far"), (0.2 / 1.5, "near")])
def test_path_traced_edge_matches_the_exact_kernel(gpu, depth_m, side):
    """The path tracer's camera: an edge blurs by the aperture's kernel, turned by 180° in front of the focus."""
    lens = dict(focal_length_mm=100.0, fstop=2.0, focus_distance_m=0.2)
    width = 64
    diameter = expected_diameter_px(lens, depth_m, width)
    profile = edge_profile(depth_m, width=width, height=16, spp=1024, aperture=make_aperture("triangle", 0.0), **lens)
    expected = expected_edge_profile("triangle", 0.0, diameter, side, width)
    wrong = expected_edge_profile("triangle", 0.0, diameter, "near" if side == "far" else "far", width)
    # Monte-Carlo noise: 16 rows × 1024 spp of a 0/1 variable, σ ≤ 0.004 per column. A blur
    # 7 % too small or large moves the profile by 0.04; the other side's by 0.11.
    assert np.abs(profile - expected).max() < 0.025, np.round(np.stack([profile, expected]), 3)
    assert np.abs(profile - wrong).max() > 0.07, "the triangle's edge spread must tell far from near"


def width_10_90(profile: np.ndarray) -> float:
    """Distance (pixels) between the 10 % and 90 % crossings of a rising edge, interpolated."""
    low, high = profile[:4].mean(), profile[-4:].mean()
    p = (profile - low) / (high - low)

    def crossing(level: float) -> float:
        i = int(np.argmax(p >= level))  # first pixel at or above the level (i ≥ 1: p starts near 0)
        return i - 1 + (level - p[i - 1]) / (p[i] - p[i - 1])

    return crossing(0.9) - crossing(0.1)


def test_edge_at_the_focus_distance_stays_sharp_at_f1_4(gpu):
    lens = dict(fstop=1.4, focus_distance_m=0.5)  # 35 mm lens, 36 mm sensor
    sharp = width_10_90(edge_profile(0.5, width=64, spp=64, **lens))
    assert sharp <= 1.5, f"edge at the focus distance is {sharp:.2f} px wide (10-90 %)"
    # The same edge at 0.25 m blurs to (35²/1.4)·2 m⁻¹ = 1.75 mm = 3.1 px: the check can fail.
    blurred = width_10_90(edge_profile(0.25, width=64, spp=64, **lens))
    assert blurred > 1.5, f"a defocused edge measured only {blurred:.2f} px"


def test_mean_brightness_does_not_depend_on_the_shape(gpu):
    """Equal area at equal f-stop: the Cornell box's mean is the same through every aperture.

    Each shape is rendered with SEEDS independent seeds of its own. Tolerance:
    4 standard errors of the difference of two such averages, the standard
    error of one render's mean pooled over all renders (about 1.5 % here, so
    the tolerance is about 4 % of the mean).
    """
    seeds = 4
    shapes = (("circle", {}), ("slit", {}), ("triangle", {}), ("star", {}), ("ngon", {"blades": 9}), ("square", {}))
    lenses = {shape: make_lens(make_aperture(shape, 20.0, **params), fstop=1.4, focus_distance_m=CORNELL_FOCUS_M)
              for shape, params in shapes}
    means = {
        shape: [float(render("cornell", lens, make_settings(32, 32, 128, 100 * i + s)).image.mean()) for s in range(seeds)]
        for i, (shape, lens) in enumerate(lenses.items())
    }
    sigma = math.sqrt(np.mean([np.var(m, ddof=1) for m in means.values()]))
    reference = float(np.mean(means["circle"]))
    tolerance = 4.0 * sigma * math.sqrt(2.0 / seeds)
    assert 0.0 < tolerance < 0.06 * reference, "the Monte-Carlo noise must be small enough for the test to mean something"
    for shape, values in means.items():
        mean = float(np.mean(values))
        assert abs(mean - reference) <= tolerance, f"{shape}: mean {mean:.4f} vs circle {reference:.4f} ± {tolerance:.4f}"


def test_fixed_seed_gives_the_same_image(gpu):
    hexagon = make_aperture("hexagon", 20.0)
    lens = make_lens(hexagon, fstop=1.4, focus_distance_m=CORNELL_FOCUS_M)
    a = render("cornell", lens, make_settings(16, 12, 4, seed=3)).image
    b = render("cornell", lens, make_settings(16, 12, 4, seed=3)).image
    c = render("cornell", lens, make_settings(16, 12, 4, seed=4)).image
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    lens = make_lens(hexagon, fstop=1.4, focus_distance_m=POINTS_FOCUS_M)
    p = render("points", lens, make_settings(16, 12, 4, seed=3)).image
    np.testing.assert_array_equal(p, render("points", lens, make_settings(16, 12, 4, seed=3)).image)


#: Focus on the mirror wall: from the camera (z = −0.55 m) to the rear wall (z = 0.555 m).
REAR_WALL_M = 0.555 + 0.55


@pytest.mark.parametrize(
    "params",
    [
        dict(focus_distance_m=REAR_WALL_M),
        dict(fstop=0.7),
        dict(fstop=64.0),
        dict(shape="slit", aspect=0.01),
        dict(shape="slit", aspect=0.01, fstop=0.7),
        dict(width=1, height=1, spp=16),
    ],
    ids=["focus-on-wall", "f0.7", "f64", "aspect0.01", "aspect0.01-f0.7", "1x1"],
)
def test_hard_parameters_give_finite_pixels(gpu, params):
    args = dict(shape="star", fstop=2.8, focus_distance_m=CORNELL_FOCUS_M, spp=4, width=12, height=10)
    args.update(params)
    aperture = make_aperture(args.pop("shape"), aspect=args.pop("aspect", None))
    settings = make_settings(args.pop("width"), args.pop("height"), args.pop("spp"))
    image = render("cornell", make_lens(aperture, **args), settings).image
    assert np.isfinite(image).all()
    assert image.min() >= 0.0 and image.max() > 0.0


def test_points_scene_hard_cases_are_finite(gpu):
    # A light on the focus plane (one sharp pixel), one at infinity, one very near; a needle slit.
    lens = make_lens(make_aperture("slit", aspect=0.01), fstop=0.7, focus_distance_m=POINTS_FOCUS_M)
    result = render("points", lens, make_settings(48, 24, 4), light_depths_m=(0.3, math.inf, 0.01))
    assert np.isfinite(result.image).all()
    assert result.image.max() > 0.0


def test_large_image_is_tiled_within_the_adapter_limits(gpu):
    limits = gpu.device.limits
    tiles = tile_plan(4096, 4096, limits["max-storage-buffer-binding-size"] // 16, 8 * limits["max-compute-workgroups-per-dimension"])
    covered = np.zeros((4096, 4096), dtype=np.uint8)
    for x, y, w, h in tiles:
        assert w * h * 16 <= limits["max-storage-buffer-binding-size"]
        covered[y : y + h, x : x + w] += 1
    assert (covered == 1).all() and len(tiles) > 1
    lens = make_lens(make_aperture("hexagon"), fstop=2.8, focus_distance_m=POINTS_FOCUS_M)
    result = render("points", lens, make_settings(4096, 4096, 1))
    assert result.tiles > 1
    assert np.isfinite(result.image).all() and result.image.max() > 0.0


@pytest.mark.parametrize("scene", ["cornell", "points"])
@pytest.mark.parametrize("max_tile_pixels", [16, 40])
def test_tiles_give_the_untiled_image(gpu, scene, max_tile_pixels):
    lens = make_lens(make_aperture("triangle", 10.0), fstop=1.4, focus_distance_m=build_scene(scene).default_focus_m)
    whole = render(scene, lens, make_settings(20, 13, 3, 5))
    tiled = render(scene, lens, make_settings(20, 13, 3, 5, max_tile_pixels=max_tile_pixels))
    assert whole.tiles == 1 and tiled.tiles > 2
    np.testing.assert_array_equal(tiled.image, whole.image)


def test_bad_lens_parameters_raise_input_error():
    circle = make_aperture("circle")
    for build in (
        lambda: make_aperture("hexgon"),
        lambda: make_lens(circle, fstop=0.0, focus_distance_m=CORNELL_FOCUS_M),
        lambda: make_lens(circle, fstop=float("nan"), focus_distance_m=CORNELL_FOCUS_M),
        lambda: make_lens(circle, fstop=2.8, focus_distance_m=0.0),
        lambda: make_settings(512, 512, 0),
        lambda: make_settings(0, 512, 64),
        lambda: render("cornell", circle),  # a lens is more than its aperture
        lambda: render("cornell", make_lens(circle, fstop=2.8, focus_distance_m=CORNELL_FOCUS_M), dict(spp=4)),
    ):
        with pytest.raises(InputError):
            build()


# --- the command line --------------------------------------------------------------------------


def bokehfit(*args, cwd):
    return subprocess.run([sys.executable, "-m", "bokehfit", *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def test_cli_writes_png_exr_and_json(tmp_path, gpu):
    common = ["render", "--shape", "pentagon", "--angle", "7", "--fstop", "2", "--spp", "4", "--size", "24x16", "--seed", "2"]
    done = bokehfit(*common, "--out", "c.png", "--json", "c.json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "samples/s" in done.stdout and gpu.adapter_name in done.stdout
    assert done.stderr == "", "no progress bar when stderr is not a terminal"
    png = cv2.imread(str(tmp_path / "c.png"), cv2.IMREAD_UNCHANGED)
    assert png.shape == (16, 24, 3) and png.dtype == np.uint8 and png.max() > 0
    stats = json.loads((tmp_path / "c.json").read_text())
    for key in ("samples_per_second", "spp", "width", "height", "time_s", "adapter", "backend"):
        assert key in stats, key
    assert (stats["spp"], stats["width"], stats["height"]) == (4, 24, 16)
    assert stats["samples_per_second"] > 0 and stats["adapter"] == gpu.adapter_name

    done = bokehfit(*common, "--out", "c.exr", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    with OpenEXR.File(str(tmp_path / "c.exr")) as exr:
        channels = exr.channels()  # R, G and B, which the reader groups as "RGB"
        rgb = channels["RGB"].pixels if "RGB" in channels else np.stack([channels[c].pixels for c in "RGB"], axis=-1)
    lens = make_lens(make_aperture("pentagon", 7.0), fstop=2.0, focus_distance_m=CORNELL_FOCUS_M)
    expected = render("cornell", lens, make_settings(24, 16, 4, seed=2)).image
    np.testing.assert_array_equal(rgb, expected)
    assert not list(tmp_path.glob(".c.*")), "temporary files left behind"


def test_cli_real_lens_features(tmp_path, gpu):
    """The §3b flags reach the renderer: the image is the Python API's, and the JSON names them."""
    features = ["--roundness", "0.4", "--squeeze", "1.3", "--vignetting", "1.1,2", "--rim", "0.5", "--chromatic", "0.03,-0.02"]
    common = ["render", "--scene", "points", "--shape", "ngon", "--blades", "9", "--fstop", "1.4", "--spp", "4", "--size", "48x32"]
    done = bokehfit(*common, *features, "--out", "f.exr", "--json", "f.json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    lens = json.loads((tmp_path / "f.json").read_text())["lens"]
    assert (lens["roundness"], lens["squeeze"], lens["rim"]) == (0.4, 1.3, 0.5)
    assert lens["vignetting"] == {"radius": 1.1, "shift": 2.0} and lens["chromatic"] == {"red": 0.03, "blue": -0.02}
    with OpenEXR.File(str(tmp_path / "f.exr")) as exr:
        channels = exr.channels()
        rgb = channels["RGB"].pixels if "RGB" in channels else np.stack([channels[c].pixels for c in "RGB"], axis=-1)
    featured = make_aperture("ngon", blades=9, roundness=0.4, squeeze=1.3, vignetting=dict(radius=1.1, shift=2.0), rim=0.5,
                             chromatic=dict(red=0.03, blue=-0.02))
    settings = make_settings(48, 32, 4)
    expected = render("points", make_lens(featured, fstop=1.4, focus_distance_m=POINTS_FOCUS_M), settings).image
    np.testing.assert_array_equal(rgb, expected)
    plain = render("points", make_lens(make_aperture("ngon", blades=9), fstop=1.4, focus_distance_m=POINTS_FOCUS_M), settings).image
    assert not np.array_equal(rgb, plain)


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--shape", "hexgon"], "shape"),
        (["--fstop", "0"], "fstop"),
        (["--fstop", "-2"], "fstop"),
        (["--fstop", "nan"], "fstop"),
        (["--size", "0x0"], "size"),
        (["--size", "12"], "size"),
        (["--spp", "0"], "spp"),
        (["--focus-distance", "0"], "--focus-distance"),
        (["--focus-distance", "-1"], "--focus-distance"),
        (["--scene", "kitchen"], "scene"),
        (["--scene", "cornell", "--light-depths", "1,2"], "light depths"),
        (["--roundness", "1.5", "--shape", "hexagon"], "--roundness: must be a finite number in [0, 1]"),
        (["--roundness", "0.5"], "roundness applies only to n-gons"),
        (["--squeeze", "0"], "--squeeze: must be"),
        (["--rim", "-2"], "--rim: must be"),
        (["--vignetting", "1.2"], "--vignetting: must be RADIUS,SHIFT"),
        (["--vignetting", "0.5,1"], "--vignetting: must be a finite number in [1, 1000]"),
        (["--chromatic", "0.1,x"], "--chromatic: must be"),
        (["--chromatic", "0.9,0"], "--chromatic: must be a finite number in [-0.5, 0.5]"),
    ],
)
def test_cli_bad_input_one_line_exit_2(tmp_path, args, needle):
    done = bokehfit("render", *args, "--out", "x.png", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert needle in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not (tmp_path / "x.png").exists()


# --- long renders: a cap, an estimate before starting, a bound on the time -----------------------


@pytest.mark.parametrize("scene", ["cornell", "points"])
def test_estimate_is_near_the_time_the_render_takes(gpu, scene):
    from bokehfit.scene import build_scene, estimate_render_s, make_lens, make_settings, render_scene

    built = build_scene(scene)
    lens = make_lens(make_aperture("hexagon"), fstop=2.0, focus_distance_m=built.default_focus_m)
    settings = make_settings(96, 64, 24, 0)
    estimate, rate = estimate_render_s(built, lens, settings)
    actual = render_scene(built, lens, settings)
    assert rate > 0
    # Timings on a shared CPU adapter are noisy: the estimate only has to be the right size.
    assert actual.time_s / 4 < estimate < actual.time_s * 4 + 0.05, (estimate, actual.time_s)


def test_render_beyond_max_time_is_refused_before_it_starts(gpu):
    with pytest.raises(InputError, match=r"^max_time_s: the render would take about .* s, more than 0.5 s"):
        render("cornell", make_lens(make_aperture("circle"), fstop=2.8, focus_distance_m=CORNELL_FOCUS_M),
               make_settings(512, 512, 65536), max_time_s=0.5)


def test_cli_long_render_is_refused_with_its_estimate(tmp_path, gpu):
    done = bokehfit("render", "--spp", "65536", "--max-time", "1", "--out", "x.png", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "the render would take about" in done.stderr and "more than --max-time 1 s" in done.stderr
    assert not (tmp_path / "x.png").exists()
