"""Longitudinal chromatic aberration from the discs' colours (``bokehfit.fit.chromatic``).

The photos are drawn here from geometry: per channel a flat disc of its own radius,
sampled 4×4 per pixel and blurred, not with bokehfit's kernels. Then a JPEG of it
(4:2:0 chroma, as cameras write), and the two reference photos whose coloured
rims a person described (reference_photos/MANIFEST.md).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from bokehfit.discs import find_discs
from bokehfit.fit import fit_aperture
from bokehfit.fit.chromatic import MIN_CHROMATIC, MIN_SIGNIFICANCE, measure_chromatic, median_and_bar
from bokehfit.io import load_photo
from bokehfit.io.colour import srgb_encode

WIDTH, HEIGHT = 360, 240
CENTRES = [(60.3, 60.7), (180.2, 60.1), (300.6, 61.4), (60.9, 180.5), (180.4, 179.8), (300.1, 180.3)]
#: Linear RGB of the lights (a warm white) and of the background.
LIGHT, BACKGROUND = np.array([0.55, 0.5, 0.42]), np.array([0.02, 0.025, 0.03])
#: |measured − true| allowed on the linear photo; through a 4:2:0 JPEG the chroma, stored at half
#: resolution, follows the luma's edge in part, and the colour differences come out smaller: a share lost.
TOL, JPEG_LOSS = 0.004, 0.35


def disc_photo(red: float, blue: float, diameter: float = 36.0, seed: int = 0) -> np.ndarray:
    """Linear RGB (float32): green discs of ``diameter``, red ones (1 + red) and blue ones (1 + blue) times it."""
    sub = 4
    rows, cols = np.indices((HEIGHT * sub, WIDTH * sub), dtype=np.float64)
    x, y = (cols + 0.5) / sub - 0.5, (rows + 0.5) / sub - 0.5  # pixel centres at integers
    image = np.empty((HEIGHT, WIDTH, 3), np.float32)
    for channel, scale in enumerate((1.0 + red, 1.0, 1.0 + blue)):
        radius = 0.5 * diameter * scale
        inside = np.zeros_like(x, dtype=bool)
        for cx, cy in CENTRES:
            inside |= np.hypot(x - cx, y - cy) <= radius
        fine = inside.reshape(HEIGHT, sub, WIDTH, sub).mean(axis=(1, 3))
        plane = BACKGROUND[channel] + (LIGHT[channel] - BACKGROUND[channel]) * fine
        image[..., channel] = cv2.GaussianBlur(plane.astype(np.float32), (0, 0), 0.8)
    noise = np.random.default_rng(seed).normal(0.0, 0.002, image.shape).astype(np.float32)
    return np.clip(image + noise, 0.0, 1.0)


def luminance(rgb: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(rgb @ np.array([0.2126, 0.7152, 0.0722], np.float32))


def measured(rgb: np.ndarray):
    discs = find_discs(luminance(rgb)).discs
    assert len(discs) == len(CENTRES)
    return measure_chromatic(lambda rows, cols: rgb[rows, cols], discs, rgb.shape[:2])


@pytest.mark.parametrize("red, blue", [(0.04, -0.03), (-0.06, 0.02), (0.015, 0.015)])
def test_channel_sizes_are_measured(red, blue):
    found = measured(disc_photo(red, blue))
    assert found is not None and found.discs == len(CENTRES) and found.significant
    assert found.chromatic.red == pytest.approx(red, abs=TOL)
    assert found.chromatic.blue == pytest.approx(blue, abs=TOL)
    assert found.reason == f"kept: {found.describe()}" and found.to_json()["kept"] is True


def test_a_lens_without_colour_error_gets_no_chromatic_model():
    rgb = disc_photo(0.0, 0.0)
    found = measured(rgb)
    assert found is not None and not found.significant, found.describe()
    assert abs(found.chromatic.red) < MIN_CHROMATIC and abs(found.chromatic.blue) < MIN_CHROMATIC
    fit = fit_aperture(luminance(rgb), find_discs(luminance(rgb)).discs, shapes=["circle"],
                       rgb=lambda rows, cols: rgb[rows, cols])
    assert fit.aperture.chromatic is None and fit.parameters["chromatic"].value is None
    # The report says what the colours measured and why that is no chromatic aberration.
    trial = next(t for t in fit.to_json()["feature_trials"] if t["feature"] == "chromatic")
    assert trial["kept"] is False and trial["discs"] == len(CENTRES), trial
    assert trial["value"]["red"] == pytest.approx(found.chromatic.red, abs=1e-4), trial
    assert trial["reason"].startswith("not kept: red ") and "6 discs can differ by chance" in trial["reason"], trial
    assert "|red| ≥ " in trial["reason"] and "% needed" in trial["reason"], trial


def test_a_grey_photo_is_measured_once_a_disc_with_no_colour_error(monkeypatch):
    """A photo whose channels are the same (a monochrome camera's, a black-and-white print's) shows no
    colour error: each disc's outline is measured in one channel, not three, and the colours come out
    as the three measures would give them, 0 exactly, from as many discs, not significant."""
    import bokehfit.fit.chromatic as chromatic

    grey = np.repeat(luminance(disc_photo(0.0, 0.0))[..., None], 3, axis=2)
    calls = []
    measure = chromatic.outline_diameter
    monkeypatch.setattr(chromatic, "outline_diameter", lambda *a, **k: calls.append(1) or measure(*a, **k))
    found = measured(grey)
    assert len(calls) == len(CENTRES)
    assert found is not None and found.discs == len(CENTRES) and not found.significant
    assert found.chromatic.red == 0.0 and found.chromatic.blue == 0.0
    coloured = disc_photo(0.04, -0.03)
    calls.clear()
    assert measured(coloured).significant and len(calls) == 3 * len(CENTRES)


def test_colours_of_too_few_discs_are_not_measured_and_the_report_says_why():
    rgb = np.ascontiguousarray(disc_photo(0.04, -0.03)[:120, :240])  # two of the discs
    fit = fit_aperture(luminance(rgb), find_discs(luminance(rgb)).discs, shapes=["circle"],
                       rgb=lambda rows, cols: rgb[rows, cols])
    assert fit.chromatic_measure is None and fit.aperture.chromatic is None
    assert ("chromatic", "2 discs kept (4 needed)") in fit.features_not_tried, fit.features_not_tried
    assert {"feature": "chromatic", "reason": "2 discs kept (4 needed)"} in fit.to_json()["features_not_tried"]


def test_a_few_discs_that_agree_by_chance_are_not_significant():
    """Four discs whose red ratios spread by their own scatter: 4.8 standard errors from 0, past a normal 3σ but not
    past Student's t with 3 degrees of freedom (9.2); the same scatter over twelve discs is (t with 11: 3.85). Where
    the discs agree exactly, the error is what their size lets a channel tell, known: 3 errors suffice."""
    four = np.array([[-0.015, 0.0], [-0.025, 0.0], [-0.030, 0.0], [-0.020, 0.0]])
    median, error, bar = median_and_bar(four, [0.001] * 4)
    assert abs(median[0]) / error[0] == pytest.approx(4.84, abs=0.01)
    assert abs(median[0]) > MIN_SIGNIFICANCE * error[0] and abs(median[0]) < bar[0]
    median, error, bar = median_and_bar(np.tile(four, (3, 1)), [0.001] * 12)
    assert abs(median[0]) > bar[0] and bar[0] / error[0] == pytest.approx(3.85, abs=0.01)
    same = np.tile([[0.015, 0.0]], (6, 1))
    median, error, bar = median_and_bar(same, [0.0079] * 6)
    assert bar[0] == pytest.approx(MIN_SIGNIFICANCE * error[0]) and abs(median[0]) > bar[0]


def test_through_a_jpeg_and_the_fit(tmp_path):
    red, blue = 0.05, -0.04
    encoded = np.round(srgb_encode(disc_photo(red, blue)) * 255).astype(np.uint8)
    path = tmp_path / "chromatic.jpg"
    assert cv2.imwrite(str(path), cv2.cvtColor(encoded, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 90])
    photo = load_photo(path)
    fit = fit_aperture(photo.luminance, find_discs(photo.luminance, photo.clipped).discs, shapes=["circle"],
                       clipped=photo.clipped, rgb=photo.linear_rgb)
    assert fit.aperture.chromatic is not None, fit.message
    for true, found in ((red, fit.aperture.chromatic.red), (blue, fit.aperture.chromatic.blue)):
        assert (1.0 - JPEG_LOSS) * abs(true) <= found * np.sign(true) <= abs(true) + TOL, fit.message
    assert "chromatic" in fit.message
    # the near side turns the sign (design.md §3b)
    near = fit_aperture(photo.luminance, find_discs(photo.luminance, photo.clipped).discs, shapes=["circle"],
                        clipped=photo.clipped, rgb=photo.linear_rgb, focus_side="near")
    assert near.aperture.chromatic.red == pytest.approx(-fit.aperture.chromatic.red)


# The two reference photos whose rims a person described: 01 "green/magenta rims" (zoomed crops
# of its discs show green outer rims and magenta centres: the green disc is the largest) and 06
# "cyan/teal rims" (no red at the rim: the red disc is the smallest).
@pytest.mark.parametrize("name, signs", [("01_water-glints_canon6d_ef85.jpg", {"red": -1, "blue": -1}),
                                         ("06_christmas-lights_nikon-d5300.jpg", {"red": -1})])
def test_coloured_rims_of_real_photos(reference_photo, name, signs):
    photo = load_photo(reference_photo(name))
    fit = fit_aperture(photo.luminance, find_discs(photo.luminance, photo.clipped).discs,
                       clipped=photo.clipped, rgb=photo.linear_rgb)
    measure = fit.chromatic_measure
    assert measure is not None and measure.significant, fit.message
    for channel, sign in signs.items():
        value, error = getattr(measure.chromatic, channel), getattr(measure.uncertainty, channel)
        assert value * sign > 3 * error, measure.describe()
