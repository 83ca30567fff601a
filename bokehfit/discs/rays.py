"""Measure a disc at a place along rays from its centre: where its light steps down.

Notes
-----
The contour measurement (:mod:`bokehfit.discs.measure`) draws one iso-contour
at half the disc's contrast over one background level taken from the annulus
around it. That is right for a disc on an even ground, and it fails where a
person still reads the disc at a glance:

- a **faint large disc** over haze, whose annulus holds the neighbours' light
  and the scene's structure: their spread, taken as noise, swamps a contrast
  of a few per cent that the disc's edge shows over thousands of pixels;
- **overlapping discs**, whose surround is partly other discs: the light of
  defocused points adds, so where disc A lies over disc B, A's own edge is
  still a step down of A's contrast, but no one level outlines it.

This measurement follows the edge itself. Around the centre, ``RAYS`` rays
(each the mean of a thin wedge) sample the lightly smoothed light; the
outline is the closed path through the rays' radial derivative that is
steepest downwards (dynamic programming, the radius changing by at most
``MAX_SLOPE`` radius per radian from ray to ray, over three turns of which the
middle is kept: a closed path without a chosen start). On each ray the step
is measured by the light just inside and just outside it (``SIDE_REL``), and the
outline point is the half-level crossing between them (the labels'
definition of the outline, as in the contour measurement). A ray shows the
disc's own edge where its step is positive, stands ``MIN_STEP_SIGMA`` of its
noise out of the pixel noise (estimated from the crop's finest scale, where
smooth neighbours and haze add nothing) and is within ``STEP_RATIO`` of the
median step: a ray that runs into an occluder, a brighter neighbour or the
frame is marked not seen, and the outline there is interpolated from the
seen rays. The disc is then judged as every measured disc is
(:func:`bokehfit.discs.measure.describe`): soft edge, elongation,
solidity, line-likeness, with the pixel noise as its noise.

It is what a defocused light is, not a threshold on one photo: a plateau or a
rim with a step of one blur width all round. A Gaussian blob or a cone has no
step (their edges are as wide as their radius: "soft edge"), and texture gives
no closed path whose steps agree.
"""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np
from scipy import ndimage

from bokehfit.discs.contours import polygon_area_centroid
from bokehfit.discs.levels import Levels, Window, _median, _row_medians, pixel_noise
from bokehfit.discs.outlines import Outlined
from bokehfit.discs.reasons import NoDisc, Reason
from bokehfit.discs.verdict import Measurement, describe

__all__ = ["measure_rays", "RAYS", "MIN_STEP_SIGMA", "MIN_SEEN"]

#: Rays around the centre: about one per 3 px of circumference, within these bounds.
RAYS = (48, 256)
#: Rays are the mean of this many sub-rays spread over their wedge.
SUB_RAYS = 3
#: The outline is sought between these shares of the place's radius.
BAND_REL = (0.5, 1.55)
#: Radial sampling step: this share of the radius, at least MIN_STEP_PX.
RADIAL_STEP_REL = 1.0 / 160.0
MIN_STEP_PX = 0.25
#: Largest change of the outline's radius between rays, in radii per radian (tan 60°: a
#: hexagon's outline changes by tan 30°, a square's by tan 45°, at their corners).
MAX_SLOPE = 1.75
#: The light inside and outside the step: over SIDE_REL of the radius (at least SIDE_MIN_PX),
#: beginning GAP_REL of the radius (at least GAP_MIN_PX) from it, clear of the blurred edge.
SIDE_REL = 0.15
SIDE_MIN_PX = 3.0
GAP_REL = 0.06
GAP_MIN_PX = 1.5
#: A ray's step must stand this many of its noise's standard deviations out ...
MIN_STEP_SIGMA = 3.0
#: ... and lie within these ratios of the median step (another light's edge, an occluder's, steps
#: by another amount).
STEP_RATIO = (0.1, 3.0)
#: A ray whose light just outside the step lies this share of the disc's contrast below the light a
#: side's width farther out steps onto something dark in front of the disc (a branch), not its ground.
OCCLUDER_DROP = 0.5
#: The seen edge points are fitted by a smooth closed curve of this order (half of it under 96 rays);
#: points farther than OFF_CURVE_REL of the radius (at least OFF_CURVE_PX) from it are another edge.
FOURIER_ORDER = 12
OFF_CURVE_REL = 0.04
OFF_CURVE_PX = 1.5
CURVE_STIFFNESS = 1e-6
#: The width of the fall across the edge (the step over the steepest slope) may be at most this share of
#: the distance between the step's two sides: a disc's edge, of a blur width, is well under it; a
#: glow's or a cone's fall, a ramp across the whole distance, is 0.8 to 1.
MAX_RAMP_SHARE = 0.85
#: The light within RISE_CORE of the way out may exceed the light just inside the step by at most
#: MAX_RISE steps: a plateau (0), a rim (below 0) or a bright centre do; a Gaussian glow rises about 1.5
#: steps, a cone 1.3 to 3. (A person's labelled discs of the reference photos: 9 in 10 under 0.7.)
RISE_CORE = 0.3
MAX_RISE = 1.0
#: A ray's plateau is the light between this share of the way out and the step.
PLATEAU_FROM = 0.35
#: Least share of the rays that must show the disc's edge for there to be an outline at all.
MIN_SEEN = 0.35
#: Gaussian smoothing of the crop before sampling (px): this share of the radius, within bounds.
SMOOTH_REL = 0.015
SMOOTH_PX = (0.6, 3.0)


def _polar(crop: np.ndarray, centre_rc: tuple[float, float], rays: int, radii: np.ndarray):
    """Wedge-mean samples of ``crop`` along ``rays`` rays at ``radii`` (rays × radii), and which
    samples lie inside the crop."""
    angles = 2.0 * np.pi * (np.arange(rays * SUB_RAYS) + 0.5 - SUB_RAYS / 2.0) / (rays * SUB_RAYS)
    xs = (centre_rc[1] + np.cos(angles)[:, None] * radii[None, :]).astype(np.float32)
    ys = (centre_rc[0] + np.sin(angles)[:, None] * radii[None, :]).astype(np.float32)
    samples = cv2.remap(np.ascontiguousarray(crop, np.float32), xs, ys, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    inside = (xs >= 0) & (ys >= 0) & (xs <= crop.shape[1] - 1) & (ys <= crop.shape[0] - 1)
    samples = samples.reshape(rays, SUB_RAYS, -1).mean(axis=1)
    inside = inside.reshape(rays, SUB_RAYS, -1).all(axis=1)
    return samples, inside, angles.reshape(rays, SUB_RAYS).mean(axis=1)


def _closed_path(strength: np.ndarray, reach: int) -> np.ndarray:
    """Per ray, the radial index of the closed path of greatest total ``strength`` (rays × radii)
    whose index changes by at most ``reach`` from ray to ray: dynamic programming over three
    turns, the middle one kept."""
    rays, count = strength.shape
    window = np.ones((1, 2 * reach + 1), np.uint8)  # the best of the previous ray within ``reach``: a dilation
    total = np.empty((3 * rays, count), np.float64)
    total[0] = strength[0]
    for i in range(1, 3 * rays):
        total[i] = strength[i % rays] + cv2.dilate(total[i - 1 : i], window, borderType=cv2.BORDER_CONSTANT,
                                                   borderValue=-np.inf)[0]
    path = np.empty(3 * rays, np.int64)
    path[-1] = int(np.argmax(total[-1]))
    for i in range(3 * rays - 2, rays - 1, -1):  # back to the middle turn, the one kept
        j0 = max(0, path[i + 1] - reach)
        path[i] = j0 + int(np.argmax(total[i, j0 : path[i + 1] + reach + 1]))
    return path[rays : 2 * rays]


class _Rays:
    """The light along the rays around a centre, and the steps of the edge measured on them."""

    def __init__(self, crop, centre_rc, radius, noise, farthest):
        self.count = int(np.clip(round(2.0 * math.pi * radius / 3.0), *RAYS))
        self.step = max(MIN_STEP_PX, RADIAL_STEP_REL * radius)
        self.gap = max(1, int(round(max(GAP_MIN_PX, GAP_REL * radius) / self.step)))
        self.side = max(1, int(round(max(SIDE_MIN_PX, SIDE_REL * radius) / self.step)))
        reach = farthest + (self.gap + 2 * self.side + 2) * self.step
        self.radii = np.arange(0.0, reach, self.step)
        self.profile, self.inside, self.angles = _polar(crop, centre_rc, self.count, self.radii)
        self.slope = ndimage.gaussian_filter1d(self.profile, max(1.0, 1.0 / self.step), axis=1, order=1) / self.step
        self.noise = noise

    def levels(self, rays: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The light just inside and just outside radial index ``at[i]`` of ray ``rays[i]`` (medians over the
        sides), the light a side's width farther out, and whether the sides lie in the frame, as arrays over
        the rays given; NaNs and False where a side is empty."""
        rays, at = np.asarray(rays, np.int64), np.asarray(at, np.int64)
        lo, hi = at - self.gap - self.side, at + self.gap + self.side
        valid = (lo >= 0) & (hi < len(self.radii))
        inner, outer, beyond = (np.full(len(rays), math.nan) for _ in range(3))
        width = np.arange(self.side + 1)

        def medians(which: np.ndarray, start: np.ndarray) -> np.ndarray:  # over side + 1 samples from ``start``
            return np.median(self.profile[rays[which][:, None], start[which][:, None] + width], axis=1)

        inner[valid], outer[valid] = medians(valid, lo), medians(valid, at + self.gap)
        whole = valid & (hi + self.side < len(self.radii))
        beyond[whole] = medians(whole, hi)
        for i in np.nonzero(valid & ~whole)[0]:  # the farther side cut by the rays' end
            beyond[i] = float(_median(self.profile[rays[i], hi[i] :]))
        outside = np.cumsum(~self.inside[rays], axis=1)  # rays[i]'s samples out of the frame, up to each radius
        last = outside[np.arange(len(rays)), np.clip(hi, 0, len(self.radii) - 1)]
        first = np.where(lo > 0, outside[np.arange(len(rays)), np.clip(lo - 1, 0, len(self.radii) - 1)], 0)
        return inner, outer, beyond, valid & (last == first)

    def sigma(self, at: np.ndarray) -> np.ndarray:
        """The noise of a step at each radial index of ``at``: the pixel noise over the pixels each side
        averages (its length by the wedge's width)."""
        pixels = self.side * self.step * np.maximum(self.radii[at] * 2.0 * math.pi / self.count, 1.0)
        return self.noise * np.sqrt(2.0 / np.maximum(pixels, 1.0))

    def plateaus(self, rays: np.ndarray, at: np.ndarray) -> np.ndarray:
        """The light of each ray ``rays[i]`` inside radial index ``at[i]``, from PLATEAU_FROM of the way out to
        the step's inner side (median): a disc's plateau or rim, where a glow or a cone keeps rising inwards."""
        lo = (PLATEAU_FROM * np.asarray(at)).astype(np.int64)
        return _row_medians(self.profile, rays, lo, np.maximum(lo + 1, np.asarray(at) - self.gap + 1)).astype(np.float64)

    def crossings(self, rays: np.ndarray, at: np.ndarray, levels: np.ndarray) -> np.ndarray:
        """The radius where each ray ``rays[i]`` falls through ``levels[i]`` nearest radial index ``at[i]``
        (linear interpolation), within the step's sides; NaN where it does not. The levels' type
        is the arithmetic's: float64, or float32, the profile's own."""
        rays, at = np.asarray(rays, np.int64), np.asarray(at, np.int64)
        reach = self.gap + self.side // 2
        lo = np.maximum(0, at - reach)
        hi = np.minimum(len(self.radii) - 1, at + reach)
        index = lo[:, None] + np.arange(2 * reach + 1)
        p = self.profile[rays[:, None], np.minimum(index, len(self.radii) - 1)]
        above = p >= levels[:, None]
        falls = above[:, :-1] & ~above[:, 1:] & (index[:, 1:] <= hi[:, None])
        # the fall nearest the index, the first of equals
        c = np.argmin(np.where(falls, np.abs(index[:, :-1] - at[:, None]), np.iinfo(np.int64).max), axis=1)
        each = np.arange(len(rays))
        found = falls[each, c]
        p_c, p_next = p[each, c], p[each, c + 1]
        drop = np.maximum((p_c - p_next).astype(np.float64), 1e-12).astype(levels.dtype)
        t = (p_c - levels) / drop
        radii = self.radii[lo + c] + t * levels.dtype.type(self.step)
        return np.where(found, radii, np.nan)


def _smooth_curve(angles: np.ndarray, edge: np.ndarray, seen: np.ndarray, radius: float):
    """A smooth closed curve ρ(θ) fitted robustly to the seen edge points, and which of them lie on
    it: within OFF_CURVE_REL of the radius (at least OFF_CURVE_PX, and three robust deviations of the
    points about it). The curve is a Fourier series of FOURIER_ORDER whose k-th terms are damped by
    CURVE_STIFFNESS · k⁴ (a smoothing spline around the turn): across a gap in the seen points it
    bends as little as it can, instead of swinging."""
    order = FOURIER_ORDER
    terms = [np.ones_like(angles)] + [f(k * angles) for k in range(1, order + 1) for f in (np.cos, np.sin)]
    design = np.column_stack(terms)
    damping = CURVE_STIFFNESS * np.concatenate([[0.0], np.repeat(np.arange(1, order + 1, dtype=np.float64) ** 4, 2)])
    on = seen.copy()
    curve = np.full_like(edge, float(np.median(edge[seen])))
    tolerance = max(OFF_CURVE_PX, OFF_CURVE_REL * radius)
    for _ in range(3):
        if on.sum() < 8:
            break
        a = design[on]
        coefficients = np.linalg.solve(a.T @ a + on.sum() * np.diag(damping), a.T @ edge[on])
        curve = design @ coefficients
        residual = edge - curve
        spread = 1.4826 * float(np.median(np.abs(residual[on] - np.median(residual[on]))))
        tolerance = max(OFF_CURVE_PX, OFF_CURVE_REL * radius, 3.0 * spread)
        on = seen & (np.abs(residual) <= tolerance)
    return curve, on, tolerance


def _fill(angles: np.ndarray, edge: np.ndarray, on: np.ndarray) -> np.ndarray:
    """``edge`` where ``on``, elsewhere interpolated around the turn between the nearest points on."""
    order = np.nonzero(on)[0]
    turn = np.concatenate([angles[order] - 2 * math.pi, angles[order], angles[order] + 2 * math.pi])
    return np.where(on, edge, np.interp(angles, turn, np.tile(edge[order], 3)))


def _trace(crop, centre_rc, radius, noise, band_px) -> tuple[np.ndarray, np.ndarray, Levels] | NoDisc:
    """One pass: the outline (x, y in the crop) with its seen rays, and the levels; or why there is none. The
    edge is sought between the radii ``band_px`` (least, most)."""
    rays = _Rays(crop, centre_rc, radius, noise, band_px[1])
    strength = np.maximum(-rays.slope, 0.0)
    strength = ndimage.gaussian_filter1d(strength, 1.0, axis=0, mode="wrap")
    band = (rays.radii >= band_px[0]) & (rays.radii <= band_px[1])
    strength[:, ~band] = 0.0
    strength[~rays.inside] = 0.0  # the frame's edge is no step of the disc's
    reach = max(1, math.ceil(MAX_SLOPE * radius * 2.0 * math.pi / rays.count / rays.step))
    path = _closed_path(strength, reach)
    inner, outer, beyond, framed = rays.levels(np.arange(rays.count), path)
    steps = inner - outer
    sigma = rays.sigma(path)
    positive = framed & (steps > MIN_STEP_SIGMA * sigma)
    if positive.mean() < MIN_SEEN:
        return NoDisc(Reason.FAINT)
    typical = float(np.median(steps[positive]))

    def shows_edge(step, outside, farther, sigma_k) -> np.ndarray:
        # The disc's own step: significant, of about its contrast, and onto its ground or other light
        # over it (light adds), not onto something darker in front of it, beyond which the light
        # comes back (an occluder's edge). Over arrays of rays.
        return ((step > MIN_STEP_SIGMA * sigma_k) & (STEP_RATIO[0] * typical <= step) & (step <= STEP_RATIO[1] * typical)
                & ~(outside < farther - OCCLUDER_DROP * typical))

    edge = rays.radii[path].astype(np.float64)
    shown = np.nonzero(positive)[0]
    shown = shown[shows_edge(steps[shown], outer[shown], beyond[shown], sigma[shown])]
    where = rays.crossings(shown, path[shown], outer[shown] + 0.5 * steps[shown])
    seen = np.zeros(rays.count, bool)
    seen[shown] = ~np.isnan(where)
    edge[seen] = where[~np.isnan(where)]
    if seen.mean() < MIN_SEEN:
        return NoDisc(Reason.NO_OUTLINE)
    curve, on, tolerance = _smooth_curve(rays.angles, edge, seen, radius)
    # Rays off the curve (a neighbour's edge, an occluder's) or not seen: the disc's edge is looked for
    # again near the curve, where the path did not go.
    near = tolerance / rays.step
    again, at = [], []  # the rays looked at again, and the steepest fall near the curve on each
    for k in np.nonzero(~on)[0]:
        centre_j = curve[k] / rays.step
        j0, j1 = max(0, int(centre_j - near)), min(len(rays.radii) - 1, int(centre_j + near) + 1)
        if j1 > j0:
            again.append(k)
            at.append(j0 + int(np.argmin(rays.slope[k, j0 : j1 + 1])))
    again, at = np.array(again, np.int64), np.array(at, np.int64)
    inside_a, outside_a, beyond_a, framed_a = rays.levels(again, at)
    shown = framed_a & shows_edge(inside_a - outside_a, outside_a, beyond_a, rays.sigma(at))
    # The levels as float32, the profile's: the crossings are taken in its arithmetic here.
    where = rays.crossings(again[shown], at[shown], (outside_a + 0.5 * (inside_a - outside_a))[shown].astype(np.float32))
    back = np.abs(where - curve[again[shown]]) <= near * rays.step  # False where there is no crossing (NaN)
    back_rays = again[shown][back]
    edge[back_rays], on[back_rays], outer[back_rays] = where[back], True, outside_a[shown][back]
    if on.mean() < MIN_SEEN:
        return NoDisc(Reason.NO_OUTLINE)
    # A step, not a ramp or a glow: the light falls across the edge within a share of the distance
    # between the step's two sides, and inside it is a plateau or a rim, not a rise to a peak.
    at = np.clip(np.round(edge / rays.step).astype(int), 1, len(rays.radii) - 2)
    ks = np.nonzero(on)[0]
    at_k = at[ks]
    near_inside = _row_medians(rays.profile, ks, np.maximum(0, at_k - rays.gap - rays.side), at_k - rays.gap + 1).astype(np.float64)
    step_k = np.maximum(near_inside - outer[ks], 1e-12)
    span = 2 * rays.gap + 1  # the steepest slope within the gap of the edge
    slopes = rays.slope[ks[:, None], np.clip(at_k[:, None] - rays.gap + np.arange(span), 0, len(rays.radii) - 1)]
    steepest = slopes.min(axis=1).astype(np.float64)
    falls = step_k / np.maximum(-steepest, 1e-12)
    core = _row_medians(rays.profile, ks, np.zeros_like(ks), np.maximum(1, (RISE_CORE * at_k).astype(np.int64))).astype(np.float64)
    rises = (core - near_inside) / step_k
    if float(np.median(falls)) > MAX_RAMP_SHARE * (2 * rays.gap + rays.side) * rays.step or float(np.median(rises)) > MAX_RISE:
        return NoDisc(Reason.SOFT_EDGE)
    edge = _fill(rays.angles, edge, on)
    outline = np.column_stack([centre_rc[1] + edge * np.cos(rays.angles), centre_rc[0] + edge * np.sin(rays.angles)])
    background = float(np.median(outer[on]))
    lift = background - float(np.percentile(outer[on], 10))
    # The disc's contrast, for its tests (the edge's width among them): its plateau over the ground, not
    # the step's two sides alone (a glow's local step is as steep as a disc's; its rise inwards is not).
    contrast = float(np.median(rays.plateaus(ks, at_k) - outer[ks]))
    return outline, on, Levels(background, background + max(contrast, typical), noise, lift)


def measure_rays(
    luminance: np.ndarray,
    clipped_mask: np.ndarray | None,
    center_xy: tuple[float, float],
    diameter_px: float,
    min_noise: float,
    min_diameter_px: float,
    band_px: tuple[float, float] | None = None,
) -> Measurement | NoDisc:
    """Measure the disc of about ``diameter_px`` around ``center_xy`` by the step of its edge along
    rays (the module's Notes); a :class:`~bokehfit.discs.reasons.NoDisc` where no outline of a disc is there.

    The edge is sought between the radii ``band_px`` (least, most: px from the centre), where the size is known
    that well (a person's reading of it); by default between BAND_REL of each pass's radius.
    Two passes: the second from the first's centre and size. The outline points of rays that do not
    show the disc's own edge are marked not seen (``outline_reliable``); the measurement's tests of a
    disc are :func:`bokehfit.discs.measure.describe`'s, with the crop's pixel noise as its noise.
    """
    height, width = luminance.shape
    radius = max(1.0, 0.5 * float(diameter_px))
    found = None
    for _ in range(2):
        band = band_px if band_px is not None else (BAND_REL[0] * radius, BAND_REL[1] * radius)
        margin = band[1] + max(GAP_MIN_PX, GAP_REL * radius) + max(SIDE_MIN_PX, SIDE_REL * radius) + 3.0
        col, row = center_xy
        r0, c0 = max(0, int(math.floor(row - margin))), max(0, int(math.floor(col - margin)))
        r1, c1 = min(height, int(math.ceil(row + margin)) + 1), min(width, int(math.ceil(col + margin)) + 1)
        if r1 - r0 < 3 or c1 - c0 < 3 or not (0 <= col < width and 0 <= row < height):
            return NoDisc(Reason.OUTSIDE_PHOTO)
        raw = luminance[r0:r1, c0:c1]
        noise = max(pixel_noise(raw), min_noise)
        smooth = float(np.clip(SMOOTH_REL * radius, *SMOOTH_PX))
        crop = cv2.GaussianBlur(np.ascontiguousarray(raw, np.float32), (0, 0), smooth, borderType=cv2.BORDER_REPLICATE)
        traced = _trace(crop, (row - r0, col - c0), radius, noise, band)
        if isinstance(traced, NoDisc):
            return traced
        outline, seen, levels = traced
        found = Outlined(Window(r0, c0, r1, c1), crop, levels, outline, False, None, ~seen,
                         smoothing_px=smooth, pixel_noise=noise)
        area, cx, cy = polygon_area_centroid(outline)
        if area <= 0:
            return NoDisc(Reason.NO_OUTLINE)
        if math.hypot(cx + c0 - col, cy + r0 - row) > 0.5 * radius:
            break  # the outline is not around the place: the first pass's is judged
        center_xy, radius = (cx + c0, cy + r0), max(1.0, math.sqrt(area / math.pi))
    return replace(describe(luminance, clipped_mask, found, min_noise, min_diameter_px), own_step=True)
