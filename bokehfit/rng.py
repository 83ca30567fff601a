"""NumPy twins of ``shaders/rng.wgsl``: the PCG hash and its [0, 1) floats (design.md §5)."""

from __future__ import annotations

import numpy as np

__all__ = ["pcg_hash", "rand_bits", "bits_to_unit_float", "rand_unit_float"]


def pcg_hash(v) -> np.ndarray:
    """PCG-RXS-M-XS hash of uint32 values, bit for bit as in WGSL (wrapping uint32 maths)."""
    v = np.asarray(v, dtype=np.uint32)
    with np.errstate(over="ignore"):
        state = v * np.uint32(747796405) + np.uint32(2891336453)
        word = ((state >> ((state >> np.uint32(28)) + np.uint32(4))) ^ state) * np.uint32(277803737)
    return (word >> np.uint32(22)) ^ word


def rand_bits(pixel, sample, dimension) -> np.ndarray:
    """Random bits for one (pixel, sample, dimension), as ``rand_bits`` in WGSL."""
    return pcg_hash(np.asarray(pixel, np.uint32) ^ pcg_hash(np.asarray(sample, np.uint32) ^ pcg_hash(dimension)))


def bits_to_unit_float(bits) -> np.ndarray:
    """Top 24 bits times 2⁻²⁴: float32 in [0, 1), never 1.0."""
    return (np.asarray(bits, dtype=np.uint32) >> np.uint32(8)).astype(np.float32) * np.float32(2.0**-24)


def rand_unit_float(pixel, sample, dimension) -> np.ndarray:
    """Uniform float32 in [0, 1) for one (pixel, sample, dimension)."""
    return bits_to_unit_float(rand_bits(pixel, sample, dimension))
