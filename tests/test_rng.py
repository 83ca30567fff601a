"""The PCG hash and its [0, 1) floats: NumPy twins (bokehfit/rng.py) against WGSL (shaders/rng.wgsl)."""

from __future__ import annotations

import numpy as np
import pytest

from bokehfit.rng import bits_to_unit_float, pcg_hash, rand_bits, rand_unit_float

#: Draws for the distribution checks of rand_unit_float.
N_DRAWS = 1_000_000
#: The mean of N_DRAWS uniform floats must be within this of 1/2: five standard
#: errors, 5 · (1/√12) / √N_DRAWS ≈ 1.44e-3.
MEAN_TOLERANCE = 5.0 / np.sqrt(12.0) / np.sqrt(N_DRAWS)
#: The largest float the top-24-bit construction can give (design.md §5).
LARGEST_UNIT_FLOAT = np.float32(1.0 - 2.0**-24)

MASK = 0xFFFFFFFF


def _pcg_hash_reference(v: int) -> int:
    """Jarzynski and Olano's pcg_hash in Python integers, written out independently."""
    state = (v * 747796405 + 2891336453) & MASK
    shift = ((state >> 28) + 4) & MASK
    word = (((state >> shift) ^ state) * 277803737) & MASK
    return ((word >> 22) ^ word) & MASK


def _hash_inputs() -> np.ndarray:
    """Edge values, every single bit, and a fixed-seed random spread of uint32."""
    edges = [0, 1, 2, 3, 0x7FFFFFFF, 0x80000000, 0x80000001, 0xFFFFFFFE, 0xFFFFFFFF, 0xDEADBEEF, 0x12345678]
    bits = [1 << k for k in range(32)]
    spread = np.random.default_rng(20240521).integers(0, 2**32, size=20_000, dtype=np.uint64)
    return np.concatenate([np.array(edges + bits, dtype=np.uint64), spread]).astype(np.uint32)


def test_pcg_hash_numpy_matches_integer_reference():
    values = _hash_inputs()[:2000]
    expected = np.array([_pcg_hash_reference(int(v)) for v in values], dtype=np.uint32)
    got = pcg_hash(values)
    assert got.dtype == np.uint32
    bad = np.flatnonzero(got != expected)
    assert bad.size == 0, f"pcg_hash({values[bad[0]]:#x}) = {got[bad[0]]:#x}, expected {expected[bad[0]]:#x}"


def test_pcg_hash_scalar_and_array_agree():
    assert int(pcg_hash(0)) == _pcg_hash_reference(0)
    assert int(pcg_hash(0xFFFFFFFF)) == _pcg_hash_reference(0xFFFFFFFF)


@pytest.mark.gpu
def test_pcg_hash_wgsl_matches_numpy_bit_exact(gpu, run_wgsl_u32):
    values = _hash_inputs()
    got = run_wgsl_u32(gpu, "pcg_hash(v)", values)
    expected = pcg_hash(values)
    bad = np.flatnonzero(got != expected)
    assert bad.size == 0, (
        f"{bad.size} mismatches; first: pcg_hash({values[bad[0]]:#x}) WGSL {got[bad[0]]:#x}, "
        f"NumPy {expected[bad[0]]:#x}"
    )


@pytest.mark.gpu
def test_rand_bits_and_rand_unit_float_wgsl_match_numpy(gpu, run_wgsl_u32x3):
    rng = np.random.default_rng(7)
    triples = rng.integers(0, 2**32, size=(5000, 3), dtype=np.uint64).astype(np.uint32)
    triples[:4] = [[0, 0, 0], [0xFFFFFFFF, 0xFFFFFFFF, 0xFFFFFFFF], [1, 2, 3], [0xFFFFFFFF, 0, 1]]
    bits = run_wgsl_u32x3(gpu, "rand_bits(v.x, v.y, v.z)", triples)
    np.testing.assert_array_equal(bits, rand_bits(triples[:, 0], triples[:, 1], triples[:, 2]))
    floats = run_wgsl_u32x3(gpu, "rand_unit_float(v.x, v.y, v.z)", triples, out_type="f32")
    expected = rand_unit_float(triples[:, 0], triples[:, 1], triples[:, 2])
    assert expected.dtype == np.float32
    np.testing.assert_array_equal(floats.view(np.uint32), expected.view(np.uint32))


def test_bits_to_unit_float_top_value_below_one_numpy():
    top = bits_to_unit_float(np.uint32(0xFFFFFFFF))
    assert top.dtype == np.float32
    assert top < 1.0
    assert top == LARGEST_UNIT_FLOAT
    assert bits_to_unit_float(np.uint32(0)) == 0.0
    # The naive f32(x) / 2^32 that design.md §5 forbids does round to 1.0, so
    # the check above is not vacuous.
    assert np.float32(0xFFFFFFFF) / np.float32(2.0**32) == 1.0


@pytest.mark.gpu
def test_bits_to_unit_float_wgsl_matches_numpy(gpu, run_wgsl_u32):
    edges = np.array([0, 1, 0xFF, 0x100, 0x7FFFFFFF, 0x80000000, 0xFFFFFF00, 0xFFFFFFFF], dtype=np.uint32)
    values = np.concatenate([edges, _hash_inputs()])
    got = run_wgsl_u32(gpu, "bits_to_unit_float(v)", values, out_type="f32")
    np.testing.assert_array_equal(got.view(np.uint32), bits_to_unit_float(values).view(np.uint32))
    top = got[np.flatnonzero(values == 0xFFFFFFFF)[0]]
    assert top < 1.0
    assert top == LARGEST_UNIT_FLOAT
    assert got.max() < 1.0


def _check_unit_floats(x: np.ndarray, where: str) -> None:
    assert x.dtype == np.float32
    assert x.min() >= 0.0, f"{where}: value below 0: {x.min()}"
    assert x.max() < 1.0, f"{where}: value {x.max()} not below 1"
    assert not np.any(x == 1.0)
    mean = float(x.mean(dtype=np.float64))
    assert abs(mean - 0.5) < MEAN_TOLERANCE, f"{where}: mean {mean} differs from 0.5 by more than {MEAN_TOLERANCE:.2e}"
    # Each of 16 equal bins must hold its share within five binomial standard errors.
    counts = np.bincount((x * 16).astype(np.int64), minlength=16)
    share = len(x) / 16
    assert np.all(np.abs(counts - share) < 5 * np.sqrt(share * (15 / 16))), f"{where}: bins {counts}"


def test_rand_unit_float_numpy_million_draws_in_unit_interval():
    pixel = np.arange(N_DRAWS, dtype=np.uint32)
    _check_unit_floats(rand_unit_float(pixel, 3, 0), "NumPy rand_unit_float")


@pytest.mark.gpu
def test_rand_unit_float_wgsl_million_draws_in_unit_interval(gpu, run_wgsl_u32):
    pixel = np.arange(N_DRAWS, dtype=np.uint32)
    x = run_wgsl_u32(gpu, "rand_unit_float(v, 3u, 0u)", pixel, out_type="f32")
    _check_unit_floats(x, "WGSL rand_unit_float")
    np.testing.assert_array_equal(x.view(np.uint32), rand_unit_float(pixel, 3, 0).view(np.uint32))
