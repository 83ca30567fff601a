"""The disc finder on what real photos hold: saturated, overlapping, occluded, large
and faint, and ring-shaped discs, and things that are not discs.

The photos here are drawn with OpenCV (filled circles and polygons, Gaussian blur,
clipping), not with bokehfit's kernels, so the finder is not tested against its own model.

Thresholds (stated once, asserted below):
- diameter within DIAMETER_TOL_REL of the drawn one, centre within CENTRE_TOL_PX;
- a disc overlapped by its neighbours shows between OVERLAP_SEEN_RANGE of its outline as its own;
- a saturated disc's 50 % outline lies outside the true edge, by at most CLIP_SHIFT_SIGMA blur sigmas:
  a blurred edge of height A clipped at c reaches c/2 at σ·Φ⁻¹(1 − c/(2A)) outside the edge (A = 4c: 1.15 σ).
  The outline keeps the shape; the fit with the clipping in its model recovers the size.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from bokehfit.discs import FULL_OUTLINE_SEEN, MIN_FIT_SEEN, find_discs
from bokehfit.discs.candidates import MIN_NOISE
from bokehfit.discs.measure import measure_candidate

DIAMETER_TOL_REL = 0.03
CENTRE_TOL_PX = 1.0
#: Three discs of diameter d in a row, d·0.8 apart: outside the middle one, the outer ones show about
#: 0.74 of their outline (the middle one, outside both, about 2·(1 − 2·0.41/π) ≈ 0.48); a margin either way.
OVERLAP_SEEN_RANGE = (0.35, 0.9)
CLIP_SHIFT_SIGMA = 1.5
#: Subpixel drawing: OpenCV's shift argument (coordinates in 1/16 px).
SHIFT = 4


def drawn_diameter(diameter):
    """Equal-area diameter of the filled circle :func:`draw_disc` draws for ``diameter`` (OpenCV's
    anti-aliased circles come out about a pixel wider than asked)."""
    layer = draw_disc(np.zeros((int(diameter) + 20,) * 2, np.float32), ((diameter + 19) / 2,) * 2, diameter, 1.0)
    return 2.0 * math.sqrt(float(layer.sum()) / math.pi)


def draw_disc(image, centre, diameter, value, *, thickness=-1):
    """Add a filled (or, with ``thickness`` > 0, a ring) circle of ``value`` to ``image`` (anti-aliased)."""
    layer = np.zeros_like(image)
    scale = 1 << SHIFT
    cv2.circle(
        layer,
        (round(centre[0] * scale), round(centre[1] * scale)),
        round(diameter / 2 * scale),
        float(value),
        thickness=thickness,
        lineType=cv2.LINE_AA,
        shift=SHIFT,
    )
    return image + layer


def finish(image, *, blur=1.0, noise=0.003, clip=None, seed=0):
    """Blur (the lens), noise (the sensor) and clipping (the file); returns luminance and the clipped mask."""
    image = cv2.GaussianBlur(image, (0, 0), blur) if blur else image
    image = image + np.random.default_rng(seed).normal(0.0, noise, image.shape).astype(np.float32)
    if clip is None:
        return image, None
    return np.minimum(image, clip), image >= clip


def nearest(discs, centre):
    return min(discs, key=lambda d: math.hypot(d.center_xy[0] - centre[0], d.center_xy[1] - centre[1]), default=None)


def assert_measured(disc, centre, diameter):
    diameter = drawn_diameter(diameter)
    assert disc is not None
    offset = math.hypot(disc.center_xy[0] - centre[0], disc.center_xy[1] - centre[1])
    assert offset <= CENTRE_TOL_PX, f"centre off by {offset:.2f} px"
    assert abs(disc.diameter_px - diameter) <= DIAMETER_TOL_REL * diameter, f"diameter {disc.diameter_px:.2f} for {diameter}"


def test_saturated_disc_is_kept_as_edge_evidence():
    image = np.full((200, 300), 0.05, dtype=np.float32)
    image = draw_disc(image, (90.3, 100.6), 70, 4.0)  # clipped four times over
    image = draw_disc(image, (215.2, 98.9), 60, 0.5)  # clean
    blur = 1.0
    luminance, clipped = finish(image, blur=blur, clip=1.0)
    search = find_discs(luminance, clipped)
    hot, clean = nearest(search.discs, (90.3, 100.6)), nearest(search.discs, (215.2, 98.9))
    assert hot is not None and math.hypot(hot.center_xy[0] - 90.3, hot.center_xy[1] - 100.6) <= CENTRE_TOL_PX
    assert drawn_diameter(70) <= hot.diameter_px <= drawn_diameter(70) + 2.0 * CLIP_SHIFT_SIGMA * blur, hot.diameter_px
    assert hot.saturated and hot.evidence == "edge" and hot.clipped_share > 0.8
    assert hot.outline_seen >= FULL_OUTLINE_SEEN and hot.shape_usable and hot.usable  # fitted by its edge
    assert_measured(clean, (215.2, 98.9), 60)
    assert not clean.saturated and clean.evidence == "plateau" and clean.clipped_share == 0.0 and clean.usable


def test_bloom_into_clipped_light_marks_the_outline_unseen():
    image = np.full((200, 260), 0.05, dtype=np.float32)
    image = draw_disc(image, (120.0, 100.0), 80, 4.0)
    luminance, clipped = finish(image, clip=1.0)
    # A red light beside the disc's right side: dim in luminance, clipped in its red channel.
    luminance[60:140, 161:175] += 0.2
    clipped[60:140, 161:175] = True
    search = find_discs(luminance, clipped)
    disc = nearest(search.discs, (120.0, 100.0))
    assert disc is not None and disc.saturated, search.rejected
    assert disc.evidence == "partial" and 0.5 < disc.outline_seen < FULL_OUTLINE_SEEN
    unseen = disc.outline_xy[~disc.outline_reliable]
    assert unseen[:, 0].min() > 140.0  # only the stretch next to the streak


def test_overlapping_discs_are_split_into_a_cluster():
    centres = [(80.4, 100.2), (136.1, 100.7), (191.8, 99.6)]
    image = np.full((200, 280), 0.04, dtype=np.float32)
    for (x, y), value in zip(centres, (0.5, 0.6, 0.45)):
        image = draw_disc(image, (x, y), 70, value)
    luminance, _ = finish(image)
    search = find_discs(luminance)
    found = [nearest(search.discs, c) for c in centres]
    assert len({id(d) for d in found}) == 3, [d.center_xy for d in search.discs]
    for disc, centre in zip(found, centres):
        offset = math.hypot(disc.center_xy[0] - centre[0], disc.center_xy[1] - centre[1])
        assert offset <= 4.0, f"centre off by {offset:.1f} px"
        assert disc.evidence == "partial" and disc.overlaps
        assert disc.usable == (disc.outline_seen >= MIN_FIT_SEEN)  # fitted with the others' light left out
        assert OVERLAP_SEEN_RANGE[0] <= disc.outline_seen, disc.outline_seen
    # Light adds: the middle disc's edge inside its neighbours' light is still a step of its own
    # contrast, which the measurement along rays follows all round; the outer ones' contours show
    # their part outside the middle one.
    assert found[1].outline_seen >= 0.95 and found[1].usable
    assert all(OVERLAP_SEEN_RANGE[0] <= d.outline_seen <= OVERLAP_SEEN_RANGE[1] for d in (found[0], found[2]))
    assert found[0].cluster is not None and found[0].cluster == found[1].cluster == found[2].cluster
    # The middle disc's own outline is its circle, the arcs inside its neighbours' light included.
    middle = found[1]
    own = middle.outline_xy[middle.outline_reliable]
    assert np.abs(np.hypot(*(own - np.array(centres[1])).T) - 35.0).max() < 1.5
    assert (np.abs(own[:, 0] - centres[1][0]) > 0.5 * 56.0).any()  # inside the neighbours' light


#: A small disc on a large one's edge (a near light's disc over a far one's, or the other way round): the
#: small one's centre is no peak of their union's distance transform (its depth, its radius, is under half
#: the large one's), so only the outline's arcs between its cusps tell the two apart. (diameters, centre
#: distance, brightnesses): the same light, the small one dimmer, the small one brighter.
SMALL_ON_LARGE = [((100, 40), 45, (0.5, 0.5)), ((100, 40), 45, (0.5, 0.3)), ((100, 50), 50, (0.4, 0.6))]


def small_on_large(diameters, distance, values):
    centres = [(100.3, 110.6), (100.3 + distance, 110.6 + 0.2 * distance)]
    image = np.full((220, 260), 0.04, dtype=np.float32)
    for centre, diameter, value in zip(centres, diameters, values):
        image = draw_disc(image, centre, diameter, value)
    return finish(image)[0], centres


@pytest.mark.parametrize("diameters, distance, values", SMALL_ON_LARGE)
def test_a_small_disc_on_a_large_ones_edge_is_split_from_it(diameters, distance, values):
    luminance, centres = small_on_large(diameters, distance, values)
    search = find_discs(luminance)
    found = [nearest(search.discs, c) for c in centres]
    assert len({id(d) for d in found}) == 2, [(d.center_xy, d.diameter_px) for d in search.discs]
    for disc, centre, diameter in zip(found, centres, diameters):
        assert_measured(disc, centre, diameter)
    assert len(search.discs) == 2  # and no disc of their union


@pytest.mark.parametrize("seed", range(8))
def test_a_disc_whose_edge_wanders_is_not_cut_at_its_dents(seed):
    """A real disc's edge wanders by several per cent of its radius (dust, the blades' play, the tone curve): its
    outline's dents are concavities, but the arcs between them fit one circle about as well as each its own, so
    the outline is one disc's, not discs run together. Drawn: harmonics 2, 4, 5 and 7 of 4 % each at random
    phases (the outlines of tests/test_fit_blades_shown.py), filled at 8× and area-averaged."""
    rng = np.random.default_rng(seed)
    theta = np.linspace(0.0, 2.0 * math.pi, 720, endpoint=False)
    r = 1.0 + sum(0.04 * rng.normal() * np.cos(k * theta + rng.uniform(0.0, 2.0 * math.pi)) for k in (2, 4, 5, 7))
    scale, side, centre = 8, 140, (70.3, 69.6)
    big = np.zeros((side * scale, side * scale), np.uint8)
    outline = np.stack([centre[0] + 40.0 * r * np.cos(theta), centre[1] + 40.0 * r * np.sin(theta)], axis=1)
    cv2.fillPoly(big, [np.round((outline + 0.5) * scale - 0.5).astype(np.int32)], 255)
    light = cv2.resize(big.astype(np.float32) / 255.0, (side, side), interpolation=cv2.INTER_AREA)
    luminance, _ = finish(0.05 + 0.5 * light)
    search = find_discs(luminance)
    assert len(search.discs) == 1, [(d.center_xy, d.diameter_px) for d in search.discs]
    drawn = 2.0 * math.sqrt(float(light.sum()) / math.pi)
    assert abs(search.discs[0].diameter_px - drawn) <= DIAMETER_TOL_REL * drawn


def test_a_step_traced_round_two_discs_is_split_into_them():
    """An outline along rays that runs round a disc's neighbour too (a soft edge's step found on the far side of
    both) is the union's: the disc asked for is the one of its parts at the place (places._split_steps)."""
    from bokehfit.discs.places import _split_steps
    from bokehfit.discs.reasons import NoDisc, Reason

    diameters = (100, 40)
    luminance, centres = small_on_large(diameters, 45, (0.5, 0.5))
    union = measure_candidate(luminance, None, (120.0, 114.0), 110.0, 60.0, MIN_NOISE, 8.0)
    assert union.reason is None and union.diameter_px > 1.02 * drawn_diameter(diameters[0])  # the two as one
    for centre, diameter in zip(centres, diameters):
        assert_measured(_split_steps(union, centre, diameter), centre, diameter)
    none = NoDisc(Reason.FAINT)
    assert _split_steps(none, centres[0], diameters[0]) is none


def test_disc_crossed_by_a_branch_is_kept_with_the_crossing_unseen():
    centre = (120.3, 110.8)
    image = np.full((220, 240), 0.04, dtype=np.float32)
    image = draw_disc(image, centre, 90, 0.6)
    branch = np.zeros_like(image)
    cv2.line(branch, (20, 30), (220, 190), 1.0, thickness=5, lineType=cv2.LINE_AA)
    image = image * (1.0 - branch) + 0.02 * branch  # the in-focus branch hides the disc behind it
    luminance, _ = finish(image, blur=0.0)
    search = find_discs(luminance)
    near = [d for d in search.discs if math.hypot(d.center_xy[0] - centre[0], d.center_xy[1] - centre[1]) < 45]
    assert len(near) == 1, [(d.center_xy, d.diameter_px) for d in near]  # one disc, not its two halves
    disc = near[0]
    assert_measured(disc, centre, 90)
    assert disc.occluded and disc.evidence == "partial" and 0.8 < disc.outline_seen < FULL_OUTLINE_SEEN
    assert disc.shape_usable and disc.usable  # fitted with the branch's pixels left out
    # The unseen points are where the branch crosses the outline, nowhere else.
    unseen = disc.outline_xy[~disc.outline_reliable]
    to_line = np.abs((unseen[:, 1] - 30) * 200 - (unseen[:, 0] - 20) * 160) / math.hypot(200, 160)
    assert to_line.max() < 8.0


@pytest.mark.parametrize("contrast", [0.05, 0.1, 0.2])
def test_large_faint_discs_over_a_bright_background(contrast):
    height, width = 2000, 3000
    rows, cols = np.mgrid[0:height, 0:width].astype(np.float32)
    vignetting = ((cols - width / 2) ** 2 + (rows - height / 2) ** 2) / ((width / 2) ** 2 + (height / 2) ** 2)
    background = 0.4 + 0.15 * cols / width - 0.1 * vignetting  # smooth bright haze, darker at the corners
    discs = [((600.4, 640.2), 160.0), ((1700.7, 960.3), 300.0), ((2400.2, 1400.6), 420.0), ((700.3, 1500.8), 480.0)]
    image = background.astype(np.float32)
    for (x, y), diameter in discs:
        image = image + draw_disc(np.zeros_like(image), (x, y), diameter, contrast * background[round(y), round(x)])
    luminance, _ = finish(image, blur=2.0, noise=0.004)
    search = find_discs(luminance)
    for centre, diameter in discs:
        assert_measured(nearest(search.discs, centre), centre, diameter)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_faint_disc_s_frayed_edge_is_no_occluder(seed):
    # A 150-px disc 6 % above its ground with pixel noise of a quarter of its contrast (reference photo
    # 02's faint dew discs), seen by the blob search as a smaller hollow blob: measured as a ring, its
    # gaps closed. Pixel by pixel its 50 % region frays all round; the outline is drawn on the light
    # with that noise quieted, and so are its gaps sought: the fraying is no gap, and the outline the
    # disc's own (before, 0-6 % of it was, and the closed fraying made it 7-10 % too large).
    centre, diameter = (200.3, 190.7), 150.0
    image = draw_disc(np.full((400, 420), 0.2, np.float32), centre, diameter, 0.06)
    luminance, _ = finish(image, blur=2.0, noise=0.014, seed=seed)
    disc = measure_candidate(luminance, None, centre, 60.0, 0.5 * diameter, MIN_NOISE, 16.0)
    assert disc.reason is None, disc.reason
    assert_measured(disc, centre, diameter)
    assert disc.outline_reliable.mean() >= MIN_FIT_SEEN


def test_ring_discs_are_measured_by_their_outer_outline():
    image = np.full((200, 300), 0.03, dtype=np.float32)
    rings = [((70.2, 100.4), 36.0), ((160.6, 99.1), 44.0)]
    for centre, diameter in rings:
        image = draw_disc(image, centre, diameter - 3.0, 0.5, thickness=3)  # a 3-px rim, outer edge at the diameter
        image = draw_disc(image, centre, diameter - 5.0, 0.05)  # a dim centre
    image = draw_disc(image, (245.3, 100.7), 40.0, 0.4)  # a plain disc
    luminance, _ = finish(image, blur=0.7)
    search = find_discs(luminance)
    for centre, diameter in rings:
        disc = nearest(search.discs, centre)
        assert disc is not None and disc.ring and disc.evidence == "edge", search.rejected
        offset = math.hypot(disc.center_xy[0] - centre[0], disc.center_xy[1] - centre[1])
        assert offset <= CENTRE_TOL_PX and abs(disc.diameter_px - diameter) <= 0.06 * diameter, disc.diameter_px
    plain = nearest(search.discs, (245.3, 100.7))
    assert plain is not None and not plain.ring and plain.evidence == "plateau"


def test_not_discs_are_refused_with_a_reason_each():
    image = np.full((300, 400), 0.04, dtype=np.float32)
    wave = [(30 + t, 110 + 30 * math.sin(t / 30.0)) for t in np.linspace(0, 60 * math.pi, 100)]  # its centre on it
    cv2.polylines(image, [np.round(np.array(wave) * 16).astype(np.int32)], False, 0.7, 2, cv2.LINE_AA, 4)  # a wavy glint
    cv2.line(image, (30, 260), (370, 250), 0.6, thickness=3, lineType=cv2.LINE_AA)  # a lit stem
    petals = [
        (320 + r * math.cos(t), 100 + r * math.sin(t))
        for t, r in zip(np.linspace(0, 2 * math.pi, 48, endpoint=False), np.tile([55, 55, 15, 15], 12))
    ]
    cv2.fillPoly(image, [np.round(np.array(petals) * 16).astype(np.int32)], 0.6, lineType=cv2.LINE_AA, shift=4)  # a flower
    luminance, _ = finish(image, blur=0.8)
    search = find_discs(luminance)
    assert not search, [(d.center_xy, d.diameter_px) for d in search.discs]
    reasons = {r.rejected_because for r in search.rejections}
    assert {"elongated", "not compact"} <= reasons, search.rejected
    # The wavy glint: measured as a line, or, where its candidate's centre lies beside the line
    # (a band's blob of its bends), as no outline closing around that centre.
    wave_reasons = {r.rejected_because for r in search.rejections if 60 < r.center_xy[0] < 190 and not r.rejected_because.startswith("not a")}
    assert wave_reasons and wave_reasons <= {"line-like", "no outline", "faint", "inside a larger disc"}, search.rejections
    for reason, count in search.rejected.items():
        if reason != "beyond the candidate limit":
            assert sum(r.rejected_because == reason for r in search.rejections) == count
    flower = [r for r in search.rejections if math.hypot(r.center_xy[0] - 320, r.center_xy[1] - 100) < 20]
    assert "not compact" in {r.rejected_because for r in flower}
