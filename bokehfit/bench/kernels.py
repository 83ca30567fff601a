"""Part (a) of ``bokehfit bench``: kernel error against time for every kernel method.

Every method of :data:`bokehfit.kernels.METHODS` renders the same kernels (one
per shape and disc diameter) at sample counts a decade apart, and each result
is scored by its L1 distance to the exact reference.

Notes
-----
**Reference.** The exact coverage (:func:`bokehfit.kernels.exact.coverage`) is
evaluated in float64 on a grid ``REFINE`` times finer and summed over
``REFINE`` × ``REFINE`` blocks. The fine grid's borders include every coarse
border (the frame's centre is the same point on both), so the binned result is
the same integral computed through other corner points: ``exact``'s own L1
against it measures only rounding (float32 storage of the image, ~1e-8), and it
is a check of ``exact`` as well as the reference for the sampling methods.

**Frame.** A disc of equal-area diameter d sits in a square frame of side
⌈``FRAME_FACTOR`` × (outline width)⌉ + 2 × ``FRAME_MARGIN_PX``, the outline
width being twice the shape's reach (its farthest vertex), so no light is
clipped.

**Real-lens features.** Besides the plain shapes, :data:`FEATURE_CASES`
renders one aperture per feature of design.md §3b (rounded 9 blades at
roundness 0.5, squeezed, vignetted at a field position, rim, chromatic); the
``shape`` column holds the case's name. Their reference is ``exact`` itself
on the ``REFINE``× grid, binned (for ``rim`` that is the tabulated kernel,
whose own stated bound is in ``notes``); a chromatic kernel's L1 is the mean
over its red, green and blue channels.

**Timing.** ``time_s`` is :attr:`bokehfit.kernels.Kernel.time_s` (upload,
render and read-back; the one-time start-up is in ``setup_s`` and is not
counted). Every method renders one small kernel first, so shader compilation
and the first dispatch are not timed either. A point that takes under
``REPEAT_BELOW_S`` is rendered ``REPEATS`` times and the fastest run is kept
(the image is the same every time: the seed is fixed and the counts are
integers); slower points are rendered once.

**Cut-off.** The sample counts of one series run in increasing order; a count
whose predicted time (the previous count's time scaled by the ratio of the
counts) exceeds ``max_point_s`` is skipped with every larger one, and listed
in ``skipped``. A count that rounds to the same number of samples as the
previous one (``raster`` draws whole passes over the disc, so at 256 px 1e3 and
1e4 are both one pass) is measured once.

**Rate.** The convergence rate is the least-squares slope of log L1 against
log samples over the points with at least one sample per pixel of the disc on
average (samples ≥ its area π d²/4). Below that most pixels get zero or one
sample, L1 saturates near 2 whatever the method, and the slope would measure
that plateau rather than the convergence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = [
    "ANGLE_DEG",
    "DIAMETERS_PX",
    "MAX_POINT_S",
    "QUICK_DIAMETERS_PX",
    "QUICK_SAMPLES",
    "SAMPLES",
    "SHAPES",
    "VARIANTS",
    "Variant",
    "BENCH_APERTURES",
    "FEATURE_CASES",
    "bench_aperture",
    "convergence_rate",
    "kernel_l1",
    "frame_size",
    "kernel_steps",
    "kernel_sweep",
    "reference_kernel",
]


@dataclass(frozen=True)
class Variant:
    """One kernel method with its sample pattern (None where the method has no choice)."""

    method: str
    sampling: str | None

    @property
    def sampled(self) -> bool:
        return self.method != "exact"

    @property
    def label(self) -> str:
        return self.method if self.sampling is None else f"{self.method} {self.sampling}"


#: What is measured: ``raster`` is always stratified inside each pixel, ``exact`` draws no samples.
VARIANTS = (Variant("exact", None), Variant("mc", "independent"), Variant("mc", "stratified"), Variant("raster", None))
SHAPES = ("circle", "hexagon", "star")
def _bench_mask(side: int = 48) -> np.ndarray:
    """A custom mask made by geometry (read-only): a clear ring around a half-grey disc crossed by an opaque bar."""
    yy, xx = (np.mgrid[0:side, 0:side] + 0.5 - side / 2) / (side / 2)
    r = np.hypot(xx, yy)
    mask = np.where(r <= 1.0, np.where(r >= 0.7, 1.0, 0.5), 0.0)
    mask[np.abs(yy) < 0.08] = 0.0
    mask.flags.writeable = False
    return mask


#: One aperture per §3b feature: name → (make_aperture keywords, field position or None).
FEATURE_CASES = {
    "rounded": (dict(shape="ngon", blades=9, roundness=0.5), None),
    "squeezed": (dict(shape="hexagon", squeeze=1.6), None),
    "vignetted": (dict(shape="hexagon", vignetting={"radius": 1.1, "shift": 1.0}), (0.7, 0.4)),
    "rim": (dict(shape="hexagon", rim=0.6), None),
    "chromatic": (dict(shape="hexagon", chromatic={"red": 0.05, "blue": -0.04}), None),
    "mask": (dict(shape="mask", mask=_bench_mask()), None),
}
#: Everything ``bokehfit bench`` renders: the plain shapes, then the feature cases.
BENCH_APERTURES = SHAPES + tuple(FEATURE_CASES)
DIAMETERS_PX = (16.0, 64.0, 256.0)
QUICK_DIAMETERS_PX = (64.0,)
#: Requested samples per kernel, a decade apart (the methods round up: ``mc`` stratified to m², ``raster`` to whole passes).
SAMPLES = tuple(10**k for k in range(3, 9))
QUICK_SAMPLES = tuple(10**k for k in range(3, 7))
ANGLE_DEG = 20.0
SEED = 7
#: Frame side = ⌈FRAME_FACTOR × outline width⌉ + 2 × FRAME_MARGIN_PX.
FRAME_FACTOR = 1.25
FRAME_MARGIN_PX = 4
#: Reference grid refinement (see the module notes).
REFINE = 2
#: Points faster than this are run REPEATS times (best kept).
REPEAT_BELOW_S = 0.2
REPEATS = 3
#: Default cut-off of one point's predicted render time, seconds (see the module notes). On
#: two CPU cores with lavapipe a 1e8-sample ``mc`` kernel takes 4–8 s, so the full run
#: (every point) takes about 4–5 minutes; a slower machine cuts the largest counts instead.
MAX_POINT_S = 10.0
#: Samples used by the warm-up render of each method.
WARMUP_SAMPLES = 1000


def bench_aperture(name: str, angle_deg: float = ANGLE_DEG):
    """(aperture, field position or None) of a plain shape or a :data:`FEATURE_CASES` name."""
    from bokehfit.apertures import make_aperture

    if name not in FEATURE_CASES:
        return make_aperture(name, angle_deg), None
    params, field_position = FEATURE_CASES[name]
    params = dict(params)
    return make_aperture(params.pop("shape"), angle_deg, **params), field_position


def frame_size(shape: str, diameter_px: float, angle_deg: float = ANGLE_DEG) -> int:
    """Side of the square frame that holds the disc with room to spare (see the module notes)."""
    aperture, _ = bench_aperture(shape, angle_deg)
    largest = 1.0 if aperture.chromatic is None else 1.0 + max(0.0, aperture.chromatic.red, aperture.chromatic.blue)
    reach = aperture.extent() * largest * diameter_px * math.sqrt(math.pi) / 2.0
    return math.ceil(FRAME_FACTOR * 2.0 * reach) + 2 * FRAME_MARGIN_PX


def reference_kernel(shape: str, angle_deg: float, diameter_px: float, size: int) -> np.ndarray:
    """Exact kernel in float64 from a ``REFINE``× finer grid, binned; sums to 1 (each channel)."""
    from bokehfit.kernels import compute_kernel
    from bokehfit.kernels.exact import coverage

    aperture, field_position = bench_aperture(shape, angle_deg)
    if shape in FEATURE_CASES:
        fine = compute_kernel(aperture, diameter_px=REFINE * diameter_px, size=REFINE * size,
                              field_position=field_position).image.astype(np.float64)
    else:
        scale = diameter_px * math.sqrt(math.pi) / 2.0  # equal-area convention, as compute_kernel
        fine = coverage(aperture, REFINE * scale, REFINE * size)
    binned = fine.reshape(size, REFINE, size, REFINE, *fine.shape[2:]).sum(axis=(1, 3))
    return binned / binned.sum(axis=(0, 1))


def kernel_l1(image: np.ndarray, reference: np.ndarray) -> float:
    """L1 distance of a kernel to its reference; the mean over the channels of a colour kernel."""
    channels = image.shape[2] if image.ndim == 3 else 1
    return float(np.abs(image.astype(np.float64) - reference).sum()) / channels


def convergence_rate(samples, l1, min_samples: float = 0.0) -> tuple[float | None, int]:
    """Slope of log L1 against log samples over the points with samples ≥ ``min_samples``.

    Returns (slope, points used); the slope is None with fewer than two points.
    """
    chosen = [(n, e) for n, e in zip(samples, l1) if n >= min_samples and e > 0.0]
    if len(chosen) < 2:
        return None, len(chosen)
    n, e = np.log(np.array(chosen, dtype=np.float64)).T
    return float(np.polyfit(n, e, 1)[0]), len(chosen)


def kernel_steps(shapes, diameters, samples) -> int:
    """Kernels :func:`kernel_sweep` renders at most (for a progress bar; warm-ups not counted)."""
    per_frame = sum(len(samples) if v.sampled else 1 for v in VARIANTS)
    return len(shapes) * len(diameters) * per_frame


def _measure(shape, angle, diameter, size, variant: Variant, samples, repeats, adapter=None):
    from bokehfit.kernels import compute_kernel

    aperture, field_position = bench_aperture(shape, angle)
    best_kernel, best = None, math.inf
    for _ in range(max(1, repeats)):
        kernel = compute_kernel(
            aperture, diameter_px=diameter, size=size, method=variant.method, samples=samples,
            sampling=variant.sampling or "stratified", seed=SEED, adapter=adapter, field_position=field_position,
        )
        if kernel.time_s < best:
            best_kernel, best = kernel, kernel.time_s
        if kernel.time_s >= REPEAT_BELOW_S:
            break
    return best_kernel, best


def kernel_sweep(
    shapes=SHAPES,
    diameters=DIAMETERS_PX,
    samples=SAMPLES,
    *,
    angle_deg: float = ANGLE_DEG,
    size: int | None = None,
    repeats: int = REPEATS,
    max_point_s: float = MAX_POINT_S,
    progress: Callable[[str], None] | None = None,
    adapter=None,
) -> dict:
    """Render every variant × shape × diameter × sample count; score, time and fit the rates.

    Parameters
    ----------
    shapes, diameters, samples : sequences
        Aperture shapes, equal-area diameters (pixels) and requested sample counts.
    size : int, optional
        Frame side for every kernel (default: :func:`frame_size` of each shape and diameter).
    repeats : int
        Runs of a point faster than ``REPEAT_BELOW_S`` (the fastest is kept).
    max_point_s : float
        Skip a count whose predicted time exceeds this (``math.inf``: never).
    progress : callable, optional
        Called with a short description after each kernel.
    adapter : bokehfit.gpu.AdapterChoice, optional
        The WebGPU adapter of ``mc`` (the best one found by default).

    Returns
    -------
    dict
        ``rows`` (method, sampling, shape, diameter_px, size, requested_samples, samples,
        time_s, l1, error_bound: the stated bound of a tabulated exact kernel, else None), ``rates`` (method, sampling, shape, diameter_px, rate, points,
        min_samples), ``skipped`` (the points left out, with predicted_s), ``devices``
        (by method) and ``notes`` (one line each, for people).
    """
    from bokehfit.kernels import compute_kernel

    notify = progress or (lambda what: None)
    counts = sorted({int(n) for n in samples})
    rows, rates, skipped, notes, devices = [], [], [], [], {}
    warmed = set()
    for shape in shapes:
        for diameter in diameters:
            frame = size if size is not None else frame_size(shape, diameter, angle_deg)
            reference = reference_kernel(shape, angle_deg, diameter, frame)
            area_px = math.pi * diameter * diameter / 4.0
            for variant in VARIANTS:
                if variant.method not in warmed:
                    compute_kernel(bench_aperture(shape, angle_deg)[0], diameter_px=diameter, size=frame,
                                   method=variant.method, samples=WARMUP_SAMPLES, adapter=adapter)
                    warmed.add(variant.method)
                series = []
                previous = None  # (requested, drawn, time)
                for requested in counts if variant.sampled else [None]:
                    what = f"{variant.label} {shape} {diameter:g}px" + (f" {requested:.0e}" if requested else "")
                    if previous is not None and previous[2] * requested / previous[0] > max_point_s:
                        predicted = previous[2] * requested / previous[0]
                        skipped.append(dict(method=variant.method, sampling=variant.sampling, shape=shape,
                                            diameter_px=diameter, requested_samples=requested,
                                            predicted_s=round(predicted, 3)))
                        notify(what + " skipped")
                        continue
                    kernel, seconds = _measure(shape, angle_deg, diameter, frame, variant, requested, repeats, adapter)
                    devices.setdefault(variant.method, kernel.device)
                    notify(what)
                    if previous is not None and kernel.samples == previous[1]:
                        notes.append(f"{variant.label}, {shape} {diameter:g} px: {requested:.0e} samples round to "
                                     f"the {kernel.samples} of the previous count; measured once")
                        continue
                    l1 = kernel_l1(kernel.image, reference)
                    if kernel.error_bound is not None and variant.method == "exact" and shape in FEATURE_CASES:
                        notes.append(f"{shape} {diameter:g} px: exact is tabulated (rim), stated L1 bound "
                                     f"{kernel.error_bound:.2g}; measured {l1:.2g} against the {REFINE}× grid")
                    row = dict(method=variant.method, sampling=variant.sampling, shape=shape, diameter_px=diameter,
                               size=frame, requested_samples=requested, samples=kernel.samples, time_s=seconds, l1=l1,
                               error_bound=kernel.error_bound)
                    rows.append(row)
                    series.append(row)
                    if requested is not None:
                        previous = (requested, kernel.samples, seconds)
                if variant.sampled:
                    rate, points = convergence_rate([r["samples"] for r in series], [r["l1"] for r in series], area_px)
                    rates.append(dict(method=variant.method, sampling=variant.sampling, shape=shape,
                                      diameter_px=diameter, rate=rate, points=points, min_samples=round(area_px)))
    if skipped:
        by_series = {}
        for s in skipped:
            key = (Variant(s["method"], s["sampling"]).label, s["diameter_px"])
            by_series.setdefault(key, []).append(s)
        for (label, diameter), items in by_series.items():
            smallest = min(s["requested_samples"] for s in items)
            slowest = max(s["predicted_s"] for s in items)
            shapes_cut = sorted({s["shape"] for s in items})
            notes.append(f"{label} at {diameter:g} px ({', '.join(shapes_cut)}): {smallest:.0e} samples and up skipped, "
                         f"predicted up to {slowest:.1f} s a kernel (cut-off {max_point_s:g} s)")
    return dict(rows=rows, rates=rates, skipped=skipped, devices=devices, notes=notes)
