"""``compare`` on the real CC0 photos: the expectations in reference_photos/manifest.json."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bokehfit.fit import ROUND_ENOUGH

MANIFEST = json.loads((Path(__file__).resolve().parents[1] / "reference_photos" / "manifest.json").read_text(encoding="utf-8"))
LABELS = {entry["file"]: entry["label"] for entry in MANIFEST["photos"]}


@pytest.mark.parametrize("name", ["01_water-glints_canon6d_ef85.jpg", "02_dew-glints_aaron-burden.jpg"])
def test_round_discs_fit_round(compared, name):
    comparison = compared(name)
    assert comparison.fit and comparison.acceptable
    # Round: the circle, or blades so rounded that they are nearly one (the bar: roundness ≥ ROUND_ENOUGH, 0.8).
    aperture = comparison.fit.aperture
    assert aperture.aspect is None
    assert aperture.is_circle or aperture.roundness >= ROUND_ENOUGH, comparison.fit.message
    if comparison.status == "fitted":
        assert aperture.is_circle, "a sure answer on round discs is the circle"


def test_01_fstop_uses_the_lensfun_sensor_width(compared):
    comparison = compared("01_water-glints_canon6d_ef85.jpg")
    assert comparison.geometry.sensor_width_mm == pytest.approx(35.8, abs=0.1)
    assert "lensfun database" in comparison.geometry.sources["sensor_width_mm"]
    assert comparison.fstop.bound == "upper"
    # The lights are not at infinity, so the f-stop found is an upper bound on the real f/1.8.
    assert comparison.fstop.value is not None and comparison.fstop.value > 1.8


def test_05_weak_case_is_not_a_confident_fit(compared):
    comparison = compared("05_backlit-grass_unsplash-522b53fb137bb.jpg")
    assert not comparison.acceptable or comparison.doubts


@pytest.mark.parametrize("name", sorted(LABELS))
def test_a_fitted_answer_is_never_wrong(compared, name):
    """Every labelled photo (a person's reading of zoomed crops): a sure answer shares the label
    (round, the rim's sign where the discs show one, a strong cat-eye); anything else is unsure, no_fit or no_discs
    with a reason. Edge discs' lemon shapes are vignetting, never an elongated aperture."""
    label = LABELS[name]
    comparison = compared(name)
    aperture = comparison.fit.aperture if comparison.fit else None
    if aperture is not None and label.get("vignetting"):
        assert aperture.aspect is None, f"cat-eyed edge discs read as an elongated aperture: {comparison.fit.message}"
    if comparison.status != "fitted":
        assert comparison.reason, f"{comparison.status} without a reason"
        return
    assert aperture.aspect is None, comparison.fit.message
    if label["round"]:
        assert aperture.is_circle or aperture.roundness >= ROUND_ENOUGH, comparison.fit.message
    if label.get("rim") == "positive":
        assert aperture.rim > 0, f"a sure answer without the bright rim the discs show: {comparison.fit.message}"
    if label.get("vignetting") == "strong":
        assert aperture.vignetting is not None, f"a sure answer without the cat-eye the edge discs show: {comparison.fit.message}"
