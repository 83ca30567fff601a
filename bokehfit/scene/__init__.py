"""The seed's scene: a WGSL path tracer with the thin-lens camera and every aperture.

``render("cornell", shape="hexagon", fstop=1.4, ...)`` path-traces the Cornell
box of :mod:`bokehfit.scene.cornell` (mirror rear wall, mirror balls, a fine
floor grid) through the renderer camera of design.md §4;
``render("points", ...)`` draws point lights at chosen depths on black
(:mod:`bokehfit.scene.points`). Both run as WGSL compute shaders through wgpu
(``shaders/pathtrace.wgsl``, ``shaders/points.wgsl``), written for WebGPU as
browsers implement it. Scenes are picked by name from ``SCENES``.

Examples
--------
>>> result = render("points", shape="triangle", fstop=2.0, spp=4, width=64, height=32)  # doctest: +SKIP
>>> result.image.shape  # doctest: +SKIP
(32, 64, 3)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from bokehfit.errors import InputError
from bokehfit.scene.camera import FOCAL_LENGTH_MM, SENSOR_WIDTH_MM, Lens, RenderSettings, make_lens, make_settings
from bokehfit.scene.cornell import cornell_box
from bokehfit.scene.geometry import Box, Material, Pose, Quad, Scene, Sphere
from bokehfit.scene.images import RENDER_FORMATS, tone_map_srgb8, write_render
from bokehfit.scene.points import DEFAULT_DEPTHS_M, PointLight, PointScene, parse_depths, points_scene
from bokehfit.scene.renderer import QUICK_WORK, RenderResult, estimate_render_s, render_scene, tile_plan, total_work
from bokehfit.validate import check

__all__ = [
    "SCENES",
    "SceneEntry",
    "Box",
    "Lens",
    "Material",
    "PointLight",
    "PointScene",
    "Pose",
    "Quad",
    "RENDER_FORMATS",
    "RenderResult",
    "RenderSettings",
    "Scene",
    "Sphere",
    "DEFAULT_DEPTHS_M",
    "FOCAL_LENGTH_MM",
    "SENSOR_WIDTH_MM",
    "build_scene",
    "cornell_box",
    "estimate_render_s",
    "make_lens",
    "make_settings",
    "parse_depths",
    "points_scene",
    "render",
    "render_scene",
    "tile_plan",
    "tone_map_srgb8",
    "total_work",
    "write_render",
]


@dataclass(frozen=True)
class SceneEntry:
    """A registry entry: how to build a named scene, and what it is."""

    build: Callable[..., Scene | PointScene]
    description: str
    takes_light_depths: bool = False


SCENES: dict[str, SceneEntry] = {
    "cornell": SceneEntry(lambda: cornell_box(), "Cornell box, mirror rear wall, mirror balls, floor grid (path traced)"),
    "points": SceneEntry(
        lambda light_depths_m=DEFAULT_DEPTHS_M: points_scene(light_depths_m),
        "point lights at chosen depths on black (splatted through the aperture)",
        takes_light_depths=True,
    ),
}


def build_scene(name: str, *, light_depths_m=None) -> Scene | PointScene:
    """The scene registered as ``name``; ``light_depths_m`` only for ``points``."""
    if not isinstance(name, str) or name not in SCENES:
        raise InputError(f"scene must be one of {', '.join(SCENES)} (got {name!r})")
    entry = SCENES[name]
    if light_depths_m is None:
        return entry.build()
    if not entry.takes_light_depths:
        raise InputError(f"light depths apply only to scene 'points' (got them for {name!r})")
    return entry.build(light_depths_m=tuple(light_depths_m))


def render(
    scene: str | Scene | PointScene = "cornell",
    *,
    shape: str = "circle",
    angle_deg: float = 0.0,
    fstop: float = 2.8,
    focus_distance_m: float | None = None,
    blades: int | None = None,
    aspect: float | None = None,
    roundness: float = 0.0,
    squeeze: float = 1.0,
    vignetting=None,
    rim: float = 0.0,
    chromatic=None,
    mask=None,
    spp: int = 64,
    width: int = 512,
    height: int = 512,
    seed: int = 0,
    light_depths_m=None,
    focal_length_mm: float = FOCAL_LENGTH_MM,
    sensor_width_mm: float = SENSOR_WIDTH_MM,
    max_tile_pixels: int | None = None,
    progress: Callable[[int], None] | None = None,
    max_time_s: float | None = None,
) -> RenderResult:
    """Validate the parameters and render a scene (by name, or a Scene/PointScene).

    Parameters
    ----------
    scene : str or Scene or PointScene
        ``"cornell"`` or ``"points"`` (see ``SCENES``), or a scene built in Python.
    shape, angle_deg, blades, aspect : optional
        The aperture (``bokehfit.apertures.make_aperture``).
    roundness, squeeze, vignetting, rim, chromatic : optional
        Its real-lens features (design.md §3b; ``make_aperture`` takes them
        the same way): rounded blades, anamorphic squeeze, cat-eye vignetting
        ``{radius, shift}``, intensity profile, longitudinal colour ``{red, blue}``.
    mask : MaskTable, path or 2-D array, optional
        The transmission image of shape ``"mask"`` (design.md §3b), sampled by
        both renderers from its CDF tables.
    fstop : float
        Equal-area f-stop: the aperture has the area of a circle of diameter f/N.
    focus_distance_m : float, optional
        Distance of the focus plane along the view axis (default: the scene's).
    spp : int
        Samples per pixel (points: aperture samples per pixel of each disc).
    width, height : int
        Image size in pixels; larger images are rendered in tiles.
    seed : int
        The same seed gives the same image.
    light_depths_m : sequence of float, optional
        Depths of the point lights of ``points`` (``inf`` allowed).
    focal_length_mm, sensor_width_mm : float
        Lens and sensor (default 35 mm on 36 mm).
    max_tile_pixels : int, optional
        Most pixels per tile (default: the adapter's limit, at most 2²²).
    progress : callable, optional
        Called with the number of samples finished, now and then.
    max_time_s : float, optional
        Refuse (``InputError``) a render of more than ``QUICK_WORK`` samples
        whose estimated time (:func:`estimate_render_s`) exceeds this many
        seconds; default no bound.

    Returns
    -------
    RenderResult
        ``image``: float32 (height, width, 3) linear radiance, and timing and adapter.

    Raises
    ------
    InputError
        Naming the bad parameter.
    """
    if isinstance(scene, (Scene, PointScene)):
        if light_depths_m is not None:
            raise InputError("light_depths_m applies only to a scene given by name")
        built = scene
    else:
        built = build_scene(scene, light_depths_m=light_depths_m)
    lens = make_lens(
        shape,
        angle_deg,
        fstop=fstop,
        focus_distance_m=built.default_focus_m if focus_distance_m is None else focus_distance_m,
        blades=blades,
        aspect=aspect,
        roundness=roundness,
        squeeze=squeeze,
        vignetting=vignetting,
        rim=rim,
        chromatic=chromatic,
        mask=mask,
        focal_length_mm=focal_length_mm,
        sensor_width_mm=sensor_width_mm,
    )
    settings = make_settings(width, height, spp, seed, max_tile_pixels=max_tile_pixels)
    if max_time_s is not None:
        max_time_s = check("max_time_s", max_time_s)
        if total_work(built, lens, settings) > QUICK_WORK:
            estimate, _ = estimate_render_s(built, lens, settings)
            if estimate > max_time_s:
                raise InputError(
                    f"max_time_s: the render would take about {estimate:.3g} s, more than {max_time_s:g} s "
                    "(lower spp or the image size, or raise max_time_s)"
                )
    return render_scene(built, lens, settings, progress)
