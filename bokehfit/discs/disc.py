"""What a disc search gives, what it takes, and how its measurements become its discs.

The types of the result: a :class:`Disc` (what it offers as evidence of the aperture's shape, and
whether the fit can use it), a :class:`Rejection` (a measured candidate that is not a disc, and why)
and the :class:`DiscSearch` that holds them. The checks of the searches' inputs (the image and the
limits), shared by :func:`bokehfit.discs.find_discs` and :func:`bokehfit.discs.measure_discs_at`.
And the making of the result from the measurements (:func:`_discs_of`): one measurement per disc,
each disc's own share of its outline where discs overlap, their clusters, and their evidence.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import dataclass, field, replace

import cv2
import numpy as np
from scipy.spatial import cKDTree

from bokehfit.clock import Clock
from bokehfit.discs.measure import RESOLVABLE_PX, Measurement
from bokehfit.discs.reasons import NoDisc, Reason
from bokehfit.errors import InputError, check_finite

#: Two measurements are of one disc when their centres lie within this share of the diameter and
#: the ratio of their sizes within these bounds.
SAME_DISC_CENTRE_REL = 0.25
SAME_DISC_SIZE_RATIOS = (0.75, 1.33)
#: A disc whose reliable share of the outline reaches this is seen whole (a stray point or two
#: near a frame corner or a pixel of bloom do not make it partial).
FULL_OUTLINE_SEEN = 0.98
#: What a usable disc offers (:attr:`Disc.evidence`), best first.
USABLE_EVIDENCE = ("plateau", "edge", "partial")
#: Least share of its outline a disc must show to say something about the shape ...
MIN_OUTLINE_SEEN = 0.5
#: ... and to be fitted (the rest of its crop, another light's, is left out of the fit).
MIN_FIT_SEEN = 0.75
#: Outline points closer than this (px) inside another disc's outline belong to the overlap.
OVERLAP_MARGIN_PX = 1.5
#: Smallest image searched, in pixels a side: a disc needs a surround to be told from the background.
MIN_IMAGE_SIDE_PX = 8
#: Largest luminance accepted (linear light, 1.0 = white). Highlights of real photos stay far
#: below it; squares of larger values overflow float32 in the fit.
MAX_LUMINANCE = 1e6


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
    #: What the disc offers: "plateau" (clean), "edge" (the outline only: saturated, a ring or a bright centre),
    #: "partial" (part of the outline: cut, occluded, overlapping or joined by bloom).
    evidence: str = "plateau"
    #: Share of the outline that is the disc's own and reliable, 0–1.
    outline_seen: float = 1.0
    #: Per point of ``outline_xy``: True where the outline is the disc's own and reliable.
    outline_reliable: np.ndarray | None = None
    #: Shared by discs whose outlines overlap; None for a disc on its own.
    cluster: int | None = None
    ring: bool = False  #: rim brighter than the centre (soap-bubble disc)
    bright_centre: bool = False  #: centre brighter than the rim, the edge a step below it (rim < 0)
    occluded: bool = False  #: crossed by a thin occluder (bridged, outline there not seen)
    clipped_share: float = 0.0  #: share of the disc's area clipped in the source
    #: Its edge is wider than a sharp disc's (:func:`bokehfit.discs.verdict.soft_edged`): a disc whose light
    #: falls from a bright centre, or a glow as soft; second-tier evidence, fitted only beside sharp discs.
    soft_edge: bool = False

    @property
    def usable(self) -> bool:
        """The fit can use it: resolvable, not cut by the frame, and at least MIN_FIT_SEEN of its outline
        its own: a clean plateau, an outline of its own (``edge``: a saturated disc, fitted with its clipped
        pixels as lower bounds, a ring or a bright centre, fitted with the rim profile), or one seen in part
        (``partial``: overlapping others, whose light is left out of its fit, or crossed by an occluder,
        whose pixels are)."""
        return (self.resolvable and self.evidence in USABLE_EVIDENCE and not self.clipped
                and self.outline_seen >= MIN_FIT_SEEN)

    @property
    def profiled(self) -> bool:
        """Its light is not spread evenly over the aperture: a ring or a bright centre (a rim, §3b)."""
        return self.ring or self.bright_centre

    @property
    def shape_usable(self) -> bool:
        """Its outline says something about the shape: resolvable and at least MIN_OUTLINE_SEEN of it seen."""
        return self.resolvable and self.outline_seen >= MIN_OUTLINE_SEEN

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
            "usable": bool(self.usable),
            "plateau": float(self.plateau),
            "background": float(self.background),
            "snr": round(float(self.snr), 2),
            "evidence": self.evidence,
            "outline_seen": round(float(self.outline_seen), 3),
            "cluster": self.cluster,
            "ring": bool(self.ring),
            "bright_centre": bool(self.bright_centre),
            "occluded": bool(self.occluded),
            "clipped_share": round(float(self.clipped_share), 4),
            "soft_edge": bool(self.soft_edge),
        }
        if outline:
            data["outline_xy"] = np.round(self.outline_xy, 3).tolist()
            if self.outline_reliable is not None:
                data["outline_reliable"] = [bool(v) for v in self.outline_reliable]
        return data


@dataclass(frozen=True)
class Rejection:
    """A measured candidate that is not a disc, and why: ``rejected_because`` is the reason in words
    (a :class:`~bokehfit.discs.reasons.Reason`'s, or a :class:`~bokehfit.discs.reasons.NoDisc`'s
    detail with its numbers)."""

    center_xy: tuple[float, float]
    diameter_px: float
    rejected_because: str

    @classmethod
    def of(cls, center_xy: tuple[float, float], diameter_px: float, why: NoDisc | Reason) -> Rejection:
        """The rejection at ``center_xy`` of a candidate of ``diameter_px``, for ``why``."""
        return cls(center_xy, diameter_px, str(why))

    def to_json(self) -> dict:
        return {
            "center_xy": [round(float(self.center_xy[0]), 2), round(float(self.center_xy[1]), 2)],
            "diameter_px": round(float(self.diameter_px), 2),
            "rejected_because": self.rejected_because,
        }


@dataclass(frozen=True)
class DiscSearch:
    """What :func:`find_discs` found; falsy (with ``reason``) when no disc was found."""

    discs: list[Disc]
    candidates: int
    #: How many candidates were not kept, by the reason in words (a :class:`Rejection`'s ``rejected_because``).
    rejected: Counter = field(default_factory=Counter)
    time_s: float = 0.0
    #: One line each, for people: limits reached (``"30976 candidates found, the 2000 clearest measured"``).
    notes: tuple[str, ...] = ()
    #: Every measured candidate that was not kept, with its reason (those beyond the
    #: candidate limit are only counted).
    rejections: tuple[Rejection, ...] = ()
    #: The places were given (a person's discs, :func:`bokehfit.discs.measure_discs_at`), not searched for:
    #: each that is no disc is one the person asked about.
    given: bool = False
    #: Seconds (wall) of the search's steps, by name (:func:`bokehfit.discs.find_discs`'s: the candidates, their
    #: measurement, the circles through edges, the circles of the sizes found, the own steps, the result).
    timing_s: dict[str, float] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return bool(self.discs)

    def __len__(self) -> int:
        return len(self.discs)

    @property
    def reason(self) -> str:
        """Why nothing was found (empty when discs were found)."""
        if self.discs:
            return ""
        why = ", ".join(f"{n} {reason}" for reason, n in self.rejected.most_common())
        if self.given:
            return f"no disc at the {self.candidates} places given ({why})" if self.candidates else "no places given"
        if not self.candidates:
            return "no highlight stands out from the background"
        return f"no disc among {self.candidates} highlight candidates ({why})"


def _check_image(luminance) -> np.ndarray:
    """``luminance`` as a float32 (M, N) array, or ``InputError`` naming what is wrong."""
    try:
        array = np.asarray(luminance)
    except Exception:  # noqa: BLE001 - ragged lists and the like
        raise InputError("luminance must be a 2-D array of numbers (got an object NumPy cannot read)") from None
    if array.dtype == np.bool_ or array.dtype.kind not in "uif":
        raise InputError(f"luminance must be a 2-D array of real numbers (got dtype {array.dtype})")
    if array.ndim != 2:
        raise InputError(f"luminance must be a 2-D array (got shape {array.shape})")
    if min(array.shape) < MIN_IMAGE_SIDE_PX:
        raise InputError(
            f"luminance must be at least {MIN_IMAGE_SIDE_PX}×{MIN_IMAGE_SIDE_PX} pixels (got shape {array.shape})"
        )
    if array.dtype != np.float32:
        with np.errstate(over="ignore"):  # float64 beyond float32's range becomes inf: refused below
            array = array.astype(np.float32)
    # Reductions, not element-wise tests: no temporary the size of the image. NaN makes both NaN.
    low, high = float(array.min()), float(array.max())
    if not (math.isfinite(low) and math.isfinite(high)):
        raise InputError("luminance contains NaN or Inf values")
    peak = max(abs(low), abs(high))
    if peak > MAX_LUMINANCE:
        raise InputError(
            f"luminance reaches {peak:.3g}; find_discs expects linear light with 1.0 = white and values up to"
            f" {MAX_LUMINANCE:g}: scale the image"
        )
    return array


def _check_parameters(shape, clipped, min_diameter_px, max_diameter_px, max_discs) -> tuple:
    """Validated ``(clipped, min_diameter_px, max_diameter_px, max_discs)`` (module constants for limits)."""
    if clipped is not None:
        clipped = np.asarray(clipped)
        if clipped.shape != shape:
            raise InputError(f"clipped must have the shape of luminance {shape} (got {clipped.shape})")
        if clipped.dtype != np.bool_:
            if clipped.dtype.kind not in "uif":
                raise InputError(f"clipped must be a boolean array (got dtype {clipped.dtype})")
            clipped = clipped != 0
    min_diameter_px = check_finite("min_diameter_px", min_diameter_px)
    if min_diameter_px < 1.0:
        raise InputError(f"min_diameter_px must be at least 1 (got {min_diameter_px:g})")
    if isinstance(max_diameter_px, bool):
        raise InputError(f"max_diameter_px must be a number or inf (got {max_diameter_px!r})")
    try:
        max_diameter_px = float(max_diameter_px)
    except (TypeError, ValueError):
        raise InputError(f"max_diameter_px must be a number or inf (got {max_diameter_px!r})") from None
    if math.isnan(max_diameter_px) or max_diameter_px <= min_diameter_px:
        raise InputError(
            f"max_diameter_px must be above min_diameter_px ({min_diameter_px:g}), or inf for no limit"
            f" (got {max_diameter_px:g})"
        )
    if max_discs is not None:
        if isinstance(max_discs, bool) or not isinstance(max_discs, (int, np.integer)) or max_discs < 1:
            raise InputError(f"max_discs must be a whole number of at least 1 (got {max_discs!r})")
        max_discs = int(max_discs)
    return clipped, min_diameter_px, max_diameter_px, max_discs


def _discs_of(measurements, found, rejected, start, notes, rejections, max_discs, given: bool = False,
              soft=(), clock: Clock | None = None) -> DiscSearch:
    """The search's discs from its measurements: one per disc, largest first, each with what it offers (``given``:
    the places were a person's, :attr:`DiscSearch.given`). ``soft``: the soft-edged discs the search measured
    ((measurement, its rejection) each, :func:`bokehfit.discs.verdict.soft_edged`), kept as discs of the second
    tier where they lie clear of every sharp disc (:func:`_clear_of`): their rejections leave ``rejections`` and
    ``rejected``. The sharp discs are made from their own measurements alone, as without them. ``clock``: the
    search's steps timed so far (:attr:`DiscSearch.timing_s`), to which this one ("result") is added."""
    measurements = _distinct_measurements(measurements)
    measurements.sort(key=lambda m: -m.diameter_px)
    if max_discs is not None:
        measurements = measurements[:max_discs]
    discs = _made(measurements)
    kept = _clear_of(measurements, _distinct_measurements([m for m, _ in soft]))
    if kept:
        clusters = max((d.cluster for d in discs if d.cluster is not None), default=-1) + 1
        discs += _made(kept, clusters, soft_edge=True)
        discs.sort(key=lambda d: -d.diameter_px)  # stable: the sharp discs keep their order
        discs = [replace(d, index=i) for i, d in enumerate(discs)][:max_discs]
        # A soft disc's rejection leaves the lists, and so do those of its other measurements (the same disc).
        dropped = {id(r) for m, r in soft if any(_same_disc(m, k) for k in kept)}
        rejected = rejected.copy()
        for _, r in soft:
            if id(r) in dropped:
                rejected[r.rejected_because] -= 1
        rejections = [r for r in rejections if id(r) not in dropped]
    if clock is not None:
        clock("result")
    return DiscSearch(discs, found, +rejected, time.perf_counter() - start, tuple(notes), tuple(rejections), given,
                      dict(clock.timing) if clock is not None else {})


def _same_disc(m: Measurement, other: Measurement) -> bool:
    """Two measurements of one disc: centres within SAME_DISC_CENTRE_REL of the diameter, sizes alike (:func:`_same_size`)."""
    return m is other or (math.dist(m.center_xy, other.center_xy) <= SAME_DISC_CENTRE_REL * other.diameter_px
                          and _same_size(m.diameter_px, other.diameter_px))


def _made(measurements: list[Measurement], first_cluster: int = 0, soft_edge: bool = False) -> list[Disc]:
    """The discs of ``measurements`` (largest first), indexed in that order, each with its own share of its
    outline, its cluster (numbered from ``first_cluster``) and what it offers."""
    overlaps = _flag_neighbours(measurements)
    own, clusters = _own_outlines(measurements)
    discs = []
    for i, (m, overlap, reliable, cluster) in enumerate(zip(measurements, overlaps, own, clusters)):
        seen = float(reliable.mean()) if len(reliable) else 0.0
        if seen < FULL_OUTLINE_SEEN or cluster is not None:  # in a cluster its light is not all its own
            evidence = "partial"
        elif m.saturated or m.ring or m.bright_centre:
            evidence = "edge"
        else:
            evidence = "plateau"
        discs.append(
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
                overlaps=overlap or cluster is not None,
                resolvable=m.diameter_px >= RESOLVABLE_PX,
                evidence=evidence,
                outline_seen=seen,
                outline_reliable=reliable,
                cluster=None if cluster is None else first_cluster + cluster,
                ring=m.ring,
                bright_centre=m.bright_centre,
                occluded=m.occluded,
                clipped_share=m.clipped_share,
                soft_edge=soft_edge,
            )
        )
    return discs


def _clear_of(sharp: list[Measurement], soft: list[Measurement]) -> list[Measurement]:
    """The soft-edged measurements, largest first, whose outlines lie clear of every sharp disc's (none of their
    points within OVERLAP_MARGIN_PX of one, and none of the sharp disc's inside theirs): a soft blob against a
    sharp disc is its light or its neighbour's glow, and the sharp disc already says what that place shows."""
    extents = _Extents(sharp) if sharp else None
    clear = [m for m in soft if extents is None or not any(
        _within_outline(m.outline_xy, sharp[j].outline_xy, OVERLAP_MARGIN_PX).any()
        or _within_outline(sharp[j].outline_xy, m.outline_xy, OVERLAP_MARGIN_PX).any() for j in extents.near(m))]
    return sorted(clear, key=lambda m: -m.diameter_px)


def _reach(m: Measurement) -> float:
    """How far the measurement's outline reaches from its centre."""
    return float(np.max(np.hypot(*(m.outline_xy - m.center_xy).T)))


class _Extents:
    """Measurements' centres and reaches, asked which of them may touch an outline (within OVERLAP_MARGIN_PX)."""

    def __init__(self, measurements: list[Measurement]):
        self.centres = np.array([m.center_xy for m in measurements])
        self.reach = np.array([_reach(m) for m in measurements])
        self._tree = cKDTree(self.centres)

    def near(self, m: Measurement, reach: float | None = None) -> list[int]:
        """The indices of those whose extent comes within OVERLAP_MARGIN_PX of ``m``'s (its reach ``reach``)."""
        reach = _reach(m) if reach is None else reach
        return [j for j in self._tree.query_ball_point(m.center_xy, reach + self.reach.max() + OVERLAP_MARGIN_PX)
                if np.hypot(*(self.centres[j] - m.center_xy)) <= reach + self.reach[j] + OVERLAP_MARGIN_PX]


def _flag_neighbours(measurements: list[Measurement]) -> list[bool]:
    """True for discs whose outline reaches into another disc's extent."""
    if len(measurements) < 2:
        return [m.overlaps for m in measurements]
    centres = np.array([m.center_xy for m in measurements])
    reach = np.array([_reach(m) for m in measurements])
    tree = cKDTree(centres)
    flags = []
    for i, m in enumerate(measurements):
        near = tree.query_ball_point(m.center_xy, reach[i] + reach.max())
        touching = any(j != i and np.hypot(*(centres[j] - centres[i])) < reach[i] + reach[j] for j in near)
        flags.append(m.overlaps or touching)
    return flags


def _own_outlines(measurements: list[Measurement]) -> tuple[list[np.ndarray], list[int | None]]:
    """Per disc, which outline points are its own and reliable, and its cluster id.

    A point of one disc's outline that lies inside another disc's outline (or
    within OVERLAP_MARGIN_PX of it) is the overlap's edge, not the disc's, unless
    the outline was traced as the disc's own step down (``own_step``: light adds,
    so that step is its edge inside the other's light too). Discs
    that overlap so are joined into clusters (numbered from 0 by their largest
    disc); a disc on its own has cluster None.
    """
    own = [
        m.outline_reliable.copy() if m.outline_reliable is not None else np.ones(len(m.outline_xy), bool)
        for m in measurements
    ]
    parent = list(range(len(measurements)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    if len(measurements) >= 2:
        extents = _Extents(measurements)
        for i, m in enumerate(measurements):
            for j in extents.near(m, extents.reach[i]):
                if j == i:
                    continue
                inside = _within_outline(m.outline_xy, measurements[j].outline_xy, OVERLAP_MARGIN_PX)
                if inside.any():
                    if not m.own_step:  # a contour through the sum of two discs' light is neither's edge
                        own[i] &= ~inside
                    parent[root(i)] = root(j)
    roots = [root(i) for i in range(len(measurements))]
    sizes = Counter(roots)
    numbers: dict[int, int] = {}
    clusters = [numbers.setdefault(r, len(numbers)) if sizes[r] > 1 else None for r in roots]
    return own, clusters


def _within_outline(points: np.ndarray, outline: np.ndarray, margin_px: float) -> np.ndarray:
    """Per point of ``points`` (N, 2): inside the closed ``outline`` or within ``margin_px`` of it. Only the
    points within the margin of the outline's bounding box are tested (the others lie farther from it)."""
    low, high = outline.min(axis=0) - margin_px - 1.0, outline.max(axis=0) + margin_px + 1.0
    near = np.all((points >= low) & (points <= high), axis=1)
    inside = np.zeros(len(points), dtype=bool)
    if near.any():
        polygon = outline.astype(np.float32)
        inside[near] = [cv2.pointPolygonTest(polygon, (float(x), float(y)), True) >= -margin_px
                        for x, y in points[near]]
    return inside


def _same_size(diameter_px: float, other_px: float) -> bool:
    """Two measurements of one disc: the ratio of their sizes within SAME_DISC_SIZE_RATIOS (their
    centres within SAME_DISC_CENTRE_REL of the diameter)."""
    low, high = SAME_DISC_SIZE_RATIOS
    return low < diameter_px / other_px < high


def _distinct_measurements(measurements: list[Measurement]) -> list[Measurement]:
    """One measurement per disc: two candidates that converged on the same outline count once."""
    kept: list[Measurement] = []
    if not measurements:
        return kept
    order = sorted(measurements, key=lambda m: -m.snr)
    tree = cKDTree(np.array([m.center_xy for m in order]))
    dropped = np.zeros(len(order), dtype=bool)
    for i, m in enumerate(order):
        if dropped[i]:
            continue
        kept.append(m)
        for j in tree.query_ball_point(m.center_xy, SAME_DISC_CENTRE_REL * m.diameter_px):
            other = order[j]
            if j > i and _same_size(other.diameter_px, m.diameter_px):
                dropped[j] = True
    return kept
