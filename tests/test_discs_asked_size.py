"""A person's disc is measured at about the size they read: its edge sought within the labels' own match of it.

Reference photo 14 (an autumn leaf) shows vertical strings of overlapping discs over a glow; a person reads
the bottom disc of each string from the part of its outline it shows. Measured along rays from the person's
place with the rays' own band (half to 1.55 times the radius), the disc's top took the far side of its upper
neighbour's bright rim, a line crossing the disc well inside its edge: outlines flattened on top, which no
aperture shape explains, and no disc to fit. The scene is drawn here by geometry (OpenCV's anti-aliased
circles, not bokehfit's aperture model): a faint disc under a brighter neighbour with a bright rim, over a glow.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from bokehfit.discs import measure_discs_at
from bokehfit.discs.labels import MATCH_DIAMETER_REL
from bokehfit.discs.places import asked_band

RADIUS = 100.0
CENTRE = (210.0, 360.0)


def _string_of_discs(seed: int, gap: float = 140.0) -> np.ndarray:
    """Linear light: a glow, a disc of 3 % at CENTRE and, ``gap`` px above it, a neighbour of 6 % with a bright
    rim 8 px wide (20 %) just inside its edge; blurred (σ 2.5 px) and with noise of 0.004."""
    rng = np.random.default_rng(seed)
    height, width = 560, 420
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    image = 0.05 + 0.1 * np.exp(-((xx - 210.0) ** 2 + (yy - 150.0) ** 2) / (2 * 200.0 ** 2))

    def circle(level: float, cy: float, radius: float, thickness: int = -1) -> np.ndarray:
        layer = np.zeros((height, width), np.float32)
        cv2.circle(layer, (round(CENTRE[0] * 16), round(cy * 16)), round(radius * 16), level, thickness, cv2.LINE_AA, 4)
        return layer

    image = image + circle(0.03, CENTRE[1], RADIUS) + circle(0.06, CENTRE[1] - gap, RADIUS) \
        + circle(0.2, CENTRE[1] - gap, RADIUS - 4, 8)
    blurred = cv2.GaussianBlur(image.astype(np.float32), (0, 0), 2.5)
    return blurred + rng.normal(0.0, 0.004, blurred.shape).astype(np.float32)


def _measured(image: np.ndarray):
    search = measure_discs_at(image, None, [(CENTRE, 2.0 * RADIUS)])
    assert len(search.discs) == 1, [r.rejected_because for r in search.rejections]
    return search.discs[0]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_disc_of_a_string_is_measured_at_the_size_read(seed, monkeypatch):
    image = _string_of_discs(seed)
    disc = _measured(image)
    assert math.dist(disc.center_xy, CENTRE) <= 2.0 and abs(disc.diameter_px / (2.0 * RADIUS) - 1.0) <= 0.02, disc
    radii = np.hypot(*(disc.outline_xy - np.array(disc.center_xy)).T)
    assert np.std(radii) <= 0.02 * RADIUS and disc.usable
    # With the rays' own band the top is the neighbour's rim: the disc comes out 6 % small, 10 px low.
    monkeypatch.setattr("bokehfit.discs.places.asked_band", lambda diameter: None)
    wide = _measured(image)
    assert math.dist(wide.center_xy, CENTRE) >= 8.0 and wide.diameter_px <= 0.96 * 2.0 * RADIUS, wide


def _polygon(points: np.ndarray, seed: int) -> np.ndarray:
    """Linear light: a polygon of 3 % over a glow, blurred (σ 2 px), with noise of 0.003."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:400, 0:400].astype(np.float32)
    image = 0.05 + 0.1 * np.exp(-((xx - 200.0) ** 2 + (yy - 100.0) ** 2) / (2 * 250.0 ** 2))
    layer = np.zeros((400, 400), np.float32)
    cv2.fillPoly(layer, [np.round(points * 16).astype(np.int32)], 0.03, cv2.LINE_AA, 4)
    blurred = cv2.GaussianBlur((image + layer).astype(np.float32), (0, 0), 2.0)
    return blurred + rng.normal(0.0, 0.003, blurred.shape).astype(np.float32)


def _reach(m) -> float:
    return float(np.max(np.hypot(*(m.outline_xy - np.array(m.center_xy)).T)))


@pytest.mark.parametrize("shape", ["triangle", "slit"])
def test_corners_outside_the_band_are_kept(shape):
    """A triangle's corners lie at 1.56 equal-area radii, a slit's (aspect 0.4) at 1.5: read 10 % small, they lie
    outside the band of the size read. Its rays there find no step, and the rays' own band keeps the corners."""
    from bokehfit.discs.candidates import MIN_NOISE
    from bokehfit.discs.places import _stepped
    from bokehfit.discs.rays import measure_rays

    radius, centre = 60.0, np.array([200.0, 200.0])
    area = math.pi * radius ** 2
    if shape == "triangle":
        circumradius = math.sqrt(2.0 * area / (3.0 * math.sin(2.0 * math.pi / 3.0)))
        angles = 0.3 + 2.0 * np.pi * np.arange(3) / 3.0
        points = centre + circumradius * np.column_stack([np.cos(angles), np.sin(angles)])
    else:
        height = math.sqrt(area / 0.4)
        points = centre + 0.5 * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * np.array([0.4 * height, height])
    image = _polygon(points, 0)
    reading = 0.9 * 2.0 * radius
    wide = measure_rays(image, None, tuple(centre), reading, MIN_NOISE, 1.0)
    narrow = measure_rays(image, None, tuple(centre), reading, MIN_NOISE, 1.0, asked_band(reading))
    kept = _stepped(image, None, tuple(centre), reading, 1.0, read=True)
    assert _reach(narrow) < 0.92 * _reach(wide)  # the band alone would round the corners off
    assert kept.diameter_px == wide.diameter_px and _reach(kept) == _reach(wide)


def test_the_band_is_the_labels_own_match():
    low, high = asked_band(200.0)
    assert math.isclose(low, 100.0 * (1.0 - MATCH_DIAMETER_REL)) and math.isclose(high, 100.0 * (1.0 + MATCH_DIAMETER_REL))
