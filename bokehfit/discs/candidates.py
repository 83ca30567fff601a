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
  exceeds ``PEAK_SIGMA`` σ and the contrast floors become candidates (the
  relative floor is lower from ``LARGE_DISC_PX`` on, see ``MIN_CONTRAST_REL_LARGE``);
- a blob above the low threshold more than ``CLUSTER_AREA_RATIO`` times the
  largest half-peak region in it may be a cluster of overlapping discs (the
  half-peak cut keeps the brightest of them, where their light adds up, and
  loses the others): it is also a candidate, marked ``cluster``, measured as a
  whole and split into its discs (or dropped where it does not split).

Each candidate is measured at full resolution by :mod:`bokehfit.discs.measure`;
one disc seen in two bands is kept once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

__all__ = [
    "Candidate",
    "find_candidates",
    "contrast_floor_rel",
    "SIGMA_THRESHOLD",
    "PEAK_SIGMA",
    "MIN_CONTRAST_ABS",
    "MIN_CONTRAST_REL",
    "MIN_CONTRAST_REL_LARGE",
    "LARGE_DISC_PX",
]

#: Blob pixels: residual above this many noise levels.
SIGMA_THRESHOLD = 4.0
#: Candidates: peak residual above this many noise levels.
PEAK_SIGMA = 5.0
#: Contrast floors, whatever the noise (linear units, and relative to the
#: background): flat JPEG areas have almost no noise, yet their block
#: artefacts are a few codes high.
MIN_CONTRAST_ABS = 0.003
MIN_CONTRAST_REL = 0.15
#: Discs from this size (px) on need only MIN_CONTRAST_REL_LARGE of the background: their
#: band is searched on a copy reduced 20 times or more, where JPEG blocks (8 px) and grain
#: average out, and their outline is measured over hundreds of pixels. Large faint discs
#: over bright haze (5–20 % contrast at 150–500 px) are common in real photos.
LARGE_DISC_PX = 120.0
MIN_CONTRAST_REL_LARGE = 0.04
#: Half the side of the opening's square, in units of the band's smallest diameter s: the
#: square (2·reach·s + 3 px) must be wider than the band's largest disc (2.5 s). Bands that
#: reach LARGE_DISC_PX use the least that does, so that the opening follows broad light
#: (haze, vignetting) whose curvature would otherwise lift a faint disc's surround.
BACKGROUND_REACH = 2.0
BACKGROUND_REACH_LARGE = 1.3
#: Smallest disc of a band, in pixels of the reduced copy it is searched on.
BAND_SIDE_PX = 6.0
#: A low-threshold blob this many times larger than its largest half-peak region is also a
#: cluster candidate (a disc's blur and glow make its blob up to about 2 times larger).
CLUSTER_AREA_RATIO = 2.0
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
    cluster: bool = False  #: a blob that may hold several overlapping discs


def contrast_floor_rel(diameter_px):
    """Smallest contrast over the background, as a share of it, for discs of ``diameter_px``."""
    return np.where(np.asarray(diameter_px) >= LARGE_DISC_PX, MIN_CONTRAST_REL_LARGE, MIN_CONTRAST_REL)


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
    reach = BACKGROUND_REACH_LARGE if 2.0 * band >= LARGE_DISC_PX else BACKGROUND_REACH
    side = 2 * math.ceil(reach * band / factor) + 3
    element = cv2.getStructuringElement(cv2.MORPH_RECT, (side, side))
    background = cv2.morphologyEx(image, cv2.MORPH_OPEN, element, borderType=cv2.BORDER_REFLECT)
    residual = image - background
    step = max(1, round(math.sqrt(residual.size / 250_000)))
    sample = residual[::step, ::step]
    median = float(np.median(sample))
    sigma = max(MIN_NOISE, 1.4826 * float(np.median(np.abs(sample - median))))
    low_count, low_labels, low_stats, low_centroids = cv2.connectedComponentsWithStats(
        (residual > SIGMA_THRESHOLD * sigma).view(np.uint8), connectivity=8, ltype=cv2.CV_32S
    )
    if low_count <= 1:
        return []
    low_peaks = _label_maxima(residual, low_labels, low_count)
    low_peaks[0] = np.inf  # background pixels never pass
    count, labels, stats, centroids = cv2.connectedComponentsWithStats(
        (residual >= 0.5 * low_peaks[low_labels]).view(np.uint8), connectivity=8, ltype=cv2.CV_32S
    )
    clusters = _cluster_candidates(
        residual, background, sigma, factor, band, (low_count, low_labels, low_stats, low_centroids, low_peaks), labels, stats
    )
    diameters = 2.0 * np.sqrt(stats[:, cv2.CC_STAT_AREA] / math.pi) * factor
    low = min_diameter if band <= min_diameter * 1.01 else BAND_OVERLAP_LOW * band
    peaks = _label_maxima(residual, labels, count)
    floor = np.maximum(MIN_CONTRAST_ABS, contrast_floor_rel(diameters) * _label_maxima(background, labels, count))
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
    ] + clusters


def _cluster_candidates(residual, background, sigma, factor, band, low, labels, stats) -> list[Candidate]:
    """Candidates for low-threshold blobs much larger than their largest half-peak region."""
    low_count, low_labels, low_stats, low_centroids, low_peaks = low
    inside = labels > 0
    largest = np.zeros(low_count, dtype=np.int64)
    np.maximum.at(largest, low_labels[inside], stats[labels[inside], cv2.CC_STAT_AREA])
    areas = low_stats[:, cv2.CC_STAT_AREA]
    diameters = 2.0 * np.sqrt(areas / math.pi) * factor
    floor = np.maximum(MIN_CONTRAST_ABS, contrast_floor_rel(diameters) * _label_maxima(background, low_labels, low_count))
    keep = (areas > CLUSTER_AREA_RATIO * np.maximum(largest, 1)) & (largest > 0)
    keep &= (diameters >= BAND_OVERLAP_LOW * band) & (diameters < BAND_OVERLAP_HIGH * 2.0 * band)
    keep &= (low_peaks >= PEAK_SIGMA * sigma) & (low_peaks >= floor)
    keep[0] = False
    return [
        Candidate(
            ((low_centroids[k, 0] + 0.5) * factor - 0.5, (low_centroids[k, 1] + 0.5) * factor - 0.5),
            float(diameters[k]),
            0.5 * max(low_stats[k, cv2.CC_STAT_WIDTH], low_stats[k, cv2.CC_STAT_HEIGHT]) * factor,
            float(low_peaks[k] / sigma),
            cluster=True,
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
