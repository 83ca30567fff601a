"""Run the WGSL renderers through wgpu: tiles, progressive accumulation, read-back.

Two renderers, chosen by the scene's type:

``path tracing`` (:class:`~bokehfit.scene.geometry.Scene`, ``shaders/pathtrace.wgsl``)
    Every dispatch adds one sample (with its own sample index) to every pixel
    of a tile, into a float32 accumulation buffer; the image is the sum over
    the sample count.
``splatting`` (:class:`~bokehfit.scene.points.PointScene`, ``shaders/points.wgsl``)
    Each point light's aperture samples are counted in the pixels they reach,
    then added to the accumulation buffer with the light's weight. A light gets
    ``spp`` samples per pixel of its disc (at least ``spp``), on a jittered grid.

Images larger than the adapter allows in one binding (``max-storage-buffer-binding-size``,
16 bytes a pixel) or one dispatch (``max-compute-workgroups-per-dimension``) are
rendered tile by tile. The random streams depend on the pixel's place in the
whole image, so tiling does not change the result.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import lru_cache
from typing import Callable

import numpy as np

from bokehfit.gpu import get_gpu
from bokehfit.gpu.compute import bind_buffers, dispatch
from bokehfit.gpu.layout import Struct
from bokehfit.gpu.shaders import load_shader
from bokehfit.scene.camera import Lens, RenderSettings
from bokehfit.scene.geometry import BOX, MATERIAL, QUAD, SPHERE, Pose, Scene
from bokehfit.scene.wgsl import scene_wgsl
from bokehfit.scene.points import PointScene

__all__ = ["RENDER_PARAMS", "POINT_PARAMS", "RenderResult", "pathtrace_source", "render_params", "render_scene", "set_tile", "tile_plan", "total_work", "DEFAULT_MAX_TILE_PIXELS"]

RENDER_PARAMS = Struct(
    "RenderParams",
    (
        ("image_width", "u32"),
        ("image_height", "u32"),
        ("tile_x", "u32"),
        ("tile_y", "u32"),
        ("tile_width", "u32"),
        ("tile_height", "u32"),
        ("sample_index", "u32"),
        ("seed", "u32"),
        ("shape", "u32"),
        ("blades", "u32"),
        ("aspect", "f32"),
        ("cos_angle", "f32"),
        ("sin_angle", "f32"),
        ("aperture_scale", "f32"),
        ("focus_distance", "f32"),
        ("tan_half_x", "f32"),
        ("tan_half_y", "f32"),
        ("position_x", "f32"),
        ("position_y", "f32"),
        ("position_z", "f32"),
        ("right_x", "f32"),
        ("right_y", "f32"),
        ("right_z", "f32"),
        ("up_x", "f32"),
        ("up_y", "f32"),
        ("up_z", "f32"),
        ("forward_x", "f32"),
        ("forward_y", "f32"),
        ("forward_z", "f32"),
        ("max_depth", "u32"),
        ("rr_depth", "u32"),
    ),
)
POINT_PARAMS = Struct(
    "PointParams",
    (
        ("slope_x", "f32"),
        ("slope_y", "f32"),
        ("inv_depth", "f32"),
        ("weight_r", "f32"),
        ("weight_g", "f32"),
        ("weight_b", "f32"),
        ("stream", "u32"),
        ("strata", "u32"),
        ("first", "u32"),
        ("count", "u32"),
    ),
)

#: Largest tile by default (pixels): bounds one dispatch's work, so that a
#: desktop GPU's watchdog never sees a long one.
DEFAULT_MAX_TILE_PIXELS = 2**22
_ACCUM_BYTES = 16  # vec4f per pixel
_TILE_GROUP = 8  # pathtrace.wgsl: @workgroup_size(8, 8)
_LINEAR_GROUP = 256  # points.wgsl: @workgroup_size(256)
#: Aperture samples of one light per splat dispatch.
_SPLAT_CHUNK = 2**22
#: Most jittered-grid strata a side for one light (strata² stays below 2³¹).
_MAX_STRATA = 46340
#: Wait for the adapter (and advance the progress bar) about this often, seconds.
_SYNC_INTERVAL_S = 0.25


@dataclass(frozen=True)
class RenderResult:
    """A rendered image and how it was made."""

    image: np.ndarray  #: float32 (height, width, 3), linear radiance
    scene: str
    lens: Lens
    settings: RenderSettings
    samples: int  #: camera paths traced, or aperture samples splatted
    time_s: float  #: rendering, from the first dispatch to the last read-back
    setup_s: float  #: adapter, shader compilation and buffers before it
    adapter: str
    backend: str
    tiles: int

    @property
    def samples_per_second(self) -> float:
        return self.samples / self.time_s if self.time_s > 0 else math.inf

    @property
    def nonfinite_pixels(self) -> int:
        return int(np.count_nonzero(~np.isfinite(self.image).all(axis=-1)))

    def to_json(self) -> dict:
        s = self.settings
        return dict(
            scene=self.scene,
            width=s.width,
            height=s.height,
            spp=s.spp,
            seed=s.seed,
            samples=self.samples,
            samples_per_second=self.samples_per_second,
            time_s=self.time_s,
            setup_s=self.setup_s,
            tiles=self.tiles,
            adapter=self.adapter,
            backend=self.backend,
            nonfinite_pixels=self.nonfinite_pixels,
            mean_rgb=[float(v) for v in self.image.reshape(-1, 3).mean(axis=0)] if self.nonfinite_pixels == 0 else None,
            lens=self.lens.to_json(),
        )


def tile_plan(width: int, height: int, max_pixels: int, max_side: int) -> list[tuple[int, int, int, int]]:
    """Tiles ``(x, y, w, h)`` covering the image, each at most ``max_pixels`` and ``max_side`` a side.

    Tiles are as wide as allowed (whole rows where possible), then as tall as
    the pixel budget allows.
    """
    tile_w = max(1, min(width, max_side, max_pixels))
    tile_h = max(1, min(height, max_side, max_pixels // tile_w))
    return [
        (x, y, min(tile_w, width - x), min(tile_h, height - y))
        for y in range(0, height, tile_h)
        for x in range(0, width, tile_w)
    ]


def _max_tile_pixels(device, settings: RenderSettings) -> int:
    limits = device.limits
    allowed = min(limits["max-storage-buffer-binding-size"], limits["max-buffer-size"]) // _ACCUM_BYTES
    cap = DEFAULT_MAX_TILE_PIXELS if settings.max_tile_pixels is None else settings.max_tile_pixels
    return max(1, min(allowed, cap))


@lru_cache(maxsize=16)
def pathtrace_source(scene_source: str) -> str:
    """The whole path-tracer WGSL for one generated scene, every include resolved.

    The browser viewer runs this same text (``bokehfit view``)."""
    generated = {s.name: s.wgsl() for s in (RENDER_PARAMS, MATERIAL, QUAD, BOX, SPHERE)}
    generated["scene"] = scene_source
    return load_shader("pathtrace.wgsl", generated)


def _pathtrace_pipeline(scene_source: str):
    """The path tracer compiled for one scene (its generated WGSL is the cache key)."""
    import wgpu

    device = get_gpu().device
    module = device.create_shader_module(label="pathtrace", code=pathtrace_source(scene_source))
    return device.create_compute_pipeline(layout=wgpu.AutoLayoutMode.auto, compute={"module": module, "entry_point": "main"})


@lru_cache(maxsize=None)
def _points_pipelines():
    import wgpu

    device = get_gpu().device
    generated = {s.name: s.wgsl() for s in (RENDER_PARAMS, POINT_PARAMS)}
    module = device.create_shader_module(label="points", code=load_shader("points.wgsl", generated))
    return tuple(
        device.create_compute_pipeline(layout=wgpu.AutoLayoutMode.auto, compute={"module": module, "entry_point": entry})
        for entry in ("splat", "resolve")
    )


def render_params(lens: Lens, settings: RenderSettings, pose: Pose) -> np.ndarray:
    """The uniform record, tile and sample fields left at 0."""
    aperture = lens.aperture
    angle = math.radians(aperture.angle_deg)
    tan_x, tan_y = lens.tan_half_fov(settings.width, settings.height)
    right, up, forward = pose.basis()
    record = np.zeros((), dtype=RENDER_PARAMS.dtype)
    values = dict(
        image_width=settings.width,
        image_height=settings.height,
        seed=settings.seed,
        shape=aperture.spec.shader_id,
        blades=aperture.blades or 0,
        aspect=aperture.aspect or 1.0,
        cos_angle=math.cos(angle),
        sin_angle=math.sin(angle),
        aperture_scale=lens.aperture_scale_m,
        focus_distance=lens.focus_distance_m,
        tan_half_x=tan_x,
        tan_half_y=tan_y,
        max_depth=settings.max_depth,
        rr_depth=settings.rr_depth,
    )
    for axis, name in enumerate("xyz"):
        values[f"position_{name}"] = pose.position[axis]
        values[f"right_{name}"] = right[axis]
        values[f"up_{name}"] = up[axis]
        values[f"forward_{name}"] = forward[axis]
    for key, value in values.items():
        record[key] = value
    return record


def set_tile(record: np.ndarray, tile: tuple[int, int, int, int]) -> None:
    record["tile_x"], record["tile_y"], record["tile_width"], record["tile_height"] = tile


class _Ticker:
    """Waits for the adapter now and then, and reports finished work to ``progress``.

    It waits by reading a few bytes back from ``probe`` (a COPY_SRC buffer):
    wgpu 0.32's ``queue.on_submitted_work_done_sync()`` fails with a cffi
    TypeError (its callback type lacks the message argument of wgpu-native's).
    """

    def __init__(self, device, progress: Callable[[int], None] | None, probe):
        self.device = device
        self.progress = progress
        self.probe = probe
        self.pending = 0
        self.last = time.perf_counter()

    def add(self, units: int) -> None:
        self.pending += units
        if self.progress is not None and time.perf_counter() - self.last > _SYNC_INTERVAL_S:
            self.flush()

    def flush(self) -> None:
        if self.progress is not None and self.pending:
            self.device.queue.read_buffer(self.probe, 0, 16)
            self.progress(self.pending)
        self.pending = 0
        self.last = time.perf_counter()


def _read_tile(device, accum, tile) -> np.ndarray:
    _, _, w, h = tile
    return np.frombuffer(device.queue.read_buffer(accum), dtype=np.float32).reshape(h, w, 4)


def _path_trace(scene: Scene, lens: Lens, settings: RenderSettings, progress):
    """(image, samples, tiles, setup_s, time_s) of the path tracer."""
    import wgpu

    gpu = get_gpu()
    device = gpu.device
    start = time.perf_counter()
    pipeline = _pathtrace_pipeline(scene_wgsl(scene, mirror_nee=settings.mirror_nee))
    record = render_params(lens, settings, scene.pose)
    uniform = device.create_buffer(size=RENDER_PARAMS.dtype.itemsize, usage=wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST)
    max_side = _TILE_GROUP * device.limits["max-compute-workgroups-per-dimension"]
    tiles = tile_plan(settings.width, settings.height, _max_tile_pixels(device, settings), max_side)
    # Warm-up: an empty tile, so that a driver that compiles at the first dispatch
    # (lavapipe does) does it inside the setup time, not the render time.
    probe = device.create_buffer(size=_ACCUM_BYTES, usage=wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.COPY_SRC)
    device.queue.write_buffer(uniform, 0, record.tobytes())  # tile 0 × 0: every invocation returns
    dispatch(device, pipeline, bind_buffers(device, pipeline, uniform, probe), 1, 1)
    device.queue.read_buffer(probe)
    setup = time.perf_counter() - start

    start = time.perf_counter()
    image = np.empty((settings.height, settings.width, 3), dtype=np.float32)
    for tile in tiles:
        x, y, w, h = tile
        accum = device.create_buffer(size=_ACCUM_BYTES * w * h, usage=wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.COPY_SRC)
        ticker = _Ticker(device, progress, accum)
        bind_group = bind_buffers(device, pipeline, uniform, accum)
        set_tile(record, tile)
        groups = (-(-w // _TILE_GROUP), -(-h // _TILE_GROUP))
        for sample in range(settings.spp):
            record["sample_index"] = sample
            device.queue.write_buffer(uniform, 0, record.tobytes())
            dispatch(device, pipeline, bind_group, *groups)
            ticker.add(w * h)
        ticker.flush()
        data = _read_tile(device, accum, tile)
        # Every pixel got exactly spp samples: divide by the count the shader kept (a).
        image[y : y + h, x : x + w] = data[..., :3] / np.maximum(data[..., 3:], 1.0)
        accum.destroy()
    elapsed = time.perf_counter() - start
    return image, settings.width * settings.height * settings.spp, len(tiles), setup, elapsed


def _light_plan(scene: PointScene, lens: Lens, settings: RenderSettings) -> list[dict]:
    """Per light: slopes, 1/depth, strata, weight and the disc's bounding box (pixels)."""
    tan_x, tan_y = lens.tan_half_fov(settings.width, settings.height)
    extent = lens.aperture.extent() * math.sqrt(math.pi) / 2.0  # unit-area extent → per equal-area diameter
    plans = []
    for index, light in enumerate(scene.lights):
        diameter = lens.coc_px(light.depth_m, settings.width)
        area = math.pi / 4.0 * diameter * diameter
        strata = min(_MAX_STRATA, math.isqrt(max(0, math.ceil(settings.spp * max(area, 1.0)) - 1)) + 1)
        samples = strata * strata
        weight = np.asarray(light.color, dtype=np.float64) * max(area, 1.0) / samples
        centre = (light.x * settings.width, light.y * settings.height)
        reach = extent * diameter + 1.0
        plans.append(
            dict(
                slope_x=(2.0 * light.x - 1.0) * tan_x,
                slope_y=(1.0 - 2.0 * light.y) * tan_y,
                inv_depth=0.0 if math.isinf(light.depth_m) else 1.0 / light.depth_m,
                weight_r=weight[0],
                weight_g=weight[1],
                weight_b=weight[2],
                stream=index,
                strata=strata,
                samples=samples,
                box=(centre[0] - reach, centre[1] - reach, centre[0] + reach, centre[1] + reach),
            )
        )
    return plans


def _splat(scene: PointScene, lens: Lens, settings: RenderSettings, progress):
    """(image, samples, tiles, setup_s, time_s) of the point-light splatter."""
    import wgpu

    gpu = get_gpu()
    device = gpu.device
    start = time.perf_counter()
    splat, resolve = _points_pipelines()
    record = render_params(lens, settings, Pose((0.0, 0.0, 0.0)))
    uniform = device.create_buffer(size=RENDER_PARAMS.dtype.itemsize, usage=wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST)
    light_uniform = device.create_buffer(size=POINT_PARAMS.dtype.itemsize, usage=wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST)
    tiles = tile_plan(settings.width, settings.height, _max_tile_pixels(device, settings), settings.width)
    plans = _light_plan(scene, lens, settings)
    max_groups = device.limits["max-compute-workgroups-per-dimension"]
    # Warm-up: no samples on an empty tile (see _path_trace).
    device.queue.write_buffer(uniform, 0, record.tobytes())
    device.queue.write_buffer(light_uniform, 0, np.zeros((), dtype=POINT_PARAMS.dtype).tobytes())
    probes = [device.create_buffer(size=_ACCUM_BYTES, usage=wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.COPY_SRC) for _ in range(2)]
    dispatch(device, splat, bind_buffers(device, splat, uniform, light_uniform, probes[0]), 1)
    dispatch(device, resolve, bind_buffers(device, resolve, uniform, light_uniform, *probes), 1)
    device.queue.read_buffer(probes[1])
    setup = time.perf_counter() - start

    start = time.perf_counter()
    image = np.empty((settings.height, settings.width, 3), dtype=np.float32)
    drawn = 0
    light_record = np.zeros((), dtype=POINT_PARAMS.dtype)
    for tile in tiles:
        x, y, w, h = tile
        set_tile(record, tile)
        device.queue.write_buffer(uniform, 0, record.tobytes())
        counts = device.create_buffer(size=4 * w * h, usage=wgpu.BufferUsage.STORAGE)
        accum = device.create_buffer(size=_ACCUM_BYTES * w * h, usage=wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.COPY_SRC)
        ticker = _Ticker(device, progress, accum)
        splat_group = bind_buffers(device, splat, uniform, light_uniform, counts)
        resolve_group = bind_buffers(device, resolve, uniform, light_uniform, counts, accum)
        for plan in plans:
            x0, y0, x1, y1 = plan["box"]
            if x1 < x or x0 > x + w or y1 < y or y0 > y + h:
                ticker.add(plan["samples"])
                continue  # this light's disc misses the tile
            for key in ("slope_x", "slope_y", "inv_depth", "weight_r", "weight_g", "weight_b", "stream", "strata"):
                light_record[key] = plan[key]
            for first in range(0, plan["samples"], _SPLAT_CHUNK):
                count = min(_SPLAT_CHUNK, plan["samples"] - first)
                light_record["first"], light_record["count"] = first, count
                device.queue.write_buffer(light_uniform, 0, light_record.tobytes())
                dispatch(device, splat, splat_group, min(-(-count // _LINEAR_GROUP), max_groups))
                drawn += count
                ticker.add(count)
            dispatch(device, resolve, resolve_group, min(-(-(w * h) // _LINEAR_GROUP), max_groups))
        ticker.flush()
        image[y : y + h, x : x + w] = _read_tile(device, accum, tile)[..., :3]
        counts.destroy()
        accum.destroy()
    elapsed = time.perf_counter() - start
    return image, drawn, len(tiles), setup, elapsed


def render_scene(
    scene: Scene | PointScene,
    lens: Lens,
    settings: RenderSettings,
    progress: Callable[[int], None] | None = None,
) -> RenderResult:
    """Render ``scene`` through ``lens``; ``progress(n)`` is told of finished work units.

    The units are samples: ``width·height·spp`` camera paths in all for a path
    traced scene, the aperture samples of every light (once per tile) for points.
    """
    gpu = get_gpu()
    if isinstance(scene, PointScene):
        image, samples, tiles, setup, elapsed = _splat(scene, lens, settings, progress)
    else:
        image, samples, tiles, setup, elapsed = _path_trace(scene, lens, settings, progress)
    return RenderResult(image, scene.name, lens, settings, samples, elapsed, setup, gpu.adapter_name, gpu.backend, tiles)


def total_work(scene: Scene | PointScene, lens: Lens, settings: RenderSettings) -> int:
    """The number of progress units ``render_scene`` will report (for a progress bar)."""
    if isinstance(scene, PointScene):
        device = get_gpu().device
        tiles = len(tile_plan(settings.width, settings.height, _max_tile_pixels(device, settings), settings.width))
        return tiles * sum(p["samples"] for p in _light_plan(scene, lens, settings))
    return settings.width * settings.height * settings.spp
