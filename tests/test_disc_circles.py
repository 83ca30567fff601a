"""Disc candidates seen by their edges (:mod:`bokehfit.discs.circles`): overlapping discs, each found
by its own arc where the blob search sees one blob; judged on a person's labels of real photos."""

from __future__ import annotations

import math
from collections import Counter

import cv2
import numpy as np
import pytest

from bokehfit.apertures import make_aperture
from bokehfit.discs import find_discs
from bokehfit.discs.circles import (
    MIN_DIAMETER_PX,
    SIZED_MIN_DISCS,
    SMOOTH_REDUCE_SIGMA,
    _smoothed,
    find_circles,
    find_sized_circles,
)
from bokehfit.discs.labels import matches
from bokehfit.synthetic import SyntheticDisc, render_discs

CIRCLE = make_aperture("circle", 0.0)
#: Three discs of 80 px in a chain, each overlapping the next by 24 px, on a haze that brightens to the right.
CHAIN = [SyntheticDisc((100 + 56 * i, 200), 80.0, CIRCLE, brightness=0.3) for i in range(3)]


#: Five discs of 80 px in a chain, each overlapping the next by half its diameter.
TIGHT_CHAIN = [SyntheticDisc((80 + 40 * i, 200), 80.0, CIRCLE, brightness=0.3) for i in range(5)]


def _chain_photo(seed=1, chain=CHAIN, width=420):
    height = 400
    haze = np.broadcast_to(0.3 + 0.2 * np.arange(width, dtype=np.float32) / width, (height, width))
    return render_discs(width, height, chain, background=np.ascontiguousarray(haze), edge_blur_px=1.5,
                        noise_sigma=0.004, seed=seed)


def test_the_discs_at_a_chains_ends_are_circles_of_their_own():
    """The blob search sees one blob; each end disc shows over 3/4 of its outline as its own arc
    (the middle one, half of it, is no usable disc)."""
    circles = find_circles(_chain_photo(), 8.0, 500.0)
    for disc in (CHAIN[0], CHAIN[-1]):
        near = [(xy, d) for xy, d in circles if math.dist(xy, disc.center_xy) < 0.1 * disc.diameter_px]
        assert near, (disc.center_xy, circles)
        assert any(abs(d / disc.diameter_px - 1) < 0.1 for _, d in near), near


def test_no_circle_in_noise_or_a_smooth_swell():
    """Noise, and a swell of the light (a toned sky) of under 5 % of its level, are no edges."""
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:300, 0:400]
    swell = 0.4 * (1 + 0.04 * np.exp(-((xx - 200) ** 2 + (yy - 150) ** 2) / (2 * 40.0 ** 2)))
    image = (swell + rng.normal(0, 0.004, swell.shape)).astype(np.float32)
    assert find_circles(image, 8.0, 500.0) == []


@pytest.mark.parametrize("sigma", [2.0 * SMOOTH_REDUCE_SIGMA, 16.0, 32.0])
def test_a_wide_blur_on_a_reduced_copy_is_the_gaussian(sigma):
    """The band's local mean and spread, blurred on a reduced copy, are OpenCV's Gaussian blur of the
    whole copy to a hundredth of the light's spread about it, on texture at every scale from the
    pixel's to the blur's (away from the border, where the two extend the image differently)."""
    rng = np.random.default_rng(3)
    image = sum(cv2.GaussianBlur(rng.random((600, 800)).astype(np.float32), (0, 0), s) * s
                for s in (0.5, 3.0, 12.0, 40.0)).astype(np.float32)
    exact = cv2.GaussianBlur(image, (0, 0), sigma)
    inner = (slice(int(3 * sigma), -int(3 * sigma)),) * 2
    error = np.abs(_smoothed(image, sigma) - exact)[inner].max()
    assert error < 0.01 * float(np.std((image - exact)[inner])), error


def test_a_narrow_blur_is_the_gaussian_itself():
    image = np.random.default_rng(4).random((120, 160)).astype(np.float32)
    sigma = 1.9 * SMOOTH_REDUCE_SIGMA
    assert np.array_equal(_smoothed(image, sigma), cv2.GaussianBlur(image, (0, 0), sigma))


def test_small_discs_are_left_to_the_blob_search():
    image = _chain_photo()
    assert find_circles(image, 8.0, MIN_DIAMETER_PX) == []


def test_a_tight_chains_discs_are_found_at_the_size_found():
    """A chain of 80-px discs each overlapping the next by half: the edges follow the second disc's
    circle over less than the Hough transform's 0.8, yet over half of it they point at its centre.
    Voted for at the size found twice, it is found as the ends are, at its place and size (the radius
    the votes gather at, not the band's edge)."""
    image = _chain_photo(chain=TIGHT_CHAIN, width=520)
    sized = find_sized_circles(image, [(TIGHT_CHAIN[0].center_xy, 80.0), (TIGHT_CHAIN[-1].center_xy, 80.0)])
    for disc in (TIGHT_CHAIN[0], TIGHT_CHAIN[1], TIGHT_CHAIN[-1]):
        near = [(xy, d) for xy, d, _ in sized if math.dist(xy, disc.center_xy) < 0.1 * disc.diameter_px]
        assert len(near) == 1 and abs(near[0][1] / disc.diameter_px - 1) < 0.1, (disc.center_xy, sized)
    assert all(0.5 <= share for _, _, share in sized)


def test_a_size_is_sought_again_only_where_discs_have_it():
    """A size measured once is one blob's, not a depth's: not searched again. Noise and a smooth swell
    of the light give no circle at a size found."""
    image = _chain_photo(chain=TIGHT_CHAIN, width=520)
    assert find_sized_circles(image, [(TIGHT_CHAIN[0].center_xy, 80.0)] * (SIZED_MIN_DISCS - 1)
                              + [((300.0, 200.0), 20.0), ((300.0, 200.0), 300.0)]) == []
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:300, 0:400]
    swell = 0.4 * (1 + 0.04 * np.exp(-((xx - 200) ** 2 + (yy - 150) ** 2) / (2 * 40.0 ** 2)))
    noise = (swell + rng.normal(0, 0.004, swell.shape)).astype(np.float32)
    assert find_sized_circles(noise, [((100.0, 100.0), 40.0), ((300.0, 200.0), 40.0), ((200.0, 150.0), 80.0)] * 2) == []


@pytest.mark.parametrize("name, least", [("02_dew-glints_aaron-burden.jpg", 25),
                                         ("07_touch-the-light_canon-50d-ef100.jpg", 7),
                                         ("12_bokeh-lights_sebastian-muller.jpg", 6)])
def test_real_overlapping_discs_are_found_by_their_edges(reference_photo, name, least):
    """Photo 02's large dew discs, many touching, and photo 07's heavily overlapping 170-210 px discs:
    the blob search alone found 15 of 41 and 4 of 13 of the discs a person labelled usable; with the
    edge circles and the measurement along rays, 27 and 8. Photo 12's chain of 285-360 px discs: 5 of
    15 with the edge circles, 7 with the circles of the sizes found; 6 since outlines round two discs are split
    into them (bokehfit.discs.clusters): two of the 7 were such outlines, a 432-px one round the green and the
    peach disc and a 354-px one round the red-pink disc and the salmon one's near side, each within the match's
    tolerance of one of the pair, and most of the pairs' discs show under 75 % of their outline as their own."""
    from photo_factory import reference_labels

    from bokehfit.io import load_photo

    _, labels = reference_labels(name)
    photo = load_photo(reference_photo(name))
    found = [d for d in find_discs(photo.luminance, photo.clipped, min_diameter_px=8).discs if d.usable]
    hits = sum(any(matches(d.center_xy, d.diameter_px, label) for d in found) for label in labels.usable)
    assert hits >= least, f"{hits} of {len(labels.usable)} labelled usable discs found usable"


def test_a_carpet_of_small_discs_costs_the_edge_search_nothing():
    """Every pixel an edge (a grid of 9-px discs, 30 000 of them): texture, not discs of 32 px or more;
    the bands are skipped, not fed to the transform (whose work there has no bound). Judged by CPU time."""
    import time

    yy, xx = np.mgrid[-6:6, -6:6] + 0.5
    tile = np.where(np.hypot(xx, yy) <= 4.5, 0.8, 0.03).astype(np.float32)
    image = np.tile(tile, (174, 174))
    start = time.process_time()
    assert find_circles(image, 8.0, 500.0) == []
    assert time.process_time() - start < 2.0  # 12 s of CPU when the finest band was transformed


def _ring_photo(width: int, height: int, centres, diameter: float, seed: int = 3, glow: float = 0.06,
                glow_size: float = 0.75, glow_area_px: int = 10_000, centre: float = 0.015) -> np.ndarray:
    """Soap-bubble rings (a rim a sixth of the radius wide, a centre a little above the ground) over lit
    ground, blurred glows of foliage of about their size and larger: the ground's light varies as much
    as the rings', so that no blob of a ring stands out of it. A glow every ``glow_area_px`` pixels,
    ``glow`` at its peak, its σ ``glow_size`` of the rings' diameter."""
    rng = np.random.default_rng(seed)
    image = np.zeros((height, width), dtype=np.float32)
    glows = rng.uniform((0, 0), (width, height), size=(width * height // glow_area_px, 2))
    spread = glow_size * diameter
    for gx, gy in glows.astype(int):  # points of light, blurred below into glows of ``glow`` at their peak
        image[gy, gx] += glow * 2.0 * math.pi * spread**2
    image = 0.04 + cv2.GaussianBlur(image, (0, 0), spread)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    radius = 0.5 * diameter
    for cx, cy in centres:
        r = np.hypot(xx - cx, yy - cy)
        inside = np.clip(radius - r + 0.5, 0.0, 1.0)  # the disc, its edge antialiased
        rim = np.clip((r - 0.66 * radius) / (0.17 * radius), 0.0, 1.0)  # rising to the edge
        image += inside * (centre + 0.08 * rim)
    image = cv2.GaussianBlur(image, (0, 0), 1.0)  # the edge blur
    return (image + rng.normal(0.0, 0.003, image.shape)).astype(np.float32)


def _found(circles, centres, diameter):
    return [any(math.dist(xy, c) < 0.15 * diameter and abs(d / diameter - 1) < 0.15 for xy, d in circles)
            for c in centres]


def test_rings_of_a_large_photo_are_sought_at_their_own_scale():
    """A 9-MP photo's 40-px rings: the band of 32–64 px is searched on the photo halved, where they are
    20 px across, not left out to keep one copy small (the copy is searched tile by tile)."""
    from bokehfit.discs import circles

    centres = [(600.0 + 700.0 * i, 500.0 + 650.0 * j) for i in range(4) for j in range(4)]
    image = _ring_photo(3072, 3072, centres, 40.0)
    assert 3072 * 3072 / 4 <= circles.MAX_COPY_PIXELS  # halved, the photo is one copy of its band
    assert all(_found(find_circles(image, 8.0, 64.0), centres, 40.0))


def test_a_circle_across_the_tiles_borders_is_found_once():
    """Each tile is searched with a margin of the band's largest circle and keeps the circles whose
    centres it holds: a disc astride a border (or a corner) of the tiles is found, and once."""
    from bokehfit.discs import circles

    border = 2.0 * circles.TILE_PX  # a border of the tiles in the photo halved, in full-resolution pixels
    centres = [(border - 1.0, 700.0), (700.0, border + 1.0), (border, border), (border + 200.0, border - 300.0)]
    image = _ring_photo(1600, 1600, centres, 48.0)
    found = find_circles(image, 8.0, 64.0)
    assert all(_found(found, centres, 48.0)), found
    for centre in centres:
        assert sum(math.dist(xy, centre) < 0.15 * 48.0 for xy, _ in found) == 1, (centre, found)


def test_rings_over_bright_foliage_are_kept_by_their_own_step(monkeypatch):
    """Rings of 48 px over denser, brighter glows of foliage (a glow every 3,000 px, 0.1 at its peak,
    σ half their size; the rims 0.08): the surround varies pixel by pixel about as much as the
    rim, so the contour calls each ring faint, as on photo 04. The edges follow each circle, and its own
    step along rays shows a rim above a dimmer centre: kept, as rings of their size. The ground alone
    gives no ring, and without the rays (RING_RAYS_AFTER empty) the rings are lost."""
    from bokehfit.discs import search

    centres = [(300.0 + 300.0 * i, 300.0 + 300.0 * j) for i in range(3) for j in range(3)]
    dense = dict(glow=0.1, glow_size=0.5, glow_area_px=3000)

    def rings_found(image):
        discs = [d for d in find_discs(image, min_diameter_px=8).discs if d.usable and d.ring]
        return sum(any(math.dist(d.center_xy, c) < 0.15 * 48.0 and abs(d.diameter_px / 48.0 - 1) < 0.15
                       for d in discs) for c in centres), len(discs)

    image = _ring_photo(1200, 1200, centres, 48.0, **dense)
    found, rings = rings_found(image)
    assert found >= 7 and rings <= found + 1, (found, rings)
    assert rings_found(_ring_photo(1200, 1200, [], 48.0, **dense))[1] == 0
    monkeypatch.setattr(search, "RING_RAYS_AFTER", ())
    assert rings_found(image)[0] <= 1


def test_a_circle_of_a_size_found_is_a_disc_of_a_chain_where_it_crosses_a_disc_measured():
    """Where the circles of a size found are kept (:func:`bokehfit.discs.search._sized_discs`): those whose
    outline crosses a measured disc's, as a disc of a chain does; not one apart, nor one around a smaller
    disc or inside a larger one (a lit leaf about a disc, photo 09)."""
    from bokehfit.discs.search import _Chain

    chain = _Chain([((100.0, 100.0), 80.0), ((400.0, 100.0), 30.0)])
    assert chain.crosses((160.0, 100.0), 80.0)  # the next disc of the chain, 60 px on
    assert chain.crosses((100.0, 175.0), 80.0)  # overlapping it by 5 px
    assert not chain.crosses((200.0, 100.0), 80.0)  # 20 px apart
    assert not chain.crosses((402.0, 101.0), 72.0)  # around the 30-px disc
    assert not chain.crosses((110.0, 100.0), 40.0)  # inside the 80-px disc
    assert not _Chain([]).crosses((100.0, 100.0), 80.0)


#: Lone rings of 24 px (under the edge search's sizes), beside discs of their size that the search measured.
LONE_RING_DIAMETER = 24.0
LONE_PLAIN = [(150.0 + 300.0 * i, 150.0 + 300.0 * j) for i in range(3) for j in range(3)]
LONE_RINGS = [(x + 70.0, y) for x, y in LONE_PLAIN] + [(x, y + 70.0) for x, y in LONE_PLAIN]
LONE_OTHERS = [(x - 70.0, y) for x, y in LONE_PLAIN]


def _lone_ring_photo(seed: int, rings=True, flat_discs=False) -> np.ndarray:
    """Soap-bubble rings whose centres are no brighter than the lit ground (:func:`_ring_photo`), each 70 px
    from one of nine bright plain discs of their size, on no chain; beside each plain disc on the other side
    a glow of the discs' size or, with ``flat_discs``, a faint flat disc of it (no rim)."""
    d = LONE_RING_DIAMETER
    image = _ring_photo(900, 900, LONE_RINGS if rings else [], d, seed=seed, glow=0.1, glow_size=0.5,
                        glow_area_px=3000, centre=0.0)
    yy, xx = np.mgrid[0:900, 0:900].astype(np.float32)
    for cx, cy in LONE_PLAIN:
        image += 0.3 * np.clip(0.5 * d - np.hypot(xx - cx, yy - cy) + 0.5, 0.0, 1.0)
    for cx, cy in LONE_OTHERS:
        r = np.hypot(xx - cx, yy - cy)
        image += 0.05 * np.clip(0.5 * d - r + 0.5, 0.0, 1.0) if flat_discs else 0.08 * np.exp(-0.5 * (r / (0.3 * d)) ** 2)
    return image.astype(np.float32)


@pytest.mark.parametrize("seed", [3, 4])
def test_a_circle_of_a_size_found_on_no_chain_is_kept_only_as_a_ring_all_round(seed, monkeypatch):
    """The circles of a size the search measured that cross no disc of a chain (photo 04's soap-bubble rings
    over lit juniper, which no blob and no edge circle shows) are measured as rings
    (:func:`bokehfit.discs.search._lone_ring`): each ring is found at its size, and nothing else is: not the
    glows or the faint flat discs of the same size beside the same discs, not the ground. Without the lone
    circles (MAX_LONE_RINGS 0) no ring is."""
    from bokehfit.discs import search
    from bokehfit.discs.places import _measure_place

    d = LONE_RING_DIAMETER

    def sized(image):
        measured = [_measure_place(image, None, xy, d, 8.0) for xy in LONE_PLAIN]
        assert all(m.reason is None for m in measured)
        search._sized_discs(image, None, measured, 8.0, 500.0, Counter(), [])
        return measured[len(LONE_PLAIN):]

    def rings_found(new):
        return sum(any(math.dist(m.center_xy, c) < 0.15 * d and abs(m.diameter_px / d - 1) < 0.15 and m.ring
                       for m in new) for c in LONE_RINGS)

    new = sized(_lone_ring_photo(seed))
    assert rings_found(new) >= 16 and len(new) == rings_found(new), [(m.center_xy, m.diameter_px) for m in new]
    assert sized(_lone_ring_photo(seed, rings=False)) == []
    assert sized(_lone_ring_photo(seed, rings=False, flat_discs=True)) == []
    monkeypatch.setattr(search, "MAX_LONE_RINGS", 0)
    assert sized(_lone_ring_photo(seed)) == []
