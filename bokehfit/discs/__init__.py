"""Find bokeh discs in a linear-light luminance image.

:func:`find_discs` finds bright blobs above the local background
(:mod:`bokehfit.discs.candidates`), measures each with a sub-pixel 50 %
outline and keeps those that look like discs (:mod:`bokehfit.discs.measure`
states the criteria). The result is a :class:`DiscSearch`, falsy with a
``reason`` when no disc was found.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.spatial import cKDTree

from bokehfit.discs.candidates import Candidate, find_candidates
from bokehfit.discs.measure import RESOLVABLE_PX, Measurement, measure_candidate
from bokehfit.errors import InputError

__all__ = ["Disc", "DiscSearch", "find_discs", "DEFAULT_MIN_DIAMETER_PX", "DEFAULT_MAX_DIAMETER_PX"]

DEFAULT_MIN_DIAMETER_PX = 4.0
DEFAULT_MAX_DIAMETER_PX = 500.0
#: Most candidates measured (the strongest first); the rest are counted as rejected.
MAX_CANDIDATES = 5000
#: Noise floor of the local noise estimate (linear units).
MIN_NOISE = 1e-4


@dataclass(frozen=True)
class Disc:
    """A bokeh disc found in a photo (design.md §7 names; coordinates (x, y) = (column, row))."""

    index: int
    center_xy: tuple[float, float]
    diameter_px: float
    outline_xy: np.ndarray
    plateau: float
    background: float
    snr: float
    saturated: bool
    clipped: bool
    overlaps: bool
    resolvable: bool

    @property
    def usable(self) -> bool:
        """Clean enough to fit a shape to: resolvable, not saturated, clipped or overlapping."""
        return self.resolvable and not (self.saturated or self.clipped or self.overlaps)

    def to_json(self, outline: bool = True) -> dict:
        data = {
            "index": self.index,
            "center_xy": [round(float(self.center_xy[0]), 3), round(float(self.center_xy[1]), 3)],
            "diameter_px": round(float(self.diameter_px), 3),
            "angle_deg": None,
            "iou": None,
            "hausdorff_rel": None,
            "saturated": bool(self.saturated),
            "clipped": bool(self.clipped),
            "overlaps": bool(self.overlaps),
            "resolvable": bool(self.resolvable),
            "used": bool(self.usable),
            "plateau": float(self.plateau),
            "background": float(self.background),
            "snr": round(float(self.snr), 2),
        }
        if outline:
            data["outline_xy"] = np.round(self.outline_xy, 3).tolist()
        return data


@dataclass(frozen=True)
class DiscSearch:
    """What :func:`find_discs` found; falsy (with ``reason``) when no disc was found."""

    discs: list[Disc]
    candidates: int
    rejected: Counter = field(default_factory=Counter)
    time_s: float = 0.0

    def __bool__(self) -> bool:
        return bool(self.discs)

    def __len__(self) -> int:
        return len(self.discs)

    @property
    def reason(self) -> str:
        """Why nothing was found (empty when discs were found)."""
        if self.discs:
            return ""
        if not self.candidates:
            return "no highlight stands out from the background"
        why = ", ".join(f"{n} {reason}" for reason, n in self.rejected.most_common())
        return f"no disc among {self.candidates} highlight candidates ({why})"


def _check_image(luminance) -> np.ndarray:
    luminance = np.asarray(luminance)
    if luminance.ndim != 2:
        raise InputError(f"luminance must be a 2-D array (got shape {luminance.shape})")
    if luminance.dtype != np.float32:
        luminance = luminance.astype(np.float32)
    if not np.isfinite(luminance).all():
        raise InputError("luminance contains NaN or Inf values")
    return luminance


def _distinct(candidates: list[Candidate]) -> list[Candidate]:
    """Strongest first; drop a candidate that repeats a stronger one (same place, similar size)."""
    kept: list[Candidate] = []
    if not candidates:
        return kept
    order = sorted(candidates, key=lambda c: -c.strength)
    centres = np.array([c.center_xy for c in order])
    tree = cKDTree(centres)
    taken = np.zeros(len(order), dtype=bool)
    for i, c in enumerate(order):
        if taken[i]:
            continue
        kept.append(c)
        for j in tree.query_ball_point(c.center_xy, 0.5 * c.diameter_px + 1.0):
            if 0.4 <= order[j].diameter_px / c.diameter_px <= 2.5:
                taken[j] = True
    return kept


def _inside_any(point: tuple[float, float], measurements: list[Measurement]) -> bool:
    x, y = point
    for m in measurements:
        outline = m.outline_xy
        if (outline[:, 0].min() <= x <= outline[:, 0].max() and outline[:, 1].min() <= y <= outline[:, 1].max()
                and cv2.pointPolygonTest(outline.astype(np.float32), (float(x), float(y)), False) >= 0):
            return True
    return False


def _flag_neighbours(measurements: list[Measurement]) -> list[bool]:
    """True for discs whose outline reaches into another disc's extent."""
    if len(measurements) < 2:
        return [m.overlaps for m in measurements]
    centres = np.array([m.center_xy for m in measurements])
    reach = np.array([np.max(np.hypot(*(m.outline_xy - m.center_xy).T)) for m in measurements])
    tree = cKDTree(centres)
    flags = []
    for i, m in enumerate(measurements):
        near = tree.query_ball_point(m.center_xy, reach[i] + reach.max())
        touching = any(j != i and np.hypot(*(centres[j] - centres[i])) < reach[i] + reach[j] for j in near)
        flags.append(m.overlaps or touching)
    return flags


def find_discs(
    luminance: np.ndarray,
    clipped: np.ndarray | None = None,
    *,
    min_diameter_px: float = DEFAULT_MIN_DIAMETER_PX,
    max_diameter_px: float = DEFAULT_MAX_DIAMETER_PX,
    max_discs: int | None = None,
    progress: bool = False,
) -> DiscSearch:
    """Find the bokeh discs of a linear-light image.

    Parameters
    ----------
    luminance : ndarray of shape (M, N), float32
        Linear light (1.0 = white).
    clipped : ndarray of shape (M, N), bool, optional
        Pixels clipped in the source; discs containing them are flagged ``saturated``.
    min_diameter_px, max_diameter_px : float
        Range of equal-area diameters sought.
    max_discs : int, optional
        Keep the largest ``max_discs`` discs.
    progress : bool
        Show a progress bar while measuring many candidates.

    Returns
    -------
    DiscSearch
        Discs sorted by diameter, largest first; falsy with ``reason`` if none.
    """
    start = time.perf_counter()
    luminance = _check_image(luminance)
    if not 1.0 <= min_diameter_px < max_diameter_px:
        raise InputError(
            f"min_diameter_px must be at least 1 and below max_diameter_px (got {min_diameter_px}, {max_diameter_px})"
        )
    if max_discs is not None and max_discs < 1:
        raise InputError(f"max_discs must be at least 1 (got {max_discs})")
    candidates = _distinct(find_candidates(luminance, min_diameter_px, max_diameter_px))
    rejected: Counter = Counter()
    if len(candidates) > MAX_CANDIDATES:
        rejected["beyond the candidate limit"] = len(candidates) - MAX_CANDIDATES
        candidates = candidates[:MAX_CANDIDATES]
    candidates.sort(key=lambda c: -c.diameter_px)  # a larger disc claims the candidates inside it
    iterator = candidates
    if progress and len(candidates) > 200:
        from tqdm import tqdm

        iterator = tqdm(candidates, desc="measuring discs", unit="candidate", leave=False)
    measurements: list[Measurement] = []
    for candidate in iterator:
        if _inside_any(candidate.center_xy, measurements):
            rejected["inside a larger disc"] += 1
            continue
        m = measure_candidate(
            luminance, clipped, candidate.center_xy, candidate.diameter_px, candidate.extent_px, MIN_NOISE, min_diameter_px
        )
        if isinstance(m, str):
            rejected[m] += 1
        elif m.reason is not None:
            rejected[m.reason] += 1
        elif m.diameter_px > max_diameter_px:
            rejected["too large"] += 1
        else:
            measurements.append(m)
    measurements = _distinct_measurements(measurements)
    measurements.sort(key=lambda m: -m.diameter_px)
    if max_discs is not None:
        measurements = measurements[:max_discs]
    overlaps = _flag_neighbours(measurements)
    discs = [
        Disc(
            index=i,
            center_xy=m.center_xy,
            diameter_px=m.diameter_px,
            outline_xy=m.outline_xy,
            plateau=m.plateau,
            background=m.background,
            snr=m.snr,
            saturated=m.saturated,
            clipped=m.clipped,
            overlaps=overlap,
            resolvable=m.diameter_px >= RESOLVABLE_PX,
        )
        for i, (m, overlap) in enumerate(zip(measurements, overlaps))
    ]
    return DiscSearch(discs, len(candidates), +rejected, time.perf_counter() - start)


def _distinct_measurements(measurements: list[Measurement]) -> list[Measurement]:
    """One measurement per disc: two candidates that converged on the same outline count once."""
    kept: list[Measurement] = []
    for m in sorted(measurements, key=lambda m: -m.snr):
        if not any(
            math.hypot(m.center_xy[0] - k.center_xy[0], m.center_xy[1] - k.center_xy[1]) < 0.25 * k.diameter_px
            and 0.75 < m.diameter_px / k.diameter_px < 1.33
            for k in kept
        ):
            kept.append(m)
    return kept
