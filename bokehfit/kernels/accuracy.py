"""Adaptive accuracy: the cheapest kernel method and sample count that meet an L1 tolerance.

Notes
-----
The error models are fitted to ``bokehfit bench`` measurements (L1 against
``exact``, 16- to 256-px circles, hexagons and stars; lavapipe and an NVIDIA
H200 give the same errors, only the times differ). With A the disc's area in
px², d its diameter and N the point samples over the disc:

- ``mc`` stratified:   L1 ≈ 1.0 · (A / N)^0.74  (the star, the worst shape; circles 15 % less)
- ``mc`` independent:  L1 ≈ 0.80 · (A / N)^0.50
- ``raster``:          L1 ≈ 2.0 / d · (A / N)^0.75   (N / A super-samples a pixel)
- ``exact``:           L1 = 0 (float64 rounding)

A ``mask`` aperture (design.md §3b) converges at the same rates with larger
constants: binary masks err like the circle, grey ones more (the density
varies, and the sampler's rows cut the strata), up to 1.9 times the model
for ``mc`` and 1.2 times for ``raster`` (8² to 512² masks, 16- to 96-px discs,
lavapipe and llvmpipe); the models take 2.3 and 1.25 times their constants
for every mask. The mask's resolution does not change them.

The time models are rough costs on the slowest adapter bokehfit supports
(Mesa lavapipe on two cores): ``exact`` 2.5e-8 s per pixel-corner and outline
edge, or, where a large frame has only the pixels the outline crosses
integrated, 5e-4 s plus 1.5e-5 s per pixel of the disc's diameter, whichever is
less (a ``rim`` kernel: 5.5e-6 s per pixel, tabulated on 8×8 sub-pixels);
``mc`` 2.2e-8 s per sample plus 5 ms; ``raster`` 1e-9 s per pixel and
pass plus 10 ms (the fixed costs are upload, dispatch and read-back). The
one-time start-up of a method's device is counted only for a kernel drawn on
its own (``count_startup``, ``method="auto"`` of :func:`bokehfit.kernels.compute_kernel`):
0.8 s for ``mc`` (the WebGPU device, the compute pipeline and its first
dispatch on lavapipe), 0.06 s for ``raster`` (a headless OpenGL context). They
only rank the methods, so a faster GPU changes the choice little: it favours
the sampling methods sooner. A mask's
``exact`` kernel costs 3.5e-7 s per border segment between cells of different
transmission and pixel its box touches, and its ``mc`` samples cost
1 + 0.1·log2(cells) times as much (the two binary searches of ``sample_mask``;
measured 1.4 times for 4², 2.5 times for 256²). With ``chromatic`` every method
renders three channels: three times the time. The error models hold per
channel, as the tolerance does (each channel sums to 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from bokehfit.apertures import Aperture
from bokehfit.errors import InputError
from bokehfit.kernels.masks import mask_border_segments
from bokehfit.validate import RANGES, check

__all__ = ["MIN_TOLERANCE", "Plan", "plan_kernel", "predicted_l1"]

#: (coefficient, exponent) of the error models above.
_MC_STRATIFIED = (1.0, 0.74)
_MC_INDEPENDENT = (0.80, 0.50)
_RASTER = (2.0, 0.75)
#: Cost models (seconds).
_EXACT_PER_CELL_EDGE = 2.5e-8
_EXACT_FIXED = 5e-4
_EXACT_PER_DIAMETER_PX = 1.5e-5
_EXACT_RIM_PER_PIXEL = 5.5e-6
#: One-time start-up of each method's device, for a kernel drawn on its own (module notes).
_STARTUP_S = {"exact": 0.0, "mc": 0.8, "raster": 0.06}
_MC_PER_SAMPLE = 2.2e-8
_RASTER_PER_PIXEL_PASS = 1e-9
_MC_FIXED = 5e-3
_RASTER_FIXED = 1e-2
#: A mask's error constants over the model's, per sampling method (module notes).
_MASK_ERROR = {"mc": 2.3, "raster": 1.25}
#: A mask's ``exact`` cost per weighted border segment and pixel of its box (s), and the
#: extra ``mc`` cost per binary-search step (one per halving of the cell count).
_EXACT_PER_MASK_SEGMENT_PIXEL = 3.5e-7
_MC_MASK_PER_STEP = 0.1
#: Sample counts the planner may choose (the most that a kernel takes).
_MIN_SAMPLES, _MAX_SAMPLES = 1_000, int(RANGES["kernel_samples"].high)
#: Smallest L1 tolerance any method reaches: the kernel is float32 and sums to
#: 1, so rounding its values alone moves it by up to 2⁻²⁴ in L1.
MIN_TOLERANCE = 2.0**-24


@dataclass(frozen=True)
class Plan:
    """A method and sample count, with the error and time they are expected to give."""

    method: str
    sampling: str
    samples: int | None
    predicted_l1: float
    predicted_time_s: float


def _model(method: str, sampling: str, diameter_px: float, aperture: Aperture | None) -> tuple[float, float]:
    """(coefficient, exponent) of L1 ≈ coefficient · (A / N)^exponent (raster's coefficient includes 1/d)."""
    if method == "raster":
        c, a = _RASTER
        c = c / diameter_px
    else:
        c, a = _MC_STRATIFIED if sampling == "stratified" else _MC_INDEPENDENT
    if aperture is not None and aperture.mask is not None:
        c *= _MASK_ERROR[method]
    return c, a


def predicted_l1(method: str, sampling: str, diameter_px: float, samples: int | None, aperture: Aperture | None = None) -> float:
    """Expected L1 error against ``exact`` (per channel; see the module notes), for ``aperture`` where given."""
    if method == "exact":
        return 0.0
    c, a = _model(method, sampling, diameter_px, aperture)
    return c * (math.pi * diameter_px**2 / 4.0 / samples) ** a


def _samples_for(method: str, sampling: str, diameter_px: float, tolerance: float, aperture: Aperture | None = None) -> int:
    c, a = _model(method, sampling, diameter_px, aperture)
    n = math.pi * diameter_px**2 / 4.0 * (c / tolerance) ** (1.0 / a)
    return int(min(max(math.ceil(n), _MIN_SAMPLES), _MAX_SAMPLES))


def _time(method: str, aperture: Aperture, diameter_px: float, size: int, samples: int | None) -> float:
    """Expected time of one kernel: one channel's, three times with ``chromatic`` (module notes)."""
    channels = 1 if aperture.chromatic is None else 3
    return channels * _channel_time(method, aperture, diameter_px, size, samples)


def _channel_time(method: str, aperture: Aperture, diameter_px: float, size: int, samples: int | None) -> float:
    mask = aperture.mask
    if method == "exact" and mask is not None:
        cell_px = mask.cell * diameter_px * math.sqrt(math.pi) / 2.0 * max(aperture.squeeze, 1.0 / aperture.squeeze) ** 0.5
        return _EXACT_PER_MASK_SEGMENT_PIXEL * mask_border_segments(aperture) * (cell_px + 2.0) ** 2
    if method == "exact" and aperture.rim != 0.0:
        return _EXACT_RIM_PER_PIXEL * size * size
    if method == "exact":
        edges = 4 if aperture.is_circle else len(aperture.vertices())
        return min(_EXACT_PER_CELL_EDGE * (size + 1) ** 2 * edges, _EXACT_FIXED + _EXACT_PER_DIAMETER_PX * diameter_px)
    if method == "raster":
        passes = max(1, math.ceil(samples / (math.pi * diameter_px**2 / 4.0)))
        return _RASTER_FIXED + _RASTER_PER_PIXEL_PASS * size * size * passes
    per_sample = _MC_PER_SAMPLE
    if mask is not None:
        per_sample *= 1.0 + _MC_MASK_PER_STEP * math.log2(mask.transmission.size)
    return _MC_FIXED + per_sample * samples


def plan_kernel(
    aperture: Aperture,
    diameter_px: float,
    size: int,
    tolerance: float,
    method: str | None = None,
    *,
    count_startup: bool = False,
) -> Plan:
    """The cheapest way (or, with ``method``, the fewest samples) to reach L1 ≤ ``tolerance``.

    ``count_startup`` adds each method's one-time start-up to its time (a kernel
    drawn on its own: a GPU is not started for a kernel that ``exact`` draws sooner).
    """
    tolerance = check("tolerance", tolerance)
    if tolerance < MIN_TOLERANCE:
        raise InputError(
            f"tolerance must be at least {MIN_TOLERANCE:.3g}, the float32 rounding of a kernel that sums to 1 (got {tolerance!r})"
        )
    if method in ("mc", "raster"):
        smallest = predicted_l1(method, "stratified", diameter_px, _MAX_SAMPLES, aperture)
        if tolerance < smallest:
            raise InputError(
                f"tolerance must be at least {smallest:.3g} for method {method!r} on a {diameter_px:g}-px disc "
                f"({_MAX_SAMPLES} samples, the most it takes; method 'exact' reaches any tolerance) (got {tolerance!r})"
            )
    options = []
    for name, sampling in (("exact", "stratified"), ("mc", "stratified"), ("raster", "stratified")):
        if method is not None and name != method:
            continue
        samples = None if name == "exact" else _samples_for(name, sampling, diameter_px, tolerance, aperture)
        error = predicted_l1(name, sampling, diameter_px, samples, aperture)
        if error > tolerance * 1.000001:  # the sample count hit its cap
            continue
        cost = _time(name, aperture, diameter_px, size, samples) + (_STARTUP_S[name] if count_startup else 0.0)
        options.append(Plan(name, sampling, samples, error, cost))
    if not options:
        raise InputError(f"no sample count within {_MAX_SAMPLES} reaches tolerance {tolerance:g} with method {method!r}")
    return min(options, key=lambda plan: plan.predicted_time_s)
