"""Highlight candidates at several scales: blobs well above their local background.

Notes
-----
Disc diameters are split into octave bands [s, 2s) with s = 4, 8, 16, … px.
Band s is searched on a copy reduced by ``f = max(1, s / BAND_SIDE_PX)``
(area averaging), so its discs are 6 to 12 px across there whatever their size,
and every band costs about the same. On that copy:

- the background is a grey-scale morphological opening with a square wider
  than the band's largest disc (a square that fits inside no disc of the band
  removes them all, and follows smooth gradients and broader light);
- the noise level σ is 1.4826 × the median absolute deviation of the residual
  (image − background): sensor noise and the texture at that scale;
- blobs are 8-connected pixels above ``SIGMA_THRESHOLD`` σ, each cut at half
  its peak (the half-peak region has the disc's size, where the low threshold
  also takes in blur and glow, and glow-joined discs come apart); regions whose
  equal-area diameter (in full-resolution pixels) lies in the band, whose peak
  exceeds ``PEAK_SIGMA`` σ and the contrast floors become candidates.

Each candidate is measured at full resolution by :mod:`bokehfit.discs.measure`;
one disc seen in two bands is kept once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["Candidate", "find_candidates", "SIGMA_THRESHOLD", "PEAK_SIGMA", "MIN_CONTRAST_ABS", "MIN_CONTRAST_REL"]

#: Blob pixels: residual above this many noise levels.
SIGMA_THRESHOLD = 4.0
#: Candidates: peak residual above this many noise levels.
PEAK_SIGMA = 5.0
#: Contrast floors, whatever the noise (linear units, and relative to the
#: background): flat JPEG areas have almost no noise, yet their block
#: artefacts are a few codes high.
MIN_CONTRAST_ABS = 0.003
MIN_CONTRAST_REL = 0.15
#: Smallest disc of a band, in pixels of the reduced copy it is searched on.
BAND_SIDE_PX = 6.0
#: Bands overlap by these factors, so that a disc at a band's edge, measured a
#: little differently on the two reduced copies, is a candidate in at least one.
BAND_OVERLAP_LOW = 0.8
BAND_OVERLAP_HIGH = 1.25
#: Noise floor (linear units).
MIN_NOISE = 1e-4


@dataclass(frozen=True)
class Candidate:
    """A bright blob: where, about how big, how strong."""

    center_xy: tuple[float, float]  #: full-resolution (column, row)
    diameter_px: float  #: equal-area diameter of the half-peak region
    extent_px: float  #: half the longer side of its bounding box
    strength: float  #: peak residual in noise levels of its band


def _label_maxima(values: np.ndarray, labels: np.ndarray, count: int) -> np.ndarray:
    """Largest value under each label 1 … count − 1 (label 0, the background, gets −∞)."""
    maxima = np.full(count, -np.inf, dtype=np.float32)
    inside = labels > 0  # blobs cover a small part of the image: visit only their pixels
    np.maximum.at(maxima, labels[inside], values[inside])
    return maxima


def _band_candidates(luminance: np.ndarray, band: float, min_diameter: float) -> list[Candidate]:
    height, width = luminance.shape
    factor = max(1.0, band / BAND_SIDE_PX)
    if factor > 1.0:
        size = (max(1, round(width / factor)), max(1, round(height / factor)))
        image = cv2.resize(luminance, size, interpolation=cv2.INTER_AREA)
    else:
        image = luminance
    side = 2 * math.ceil(2.0 * band / factor) + 3
    element = cv2.getStructuringElement(cv2.MORPH_RECT, (side, side))
    background = cv2.morphologyEx(image, cv2.MORPH_OPEN, element, borderType=cv2.BORDER_REFLECT)
    residual = image - background
    step = max(1, round(math.sqrt(residual.size / 250_000)))
    sample = residual[::step, ::step]
    median = float(np.median(sample))
    sigma = max(MIN_NOISE, 1.4826 * float(np.median(np.abs(sample - median))))
    count, labels = cv2.connectedComponents((residual > SIGMA_THRESHOLD * sigma).view(np.uint8), connectivity=8)
    if count <= 1:
        return []
    peaks = _label_maxima(residual, labels, count)
    peaks[0] = np.inf  # background pixels never pass
    count, labels, stats, centroids = cv2.connectedComponentsWithStats(
        (residual >= 0.5 * peaks[labels]).view(np.uint8), connectivity=8, ltype=cv2.CV_32S
    )
    diameters = 2.0 * np.sqrt(stats[:, cv2.CC_STAT_AREA] / math.pi) * factor
    low = min_diameter if band <= min_diameter * 1.01 else BAND_OVERLAP_LOW * band
    peaks = _label_maxima(residual, labels, count)
    floor = np.maximum(MIN_CONTRAST_ABS, MIN_CONTRAST_REL * _label_maxima(background, labels, count))
    keep = (diameters >= low) & (diameters < BAND_OVERLAP_HIGH * 2.0 * band)
    keep &= (peaks >= PEAK_SIGMA * sigma) & (peaks >= floor)
    keep[0] = False
    return [
        Candidate(
            ((centroids[k, 0] + 0.5) * factor - 0.5, (centroids[k, 1] + 0.5) * factor - 0.5),
            float(diameters[k]),
            0.5 * max(stats[k, cv2.CC_STAT_WIDTH], stats[k, cv2.CC_STAT_HEIGHT]) * factor,
            float(peaks[k] / sigma),
        )
        for k in np.nonzero(keep)[0]
    ]


def find_candidates(luminance: np.ndarray, min_diameter_px: float, max_diameter_px: float) -> list[Candidate]:
    """Candidates of every octave band from ``min_diameter_px`` to ``max_diameter_px``."""
    candidates: list[Candidate] = []
    band = min_diameter_px
    while band < max_diameter_px:
        candidates.extend(_band_candidates(luminance, band, min_diameter_px))
        band *= 2.0
    return candidates
