"""The measurement of a disc along rays (:mod:`bokehfit.discs.rays`): faint discs over haze and the
light of neighbours, overlapping discs, occluders; and what is no disc (a Gaussian glow, a cone,
noise). The photos are drawn here by geometry (supersampled indicator functions, a Gaussian edge
blur), not by bokehfit's renderer."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from bokehfit.discs import measure_discs_at
from bokehfit.discs.candidates import MIN_NOISE
from bokehfit.discs.levels import pixel_noise
from bokehfit.discs.measure import measure_candidate
from bokehfit.discs.rays import measure_rays
from bokehfit.discs.reasons import NoDisc

SUPERSAMPLE = 4


def _indicator(shape, inside) -> np.ndarray:
    """The share of each pixel that ``inside(x, y)`` covers (pixel centres at integers)."""
    height, width = shape
    offsets = (np.arange(SUPERSAMPLE) + 0.5) / SUPERSAMPLE - 0.5
    ys = (np.arange(height)[:, None] + offsets[None, :]).reshape(-1)
    xs = (np.arange(width)[:, None] + offsets[None, :]).reshape(-1)
    covered = inside(xs[None, :], ys[:, None]).astype(np.float32)
    return covered.reshape(height, SUPERSAMPLE, width, SUPERSAMPLE).mean(axis=(1, 3))


def _circle(centre, diameter):
    cx, cy = centre
    return lambda x, y: (x - cx) ** 2 + (y - cy) ** 2 <= (diameter / 2) ** 2


def _hexagon(centre, circumradius, angle_deg=15.0):
    cx, cy = centre
    inradius = circumradius * math.cos(math.pi / 6)
    normals = [math.radians(angle_deg + 30 + 60 * k) for k in range(6)]

    def inside(x, y):
        ok = np.ones(np.broadcast(x, y).shape, bool)
        for a in normals:
            ok &= (x - cx) * math.cos(a) + (y - cy) * math.sin(a) <= inradius
        return ok
    return inside


def _photo(shape, discs, background, blur=1.5, noise=0.004, seed=0):
    """Discs of light ``(inside, brightness)`` added over ``background`` (light adds), the edges
    blurred by ``blur`` px, and white noise."""
    light = np.zeros(shape, np.float32)
    for inside, brightness in discs:
        light += brightness * _indicator(shape, inside)
    light = ndimage.gaussian_filter(light, blur)
    rng = np.random.default_rng(seed)
    return (background + light + rng.normal(0.0, noise, shape)).astype(np.float32)


def _haze(shape, low=0.25, high=0.45):
    """Light that brightens to the right and down (vignetting, haze)."""
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]]
    return (low + (high - low) * (0.6 * xx / shape[1] + 0.4 * yy / shape[0])).astype(np.float32)


def test_pixel_noise_reads_white_noise_and_ignores_smooth_light():
    rng = np.random.default_rng(3)
    smooth = _haze((200, 200), 0.1, 0.9) + 0.2 * _indicator((200, 200), _circle((100, 100), 120))
    smooth = ndimage.gaussian_filter(smooth, 2.0)
    image = smooth + rng.normal(0, 0.01, smooth.shape)
    assert pixel_noise(image) == pytest.approx(0.01, rel=0.15)
    assert pixel_noise(smooth) < 0.002


def test_a_faint_large_disc_among_brighter_neighbours_is_measured_by_its_edge():
    """A 160 px disc of 6 % contrast over haze, with two brighter discs overlapping its surround: the
    surround's spread (the neighbours' light) is far above the disc's contrast, so one level does not
    outline it (the contour measurement calls it faint); its edge along rays is a clear step."""
    shape = (420, 520)
    centre, diameter = (250.0, 210.0), 160.0
    discs = [(_circle(centre, diameter), 0.02), (_circle((120, 130), 150), 0.3), (_circle((400, 330), 170), 0.25)]
    image = _photo(shape, discs, _haze(shape), noise=0.003)
    contour = measure_candidate(image, None, centre, diameter, diameter / 2, MIN_NOISE, 8.0)
    assert isinstance(contour, NoDisc) or contour.reason is not None or abs(contour.diameter_px / diameter - 1) > 0.1
    m = measure_rays(image, None, centre, diameter, MIN_NOISE, 8.0)
    assert not isinstance(m, NoDisc), m
    assert m.reason is None, m.reason
    assert m.diameter_px == pytest.approx(diameter, rel=0.03)
    assert math.dist(m.center_xy, centre) < 2.0
    assert m.outline_reliable.mean() > 0.6  # the arcs inside the neighbours' light are its own edge too


def test_overlapping_discs_of_different_brightness_each_keep_their_own_outline():
    """Light adds: where disc A lies over disc B, A's edge is still a step of A's contrast. Each is
    measured at its place, its size and centre right and its outline seen nearly all round."""
    shape = (300, 420)
    a, b = ((160.0, 150.0), 140.0, 0.25), ((260.0, 150.0), 120.0, 0.1)
    image = _photo(shape, [(_circle(c, d), k) for c, d, k in (a, b)], np.full(shape, 0.05, np.float32))
    search = measure_discs_at(image, None, [(a[0], a[1]), (b[0], b[1])])
    assert len(search.discs) == 2, search.rejections
    for (centre, diameter, _), disc in zip((a, b), sorted(search.discs, key=lambda d: d.center_xy[0])):
        assert disc.diameter_px == pytest.approx(diameter, rel=0.03)
        assert math.dist(disc.center_xy, centre) < 2.0
    rays = measure_rays(image, None, b[0], b[1], MIN_NOISE, 8.0)
    assert rays.outline_reliable.mean() > 0.9, rays.outline_reliable.mean()


def test_a_dark_branch_across_a_disc_is_not_its_edge():
    """A dark bar in front of a disc: the rays that meet it are not seen, the outline elsewhere is the
    disc's, and its size is the disc's."""
    shape = (300, 300)
    centre, diameter = (150.0, 150.0), 160.0
    image = _photo(shape, [(_circle(centre, diameter), 0.3)], _haze(shape, 0.2, 0.3))
    bar = _indicator(shape, lambda x, y: np.abs((x - 150) * 0.8 + (y - 150) * 0.6 - 55) <= 6)
    image = (image * (1 - 0.9 * ndimage.gaussian_filter(bar, 1.0))).astype(np.float32)
    m = measure_rays(image, None, centre, diameter, MIN_NOISE, 8.0)
    assert not isinstance(m, NoDisc), m
    assert m.diameter_px == pytest.approx(diameter, rel=0.04)
    reliable = m.outline_reliable
    assert 0.6 < reliable.mean() < 0.97
    # No seen point lies in the bar.
    x, y = m.outline_xy[reliable].T
    assert np.all(np.abs((x - 150) * 0.8 + (y - 150) * 0.6 - 55) > 4.0)


def test_a_hexagons_outline_follows_its_blades():
    shape = (260, 260)
    inside = _hexagon((130.0, 130.0), 80.0)
    image = _photo(shape, [(inside, 0.08)], _haze(shape, 0.3, 0.4), noise=0.004)
    m = measure_rays(image, None, (128.0, 133.0), 140.0, MIN_NOISE, 8.0)
    assert not isinstance(m, NoDisc) and m.reason is None, m
    truth = _indicator(shape, inside) > 0.5
    import cv2
    drawn = np.zeros(shape, np.uint8)
    cv2.fillPoly(drawn, [np.round(m.outline_xy * 16).astype(np.int32)], 1, shift=4)
    iou = (truth & (drawn > 0)).sum() / (truth | (drawn > 0)).sum()
    assert iou > 0.97, iou


@pytest.mark.parametrize("kind", ["gaussian", "cone"])
def test_a_glow_without_a_step_is_no_disc(kind):
    """A Gaussian glow and a cone of light have no step at their edge: their edges are as wide as
    they are ("soft edge"), whatever size is asked for."""
    shape = (300, 300)
    yy, xx = np.mgrid[0:300, 0:300]
    distance = np.hypot(xx - 150.0, yy - 150.0)
    glow = np.exp(-0.5 * (distance / 40.0) ** 2) if kind == "gaussian" else np.clip(1 - distance / 90.0, 0, None)
    image = (0.1 + 0.3 * glow + np.random.default_rng(1).normal(0, 0.003, shape)).astype(np.float32)
    for diameter in (80.0, 100.0, 140.0):
        m = measure_rays(image, None, (150.0, 150.0), diameter, MIN_NOISE, 8.0)
        assert isinstance(m, NoDisc) or m.reason is not None, (diameter, m.diameter_px, m.edge_width_px)


def test_noise_alone_has_no_outline():
    image = (0.3 + np.random.default_rng(2).normal(0, 0.01, (200, 200))).astype(np.float32)
    m = measure_rays(image, None, (100.0, 100.0), 80.0, MIN_NOISE, 8.0)
    assert isinstance(m, NoDisc) or m.reason is not None


def test_a_disc_cut_by_the_frame_is_seen_where_the_frame_does_not_cut_it():
    shape = (200, 300)
    centre, diameter = (40.0, 100.0), 120.0  # a third of it beyond the left edge
    image = _photo(shape, [(_circle(centre, diameter), 0.2)], np.full(shape, 0.1, np.float32))
    m = measure_rays(image, None, centre, diameter, MIN_NOISE, 8.0)
    assert not isinstance(m, NoDisc), m
    assert m.clipped  # cut by the frame
    seen = m.outline_xy[m.outline_reliable]
    assert seen[:, 0].min() > 0.5
    assert np.abs(np.hypot(*(seen - np.array(centre)).T) - diameter / 2).max() < 1.5


@pytest.mark.parametrize("kind", ["gaussian", "cone"])
def test_the_search_finds_no_disc_in_a_glow(kind):
    """Nor does the photo search (blobs, edge circles and their measurement along rays)."""
    from bokehfit.discs import find_discs

    yy, xx = np.mgrid[0:300, 0:300]
    distance = np.hypot(xx - 150.0, yy - 150.0)
    glow = np.exp(-0.5 * (distance / 40.0) ** 2) if kind == "gaussian" else np.clip(1 - distance / 90.0, 0, None)
    image = (0.1 + 0.3 * glow + np.random.default_rng(1).normal(0, 0.003, glow.shape)).astype(np.float32)
    assert not [d for d in find_discs(image, None, min_diameter_px=8).discs if d.usable]



def _bright_centre_disc(shape, centre, radius, seed):
    """A disc whose light falls from a bright core (0.87, over 0.3 of its radius) along a smooth
    shoulder to 0.4 at its edge, where it steps down to the ground (0.05), as the discs of bright lamps
    do in a JPEG: drawn by geometry, the edge blurred by 1.2 px, white noise."""
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    fall = np.clip((np.hypot(xx - centre[0], yy - centre[1]) - 0.3 * radius) / (0.7 * radius), 0, 1)
    shoulder = 0.4 + 0.47 * 0.5 * (1 + np.cos(math.pi * fall))
    light = ndimage.gaussian_filter((shoulder * _indicator(shape, _circle(centre, 2 * radius))).astype(np.float32), 1.2)
    return (0.05 + light + np.random.default_rng(seed).normal(0.0, 0.004, shape)).astype(np.float32)


@pytest.mark.parametrize("radius,seed", [(12.0, 1), (12.0, 2), (13.0, 3)])
def test_the_search_measures_a_bright_centre_blob_by_its_step(radius, seed, monkeypatch):
    """The blob's half-peak region is its core; one level between its peak and the ground runs along the
    shoulder, whose fall is as wide as the disc ("soft edge"), and the contour finds no sharp disc (at most
    the shoulder's outline, inside the disc, as a soft-edged one). The disc's own step at its edge is sharp:
    measured along rays, the blob is the disc at its edge, a sharp disc."""
    from bokehfit.discs import search

    shape, centre = (160, 160), (80.3, 79.6)
    image = _bright_centre_disc(shape, centre, radius, seed)
    monkeypatch.setattr(search, "BLOB_RAYS_MIN_DIAMETER_PX", math.inf)
    alone = [d for d in search.find_discs(image, None, min_diameter_px=8).discs if d.usable]  # the contour alone
    assert all(d.soft_edge and d.diameter_px < 2 * radius * 0.92 for d in alone), [(d.soft_edge, d.diameter_px) for d in alone]
    monkeypatch.undo()
    usable = [d for d in search.find_discs(image, None, min_diameter_px=8).discs if d.usable]
    assert len(usable) == 1 and not usable[0].soft_edge, [(d.center_xy, d.diameter_px) for d in usable]
    assert abs(usable[0].diameter_px / (2 * radius) - 1) < 0.08, usable[0].diameter_px
    assert math.hypot(usable[0].center_xy[0] - centre[0], usable[0].center_xy[1] - centre[1]) < 1.0


def test_the_rays_crossings_are_each_rays_own():
    """Where each ray falls through its level, taken for many rays at once, is what one ray's own
    search gives: of the falls within the step's sides of its index, the nearest (the first of two as
    near), linearly interpolated; none where the ray does not fall there; in float64, or in the
    profile's float32 where the levels are float32 (as a Python float level with the float32 profile)."""
    from bokehfit.discs.rays import BAND_REL, _Rays

    def one_ray(rays, k, j, level):
        lo = max(0, j - rays.gap - rays.side // 2)
        hi = min(len(rays.radii) - 1, j + rays.gap + rays.side // 2)
        p = rays.profile[k, lo : hi + 1]
        above = p >= level
        falls = np.nonzero(above[:-1] & ~above[1:])[0]
        if not len(falls):
            return None
        c = falls[np.argmin(np.abs(falls + lo - j))]
        t = (p[c] - level) / max(float(p[c] - p[c + 1]), 1e-12)
        return float(rays.radii[lo + c] + t * rays.step)

    rng = np.random.default_rng(6)
    crop = np.round(rng.random((90, 130)), 2).astype(np.float32)  # ties between falls as near
    rays = _Rays(crop, (45.0, 64.0), 30.0, 0.01, BAND_REL[1] * 30.0)
    ks = np.arange(rays.count)
    at = rng.integers(0, len(rays.radii), rays.count)
    levels = rng.uniform(0.2, 0.8, rays.count)
    for kind, as_given in ((np.float64, lambda v: np.float64(v)), (np.float32, float)):
        got = rays.crossings(ks, at, levels.astype(kind))
        expected = [one_ray(rays, k, int(j), as_given(v)) for k, j, v in zip(ks, at, levels)]
        assert any(e is None for e in expected) and any(e is not None for e in expected)
        for value, wanted in zip(got, expected):
            assert (math.isnan(value) and wanted is None) or value == wanted, (value, wanted)


def test_the_rays_levels_are_each_rays_own_medians():
    """The light inside, outside and beyond a step and whether its sides are in the frame, taken for many rays
    at once, are each ray's own medians over its own samples (a crop cut by the frame, steps anywhere, some
    too near the rays' ends to have sides); and the closed path is the dynamic programme's, written out plainly."""
    from bokehfit.discs.levels import _median
    from bokehfit.discs.rays import BAND_REL, _closed_path, _Rays

    rng = np.random.default_rng(5)
    crop = rng.random((90, 130)).astype(np.float32)
    rays = _Rays(crop, (20.0, 110.0), 30.0, 0.01, BAND_REL[1] * 30.0)  # near a corner: rays leave the crop
    assert not rays.inside.all()
    at = rng.integers(0, len(rays.radii), rays.count)
    inner, outer, beyond, framed = rays.levels(np.arange(rays.count), at)
    gap, side = rays.gap, rays.side
    for k, j in enumerate(at):
        lo, hi = j - gap - side, j + gap + side
        if lo < 0 or hi >= len(rays.radii):
            assert math.isnan(inner[k]) and math.isnan(outer[k]) and not framed[k]
            continue
        row = rays.profile[k]
        assert inner[k] == float(_median(row[lo : j - gap + 1]))
        assert outer[k] == float(_median(row[j + gap : hi + 1]))
        assert beyond[k] == float(_median(row[hi : hi + side + 1]))
        assert framed[k] == bool(rays.inside[k, lo : hi + 1].all())
    # The path: the dynamic programme over three turns written out plainly (each ray's best predecessor within
    # ``reach``, then back from the best end), its middle turn kept.
    strength = rng.random((24, 40))
    for reach in (1, 2, 5):
        total = [strength[0]]
        for i in range(1, 3 * 24):
            total.append(strength[i % 24] + ndimage.maximum_filter1d(total[-1], 2 * reach + 1, mode="constant",
                                                                     cval=-np.inf))
        plain = [int(np.argmax(total[-1]))]
        for i in range(3 * 24 - 2, -1, -1):
            j0 = max(0, plain[-1] - reach)
            plain.append(j0 + int(np.argmax(total[i][j0 : plain[-1] + reach + 1])))
        expected = np.array(plain[::-1][24:48])
        np.testing.assert_array_equal(_closed_path(strength, reach), expected)
