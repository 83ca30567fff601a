"""The fit on photos drawn with OpenCV (filled circles, ellipses and polygons, Gaussian blur,
noise), not with bokehfit's model: what a real photo puts beside its discs.

A real photo's clearest blobs are often not discs at all: a lit leaf, a petal, two glows run
together. They are larger and brighter than the discs, so a fit that takes the clearest first
would be left with them. The fit takes the discs whose outline some aperture shape explains
first, and then asks the winner to show one angle on every disc it keeps.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from bokehfit.discs import find_discs
from bokehfit.fit import FitOptions, fit_aperture

#: Subpixel drawing: OpenCV's shift argument (coordinates in 1/16 px).
SHIFT = 4
ROUND_DIAMETER_PX = 30.0
ROUND_BRIGHTNESS = 0.35
JUNK_BRIGHTNESS = 0.8


def _scaled(points):
    return np.round(np.asarray(points, dtype=np.float64) * (1 << SHIFT)).astype(np.int32)


def _leaf(centre, length, angle_deg):
    """A lit leaf: a pointed, lopsided outline (two arcs meeting at a tip), turned by ``angle_deg``."""
    t = np.linspace(0.0, math.pi, 40)
    upper = np.column_stack([length * (0.5 - 0.5 * np.cos(t)), 0.35 * length * np.sin(t) ** 0.8])
    lower = np.column_stack([length * (0.5 + 0.5 * np.cos(t)), -0.18 * length * np.sin(t) ** 1.5])
    outline = np.vstack([upper, lower]) - [0.5 * length, 0.0]
    a = math.radians(angle_deg)
    turned = outline @ np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
    return turned + centre


def _photo(seed=0):
    """Eight round discs in a row and, below them, eight larger and brighter things that are not discs:
    lit leaves at several angles and pairs of glows run together."""
    rng = np.random.default_rng(seed)
    image = np.full((330, 760), 0.04, dtype=np.float32)
    rounds = [(60.0 + 90.0 * i + rng.uniform(-3, 3), 60.0 + rng.uniform(-3, 3)) for i in range(8)]
    for centre in rounds:
        cv2.circle(image, tuple(int(v) for v in _scaled(centre)), int(round(ROUND_DIAMETER_PX / 2 * (1 << SHIFT))),
                   ROUND_BRIGHTNESS + 0.04, thickness=-1, lineType=cv2.LINE_AA, shift=SHIFT)
    for i in range(8):
        centre = np.array([60.0 + 90.0 * i, 200.0 + 60.0 * (i % 2)])
        layer = np.zeros_like(image)
        if i % 2 == 0:
            cv2.fillPoly(layer, [_scaled(_leaf(centre, 52.0, rng.uniform(0, 180)))], JUNK_BRIGHTNESS,
                         lineType=cv2.LINE_AA, shift=SHIFT)
        else:
            for dx in (-9.0, 9.0):
                cv2.circle(layer, tuple(int(v) for v in _scaled(centre + [dx, 0.5 * dx])), int(18 * (1 << SHIFT)),
                           JUNK_BRIGHTNESS, thickness=-1, lineType=cv2.LINE_AA, shift=SHIFT)
        image = np.maximum(image, layer + 0.04)
    image = cv2.GaussianBlur(image, (0, 0), 1.0)
    image += rng.normal(0.0, 0.003, image.shape).astype(np.float32)
    return image, rounds


def test_discs_whose_outline_a_shape_explains_are_fitted_before_clearer_junk():
    image, rounds = _photo()
    search = find_discs(image)
    fit = fit_aperture(image, search.discs, options=FitOptions(max_discs=8))
    assert fit, fit
    assert fit.aperture.is_circle, fit.message
    used = [item.disc.center_xy for item in fit.disc_fits]
    on_rounds = sum(min(math.dist(c, r) for r in rounds) < 2.0 for c in used)
    assert on_rounds >= 6, f"{on_rounds} of the {len(used)} discs used are the round discs: {fit.message}"
    assert fit.diameter_px == pytest.approx(ROUND_DIAMETER_PX, rel=0.08)


def test_blobs_no_aperture_explains_are_set_aside_with_the_reason():
    """A defocused light is the aperture's image: with a budget for every blob (16), the lit leaves
    and the glows run together are still not fitted; each says why in the fit (no shape explains its
    outline, it is stretched as no other disc is and not as a cat-eye, or, a glow measured as a circle
    of its own, its outline is not the shape the other discs share)."""
    image, rounds = _photo()
    search = find_discs(image)
    fit = fit_aperture(image, search.discs, options=FitOptions(max_discs=16))
    assert fit and fit.aperture.is_circle, fit.message
    used = [item.disc for item in fit.disc_fits]
    assert all(min(math.dist(d.center_xy, r) for r in rounds) < 2.0 for d in used), [d.center_xy for d in used]
    junk = [d for d in search.discs if d.usable and min(math.dist(d.center_xy, r) for r in rounds) > 10.0]
    assert junk, "the photo's leaves and glows are found as usable blobs"
    reasons = [fit.rejected.get(d.index, "") for d in junk]
    assert all("no aperture shape explains its outline" in r or "not the aperture's image" in r
               or "not the shape the other discs share" in r for r in reasons), reasons
