"""Large candidates measured on the photo area-averaged (bokehfit/discs/scales.py).

Thresholds (stated once, asserted below):
- a copy pixel is the mean of its k × k photo pixels (float32: 1e-6 relative), clipped where any is;
- a disc of 300–420 px measured by the search on the copy lies within CENTRE_TOL_PX of its
  full-resolution measurement's centre and within DIAMETER_TOL_REL of its diameter, its outline
  within OUTLINE_TOL_PX of its outline (measured: 0.001 px, 4e-5 and 0.08–0.21 px: a hexagon's corners);
- a disc under 2 · MEASURE_SIDE_PX is measured on the photo itself (no copy is asked for), one over it on a copy.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from bokehfit.apertures import make_aperture
from bokehfit.discs import find_discs
from bokehfit.discs.measure import measure_candidate
from bokehfit.discs.scales import MEASURE_SIDE_PX, PhotoScales
from bokehfit.synthetic import SyntheticDisc, render_discs

CENTRE_TOL_PX = 0.05
DIAMETER_TOL_REL = 0.001
OUTLINE_TOL_PX = 0.4


def test_a_copy_pixel_is_the_mean_of_its_block_and_clipped_where_any_is():
    rng = np.random.default_rng(3)
    luminance = rng.uniform(0.0, 1.0, (101, 77)).astype(np.float32)
    clipped = rng.uniform(0.0, 1.0, (101, 77)) > 0.97
    scales = PhotoScales(luminance, clipped)
    assert scales.at(1)[0] is luminance
    copy, clipped_copy = scales.at(3)
    assert copy.shape == clipped_copy.shape == (33, 25)
    blocks = luminance[:99, :75].reshape(33, 3, 25, 3)
    np.testing.assert_allclose(copy, blocks.mean(axis=(1, 3)), rtol=1e-6)
    assert (clipped_copy == clipped[:99, :75].reshape(33, 3, 25, 3).any(axis=(1, 3))).all()
    assert scales.at(3)[0] is copy  # made once while it is the one asked for
    assert scales.at(2)[0].shape == (50, 38) and scales.at(3)[0] is not copy  # one copy held at a time


def test_the_factor_keeps_a_disc_at_least_measure_side_across():
    assert PhotoScales.factor(2.0 * MEASURE_SIDE_PX - 0.1) == 1
    assert PhotoScales.factor(2.0 * MEASURE_SIDE_PX) == 2
    assert PhotoScales.factor(7.5 * MEASURE_SIDE_PX) == 7


@pytest.mark.parametrize("diameter, shape", [(300.0, "circle"), (420.0, "ngon")])
def test_a_large_disc_measured_on_the_copy_is_the_full_resolution_one(diameter, shape):
    aperture = make_aperture(shape, 10.0, blades=6) if shape == "ngon" else make_aperture(shape)
    centre = (301.3, 287.8)
    image = render_discs(600, 580, [SyntheticDisc(centre, diameter, aperture, brightness=0.5)],
                         edge_blur_px=1.5, noise_sigma=0.003, seed=5)
    search = find_discs(image)
    assert len(search.discs) == 1 and PhotoScales.factor(diameter) >= 2
    found = search.discs[0]
    full = measure_candidate(image, None, found.center_xy, found.diameter_px, 0.5 * found.diameter_px, 1e-4, 4.0)
    assert full.reason is None
    assert np.hypot(*np.subtract(found.center_xy, full.center_xy)) <= CENTRE_TOL_PX
    assert abs(found.diameter_px / full.diameter_px - 1.0) <= DIAMETER_TOL_REL
    # Each outline point of the copy's lies near the full-resolution outline (its distance to that polygon).
    polygon = full.outline_xy.astype(np.float32)
    gaps = np.abs([cv2.pointPolygonTest(polygon, (float(x), float(y)), True) for x, y in found.outline_xy])
    assert np.max(gaps) <= OUTLINE_TOL_PX


def test_only_a_disc_of_twice_the_side_is_measured_on_a_copy(monkeypatch):
    asked = []
    at = PhotoScales.at
    monkeypatch.setattr(PhotoScales, "at", lambda self, factor: asked.append(factor) or at(self, factor))
    circle = make_aperture("circle")
    small = render_discs(400, 400, [SyntheticDisc((200.4, 199.6), 2.0 * MEASURE_SIDE_PX - 30.0, circle, brightness=0.5)],
                         noise_sigma=0.003, seed=2)
    assert len(find_discs(small)) == 1 and set(asked) == {1}
    asked.clear()
    large = render_discs(400, 400, [SyntheticDisc((200.4, 199.6), 2.0 * MEASURE_SIDE_PX + 30.0, circle, brightness=0.5)],
                         noise_sigma=0.003, seed=2)
    assert len(find_discs(large)) == 1 and 2 in asked
