"""Shape similarity of outlines, by metrics chosen by name from one registry.

Every metric compares two closed outlines ((N, 2) arrays of (x, y) points, any
orientation, start point and units) after :func:`normalise` has put both at
unit area with their centroids at 0, so it measures shape only:

``iou``
    Intersection over union at equal area after the best rotation of ``b``
    (higher is better, 1 for the same shape).
``hausdorff_rel``
    Symmetric Hausdorff distance between the outlines at that rotation, over
    the equivalent radius 1/√π (lower is better, 0 for the same shape).
``efd_distance``
    Distance between elliptic Fourier descriptors (Kuhl & Giardina 1982),
    normalised for size, rotation and start point (lower is better).
``hu_distance``
    OpenCV's ``matchShapes`` on Hu's moment invariants, method I2 (lower is better).

Adding a metric is one :class:`Metric` entry in ``METRICS``;
:func:`compare_outlines` runs them all, or those named. How they align the
outlines is an explicit :class:`MetricOptions` value: nothing is remembered
between calls, so the same call always gives the same answer.

Examples
--------
>>> from bokehfit.apertures import make_aperture
>>> hexagon = aperture_outline(make_aperture("hexagon", 20))
>>> circle = aperture_outline(make_aperture("circle"))
>>> round(compare_outlines(hexagon, circle)["iou"], 3)
0.928
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Iterable

import cv2
import numpy as np

from bokehfit.apertures import CIRCLE_RADIUS
from bokehfit.errors import InputError, check_finite, check_positive
from bokehfit.metrics.efd import efd_aligned_distance, efd_coefficients, normalise_efd
from bokehfit.metrics.outlines import (
    DEFAULT_POINTS,
    DistanceToOutline,
    aperture_outline,
    densify,
    intersection_area,
    normalise,
    rotate,
    signed_area,
)

__all__ = [
    "METRICS",
    "Metric",
    "MetricOptions",
    "angle_error",
    "aperture_outline",
    "best_rotation_deg",
    "compare_outlines",
    "efd_distance",
    "hausdorff_rel",
    "hu_distance",
    "iou",
    "normalise",
    "DEFAULT_HARMONICS",
]

#: Scanlines, outline simplification (Douglas–Peucker tolerance, in units of
#: the unit-area outline) and angle step of the coarse rotation
#: search. The IoU of two polygons falls off linearly from an alignment (~5e-3
#: per degree for a hexagon); the simplified outlines' IoU errs by at most
#: about perimeter × tolerance ≈ 1e-3, so the coarse maxima land within a step
#: of the true ones and the refinement, on the full outlines, finds them.
COARSE_LINES = 128
COARSE_SIMPLIFY = 3e-4
COARSE_STEP_DEG = 1.0
#: Local maxima of the coarse search refined with the exact IoU, and the
#: refinement's tolerance (bounded Brent/golden-section search over ±1.5 steps).
REFINED_PEAKS = 3
REFINE_TOL_DEG = 0.01
#: Harmonics of the elliptic Fourier descriptors.
DEFAULT_HARMONICS = 20
#: Sample points of each outline whose Hausdorff distance is refined between
#: their neighbours (the maximum of a distance along a side may fall between
#: two samples).
_HAUSDORFF_REFINED = 8
#: The refinement along a side: ``_REFINE_GRID`` evenly spaced points, then the
#: same around the best of them over ±1 spacing, ``_REFINE_PASSES`` times. Each
#: pass narrows the window by (grid − 1)/2 = 16, so 4 passes place the maximum
#: within 1/(32·16³) ≈ 7.6e-6 of the side's length; the distance is 1-Lipschitz,
#: so its value is then off by less than that times the length (~4e-8 at unit
#: area and 720 points): far below the 1e-4 of a side that a bounded scalar search reached.
_REFINE_GRID = 33
_REFINE_PASSES = 4


@dataclass(frozen=True)
class MetricOptions:
    """How the metrics of :func:`compare_outlines` align and describe two outlines.

    Parameters
    ----------
    align : bool
        Turn ``b`` to the rotation that maximises its IoU with ``a`` before
        ``iou`` and ``hausdorff_rel``; if False, compare them as given.
    rotation_within_deg : float, optional
        Search that rotation only within ±this many degrees of none (for
        outlines known to be nearly aligned already, such as a disc against
        the kernel fitted to it: some 20 times faster); None searches every angle.
    harmonics : int
        Harmonics of ``efd_distance``.

    Raises
    ------
    InputError
        Naming the field that is out of range.
    """

    align: bool = True
    rotation_within_deg: float | None = None
    harmonics: int = DEFAULT_HARMONICS

    def __post_init__(self):
        if not isinstance(self.align, (bool, np.bool_)):
            raise InputError(f"align must be True or False (got {self.align!r})")
        within = self.rotation_within_deg
        if within is not None:
            if isinstance(within, bool) or not isinstance(within, (int, float, np.integer, np.floating)):
                raise InputError(f"rotation_within_deg must be a positive number of degrees or None (got {within!r})")
            if not (math.isfinite(within) and within > 0):
                raise InputError(f"rotation_within_deg must be a positive number of degrees or None (got {within!r})")
        _check_harmonics(self.harmonics)


def _check_harmonics(harmonics) -> int:
    if isinstance(harmonics, bool) or not isinstance(harmonics, (int, np.integer)) or harmonics < 1:
        raise InputError(f"harmonics must be a positive integer (got {harmonics!r})")
    return int(harmonics)


@dataclass(frozen=True)
class Metric:
    """One registry entry: a shape metric of two outlines.

    ``function(a, b)`` is the public function (any outlines, default options);
    ``of_normalised(a, b, options)`` is what :func:`compare_outlines` calls
    on outlines already normalised and, where ``aligned``, with ``b`` already
    turned to the best rotation, which the aligned metrics then share.
    """

    name: str
    function: Callable[[np.ndarray, np.ndarray], float]
    description: str
    better: str  #: "higher" or "lower"
    range: str  #: the values it takes, for people
    of_normalised: Callable[[np.ndarray, np.ndarray, MetricOptions], float]
    aligned: bool  #: compares ``b`` at the best rotation (when ``options.align``)

    def __call__(self, a, b) -> float:
        return self.function(a, b)


# ---------------------------------------------------------------------------
# IoU and the best rotation


def _iou_of_normalised(a: np.ndarray, b: np.ndarray, lines: int = 64, *, exact: bool = True, areas=None) -> float:
    """IoU of two outlines: intersection by scanlines, union = area a + area b − intersection."""
    intersection = intersection_area(a, b, lines, exact=exact)
    area_a, area_b = areas if areas is not None else (signed_area(a), signed_area(b))
    return intersection / (area_a + area_b - intersection)


def _simplify(outline: np.ndarray) -> np.ndarray:
    """Douglas–Peucker simplification to ``COARSE_SIMPLIFY`` (corners kept, runs of collinear points dropped)."""
    simple = cv2.approxPolyDP(outline.astype(np.float32)[:, None, :], COARSE_SIMPLIFY, True)[:, 0, :].astype(np.float64)
    return simple if len(simple) >= 3 and abs(signed_area(simple)) > 0.5 else outline


def _local_rotation(a: np.ndarray, b: np.ndarray, within_deg: float) -> float:
    """Best rotation of ``b`` searched only within ±``within_deg`` of none; both normalised.

    The exact IoU of the outlines simplified to ``COARSE_SIMPLIFY`` is searched, at about half the
    cost: their sides lie within that distance of the outlines' (a unit area's outline is about 3.5
    long), so its IoU is theirs to about 1e-3 at every angle, and the full outlines' IoU at the angle
    it finds lies within 1e-5 of its maximum (the tests)."""
    from scipy.optimize import minimize_scalar  # on first use: scipy.optimize takes ~0.3 s to import

    simple_a, simple_b = _simplify(a), _simplify(b)
    areas = (signed_area(simple_a), signed_area(simple_b))
    result = minimize_scalar(
        lambda angle: -_iou_of_normalised(simple_a, rotate(simple_b, angle), areas=areas),
        bounds=(-within_deg, within_deg),
        method="bounded",
        options={"xatol": REFINE_TOL_DEG},
    )
    return float(result.x)


def _best_rotation(a: np.ndarray, b: np.ndarray) -> float:
    """Rotation of ``b`` (degrees, in [−180, 180)) maximising the IoU with ``a``; both normalised."""
    from scipy.optimize import minimize_scalar  # on first use: scipy.optimize takes ~0.3 s to import

    angles = np.arange(0.0, 360.0, COARSE_STEP_DEG)
    simple_a, simple_b = _simplify(a), _simplify(b)
    simple_areas = (signed_area(simple_a), signed_area(simple_b))
    coarse = np.array(
        [_iou_of_normalised(simple_a, rotate(simple_b, angle), COARSE_LINES, exact=False, areas=simple_areas) for angle in angles]
    )
    areas = (signed_area(a), signed_area(b))
    is_peak = (coarse >= np.roll(coarse, 1)) & (coarse >= np.roll(coarse, -1))
    peaks = np.flatnonzero(is_peak)
    peaks = peaks[np.argsort(-coarse[peaks], kind="stable")][:REFINED_PEAKS]
    best_angle, best_iou = 0.0, -1.0
    span = 1.5 * COARSE_STEP_DEG
    for peak in peaks:
        centre = float(angles[peak])
        result = minimize_scalar(
            lambda offset: -_iou_of_normalised(a, rotate(b, centre + offset), areas=areas),
            bounds=(-span, span),
            method="bounded",
            options={"xatol": REFINE_TOL_DEG},
        )
        if -result.fun > best_iou:
            best_angle, best_iou = centre + float(result.x), -float(result.fun)
    return (best_angle + 180.0) % 360.0 - 180.0


def _aligned(a: np.ndarray, b: np.ndarray, options: MetricOptions) -> np.ndarray:
    """``b`` turned to its best rotation against ``a`` as ``options`` ask (both normalised).

    The search costs about 0.1 s for a pair of 720-point outlines (5 ms
    within ±1°); :func:`compare_outlines` runs it once for all the aligned
    metrics, so nothing needs to be remembered between calls.
    """
    if not options.align:
        return b
    if options.rotation_within_deg is None:
        return rotate(b, _best_rotation(a, b))
    return rotate(b, _local_rotation(a, b, float(options.rotation_within_deg)))


def best_rotation_deg(a, b) -> float:
    """The counter-clockwise rotation of ``b`` (degrees, in [−180, 180)) that maximises its IoU with ``a``.

    Both outlines are normalised (centroid at 0, unit area) and ``b`` is turned
    about its centroid. The search tries every 1° (approximate IoU of
    simplified outlines on 128 scanlines), then refines the three best local
    maxima to 0.01° with the exact IoU (bounded golden-section/Brent search).
    Where the IoU does not depend on the rotation (either shape a circle) the
    angle is arbitrary; for a shape with n-fold symmetry it is one of n
    equivalent angles.
    """
    return _best_rotation(normalise(a, "a"), normalise(b, "b"))


def iou(a, b, *, align: bool = True, rotation_within_deg: float | None = None) -> float:
    """Intersection over union of two outlines at equal area, after the best alignment.

    Parameters
    ----------
    a, b : array_like of shape (N, 2)
        Closed simple polygons; each is normalised (centroid at 0, unit area).
    align : bool
        Rotate ``b`` to the angle that maximises the IoU
        (:func:`best_rotation_deg`); if False, compare them as given.
    rotation_within_deg : float, optional
        Search that angle only within ±this many degrees (see :class:`MetricOptions`).

    Returns
    -------
    float in [0, 1]
        1 for the same shape.

    Notes
    -----
    Exact up to rounding: the intersection is integrated on scanlines, exactly
    across each line and by the midpoint rule between lines cut at every
    vertex and every crossing of the two outlines, where the length inside
    both is linear (:func:`bokehfit.metrics.outlines.intersection_area`); the
    union is 2 − intersection. The tests hold it to shapely's exact polygon
    IoU within 1e-9 (differences of ~1e-15 seen).
    (A 1024² pixel mask errs by up to 4e-3 where long sides align with the
    grid, which is why this is not one.)
    """
    options = MetricOptions(align=align, rotation_within_deg=rotation_within_deg)
    a, b = normalise(a, "a"), normalise(b, "b")
    return _iou_of_normalised(a, _aligned(a, b, options))


# ---------------------------------------------------------------------------
# Hausdorff distance


def _directed_hausdorff(samples: np.ndarray, target: np.ndarray) -> float:
    """max over the closed polyline ``samples`` of the distance to the outline ``target``.

    The largest distances among the samples are refined along their two
    neighbouring sides, where the true maximum may lie between samples: all
    those sides at once, on nested grids (:data:`_REFINE_GRID`), each against
    only the sides of ``target`` that can be nearest to some point of it."""
    distance_to = DistanceToOutline(target)
    distances = distance_to(samples)
    best = float(distances.max())
    count = len(samples)
    top = np.argsort(-distances)[:_HAUSDORFF_REFINED]
    sides = np.unique(np.concatenate(((top - 1) % count, top)))  # side k runs from sample k to k + 1
    start, end = samples[sides], samples[(sides + 1) % count]
    length = np.hypot(*(end - start).T)
    # The distance is 1-Lipschitz: along a side it stays below (d_start + d_end + length)/2.
    promising = 0.5 * (distances[sides] + distances[(sides + 1) % count] + length) > best
    start, end, half = start[promising], end[promising], 0.5 * length[promising]
    if len(start) == 0:
        return best
    # A point p of a side is within `half` of its midpoint m, so d(p) ≤ d(m) + half; a target
    # side farther than d(m) + 2·half from m is farther than that from p: never the nearest.
    middle = 0.5 * (start + end)
    to_middle = distance_to.to_sides(middle[:, 0, None], middle[:, 1, None])  # (sides, target sides)
    reach = to_middle.min(axis=1) + 2.0 * half
    near = to_middle <= reach[:, None] * (1.0 + 1e-9) + 1e-12
    order = np.argsort(~near, axis=1, kind="stable")[:, : int(near.sum(axis=1).max())]
    rows = np.arange(len(start))
    candidates = np.where(near[rows[:, None], order], order, order[:, :1])[:, None, :]  # padded with a real one
    grid = np.linspace(0.0, 1.0, _REFINE_GRID)
    low, width = np.zeros(len(start)), np.ones(len(start))
    for _ in range(_REFINE_PASSES):
        at = low[:, None] + width[:, None] * grid  # (sides, grid): position along each side, in [0, 1]
        x = start[:, 0, None] + at * (end - start)[:, 0, None]
        y = start[:, 1, None] + at * (end - start)[:, 1, None]
        found = distance_to.to_sides(x[..., None], y[..., None], candidates).min(axis=2)
        peak = np.argmax(found, axis=1)
        best = max(best, float(found[rows, peak].max()))
        width = width * 2.0 / (_REFINE_GRID - 1)
        low = np.clip(at[rows, peak] - 0.5 * width, 0.0, 1.0 - width)
    return best


def hausdorff_rel(a, b, *, align: bool = True, rotation_within_deg: float | None = None) -> float:
    """Symmetric Hausdorff distance between two outlines, over the equivalent radius 1/√π.

    Both outlines are normalised (unit area, centroid at 0); with
    ``align=True`` ``b`` is first turned by :func:`best_rotation_deg` (the
    rotation that maximises the IoU, which need not be the one minimising this
    distance). The distance is between the outlines as curves: each is
    densified to ~720 points, the distance from every point to the other
    outline's sides is exact, and the largest are refined between samples.
    ``rotation_within_deg`` limits the rotation search as in :class:`MetricOptions`.

    Returns
    -------
    float ≥ 0
        0 for the same shape; (√2/2 − 1/√π)/(1/√π) = 0.2533 for a square against a circle.
    """
    options = MetricOptions(align=align, rotation_within_deg=rotation_within_deg)
    a, b = normalise(a, "a"), normalise(b, "b")
    return _hausdorff_of_normalised(a, _aligned(a, b, options))


def _hausdorff_of_normalised(a: np.ndarray, b: np.ndarray, options: MetricOptions | None = None) -> float:
    distance = max(
        _directed_hausdorff(densify(a, DEFAULT_POINTS), b),
        _directed_hausdorff(densify(b, DEFAULT_POINTS), a),
    )
    return distance / CIRCLE_RADIUS


# ---------------------------------------------------------------------------
# Elliptic Fourier descriptors and Hu moments


def efd_distance(a, b, harmonics: int = DEFAULT_HARMONICS) -> float:
    """Distance between the elliptic Fourier descriptors of two outlines (Kuhl & Giardina 1982).

    Each outline is made counter-clockwise and its coefficients a_n, b_n, c_n,
    d_n (n = 1 … ``harmonics``) normalised as K&G do
    (:func:`bokehfit.metrics.efd.normalise_efd`: semi-major axis of the first
    harmonic 1, along +x, start point at its end). The result is the
    Euclidean distance between the two 4·``harmonics`` vectors.

    Notes
    -----
    K&G's normal form leaves the start point two-fold ambiguous (θ1 or θ1 + π),
    and undefined when the first harmonic is a circle: every regular polygon
    and the star. So ``b`` is then moved along that residual freedom (start
    point τ and rotation ψ, both isometries of the vector) to the pose that
    minimises the distance (:func:`bokehfit.metrics.efd.efd_aligned_distance`).
    Where K&G's own pose is the best one, a1 = 1, b1 = c1 = 0 in both and the
    result is K&G's distance over the remaining coefficients; it is never
    larger. It is invariant to translation, scale, rotation, start point and
    orientation (to ~1e-12 in the tests), not to mirroring.

    References
    ----------
    F. P. Kuhl and C. R. Giardina, "Elliptic Fourier features of a closed
    contour", Computer Graphics and Image Processing 18 (1982) 236–258.
    """
    harmonics = _check_harmonics(harmonics)
    return _efd_of_normalised(normalise(a, "a"), normalise(b, "b"), MetricOptions(harmonics=harmonics))


def _efd_of_normalised(a: np.ndarray, b: np.ndarray, options: MetricOptions) -> float:
    normal_a = normalise_efd(efd_coefficients(a, options.harmonics))
    normal_b = normalise_efd(efd_coefficients(b, options.harmonics))
    return efd_aligned_distance(normal_a, normal_b)[0]


def hu_distance(a, b) -> float:
    """``cv2.matchShapes(a, b, cv2.CONTOURS_MATCH_I2, 0)`` on the normalised outlines as float32.

    I2 = Σ_i |m_i^A − m_i^B|, m_i = sign(h_i)·log10|h_i|, over Hu's seven
    invariants h_i; OpenCV skips an invariant that is below 1e-5 in either
    shape. A circle, a regular polygon other than the triangle (which keeps
    h3) and the star have only h1 above that, so between them this compares
    h1 alone: the polar moment of inertia at unit area.
    Normalising first changes nothing in exact arithmetic (the invariants are)
    but keeps float32 from losing digits to large offsets.
    """
    return _hu_of_normalised(normalise(a, "a"), normalise(b, "b"))


def _hu_of_normalised(a: np.ndarray, b: np.ndarray, options: MetricOptions | None = None) -> float:
    return float(cv2.matchShapes(a.astype(np.float32), b.astype(np.float32), cv2.CONTOURS_MATCH_I2, 0.0))


# ---------------------------------------------------------------------------
# Angles


def angle_error(angle_a_deg, angle_b_deg, symmetry_deg: float | None) -> float:
    """Smallest |angle_a − angle_b| modulo the shape's symmetry, degrees, in [0, symmetry/2].

    ``symmetry_deg`` None (a circle, whose angle is meaningless) gives 0.0.

    Examples
    --------
    >>> angle_error(59.0, 1.0, 60.0)
    2.0
    """
    a = check_finite("angle_a_deg", angle_a_deg)
    b = check_finite("angle_b_deg", angle_b_deg)
    if symmetry_deg is None:
        return 0.0
    symmetry = check_positive("symmetry_deg", symmetry_deg)
    difference = math.fmod(abs(a - b), symmetry)
    return min(difference, symmetry - difference)


# ---------------------------------------------------------------------------
# The registry


METRICS: dict[str, Metric] = {
    metric.name: metric
    for metric in (
        Metric(
            "iou",
            iou,
            "intersection over union at equal area, best rotation",
            "higher",
            "[0, 1]",
            lambda a, b, options: _iou_of_normalised(a, b),
            aligned=True,
        ),
        Metric(
            "hausdorff_rel",
            hausdorff_rel,
            "Hausdorff distance of the outlines at that rotation / equivalent radius",
            "lower",
            "[0, ∞)",
            _hausdorff_of_normalised,
            aligned=True,
        ),
        Metric(
            "efd_distance",
            efd_distance,
            f"elliptic Fourier descriptors (Kuhl & Giardina, {DEFAULT_HARMONICS} harmonics), normalised",
            "lower",
            "[0, ∞)",
            _efd_of_normalised,
            aligned=False,
        ),
        Metric(
            "hu_distance",
            hu_distance,
            "Hu moment invariants, cv2.matchShapes I2",
            "lower",
            "[0, ∞)",
            _hu_of_normalised,
            aligned=False,
        ),
    )
}


def compare_outlines(
    a,
    b,
    metrics: Iterable[str] | str | None = None,
    *,
    options: MetricOptions | None = None,
    rotation_within_deg: float | None = None,
) -> dict[str, float]:
    """Every metric of ``METRICS`` (or those named, in that order) for two outlines.

    Parameters
    ----------
    a, b : array_like of shape (N, 2)
        Closed simple polygons, any orientation, start point and units.
    metrics : str or iterable of str, optional
        Names from ``METRICS``; all of them by default.
    options : MetricOptions, optional
        Alignment and harmonics; ``MetricOptions()`` by default.
    rotation_within_deg : float, optional
        Shorthand for ``options=MetricOptions(rotation_within_deg=...)``.

    Returns
    -------
    dict
        Metric name → value. ``iou`` and ``hausdorff_rel`` share one rotation
        search, made afresh on every call: the result depends only on the
        arguments.

    Raises
    ------
    InputError
        Naming ``a``, ``b``, ``metrics``, ``options`` or ``rotation_within_deg``.
    """
    if metrics is None:
        names = list(METRICS)
    else:
        names = [metrics] if isinstance(metrics, str) else list(metrics)
        unknown = [name for name in names if name not in METRICS]
        if unknown or not names:
            raise InputError(f"metrics must be names from {', '.join(METRICS)} (got {unknown[0] if unknown else 'none'!r})")
    if options is None:
        options = MetricOptions(rotation_within_deg=rotation_within_deg)
    elif not isinstance(options, MetricOptions):
        raise InputError(f"options must be a MetricOptions (got {type(options).__name__})")
    elif rotation_within_deg is not None:
        raise InputError("rotation_within_deg must not be given with options (set it in the MetricOptions)")
    normal_a, normal_b = normalise(a, "a"), normalise(b, "b")  # errors name the parameter first
    aligned_b = _aligned(normal_a, normal_b, options) if any(METRICS[name].aligned for name in names) else None
    return {
        name: float(METRICS[name].of_normalised(normal_a, aligned_b if METRICS[name].aligned else normal_b, options))
        for name in names
    }
