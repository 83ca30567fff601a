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

The real-lens features of design.md §3b are in every method: rounded blades,
the squeeze and the vignetting cut through the exact outline (``exact``), the
WGSL twin ``sample_aperture_params`` (``mc``) and the outline's polygon
(``raster``); ``rim`` is tabulated in ``exact``
(:func:`bokehfit.kernels.rim.rim_coverage`, with a stated bound), drawn
with its density in ``mc`` and weighted per fragment in ``raster``.
``chromatic`` gives three channels (red, green, blue), the red and blue discs
scaled by (1 + red) and (1 + blue). The near side is :meth:`Aperture.near`.

A ``mask`` aperture (design.md §3b): ``exact`` integrates its piecewise-constant
transmission over each pixel exactly, at any angle and squeeze
(:func:`bokehfit.kernels.masks.mask_coverage`); ``mc`` samples it with the
WGSL twin ``sample_mask`` from the CDF tables in a storage buffer; ``raster``
draws its transmission as a texture on the image's quad, super-sampled as the
outlines are (:mod:`bokehfit.kernels.raster`).

Vignetting: a kernel is always renormalised to sum to 1 (per channel); the
light the barrel stops is reported as :attr:`Kernel.transmitted`, the share
of the unclipped aperture's light that passes (1 without vignetting).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np

from bokehfit.apertures import Aperture
from bokehfit.errors import InputError
from bokehfit.gpu.runtime import AdapterChoice
from bokehfit.kernels.accuracy import plan_kernel
from bokehfit.kernels.exact import coverage, quadrant_area
from bokehfit.kernels.rim import rim_coverage
from bokehfit.kernels.masks import mask_coverage
from bokehfit.validate import RANGES, check

__all__ = ["AUTO", "METHODS", "SAMPLINGS", "SIDES", "Kernel", "KernelMethod", "KernelClippedWarning", "compute_kernel", "render_kernel"]

SIDES = ("far", "near")
#: Sample patterns of ``mc``: a jittered grid over u, or independent u.
SAMPLINGS = ("stratified", "independent")
#: The ``method`` that picks one for a kernel drawn on its own: the cheapest that meets the
#: tolerance, the one-time start-up of its device included (no GPU is started for a kernel
#: that ``exact`` draws sooner); ``exact`` when no tolerance is given.
AUTO = "auto"
#: Default sample count of the sampling methods.
DEFAULT_SAMPLES = 2**22
#: Largest kernel frame (pixels a side), disc diameter and sample count accepted
#: (bokehfit.validate.RANGES says why).
MAX_SIZE = int(RANGES["kernel_size"].high)
MAX_DIAMETER_PX = RANGES["diameter_px"].high
MAX_SAMPLES = int(RANGES["kernel_samples"].high)


class KernelClippedWarning(UserWarning):
    """Part of the disc falls outside the kernel's frame; the rest is renormalised."""


@dataclass(frozen=True)
class Kernel:
    """A rendered kernel and how it was made."""

    image: np.ndarray  #: float32 (size, size), or (size, size, 3) red/green/blue with ``chromatic``; each channel sums to 1
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
    #: share of the unclipped aperture's light the vignetting passes at ``field_position`` (design.md §3b)
    transmitted: float = 1.0
    field_position: tuple[float, float] | None = None
    #: stated L1 bound of a tabulated ``exact`` kernel (``rim``); None where exact to rounding or sampled
    error_bound: float | None = None


@dataclass(frozen=True)
class KernelMethod:
    """A registry entry: one-time start-up, then the renderer."""

    #: (adapter choice) → opens what the method runs on (adapter, context,
    #: compiled shaders); returns its description, or None for CPU-only methods.
    prepare: Callable[..., str | None]
    #: (aperture as seen from its side, scale, size, samples, seed, sampling,
    #: adapter choice, field position) → (unnormalised light, samples drawn or
    #: None, stated L1 bound or None).
    render: Callable[..., tuple[np.ndarray, int | None, float | None]]


def _exact(aperture, scale, size, samples, seed, sampling, adapter=None, field_position=None):
    if aperture.spec.tabulated:
        return mask_coverage(aperture, scale, size), None, None
    if aperture.rim != 0.0:
        image, bound = rim_coverage(aperture, scale, size, field_position)
        return image, None, bound
    return coverage(aperture, scale, size, field_position=field_position), None, None


def _prepare_mc(adapter=None):
    from bokehfit.gpu import get_gpu
    from bokehfit.kernels.mc import prepare_pipeline

    prepare_pipeline(adapter)
    return get_gpu(adapter).describe()


def _mc(aperture, scale, size, samples, seed, sampling, adapter=None, field_position=None):
    from bokehfit.kernels.mc import mc_counts

    counts, drawn = mc_counts(aperture, scale, size, samples, seed, sampling, adapter=adapter, field_position=field_position)
    return counts.astype(np.float64), drawn, None


def _prepare_raster(adapter=None):
    from bokehfit.kernels.raster import gl_renderer

    return f"{gl_renderer()} (OpenGL)"


def _raster(aperture, scale, size, samples, seed, sampling, adapter=None, field_position=None):
    from bokehfit.kernels.raster import raster_counts

    from bokehfit.kernels.raster import MAX_PASSES

    # A sub-pixel disc asks for more super-samples per pixel than the float32
    # target counts exactly: it gets the most there are, MAX_PASSES, which
    # already resolves its coverage far below float32 rounding.
    area_px = scale * scale
    passes = min(max(1, math.ceil(samples / area_px)), MAX_PASSES)
    counts, drawn = raster_counts(aperture, scale, size, passes, seed, field_position=field_position)
    return counts.astype(np.float64), int(round(drawn * area_px)), None


METHODS: dict[str, KernelMethod] = {
    "exact": KernelMethod(lambda adapter=None: None, _exact),
    "mc": KernelMethod(_prepare_mc, _mc),
    "raster": KernelMethod(_prepare_raster, _raster),
}


def _clipped_fraction(aperture: Aperture, scale: float, size: int, field_position=None) -> float:
    """Share of the disc's area outside the frame (exact; the frame is centred on the light)."""
    half = size / 2.0
    if aperture.extent() * scale <= half:
        return 0.0
    if aperture.spec.tabulated:  # the transmitted area is 1: what the frame holds is exact
        return max(0.0, 1.0 - float(mask_coverage(aperture, scale, size).sum()) / (scale * scale))
    outline = aperture.outline(field_position)
    area = outline.area() * scale * scale
    if not area > 0.0:
        return 0.0
    corners = quadrant_area(outline, scale, [-half, half], [-half, half])
    inside = corners[1, 1] - corners[0, 1] - corners[1, 0] + corners[0, 0]
    return max(0.0, 1.0 - inside / area)


def compute_kernel(
    aperture: Aperture,
    diameter_px: float,
    size: int,
    *,
    side: str = "far",
    method: str | None = None,
    samples: int | None = None,
    field_position=None,
    sampling: str = "stratified",
    seed: int = 0,
    tolerance: float | None = None,
    adapter: AdapterChoice | None = None,
) -> Kernel:
    """Render a kernel and report how: see :func:`render_kernel` for the parameters."""
    if not isinstance(aperture, Aperture):
        raise InputError(
            f"aperture must be an Aperture, built once by bokehfit.apertures.make_aperture (got {aperture!r:.60})"
        )
    diameter_px = check("diameter_px", diameter_px)
    size = check("kernel_size", size, name="size")
    if side not in SIDES:
        raise InputError(f"side must be one of {', '.join(SIDES)} (got {side!r})")
    if method is not None and method not in METHODS and method != AUTO:
        raise InputError(f"method must be one of {', '.join([*METHODS, AUTO])} (got {method!r})")
    if field_position is not None:
        pair = np.asarray(field_position, dtype=object)
        if pair.shape != (2,):
            raise InputError(f"field_position must be a pair (x, y) in half-diagonals, y up (got {field_position!r})")
        field_position = tuple(float(check("field_position", v)) for v in pair)
    elif aperture.vignetting is not None:
        field_position = (0.0, 0.0)  # as Aperture.sample: the frame's centre
    predicted = None
    if tolerance is not None:
        if samples is not None:
            raise InputError("give samples or tolerance, not both")
        alone = method == AUTO
        plan = plan_kernel(aperture, diameter_px, size, tolerance, None if alone else method, count_startup=alone)
        method, samples, sampling, predicted = plan.method, plan.samples, plan.sampling, plan.predicted_l1
    method = "exact" if method in (None, AUTO) else method
    if sampling not in SAMPLINGS:
        raise InputError(f"sampling must be one of {', '.join(SAMPLINGS)} (got {sampling!r})")
    samples = DEFAULT_SAMPLES if samples is None else check("kernel_samples", samples, name="samples")
    seed = check("seed", seed)

    # Equal-area convention (design.md §4): a unit-area shape scaled by d·√π/2
    # has the area of a circle of diameter d. Near side: Aperture.near (§3b).
    scale = diameter_px * math.sqrt(math.pi) / 2.0
    seen = aperture if side == "far" else aperture.near()
    transmitted = 1.0 if seen.vignetting is None or field_position is None else seen.area(field_position)
    if not transmitted > 0.0:
        raise InputError(
            f"vignetting stops all the light at field_position={field_position} (vignetting={aperture.vignetting})"
        )
    channels = [1.0] if seen.chromatic is None else [1.0 + seen.chromatic.red, 1.0, 1.0 + seen.chromatic.blue]
    start = time.perf_counter()
    device = METHODS[method].prepare(adapter)
    prepared = time.perf_counter()
    images, clipped, drawn, bounds = [], 0.0, None, []
    for channel_scale in channels:
        counts, drawn, bound = METHODS[method].render(
            seen, scale * channel_scale, size, int(samples), int(seed), sampling, adapter, field_position
        )
        total = counts.sum()
        if not total > 0.0:
            raise InputError(f"the disc falls outside the {size}×{size} frame (diameter_px={diameter_px:g})")
        clipped = max(clipped, _clipped_fraction(seen, scale * channel_scale, size, field_position))
        images.append(counts / total)
        if bound is not None:
            bounds.append(bound)
    elapsed = time.perf_counter() - prepared
    if clipped > 1e-9:
        warnings.warn(
            KernelClippedWarning(
                f"kernel clipped: {100 * clipped:.3g}% of the light of a {diameter_px:g}-px disc falls "
                f"outside the {size}×{size} frame; the rest is renormalised to sum to 1"
            ),
            stacklevel=3,
        )
    image = (images[0] if len(images) == 1 else np.stack(images, axis=-1)).astype(np.float32)
    return Kernel(image, aperture, diameter_px, side, method, drawn, elapsed, prepared - start, device, clipped, predicted,
                  transmitted, field_position, max(bounds) if bounds else None)


def render_kernel(
    aperture: Aperture,
    diameter_px: float,
    size: int,
    *,
    side: str = "far",
    method: str | None = None,
    samples: int | None = None,
    field_position=None,
    sampling: str = "stratified",
    seed: int = 0,
    tolerance: float | None = None,
    adapter: AdapterChoice | None = None,
) -> np.ndarray:
    """Point-light defocus kernel: float32 (size, size) (or (size, size, 3) with ``chromatic``), summing to 1.

    Parameters
    ----------
    aperture : Aperture
        The aperture, its shape, angle and real-lens features (design.md §3, §3b)
        in one :class:`~bokehfit.apertures.Aperture`, built by
        :func:`bokehfit.apertures.make_aperture`. The kernel takes nothing
        else of the aperture.
    diameter_px : float
        Diameter of the circle with the disc's area, pixels (equal-area convention).
    size : int
        Frame side, pixels. The light projects to ((size−1)/2, (size−1)/2) in
        pixel-centre coordinates, y up on screen.
    side : {"far", "near"}
        A light behind the focus plane shows the aperture upright; one in front
        shows it rotated by 180°.
    method : {"exact", "mc", "raster", "auto"}, optional
        See the module docstring. Default ``exact``; with ``tolerance`` and no
        method, the cheapest method that meets the tolerance; ``auto`` (``AUTO``)
        the same for a kernel drawn on its own, counting the one-time start-up of
        the method's device (so a small kernel is ``exact`` and starts no GPU).
        :attr:`Kernel.method` says which one drew it.
    samples : int, optional
        Point samples over the disc for ``mc`` and ``raster`` (default 2²²).
    field_position : (float, float), optional
        The disc's position from the image centre in half-diagonals, y up:
        where the vignetting cuts it (default the centre, (0, 0)). The
        kernel is renormalised; :attr:`Kernel.transmitted` from
        :func:`compute_kernel` is the share of light that passed.
    sampling : {"stratified", "independent"}
        Sample pattern of ``mc`` (``raster`` is always stratified).
    seed : int
        Random seed; the same seed gives the same kernel.
    tolerance : float, optional
        Largest L1 error against ``exact`` wanted: the method (unless given)
        and the sample count are chosen from the measured convergence models
        (:mod:`bokehfit.kernels.accuracy`) to meet it at the least cost.
    adapter : AdapterChoice, optional
        The WebGPU adapter of ``mc`` (:func:`bokehfit.gpu.get_gpu`); the best one found by default.

    Returns
    -------
    ndarray of shape (size, size) or (size, size, 3), float32
        Sums to 1 (each of red, green, blue with ``chromatic``; the red and
        blue discs are the green one scaled by 1 + red, 1 + blue; a near
        disc shows −red, −blue and −rim). If the disc is larger than the frame, the kernel is clipped,
        a :class:`KernelClippedWarning` says how much light was lost, and the
        visible part is renormalised.

    Raises
    ------
    ValueError
        (``bokehfit.errors.InputError``) naming the bad parameter.

    Examples
    --------
    >>> from bokehfit.apertures import make_aperture
    >>> k = render_kernel(make_aperture("hexagon", 20), 64, 128)
    >>> k.shape, round(float(k.sum()), 6)
    ((128, 128), 1.0)
    """
    return compute_kernel(
        aperture,
        diameter_px,
        size,
        side=side,
        method=method,
        samples=samples,
        field_position=field_position,
        sampling=sampling,
        seed=seed,
        tolerance=tolerance,
        adapter=adapter,
    ).image
