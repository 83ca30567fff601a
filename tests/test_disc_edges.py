"""A disc's edge read through noise: noise adds its power to the slope an edge shows, and the measurement takes it
out (``bokehfit.discs.contours._edge_gradient``), so that a soft edge through noise is not read as a sharp one."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy import ndimage

from bokehfit.discs import verdict
from bokehfit.discs.contours import _crop_gradients, _gradient_noise_power
from bokehfit.discs.measure import measure_candidate


@pytest.mark.parametrize("smoothing_px", [0.0, 0.6, 1.5])
def test_the_gradient_noise_model_is_what_white_noise_gives(smoothing_px):
    """Simulated white noise, smoothed as the rays smooth their crop (or not, as the contour's is), differenced and
    sampled bilinearly at random points: the mean squared gradient is the model's, at points near a pixel's centre
    and halfway between pixels alike (where interpolation averages four samples)."""
    rng = np.random.default_rng(1)
    field = rng.normal(0.0, 0.01, (400, 400)).astype(np.float32)
    if smoothing_px:
        field = cv2.GaussianBlur(field, (0, 0), smoothing_px, borderType=cv2.BORDER_REPLICATE)
    gy, gx = _crop_gradients(field)
    points = rng.uniform(20, 380, (40000, 2))
    coords = [points[:, 1], points[:, 0]]
    power = ndimage.map_coordinates(gx, coords, order=1) ** 2 + ndimage.map_coordinates(gy, coords, order=1) ** 2
    model = _gradient_noise_power(0.01, smoothing_px, points)
    from_half = np.abs(points % 1.0 - 0.5)
    near_centre, halfway = from_half.min(axis=1) >= 0.4, from_half.max(axis=1) <= 0.1
    for where in (near_centre, halfway):
        assert power[where].mean() == pytest.approx(model[where].mean(), rel=0.06)
    if not smoothing_px:  # unsmoothed samples are independent: interpolation between four of them quiets them
        assert model[halfway].mean() < 0.4 * model[near_centre].mean()


def _soft_disc(noise: float, seed: int) -> np.ndarray:
    """A disc of radius 20 px and contrast 0.1 over a ground of 0.05, its edge blurred to 0.8 of its radius (a
    Gaussian of 6.2 px), with white noise."""
    rows, cols = np.mgrid[:200, :200]
    image = np.where(np.hypot(cols - 100, rows - 100) <= 20, 0.1, 0.0).astype(np.float32)
    image = cv2.GaussianBlur(image, (0, 0), 15.6 / np.sqrt(2.0 * np.pi)) + 0.05
    return (image + np.random.default_rng(seed).normal(0.0, noise, image.shape)).astype(np.float32)


def _edge_rel(image: np.ndarray) -> float:
    m = measure_candidate(image, None, (100.0, 100.0), 40.0, 40.0, 1e-6, 8.0)
    return m.edge_width_px / (0.5 * m.diameter_px)


def test_a_soft_edge_through_noise_reads_as_wide_as_without(monkeypatch):
    """At a noise of 1/20 of the contrast the soft disc's edge reads within 10 % of its width without noise (0.81 of
    the radius: soft); with the noise's share left in the slope, over 12 % narrower (three draws each)."""
    clean = _edge_rel(_soft_disc(0.0, 0))
    assert clean == pytest.approx(0.81, abs=0.02)
    noisy = [_edge_rel(_soft_disc(0.005, seed)) for seed in range(3)]
    assert all(abs(w / clean - 1.0) < 0.10 for w in noisy), (clean, noisy)
    monkeypatch.setattr(verdict, "pixel_noise", lambda crop: 0.0)
    biased = [_edge_rel(_soft_disc(0.005, seed)) for seed in range(3)]
    assert all(w < 0.88 * clean for w in biased), (clean, biased)


def test_a_sharp_edge_reads_the_same_with_the_noise_taken_out(monkeypatch):
    """Where the slope is far above the noise (a sharp disc at 1/50 of its contrast), taking the noise's share out
    changes its width by under 2 %."""
    rows, cols = np.mgrid[:160, :160]
    image = np.where(np.hypot(cols - 80, rows - 80) <= 25, 0.3, 0.05).astype(np.float32)
    image = cv2.GaussianBlur(image, (0, 0), 1.0) + np.random.default_rng(4).normal(0.0, 0.006, image.shape)
    image = image.astype(np.float32)
    m = measure_candidate(image, None, (80.0, 80.0), 50.0, 50.0, 1e-6, 8.0)
    monkeypatch.setattr(verdict, "pixel_noise", lambda crop: 0.0)
    left_in = measure_candidate(image, None, (80.0, 80.0), 50.0, 50.0, 1e-6, 8.0)
    assert m.reason is None and left_in.reason is None
    assert m.edge_width_px == pytest.approx(left_in.edge_width_px, rel=0.02)
    assert m.edge_width_px >= left_in.edge_width_px
