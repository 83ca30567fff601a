"""Disc candidates seen by their edges: circles through the edge of defocused light.

Notes
-----
The blob search (:mod:`bokehfit.discs.candidates`) finds light above its
surround. Where discs overlap, it sees one blob (their light adds up) and keeps
its brightest part; a faint disc over bright haze, or a soap-bubble disc whose
centre is no brighter than its surround, is no blob at all. Each of these
still shows its own edge: a step of one blur width all round, or wherever it
borders the background. This search looks for that edge.

For each octave band of diameters [s, 2 s) from ``MIN_DIAMETER_PX``, the photo
is area-averaged so that the band's discs are ``SIDE_PX`` to 2 ``SIDE_PX``
across (at least ``MIN_REDUCTION``, and enough that the copy has at most
``MAX_COPY_PIXELS``; a band whose discs would be under ``SIDE_PX`` on that copy
is left to the blob search). The copy is searched in tiles of ``TILE_PX``
(each with a margin of the band's largest circle, a circle kept by the tile that
holds its centre): the transform's work grows faster than the pixels it is
given (a 5.5-MP copy of a sunlit juniper took 43 s of CPU whole, 2.2 s in tiles
of 512 px, for about the same circles: the accumulator's grid lies on each
tile's corner, so a circle's centre may move by a pixel, and a circle at the
transform's threshold come or go, with the tiling), and a tile that shows
texture rather than discs of the band (below) is skipped without costing its
neighbours their discs. On
the copy's logarithm (a disc of 5 % contrast over bright haze steps as much as
one of 5 % over a dark ground; ``LOG_FLOOR`` keeps the dark's noise from
becoming steps), less its mean at the band's scale and over its local spread
(``SPREAD_CODES`` codes a standard deviation, the spread at least ``MIN_SPREAD``), OpenCV's Hough gradient
transform (``HOUGH_GRADIENT_ALT``, which scores each circle by how much of it
the edges follow, 0–1) keeps the circles followed over at least
``MIN_PERFECTNESS`` of their length. Each is a place to measure
(:func:`bokehfit.discs.measure_discs_at`'s measurement), not a disc: the
measurement and the fit decide.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ["find_circles", "MIN_DIAMETER_PX", "SIDE_PX", "MIN_PERFECTNESS"]

#: Smallest disc sought by its edge (px): smaller discs are blobs the blob search sees whole.
MIN_DIAMETER_PX = 32.0
#: Smallest disc of a band, in pixels of the copy it is searched on (the Hough transform needs
#: a radius of several pixels to tell a circle's arc from a corner).
SIDE_PX = 16.0
#: Least reduction of a band's copy: the photo halved at least (its noise averaged 2 × 2).
MIN_REDUCTION = 2.0
#: Largest copy searched (pixels): the work follows the copy's pixels (tile by tile).
MAX_COPY_PIXELS = 1 << 23
#: Side of the tiles a band's copy is searched in (pixels of the copy). The transform's time grows as
#: about the 1.7th power of a tile's pixels (a tile of noise: 14 ms at 290², 158 ms at 580²), so smaller
#: tiles cost less in all, down to where their margins (the band's largest circle, 22 px) are much of
#: them: 256-px tiles took half the time of 512-px ones on the 24-MP bench photo (the same 5 circles),
#: 7.5 s instead of 12.2 on it and the 17 reference photos together; 128-px ones saved little more.
TILE_PX = 256
#: Linear light added before the logarithm (1 % of white): below it, noise is not a step.
LOG_FLOOR = 0.01
#: 8-bit codes per local standard deviation of the normalised copy, and the Canny threshold on it. The
#: transform thresholds OpenCV's Scharr gradient, sixteen times a step's height: 100 is a step of about
#: 6 codes, 0.16 of the local spread, so that most pixels of a noisy tile are edges (a third of them on the
#: 24-MP bench photo). What selects is the transform's own test, MIN_PERFECTNESS of a circle followed by
#: edges whose gradient points at its centre: a threshold of 1.6 spreads (1,000) lost 19 of the reference
#: photos' 131 discs found (RESULTS.md, "Tried, not kept", 2026-11-28).
SPREAD_CODES = 40.0
CANNY_HIGH = 100.0
#: Least local spread of the logarithm: on smooth ground a swell of the light fainter than this (haze, a
#: toned sky, JPEG's smooth gradients) is not stretched to the codes of a step.
MIN_SPREAD = 0.02
#: A tile whose light varies mostly at scales under FINE_SCALE of the band's smallest disc (more than
#: MAX_FINE_SHARE of the variance about its local mean) shows texture, not discs of the band: a carpet
#: of small glints or grass, where every pixel is an edge and the transform's work has no bound.
FINE_SCALE = 0.25
MAX_FINE_SHARE = 0.5
#: Least share of a circle the edges follow (OpenCV's HOUGH_GRADIENT_ALT param2).
MIN_PERFECTNESS = 0.8


def _normalised(copy: np.ndarray, scale_px: float) -> np.ndarray:
    """The copy's logarithm less its local mean, over its local spread, as 8-bit codes about 128."""
    logged = np.log(copy.astype(np.float32) + LOG_FLOOR)
    residual = logged - cv2.GaussianBlur(logged, (0, 0), scale_px)
    spread = np.maximum(np.sqrt(cv2.GaussianBlur(residual * residual, (0, 0), scale_px)), MIN_SPREAD)
    return np.clip(residual / spread * SPREAD_CODES + 128.0, 0, 255).astype(np.uint8)


def _fine_share(copy: np.ndarray, side: float) -> float:
    """Share of the copy's variance about its local mean (at the band's scale) that lies at scales
    under FINE_SCALE · ``side``."""
    image = copy.astype(np.float32)
    coarse = image - cv2.GaussianBlur(image, (0, 0), side)
    fine = image - cv2.GaussianBlur(image, (0, 0), FINE_SCALE * side)
    total = float(np.mean(coarse * coarse))
    return float(np.mean(fine * fine)) / total if total > 0 else 0.0


def find_circles(luminance: np.ndarray, min_diameter_px: float, max_diameter_px: float) -> list[tuple[tuple[float, float], float]]:
    """Places of circles through the edges of the photo's light: ((x, y), diameter_px), full-resolution
    pixels, band by band from the smallest, each band's tile by tile (module notes)."""
    height, width = luminance.shape
    least = max(math.sqrt(height * width / MAX_COPY_PIXELS), MIN_REDUCTION)
    places = []
    band = max(min_diameter_px, MIN_DIAMETER_PX)
    while band < max_diameter_px:
        factor = max(band / SIDE_PX, least)
        side = band / factor  # the band's smallest disc on the copy
        size = (round(width / factor), round(height / factor))
        if side >= SIDE_PX - 1e-9 and min(size) >= 2.0 * band / factor:
            copy = cv2.resize(luminance, size, interpolation=cv2.INTER_AREA)
            for x, y, r in _band_circles(copy, side):
                # Copy pixel centres to full-resolution ones (area averaging by ``factor``).
                places.append((((x + 0.5) * width / size[0] - 0.5, (y + 0.5) * height / size[1] - 0.5),
                               2.0 * r * factor))
        band *= 2.0
    return places


def _band_circles(copy: np.ndarray, side: float) -> list[tuple[float, float, float]]:
    """The circles (x, y, radius; pixels of ``copy``) of a band whose smallest disc is ``side`` across
    on ``copy``, searched in tiles of TILE_PX with a margin of the largest circle, each kept by the tile
    that holds its centre, and once: two tiles may both see a circle astride their border, its centre a
    pixel apart, and a circle within the transform's least distance (half the band's smallest disc)
    of one kept from another tile is that one. A tile that shows texture (:func:`_fine_share`) is skipped."""
    height, width = copy.shape
    largest = int(math.ceil(1.25 * side))
    margin = largest + 2
    normalised = _normalised(copy, side)
    found = []
    for y0 in range(0, height, TILE_PX):
        for x0 in range(0, width, TILE_PX):
            r0, c0 = max(0, y0 - margin), max(0, x0 - margin)
            r1, c1 = min(height, y0 + TILE_PX + margin), min(width, x0 + TILE_PX + margin)
            if min(r1 - r0, c1 - c0) < 2 * largest or _fine_share(copy[r0:r1, c0:c1], side) > MAX_FINE_SHARE:
                continue
            circles = cv2.HoughCircles(normalised[r0:r1, c0:c1], cv2.HOUGH_GRADIENT_ALT, 1.5, 0.5 * side,
                                       param1=CANNY_HIGH, param2=MIN_PERFECTNESS,
                                       minRadius=max(1, int(0.4 * side)), maxRadius=largest)
            kept = len(found)  # the circles of the tiles before this one
            for x, y, r in ([] if circles is None else circles[0]):
                x, y = float(x) + c0, float(y) + r0
                if not (y0 <= y < y0 + TILE_PX and x0 <= x < x0 + TILE_PX):
                    continue
                if any(math.hypot(x - u, y - v) < 0.5 * side for u, v, _ in found[:kept]):
                    continue
                found.append((x, y, float(r)))
    return found
