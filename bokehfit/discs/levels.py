"""The levels around a candidate: its window, the surround's background and noise, and whether
a plateau stands out of them.

Notes
-----
Levels, around a candidate of approximate radius r: the local background ``b``
is the median of the annulus from 1.3 r to 1.7 r (plus a few pixels), the local
noise the scaled median absolute deviation of that annulus (sensor noise and
texture around the disc), and the plateau ``p`` the 90th percentile of the
pixels within 0.8 r (robust to noise, and the rim of ring-shaped
"soap-bubble" discs). Where the frame holds enough of the annulus, a plane fitted
to it (robustly) is the background's gradient across the window, and the levels
are taken less that plane.

A plateau is too faint (``faint``) where its contrast ``p − b`` is below
``MIN_SNR`` local noise levels, below ``MIN_CONTRAST_ABS`` (linear) or below
``MIN_CONTRAST_REL`` of the background (:mod:`bokehfit.discs.candidates`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from bokehfit.discs.candidates import MIN_CONTRAST_ABS, contrast_floor_rel

__all__ = ["Levels", "Surround", "Window", "MIN_SNR", "pixel_noise"]

MIN_SNR = 4.0
#: The background plane: fitted where the surround has at least this many pixels (a
#: plane through a handful of pixels would follow their noise), from the pixels within
#: this many robust deviations of a first fit.
PLANE_MIN_PIXELS = 200
PLANE_INLIER_MAD = 3.0
#: ... and only where the frame holds at least this share of the annulus: a plane fitted to
#: a surround cut by the frame on two sides is extrapolated across the disc and tilts its plateau.
PLANE_MIN_ANNULUS_SHARE = 0.6
#: ... using at most this many of them (evenly spread): the plane's three numbers are then
#: known to well below the noise, at a fraction of the cost.
PLANE_MAX_PIXELS = 1000


@dataclass(frozen=True)
class Window:
    """A search window of the photo: rows ``r0`` to ``r1`` − 1, columns ``c0`` to ``c1`` − 1."""

    r0: int
    c0: int
    r1: int
    c1: int

    @classmethod
    def around(cls, shape: tuple[int, int], center_xy: tuple[float, float], half: int) -> Window:
        """The window of ``half`` pixels each side of the pixel at ``center_xy``, within a frame of ``shape``."""
        height, width = shape
        col, row = int(round(center_xy[0])), int(round(center_xy[1]))
        return cls(max(0, row - half), max(0, col - half), min(height, row + half + 1), min(width, col + half + 1))

    def of(self, image: np.ndarray) -> np.ndarray:
        """The window's pixels of ``image`` (a view)."""
        return image[self.r0 : self.r1, self.c0 : self.c1]

    def distance(self, center_xy: tuple[float, float]) -> np.ndarray:
        """Distance of each of the window's pixels from ``center_xy`` (photo coordinates)."""
        rows, cols = np.ogrid[self.r0 - center_xy[1] : self.r1 - center_xy[1], self.c0 - center_xy[0] : self.c1 - center_xy[0]]
        return np.sqrt(rows * rows + cols * cols)


@dataclass(frozen=True)
class Surround:
    """The levels of a candidate's surround (the annulus of the module's Notes)."""

    plane: _Plane | None  #: the background's gradient across the window, or None (a flat background)
    background: float  #: median of the annulus, less the plane
    noise: float  #: its scaled median absolute deviation
    lift: float  #: its median less its 10th percentile (other light in part of the surround)


@dataclass(frozen=True)
class Levels:
    """The levels a disc's outline was drawn with (the module's Notes); the outline lies halfway
    between ``background`` and ``plateau``."""

    background: float
    plateau: float
    noise: float
    ring_lift: float  #: the surround's lift (:attr:`Surround.lift`)


def _median(values: np.ndarray):
    """``np.median`` of a 1-D array without NaN, the same number in the array's type, without
    its general machinery (a candidate's levels take a dozen medians and percentiles)."""
    half = values.size // 2
    if values.size % 2:
        return np.partition(values, half)[half]
    part = np.partition(values, (half - 1, half))
    return (part[half - 1] + part[half]) / 2


def _row_medians(values: np.ndarray, rows: np.ndarray, starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """:func:`_median` of ``values[rows[i], starts[i]:stops[i]]`` for every i at once (each slice
    non-empty and in the row), the same numbers in the array's type: each window sorted, padded
    beyond its end with +inf, and its middle one or two taken."""
    rows, starts, stops = (np.asarray(v, np.int64) for v in (rows, starts, stops))
    counts = stops - starts
    if len(counts) == 0:
        return np.empty(0, values.dtype)
    at = starts[:, None] + np.arange(int(counts.max()))
    window = values[rows[:, None], np.minimum(at, values.shape[1] - 1)]
    window = np.sort(np.where(at < stops[:, None], window, np.inf).astype(values.dtype, copy=False), axis=1)
    half, each = counts // 2, np.arange(len(counts))
    upper = window[each, half]
    lower = window[each, np.maximum(half - 1, 0)]
    return np.where(counts % 2 == 1, upper, (lower + upper) / 2)


def _percentile(values: np.ndarray, q: float):
    """``np.percentile(values, q)`` (its default, linear method) of a 1-D array without NaN,
    the same number in the array's type."""
    virtual = (values.size - 1) * (q / 100)
    lower = math.floor(virtual)
    if virtual >= values.size - 1:
        return np.partition(values, -1)[-1]
    part = np.partition(values, (lower, lower + 1))
    below, above = part[lower], part[lower + 1]
    gamma = virtual - lower
    step = above - below
    return above - step * (1 - gamma) if gamma >= 0.5 else below + step * gamma


@dataclass(frozen=True)
class _Plane:
    """A background plane over a crop, ``slope_row · row + slope_col · col − offset`` (float32)."""

    slope_row: float
    slope_col: float
    offset: float

    def at(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Its values at the pixels (rows, cols)."""
        return (self.slope_row * rows + self.slope_col * cols - self.offset).astype(np.float32)

    def over(self, shape: tuple[int, int]) -> np.ndarray:
        """Its values over a crop of ``shape``."""
        rows, cols = np.ogrid[: shape[0], : shape[1]]
        return (self.slope_row * rows + self.slope_col * cols - self.offset).astype(np.float32)


def _background_plane(crop: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> _Plane | None:
    """A plane fitted to the crop's pixels (rows, cols), robustly (least squares on the pixels
    within PLANE_INLIER_MAD scaled deviations of a first fit, so that a neighbouring disc in
    the surround does not tilt it), less its median over them; None where too few pixels fit."""
    step = max(1, len(rows) // PLANE_MAX_PIXELS)  # a plane needs a few hundred pixels, not all of them
    rows, cols = rows[::step], cols[::step]
    values = crop[rows, cols].astype(np.float64)
    design = np.column_stack([np.ones(len(rows)), rows, cols]).astype(np.float64)
    inliers = np.ones(len(values), dtype=bool)
    for _ in range(2):
        coefficients = _least_squares_3(design[inliers], values[inliers])
        residual = values - design @ coefficients
        deviation = np.abs(residual - _median(residual))
        spread = 1.4826 * float(_median(deviation))
        inliers = deviation <= PLANE_INLIER_MAD * max(spread, 1e-12)
        if inliers.sum() < 8:
            return None
    return _Plane(float(coefficients[1]), float(coefficients[2]), float(_median(design[:, 1:] @ coefficients[1:])))


def _least_squares_3(design: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The least-squares coefficients of a design of three columns (a plane: 1, row, col), by its
    3 × 3 normal equations: well conditioned for a window's coordinates, and a tenth of the cost of
    ``np.linalg.lstsq``'s SVD on a few hundred rows; the SVD where LAPACK finds them singular."""
    try:
        return np.linalg.solve(design.T @ design, design.T @ values)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(design, values, rcond=None)[0]


def _annulus_levels(crop: np.ndarray, distance: np.ndarray, radius: float) -> Surround | None:
    """The :class:`Surround`: the plane of the surround's gradient (or None), and the median, robust
    spread and lift (median − 10th percentile) of the annulus 1.3 r … 1.7 r (+ 2 px) less that plane;
    None where the window holds no surround.

    The background model at the disc's scale is a plane fitted to the annulus: a
    smooth gradient across a large disc's surround (haze, vignetting) can exceed
    the contrast of a faint disc, and no one level would then outline it. Texture
    and grain stay in the spread. The plane is taken out of the pixels used here only:
    most candidates are found faint on these levels, and need no more of the crop.
    """
    where = (distance >= 1.3 * radius + 1.0) & (distance <= 1.7 * radius + 3.0)
    inside = int(where.sum())
    if inside < 8:
        where = distance >= 1.3 * radius + 1.0
        inside = int(where.sum())
    if inside < 8:
        return None  # the window holds no surround: the disc fills or overflows the frame
    annulus_px = math.pi * ((1.7 * radius + 3.0) ** 2 - (1.3 * radius + 1.0) ** 2)
    rows, cols = np.nonzero(where)
    plane = None
    if inside >= max(PLANE_MIN_PIXELS, PLANE_MIN_ANNULUS_SHARE * annulus_px):
        plane = _background_plane(crop, rows, cols)
    ring = crop[rows, cols] if plane is None else crop[rows, cols] - plane.at(rows, cols)
    median = float(_median(ring))
    low = float(_percentile(ring, 10))
    return Surround(plane, median, 1.4826 * float(_median(np.abs(ring - median))), median - low)


def _levelled(crop: np.ndarray, where: np.ndarray, plane: _Plane | None) -> np.ndarray:
    """``crop[where]`` less the background plane."""
    return crop[where] if plane is None else crop[where] - plane.at(*np.nonzero(where))


def _contrast_ok(contrast: float, noise: float, background: float, diameter_px: float) -> bool:
    return contrast >= max(MIN_SNR * noise, MIN_CONTRAST_ABS, float(contrast_floor_rel(diameter_px)) * background)


def pixel_noise(crop: np.ndarray) -> float:
    """The standard deviation of the pixel noise of ``crop``, from its finest scale: the median
    absolute response to the 3×3 second-difference mask (Immerkær 1996) over its norm, 6. Smooth
    light (haze, a neighbouring disc) adds nothing; edges are a minority the median ignores."""
    if min(crop.shape) < 3:
        return 0.0
    mask = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
    response = cv2.filter2D(np.ascontiguousarray(crop, np.float32), -1, mask, borderType=cv2.BORDER_REFLECT)
    return float(1.4826 * np.median(np.abs(response[1:-1, 1:-1])) / 6.0)
