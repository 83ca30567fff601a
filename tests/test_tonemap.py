"""The tone map: ``tone_map_srgb8`` of shaders/tonemap.wgsl against its NumPy twin.

``bokehfit render --out x.png`` writes PNGs through the NumPy ``tone_map_srgb8``
(bokehfit/scene/images.py); the viewer's page shows its frames through the WGSL
function of the same name (shaders/display.wgsl). Both scale by 2^EV, clip,
round to a 16-bit level, sRGB-encode and round to 8 bits. Here they run on the
same inputs: on every 16-bit level they agree exactly, and elsewhere they differ
only where float32 rounding of the scaled value crosses a rounding boundary
(by one code value).
"""

from __future__ import annotations

import numpy as np
import pytest

from bokehfit.io.colour import srgb_encode
from bokehfit.scene.images import tone_map_srgb8
from conftest import run_wgsl

#: Where the twins differ, the exact scaled value lies this close (in 16-bit levels) to half a
#: level, or the exact encoded value this close (in 8-bit codes) to half a code: float32 rounding.
LEVEL_SLACK = 0.02
CODE_SLACK = 1e-3
#: At most this share of random channels may differ (lavapipe: about 3 in a million).
MAX_MISMATCH_SHARE = 1e-4


def wgsl_tone_map(gpu, rgb: np.ndarray, exposure_ev: float) -> np.ndarray:
    """WGSL ``tone_map_srgb8`` of each row of an (N, 3) float32 array: (N, 3) uint8."""
    rows = np.concatenate([np.asarray(rgb, np.float32), np.full((len(rgb), 1), exposure_ev, np.float32)], axis=1)
    return run_wgsl(gpu, "vec4u(tone_map_srgb8(v.rgb, v.a), 0u)", rows, "vec4f", "vec4u")[:, :3].astype(np.uint8)


def assert_twins_agree(linear: np.ndarray, exposure_ev: float, wgsl: np.ndarray, numpy: np.ndarray) -> None:
    """|WGSL − NumPy| ≤ 1 code value, and only where float32 rounding explains it."""
    diff = wgsl.astype(int) - numpy.astype(int)
    assert np.abs(diff).max(initial=0) <= 1
    where = diff != 0
    assert np.count_nonzero(where) <= MAX_MISMATCH_SHARE * diff.size + 1, np.count_nonzero(where)
    level = np.clip(linear.astype(np.float64)[where] * 2.0**exposure_ev, 0.0, 1.0) * 65535.0
    code = srgb_encode(np.rint(level) / 65535.0) * 255.0
    explained = (np.abs(level - np.floor(level) - 0.5) < LEVEL_SLACK) | (np.abs(code - np.floor(code) - 0.5) < CODE_SLACK)
    assert explained.all(), f"unexplained differences at {linear[where][~explained][:5]}"


def test_wgsl_tone_map_is_the_numpy_twin_on_every_16_bit_level(gpu):
    levels = (np.arange(65536, dtype=np.float64) / 65535.0).astype(np.float32)
    rgb = np.stack([levels, levels[::-1], np.roll(levels, 12345)], axis=-1)
    np.testing.assert_array_equal(wgsl_tone_map(gpu, rgb, 0.0), tone_map_srgb8(rgb[None], 0.0)[0])


@pytest.mark.parametrize("exposure_ev", [0.0, 1.0, -2.0, 0.5, 3.3])
def test_wgsl_tone_map_matches_its_numpy_twin(gpu, exposure_ev):
    rng = np.random.default_rng(17)
    # Across [−0.1, 1.4] (negative and clipped light), and crowded near black where sRGB is steepest.
    linear = np.concatenate([rng.uniform(-0.1, 1.4, (60_000, 3)), rng.random((60_000, 3)) ** 6]).astype(np.float32)
    wgsl = wgsl_tone_map(gpu, linear, exposure_ev)
    assert_twins_agree(linear, exposure_ev, wgsl, tone_map_srgb8(linear[None], exposure_ev)[0])


def test_wgsl_srgb_encode_is_the_numpy_twin(gpu):
    x = np.linspace(0.0, 1.0, 100_001, dtype=np.float32)
    rows = np.stack([x, x, x, np.zeros_like(x)], axis=-1)
    got = run_wgsl(gpu, "vec4f(srgb_encode(v.rgb), 0.0).xy", rows, "vec4f", "vec2f")[:, 0]
    np.testing.assert_allclose(got, srgb_encode(x), rtol=0, atol=1e-6)


def test_the_pages_display_pass_shows_what_a_png_of_the_render_holds(gpu):
    """display.wgsl, as served to the page: the accumulation buffer's mean through the WGSL tone map, as RGBA."""
    import wgpu

    from bokehfit.gpu.compute import dispatch
    from bokehfit.scene.renderer import RENDER_PARAMS, set_tile
    from bokehfit.view.wgsl import DISPLAY_INTERFACE, display_source

    width, height, exposure_ev = 37, 23, 1.0
    rng = np.random.default_rng(5)
    count = rng.choice([1.0, 2.0, 4.0, 8.0], (height * width, 1)).astype(np.float32)  # exact divisions
    mean = rng.uniform(-0.05, 0.7, (height * width, 3)).astype(np.float32)
    accum = np.concatenate([mean * count, count], axis=1).astype(np.float32)
    record = np.zeros((), dtype=RENDER_PARAMS.dtype)
    record["image_size"] = (width, height)
    set_tile(record, (0, 0, width, height))

    device = gpu.device
    module = device.create_shader_module(label="display", code=display_source())
    pipeline = device.create_compute_pipeline(
        layout=wgpu.AutoLayoutMode.auto, compute={"module": module, "entry_point": "display", "constants": {"exposure_ev": exposure_ev}}
    )
    params = device.create_buffer_with_data(data=record.tobytes(), usage=wgpu.BufferUsage.UNIFORM)
    source = device.create_buffer_with_data(data=accum.tobytes(), usage=wgpu.BufferUsage.STORAGE)
    rgba = device.create_buffer(size=4 * width * height, usage=wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.COPY_SRC)
    group = DISPLAY_INTERFACE.bind(device, pipeline, params=params, accum=source, rgba=rgba)
    gx, gy = DISPLAY_INTERFACE.workgroup_size
    dispatch(device, pipeline, group, -(-width // gx), -(-height // gy))
    shown = np.frombuffer(device.queue.read_buffer(rgba), dtype=np.uint8).reshape(height, width, 4)

    assert (shown[..., 3] == 255).all()
    image = (accum[:, :3] / np.maximum(accum[:, 3:], 1.0)).reshape(height, width, 3)
    assert_twins_agree(image, exposure_ev, shown[..., :3], tone_map_srgb8(image, exposure_ev))
