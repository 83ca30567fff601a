"""A lens's §3b feature is every disc's: it joins the model only where it still gains
FEATURE_DELTA_BIC with any one disc left out (bokehfit.fit.features.gain_without_one_disc).
One ring among flat discs is that disc's own light (a drop's, a neighbour's), not the lens's rim."""

from __future__ import annotations

import math
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from bokehfit.discs import find_discs
from bokehfit.fit import fit_aperture
from bokehfit.fit.features import FEATURE_DELTA_BIC, RIM_SIGNAL, FeatureTrial, gain_without_one_disc


def _joint(rss: list[float], parameters: int, pixels: int = 1000):
    """What gain_without_one_disc reads of a joint fit: each disc's RSS and pixels, the parameters."""
    return SimpleNamespace(fits=[SimpleNamespace(rss=r, pixels=pixels) for r in rss], parameters=parameters)


def test_a_gain_every_disc_shares_survives_leaving_one_out():
    before, after = _joint([1000.0] * 4, 20), _joint([960.0] * 4, 21)
    whole = 4000 * math.log(4000 / 3840) - math.log(4000)
    least = gain_without_one_disc(before, after, [1.0] * 4)
    assert least == pytest.approx(3000 * math.log(3000 / 2880) - math.log(3000))
    assert FEATURE_DELTA_BIC <= least < whole


def test_a_gain_one_disc_carries_does_not():
    before, after = _joint([1000.0] * 4, 20), _joint([700.0, 1000.0, 1000.0, 1000.0], 21)
    assert gain_without_one_disc(before, after, [1.0] * 4) < 0.0  # the others gain nothing, and pay the parameter


def test_the_noise_levels_weigh_the_discs_as_the_joint_fit_does():
    """Each disc's RSS counts over its noise level squared, as in the joint fit's weighted RSS: a disc whose
    pixels are twice as noisy, with four times the RSS before and after, is the same evidence."""
    rss_before, rss_after = [1000.0, 900.0, 1100.0], [950.0, 860.0, 1040.0]
    plain = gain_without_one_disc(_joint(rss_before, 20), _joint(rss_after, 21), [1.0, 1.0, 1.0])
    scaled = gain_without_one_disc(_joint([4 * rss_before[0], *rss_before[1:]], 20),
                                   _joint([4 * rss_after[0], *rss_after[1:]], 21), [2.0, 1.0, 1.0])
    unweighted = gain_without_one_disc(_joint([4 * rss_before[0], *rss_before[1:]], 20),
                                       _joint([4 * rss_after[0], *rss_after[1:]], 21), [1.0, 1.0, 1.0])
    assert scaled == pytest.approx(plain) and unweighted != pytest.approx(plain)


def test_one_disc_carries_no_feature():
    assert gain_without_one_disc(_joint([10.0], 5), _joint([1.0], 6), [1.0]) == -math.inf


def _discs(rings: list[bool], diameter: float = 120.0, seed: int = 4) -> np.ndarray:
    """Discs drawn by geometry, their centres 130 px apart in a row: a ring's centre 0.15 over the ground
    rising to a rim of 0.65 at the edge, a flat disc 0.4 all over; blurred by 1 px, with noise."""
    width, height = 130 * len(rings) + 40, 170
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    image = np.full((height, width), 0.03, np.float32)
    radius = 0.5 * diameter
    for i, ring in enumerate(rings):
        r = np.hypot(xx - (70.0 + 130.0 * i), yy - 85.0)
        inside = np.clip(radius - r + 0.5, 0.0, 1.0)
        light = 0.15 + 0.5 * np.clip((r - 0.5 * radius) / (0.45 * radius), 0.0, 1.0) if ring else 0.4
        image += inside * light
    image = cv2.GaussianBlur(image, (0, 0), 1.0)
    return (image + np.random.default_rng(seed).normal(0.0, 0.004, image.shape)).astype(np.float32)


def test_one_ring_among_flat_discs_is_no_rim_of_the_lens():
    """Discs of 120 px, 10 px apart: fitted jointly, the ring alone gains a rim of +0.08 on every disc a ΔBIC
    of 61, which one disc carries."""
    image = _discs([True, False, False, False])
    discs = find_discs(image).discs
    assert sorted(d.ring for d in discs) == [False] * 3 + [True]
    fit = fit_aperture(image, discs, shapes=["circle"])
    assert "rim" not in fit.aperture.enabled_features, fit.message
    # The report names the disc that carries the gain, which the JSON and the summary give.
    trial = next(t for t in fit.feature_trials if t.feature == "rim")
    ring = next(d for d in discs if d.ring)
    assert trial.asked == f"disc {ring.index} is a ring or has a bright centre", trial
    assert trial.gain >= FEATURE_DELTA_BIC and not trial.kept and trial.carried_by == ring.index, trial
    assert trial.reason.endswith(f"without disc {ring.index}: one disc's, not the lens's"), trial.reason
    assert trial.to_json() in fit.to_json()["feature_trials"]


def test_rings_in_every_disc_are_the_lens_s_rim():
    image = _discs([True] * 4, diameter=90.0)
    fit = fit_aperture(image, find_discs(image).discs, shapes=["circle"])
    assert "rim" in fit.aperture.enabled_features and fit.aperture.rim > 0.5, fit.message
    trial = next(t for t in fit.feature_trials if t.feature == "rim")
    assert trial.kept and trial.reason.startswith("kept: ΔBIC ") and trial.least_gain >= FEATURE_DELTA_BIC, trial


def _trial(**values) -> FeatureTrial:
    return FeatureTrial(**{"feature": "rim", "gain": 50.0, "least_gain": 40.0, "shows": True, "at_bound": False,
                           "value": 0.3, "carried_by": 2, **values})


@pytest.mark.parametrize("values, kept, says", [
    ({}, True, "kept: ΔBIC 50, at least 40 with any one disc left out"),
    ({"gain": 4.0}, False, f"not kept: ΔBIC 4 ({FEATURE_DELTA_BIC:.0f} needed)"),
    ({"shows": False, "value": 0.01}, False, "not kept: ΔBIC 50, but its value (+0.01) is too small for discs to show"),
    ({"at_bound": True, "value": {"radius": 1.0, "shift": -2.0}}, False,
     "not kept: ΔBIC 50, but its value (radius +1.00, shift -2.00) is at the end of its range"),
    ({"least_gain": -30.0, "carried_by": 7}, False, "not kept: ΔBIC 50, but -30 without disc 7: one disc's, not the lens's"),
    ({"least_gain": -math.inf, "carried_by": None}, False, "not kept: ΔBIC 50, but from a single disc: one disc's"),
])
def test_a_trial_says_why_the_feature_joined_the_model_or_did_not(values, kept, says):
    """The reason is the first of the tests that keep a feature (the order of FeatureTrial.kept) that the trial fails."""
    trial = _trial(**values)
    assert trial.kept is kept and trial.reason.startswith(says), trial.reason
    assert trial.to_json()["kept"] is kept and trial.to_json()["reason"] == trial.reason


def test_flat_discs_ask_for_no_rim_and_the_report_says_why():
    """Four flat discs: the rim is not tried, and the fit says what the discs' profiles showed instead; every §3b
    feature the joint fit may try is either tried or named with the reason it was not."""
    fit = fit_aperture(_discs([False] * 4), find_discs(_discs([False] * 4)).discs, shapes=["circle"])
    skipped = dict(fit.features_not_tried)
    assert skipped["rim"].startswith("no disc is a ring or has a bright centre, and the flat model leaves the rims ")
    assert skipped["rim"].endswith(f"(median of 4 discs; ±{100 * RIM_SIGNAL:g} % asks for a rim)"), skipped["rim"]
    assert {t.feature for t in fit.feature_trials} | set(skipped) == {"rim", "vignetting", "squeeze"}, fit.message
    assert all(skipped.values())
    listed = fit.to_json()["features_not_tried"]
    assert {"feature": "rim", "reason": skipped["rim"]} in listed


def _stretched(level: float, seed: int = 5) -> np.ndarray:
    """Four discs drawn by geometry, 40 px wide and 50 px tall (a squeeze of 1.25), ``level`` over a ground of 0.3,
    their centres 80 px apart in a row; blurred by 1 px, with noise."""
    width, height = 360, 120
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    image = np.full((height, width), 0.3, np.float32)
    for i in range(4):
        r = np.hypot((xx - (60.0 + 80.0 * i)) / 20.0, (yy - 60.0) / 25.0)
        image += level * np.clip((1.0 - r) * 22.0 + 0.5, 0.0, 1.0)
    image = cv2.GaussianBlur(image, (0, 0), 1.0)
    return (image + np.random.default_rng(seed).normal(0.0, 0.003, image.shape)).astype(np.float32)


@pytest.mark.parametrize("level, asked", [(0.3, True), (0.1, False)])
def test_small_faint_discs_ask_for_no_feature_of_their_outlines_shape(level, asked):
    """Discs stretched alike along the frame's axes ask for a squeeze where their outlines can show it; small (45 px)
    and faint (a third above their ground) they ask for none, and the report says why: their outlines follow the
    grain as much as the lens (bokehfit.fit.features.small_and_faint, the judge's small and faint discs)."""
    image = _stretched(level)
    discs = find_discs(image).discs
    assert len(discs) == 4 and all(43 <= d.diameter_px <= 47 for d in discs), [d.diameter_px for d in discs]
    fit = fit_aperture(image, discs, shapes=["circle"])
    skipped = dict(fit.features_not_tried)
    tried = {t.feature for t in fit.feature_trials}
    if asked:
        assert "squeeze" in tried, skipped
    else:
        assert "squeeze" not in tried and skipped["squeeze"].startswith("the discs are small and faint (median 45 px, "), skipped


def test_a_feature_not_kept_is_tried_again_once_another_joins(monkeypatch):
    """Reference photo 09's rim gained a ΔBIC of 6 on the plain circle and 151 once the cat-eye that cuts its
    discs was in the model: a feature not kept is tried once more after another joins, and says so."""
    from bokehfit.fit import stages

    def gain(feature, before):  # the BIC each feature gains over ``before``'s model (its features)
        return {"rim": 151.0 if "vignetting" in before else 6.0, "vignetting": 883.0}[feature]

    def trial_of(feature, before, after, noise, discs, asked="", again=None, again_with=()):
        return FeatureTrial(feature, gain(feature, before.aperture), 100.0, True, False, 0.4, None, asked,
                            tuple(again_with), None if again is None else again.gain)

    monkeypatch.setattr(stages, "feature_asks", lambda *a: {"rim": (True, "a ring"), "vignetting": (True, "cut"),
                                                           "squeeze": (False, "round")})
    monkeypatch.setattr(stages, "add_feature", lambda aperture, feature, fits, discs: aperture | {feature})
    monkeypatch.setattr(stages, "fit_discs", lambda crops, winner, start, **_: SimpleNamespace(aperture=start, fits=[]))
    monkeypatch.setattr(stages.FeatureTrial, "of", staticmethod(trial_of))
    joint = stages.Joint([], [], [], [], SimpleNamespace(aperture=frozenset(), fits=[]))
    tried = stages.try_features(joint, SimpleNamespace(fits=[], screens=[]), winner=None)
    assert [t.feature for t in tried.trials] == ["vignetting", "rim"] and all(t.kept for t in tried.trials)
    assert tried.fit.aperture == {"rim", "vignetting"} and tried.not_tried == (("squeeze", "round"),)
    rim = tried.trials[1]
    assert rim.again_with == ("vignetting",) and rim.first_gain == 6.0, rim
    assert rim.reason == "tried again with vignetting in the model (ΔBIC 6 before), kept: ΔBIC 151, at least 100 " \
                         "with any one disc left out", rim.reason
    assert rim.to_json()["tried_again_with"] == ["vignetting"] and rim.to_json()["first_delta_bic"] == 6.0


def test_a_feature_is_tried_again_only_once(monkeypatch):
    """A feature that fails again is not retried when more join after its first trial: each is fitted at most twice."""
    from bokehfit.fit import stages

    fitted = []

    def trial_of(feature, before, after, noise, discs, asked="", again=None, again_with=()):
        return FeatureTrial(feature, 4.0 if feature == "rim" else 50.0, 40.0, True, False, 0.4, None, asked,
                            tuple(again_with), None if again is None else again.gain)

    def fit_discs(crops, winner, start, **_):
        fitted.append(start)
        return SimpleNamespace(aperture=start, fits=[])

    monkeypatch.setattr(stages, "feature_asks", lambda *a: {"rim": (True, ""), "vignetting": (True, ""),
                                                           "squeeze": (True, "")})
    monkeypatch.setattr(stages, "add_feature", lambda aperture, feature, fits, discs: aperture | {feature})
    monkeypatch.setattr(stages, "fit_discs", fit_discs)
    monkeypatch.setattr(stages.FeatureTrial, "of", staticmethod(trial_of))
    joint = stages.Joint([], [], [], [], SimpleNamespace(aperture=frozenset(), fits=[]))
    tried = stages.try_features(joint, SimpleNamespace(fits=[], screens=[]), winner=None)
    assert sum("rim" in start for start in fitted) == 2, fitted
    assert [(t.feature, t.kept) for t in tried.trials] == [("vignetting", True), ("squeeze", True), ("rim", False)]
    assert tried.trials[-1].again_with == ("vignetting", "squeeze")  # both in the model when it was tried again
