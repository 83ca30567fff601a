"""Highlight candidates at several scales: blobs well above their local background.

Notes
-----
Disc diameters are split into octave bands [s, 2s) with s = 4, 8, 16, … px.
Band s is searched on a copy reduced by ``f = s / BAND_SIDE_PX`` (area averaging),
so its discs are 6 to 12 px across there whatever their size, and every band
costs about the same. A band whose f would lie between 1 and 2 is searched on
the photo halved (f = 2, discs from ``MIN_COPY_SIDE_PX`` = 4 px there) where its
discs are 8 px or more, else on the photo itself: the first band of ``compare``
(8–16 px) is the costliest search, and a reduction by 4/3 costs a resampling of
the whole photo and leaves a copy half again as large as the half-size one,
for discs that the half-size copy still shows as blobs of 12 pixels or more
(each candidate is then measured at full resolution). The photo is halved once
(2 × 2 means); each band's copy is area-averaged from the smallest copy before
it at least ``COPY_SOURCE_RATIO`` times finer, else from the half (OpenCV's
area resampling of a large image into a very small one is slow: it works a
few output rows per thread).
On that copy:

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

Work and memory: a band's copy is searched in strips of about ``STRIP_PIXELS``
pixels, so that no temporary the size of the photo is made. Each strip's opening
is computed with a margin of the element's reach (twice its half-side), which
makes its rows exactly those of the whole copy's opening; σ is gathered strip by
strip as each is opened, each strip keeping the pixels above a provisional share of
the low threshold (opened again where that proves too high, the first strip noisier
than the whole, or keeps too many pixels), and the blobs are labelled per strip and joined where they run
across a border (8-connected, as in one piece). Only the blobs with a pixel at
the least peak a candidate needs are kept, as lists of their pixels; their
figures (centroids as sums of whole numbers over the area) are those of labelling
the copy in one piece. Candidates come out band by band from the smallest, each
band's in raster order of their first pixel.
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
#: Smallest disc of a band whose copy would be reduced by less than 2: it is searched on the
#: photo halved instead (discs from this size there), where that keeps them this large.
MIN_COPY_SIDE_PX = 4.0
#: A band's copy is area-averaged from the smallest copy made before it whose pixels are at
#: least this many times finer (else from the photo halved): so fine a source adds at most an
#: eighth of a pixel of blur, and no band resamples a large image into a very small one.
COPY_SOURCE_RATIO = 8.0
#: A low-threshold blob this many times larger than its largest half-peak region is also a
#: cluster candidate (a disc's blur and glow make its blob up to about 2 times larger).
CLUSTER_AREA_RATIO = 2.0
#: Bands overlap by these factors, so that a disc at a band's edge, measured a
#: little differently on the two reduced copies, is a candidate in at least one.
BAND_OVERLAP_LOW = 0.8
BAND_OVERLAP_HIGH = 1.25
#: Noise floor (linear units): of the candidates' noise, and of every measurement's noise estimate.
MIN_NOISE = 1e-4
#: Pixels of a band's image searched at a time (whole rows, and the margins the opening and
#: the blobs need): the search's temporaries stay a small share of the photo's own arrays.
STRIP_PIXELS = 1 << 19
#: While σ is not yet known, a strip keeps its pixels above this share of the low threshold
#: that the first strip's noise gives, and at most 1 / KEEP_MAX_SHARE of its pixels; a strip
#: that keeps more, or whose threshold proves above the final one (the first strip noisier
#: than the whole copy by more than 1 / KEEP_BELOW_THRESHOLD), is opened again. The residual
#: over an opening lies mostly above 0 (the opening follows the image from below): on the
#: bench's noisy dusk sky 5 % of it exceeds 4 σ, 10 % 3.6 σ and 19 % 3.2 σ.
KEEP_BELOW_THRESHOLD = 0.9
KEEP_MAX_SHARE = 6


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


def _opening(image: np.ndarray, element: np.ndarray, r0: int, r1: int) -> np.ndarray:
    """Rows ``r0:r1`` of the grey-scale opening of ``image``, computed on those rows and the
    element's reach around them (an erosion and a dilation: twice its half-side): exactly the
    rows of the whole image's opening, with its reflected border at the frame's edges."""
    reach = element.shape[0] - 1
    s0, s1 = max(0, r0 - reach), min(image.shape[0], r1 + reach)
    opened = cv2.morphologyEx(image[s0:s1], cv2.MORPH_OPEN, element, borderType=cv2.BORDER_REFLECT)
    return opened[r0 - s0 : r1 - s0]


def _strips(height: int, width: int, side: int) -> list[tuple[int, int]]:
    """Row ranges of about STRIP_PIXELS pixels each, at least four sides of the element tall
    (the opening's margins are then at most half the rows computed)."""
    rows = max(4 * side, STRIP_PIXELS // max(width, 1))
    return [(r0, min(r0 + rows, height)) for r0 in range(0, height, rows)]


def _above_low(image: np.ndarray, element: np.ndarray) -> tuple[float, list]:
    """The band's noise level σ (module notes), and per strip the pixels above the low threshold
    SIGMA_THRESHOLD·σ: (raster index within the strip, residual, background), index ascending.

    σ is taken on every ``step``-th row and column of the residual (about 250 000 pixels),
    gathered strip by strip. Each strip's opening is computed once: the pixels above
    ``KEEP_BELOW_THRESHOLD`` times a provisional threshold (from the first strip's samples)
    are kept as the opening is made, and filtered once σ is known. A strip whose provisional
    threshold proves higher than the final one, or that would keep more than
    ``1 / KEEP_MAX_SHARE`` of its pixels, is opened again instead.
    """
    height, width = image.shape
    step = max(1, round(math.sqrt(image.size / 250_000)))
    strips = _strips(height, width, element.shape[0])
    samples, kept, bound = [], [], None  # kept: per strip (bound, index, residual, background), or None
    for r0, r1 in strips:
        background = _opening(image, element, r0, r1)
        residual = image[r0:r1] - background
        first = -r0 % step
        samples.append(residual[first::step, ::step].copy())
        if len(strips) == 1:  # the whole band at once: σ, then its pixels above the low threshold
            sigma = _mad_sigma(samples[0])
            return sigma, [_above(residual, background, SIGMA_THRESHOLD * sigma)]
        if bound is None:
            bound = KEEP_BELOW_THRESHOLD * SIGMA_THRESHOLD * _mad_sigma(samples[0])
        at = np.flatnonzero(residual > bound)
        small = at.size * KEEP_MAX_SHARE <= residual.size
        kept.append((bound, at, residual.ravel()[at], background.ravel()[at]) if small else None)
    sigma = _mad_sigma(np.concatenate(samples))
    low = SIGMA_THRESHOLD * sigma
    pixels = []
    for (r0, r1), strip in zip(strips, kept):
        if strip is None or strip[0] > low:  # opened again
            background = _opening(image, element, r0, r1)
            pixels.append(_above(image[r0:r1] - background, background, low))
        else:
            _, at, residual, background = strip
            above = residual > low
            pixels.append((at[above], residual[above], background[above]))
    return sigma, pixels


def _above(residual: np.ndarray, background: np.ndarray, low: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A strip's pixels whose residual exceeds ``low``: (raster index, residual, background)."""
    at = np.flatnonzero(residual > low)
    return at, residual.ravel()[at], background.ravel()[at]


def _mad_sigma(sample: np.ndarray) -> float:
    """1.4826 × the median absolute deviation of ``sample``, at least MIN_NOISE."""
    median = float(np.median(sample))
    return max(MIN_NOISE, 1.4826 * float(np.median(np.abs(sample - median))))


@dataclass(frozen=True)
class _Blobs:
    """8-connected pixel regions of a band's image, one entry per region: what candidates need."""

    first: np.ndarray  #: raster index (row · width + column) of the first pixel, for a stable order
    area: np.ndarray
    centroid: np.ndarray  #: (n, 2): (column, row)
    extent: np.ndarray  #: half the longer side of the bounding box
    peak: np.ndarray  #: largest residual (float32)
    background: np.ndarray  #: largest background (float32)


def _describe(region: np.ndarray, count: int, flat: np.ndarray, residual, background, width: int) -> _Blobs:
    """The :class:`_Blobs` of ``count`` regions, from their pixels: ``region`` (0 … count − 1)
    and ``flat`` (raster index) per pixel, with its residual and background.

    The centroids are sums of whole numbers over the area, as OpenCV's connected components give them."""
    # ufunc.at is fast only where the values have the type of the array they go into.
    kind = flat.dtype
    rows, cols = np.divmod(flat, kind.type(width))
    area = np.bincount(region, minlength=count)
    first = np.full(count, np.iinfo(kind).max, dtype=kind)
    np.minimum.at(first, region, flat)
    sides = []
    for values in (cols, rows):
        low, high = np.full(count, np.iinfo(kind).max, dtype=kind), np.full(count, -1, dtype=kind)
        np.minimum.at(low, region, values)
        np.maximum.at(high, region, values)
        sides.append(high - low + 1)
    sums = [np.bincount(region, weights=values, minlength=count) for values in (cols, rows)]
    peak = np.full(count, -np.inf, dtype=np.float32)
    np.maximum.at(peak, region, residual)
    lifted = np.full(count, -np.inf, dtype=np.float32)
    np.maximum.at(lifted, region, background)
    centroid = np.column_stack([sums[0] / area, sums[1] / area])
    return _Blobs(first, area, centroid, 0.5 * np.maximum(*sides), peak, lifted)


def _join(edges: list[tuple[np.ndarray, np.ndarray]], total: int, width: int) -> tuple[int, np.ndarray]:
    """Number of regions, and the region of each of ``total`` strip-wise labels: labels that are
    8-connected across a border between strips are one region. ``edges`` holds per strip the
    labels along its first and last rows (−1: no pixel)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    sources, targets = [], []
    for (_, above), (below, _) in zip(edges, edges[1:]):
        for shift in (-1, 0, 1):  # pixel (r − 1, c) touches (r, c + shift)
            a = above[max(0, -shift) : width - max(0, shift)]
            b = below[max(0, shift) : width - max(0, -shift)]
            both = (a >= 0) & (b >= 0)
            sources.append(a[both])
            targets.append(b[both])
    sources = np.concatenate(sources) if sources else np.zeros(0, dtype=np.int32)
    targets = np.concatenate(targets) if targets else np.zeros(0, dtype=np.int32)
    graph = coo_matrix((np.ones(len(sources), dtype=np.int8), (sources, targets)), shape=(total, total))
    return connected_components(graph, directed=False)


def _strip_labels(mask: np.ndarray, offset: int) -> tuple[int, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """8-connected labels of a strip's mask, numbered from ``offset`` (−1: not in the mask), as
    (count, labels, (first row, last row))."""
    count, labels = cv2.connectedComponents(mask.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
    labels += offset - 1
    labels[~mask] = -1
    return count - 1, labels, (labels[0].copy(), labels[-1].copy())


def _band_blobs(image, element) -> tuple[float, _Blobs, _Blobs, np.ndarray]:
    """The band's noise level σ, the low-threshold blobs of its image that may give
    candidates, their half-peak regions, and per half-peak region the index of its blob.

    The image is searched in strips of rows (the opening with a margin of its reach, so
    that every row is exact), and regions that run across the borders of strips are joined.
    Only blobs with a pixel at the least peak a candidate needs (``PEAK_SIGMA`` σ and
    ``MIN_CONTRAST_ABS``) are kept: a half-peak region's peak is at most its blob's, so the
    others give none. Their pixels are kept as lists (index, residual, background): the
    candidates' blobs cover a small part of the image.
    """
    height, width = image.shape
    sigma, above = _above_low(image, element)
    least = max(PEAK_SIGMA * sigma, MIN_CONTRAST_ABS)
    strips = _strips(height, width, element.shape[0])
    index = np.int32 if image.size < 2**31 else np.int64
    kept: dict[str, list[np.ndarray]] = {"flat": [], "residual": [], "background": [], "label": []}
    edges, seeds, total = [], [], 0
    for (r0, r1), (at, residual, background) in zip(strips, above):
        mask = np.zeros((r1 - r0, width), dtype=np.bool_)
        mask.ravel()[at] = True
        count, labels, edge = _strip_labels(mask, total)
        label = labels.ravel()[at]
        wanted = np.zeros(total + count + 1, dtype=np.bool_)
        wanted[label[residual >= least] + 1] = True
        seeds.append(np.flatnonzero(wanted) - 1)
        # A blob without a seed here may still be joined to one in another strip through a border row.
        wanted[np.concatenate(edge) + 1] = True
        wanted[0] = False  # no pixel
        chosen = wanted[label + 1]
        kept["flat"].append((at[chosen] + r0 * width).astype(index))
        kept["residual"].append(residual[chosen])
        kept["background"].append(background[chosen])
        kept["label"].append(label[chosen])
        edges.append(edge)
        total += count
    del above, mask, labels, label, wanted, chosen  # the strips' pixels above the low threshold
    _, region = _join(edges, total, width)
    seeded = np.zeros(total, dtype=np.bool_)
    seeded[region[np.concatenate(seeds)]] = True
    numbers = np.cumsum(seeded) - 1  # the seeded regions, numbered 0 … n − 1
    inside = [seeded[region[label]] for label in kept["label"]]
    # One list at a time, each dropped as it is joined: the unseeded pixels are not copied.
    flat, residual, background, label = (
        np.concatenate([part[keep] for part, keep in zip(kept.pop(name), inside)])
        for name in ("flat", "residual", "background", "label")
    )
    blob_of = numbers[region[label]]
    count = int(numbers[-1]) + 1 if total else 0
    del label, inside, numbers, seeded
    blobs = _describe(blob_of, count, flat, residual, background, width)
    # Each blob cut at half its peak (as float32, as the comparison was made per pixel).
    half = residual >= 0.5 * blobs.peak[blob_of]
    flat, residual, background, blob_of = flat[half], residual[half], background[half], blob_of[half]
    bounds = np.searchsorted(flat, [r0 * width for r0, _ in strips] + [height * width])
    parts, edges, total = [], [], 0
    for (r0, r1), i0, i1 in zip(strips, bounds, bounds[1:]):
        mask = np.zeros((r1 - r0, width), dtype=np.bool_)
        mask.ravel()[flat[i0:i1] - r0 * width] = True
        count, labels, edge = _strip_labels(mask, total)
        parts.append(labels.ravel()[flat[i0:i1] - r0 * width])
        edges.append(edge)
        total += count
    del mask, labels
    count, region = _join(edges, total, width)
    region = region[np.concatenate(parts)]
    owner = np.zeros(count, dtype=np.int64)
    owner[region] = blob_of
    return sigma, blobs, _describe(region, count, flat, residual, background, width), owner


def _band_candidates(image: np.ndarray, factor: float, band: float, min_diameter: float) -> list[Candidate]:
    """The candidates of band ``band``, searched on ``image``, the photo reduced by ``factor``."""
    reach = BACKGROUND_REACH_LARGE if 2.0 * band >= LARGE_DISC_PX else BACKGROUND_REACH
    side = 2 * math.ceil(reach * band / factor) + 3
    element = cv2.getStructuringElement(cv2.MORPH_RECT, (side, side))
    low = min_diameter if band <= min_diameter * 1.01 else BAND_OVERLAP_LOW * band
    sigma, blobs, regions, owner = _band_blobs(image, element)
    diameters = 2.0 * np.sqrt(regions.area / math.pi) * factor
    floor = np.maximum(MIN_CONTRAST_ABS, contrast_floor_rel(diameters) * regions.background)
    keep = (diameters >= low) & (diameters < BAND_OVERLAP_HIGH * 2.0 * band)
    keep &= (regions.peak >= PEAK_SIGMA * sigma) & (regions.peak >= floor)
    found = [(False, regions, k, float(diameters[k])) for k in np.nonzero(keep)[0]]
    found += [(True, blobs, k, d) for k, d in _cluster_blobs(blobs, regions, owner, sigma, factor, band)]
    found.sort(key=lambda item: (item[0], item[1].first[item[2]]))  # regions, then clusters, each in raster order
    return [
        Candidate(
            ((blobs.centroid[k, 0] + 0.5) * factor - 0.5, (blobs.centroid[k, 1] + 0.5) * factor - 0.5),
            diameter,
            float(blobs.extent[k] * factor),
            float(blobs.peak[k] / sigma),
            cluster=cluster,
        )
        for cluster, blobs, k, diameter in found
    ]


def _cluster_blobs(blobs: _Blobs, regions: _Blobs, owner: np.ndarray, sigma, factor, band) -> list[tuple[int, float]]:
    """(index, diameter) of the low-threshold blobs much larger than their largest half-peak region."""
    largest = np.zeros(len(blobs.area), dtype=np.int64)
    np.maximum.at(largest, owner, regions.area)
    diameters = 2.0 * np.sqrt(blobs.area / math.pi) * factor
    floor = np.maximum(MIN_CONTRAST_ABS, contrast_floor_rel(diameters) * blobs.background)
    keep = (blobs.area > CLUSTER_AREA_RATIO * np.maximum(largest, 1)) & (largest > 0)
    keep &= (diameters >= BAND_OVERLAP_LOW * band) & (diameters < BAND_OVERLAP_HIGH * 2.0 * band)
    keep &= (blobs.peak >= PEAK_SIGMA * sigma) & (blobs.peak >= floor)
    return [(k, float(diameters[k])) for k in np.nonzero(keep)[0]]


def find_candidates(luminance: np.ndarray, min_diameter_px: float, max_diameter_px: float) -> list[Candidate]:
    """Candidates of every octave band from ``min_diameter_px`` to ``max_diameter_px``, band by band.

    The bands go from the smallest up. Each band's reduced copy is made from the copy
    before it (a pyramid: the photo itself is area-averaged once, every later copy is half
    the one before), so the reductions cost about a third of the first one in all.
    """
    height, width = luminance.shape
    found = []
    copies: list[tuple[float, np.ndarray]] = []  # (factor, copy), finest first: the photo halved, then the bands'
    band = min_diameter_px
    while band < max_diameter_px:
        factor = _reduction(band)
        image = luminance
        if factor > 1.0:
            if not copies:
                size = (max(1, round(width / 2)), max(1, round(height / 2)))
                copies.append((2.0, cv2.resize(luminance, size, interpolation=cv2.INTER_AREA)))
            # The source: the smallest copy at least COPY_SOURCE_RATIO times finer (else the half);
            # the finer ones before it are no band's source any more.
            source = max(0, sum(f * COPY_SOURCE_RATIO <= factor for f, _ in copies) - 1)
            del copies[:source]
            image = copies[0][1]
            if factor != copies[0][0]:
                size = (max(1, round(width / factor)), max(1, round(height / factor)))
                image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
                copies.append((factor, image))
        found += _band_candidates(image, factor, band, min_diameter_px)
        band *= 2.0
    return found


def _reduction(band: float) -> float:
    """The factor by which band ``band``'s copy is reduced (module notes): ``band / BAND_SIDE_PX``,
    but 2 in place of a factor between 1 and 2 where the band's discs are ``MIN_COPY_SIDE_PX`` or
    more there, else 1."""
    factor = band / BAND_SIDE_PX
    if factor >= 2.0:
        return factor
    return 2.0 if band >= 2.0 * MIN_COPY_SIDE_PX else 1.0
