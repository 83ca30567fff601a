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

The time models are rough costs on the slowest adapter bokehfit supports
(Mesa lavapipe on two cores): ``exact`` 2.5e-8 s per pixel-corner and outline
edge; ``mc`` 2.2e-8 s per sample plus 5 ms; ``raster`` 1e-9 s per pixel and
pass plus 10 ms (the fixed costs are upload, dispatch and read-back; the
one-time start-up of the GPU is not counted). They only rank the methods, so a faster
GPU changes the choice little: it favours the sampling methods sooner.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from bokehfit.apertures import Aperture
from bokehfit.errors import InputError
from bokehfit.validate import RANGES, check

__all__ = ["MIN_TOLERANCE", "Plan", "plan_kernel", "predicted_l1"]

#: (coefficient, exponent) of the error models above.
_MC_STRATIFIED = (1.0, 0.74)
_MC_INDEPENDENT = (0.80, 0.50)
_RASTER = (2.0, 0.75)
#: Cost models (seconds).
_EXACT_PER_CELL_EDGE = 2.5e-8
_MC_PER_SAMPLE = 2.2e-8
_RASTER_PER_PIXEL_PASS = 1e-9
_MC_FIXED = 5e-3
_RASTER_FIXED = 1e-2
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


def predicted_l1(method: str, sampling: str, diameter_px: float, samples: int | None) -> float:
    """Expected L1 error against ``exact`` (see the module notes)."""
    if method == "exact":
        return 0.0
    area = math.pi * diameter_px**2 / 4.0
    if method == "raster":
        c, a = _RASTER
        return c / diameter_px * (area / samples) ** a
    c, a = _MC_STRATIFIED if sampling == "stratified" else _MC_INDEPENDENT
    return c * (area / samples) ** a


def _samples_for(method: str, sampling: str, diameter_px: float, tolerance: float) -> int:
    area = math.pi * diameter_px**2 / 4.0
    if method == "raster":
        c, a = _RASTER
        n = area * (c / (diameter_px * tolerance)) ** (1.0 / a)
    else:
        c, a = _MC_STRATIFIED if sampling == "stratified" else _MC_INDEPENDENT
        n = area * (c / tolerance) ** (1.0 / a)
    return int(min(max(math.ceil(n), _MIN_SAMPLES), _MAX_SAMPLES))


def _time(method: str, aperture: Aperture, diameter_px: float, size: int, samples: int | None) -> float:
    if method == "exact":
        edges = 4 if aperture.is_circle else len(aperture.vertices())
        return _EXACT_PER_CELL_EDGE * (size + 1) ** 2 * edges
    if method == "raster":
        passes = max(1, math.ceil(samples / (math.pi * diameter_px**2 / 4.0)))
        return _RASTER_FIXED + _RASTER_PER_PIXEL_PASS * size * size * passes
    return _MC_FIXED + _MC_PER_SAMPLE * samples


def plan_kernel(aperture: Aperture, diameter_px: float, size: int, tolerance: float, method: str | None = None) -> Plan:
    """The cheapest way (or, with ``method``, the fewest samples) to reach L1 ≤ ``tolerance``."""
    tolerance = check("tolerance", tolerance)
    if tolerance < MIN_TOLERANCE:
        raise InputError(
            f"tolerance must be at least {MIN_TOLERANCE:.3g}, the float32 rounding of a kernel that sums to 1 (got {tolerance!r})"
        )
    if method in ("mc", "raster"):
        smallest = predicted_l1(method, "stratified", diameter_px, _MAX_SAMPLES)
        if tolerance < smallest:
            raise InputError(
                f"tolerance must be at least {smallest:.3g} for method {method!r} on a {diameter_px:g}-px disc "
                f"({_MAX_SAMPLES} samples, the most it takes; method 'exact' reaches any tolerance) (got {tolerance!r})"
            )
    options = []
    for name, sampling in (("exact", "stratified"), ("mc", "stratified"), ("raster", "stratified")):
        if method is not None and name != method:
            continue
        samples = None if name == "exact" else _samples_for(name, sampling, diameter_px, tolerance)
        error = predicted_l1(name, sampling, diameter_px, samples)
        if error > tolerance * 1.000001:  # the sample count hit its cap
            continue
        options.append(Plan(name, sampling, samples, error, _time(name, aperture, diameter_px, size, samples)))
    if not options:
        raise InputError(f"no sample count within {_MAX_SAMPLES} reaches tolerance {tolerance:g} with method {method!r}")
    return min(options, key=lambda plan: plan.predicted_time_s)
