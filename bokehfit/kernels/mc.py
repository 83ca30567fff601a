"""Monte-Carlo kernels on the GPU: the WGSL compute shader ``kernel_mc.wgsl``.

Samples are stratified by default: a jittered m × m grid over u ∈ [0, 1)² (the
sample count is rounded up to m²). The aperture samplers are continuous and
area-preserving, so each stratum covers an equal part of the aperture and a
pixel that an edge crosses sees a nearly fixed count; the L1 error then falls
as N^-3/4 instead of the N^-1/2 of independent samples (the benchmark
``benchmarks/kernel_convergence.py`` measures both).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from bokehfit.apertures import Aperture
from bokehfit.gpu import get_gpu
from bokehfit.gpu.compute import bind_buffers, dispatch
from bokehfit.gpu.layout import Struct
from bokehfit.gpu.shaders import load_shader

__all__ = ["KERNEL_PARAMS", "mc_counts", "prepare_pipeline"]

KERNEL_PARAMS = Struct(
    "KernelParams",
    (
        ("size", "u32"),
        ("samples", "u32"),
        ("strata", "u32"),
        ("stratified", "u32"),
        ("seed", "u32"),
        ("shape", "u32"),
        ("blades", "u32"),
        ("aspect", "f32"),
        ("scale", "f32"),
        ("cos_angle", "f32"),
        ("sin_angle", "f32"),
    ),
)
#: Most samples one dispatch takes (the sample index and its stride stay in u32).
MAX_SAMPLES = 2**31
_WORKGROUP = 256
_SAMPLES_PER_THREAD = 16


@lru_cache(maxsize=None)
def prepare_pipeline():
    """Open the GPU and compile ``kernel_mc.wgsl`` (once per process)."""
    import wgpu

    device = get_gpu().device
    code = load_shader("kernel_mc.wgsl", {"KernelParams": KERNEL_PARAMS.wgsl()})
    module = device.create_shader_module(label="kernel_mc", code=code)
    return device.create_compute_pipeline(layout=wgpu.AutoLayoutMode.auto, compute={"module": module, "entry_point": "main"})


def mc_counts(aperture: Aperture, scale: float, size: int, samples: int, seed: int, sampling: str) -> tuple[np.ndarray, int]:
    """Histogram of aperture samples on the size × size grid, and the samples drawn.

    ``scale`` is negative for the near side (180° rotation).
    """
    import wgpu

    stratified = sampling == "stratified"
    strata = math.isqrt(samples - 1) + 1 if stratified else 0
    drawn = strata * strata if stratified else samples
    if drawn > MAX_SAMPLES:
        raise ValueError(f"samples must be at most {MAX_SAMPLES} (got {samples})")
    gpu = get_gpu()
    device = gpu.device
    angle = math.radians(aperture.angle_deg)
    params = KERNEL_PARAMS.pack(
        size=size,
        samples=drawn,
        strata=strata,
        stratified=int(stratified),
        seed=seed,
        shape=aperture.spec.shader_id,
        blades=aperture.blades or 0,
        aspect=aperture.aspect or 1.0,
        scale=scale,
        cos_angle=math.cos(angle),
        sin_angle=math.sin(angle),
    )
    uniform = device.create_buffer_with_data(data=params, usage=wgpu.BufferUsage.UNIFORM)
    counts = device.create_buffer(size=4 * size * size, usage=wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.COPY_SRC)
    pipeline = prepare_pipeline()
    groups = min(-(-drawn // (_WORKGROUP * _SAMPLES_PER_THREAD)), device.limits["max-compute-workgroups-per-dimension"])
    dispatch(device, pipeline, bind_buffers(device, pipeline, uniform, counts), max(groups, 1))
    data = device.queue.read_buffer(counts)
    return np.frombuffer(data, dtype=np.uint32).reshape(size, size), drawn
