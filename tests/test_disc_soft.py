"""Soft-edged discs: the search's second tier, and the fit's use of it.

A disc whose edge is wider than a sharp disc's (more than EDGE_WIDTH_MAX_REL of its radius, at most
SOFT_EDGE_WIDTH_MAX_REL), whose light ends near that edge, and that passes every other test of a disc is
kept as a soft-edged disc (``Disc.soft_edge``); a glow, whose tail goes on, is not. The discs here are drawn
by geometry (a disc's indicator sampled 4 × 4 per pixel, blurred by OpenCV), not by bokehfit's kernels.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from bokehfit.discs import find_discs
from bokehfit.discs import search as search_module
from bokehfit.discs.verdict import EDGE_WIDTH_MAX_REL, SOFT_EDGE_WIDTH_MAX_REL
from bokehfit.fit.choice import MIN_SHARP_DISCS, choose_discs
from bokehfit.fit.families import FAMILIES

RADIUS = 20.0
SHARP = [(60.3, 60.7), (160.6, 60.2), (260.2, 59.8)]
SOFT = [(60.7, 180.4), (160.2, 179.6), (260.5, 180.3)]
GLOW = (360.0, 120.0)


def _disc(shape, centre, radius, blur_px, brightness):
    """A flat disc of ``radius`` blurred by a Gaussian of ``blur_px``, sampled 4 × 4 per pixel."""
    sub = 4
    rows, cols = np.indices((shape[0] * sub, shape[1] * sub), dtype=np.float64)
    inside = np.hypot((cols + 0.5) / sub - 0.5 - centre[0], (rows + 0.5) / sub - 0.5 - centre[1]) <= radius
    image = inside.reshape(shape[0], sub, shape[1], sub).mean(axis=(1, 3)).astype(np.float32)
    return brightness * cv2.GaussianBlur(image, (0, 0), blur_px)


def _photo(soft_blur_rel=0.3, glow=True, seed=0):
    """Three sharp discs (blur 0.8 px), three soft ones (blur ``soft_blur_rel`` of the radius: an edge of
    about 2.5 times that) and, with ``glow``, a Gaussian glow of their size, on a dark ground with noise."""
    shape = (240, 420)
    image = np.full(shape, 0.03, dtype=np.float32)
    for centre in SHARP:
        image += _disc(shape, centre, RADIUS, 0.8, 0.5)
    for centre in SOFT:
        image += _disc(shape, centre, RADIUS, soft_blur_rel * RADIUS, 0.5)
    if glow:
        rows, cols = np.indices(shape, dtype=np.float32)
        image += 0.5 * np.exp(-((cols - GLOW[0]) ** 2 + (rows - GLOW[1]) ** 2) / (2.0 * (0.85 * RADIUS) ** 2))
    return image + np.random.default_rng(seed).normal(0.0, 0.003, shape).astype(np.float32)


def _at(discs, centre):
    return [d for d in discs if math.dist(d.center_xy, centre) < 0.25 * RADIUS]


def test_the_soft_tier_lies_between_the_sharp_discs_edge_and_a_glows():
    assert EDGE_WIDTH_MAX_REL < SOFT_EDGE_WIDTH_MAX_REL < 1.44  # a Gaussian blob's edge, at its half level


@pytest.mark.parametrize("seed", [0, 1])
def test_soft_discs_are_found_as_the_second_tier_and_a_glow_is_not(seed):
    search = find_discs(_photo(seed=seed), min_diameter_px=8)
    for centre in SHARP:
        found = _at(search.discs, centre)
        assert len(found) == 1 and found[0].usable and not found[0].soft_edge, centre
    for centre in SOFT:
        found = _at(search.discs, centre)
        assert len(found) == 1 and found[0].usable and found[0].soft_edge, (centre, search.rejected)
        assert found[0].diameter_px == pytest.approx(2 * RADIUS, rel=0.1)
        assert found[0].to_json(outline=False)["soft_edge"] is True
        # kept, so not listed as refused: neither its measurement nor another of the same disc
        assert not [r for r in search.rejections if r.rejected_because == "soft edge"
                    and math.dist(r.center_xy, found[0].center_xy) < 0.25 * found[0].diameter_px], centre
    assert not _at(search.discs, GLOW), [(d.center_xy, d.diameter_px) for d in search.discs]


def test_a_disc_blurred_past_the_soft_tier_is_no_disc():
    """Blurred by 0.5 of its radius (an edge of about 1.25 radii): as soft as a glow, refused."""
    search = find_discs(_photo(soft_blur_rel=0.5, glow=False), min_diameter_px=8)
    assert all(not _at(search.discs, c) for c in SOFT), [(d.center_xy, d.diameter_px) for d in search.discs]
    assert search.rejected["soft edge"] >= 3, search.rejected


def test_the_soft_tier_leaves_the_sharp_discs_as_they_were(monkeypatch):
    """The soft-edged discs claim no candidate and seed no chain: the sharp discs come out exactly as
    where no blob is kept as soft-edged."""
    image = _photo()
    with_soft = [d for d in find_discs(image, min_diameter_px=8).discs if not d.soft_edge]
    monkeypatch.setattr(search_module, "soft_edged", lambda m: False)
    without = find_discs(image, min_diameter_px=8).discs
    assert not any(d.soft_edge for d in without)
    assert len(with_soft) == len(without) >= len(SHARP)
    for a, b in zip(with_soft, without):
        assert a.center_xy == b.center_xy and a.diameter_px == b.diameter_px and a.evidence == b.evidence
        assert np.array_equal(a.outline_xy, b.outline_xy) and a.outline_seen == b.outline_seen


def test_soft_discs_are_fitted_only_beside_sharp_ones():
    """Beside fewer than MIN_SHARP_DISCS sharp discs each soft one is set aside, saying why; beside
    enough, the soft ones fill the budget after every sharp one."""
    discs = find_discs(_photo(glow=False), min_diameter_px=8).discs
    sharp = [d for d in discs if not d.soft_edge]
    soft = [d for d in discs if d.soft_edge]
    assert len(sharp) >= MIN_SHARP_DISCS and len(soft) == len(SOFT)
    shape = (240, 420)
    few = sharp[: MIN_SHARP_DISCS - 1] + soft
    fitted, set_aside = choose_discs(few, FAMILIES, 12, {}, shape)
    assert {d.index for d in fitted} == {d.index for d in sharp[: MIN_SHARP_DISCS - 1]}
    assert all("soft" in set_aside[d.index] and f"({MIN_SHARP_DISCS - 1} here)" in set_aside[d.index] for d in soft)
    fitted, set_aside = choose_discs(sharp + soft, FAMILIES, 12, {}, shape)
    assert [d.soft_edge for d in fitted] == [False] * len(sharp) + [True] * len(soft)
    fitted, _ = choose_discs(sharp + soft, FAMILIES, len(sharp), {}, shape)
    assert not any(d.soft_edge for d in fitted)


@pytest.mark.parametrize("sigma", [60.0, 80.0])
def test_a_wide_glow_on_a_lit_ground_is_told_by_its_tail(sigma, monkeypatch):
    """A Gaussian glow over a lit ground is measured with its edge within the soft tier (its surround lies on its
    tail, which lowers its contrast, and its 50 % contour, drawn through the noise, runs where the noise steepens
    it: 1.16 of the radius without noise, 0.99 with it); its light goes on past that edge, as a disc's does not: no
    disc. Without the test of its tail it would be a soft-edged disc. (A smaller one, σ 40 px, is measured 1.12
    radii wide, beyond the tier.)"""
    size = int(8 * sigma)
    rows, cols = np.indices((size, size), dtype=np.float32)
    glow = np.exp(-((cols - size / 2) ** 2 + (rows - size / 2) ** 2) / (2.0 * sigma**2))
    image = (0.1 + 0.3 * glow + np.random.default_rng(1).normal(0.0, 0.003, glow.shape)).astype(np.float32)
    assert not [d for d in find_discs(image, min_diameter_px=8).discs if d.usable]
    monkeypatch.setattr(search_module, "light_ends", lambda luminance, m: True)
    assert [d.soft_edge for d in find_discs(image, min_diameter_px=8).discs if d.usable] == [True]


def test_a_soft_edged_disc_is_outlined_in_dashes():
    """The overlay draws a soft-edged disc's outline in dashes and gaps of about equal length, a sharp one whole."""
    from dataclasses import replace

    from bokehfit.report.overlay import draw_disc_overlay

    sharp = next(d for d in find_discs(_photo(glow=False), min_diameter_px=8).discs if not d.soft_edge)
    rows, cols = np.indices((240, 420))
    ring = np.abs(np.hypot(cols - sharp.center_xy[0], rows - sharp.center_xy[1]) - 0.5 * sharp.diameter_px) < 2.5
    drawn = {}
    for soft in (False, True):
        canvas = draw_disc_overlay(np.zeros((240, 420, 3), dtype=np.uint8), [replace(sharp, soft_edge=soft)])
        drawn[soft] = int((canvas[ring].max(axis=-1) > 100).sum())
    assert 0.3 * drawn[False] < drawn[True] < 0.7 * drawn[False], drawn
