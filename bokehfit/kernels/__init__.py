"""Point-light defocus kernels (design.md §6), by one of three methods.

``exact``
    Exact area coverage of the scaled, rotated shape on every pixel (the reference).
``mc``
    Monte Carlo on the GPU: a WGSL compute shader samples the aperture with
    stratified (jittered-grid) samples and counts them per pixel.
``raster``
    OpenGL rasterisation of the outline, super-sampled by jittered
    accumulation passes.

``samples`` always counts point samples over the disc: ``mc`` draws that many
points on the aperture; ``raster`` draws ⌈samples / disc area in px²⌉ passes,
so that both put the same number of samples in a pixel the disc covers.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np

from bokehfit.apertures import Aperture, make_aperture
from bokehfit.errors import InputError, check_positive
from bokehfit.kernels.accuracy import plan_kernel
from bokehfit.kernels.exact import coverage, quadrant_area

__all__ = ["METHODS", "SAMPLINGS", "SIDES", "Kernel", "KernelMethod", "KernelClippedWarning", "compute_kernel", "render_kernel"]

SIDES = ("far", "near")
#: Sample patterns of ``mc``: a jittered grid over u, or independent u.
SAMPLINGS = ("stratified", "independent")
#: Default sample count of the sampling methods.
DEFAULT_SAMPLES = 2**22
#: Largest kernel frame (pixels a side) and disc diameter accepted.
MAX_SIZE = 8192
MAX_DIAMETER_PX = 20000.0


class KernelClippedWarning(UserWarning):
    """Part of the disc falls outside the kernel's frame; the rest is renormalised."""


@dataclass(frozen=True)
class Kernel:
    """A rendered kernel and how it was made."""

    image: np.ndarray  #: float32 (size, size), sums to 1
    aperture: Aperture
    diameter_px: float
    side: str
    method: str
    samples: int | None  #: point samples over the disc (None for exact)
    time_s: float  #: rendering time
    setup_s: float  #: one-time start-up before it (adapter, context, shader compilation)
    device: str | None  #: adapter or GL renderer (None for exact)
    clipped_fraction: float  #: share of the disc's light outside the frame
    predicted_l1: float | None = None  #: expected L1 against exact, when planned from a tolerance


@dataclass(frozen=True)
class KernelMethod:
    """A registry entry: one-time start-up, then the renderer."""

    #: Opens what the method runs on (adapter, context, compiled shaders);
    #: returns its description, or None for CPU-only methods.
    prepare: Callable[[], str | None]
    #: (aperture, signed scale, size, samples, seed, sampling) →
    #: (unnormalised coverage, samples drawn or None).
    render: Callable[..., tuple[np.ndarray, int | None]]


def _exact(aperture, scale, size, samples, seed, sampling):
    return coverage(aperture, abs(scale), size, flip=scale < 0), None


def _prepare_mc():
    from bokehfit.gpu import get_gpu
    from bokehfit.kernels.mc import prepare_pipeline

    prepare_pipeline()
    return get_gpu().describe()


def _mc(aperture, scale, size, samples, seed, sampling):
    from bokehfit.kernels.mc import mc_counts

    counts, drawn = mc_counts(aperture, scale, size, samples, seed, sampling)
    return counts.astype(np.float64), drawn


def _prepare_raster():
    from bokehfit.kernels.raster import gl_renderer

    return f"{gl_renderer()} (OpenGL)"


def _raster(aperture, scale, size, samples, seed, sampling):
    from bokehfit.kernels.raster import raster_counts

    area_px = scale * scale
    passes = max(1, math.ceil(samples / area_px))
    counts, drawn = raster_counts(aperture, scale, size, passes, seed)
    return counts.astype(np.float64), int(round(drawn * area_px))


METHODS: dict[str, KernelMethod] = {
    "exact": KernelMethod(lambda: None, _exact),
    "mc": KernelMethod(_prepare_mc, _mc),
    "raster": KernelMethod(_prepare_raster, _raster),
}


def _check_size(size) -> int:
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or not 1 <= size <= MAX_SIZE:
        raise InputError(f"size must be an integer from 1 to {MAX_SIZE} (got {size!r})")
    return int(size)


def _clipped_fraction(aperture: Aperture, scale: float, size: int) -> float:
    """Share of the disc's area outside the frame (exact; the frame is centred on the light)."""
    half = size / 2.0
    if aperture.extent() * scale <= half:
        return 0.0
    corners = quadrant_area(aperture, scale, [-half, half], [-half, half])
    inside = corners[1, 1] - corners[0, 1] - corners[1, 0] + corners[0, 0]
    return max(0.0, 1.0 - inside / (scale * scale))


def compute_kernel(
    shape: str,
    angle_deg: float,
    diameter_px: float,
    size: int,
    *,
    side: str = "far",
    method: str | None = None,
    samples: int | None = None,
    blades: int | None = None,
    aspect: float | None = None,
    sampling: str = "stratified",
    seed: int = 0,
    tolerance: float | None = None,
) -> Kernel:
    """Render a kernel and report how: see :func:`render_kernel` for the parameters."""
    aperture = make_aperture(shape, angle_deg, blades=blades, aspect=aspect)
    diameter_px = check_positive("diameter_px", diameter_px)
    if diameter_px > MAX_DIAMETER_PX:
        raise InputError(f"diameter_px must be at most {MAX_DIAMETER_PX:g} (got {diameter_px!r})")
    size = _check_size(size)
    if side not in SIDES:
        raise InputError(f"side must be one of {', '.join(SIDES)} (got {side!r})")
    if method is not None and method not in METHODS:
        raise InputError(f"method must be one of {', '.join(METHODS)} (got {method!r})")
    predicted = None
    if tolerance is not None:
        if samples is not None:
            raise InputError("give samples or tolerance, not both")
        plan = plan_kernel(aperture, diameter_px, size, tolerance, method)
        method, samples, sampling, predicted = plan.method, plan.samples, plan.sampling, plan.predicted_l1
    method = method or "exact"
    if sampling not in SAMPLINGS:
        raise InputError(f"sampling must be one of {', '.join(SAMPLINGS)} (got {sampling!r})")
    if samples is None:
        samples = DEFAULT_SAMPLES
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or not 1 <= samples <= 2**31:
        raise InputError(f"samples must be an integer from 1 to 2**31 (got {samples!r})")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32:
        raise InputError(f"seed must be an integer from 0 to 2**32 - 1 (got {seed!r})")

    # Equal-area convention (design.md §4): a unit-area shape scaled by d·√π/2
    # has the area of a circle of diameter d. Near side: rotated by 180°.
    scale = diameter_px * math.sqrt(math.pi) / 2.0
    signed_scale = scale if side == "far" else -scale
    start = time.perf_counter()
    device = METHODS[method].prepare()
    prepared = time.perf_counter()
    counts, drawn = METHODS[method].render(aperture, signed_scale, size, int(samples), int(seed), sampling)
    elapsed = time.perf_counter() - prepared
    total = counts.sum()
    if not total > 0.0:
        raise InputError(f"the disc falls outside the {size}×{size} frame (diameter_px={diameter_px:g})")
    clipped = _clipped_fraction(aperture, scale, size)
    if clipped > 1e-9:
        warnings.warn(
            KernelClippedWarning(
                f"kernel clipped: {100 * clipped:.3g}% of the light of a {diameter_px:g}-px disc falls "
                f"outside the {size}×{size} frame; the rest is renormalised to sum to 1"
            ),
            stacklevel=3,
        )
    image = (counts / total).astype(np.float32)
    return Kernel(image, aperture, diameter_px, side, method, drawn, elapsed, prepared - start, device, clipped, predicted)


def render_kernel(
    shape: str,
    angle_deg: float,
    diameter_px: float,
    size: int,
    *,
    side: str = "far",
    method: str | None = None,
    samples: int | None = None,
    blades: int | None = None,
    aspect: float | None = None,
    sampling: str = "stratified",
    seed: int = 0,
    tolerance: float | None = None,
) -> np.ndarray:
    """Point-light defocus kernel: float32 (size, size), summing to 1.

    Parameters
    ----------
    shape : str
        Aperture shape (see ``bokehfit.apertures.SHAPES``).
    angle_deg : float
        Counter-clockwise rotation of the aperture, degrees (design.md §2).
    diameter_px : float
        Diameter of the circle with the disc's area, pixels (equal-area convention).
    size : int
        Frame side, pixels. The light projects to ((size−1)/2, (size−1)/2) in
        pixel-centre coordinates, y up on screen.
    side : {"far", "near"}
        A light behind the focus plane shows the aperture upright; one in front
        shows it rotated by 180°.
    method : {"exact", "mc", "raster"}, optional
        See the module docstring. Default ``exact``; with ``tolerance`` and no
        method, the cheapest method that meets the tolerance.
    samples : int, optional
        Point samples over the disc for ``mc`` and ``raster`` (default 2²²).
    blades, aspect : optional
        Blade count of an ``ngon``; width/height of a ``slit``.
    sampling : {"stratified", "independent"}
        Sample pattern of ``mc`` (``raster`` is always stratified).
    seed : int
        Random seed; the same seed gives the same kernel.
    tolerance : float, optional
        Largest L1 error against ``exact`` wanted: the method (unless given)
        and the sample count are chosen from the measured convergence models
        (:mod:`bokehfit.kernels.accuracy`) to meet it at the least cost.

    Returns
    -------
    ndarray of shape (size, size), float32
        Sums to 1. If the disc is larger than the frame, the kernel is clipped,
        a :class:`KernelClippedWarning` says how much light was lost, and the
        visible part is renormalised.

    Raises
    ------
    ValueError
        (``bokehfit.errors.InputError``) naming the bad parameter.

    Examples
    --------
    >>> k = render_kernel("hexagon", 20, 64, 128)
    >>> k.shape, round(float(k.sum()), 6)
    ((128, 128), 1.0)
    """
    return compute_kernel(
        shape,
        angle_deg,
        diameter_px,
        size,
        side=side,
        method=method,
        samples=samples,
        blades=blades,
        aspect=aspect,
        sampling=sampling,
        seed=seed,
        tolerance=tolerance,
    ).image
