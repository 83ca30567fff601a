"""The disc finder on synthetic photos made with bokehfit's exact kernels.

Thresholds (stated once, asserted below):
- recall and precision ≥ RECALL_MIN / PRECISION_MIN over isolated, unclipped discs;
- equal-area diameter error ≤ DIAMETER_TOL_REL of the diameter or DIAMETER_TOL_PX, whichever is larger;
- centre error ≤ CENTRE_TOL_PX.
A found disc matches a true one when its centre lies within a quarter of the true diameter (≥ 2 px).
Slits narrower than SLIT_MIN_WIDTH_PX (the 6- and 9-px ones, 1.6 and 2.4 px wide) need only be found:
their 50 % outline is widened by the edge blur.
"""

from __future__ import annotations

import itertools
import math

import cv2
import numpy as np
import pytest

from bokehfit.apertures import SHAPES, make_aperture
from bokehfit.discs import MIN_FIT_SEEN, find_discs
from bokehfit.errors import InputError
from bokehfit.synthetic import SyntheticDisc, encode_srgb8, render_discs

RECALL_MIN = 0.95
PRECISION_MIN = 0.95
DIAMETER_TOL_REL = 0.03
DIAMETER_TOL_PX = 0.35
CENTRE_TOL_PX = 0.35
#: Looser after JPEG compression (8-bit quantisation, ringing at the edges).
JPEG_DIAMETER_TOL_REL = 0.05
JPEG_DIAMETER_TOL_PX = 0.6
JPEG_CENTRE_TOL_PX = 0.6
SLIT_MIN_WIDTH_PX = 3.0

DIAMETERS = (6, 9, 14, 22, 35, 56, 90, 140, 200)
SHAPE_CASES = [dict(shape="ngon", blades=9) if s == "ngon" else dict(shape=s) for s, spec in SHAPES.items() if not spec.tabulated]  # a mask is not fitted


def layout(diameters, shapes, *, seed=0, spacing_factor=1.5, width=None):
    """Discs on a grid with room between them (no overlaps), random angles and sub-pixel centres."""
    rng = np.random.default_rng(seed)
    specs = list(zip(diameters, itertools.cycle(shapes)))
    cell = int(max(d for d, _ in specs) * spacing_factor * 2.2) + 8  # the slit is 3.3 d/2 tall
    columns = max(1, int(math.ceil(math.sqrt(len(specs)))))
    rows = int(math.ceil(len(specs) / columns))
    discs = []
    for i, (diameter, shape) in enumerate(specs):
        row, col = divmod(i, columns)
        centre = ((col + 0.5) * cell + rng.uniform(-0.5, 0.5), (row + 0.5) * cell + rng.uniform(-0.5, 0.5))
        angle, brightness = rng.uniform(0, 360), rng.uniform(0.3, 0.9)
        discs.append(SyntheticDisc(centre, diameter, make_aperture(angle_deg=angle, **shape), brightness=brightness))
    return discs, columns * cell, rows * cell


def match(found, truth):
    """Pairs (true disc, found disc or None), nearest centre within a quarter diameter."""
    pairs = []
    for t in truth:
        best = min(
            found,
            key=lambda d: math.hypot(d.center_xy[0] - t.center_xy[0], d.center_xy[1] - t.center_xy[1]),
            default=None,
        )
        if best is not None and math.hypot(best.center_xy[0] - t.center_xy[0], best.center_xy[1] - t.center_xy[1]) <= max(
            2.0, t.diameter_px / 4
        ):
            pairs.append((t, best))
        else:
            pairs.append((t, None))
    return pairs


def score(found, truth):
    pairs = match(found, truth)
    matched = [(t, f) for t, f in pairs if f is not None]
    recall = len(matched) / len(truth)
    precision = len({id(f) for _, f in matched}) / max(len(found), 1)
    return recall, precision, matched


def gradient(width, height, low=0.01, high=0.08):
    return np.linspace(low, high, width, dtype=np.float32)[None, :].repeat(height, axis=0)


def slit_width_px(disc):
    return disc.diameter_px * math.sqrt(math.pi) / 2 * 0.3


def assert_accurate(matched, tol_rel, tol_px, centre_tol):
    for t, f in matched:
        shape = t.aperture.shape
        if shape == "slit" and slit_width_px(t) < SLIT_MIN_WIDTH_PX:
            continue
        error = abs(f.diameter_px - t.diameter_px)
        assert error <= max(tol_rel * t.diameter_px, tol_px), f"{shape} {t.diameter_px} px: diameter {f.diameter_px:.2f}"
        offset = math.hypot(f.center_xy[0] - t.center_xy[0], f.center_xy[1] - t.center_xy[1])
        assert offset <= centre_tol, f"{shape} {t.diameter_px} px: centre off by {offset:.2f} px"


@pytest.mark.parametrize("case", SHAPE_CASES, ids=[c["shape"] for c in SHAPE_CASES])
def test_every_shape_and_size_is_found_and_measured(case):
    truth, width, height = layout(DIAMETERS, [case], seed=len(case["shape"]))
    image = render_discs(width, height, truth, background=gradient(width, height), noise_sigma=0.003, seed=1)
    search = find_discs(image)
    recall, precision, matched = score(search.discs, truth)
    assert recall >= RECALL_MIN and precision >= PRECISION_MIN, (recall, precision, search.rejected)
    assert_accurate(matched, DIAMETER_TOL_REL, DIAMETER_TOL_PX, CENTRE_TOL_PX)
    for t, f in matched:
        assert f.resolvable == (f.diameter_px >= 8.0)
        assert not (f.saturated or f.clipped or f.overlaps), f"{t.aperture.shape} {t.diameter_px}: flags"


def jpeg_round_trip(linear, quality):
    ok, data = cv2.imencode(".jpg", encode_srgb8(linear), [cv2.IMWRITE_JPEG_QUALITY, quality])
    decoded = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
    from bokehfit.io.colour import colour_science

    colour = colour_science()

    lut = colour.cctf_decoding(np.arange(256) / 255.0, function="sRGB").astype(np.float32)
    return lut[decoded], decoded == 255


@pytest.mark.parametrize("quality", [70, 95])
def test_jpeg_compressed_discs(quality):
    shapes = [dict(shape="hexagon"), dict(shape="circle"), dict(shape="star"), dict(shape="square")]
    truth, width, height = layout((10, 18, 30, 50, 80, 120, 12, 24, 40, 64, 100, 160), shapes, seed=3)
    linear = render_discs(width, height, truth, background=gradient(width, height, 0.02, 0.06), noise_sigma=0.002)
    luminance, clipped = jpeg_round_trip(linear, quality)
    search = find_discs(luminance, clipped)
    recall, precision, matched = score(search.discs, truth)
    assert recall >= RECALL_MIN and precision >= PRECISION_MIN, (recall, precision, search.rejected)
    assert_accurate(matched, JPEG_DIAMETER_TOL_REL, JPEG_DIAMETER_TOL_PX, JPEG_CENTRE_TOL_PX)


def test_saturated_discs_are_found_and_flagged():
    truth = [
        SyntheticDisc((60.3, 60.7), 40, make_aperture("hexagon"), brightness=3.0),
        SyntheticDisc((160.2, 60.1), 40, make_aperture("hexagon"), brightness=0.5),
    ]
    image = render_discs(220, 120, truth)
    search = find_discs(image, image >= 1.0)
    pairs = dict((t.brightness, f) for t, f in match(search.discs, truth))
    assert pairs[3.0] is not None and pairs[3.0].saturated
    assert pairs[0.5] is not None and not pairs[0.5].saturated
    assert abs(pairs[3.0].diameter_px - 40) < 2.5  # a clipped plateau still has its 50 % edge near the true one


def test_disc_clipped_by_frame_is_flagged():
    circle = make_aperture("circle")
    truth = [SyntheticDisc((8.0, 70.0), 50, circle), SyntheticDisc((120.0, 70.0), 50, circle)]
    search = find_discs(render_discs(200, 140, truth, noise_sigma=0.002))
    pairs = dict((t.center_xy[0], f) for t, f in match(search.discs, truth))
    assert pairs[8.0] is not None and pairs[8.0].clipped and not pairs[8.0].usable
    assert pairs[120.0] is not None and not pairs[120.0].clipped and pairs[120.0].usable


def test_overlapping_discs_are_flagged():
    circle = make_aperture("circle")
    truth = [SyntheticDisc((80.0, 80.0), 60, circle), SyntheticDisc((125.0, 82.0), 60, circle, brightness=0.6)]
    search = find_discs(render_discs(220, 170, truth, noise_sigma=0.002))
    assert search.discs and all(d.overlaps for d in search.discs)
    # usable (fitted with the other's light left out) only with enough of the outline its own
    assert all(d.usable == (d.outline_seen >= MIN_FIT_SEEN) for d in search.discs)


def test_points_within_an_outline_are_those_opencv_finds():
    """The overlap test's bounding-box shortcut gives OpenCV's answer for every point, near the box or far."""
    from bokehfit.discs.disc import _within_outline

    rng = np.random.default_rng(7)
    for _ in range(20):
        angles = np.sort(rng.uniform(0.0, 2.0 * math.pi, 40))
        radii = rng.uniform(20.0, 40.0, 40)
        outline = np.column_stack([100.0 + radii * np.cos(angles), 90.0 + radii * np.sin(angles)])
        points = rng.uniform(40.0, 160.0, (400, 2))
        polygon = outline.astype(np.float32)
        expected = [cv2.pointPolygonTest(polygon, (float(x), float(y)), True) >= -1.5 for x, y in points]
        assert _within_outline(points, outline, 1.5).tolist() == expected


def test_star_is_not_taken_for_overlapping_discs():
    search = find_discs(render_discs(160, 160, [SyntheticDisc((80.2, 79.6), 90, make_aperture("star", 7))]))
    assert len(search) == 1 and not search.discs[0].overlaps


def gaussian_blob(width, height, centre, sigma, peak):
    rows, cols = np.indices((height, width), dtype=np.float32)
    return peak * np.exp(-((cols - centre[0]) ** 2 + (rows - centre[1]) ** 2) / (2 * sigma**2))


def test_non_discs_are_rejected_with_reasons():
    image = np.full((240, 320), 0.03, dtype=np.float32)
    image += gaussian_blob(320, 240, (60, 60), 1.2, 0.9)  # in-focus glint: smaller than any band
    image += gaussian_blob(320, 240, (160, 60), 14.0, 0.6)  # smooth blob: soft edge
    image[150:153, 20:300] += 0.7  # a bright in-focus line: elongated
    image += np.random.default_rng(0).normal(0, 0.002, image.shape).astype(np.float32)
    search = find_discs(image)
    assert not search, [d.center_xy for d in search.discs]
    assert {"soft edge", "elongated"} <= set(search.rejected), search.rejected
    assert "no disc among" in search.reason


def radial_profile(width, height, centre, radius, profile, blur_px=1.0):
    """An image of ``profile(r / radius)`` inside ``radius`` and 0 outside, sampled 4×4 per pixel and
    blurred by ``blur_px``: made from the formula, not from bokehfit's kernels."""
    sub = 4
    rows, cols = np.indices((height * sub, width * sub), dtype=np.float64)
    # pixel centres at integer coordinates (design.md §1)
    rho = np.hypot((cols + 0.5) / sub - 0.5 - centre[0], (rows + 0.5) / sub - 0.5 - centre[1]) / radius
    fine = np.where(rho <= 1.0, profile(np.minimum(rho, 1.0)), 0.0)
    image = fine.reshape(height, sub, width, sub).mean(axis=(1, 3))
    return cv2.GaussianBlur(image.astype(np.float32), (0, 0), blur_px)


@pytest.mark.parametrize("fall", [0.6, 0.75, 0.85])
def test_bright_centre_discs_are_measured_at_their_edge(fall):
    """Centre bright, falling by ``fall`` of the peak towards the rim, then a step to the
    background (the far side of an over-corrected lens): found at the step, not on the slope.
    The edge lies at 40 %, 25 % and 15 % of the peak (design.md's rim −0.43, −0.6, −0.74)."""
    image = np.full((200, 320), 0.02, dtype=np.float32)
    centres = [(60.3, 60.7), (160.0, 100.4), (260.6, 140.2)]
    for centre in centres:
        image += radial_profile(320, 200, centre, 25.0, lambda rho: 0.6 * (1.0 - fall * rho**1.5))
    image += np.random.default_rng(3).normal(0, 0.002, image.shape).astype(np.float32)
    search = find_discs(image)
    assert len(search) == 3, search.rejected
    for disc in search.discs:
        assert disc.bright_centre and not disc.ring and disc.evidence == "edge" and disc.usable
        assert disc.diameter_px == pytest.approx(50.0, rel=0.03)
        assert min(math.dist(disc.center_xy, c) for c in centres) < 0.5


def test_cones_and_smooth_blobs_are_not_taken_for_bright_centres():
    """No step at their edge: a cone (equally steep at every level) and a Gaussian (steepest at
    0.61 of its peak) stay soft."""
    image = np.full((200, 320), 0.02, dtype=np.float32)
    image += radial_profile(320, 200, (80.0, 100.0), 40.0, lambda rho: 0.6 * (1.0 - rho))
    image += gaussian_blob(320, 200, (230, 100), 16.0, 0.6)
    image += np.random.default_rng(4).normal(0, 0.002, image.shape).astype(np.float32)
    search = find_discs(image)
    assert not search, [(d.center_xy, d.diameter_px) for d in search.discs]
    # Each is soft: once as a blob, and again where the edge search put a circle on its slope.
    assert search.rejected["soft edge"] >= 2 and set(search.rejected) <= {"soft edge", "not a cluster"}, search.rejected


@pytest.mark.parametrize("level", [0.0, 1.0])
def test_flat_images_have_no_discs(level):
    search = find_discs(np.full((64, 64), level, dtype=np.float32))
    assert not search and search.reason == "no highlight stands out from the background"


def test_faint_noise_only_image_has_no_discs():
    noise = np.random.default_rng(5).normal(0.05, 0.01, (300, 300)).astype(np.float32)
    assert not find_discs(noise)


def test_nan_is_refused():
    image = np.zeros((32, 32), dtype=np.float32)
    image[3, 4] = np.nan
    with pytest.raises(InputError, match="NaN"):
        find_discs(image)


def test_max_discs_keeps_the_largest():
    truth, width, height = layout((10, 20, 30, 40), [dict(shape="circle")], seed=2)
    search = find_discs(render_discs(width, height, truth, noise_sigma=0.002), max_discs=2)
    assert [round(d.diameter_px) for d in search.discs] == [40, 30]


def test_discs_survive_a_raw_round_trip(tmp_path):
    """A rendered bokeh image mosaiced into a Bayer DNG, read through rawpy, gives the same discs."""
    from photo_factory import write_dng

    from bokehfit.io import load_photo

    truth = [
        SyntheticDisc((70.4, 66.2), 48, make_aperture("hexagon", 10), brightness=0.5),
        SyntheticDisc((190.7, 80.3), 36, make_aperture("circle"), brightness=0.4),
        SyntheticDisc((130.2, 170.9), 56, make_aperture("star", 30), brightness=0.45),
    ]
    linear = render_discs(260, 240, truth, background=0.05, noise_sigma=0.002, seed=9)
    black, white = 256, 4095
    mosaic = np.round(black + linear * (white - black)).astype(np.uint16)  # grey scene: R = G = B
    photo = load_photo(write_dng(tmp_path / "bokeh.dng", mosaic, white=white, black=black))
    assert photo.raw and photo.luminance.shape == (240, 260)
    search = find_discs(photo.luminance, photo.clipped)
    recall, precision, matched = score(search.discs, truth)
    assert recall == 1.0 and precision == 1.0, (recall, precision, search.rejected)
    assert_accurate(matched, DIAMETER_TOL_REL, 0.5, 0.5)


# --------------------------------------------------------------------------------------
# Work done in parts or by shortcuts gives the same numbers as done whole
# --------------------------------------------------------------------------------------


def strip_scene():
    """Discs of 5 to 150 px (one pair overlapping), a diagonal streak and a large faint disc on a
    gradient with noise: blobs of every band that cross the borders of strips a few rows tall."""
    truth = [
        SyntheticDisc((60.4, 50.2), 6, make_aperture("circle")),
        SyntheticDisc((150.7, 95.3), 9, make_aperture("hexagon"), brightness=0.4),
        SyntheticDisc((260.2, 140.6), 22, make_aperture("pentagon", 12)),
        SyntheticDisc((120.5, 230.1), 60, make_aperture("circle"), brightness=0.5),
        SyntheticDisc((160.2, 236.4), 60, make_aperture("circle"), brightness=0.7),
        SyntheticDisc((330.3, 300.8), 150, make_aperture("hexagon"), brightness=0.08),
        SyntheticDisc((70.1, 380.9), 35, make_aperture("star", 40)),
    ]
    image = render_discs(420, 460, truth, background=gradient(420, 460, 0.02, 0.05), noise_sigma=0.003, seed=4)
    rows, cols = np.indices(image.shape)
    image[np.abs(rows - 1.05 * cols - 20) < 1.2] += 0.3  # a thin streak across the frame
    # A small disc just below row 152 (a border of 76-row strips) with a one-pixel thread off its
    # edge at 45°, up across the border: joined to the disc only through diagonal neighbours.
    small = SyntheticDisc((200.3, 160.2), 8, make_aperture("circle"), brightness=0.8)
    image = np.maximum(image, render_discs(420, 460, [small]))
    for k in range(-2, 30):
        image[156 - k, 196 - k] += 0.2
    return image


def test_candidates_do_not_depend_on_the_strips(monkeypatch):
    """Bands are searched in strips of rows (the opening with a margin of its reach, blobs
    joined across the borders): in strips as thin as they go, the candidates are those of
    one strip holding the whole image, in the same order, to the last bit."""
    from bokehfit.discs import candidates

    image = strip_scene()
    monkeypatch.setattr(candidates, "STRIP_PIXELS", 1 << 30)
    whole = candidates.find_candidates(image, 4.0, 500.0)
    monkeypatch.setattr(candidates, "STRIP_PIXELS", 1)
    assert len(candidates._strips(*image.shape, 19)) >= 6  # band 4: a 19-px square, strips of 76 rows
    strips = candidates.find_candidates(image, 4.0, 500.0)
    assert len(whole) >= 20 and any(c.cluster for c in whole) and any(c.diameter_px > 100 for c in whole)
    assert strips == whole


@pytest.mark.parametrize("keep_below,max_share", [(1e9, 8), (0.5, 10**9), (0.0, 1)])
def test_strips_opened_again_give_the_same_candidates(monkeypatch, keep_below, max_share):
    """A strip whose provisional threshold (made before σ is known) proves too high, or that
    would keep too many of its pixels, is opened a second time: the candidates do not change.
    (1e9: every strip's threshold too high; 10**9: every strip keeps too many; 0 and 1: a
    provisional threshold of 0 keeps every positive pixel, within the share.)"""
    from bokehfit.discs import candidates

    image = strip_scene()
    monkeypatch.setattr(candidates, "STRIP_PIXELS", 1)
    once = candidates.find_candidates(image, 4.0, 500.0)
    opened = []
    original = candidates._opening
    monkeypatch.setattr(candidates, "_opening", lambda *args: opened.append((args[0].shape, args[2])) or original(*args))
    monkeypatch.setattr(candidates, "KEEP_BELOW_THRESHOLD", keep_below)
    monkeypatch.setattr(candidates, "KEEP_MAX_SHARE", max_share)
    again = candidates.find_candidates(image, 4.0, 500.0)
    assert again == once
    twice = len(opened) - len(set(opened))  # strips (of a band's copy) opened a second time
    assert twice > 0 if keep_below > 1.0 or max_share > 10**6 else twice == 0


def test_fast_median_and_percentile_are_numpys():
    from bokehfit.discs.levels import _median, _percentile

    rng = np.random.default_rng(11)
    for trial in range(2000):
        kind = (np.float32, np.float64)[trial % 2]
        values = (rng.normal(size=int(rng.integers(1, 40))) * 10.0 ** rng.uniform(-4, 1)).astype(kind)
        if trial % 3 == 0:
            values = np.round(values, 1).astype(kind)  # ties
        expected, got = np.median(values), _median(values)
        assert got == expected and got.dtype == expected.dtype, (values, got, expected)
        for q in (10, 50, 90, 37.5):
            expected, got = np.percentile(values, q), _percentile(values, q)
            assert got == expected and got.dtype == expected.dtype, (values, q, got, expected)


def test_row_medians_are_each_windows_median():
    """The medians of many windows of a table at once are each window's :func:`_median`, in its type
    (windows of one sample to a whole row, odd and even counts, ties)."""
    from bokehfit.discs.levels import _median, _row_medians

    rng = np.random.default_rng(12)
    for kind in (np.float32, np.float64):
        table = np.round(rng.normal(size=(30, 50)), 1).astype(kind)
        rows = rng.integers(0, 30, 400)
        starts = rng.integers(0, 50, 400)
        stops = np.minimum(50, starts + rng.integers(1, 51, 400))
        got = _row_medians(table, rows, starts, stops)
        expected = [_median(table[r, a:b]) for r, a, b in zip(rows, starts, stops)]
        assert got.dtype == kind and list(got) == expected


def test_hole_filling_is_scipys():
    from scipy import ndimage

    from bokehfit.discs.gaps import _fill_holes

    rng = np.random.default_rng(12)
    for _ in range(500):
        mask = rng.random(tuple(rng.integers(1, 30, 2))) < rng.random()
        np.testing.assert_array_equal(_fill_holes(mask), ndimage.binary_fill_holes(mask))


def test_outline_is_the_largest_contour_around_the_seed():
    """The outline traces only the regions that may bound the seed; it is the contour that
    tracing every region of the crop and keeping the largest one around the seed gives."""
    from skimage import measure

    from bokehfit.discs.contours import _outline

    def every_contour(crop, level, background, seed_rc):
        padded = np.pad(crop, 1, mode="constant", constant_values=min(background, level - 1e-6))
        best, best_area = None, 0.0
        for contour in measure.find_contours(padded, level):
            if len(contour) < 4:
                continue
            xy = contour[:, ::-1] - 1.0
            area = 0.5 * abs(np.dot(xy[:, 0], np.roll(xy[:, 1], -1)) - np.dot(xy[:, 1], np.roll(xy[:, 0], -1)))
            inside = cv2.pointPolygonTest(xy.astype(np.float32), (float(seed_rc[1]), float(seed_rc[0])), False) >= 0
            if area > best_area and inside:
                best, best_area = xy, area
        return best

    rng = np.random.default_rng(13)
    found = 0
    for trial in range(150):
        size = int(rng.integers(20, 90))
        texture = cv2.GaussianBlur(rng.random((size, size)).astype(np.float32), (0, 0), rng.uniform(0.7, 3.0))
        rows, cols = np.indices(texture.shape)
        centre = rng.uniform(0.3 * size, 0.7 * size, 2)
        ring = np.abs(np.hypot(rows - centre[0], cols - centre[1]) - 0.2 * size) < 2.0  # rings leave holes
        crop = texture + np.float32(0.2) * ring.astype(np.float32)
        level = float(np.quantile(crop, rng.uniform(0.3, 0.8)))
        seed = tuple(centre + rng.normal(0, 3, 2))
        expected, got = every_contour(crop, level, 0.0, seed), _outline(crop, level, 0.0, seed)
        assert (expected is None) == (got is None)
        if expected is not None:
            found += 1  # the same points (traced in a box of the crop: rounding of its offset aside)
            assert got.shape == expected.shape
            np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)
    assert found >= 50


def test_outline_points_near_a_mask_are_those_of_the_whole_crop():
    """The distance transform is taken over the outline's box and a margin only: every point's
    verdict is the one the transform of the whole crop gives."""
    from scipy import ndimage

    from bokehfit.discs.verdict import UNSEEN_MARGIN_PX, _near

    rng = np.random.default_rng(14)
    near_some = 0
    for _ in range(1500):
        height, width = rng.integers(10, 80, 2)
        mask = rng.random((height, width)) < rng.uniform(0.001, 0.05)
        mask[rng.integers(height), rng.integers(width)] = True  # not empty (that case returns at once)
        angles = rng.uniform(0, 2 * np.pi, int(rng.integers(4, 40)))
        centre, radius = rng.uniform(0, (width, height)), rng.uniform(2, 30)
        outline = centre + radius * np.column_stack([np.cos(angles), np.sin(angles)])
        coords = [np.clip(outline[:, 1], 0, height - 1), np.clip(outline[:, 0], 0, width - 1)]
        whole = ndimage.map_coordinates(ndimage.distance_transform_edt(~mask), coords, order=1, mode="nearest")
        got = _near(mask, outline, UNSEEN_MARGIN_PX)
        np.testing.assert_array_equal(got, whole <= UNSEEN_MARGIN_PX)
        near_some += bool(got.any()) and not got.all()
    assert near_some >= 100


def test_the_background_planes_least_squares_agree_with_numpys_and_survive_pixels_on_one_row():
    """The plane through a surround's pixels is solved by its 3 × 3 normal equations (levels._least_squares_3):
    the coefficients of np.linalg.lstsq's SVD to rounding, on a window's coordinates; and pixels that all
    lie on one row (no slope across the rows to be had) still get a plane through their light."""
    from bokehfit.discs.levels import _least_squares_3

    rng = np.random.default_rng(4)
    rows, cols = rng.integers(0, 900, 800).astype(float), rng.integers(0, 900, 800).astype(float)
    design = np.column_stack([np.ones(800), rows, cols])
    values = 0.2 + 3e-4 * rows - 1e-4 * cols + rng.normal(0.0, 0.01, 800)
    expected = np.linalg.lstsq(design, values, rcond=None)[0]
    assert np.allclose(_least_squares_3(design, values), expected, rtol=1e-9, atol=1e-12)
    flat = np.column_stack([np.ones(50), np.full(50, 7.0), np.arange(50.0)])
    solved = _least_squares_3(flat, 0.5 + 0.01 * np.arange(50.0))
    assert np.allclose(flat @ solved, 0.5 + 0.01 * np.arange(50.0))


def test_the_bright_centre_search_settles_as_all_its_levels_do():
    """The step search traces its low levels, then those above from the top until one settles it: the answer
    of tracing all ten (BRIGHT_CENTRE_LEVELS) and comparing them, on glows, cones, blurred flat discs and
    bright-centre discs of many rims, with noise."""
    from bokehfit.discs.contours import _crop_gradients, _edge_gradient, _outline, polygon_area_centroid
    from bokehfit.discs.measure import (
        BRIGHT_CENTRE_LEVELS,
        BRIGHT_CENTRE_MAX_LEVEL,
        BRIGHT_CENTRE_SHOULDER,
        BRIGHT_CENTRE_STEEPER,
        _step_share,
    )
    from bokehfit.discs.outlines import _two_passes
    from bokehfit.discs.reasons import NoDisc

    def every_level(found):
        crop, levels = found.crop, found.levels
        contrast = levels.plateau - levels.background
        _, cx, cy = polygon_area_centroid(found.outline)
        gradients = _crop_gradients(crop)
        steep = []
        for share in BRIGHT_CENTRE_LEVELS:
            contour = _outline(crop, levels.background + share * contrast, levels.background, (cy, cx))
            steep.append(0.0 if contour is None else _edge_gradient(crop, contour, gradients))
        best = int(np.argmax(steep))
        share, steepest = BRIGHT_CENTRE_LEVELS[best], steep[best]
        if share > BRIGHT_CENTRE_MAX_LEVEL:
            return None
        shoulder = 2.0 * share + BRIGHT_CENTRE_SHOULDER - 1e-9
        above = max(s for level, s in zip(BRIGHT_CENTRE_LEVELS, steep) if level >= shoulder)
        return share if steepest >= BRIGHT_CENTRE_STEEPER * above else None

    rng = np.random.default_rng(21)
    size = 121
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float32)
    answers = []
    for trial in range(60):
        radius = float(rng.uniform(14.0, 40.0))
        distance = np.hypot(cols - 60.0 - rng.uniform(-0.5, 0.5), rows - 60.0 - rng.uniform(-0.5, 0.5))
        kind = trial % 4
        if kind == 0:  # a glow
            light = np.exp(-0.5 * (distance / (0.6 * radius)) ** 2)
        elif kind == 1:  # a cone
            light = np.clip(1.0 - distance / (1.4 * radius), 0.0, None)
        else:  # a flat disc blurred up to 0.4 of its radius; a disc falling from its centre to a step at its edge
            rim = float(rng.uniform(-0.95, -0.5)) if kind == 3 else 0.0
            light = (distance <= radius) * (1.0 + rim * (distance / radius) ** 2)
            blur = rng.uniform(0.8, 0.1 * radius) if kind == 3 else rng.uniform(1.0, 0.4 * radius)
            light = cv2.GaussianBlur(light.astype(np.float32), (0, 0), float(blur))
        image = (0.05 + 0.6 * light + rng.normal(0.0, 0.004, light.shape)).astype(np.float32)
        found = _two_passes(image, (60.0, 60.0), radius, radius, 0.8)
        if isinstance(found, NoDisc):
            continue
        expected = every_level(found)
        assert _step_share(found) == expected, trial
        answers.append(expected)
    assert len(answers) >= 50 and sum(a is None for a in answers) >= 10 and sum(a is not None for a in answers) >= 5, \
        (len(answers), sum(a is None for a in answers))


def test_the_search_reports_the_time_of_each_step():
    """``DiscSearch.timing_s``: the search's steps by name, each a share of its whole time (for the speed table of
    ``benchmarks/real_speed.py``)."""
    disc = SyntheticDisc((80.3, 70.6), 40, make_aperture("hexagon", 12))
    search = find_discs(render_discs(200, 160, [disc], background=0.03, seed=2), min_diameter_px=8)
    assert list(search.timing_s) == ["candidates", "measure", "edge circles", "sized circles", "own steps", "result"]
    assert all(t >= 0.0 for t in search.timing_s.values())
    assert sum(search.timing_s.values()) <= search.time_s
