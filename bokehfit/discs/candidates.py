"""Highlight candidates: pixels well above the local background, grouped into blobs.

Notes
-----
The background is a grey-scale morphological opening of the luminance with a
square wider than the largest bokeh disc sought, computed on a reduced copy (a
24-megapixel photo is opened at about 1/8 scale) and smoothed: an opening
removes every bright structure narrower than its element and follows smooth
gradients. The noise level is the median absolute deviation of the residual
(robust as long as discs cover less than half of the frame), times 1.4826.
A pixel is a candidate where the residual exceeds ``SIGMA_THRESHOLD`` noise
levels and ``RELATIVE_THRESHOLD`` of the brightest residual; candidates are
8-connected components. Discs from 4 px up to ``max_diameter_px`` are found at
one threshold because the background model, not the threshold, carries the scale.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["Candidates", "find_candidates", "SIGMA_THRESHOLD", "RELATIVE_THRESHOLD"]

#: Residual above the background, in noise standard deviations, for a candidate pixel.
SIGMA_THRESHOLD = 6.0
#: ... and as a share of the 99.9th percentile residual (ignores faint texture
#: in photos whose highlights are far brighter than their noise).
RELATIVE_THRESHOLD = 0.04
#: Side of the reduced copy on which the background is estimated.
BACKGROUND_SIDE_PX = 640
#: Noise floor: 8-bit quantisation of linear light near black is about this.
MIN_NOISE = 1e-4


@dataclass(frozen=True)
class Candidates:
    """Connected blobs of bright pixels and what they were measured against."""

    labels: np.ndarray  #: int32 (H, W), 0 = background, k = blob k
    stats: np.ndarray  #: cv2 stats rows (left, top, width, height, area), blob k at row k
    background: np.ndarray  #: float32 (H, W) background estimate
    noise_sigma: float
    threshold: float  #: residual a candidate pixel exceeds


def _background(luminance: np.ndarray, max_diameter_px: float) -> np.ndarray:
    height, width = luminance.shape
    factor = max(1.0, max(height, width) / BACKGROUND_SIDE_PX)
    small = cv2.resize(
        luminance, (max(1, round(width / factor)), max(1, round(height / factor))), interpolation=cv2.INTER_AREA
    )
    # A square wider than the largest disc fits inside no disc, so the opening
    # removes every disc; OpenCV opens with a rectangle in separable passes,
    # at a cost independent of its size.
    radius = max(2, int(np.ceil(0.55 * max_diameter_px / factor)))
    element = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * radius + 1, 2 * radius + 1))
    opened = cv2.morphologyEx(small, cv2.MORPH_OPEN, element, borderType=cv2.BORDER_REFLECT)
    opened = cv2.GaussianBlur(opened, (0, 0), radius / 2.0, borderType=cv2.BORDER_REFLECT)
    # The blur lifts the floor next to bright regions; the background never exceeds the image.
    opened = np.minimum(opened, small)
    return cv2.resize(opened, (width, height), interpolation=cv2.INTER_LINEAR)


def find_candidates(luminance: np.ndarray, max_diameter_px: float) -> Candidates:
    """Blobs of pixels well above the local background (see the module notes)."""
    background = _background(luminance, max_diameter_px)
    residual = luminance - background
    sample = residual[:: max(1, residual.shape[0] // 512), :: max(1, residual.shape[1] // 512)]
    median = float(np.median(sample))
    noise_sigma = max(MIN_NOISE, 1.4826 * float(np.median(np.abs(sample - median))))
    top = float(np.percentile(sample, 99.9))
    threshold = max(SIGMA_THRESHOLD * noise_sigma, RELATIVE_THRESHOLD * top)
    mask = (residual > threshold).astype(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8, ltype=cv2.CV_32S)
    return Candidates(labels, stats, background, noise_sigma, threshold)
