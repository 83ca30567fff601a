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
(``SPREAD_CODES`` codes a standard deviation, the spread at least ``MIN_SPREAD``; both blurs of the band's
scale made on a coarser copy, :func:`_smoothed`), OpenCV's Hough gradient
transform (``HOUGH_GRADIENT_ALT``, which scores each circle by how much of it
the edges follow, 0–1) keeps the circles followed over at least
``MIN_PERFECTNESS`` of their length. Each is a place to measure
(:func:`bokehfit.discs.measure_discs_at`'s measurement), not a disc: the
measurement and the fit decide.

Discs at one depth are one size: the aperture's image scaled by the same defocus. Once the search
has measured discs, :func:`find_sized_circles` looks again for circles of the sizes it found (each
seen at least ``SIZED_MIN_DISCS`` times, to ``SIZE_STEP`` either way), near the discs of that size
(within ``SIZED_REACH`` of their diameter: a depth's discs lie together), where a disc of a chain or
one crossed by a twig shows its own edge over only part of its outline. Each edge pixel of the copy's
normalised logarithm (as above) votes, along its gradient into the light, for the centre at each
radius of the band (:func:`_vote`), and a centre is kept where the votes come from at least
``SIZED_MIN_SHARE`` of the circle's length. With the radius known to a band of ``SIZE_STEP`` either
way, half a circle's arc points at one centre as no texture's edges do; the transform's perfectness
above must hold for any radius of an octave, and misses most discs of a chain.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ["find_circles", "find_sized_circles", "MIN_DIAMETER_PX", "SIDE_PX", "MIN_PERFECTNESS"]

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
#: Blurs of this standard deviation (px) or more are made on a reduced copy (:func:`_smoothed`).
SMOOTH_REDUCE_SIGMA = 4.0
#: A tile whose light varies mostly at scales under FINE_SCALE of the band's smallest disc (more than
#: MAX_FINE_SHARE of the variance about its local mean) shows texture, not discs of the band: a carpet
#: of small glints or grass, where every pixel is an edge and the transform's work has no bound.
FINE_SCALE = 0.25
MAX_FINE_SHARE = 0.5
#: Least share of a circle the edges follow (OpenCV's HOUGH_GRADIENT_ALT param2).
MIN_PERFECTNESS = 0.8
#: A size is searched again (:func:`find_sized_circles`) where this many discs measured have it (to a
#: band of SIZE_STEP either way): a depth with discs, not one blob's size.
SIZED_MIN_DISCS = 2
#: The band of radii searched about a size found, this factor either way; the sizes found are binned by
#: its square, so that the bands tile the sizes.
SIZE_STEP = 1.25
#: A size's copy is reduced so that its discs are this radius (px of the copy), or at least by the
#: copy's least reduction (MAX_COPY_PIXELS) ...
SIZED_RADIUS_PX = 6.0
#: ... and a size whose discs would then be under this radius (px of the copy) is not searched again
#: (the blob search sees such small discs whole).
SIZED_MIN_RADIUS_PX = 5.0
#: A size is sought within this many of its diameters of each disc measured at it (each way): a depth's
#: discs lie together (a chain, a string of drops, a bush's lights), and the work is bounded by the discs
#: found, not the frame. Each size sought over the whole frame made the 24-MP bench photo's compare (50
#: pentagons of 15-150 px, of many sizes) 1.7 s slower, 4.5 s instead of 2.8, and found 4 more of the
#: reference photos' 268 labelled discs than this reach; a reach of 2 found 5 fewer (RESULTS.md).
SIZED_REACH = 4.0
#: Each window is searched with this many diameters more of the photo about it: the local mean's scale
#: (a diameter) and the band's largest circle.
SIZED_MARGIN = 1.5
#: Least share of a circle's length whose edge pixels vote for its centre (at one radius of the band).
SIZED_MIN_SHARE = 0.5
#: Radii of a band voted for, this far apart (px of the copy).
SIZED_RADIUS_STEP_PX = 0.75


def _smoothed(image: np.ndarray, sigma_px: float) -> np.ndarray:
    """``image`` blurred by a Gaussian of ``sigma_px``: from SMOOTH_REDUCE_SIGMA on, on a copy area-averaged by
    ``sigma_px`` / SMOOTH_REDUCE_SIGMA and brought back by linear interpolation (a blur that wide holds nothing
    the coarser grid misses; the averaging and the interpolation add about a quarter of the square of the
    reduction to its variance, taken from the Gaussian's)."""
    factor = int(sigma_px // SMOOTH_REDUCE_SIGMA)
    if factor < 2:
        return cv2.GaussianBlur(image, (0, 0), sigma_px)
    height, width = image.shape
    size = (max(1, round(width / factor)), max(1, round(height / factor)))
    small = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    small = cv2.GaussianBlur(small, (0, 0), math.sqrt(sigma_px * sigma_px - 0.25 * factor * factor) / factor)
    return cv2.resize(small, (width, height), interpolation=cv2.INTER_LINEAR)


def _normalised(copy: np.ndarray, scale_px: float) -> np.ndarray:
    """The copy's logarithm less its local mean, over its local spread, as 8-bit codes about 128."""
    logged = np.log(copy.astype(np.float32) + LOG_FLOOR)
    residual = logged - _smoothed(logged, scale_px)
    spread = np.maximum(np.sqrt(_smoothed(residual * residual, scale_px)), MIN_SPREAD)
    return np.clip(residual / spread * SPREAD_CODES + 128.0, 0, 255).astype(np.uint8)


def _fine_share(copy: np.ndarray, side: float) -> float:
    """Share of the copy's variance about its local mean (at the band's scale) that lies at scales
    under FINE_SCALE · ``side``."""
    image = copy.astype(np.float32)
    coarse = image - _smoothed(image, side)
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


def find_sized_circles(luminance: np.ndarray, discs) -> list[tuple[tuple[float, float], float, float]]:
    """Places of circles of the sizes of the ``discs`` measured (((x, y), diameter_px) each; module notes),
    each size sought within SIZED_REACH of its discs: ((x, y), diameter_px, share), full-resolution pixels,
    the share of its length that points at its centre; the clearest first."""
    height, width = luminance.shape
    least = max(math.sqrt(height * width / MAX_COPY_PIXELS), 1.0)
    step = SIZE_STEP * SIZE_STEP
    discs = [((float(x), float(y)), float(d)) for (x, y), d in discs if d > 0]
    bins = np.round(np.log([d for _, d in discs]) / math.log(step)) if discs else np.zeros(0)
    values, counts = np.unique(bins, return_counts=True)
    places = []
    for k in values[counts >= SIZED_MIN_DISCS]:
        diameter = step ** float(k)
        factor = max(0.5 * diameter / SIZED_RADIUS_PX, least)
        radius = 0.5 * diameter / factor
        if radius < SIZED_MIN_RADIUS_PX or min(height, width) / factor < 2.0 * SIZE_STEP * radius:
            continue
        centres = [xy for (xy, _), b in zip(discs, bins) if b == k]
        margin = math.ceil(SIZED_MARGIN * diameter)
        for x0, y0, x1, y1 in _windows(centres, SIZED_REACH * diameter, (width, height)):
            # The window and a margin for the local mean and the band's largest circle, on a copy reduced.
            c0, r0, c1, r1 = max(0, x0 - margin), max(0, y0 - margin), min(width, x1 + margin), min(height, y1 + margin)
            size = (max(1, round((c1 - c0) / factor)), max(1, round((r1 - r0) / factor)))
            crop = luminance[r0:r1, c0:c1]
            copy = cv2.resize(crop, size, interpolation=cv2.INTER_AREA) if factor > 1.0 else crop
            if min(copy.shape) < 2.0 * SIZE_STEP * radius:
                continue
            sx, sy = (c1 - c0) / size[0], (r1 - r0) / size[1]
            for x, y, r, share in _vote(copy, radius):
                xy = (c0 + (x + 0.5) * sx - 0.5, r0 + (y + 0.5) * sy - 0.5)
                if x0 <= xy[0] < x1 and y0 <= xy[1] < y1:
                    places.append((xy, 2.0 * r * factor, share))
    places.sort(key=lambda p: -p[2])
    return places


def _windows(centres, reach: float, frame: tuple[int, int]) -> list[tuple[int, int, int, int]]:
    """The boxes (x0, y0, x1, y1; pixels, ends excluded) within ``reach`` of the ``centres`` each way, in
    the ``frame`` (width, height), those that overlap merged into one."""
    width, height = frame
    boxes = [(max(0, math.floor(x - reach)), max(0, math.floor(y - reach)),
              min(width, math.ceil(x + reach) + 1), min(height, math.ceil(y + reach) + 1)) for x, y in centres]
    merged = True
    while merged:
        merged, kept = False, []
        for box in sorted(boxes):
            for i, other in enumerate(kept):
                if box[0] < other[2] and other[0] < box[2] and box[1] < other[3] and other[1] < box[3]:
                    kept[i] = (min(box[0], other[0]), min(box[1], other[1]),
                               max(box[2], other[2]), max(box[3], other[3]))
                    merged = True
                    break
            else:
                kept.append(box)
        boxes = kept
    return boxes


def _vote(copy: np.ndarray, radius: float) -> list[tuple[float, float, float, float]]:
    """The circles (x, y, radius, share; pixels of ``copy``) of radii ``radius`` / SIZE_STEP to
    ``radius`` · SIZE_STEP whose centre the copy's edge pixels vote for, each along its gradient into
    the light, from at least SIZED_MIN_SHARE of the circle's length (a 3 × 3 neighbourhood's votes);
    one in a window of about the radius (the clearest; of a plateau's equal peaks, one), its radius the mean
    of the radii voting there."""
    normalised = _normalised(copy, 2.0 * radius)
    edges = cv2.Canny(normalised, 0.5 * CANNY_HIGH, CANNY_HIGH, L2gradient=True)
    codes = normalised.astype(np.float32)
    gx, gy = cv2.Sobel(codes, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(codes, cv2.CV_32F, 0, 1, ksize=3)
    ys, xs = np.nonzero(edges)
    dx, dy = gx[ys, xs], gy[ys, xs]
    norm = np.hypot(dx, dy)
    keep = norm > 0
    xs, ys = xs[keep].astype(np.float32), ys[keep].astype(np.float32)
    ux, uy = dx[keep] / norm[keep], dy[keep] / norm[keep]
    height, width = copy.shape
    best = np.zeros((height, width), np.float32)
    votes_sum, radius_sum = np.zeros_like(best), np.zeros_like(best)
    for r in np.arange(radius / SIZE_STEP, radius * SIZE_STEP + 1e-6, SIZED_RADIUS_STEP_PX):
        cx, cy = np.floor(xs + r * ux + 0.5).astype(np.int64), np.floor(ys + r * uy + 0.5).astype(np.int64)
        inside = (cx >= 0) & (cx < width) & (cy >= 0) & (cy < height)
        votes = np.bincount(cy[inside] * width + cx[inside], minlength=height * width)
        votes = cv2.boxFilter(votes.reshape(height, width).astype(np.float32), -1, (3, 3), normalize=False,
                              borderType=cv2.BORDER_CONSTANT)
        best = np.maximum(best, votes * np.float32(1.0 / (2.0 * math.pi * r)))
        votes_sum += votes
        radius_sum += np.float32(r) * votes
    side = max(3, round(radius) | 1)
    peaks = (best >= SIZED_MIN_SHARE) & (best >= cv2.dilate(best, np.ones((side, side), np.uint8)))
    py, px = np.nonzero(peaks)
    order = np.argsort(-best[py, px], kind="stable")
    kept: list[tuple[float, float, float, float]] = []
    cells: dict[tuple[int, int], list[tuple[int, int]]] = {}
    half = side // 2
    for y, x in zip(py[order], px[order]):
        cell = (int(x) // side, int(y) // side)
        near = (p for i in (-1, 0, 1) for j in (-1, 0, 1) for p in cells.get((cell[0] + i, cell[1] + j), ()))
        if any(abs(int(x) - u) <= half and abs(int(y) - v) <= half for u, v in near):
            continue  # an equal peak of the same plateau
        cells.setdefault(cell, []).append((int(x), int(y)))
        # The radius the votes gathered at this centre point to: those of the radii about the disc's own
        # land in its 3 x 3 neighbourhood, those of others on a ring about it.
        kept.append((float(x), float(y), float(radius_sum[y, x] / votes_sum[y, x]), float(best[y, x])))
    return kept
