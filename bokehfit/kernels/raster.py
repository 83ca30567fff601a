"""Rasterised kernels through OpenGL (moderngl, headless EGL).

The outline is drawn as a fan of triangles (the circle as a quad whose
fragments outside the radius are discarded), once per super-sample: each
instance shifts the shape by a sub-pixel offset taken from a jittered m × m
grid, and additive blending into a float32 target accumulates the coverage
counts. This is super-sampling with an accumulation buffer: memory stays at
size², whatever the sample count, and one instanced draw call does it all.

The fan is drawn from the unclipped outline: exact corners for straight
edges, arcs (rounded blades, a squeezed circle) as chords within
``Aperture.vertices``' 1e-6 of unit-area units (1e-6·scale px). Each fan
triangle (centre, a, b) carries the radial fraction ρ of design.md §3b as a
vertex attribute (0 at the centre, 1 on the outline): it is exactly linear
over the triangle, so every fragment gets its ``rim`` weight 1 + rim·(2ρ² − 1)
exactly. Fragments outside the vignetting barrel's circle are discarded.

A ``mask`` aperture (design.md §3b) has no outline to fill: its transmission
image is a float32 texture, drawn on the quad of the scaled, rotated and
squeezed image rectangle. Each fragment maps its position back to the mask's
cells (the inverse of scale·squeeze·rotation) and takes that cell's
transmission with ``texelFetch`` (no filtering: the density is piecewise
constant, :func:`bokehfit.apertures.mask_pdf`), so the super-samples
converge to the exact box integral (:func:`bokehfit.kernels.masks.mask_coverage`)
as they do to the area coverage of an outline.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from bokehfit.apertures import Aperture, aperture_rows_to_image
from bokehfit.errors import GPUUnavailableError, InputError
from bokehfit.gpu.runtime import use_headless_egl

__all__ = ["raster_counts", "gl_renderer"]

#: Most super-samples per pixel (float32 counts stay exact below 2^24).
MAX_PASSES = 2**22

_VERTEX = """
#version 330
in vec2 position;   // aperture frame, pixels, relative to the light
in float fraction;  // radial fraction: 0 at the centre, 1 on the outline
in vec2 offset;     // per instance: minus the sub-pixel sample position
uniform float size;
out vec2 frame_position;
out float radial;
void main() {
    vec2 p = position + offset;
    frame_position = position;  // the fragment relative to the shifted shape's centre
    radial = fraction;
    // Pixel-centre coordinates: the light at (size-1)/2; GL rows run upward.
    gl_Position = vec4((p + 0.5 * (size - 1.0) + 0.5) / size * 2.0 - 1.0, 0.0, 1.0);
}
"""

_FRAGMENT = """
#version 330
in vec2 frame_position;
in float radial;
uniform float disc_radius;  // > 0: draw the disc inscribed in the quad
uniform float rim;          // intensity profile (design.md 3b)
uniform vec3 barrel;        // vignetting circle: centre .xy, radius .z (0: none), pixels
uniform ivec2 mask_cells;   // a mask's columns and rows (0, 0: no mask)
uniform mat2 to_cells;      // pixels from the light -> mask cells from the mask image's centre
uniform sampler2D transmission;  // the mask's transmission, row 0 the bottom (y up)
out float coverage;
void main() {
    if (mask_cells.x > 0) {
        vec2 cell = floor(to_cells * frame_position + 0.5 * vec2(mask_cells));
        if (any(lessThan(cell, vec2(0.0))) || any(greaterThanEqual(cell, vec2(mask_cells)))) {
            discard;
        }
        coverage = texelFetch(transmission, ivec2(cell), 0).r;
        return;
    }
    float rho = radial;
    if (disc_radius > 0.0) {
        float r2 = dot(frame_position, frame_position);
        if (r2 > disc_radius * disc_radius) {
            discard;
        }
        rho = sqrt(r2) / disc_radius;
    }
    vec2 cut = frame_position - barrel.xy;
    if (barrel.z > 0.0 && dot(cut, cut) > barrel.z * barrel.z) {
        discard;
    }
    coverage = 1.0 + rim * (2.0 * rho * rho - 1.0);
}
"""


@lru_cache(maxsize=1)
def _context():
    use_headless_egl()
    import moderngl

    try:
        ctx = moderngl.create_standalone_context(backend="egl")
    except Exception as error:  # glcontext raises plain Exceptions for EGL failures
        raise GPUUnavailableError(
            f"cannot open a headless OpenGL context ({error}); on Debian or Ubuntu "
            "`apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri` gives a software one"
        ) from None
    program = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
    return ctx, program


def gl_renderer() -> str:
    """The OpenGL renderer's name (e.g. ``llvmpipe (LLVM 15.0.6, 256 bits)``)."""
    return _context()[0].info["GL_RENDERER"]


def _mask_frame(aperture: Aperture, scale: float) -> np.ndarray:
    """The 2×2 map from unit-area mask coordinates at angle 0 to pixels: scale·squeeze·rotation."""
    return scale * aperture.squeeze_matrix() @ aperture.rotation()


def _triangles(aperture: Aperture, scale: float) -> tuple[np.ndarray, float]:
    """Triangle list (x, y, radial fraction) of the scaled unclipped outline, and the disc radius (0 for polygons).

    A mask's are the two triangles of its image rectangle, mapped to pixels.
    """
    if aperture.mask is not None:
        w, h = aperture.mask.half_size
        corners = np.array([[-w, -h], [w, -h], [w, h], [-w, -h], [w, h], [-w, h]]) @ _mask_frame(aperture, scale).T
        return np.column_stack([corners, np.zeros(6)]), 0.0
    vertices = aperture.vertices()
    if vertices is None:
        r = abs(scale) / math.sqrt(math.pi)
        quad = np.array([[-r, -r], [r, -r], [r, r], [-r, -r], [r, r], [-r, r]])
        return np.column_stack([quad, np.zeros(6)]), r
    fan = np.column_stack([vertices * scale, np.ones(len(vertices))])
    centre = np.zeros((len(fan), 3))
    return np.stack([centre, fan, np.roll(fan, -1, axis=0)], axis=1).reshape(-1, 3), 0.0


def raster_counts(
    aperture: Aperture, scale: float, size: int, passes: int, seed: int, field_position=None
) -> tuple[np.ndarray, int]:
    """Super-sample counts (rim-weighted) on the size × size grid, and the passes drawn (m², m = ⌈√passes⌉).

    ``field_position`` places the vignetting cut (design.md §3b; default the frame's centre).
    """
    strata = math.isqrt(passes - 1) + 1
    drawn = strata * strata
    if drawn > MAX_PASSES:
        raise InputError(f"samples per pixel must be at most {MAX_PASSES} for method 'raster' (got {passes})")
    ctx, program = _context()
    # The float32 target is one texture and one viewport: both have the context's limits.
    largest = min(ctx.info["GL_MAX_TEXTURE_SIZE"], *ctx.info["GL_MAX_VIEWPORT_DIMS"])
    if size > largest:
        raise InputError(f"size must be at most {largest} for method 'raster' on {gl_renderer()}, its largest texture (got {size})")
    rng = np.random.default_rng(seed)
    cells = np.stack(np.meshgrid(np.arange(strata), np.arange(strata), indexing="ij"), axis=-1).reshape(-1, 2)
    sample_positions = (cells + rng.random((drawn, 2))) / strata - 0.5
    triangles, disc_radius = _triangles(aperture, scale)
    program["size"].value = float(size)
    program["disc_radius"].value = disc_radius
    program["rim"].value = aperture.rim
    barrel = (0.0, 0.0, 0.0)
    if aperture.vignetting is not None:
        from bokehfit.apertures import CIRCLE_RADIUS

        q = np.zeros(2) if field_position is None else np.asarray(field_position, dtype=np.float64)
        cx, cy = abs(scale) * aperture.vignetting.shift * CIRCLE_RADIUS * q
        barrel = (float(cx), float(cy), abs(scale) * aperture.vignetting.radius * CIRCLE_RADIUS)
    program["barrel"].value = barrel
    texture = None
    if aperture.mask is not None:
        mask = aperture.mask
        h, w = mask.shape
        # Pixels → cells: the inverse of _mask_frame, over the cell side. GLSL matrices are column-major.
        to_cells = np.linalg.inv(_mask_frame(aperture, scale)) / mask.cell
        program["to_cells"].value = tuple(float(v) for v in to_cells.T.ravel())
        program["mask_cells"].value = (w, h)
        texture = ctx.texture((w, h), 1, data=np.ascontiguousarray(mask.transmission[::-1], dtype="f4").tobytes(), dtype="f4")
        texture.filter = (ctx.NEAREST, ctx.NEAREST)
        texture.use(location=0)
        program["transmission"].value = 0
    else:
        program["mask_cells"].value = (0, 0)
    vertex_buffer = ctx.buffer(triangles.astype("f4").tobytes())
    offset_buffer = ctx.buffer((-sample_positions).astype("f4").tobytes())
    vao = ctx.vertex_array(program, [(vertex_buffer, "2f 1f", "position", "fraction"), (offset_buffer, "2f/i", "offset")])
    target = ctx.texture((size, size), 1, dtype="f4")
    framebuffer = ctx.framebuffer(color_attachments=[target])
    try:
        framebuffer.use()
        ctx.viewport = (0, 0, size, size)
        framebuffer.clear(0.0)
        ctx.enable(ctx.BLEND)
        ctx.blend_func = ctx.ONE, ctx.ONE
        vao.render(instances=drawn)
        data = np.frombuffer(framebuffer.read(components=1, dtype="f4"), dtype=np.float32)
    finally:
        for resource in (vao, vertex_buffer, offset_buffer, framebuffer, target, texture):
            if resource is not None:
                resource.release()
    return aperture_rows_to_image(data.reshape(size, size)), drawn  # the framebuffer's rows run up in y
