"""``compare`` on the real CC0 photos: the expectations in reference_photos/manifest.json."""

from __future__ import annotations

import pytest

from bokehfit.compare import compare_photo


@pytest.mark.parametrize("name", ["01_water-glints_canon6d_ef85.jpg", "02_dew-glints_aaron-burden.jpg"])
def test_round_discs_fit_round(reference_photo, gpu, name):
    comparison = compare_photo(reference_photo(name))
    assert comparison.fit and comparison.acceptable
    # Round: the circle, or blades so rounded that they are nearly one (the bar: roundness ≥ 0.8).
    aperture = comparison.fit.aperture
    assert aperture.aspect is None
    assert aperture.is_circle or aperture.roundness >= 0.8, comparison.fit.message
    if comparison.status == "fitted":
        assert aperture.is_circle, "a sure answer on round discs is the circle"


def test_01_fstop_uses_the_lensfun_sensor_width(reference_photo, gpu):
    comparison = compare_photo(reference_photo("01_water-glints_canon6d_ef85.jpg"))
    assert comparison.geometry.sensor_width_mm == pytest.approx(35.8, abs=0.1)
    assert "lensfun database" in comparison.geometry.sources["sensor_width_mm"]
    assert comparison.fstop.bound == "upper"
    # The lights are not at infinity, so the f-stop found is an upper bound on the real f/1.8.
    assert comparison.fstop.value is not None and comparison.fstop.value > 1.8


def test_05_weak_case_is_not_a_confident_fit(reference_photo, gpu):
    comparison = compare_photo(reference_photo("05_backlit-grass_unsplash-522b53fb137bb.jpg"))
    assert not comparison.acceptable or comparison.doubts
