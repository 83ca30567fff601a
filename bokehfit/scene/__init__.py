"""The seed's scene: a WGSL path tracer with the thin-lens camera and every aperture.

``render("cornell", lens, settings)`` path-traces the Cornell box of
:mod:`bokehfit.scene.cornell` (mirror rear wall, mirror balls, a fine floor
grid) through the renderer camera of design.md §4, the :class:`Lens` built by
:func:`make_lens` around one :class:`~bokehfit.apertures.Aperture`;
``render("points", lens, settings)`` draws point lights at chosen depths on black
(:mod:`bokehfit.scene.points`). Both run as WGSL compute shaders through wgpu
(``shaders/pathtrace.wgsl``, ``shaders/points.wgsl``), written for WebGPU as
browsers implement it. Scenes are picked by name from ``SCENES``.

Examples
--------
>>> from bokehfit.apertures import make_aperture
>>> lens = make_lens(make_aperture("triangle"), fstop=2.0, focus_distance_m=0.3)
>>> result = render("points", lens, make_settings(64, 32, spp=4))  # doctest: +SKIP
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
    scene: str | Scene | PointScene,
    lens: Lens,
    settings: RenderSettings | None = None,
    *,
    light_depths_m=None,
    progress: Callable[[int], None] | None = None,
    max_time_s: float | None = None,
) -> RenderResult:
    """Render a scene (by name, or a Scene/PointScene) through ``lens``.

    Parameters
    ----------
    scene : str or Scene or PointScene
        ``"cornell"`` or ``"points"`` (see ``SCENES``), or a scene built in Python.
    lens : Lens
        The aperture (one :class:`~bokehfit.apertures.Aperture`, with its
        real-lens features of design.md §3b), f-stop, focus distance, focal
        length and sensor width, built by :func:`make_lens`. A scene's own
        focus distance is ``build_scene(name).default_focus_m``.
    settings : RenderSettings, optional
        Image size, samples per pixel (points: aperture samples per pixel of
        each disc), seed and tiling, built by :func:`make_settings`; default
        512×512 pixels, 64 spp, seed 0. Larger images are rendered in tiles.
    light_depths_m : sequence of float, optional
        Depths of the point lights of ``points`` given by name (``inf`` allowed).
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
    if not isinstance(lens, Lens):
        raise InputError(f"lens must be a Lens, built by bokehfit.scene.make_lens (got {lens!r:.60})")
    if settings is None:
        settings = make_settings(512, 512, 64)
    elif not isinstance(settings, RenderSettings):
        raise InputError(f"settings must be RenderSettings, built by bokehfit.scene.make_settings (got {settings!r:.60})")
    if isinstance(scene, (Scene, PointScene)):
        if light_depths_m is not None:
            raise InputError("light_depths_m applies only to a scene given by name")
        built = scene
    else:
        built = build_scene(scene, light_depths_m=light_depths_m)
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
