"""The fit's result object, its options and its failure (no GPU needed).

A fit returns one object with named parameters and their uncertainties; the
budget is an explicit ``FitOptions``; a failed fit is falsy, converts to JSON
with its status and reason, and names the reason when a fitted field is read.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import bokehfit.fit as fitting
from bokehfit.apertures import make_aperture
from bokehfit.discs import find_discs
from bokehfit.errors import InputError, NoResultError
from bokehfit.fit import FailedFit, FitFailedError, FitOptions, fit_aperture
from bokehfit.synthetic import SyntheticDisc, render_discs

#: Hexagon discs on a grid, enough for more than the model-selection discs.
GRID_DISCS = 8
ANGLE_DEG = 22.0
DIAMETER_PX = 30.0
SIGMA_NOISE = 0.003
#: The design.md §3b keys every fitted aperture reports (null where not fitted).
LENS_KEYS = ("roundness", "squeeze", "vignetting", "rim", "chromatic")


@pytest.fixture(scope="module")
def hexagons():
    """(luminance, discs) of GRID_DISCS clean hexagons."""
    hexagon = make_aperture("hexagon", ANGLE_DEG)
    discs = [SyntheticDisc((30 + 55 * (i % 4), 30 + 55 * (i // 4)), DIAMETER_PX, hexagon, brightness=0.6)
             for i in range(GRID_DISCS)]
    luminance = render_discs(250, 140, discs, noise_sigma=SIGMA_NOISE, seed=7)
    search = find_discs(luminance, luminance >= 1.0)
    assert sum(d.usable for d in search.discs) == GRID_DISCS
    return luminance, search.discs


def test_failed_fit_is_falsy_and_says_what_failed():
    fit = fit_aperture(np.full((64, 64), 0.02, np.float32), [])
    assert not fit
    assert isinstance(fit, FailedFit)
    for name in ("family", "aperture", "diameter_px", "parameters", "seen_angle_deg"):
        with pytest.raises(FitFailedError, match=f"no aperture was fitted, so it has no {name}: no disc is clean enough"):
            getattr(fit, name)
    assert issubclass(FitFailedError, NoResultError)  # exit code 1 where it escapes to the command line


def test_failed_fit_converts_to_json_with_status_and_reason():
    fit = fit_aperture(np.full((64, 64), 0.02, np.float32), [])
    data = json.loads(json.dumps(fit.to_json()))
    assert data["status"] == "no_discs"
    assert data["reason"].startswith("no disc is clean enough to fit")
    assert data["candidates"] == []


def test_fit_options_set_the_budget(hexagons):
    luminance, discs = hexagons
    assert not hasattr(fitting, "MAX_FIT_DISCS"), "the budget is an option, not a module constant"
    small = fit_aperture(luminance, discs, options=FitOptions(max_discs=3))
    assert len(small.disc_fits) == 3 and small.options.max_discs == 3
    default = fit_aperture(luminance, discs)
    assert len(default.disc_fits) == GRID_DISCS


@pytest.mark.parametrize(
    "kwargs,needle",
    [({"max_discs": 0}, "max_discs"), ({"shortlist": 1.5}, "shortlist"), ({"sure_delta_bic_per_disc": float("nan")},
                                                                              "sure_delta_bic_per_disc")],
    ids=["zero-discs", "fractional-shortlist", "nan-threshold"],
)
def test_fit_options_refuse_bad_values(kwargs, needle):
    with pytest.raises(InputError, match=needle):
        FitOptions(**kwargs)
    with pytest.raises(Exception):
        FitOptions().max_discs = 5  # frozen


def test_winner_candidate_is_the_reported_aperture(hexagons):
    """One angle, one size: the candidate table's winner is the consensus over every fitted disc."""
    luminance, discs = hexagons
    fit = fit_aperture(luminance, discs)
    assert len(fit.disc_fits) > FitOptions().model_discs
    winner = fit.candidates[0]
    assert winner.family.name == "hexagon"
    assert winner.angle_deg == fit.seen_angle_deg
    assert winner.diameter_px == fit.diameter_px
    data = fit.to_json()
    assert data["candidates"][0]["angle_deg"] == data["angle_deg"]
    assert data["candidates"][0]["diameter_px"] == data["diameter_px"]


def test_parameters_carry_uncertainties_and_lens_keys(hexagons):
    luminance, discs = hexagons
    fit = fit_aperture(luminance, discs)
    parameters = fit.parameters
    assert parameters["angle_deg"].value == pytest.approx(ANGLE_DEG, abs=0.5)
    assert parameters["angle_deg"].uncertainty > 0
    assert parameters["diameter_px"].value == pytest.approx(DIAMETER_PX, rel=0.02)
    assert parameters["diameter_px"].uncertainty > 0
    data = fit.to_json()
    assert data["angle_uncertainty_deg"] == round(parameters["angle_deg"].uncertainty, 3)
    # The hexagons' blades are tried rounded: a straight answer reports roundness 0 (estimated);
    # the features not estimated (no ring, discs near the centre) are null.
    assert data["roundness"] is not None and data["roundness"] < 0.05
    for key in LENS_KEYS[1:]:
        assert data[key] is None and data[f"{key}_uncertainty"] is None
