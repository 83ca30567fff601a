"""A disc whose luminance edge a lens's colour error spreads (``bokehfit.discs.colours``).

The photos are drawn here from geometry: per channel a flat disc of its own radius, sampled 4 × 4 per pixel and
blurred, not with bokehfit's kernels; their luminance is the photo's Y.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from bokehfit.discs import find_discs

SIZE = 160
CENTRE = (80.3, 79.6)
#: Y's weights of linear RGB (Rec. 709), as the loader's luminance.
WEIGHTS = np.array([0.2126, 0.7152, 0.0722], np.float32)


def colour_photo(radii, light, blur, seed: int = 1) -> np.ndarray:
    """Linear RGB: one light's disc in each channel of its own radius and level, on a dark ground, blurred (σ px,
    one for all channels or one each)."""
    blurs = blur if np.ndim(blur) else (blur,) * 3
    sub = 4
    rows, cols = np.indices((SIZE * sub, SIZE * sub), dtype=np.float64)
    distance = np.hypot((cols + 0.5) / sub - 0.5 - CENTRE[0], (rows + 0.5) / sub - 0.5 - CENTRE[1])
    image = np.empty((SIZE, SIZE, 3), np.float32)
    for channel, (radius, level, sigma) in enumerate(zip(radii, light, blurs)):
        inside = (distance <= radius).reshape(SIZE, sub, SIZE, sub).mean(axis=(1, 3))
        image[..., channel] = cv2.GaussianBlur((0.02 + level * inside).astype(np.float32), (0, 0), sigma)
    noise = np.random.default_rng(seed).normal(0.0, 0.002, image.shape).astype(np.float32)
    return np.clip(image + noise, 0.0, 1.0)


def search(rgb: np.ndarray, colours: bool):
    luminance = np.ascontiguousarray(rgb @ WEIGHTS)
    source = (lambda rows, cols: rgb[rows, cols]) if colours else None
    return find_discs(luminance, rgb=source)


def near_centre(found):
    return [d for d in found.discs if math.dist(d.center_xy, CENTRE) < 8.0]


def test_a_disc_whose_colours_come_to_focus_apart_is_kept():
    """Red, green and blue discs of 10, 14 and 19 px radius, each edge sharp: the luminance steps down three times
    over 9 px, and its edge is wider than a sharp disc's. In its colours it is a sharp disc; in luminance alone, a
    soft-edged one at best (second-tier evidence: a glow's edge is as wide)."""
    rgb = colour_photo((10.0, 14.0, 19.0), (1.0, 0.5, 1.0), blur=2.2)
    alone = search(rgb, colours=False)
    assert all(d.soft_edge for d in near_centre(alone) if d.usable)
    assert any(d.soft_edge for d in near_centre(alone)) or any(
        r.rejected_because == "soft edge" and math.dist(r.center_xy, CENTRE) < 8.0 for r in alone.rejections)
    found = [d for d in near_centre(search(rgb, colours=True)) if d.usable]
    assert len(found) == 1 and not found[0].soft_edge
    assert 20.0 < found[0].diameter_px < 38.0  # the luminance's 50 % outline, between the colours' discs


@pytest.mark.parametrize("what", ["a glow", "a soft disc of one size in every colour", "a soft disc sharp in red"])
def test_a_blob_whose_colours_do_not_account_for_its_soft_edge_stays_out(what):
    """Soft in every colour, or sharp in one but its colours' discs of one size: nothing spread its luminance's
    edge but the blur, and it is no sharp disc (MIN_COLOUR_GAP_REL): a glow none, a blurred disc at most a
    soft-edged one (its light ends within its blur; a glow's does not)."""
    if what == "a glow":  # a Gaussian of σ 9 px, a little redder at its heart
        rows, cols = np.indices((SIZE, SIZE), dtype=np.float32)
        heart = np.exp(-((cols - CENTRE[0]) ** 2 + (rows - CENTRE[1]) ** 2) / (2.0 * 9.0**2))
        rgb = 0.02 + np.stack([0.8 * heart, 0.6 * heart, 0.5 * heart], axis=-1)
        rgb = rgb + np.random.default_rng(2).normal(0.0, 0.002, rgb.shape)
    elif what == "a soft disc of one size in every colour":
        rgb = colour_photo((14.0, 14.0, 14.0), (1.0, 0.6, 0.9), blur=6.0)
    else:
        rgb = colour_photo((14.0, 14.0, 14.0), (0.3, 1.0, 1.0), blur=(1.0, 6.0, 6.0))
    for colours in (False, True):
        usable = [d for d in near_centre(search(rgb.astype(np.float32), colours)) if d.usable]
        assert all(d.soft_edge for d in usable) and not (usable and what == "a glow"), (what, colours)


def test_an_rgb_that_is_not_the_photo_s_is_a_clear_error():
    from bokehfit.errors import InputError

    rgb = colour_photo((10.0, 14.0, 19.0), (1.0, 0.5, 1.0), blur=2.2)
    luminance = np.ascontiguousarray(rgb @ WEIGHTS)
    with pytest.raises(InputError, match="rgb must be a function"):
        find_discs(luminance, rgb=rgb)
    with pytest.raises(InputError, match="window's linear RGB"):
        find_discs(luminance, rgb=lambda rows, cols: rgb[rows, cols, :2])  # two channels
