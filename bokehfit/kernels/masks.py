"""Exact light of a ``mask`` aperture on a pixel grid (design.md §3b).

Notes
-----
As for the outlines (:mod:`bokehfit.kernels.exact`), a pixel's light is the second difference over its
corners of F(X, Y), the light inside the quadrant {x ≤ X, y ≤ Y}.

A mask is a piecewise-constant transmission T = Σ t_c·1_c
over square cells, so F is linear in it: every border between two cells
(and between a cell and the outside) is a straight segment weighted by the
jump of t across it, and :func:`mask_coverage` sums the same closed form over
those weighted segments, rotated and squeezed. That is exact too (float64
rounding), at any angle.
"""

from __future__ import annotations

import numpy as np

from bokehfit.apertures import Aperture, aperture_rows_to_image

__all__ = ["mask_border_segments", "mask_coverage"]


def _mask_jumps(mask) -> tuple[np.ndarray, np.ndarray]:
    """Transmission jumps across the mask's horizontal borders (h + 1, w) and vertical ones (h, w + 1).

    Rows bottom first (y up), zero outside the image: horizontal, the cell
    above minus the one below; vertical, the cell left minus the one right.
    """
    t = np.pad(mask.transmission[::-1], 1)
    return t[1:, 1:-1] - t[:-1, 1:-1], t[1:-1, :-1] - t[1:-1, 1:]


def mask_border_segments(aperture: Aperture) -> int:
    """How many weighted border segments :func:`mask_coverage` integrates for a ``mask`` aperture: its cost."""
    jump_h, jump_v = _mask_jumps(aperture.mask)
    return int(np.count_nonzero(jump_h) + np.count_nonzero(jump_v))


def _mask_segments(aperture: Aperture) -> tuple[np.ndarray, np.ndarray]:
    """The mask's cell borders as weighted segments (start, end) of shape (M, 2, 2), weights (M,).

    A horizontal border running +x weighs t(above) − t(below); a vertical one
    running +y weighs t(left) − t(right): the sum of the cells' counter-clockwise
    boundaries, each weighted by its transmission. Unit-area units, at angle 0.
    """
    mask = aperture.mask
    h, w = mask.shape
    cell = mask.cell
    # Horizontal borders: between padded rows r and r + 1 (y = r·cell − h/2·cell), columns 0..w−1;
    # vertical borders: between padded columns c and c + 1 (x = c·cell − w/2·cell), rows 0..h−1.
    jump_h, jump_v = _mask_jumps(mask)
    rows, cols = np.nonzero(jump_h)
    start_h = np.stack([cols, rows], axis=-1).astype(np.float64)
    end_h = start_h + [1.0, 0.0]
    vrows, vcols = np.nonzero(jump_v)
    start_v = np.stack([vcols, vrows], axis=-1).astype(np.float64)
    end_v = start_v + [0.0, 1.0]
    ends = np.stack([np.concatenate([start_h, start_v]), np.concatenate([end_h, end_v])], axis=1)
    ends = (ends - [0.5 * w, 0.5 * h]) * cell
    return ends, np.concatenate([jump_h[rows, cols], jump_v[vrows, vcols]])


def _segment_quadrant(x0, y0, x1, y1, X, Y):
    """−sign·∫ min(f(x), Y) dx over [x_min, clamp(X)] for the straight segments (x0, y0)→(x1, y1) (not vertical)."""
    left = x0 < x1
    sign = np.where(left, 1.0, -1.0)
    xa, ya, xb, yb = np.where(left, x0, x1), np.where(left, y0, y1), np.where(left, x1, x0), np.where(left, y1, y0)
    slope = (yb - ya) / (xb - xa)
    t = np.clip(X, xa, xb)
    flat = slope == 0.0
    crossing = np.where(flat, np.where(Y > ya, xb, xa), np.clip(xa + (Y - ya) / np.where(flat, 1.0, slope), xa, xb))
    x_cross = np.minimum(t, crossing)

    def under(x):  # ∫ f from x_min to x
        return ya * (x - xa) + 0.5 * slope * (x - xa) ** 2

    increasing = slope >= 0.0
    integral = np.where(
        increasing, under(x_cross) + Y * (t - x_cross), Y * (x_cross - xa) + under(t) - under(x_cross)
    )
    return -sign * integral


#: Segment-pixel pairs a chunk of :func:`mask_coverage` evaluates at once (bounds its memory).
_MASK_CHUNK = 2**21


def mask_coverage(aperture: Aperture, scale: float, size: int) -> np.ndarray:
    """Exact light of a ``mask`` aperture on each pixel of a size × size grid (float64, px² of unit transmission).

    The mask's transmission is piecewise constant, so the area-weighted box
    integral over each pixel is exact (up to float64 rounding) at any angle,
    squeeze and scale (see the module notes). Each weighted border segment
    changes the pixels of its bounding box, and below it a strip of
    columns (where F is linear in Y) that one cumulative sum adds.
    """
    segments, weights = _mask_segments(aperture)
    matrix = scale * aperture.squeeze_matrix() @ aperture.rotation()
    segments = segments @ matrix.T
    keep = segments[:, 0, 0] != segments[:, 1, 0]  # vertical segments add no area under the curve
    segments, weights = segments[keep], weights[keep]
    centre = (size - 1) / 2.0
    image = np.zeros((size, size))  # rows run up in y here
    strip = np.zeros((size + 1, size))
    if len(weights) == 0:
        return image
    x0, y0, x1, y1 = segments[:, 0, 0], segments[:, 0, 1], segments[:, 1, 0], segments[:, 1, 1]
    # Pixel k spans [k − 0.5 − centre, k + 0.5 − centre]; the first and last pixel each segment's box touches.
    def first(v):
        return np.clip(np.floor(v + 0.5 + centre), 0, size).astype(np.int64)

    c0, c1 = first(np.minimum(x0, x1)), np.minimum(first(np.maximum(x0, x1)), size - 1)
    r0, r1 = first(np.minimum(y0, y1)), np.minimum(first(np.maximum(y0, y1)), size - 1)
    box_w = int(np.max(c1 - c0)) + 1
    box_h = int(max(np.max(r1 - r0), 0)) + 1
    per = (box_w + 1) * (box_h + 1)
    dc, dr = np.arange(box_w + 1), np.arange(box_h + 1)
    for lo in range(0, len(weights), max(1, _MASK_CHUNK // per)):
        sl = slice(lo, lo + max(1, _MASK_CHUNK // per))
        a = [v[sl, None, None] for v in (x0, y0, x1, y1)]
        X = (c0[sl, None, None] + dc[None, None, :]) - 0.5 - centre
        Y = (r0[sl, None, None] + dr[None, :, None]) - 0.5 - centre
        f = _segment_quadrant(*a, X, Y) * weights[sl, None, None]
        cells = f[:, 1:, 1:] - f[:, :-1, 1:] - f[:, 1:, :-1] + f[:, :-1, :-1]
        rows = np.broadcast_to(r0[sl, None, None] + dr[None, :-1, None], cells.shape)
        cols = np.broadcast_to(c0[sl, None, None] + dc[None, None, :-1], cells.shape)
        inside = (rows < size) & (cols < size)
        np.add.at(image, (rows[inside], cols[inside]), cells[inside])
        # Rows below the box (top edge ≤ y_min): F = −sign·Y·(clamp X − x_min) is linear in Y,
        # so each pixel of such a row gets −sign·(clamp X₊ − clamp X₋)·weight.
        xa, xb = np.minimum(a[0], a[2])[:, 0, :], np.maximum(a[0], a[2])[:, 0, :]
        clamped = np.clip(X[:, 0, :], xa, xb)
        sign = np.where(a[0][:, 0, :] < a[2][:, 0, :], 1.0, -1.0)
        share = -sign * (clamped[:, 1:] - clamped[:, :-1]) * weights[sl, None]
        strip_rows = np.broadcast_to(r0[sl, None], share.shape)
        strip_cols = cols[:, 0, :]
        ok = strip_cols < size
        np.add.at(strip, (strip_rows[ok], strip_cols[ok]), share[ok])
    # strip[r] holds the per-row light of every row below r: add it to rows 0..r−1.
    below_rows = strip.sum(axis=0) - np.cumsum(strip, axis=0)[:-1]
    return np.clip(aperture_rows_to_image(image + below_rows), 0.0, None)
