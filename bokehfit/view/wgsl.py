"""The WGSL the viewer's pages run, how to run it, and its uniform layout and values, by the renderer's own code.

The browser runs the same path tracer as ``bokehfit render``: ``/pathtrace.wgsl``
is ``shaders/pathtrace.wgsl`` with its includes resolved by
:func:`bokehfit.gpu.shaders.load_shader`, given the same generated includes as
the Python renderer (the struct declarations of
:mod:`bokehfit.scene.renderer` and :mod:`bokehfit.scene.geometry`, and the
scene as WGSL from :func:`bokehfit.scene.wgsl.scene_wgsl`). The uniform
record is never computed in JavaScript: ``/params.json`` returns every field
of ``RenderParams`` by name (a vector field as a list), filled by the
renderer's own code (:func:`uniform_values`) from a lens built by
:func:`bokehfit.scene.make_lens`, and ``/config.json`` describes the layout
(each field's name, WGSL type, scalar type, component count and byte offset,
and the padded size) from the one :class:`bokehfit.gpu.layout.Struct`
(:meth:`~bokehfit.gpu.layout.Struct.layout_json`, :func:`uniform_layout`), so
the page packs the bytes at the offsets NumPy uses.

The page's display pass (:func:`display_source`) and the photo page's
Monte-Carlo kernel renderer (:func:`kernel_source`, :func:`kernel_config`) are
served the same way: their includes resolved, their entry points and bindings
read from their text.
"""

from __future__ import annotations

import re
from functools import lru_cache

from bokehfit.gpu.compute import Binding, ComputeInterface
from bokehfit.gpu.layout import Struct
from bokehfit.gpu.shaders import load_shader
from bokehfit.scene import Lens, Scene, build_scene, make_settings
from bokehfit.scene.renderer import PATHTRACE_INTERFACE, RENDER_PARAMS, render_params, set_tile
from bokehfit.scene.renderer import pathtrace_source as renderer_source
from bokehfit.scene.wgsl import scene_wgsl

__all__ = [
    "DISPLAY_INTERFACE",
    "display_source",
    "kernel_config",
    "kernel_source",
    "pathtrace_source",
    "uniform_layout",
    "uniform_values",
]

#: The scalar types whose components the pages pack (``SETTERS`` of common.js: viewer_renderer.js,
#: ``Renderer.setValues``; photo_kernel.js, ``pack``).
_PAGE_SCALARS = ("f32", "u32", "i32")


@lru_cache(maxsize=8)
def pathtrace_source_cached(scene_name: str, mirror_nee: bool) -> str:
    """:func:`pathtrace_source` of the scene named ``scene_name``, made once (``/pathtrace.wgsl``)."""
    return pathtrace_source(build_scene(scene_name), mirror_nee=mirror_nee)


def pathtrace_source(scene: Scene, *, mirror_nee: bool = False) -> str:
    """The WGSL the Python renderer compiles for ``scene``, every include resolved.

    The same call as :mod:`bokehfit.scene.renderer` makes: ``pathtrace.wgsl``
    through :func:`~bokehfit.gpu.shaders.load_shader`, with the generated
    struct declarations (RenderParams, Material, Quad, Box, Sphere) and the
    scene (:func:`~bokehfit.scene.wgsl.scene_wgsl`).
    """
    return renderer_source(scene_wgsl(scene, mirror_nee=mirror_nee))


#: Bind group 0 and workgroup size of the page's display pass (``shaders/display.wgsl``),
#: whose workgroups tile the image as the path tracer's do.
DISPLAY_INTERFACE = ComputeInterface(
    (
        Binding("params", "uniform", "RenderParams"),
        Binding("accum", "storage, read", "array<vec4f>"),
        Binding("rgba", "storage, read_write", "array<u32>"),
    ),
    workgroup_size=PATHTRACE_INTERFACE.workgroup_size,
)


@lru_cache(maxsize=1)
def display_source() -> str:
    """The WGSL of the page's display pass, every include resolved (``/display.wgsl``)."""
    return load_shader("display.wgsl", {"RenderParams": RENDER_PARAMS.wgsl(), "interface": DISPLAY_INTERFACE.wgsl()})


def shader_interface(source: str, interface: ComputeInterface = PATHTRACE_INTERFACE, filename: str = "pathtrace.wgsl",
                     required: tuple[str, ...] = ("params", "accum")) -> dict:
    """Entry point and bindings of the compute shader, read from its text; its workgroup size (``interface``)."""
    entry = re.search(r"@compute\s+@workgroup_size\([^)]*\)\s*fn\s+(\w+)", source)
    if entry is None:
        raise RuntimeError(f"{filename} has no @compute entry point with a @workgroup_size")
    size = [*interface.workgroup_size, 1, 1][:3]
    bindings = {
        name: {"group": int(group), "binding": int(binding), "space": space}
        for group, binding, space, name in re.findall(
            r"@group\((\d+)\)\s*@binding\((\d+)\)\s*var<\s*(\w+)[^>]*>\s*(\w+)\s*:", source
        )
    }
    for binding in required:
        if binding not in bindings:
            raise RuntimeError(f"{filename} declares no binding {binding!r}")
    return {"entry_point": entry.group(1), "workgroup_size": size, "bindings": bindings}


@lru_cache(maxsize=1)
def kernel_source() -> str:
    """The Monte-Carlo kernel renderer's WGSL (``shaders/kernel_mc.wgsl``, every include resolved), as
    :mod:`bokehfit.kernels.mc` compiles it: the photo page draws each disc's kernel with it."""
    from bokehfit.kernels.mc import kernel_mc_source

    return kernel_mc_source()


def kernel_config() -> dict:
    """How the photo page runs ``kernel_mc.wgsl`` (in ``/photo/info.json``): its URL, entry point,
    workgroup size and bindings, and the layouts of its ``KernelParams`` and ``ApertureParams``."""
    from bokehfit.gpu.shaders import APERTURE_PARAMS
    from bokehfit.kernels.mc import KERNEL_INTERFACE, KERNEL_PARAMS

    interface = shader_interface(kernel_source(), KERNEL_INTERFACE, "kernel_mc.wgsl",
                                 required=("params", "counts", "aperture", "mask_table"))
    return {"url": "/photo/kernel_mc.wgsl", **interface, "params": uniform_layout(KERNEL_PARAMS),
            "aperture": uniform_layout(APERTURE_PARAMS)}


def uniform_layout(struct: Struct = RENDER_PARAMS) -> dict:
    """The uniform's layout as JSON (:meth:`Struct.layout_json`): fields with their types and offsets, padded size, WGSL declaration."""
    for member in struct.members:
        if member.scalar not in _PAGE_SCALARS:
            raise RuntimeError(f"{struct.name}.{member.name}: the page packs only {', '.join(_PAGE_SCALARS)} components (got {member.kind})")
    return struct.layout_json()


def uniform_values(lens: Lens, width: int, height: int, scene: Scene) -> dict[str, float | int | list]:
    """Every RenderParams field by name, as the Python renderer fills it, for the whole image as one tile.

    ``sample_index`` is 0 (the page sets it per sample); seed 0 and the
    default path lengths of :func:`bokehfit.scene.make_settings`.
    """
    settings = make_settings(width, height, 1)
    record = render_params(lens, settings, scene.pose)
    set_tile(record, (0, 0, width, height))
    return {name: record[name].tolist() for name, _ in RENDER_PARAMS.fields}

