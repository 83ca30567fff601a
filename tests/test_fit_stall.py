"""A weighted fit (each disc's residuals over its noise level) stops where it no longer learns:
its last STALL_STEPS steps lowered the RSS, a χ², by less than STALL_RSS (bokehfit.fit.pixels)."""

from __future__ import annotations

import pytest

import bokehfit.fit.pixels as pixels
from bokehfit.apertures import make_aperture
from bokehfit.discs import find_discs
from bokehfit.fit.crop import crop_disc
from bokehfit.fit.families import families_for
from bokehfit.fit.pixels import STALL_RSS, STALL_STEPS, _Stall, fit_discs
from bokehfit.synthetic import SyntheticDisc, render_discs


def hexagon_crops(count: int = 3):
    """The fit's crops of ``count`` hexagon discs (12°) in a small noisy photo, as the finder sees them."""
    discs = [SyntheticDisc((60.0 + 100.0 * i, 70.0), 40.0, make_aperture("hexagon", 12.0)) for i in range(count)]
    luminance = render_discs(100 * count + 20, 140, discs, noise_sigma=0.01, seed=11)
    found = [d for d in find_discs(luminance).discs if d.usable]
    assert len(found) == count
    return [crop_disc(luminance, disc, None, found) for disc in found]


def test_the_stall_stops_at_the_first_step_whose_last_steps_together_lowered_the_rss_by_less_than_the_limit():
    stall = _Stall()
    step = 0.5 * STALL_RSS / STALL_STEPS  # each step lowers the RSS (twice scipy's cost) by STALL_RSS / STALL_STEPS
    costs = [100.0, 50.0] + [50.0 - step * (k + 1) for k in range(STALL_STEPS + 1)]
    for cost in costs[:-1]:  # the steps down to 50, then STALL_STEPS steps of exactly the limit: not stalled
        stall(_result(cost))
    with pytest.raises(StopIteration):
        stall(_result(costs[-1] + 1e-9))  # the last STALL_STEPS steps: a hair under the limit
    assert len(stall.costs) == len(costs)


def _result(cost: float):
    from scipy.optimize import OptimizeResult

    return OptimizeResult(x=None, cost=cost)


def test_a_weighted_joint_fit_is_cut_by_the_stall_and_an_unweighted_one_never(monkeypatch):
    crops = hexagon_crops()
    hexagon = families_for(["hexagon"])[0]
    start = make_aperture("hexagon", 35.0)  # 23° off: about ten steps to the discs' angle
    noise = [0.01] * len(crops)
    weighted = fit_discs(crops, hexagon, start, noise=noise)
    plain = fit_discs(crops, hexagon, start)

    monkeypatch.setattr(pixels, "STALL_RSS", 1e12)  # every fit has stalled once it has STALL_STEPS steps
    cut = fit_discs(crops, hexagon, start, noise=noise)
    assert cut.evaluations < weighted.evaluations
    assert fit_discs(crops, hexagon, start).evaluations == plain.evaluations  # no noise, no χ²: never cut
    assert all(f.success for f in cut.fits)  # a stalled fit has stopped, not failed

    monkeypatch.setattr(pixels, "STALL_RSS", 0.0)  # never stalled: the fit runs to scipy's tolerances
    full = fit_discs(crops, hexagon, start, noise=noise)
    # Clean discs converge long before they could stall: the same fit, step for step.
    assert full.evaluations == weighted.evaluations
    assert weighted.aperture.values["angle_deg"] == pytest.approx(12.0, abs=0.3)
    assert weighted.rss == pytest.approx(full.rss, rel=1e-9)


def test_the_discs_beyond_the_joint_fit_are_refitted_weighted_to_the_same_optimum(monkeypatch):
    """The discs kept beyond the joint fit's JOINT_DISCS are refitted one by one with the model's
    aperture fixed, each weighted by its own noise level as in the joint fit, so that the stall (tested
    above) stops a refit that crawls (photo 04's 242-px glow took 181 evaluations, 1.3 s, for nothing).
    A constant weight leaves the optimum where it was: each refit lands where the unweighted one does."""
    import bokehfit.fit.answer as answer
    from bokehfit.fit import fit_aperture
    from bokehfit.fit.stages import JOINT_DISCS

    count = JOINT_DISCS + 2
    discs = [SyntheticDisc((60.0 + 100.0 * i, 70.0), 40.0, make_aperture("hexagon", 12.0)) for i in range(count)]
    luminance = render_discs(100 * count + 20, 140, discs, noise_sigma=0.01, seed=11)
    refits = []

    def recorded(crops, family, start, free=None, noise=None, disc_starts=None, **kwargs):
        fit = fit_discs(crops, family, start, free, noise, disc_starts, **kwargs)
        refits.append((noise, fit, fit_discs(crops, family, start, free, None, disc_starts, **kwargs)))
        return fit

    monkeypatch.setattr(answer, "fit_discs", recorded)
    fitted = fit_aperture(luminance, find_discs(luminance).discs, shapes=["hexagon"])
    assert fitted.aperture.angle_deg == pytest.approx(12.0, abs=0.5)
    assert len(refits) == count - JOINT_DISCS
    for noise, weighted, plain in refits:
        assert noise is not None and 0.0 < noise[0] < 0.05  # the disc's own noise level
        (w,), (p,) = weighted.fits, plain.fits
        assert w.center_xy == pytest.approx(p.center_xy, abs=1e-6)
        assert w.diameter_px == pytest.approx(p.diameter_px, rel=1e-9)
