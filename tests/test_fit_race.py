"""Families out of the race (stage 2): a shape whose outline misfits every model disc far more than the
best shape's is not fitted to pixels, and a pixel fit of it would indeed trail by far.

The screen compares each disc's outline with every family's (:mod:`bokehfit.fit.signature`); a family
more than ``FitOptions.out_of_race_screen`` times worse on every model disc than the best family there is
out of the race (:func:`bokehfit.fit.stages._out_of_race`). The circle always runs, and so does the family with
the best outlines on average where the circle is not among the shapes.
"""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from bokehfit.apertures import make_aperture
from bokehfit.discs import find_discs
from bokehfit.fit import fit_aperture
from bokehfit.fit.crop import crop_disc
from bokehfit.fit.families import FAMILIES, families_for
from bokehfit.fit.pixels import fit_discs
from bokehfit.fit.result import FitOptions
from bokehfit.fit.stages import _out_of_race
from bokehfit.synthetic import SyntheticDisc, render_discs


def photo_of(aperture, count: int = 3, diameter: float = 48.0):
    discs = [SyntheticDisc((60.0 + 100.0 * i, 70.0), diameter, aperture) for i in range(count)]
    return render_discs(100 * count + 20, 140, discs, noise_sigma=0.005, seed=5)


def candidates(fit) -> set[str]:
    return {candidate.family.name for candidate in fit.candidates}


def test_round_discs_fit_the_circle_alone_and_a_twelve_gon_fitted_by_hand_trails_it_far():
    luminance = photo_of(make_aperture("circle"))
    discs = find_discs(luminance).discs
    fit = fit_aperture(luminance, discs)
    assert candidates(fit) == {"circle"}
    assert fit.others_screened  # the others were screened, and their outlines put them out
    # What the rule claims: the 12-gon (the shape nearest the circle) would have lost by far.
    twelve = families_for(["ngon(12)"])[0]
    circle = FAMILIES[0]
    for disc in [d for d in discs if d.usable]:
        crop = crop_disc(luminance, disc, None, discs)
        twelve_bic = fit_discs([crop], twelve, make_aperture("ngon(12)", 7.0)).bic
        assert twelve_bic - fit_discs([crop], circle, circle.aperture).bic > 100.0  # a model choice is made at 10


def test_hexagon_discs_run_the_hexagon_and_the_circle_not_the_twelve_gon():
    luminance = photo_of(make_aperture("hexagon", 12.0))
    fit = fit_aperture(luminance, find_discs(luminance).discs)
    assert candidates(fit) == {"hexagon", "circle"}
    assert fit.family.name == "hexagon"


@pytest.mark.parametrize("shape, kept", [("ngon(12)", "ngon(12)"), ("ngon(9)", "ngon(9)")])
def test_many_blades_near_the_circle_stay_in_the_race(shape, kept):
    """A 12-gon's outline is within a few per cent of the circle's: it is the family that fits best, and runs."""
    luminance = photo_of(make_aperture(shape, 7.0), diameter=64.0)
    fit = fit_aperture(luminance, find_discs(luminance).discs)
    assert kept in candidates(fit) and "circle" in candidates(fit)
    assert fit.family.name == kept


def test_without_the_circle_the_best_family_on_average_always_runs():
    luminance = photo_of(make_aperture("circle"))
    fit = fit_aperture(luminance, find_discs(luminance).discs, shapes=["hexagon"])
    assert "hexagon" in candidates(fit)
    fit = fit_aperture(luminance, find_discs(luminance).discs, shapes=["slit", "square"])
    assert candidates(fit)


def screens(**rms):
    """One disc's screens: family → an object with ``rms``, as stage 2 files them."""
    return {families_for([name])[0]: SimpleNamespace(rms=value) for name, value in rms.items()}


def test_out_of_the_race_only_where_every_model_disc_says_so():
    hexagon = families_for(["hexagon"])[0]
    ratio = FitOptions().out_of_race_screen
    far, near = ratio * 1.01, ratio * 0.99
    assert _out_of_race([hexagon], [screens(circle=0.01, hexagon=0.01 * far)] * 3, ratio)
    assert not _out_of_race([hexagon], [screens(circle=0.01, hexagon=0.01 * far)] * 2
                            + [screens(circle=0.01, hexagon=0.01 * near)], ratio)
    # The circle is never out; an elongated family's outline (a streak's) is no yardstick.
    assert not _out_of_race([FAMILIES[0]], [screens(circle=1.0, hexagon=0.01)] * 3, ratio)
    assert not _out_of_race([hexagon], [screens(circle=0.04, hexagon=0.05, slit=0.001)] * 3, ratio)
    assert not _out_of_race([hexagon], [], ratio)
    # Elongated shapes alone: the best of them is the yardstick.
    slit = families_for(["slit"])[0]
    assert not _out_of_race([slit], [screens(slit=0.01)] * 3, ratio)
    # Every shape runs where the option says so.
    assert not _out_of_race([hexagon], [screens(circle=0.01, hexagon=1.0)] * 3, float("inf"))
