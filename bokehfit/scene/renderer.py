"""Run the WGSL renderers through wgpu: tiles, progressive accumulation, read-back.

Two renderers, chosen by the scene's type:

``path tracing`` (:class:`~bokehfit.scene.geometry.Scene`, ``shaders/pathtrace.wgsl``)
    Every dispatch adds one sample (with its own sample index) to every pixel
    of a tile, into a float32 accumulation buffer; the image is the sum over
    the sample count.
``splatting`` (:class:`~bokehfit.scene.points.PointScene`, ``shaders/points.wgsl``)
    Each point light's aperture samples are counted in the pixels they reach,
    then added to the accumulation buffer with the light's weight. A light gets
    ``spp`` samples per pixel of its disc (at least ``spp``), on a jittered grid;
    with longitudinal colour (design.md §3b) its red, green and blue discs
    differ in size and are splatted one after the other.

Both send the lens's whole aperture (:meth:`bokehfit.apertures.Aperture.shader_params`)
in the uniform, and a custom mask's CDF tables in the storage buffer ``mask_table``
(:data:`bokehfit.gpu.shaders.MASK_TABLE_BINDING`, as the Monte-Carlo kernel binds them);
camera.wgsl samples it with ``sample_aperture_params``.

Images larger than the adapter allows in one binding (``max-storage-buffer-binding-size``,
16 bytes a pixel) or one dispatch (``max-compute-workgroups-per-dimension``) are
rendered tile by tile. The random streams depend on the pixel's place in the
whole image, so tiling does not change the result.

Long renders are estimated before they start (:func:`estimate_render_s`): a
trial render of the same scene, smaller and with fewer samples, grown until
it lasts long enough to time, gives the adapter's rate, and the total work
divided by it the time.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Callable

import numpy as np

from bokehfit.apertures import APERTURE_PARAM_FIELDS, CHANNELS, image_to_aperture
from bokehfit.gpu import AdapterChoice, get_gpu
from bokehfit.gpu.compute import Binding, ComputeInterface, dispatch
from bokehfit.gpu.layout import Struct
from bokehfit.gpu.shaders import MASK_TABLE_BINDING, MASK_TABLE_READ, load_shader, mask_table_data
from bokehfit.scene.camera import Lens, RenderSettings
from bokehfit.scene.geometry import BOX, MATERIAL, QUAD, SPHERE, Pose, Scene
from bokehfit.scene.wgsl import scene_wgsl
from bokehfit.scene.points import PointScene

__all__ = ["RENDER_PARAMS", "POINT_PARAMS", "RenderResult", "lens_aperture_wgsl", "pathtrace_source", "points_source", "render_params", "render_scene", "set_tile", "tile_plan", "total_work", "estimate_render_s", "DEFAULT_MAX_TILE_PIXELS", "QUICK_WORK"]

#: RenderParams = the image and tile, the lens's aperture (the fields of the WGSL
#: ``ApertureParams``, :data:`bokehfit.apertures.APERTURE_PARAM_FIELDS`, which the generated
#: ``lens_aperture()`` copies out: :func:`lens_aperture_wgsl`), then the camera.
_IMAGE_FIELDS = (
    ("image_size", "vec2u"),  # width, height
    ("tile_origin", "vec2u"),  # the tile's first column and row
    ("tile_size", "vec2u"),  # its width and height
    ("sample_index", "u32"),
    ("seed", "u32"),
)
_CAMERA_FIELDS = (
    ("aperture_scale", "f32"),
    ("focus_distance", "f32"),
    ("tan_half", "vec2f"),  # tan of half the field of view, across and up
    ("position", "vec3f"),
    ("right", "vec3f"),
    ("up", "vec3f"),
    ("forward", "vec3f"),
    ("max_depth", "u32"),
    ("rr_depth", "u32"),
)
RENDER_PARAMS = Struct("RenderParams", _IMAGE_FIELDS + tuple(APERTURE_PARAM_FIELDS) + _CAMERA_FIELDS)
POINT_PARAMS = Struct(
    "PointParams",
    (
        ("slope", "vec2f"),  # the light's pinhole slopes (x/z, y/z)
        ("inv_depth", "f32"),
        ("weight", "vec3f"),  # rgb
        ("stream", "u32"),
        ("channel", "u32"),
        ("strata", "u32"),
        ("first", "u32"),
        ("count", "u32"),
    ),
)

#: Largest tile by default (pixels): bounds one dispatch's work, so that a
#: desktop GPU's watchdog never sees a long one.
DEFAULT_MAX_TILE_PIXELS = 2**22
_ACCUM_BYTES = 16  # vec4f per pixel
#: Bind group 0 and workgroup size of ``pathtrace.wgsl`` (its generated include ``interface``):
#: 8 × 8 pixels a workgroup, the 64 invocations browsers allow everywhere.
PATHTRACE_INTERFACE = ComputeInterface(
    (Binding("params", "uniform", "RenderParams"), Binding("accum", "storage, read_write", "array<vec4f>"), MASK_TABLE_BINDING),
    workgroup_size=(8, 8),
)
#: Bind group 0 and workgroup size of ``points.wgsl`` (entry points ``splat`` and ``resolve``).
POINTS_INTERFACE = ComputeInterface(
    (
        Binding("params", "uniform", "RenderParams"),
        Binding("light", "uniform", "PointParams"),
        Binding("counts", "storage, read_write", "array<atomic<u32>>"),
        Binding("accum", "storage, read_write", "array<vec4f>"),
        MASK_TABLE_BINDING,
    ),
    workgroup_size=(256,),
)
_TILE_GROUP_X, _TILE_GROUP_Y = PATHTRACE_INTERFACE.workgroup_size
_LINEAR_GROUP = POINTS_INTERFACE.threads
#: Aperture samples of one light per splat dispatch.
_SPLAT_CHUNK = 2**22
#: Most jittered-grid strata a side for one light (strata² stays below 2³¹).
_MAX_STRATA = 46340
#: Wait for the adapter (and advance the progress bar) about this often, seconds.
_SYNC_INTERVAL_S = 0.25
#: Renders of at most this many samples are not estimated: a few seconds on a CPU adapter.
QUICK_WORK = 2**23
#: A trial render is grown until it lasts this long (seconds), so that its rate is measured, not its overhead.
_TRIAL_S = 0.3
#: Pixels of the first trial render.
_TRIAL_PIXELS = 4096


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


def lens_aperture_wgsl() -> str:
    """The generated include ``lens_aperture``: ``fn lens_aperture() -> ApertureParams``.

    It copies the aperture's fields out of the uniform ``params: RenderParams``
    (field position 0: camera.wgsl's ``aperture_seen`` sets it per pixel or light).
    """
    values = ", ".join(f"params.{name}" for name, _ in APERTURE_PARAM_FIELDS)
    return (
        "// generated by bokehfit.scene.renderer from APERTURE_PARAM_FIELDS\n"
        f"fn lens_aperture() -> ApertureParams {{\n    return ApertureParams({values});\n}}\n"
    )


def _generated(*structs: Struct) -> dict[str, str]:
    """Generated includes of the renderers: the structs' declarations, ``lens_aperture`` and ``mask_table``."""
    return {**{s.name: s.wgsl() for s in structs}, "lens_aperture": lens_aperture_wgsl(), "mask_table": MASK_TABLE_READ}


@lru_cache(maxsize=16)
def pathtrace_source(scene_source: str) -> str:
    """The whole path-tracer WGSL for one generated scene, every include resolved.

    The browser viewer runs this same text (``bokehfit view``)."""
    generated = _generated(RENDER_PARAMS, MATERIAL, QUAD, BOX, SPHERE)
    generated["scene"] = scene_source
    generated["interface"] = PATHTRACE_INTERFACE.wgsl()
    return load_shader("pathtrace.wgsl", generated)


def _pathtrace_pipeline(scene_source: str, adapter: AdapterChoice | None = None):
    """The path tracer compiled for one scene (its generated WGSL is the cache key)."""
    import wgpu

    device = get_gpu(adapter).device
    module = device.create_shader_module(label="pathtrace", code=pathtrace_source(scene_source))
    return device.create_compute_pipeline(layout=wgpu.AutoLayoutMode.auto, compute={"module": module, "entry_point": "main"})


@lru_cache(maxsize=1)
def points_source() -> str:
    """The whole point-light splatter WGSL (``points.wgsl``), every include resolved."""
    generated = _generated(RENDER_PARAMS, POINT_PARAMS)
    generated["interface"] = POINTS_INTERFACE.wgsl()
    return load_shader("points.wgsl", generated)


@lru_cache(maxsize=None)
def _points_pipelines(adapter: AdapterChoice | None = None):
    import wgpu

    device = get_gpu(adapter).device
    module = device.create_shader_module(label="points", code=points_source())
    return tuple(
        device.create_compute_pipeline(layout=wgpu.AutoLayoutMode.auto, compute={"module": module, "entry_point": entry})
        for entry in ("splat", "resolve")
    )


def render_params(lens: Lens, settings: RenderSettings, pose: Pose) -> np.ndarray:
    """The uniform record, tile and sample fields left at 0.

    The aperture's fields are :meth:`bokehfit.apertures.Aperture.shader_params`
    at field position 0 (the shaders set it per pixel or light).
    """
    tan_x, tan_y = lens.tan_half_fov(settings.width, settings.height)
    right, up, forward = pose.basis()
    record = np.zeros((), dtype=RENDER_PARAMS.dtype)
    values = dict(
        lens.aperture.shader_params(),
        image_size=(settings.width, settings.height),
        seed=settings.seed,
        aperture_scale=lens.aperture_scale_m,
        focus_distance=lens.focus_distance_m,
        tan_half=(tan_x, tan_y),
        position=pose.position,
        right=right,
        up=up,
        forward=forward,
        max_depth=settings.max_depth,
        rr_depth=settings.rr_depth,
    )
    for key, value in values.items():
        record[key] = value
    return record


def set_tile(record: np.ndarray, tile: tuple[int, int, int, int]) -> None:
    x, y, w, h = tile
    record["tile_origin"], record["tile_size"] = (x, y), (w, h)


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


def _mask_table_buffer(device, lens: Lens):
    """The storage buffer of the binding ``mask_table``: the lens's mask tables, or one 0 (:func:`mask_table_data`)."""
    import wgpu

    return device.create_buffer_with_data(data=mask_table_data(lens.aperture).tobytes(), usage=wgpu.BufferUsage.STORAGE)


def _read_tile(device, accum, tile) -> np.ndarray:
    _, _, w, h = tile
    return np.frombuffer(device.queue.read_buffer(accum), dtype=np.float32).reshape(h, w, 4)


def _path_trace(scene: Scene, lens: Lens, settings: RenderSettings, progress, adapter: AdapterChoice | None = None):
    """(image, samples, tiles, setup_s, time_s) of the path tracer."""
    import wgpu

    gpu = get_gpu(adapter)
    device = gpu.device
    start = time.perf_counter()
    pipeline = _pathtrace_pipeline(scene_wgsl(scene, mirror_nee=settings.mirror_nee), adapter)
    record = render_params(lens, settings, scene.pose)
    uniform = device.create_buffer(size=RENDER_PARAMS.buffer_size, usage=wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST)
    mask_table = _mask_table_buffer(device, lens)
    max_side = min(_TILE_GROUP_X, _TILE_GROUP_Y) * device.limits["max-compute-workgroups-per-dimension"]
    tiles = tile_plan(settings.width, settings.height, _max_tile_pixels(device, settings), max_side)
    # Warm-up: an empty tile, so that a driver that compiles at the first dispatch
    # (lavapipe does) does it inside the setup time, not the render time.
    probe = device.create_buffer(size=_ACCUM_BYTES, usage=wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.COPY_SRC)
    device.queue.write_buffer(uniform, 0, record.tobytes())  # tile 0 × 0: every invocation returns
    dispatch(device, pipeline, PATHTRACE_INTERFACE.bind(device, pipeline, params=uniform, accum=probe, mask_table=mask_table), 1, 1)
    device.queue.read_buffer(probe)
    setup = time.perf_counter() - start

    start = time.perf_counter()
    image = np.empty((settings.height, settings.width, 3), dtype=np.float32)
    for tile in tiles:
        x, y, w, h = tile
        accum = device.create_buffer(size=_ACCUM_BYTES * w * h, usage=wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.COPY_SRC)
        ticker = _Ticker(device, progress, accum)
        bind_group = PATHTRACE_INTERFACE.bind(device, pipeline, params=uniform, accum=accum, mask_table=mask_table)
        set_tile(record, tile)
        groups = (-(-w // _TILE_GROUP_X), -(-h // _TILE_GROUP_Y))
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


def _colour_passes(lens: Lens, color) -> list[tuple[int, np.ndarray]]:
    """The splat passes of one light: (CHANNEL_* id, rgb weight).

    One pass in every channel at once; with longitudinal colour (design.md
    §3b) the red, green and blue discs differ in size, so each is a pass of
    its own with the light's colour in that channel only.
    """
    color = np.asarray(color, dtype=np.float64)
    if lens.aperture.chromatic is None:
        return [(CHANNELS.index("green"), color)]
    passes = []
    for index, name in enumerate(("red", "green", "blue")):
        weight = np.zeros(3)
        weight[index] = color[index]
        passes.append((CHANNELS.index(name), weight))
    return passes


def _light_plan(scene: PointScene, lens: Lens, settings: RenderSettings) -> list[dict]:
    """Per light: slopes, 1/depth, strata, colour passes and the disc's bounding box (pixels)."""
    tan_x, tan_y = lens.tan_half_fov(settings.width, settings.height)
    chromatic = lens.aperture.chromatic
    largest = 1.0 if chromatic is None else 1.0 + max(0.0, abs(chromatic.red), abs(chromatic.blue))
    # unit-area extent → per equal-area diameter, for the largest colour's disc
    extent = lens.aperture.extent() * math.sqrt(math.pi) / 2.0 * largest
    plans = []
    for index, light in enumerate(scene.lights):
        diameter = lens.coc_px(light.depth_m, settings.width)
        area = math.pi / 4.0 * diameter * diameter
        strata = min(_MAX_STRATA, math.isqrt(max(0, math.ceil(settings.spp * max(area, 1.0)) - 1)) + 1)
        samples = strata * strata
        passes = [(channel, weight * max(area, 1.0) / samples) for channel, weight in _colour_passes(lens, light.color)]
        centre = (light.x * settings.width, light.y * settings.height)
        reach = extent * diameter + 1.0
        ndc_x, ndc_y = 2.0 * image_to_aperture((light.y - 0.5, light.x - 0.5))  # the frame's centre at 0, y up
        plans.append(
            dict(
                slope=(float(ndc_x) * tan_x, float(ndc_y) * tan_y),
                inv_depth=0.0 if math.isinf(light.depth_m) else 1.0 / light.depth_m,
                passes=passes,
                stream=index,
                strata=strata,
                samples=samples,
                box=(centre[0] - reach, centre[1] - reach, centre[0] + reach, centre[1] + reach),
            )
        )
    return plans


def _splat(scene: PointScene, lens: Lens, settings: RenderSettings, progress, adapter: AdapterChoice | None = None):
    """(image, samples, tiles, setup_s, time_s) of the point-light splatter."""
    import wgpu

    gpu = get_gpu(adapter)
    device = gpu.device
    start = time.perf_counter()
    splat, resolve = _points_pipelines(adapter)
    record = render_params(lens, settings, Pose((0.0, 0.0, 0.0)))
    uniform = device.create_buffer(size=RENDER_PARAMS.buffer_size, usage=wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST)
    light_uniform = device.create_buffer(size=POINT_PARAMS.buffer_size, usage=wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST)
    mask_table = _mask_table_buffer(device, lens)
    tiles = tile_plan(settings.width, settings.height, _max_tile_pixels(device, settings), settings.width)
    plans = _light_plan(scene, lens, settings)
    max_groups = device.limits["max-compute-workgroups-per-dimension"]
    # Warm-up: no samples on an empty tile (see _path_trace).
    device.queue.write_buffer(uniform, 0, record.tobytes())
    device.queue.write_buffer(light_uniform, 0, np.zeros((), dtype=POINT_PARAMS.dtype).tobytes())
    probes = [device.create_buffer(size=_ACCUM_BYTES, usage=wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.COPY_SRC) for _ in range(2)]
    dispatch(device, splat, POINTS_INTERFACE.bind(device, splat, params=uniform, light=light_uniform, counts=probes[0], mask_table=mask_table), 1)
    resolve_probe = POINTS_INTERFACE.bind(device, resolve, params=uniform, light=light_uniform, counts=probes[0], accum=probes[1])
    dispatch(device, resolve, resolve_probe, 1)
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
        splat_group = POINTS_INTERFACE.bind(device, splat, params=uniform, light=light_uniform, counts=counts, mask_table=mask_table)
        resolve_group = POINTS_INTERFACE.bind(device, resolve, params=uniform, light=light_uniform, counts=counts, accum=accum)
        for plan in plans:
            x0, y0, x1, y1 = plan["box"]
            if x1 < x or x0 > x + w or y1 < y or y0 > y + h:
                ticker.add(plan["samples"] * len(plan["passes"]))
                continue  # this light's disc misses the tile
            for key in ("slope", "inv_depth", "stream", "strata"):
                light_record[key] = plan[key]
            for channel, weight in plan["passes"]:
                light_record["channel"] = channel
                light_record["weight"] = weight
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
    *,
    adapter: AdapterChoice | None = None,
) -> RenderResult:
    """Render ``scene`` through ``lens``; ``progress(n)`` is told of finished work units.

    ``adapter`` chooses the GPU (:func:`bokehfit.gpu.get_gpu`; the best one found by default).

    The units are samples: ``width·height·spp`` camera paths in all for a path
    traced scene, the aperture samples of every light (once per tile) for points.
    """
    gpu = get_gpu(adapter)
    if isinstance(scene, PointScene):
        image, samples, tiles, setup, elapsed = _splat(scene, lens, settings, progress, adapter)
    else:
        image, samples, tiles, setup, elapsed = _path_trace(scene, lens, settings, progress, adapter)
    return RenderResult(image, scene.name, lens, settings, samples, elapsed, setup, gpu.adapter_name, gpu.backend, tiles)


def estimate_render_s(
    scene: Scene | PointScene, lens: Lens, settings: RenderSettings, adapter: AdapterChoice | None = None
) -> tuple[float, float]:
    """Expected rendering time of ``render_scene(scene, lens, settings)``, and the rate measured.

    Returns
    -------
    seconds : float
        Total work (:func:`total_work`) over the rate of a trial render.
    samples_per_second : float
        The trial's rate.

    Notes
    -----
    The trial is the same scene and lens at 1 spp on about 4096 pixels (the
    image scaled down), grown (first the image, by 2 a side, then the samples
    per pixel, by 4; never beyond the real render) until it lasts 0.3 s: it
    takes about a second at most, and on a fast adapter it grows large enough
    that dispatch overhead does not dominate. Start-up (shader compilation)
    is not counted, as in :attr:`RenderResult.time_s`.
    """
    total = total_work(scene, lens, settings, adapter)
    shrink = max(1, math.isqrt(settings.width * settings.height // _TRIAL_PIXELS))
    spp = 1
    while True:
        width, height = max(1, settings.width // shrink), max(1, settings.height // shrink)
        result = render_scene(scene, lens, replace(settings, width=width, height=height, spp=spp), adapter=adapter)
        if result.time_s >= _TRIAL_S or (shrink == 1 and spp == settings.spp):
            break
        if shrink > 1:
            shrink //= 2
        else:
            spp = min(settings.spp, spp * 4)
    rate = result.samples / max(result.time_s, 1e-9)
    return total / rate, rate


def total_work(scene: Scene | PointScene, lens: Lens, settings: RenderSettings, adapter: AdapterChoice | None = None) -> int:
    """The number of progress units ``render_scene`` will report (for a progress bar) on ``adapter``."""
    if isinstance(scene, PointScene):
        device = get_gpu(adapter).device
        tiles = len(tile_plan(settings.width, settings.height, _max_tile_pixels(device, settings), settings.width))
        return tiles * sum(p["samples"] * len(p["passes"]) for p in _light_plan(scene, lens, settings))
    return settings.width * settings.height * settings.spp
