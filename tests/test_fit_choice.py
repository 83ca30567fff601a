"""Which discs the fit takes (:func:`bokehfit.fit.choice.choose_discs`) when its clearest blobs are not discs.

The choice screens the CHOICE_POOL · budget clearest usable discs; where none of those is an aperture's image (a
window of in-focus raindrops, a carpet of glints outshining the photo's discs), it goes on through the rest, so that
a disc behind them is fitted and a reason for no fit speaks for every disc found.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from bokehfit.discs import find_discs
from bokehfit.fit.choice import CHOICE_POOL, choose_discs, no_disc_reason
from bokehfit.fit.families import FAMILIES

BUDGET = 2
SHAPE = (200, 200)


def _round_disc():
    """One sharp round disc found by the search on a drawn photo (an outline an aperture explains)."""
    image = np.full(SHAPE, 0.03, np.float32)
    cv2.circle(image, (100, 100), 30, 0.6, -1, lineType=cv2.LINE_AA)
    image = cv2.GaussianBlur(image, (0, 0), 0.8) + np.random.default_rng(0).normal(0, 0.003, SHAPE).astype(np.float32)
    (disc,) = [d for d in find_discs(image, min_diameter_px=8).discs if d.usable]
    return disc


def _blots(disc, count: int):
    """``count`` copies of ``disc``, clearer than it (larger, at other places), whose outlines are six-lobed blots
    that no aperture shape explains."""
    angles = np.linspace(0.0, 2.0 * np.pi, len(disc.outline_xy), endpoint=False)
    radius = 0.5 * disc.diameter_px * (1.0 + 0.35 * np.cos(6 * angles))
    blots = []
    for i in range(count):
        centre = np.array([40.0 + 5.0 * i, 40.0])
        outline = centre + np.column_stack([radius * np.cos(angles), radius * np.sin(angles)])
        blots.append(replace(disc, index=100 + i, center_xy=tuple(centre), diameter_px=1.5 * disc.diameter_px,
                             outline_xy=outline))
    return blots


def test_a_disc_behind_a_pool_of_blots_is_fitted():
    disc = _round_disc()
    blots = _blots(disc, CHOICE_POOL * BUDGET + 3)
    fitted, set_aside = choose_discs(blots + [disc], FAMILIES, BUDGET, {}, SHAPE)
    assert [d.index for d in fitted] == [disc.index]
    assert set(set_aside) == {b.index for b in blots}


def test_the_rest_waits_where_the_pool_gives_a_disc():
    disc = _round_disc()
    blots = _blots(disc, CHOICE_POOL * BUDGET + 3)
    first = replace(disc, diameter_px=1.6 * disc.diameter_px)  # the clearest of all
    second = replace(disc, index=disc.index + 1, diameter_px=0.9 * disc.diameter_px)  # after the blots
    fitted, set_aside = choose_discs([first, *blots, second], FAMILIES, BUDGET, {}, SHAPE)
    assert [d.index for d in fitted] == [disc.index]  # the pool's disc; the blots and the disc after the pool wait
    assert set(set_aside) == {b.index for b in blots[: CHOICE_POOL * BUDGET - 1]}


def test_no_disc_reason_counts_every_blot():
    disc = _round_disc()
    blots = _blots(disc, CHOICE_POOL * BUDGET + 3)
    fitted, set_aside = choose_discs(blots, FAMILIES, BUDGET, {}, SHAPE)
    assert not fitted
    assert f"{len(blots)} with an outline no aperture shape explains" in no_disc_reason(blots, set_aside)
