"""Find bokeh discs in a linear-light luminance image.

:func:`find_discs` finds bright blobs above the local background
(:mod:`bokehfit.discs.candidates`), measures each with a sub-pixel 50 %
outline and keeps those that look like discs (:mod:`bokehfit.discs.measure`
states the criteria). The result is a :class:`DiscSearch`, falsy with a
``reason`` when no disc was found.
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from bokehfit.discs.candidates import find_candidates
from bokehfit.discs.measure import RESOLVABLE_PX, Measurement, measure_blob
from bokehfit.errors import InputError

__all__ = ["Disc", "DiscSearch", "find_discs", "DEFAULT_MIN_DIAMETER_PX", "DEFAULT_MAX_DIAMETER_PX"]

DEFAULT_MIN_DIAMETER_PX = 4.0
DEFAULT_MAX_DIAMETER_PX = 500.0
#: Blobs smaller than this share of the smallest disc's area are not measured at all.
_MIN_BLOB_SHARE = 0.3


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
            "center_xy": [round(self.center_xy[0], 3), round(self.center_xy[1], 3)],
            "diameter_px": round(self.diameter_px, 3),
            "angle_deg": None,
            "iou": None,
            "hausdorff_rel": None,
            "saturated": self.saturated,
            "clipped": self.clipped,
            "overlaps": self.overlaps,
            "resolvable": self.resolvable,
            "used": self.usable,
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
    noise_sigma: float = 0.0
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
    found = find_candidates(luminance, max_diameter_px)
    min_blob_area = _MIN_BLOB_SHARE * np.pi * (min_diameter_px / 2.0) ** 2
    labels = [k for k in range(1, len(found.stats)) if found.stats[k, 4] >= min_blob_area]
    rejected: Counter = Counter()
    rejected["too small"] += len(found.stats) - 1 - len(labels)
    measurements: list[Measurement] = []
    iterator = labels
    if progress and len(labels) > 200:
        from tqdm import tqdm

        iterator = tqdm(labels, desc="measuring discs", unit="blob", leave=False)
    for label in iterator:
        left, top, width, height, _ = found.stats[label]
        m = measure_blob(luminance, clipped, found.labels, label, (left, top, width, height), found.noise_sigma, min_diameter_px)
        if m is None:
            rejected["no closed outline"] += 1
        elif m.reason is not None:
            rejected[m.reason] += 1
        elif m.diameter_px > max_diameter_px:
            rejected["too large"] += 1
        else:
            measurements.append(m)
    measurements.sort(key=lambda m: -m.diameter_px)
    if max_discs is not None:
        measurements = measurements[:max_discs]
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
            overlaps=m.overlaps,
            resolvable=m.diameter_px >= RESOLVABLE_PX,
        )
        for i, m in enumerate(measurements)
    ]
    return DiscSearch(discs, len(found.stats) - 1, +rejected, found.noise_sigma, time.perf_counter() - start)
