"""Discs whose light the model does not describe: rings (a bright rim) where the model has no rim
make the fit unsure (bokehfit.judging.profiles_unexplained). Light spread evenly over an aperture
makes no ring; a lens's rim is every disc's, so a ring the model lacks is a disagreement."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from bokehfit.apertures import make_aperture
from bokehfit.apertures.features import MIN_RIM
from bokehfit.discs import find_discs
from bokehfit.fit import fit_aperture
from bokehfit.judging import judge, profiles_unexplained, short_doubts

SURE_METRICS = {"iou": 0.95}


def soap_bubbles(count: int = 4, diameter: float = 90.0, seed: int = 4) -> np.ndarray:
    """Soap-bubble discs drawn by geometry (not by the fit's rim profile): a centre of 0.15 over the
    ground rising to a rim of 0.65 at the edge, blurred by 1 px, with noise."""
    width, height = 130 * count + 40, 170
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    image = np.full((height, width), 0.03, np.float32)
    radius = 0.5 * diameter
    for i in range(count):
        r = np.hypot(xx - (70.0 + 130.0 * i), yy - 85.0)
        inside = np.clip(radius - r + 0.5, 0.0, 1.0)
        image += inside * (0.15 + 0.5 * np.clip((r - 0.5 * radius) / (0.45 * radius), 0.0, 1.0))
    image = cv2.GaussianBlur(image, (0, 0), 1.0)
    return (image + np.random.default_rng(seed).normal(0.0, 0.004, image.shape)).astype(np.float32)


@pytest.fixture(scope="module")
def bubbles():
    image = soap_bubbles()
    discs = find_discs(image).discs
    assert [d.ring for d in discs] == [True] * 4
    return fit_aperture(image, discs, shapes=["circle"])


def test_rings_that_the_models_rim_describes_leave_the_fit_sure(bubbles):
    assert "rim" in bubbles.aperture.enabled_features and bubbles.aperture.rim > 0.5
    assert profiles_unexplained(bubbles) == 0
    doubts, _ = judge(bubbles, SURE_METRICS)
    assert not [d for d in doubts if "profile" in d]


def test_rings_the_model_has_no_rim_for_make_the_fit_unsure(bubbles):
    for plain in (make_aperture("circle", 0.0), make_aperture("circle", 0.0, rim=0.5 * MIN_RIM)):  # none that shows
        fit = dataclasses.replace(bubbles, aperture=plain)
        assert profiles_unexplained(fit) == 4
        doubts, rejection = judge(fit, SURE_METRICS)
        assert rejection is None
        assert any(d.startswith("4 of the 4 discs fitted show a profile the model does not have") for d in doubts), doubts
        assert "some discs show a rim the model does not have" in short_doubts(fit, SURE_METRICS)


def test_a_bright_centre_lens_explains_rings_as_its_discs_beyond_the_focus(bubbles):
    """A lens's rim turns its sign on the near side of the focus: rings and bright centres are one lens's."""
    assert profiles_unexplained(dataclasses.replace(bubbles, aperture=make_aperture("circle", 0.0, rim=-0.5))) == 0


def test_flat_discs_raise_no_such_doubt():
    from bokehfit.synthetic import SyntheticDisc, render_discs

    discs = [SyntheticDisc((70.0 + 130.0 * i, 85.0), 90.0, make_aperture("circle", 0.0)) for i in range(4)]
    image = render_discs(560, 170, discs, noise_sigma=0.004, seed=4)
    fit = fit_aperture(image, find_discs(image).discs, shapes=["circle"])
    assert profiles_unexplained(fit) == 0
    assert profiles_unexplained(dataclasses.replace(fit, aperture=make_aperture("circle", 0.0, rim=0.5))) == 0


def test_a_person_s_discs_of_dew_with_rings_the_joint_fit_does_not_show_are_unsure(reference_photo):
    """Photo 02 with the person's discs: 2 of the 12 discs fitted are rings, the 8 fitted jointly show no
    rim (the person reads "many discs have a brighter rim"). It was a sure circle without a rim."""
    from photo_factory import reference_labels

    from bokehfit.compare import compare_photo

    name = "02_dew-glints_aaron-burden.jpg"
    labels_path, _ = reference_labels(name)
    comparison = compare_photo(reference_photo(name), discs=labels_path)
    assert profiles_unexplained(comparison.fit) >= 1
    assert comparison.status == "unsure"
    assert any("the discs disagree about the lens" in d for d in comparison.doubts)
