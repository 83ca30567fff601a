"""Monte-Carlo kernels on the GPU: the WGSL compute shader ``kernel_mc.wgsl``.

Samples are stratified by default: a jittered m × m grid over u ∈ [0, 1)² (the
sample count is rounded up to m²). The aperture samplers are continuous and
area-preserving, so each stratum covers an equal part of the aperture and a
pixel that an edge crosses sees a nearly fixed count; the L1 error then falls
as N^-3/4 instead of the N^-1/2 of independent samples (the benchmark
``benchmarks/kernel_convergence.py`` measures both).

The histogram is one u32 per pixel in a storage buffer. Where ``size²·4``
bytes exceed the adapter's ``max-storage-buffer-binding-size`` (128 MiB on
many adapters: 5792² pixels), the frame is counted in bands of whole rows,
one dispatch each; every band draws the same samples, so the result is the
same as in one pass, at the cost of drawing them once per band.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from bokehfit.apertures import Aperture
from bokehfit.errors import InputError
from bokehfit.gpu import AdapterChoice, get_gpu
from bokehfit.gpu.compute import Binding, ComputeInterface, dispatch
from bokehfit.gpu.layout import Struct
from bokehfit.gpu.shaders import APERTURE_PARAMS, MASK_TABLE_BINDING, MASK_TABLE_READ, load_shader, mask_table_data

__all__ = ["KERNEL_INTERFACE", "KERNEL_PARAMS", "band_rows", "kernel_mc_source", "mc_counts", "prepare_pipeline"]

KERNEL_PARAMS = Struct(
    "KernelParams",
    (
        ("size", "u32"),
        ("samples", "u32"),
        ("strata", "u32"),
        ("stratified", "u32"),
        ("seed", "u32"),
        ("scale", "f32"),
        ("row_first", "u32"),
        ("rows", "u32"),
    ),
)
#: Most samples one dispatch takes (the sample index and its stride stay in u32).
MAX_SAMPLES = 2**31
#: Bind group 0 and workgroup size of ``kernel_mc.wgsl`` (its generated include ``interface``).
KERNEL_INTERFACE = ComputeInterface(
    (
        Binding("params", "uniform", "KernelParams"),
        Binding("counts", "storage, read_write", "array<atomic<u32>>"),
        Binding("aperture", "uniform", "ApertureParams"),
        MASK_TABLE_BINDING,
    ),
    workgroup_size=(256,),
)
_SAMPLES_PER_THREAD = 16


def kernel_mc_source() -> str:
    """The whole ``kernel_mc.wgsl``, every include resolved (with the current :data:`KERNEL_INTERFACE`)."""
    return load_shader("kernel_mc.wgsl", {"KernelParams": KERNEL_PARAMS.wgsl(), "interface": KERNEL_INTERFACE.wgsl(), "mask_table": MASK_TABLE_READ})


@lru_cache(maxsize=None)
def prepare_pipeline(adapter: AdapterChoice | None = None):
    """Open the GPU that ``adapter`` chooses and compile ``kernel_mc.wgsl`` (once per choice)."""
    import wgpu

    device = get_gpu(adapter).device
    module = device.create_shader_module(label="kernel_mc", code=kernel_mc_source())
    return device.create_compute_pipeline(layout=wgpu.AutoLayoutMode.auto, compute={"module": module, "entry_point": "main"})


def band_rows(limits, size: int, max_band_bytes: int | None = None) -> int:
    """Rows of a size-wide u32 histogram that one storage binding holds (at most ``size``).

    ``limits`` is the device's ``limits`` mapping; ``max_band_bytes`` lowers
    the bound further (tests use it to split small frames).
    """
    allowed = min(limits["max-storage-buffer-binding-size"], limits["max-buffer-size"])
    if max_band_bytes is not None:
        allowed = min(allowed, max_band_bytes)
    rows = allowed // (4 * size)
    if rows < 1:
        raise InputError(
            f"size must be at most {allowed // 4} for method 'mc': one row of the kernel must fit in "
            f"the adapter's storage binding of {allowed} bytes (got {size})"
        )
    return min(rows, size)


def mc_counts(
    aperture: Aperture,
    scale: float,
    size: int,
    samples: int,
    seed: int,
    sampling: str,
    *,
    max_band_bytes: int | None = None,
    adapter: AdapterChoice | None = None,
    field_position=None,
) -> tuple[np.ndarray, int]:
    """Histogram of aperture samples on the size × size grid, and the samples drawn.

    The aperture is sampled by the WGSL twin of :meth:`Aperture.sample`
    (every §3b feature; ``field_position`` places the vignetting cut; the
    near side is :meth:`Aperture.near`). ``scale`` < 0 turns the points by
    180° (the old near side; only the shape turns, not the cut). Frames larger
    than one storage binding are counted in bands (see the module notes).
    ``adapter`` chooses the GPU (:func:`bokehfit.gpu.get_gpu`).
    """
    import wgpu

    stratified = sampling == "stratified"
    strata = math.isqrt(samples - 1) + 1 if stratified else 0
    drawn = strata * strata if stratified else samples
    if drawn > MAX_SAMPLES:
        raise InputError(f"samples must be at most {math.isqrt(MAX_SAMPLES) ** 2} for method 'mc' (got {samples})")
    gpu = get_gpu(adapter)
    device = gpu.device
    rows = band_rows(device.limits, size, max_band_bytes)
    values = dict(size=size, samples=drawn, strata=strata, stratified=int(stratified), seed=seed, scale=scale)
    shape_params = device.create_buffer_with_data(
        data=APERTURE_PARAMS.pack(**aperture.shader_params(field_position)), usage=wgpu.BufferUsage.UNIFORM
    )
    mask_table = device.create_buffer_with_data(data=mask_table_data(aperture).tobytes(), usage=wgpu.BufferUsage.STORAGE)
    pipeline = prepare_pipeline(adapter)
    groups = min(-(-drawn // (KERNEL_INTERFACE.threads * _SAMPLES_PER_THREAD)), device.limits["max-compute-workgroups-per-dimension"])
    histogram = np.empty((size, size), dtype=np.uint32)
    for first in range(0, size, rows):
        band = min(rows, size - first)
        params = KERNEL_PARAMS.pack(**values, row_first=first, rows=band)
        uniform = device.create_buffer_with_data(data=params, usage=wgpu.BufferUsage.UNIFORM)
        counts = device.create_buffer(size=4 * size * band, usage=wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.COPY_SRC)
        bind_group = KERNEL_INTERFACE.bind(device, pipeline, params=uniform, counts=counts, aperture=shape_params, mask_table=mask_table)
        dispatch(device, pipeline, bind_group, max(groups, 1))
        histogram[first : first + band] = np.frombuffer(device.queue.read_buffer(counts), dtype=np.uint32).reshape(band, size)
        counts.destroy()
    return histogram, drawn
