"""Discs that show an odd shape turned by 180° (lights before the focus plane): the angle of a sure answer
rests on at least MIN_SURE_DISCS discs that show the aperture the same way round
(bokehfit.judging.judge). A triangle's disc turned by 180° sits 60° away: three discs each free to be turned
agree within the consensus's tolerance by chance about half the time each (a JPEG-60 copy of reference
photo 15, round discs, came out a sure rounded triangle from two discs and one "turned")."""

from __future__ import annotations

import dataclasses

import pytest

from bokehfit.apertures import make_aperture
from bokehfit.discs import find_discs
from bokehfit.fit import fit_aperture
from bokehfit.judging import MIN_SURE_DISCS, judge, short_doubts
from bokehfit.synthetic import SyntheticDisc, render_discs

SURE_METRICS = {"iou": 0.95}
DOUBT = "discs fitted show the aperture the same way round"


@pytest.fixture(scope="module")
def triangles():
    """Five triangles' discs of 70 px, the fourth and fifth turned by 180° (60° for a triangle), fitted."""
    discs = [SyntheticDisc((70.0 + 120.0 * i, 80.0), 70.0, make_aperture("triangle", 10.0 + (60.0 if i >= 3 else 0.0)))
             for i in range(5)]
    image = render_discs(640, 160, discs, noise_sigma=0.004, seed=11)
    fit = fit_aperture(image, find_discs(image).discs, shapes=["circle", "triangle"])
    assert fit.family.name.startswith("triangle"), fit.message
    assert sorted(item.turned for item in fit.disc_fits) == [False, False, False, True, True]
    return fit


def test_three_discs_the_same_way_round_fix_the_angle(triangles):
    doubts, rejection = judge(triangles, SURE_METRICS)
    assert rejection is None
    assert not [d for d in doubts if DOUBT in d], doubts


def test_fewer_the_same_way_round_make_the_fit_unsure(triangles):
    upright = [item for item in triangles.disc_fits if not item.turned]
    turned = [item for item in triangles.disc_fits if item.turned]
    fit = dataclasses.replace(triangles, disc_fits=upright[: MIN_SURE_DISCS - 1] + turned)
    doubts, _ = judge(fit, SURE_METRICS)
    assert any(d.startswith(f"only {MIN_SURE_DISCS - 1} of the {MIN_SURE_DISCS + 1} {DOUBT}") for d in doubts), doubts
    assert f"only {MIN_SURE_DISCS - 1} discs show it the same way round" in short_doubts(fit, SURE_METRICS)


def test_discs_none_of_them_turned_raise_no_such_doubt(triangles):
    upright = [item for item in triangles.disc_fits if not item.turned]
    doubts, _ = judge(dataclasses.replace(triangles, disc_fits=upright), SURE_METRICS)
    assert not [d for d in doubts if DOUBT in d], doubts
