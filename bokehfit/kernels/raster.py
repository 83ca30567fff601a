"""Rasterised kernels through OpenGL (moderngl, headless EGL).

The outline is drawn as a fan of triangles (the circle as a quad whose
fragments outside the radius are discarded), once per super-sample: each
instance shifts the shape by a sub-pixel offset taken from a jittered m × m
grid, and additive blending into a float32 target accumulates the coverage
counts. This is super-sampling with an accumulation buffer: memory stays at
size², whatever the sample count, and one instanced draw call does it all.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from bokehfit.apertures import Aperture
from bokehfit.errors import GPUUnavailableError
from bokehfit.gpu.runtime import use_headless_egl

__all__ = ["raster_counts", "gl_renderer"]

#: Most super-samples per pixel (float32 counts stay exact below 2^24).
MAX_PASSES = 2**22

_VERTEX = """
#version 330
in vec2 position;   // aperture frame, pixels, relative to the light
in vec2 offset;     // per instance: minus the sub-pixel sample position
uniform float size;
out vec2 frame_position;
void main() {
    vec2 p = position + offset;
    frame_position = position;  // the fragment relative to the shifted shape's centre
    // Pixel-centre coordinates: the light at (size-1)/2; GL rows run upward.
    gl_Position = vec4((p + 0.5 * (size - 1.0) + 0.5) / size * 2.0 - 1.0, 0.0, 1.0);
}
"""

_FRAGMENT = """
#version 330
in vec2 frame_position;
uniform float disc_radius;  // > 0: draw the disc inscribed in the quad
out float coverage;
void main() {
    if (disc_radius > 0.0 && dot(frame_position, frame_position) > disc_radius * disc_radius) {
        discard;
    }
    coverage = 1.0;
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


def _triangles(aperture: Aperture, scale: float) -> tuple[np.ndarray, float]:
    """Triangle list of the scaled outline, and the disc radius (0 for polygons)."""
    vertices = aperture.vertices()
    if vertices is None:
        r = abs(scale) / math.sqrt(math.pi)
        quad = np.array([[-r, -r], [r, -r], [r, r], [-r, -r], [r, r], [-r, r]])
        return quad, r
    fan = vertices * scale
    centre = np.zeros((len(fan), 2))
    return np.stack([centre, fan, np.roll(fan, -1, axis=0)], axis=1).reshape(-1, 2), 0.0


def raster_counts(aperture: Aperture, scale: float, size: int, passes: int, seed: int) -> tuple[np.ndarray, int]:
    """Super-sample counts on the size × size grid, and the passes drawn (m², m = ⌈√passes⌉)."""
    strata = math.isqrt(passes - 1) + 1
    drawn = strata * strata
    if drawn > MAX_PASSES:
        raise ValueError(f"samples per pixel must be at most {MAX_PASSES} for method 'raster' (got {passes})")
    ctx, program = _context()
    rng = np.random.default_rng(seed)
    cells = np.stack(np.meshgrid(np.arange(strata), np.arange(strata), indexing="ij"), axis=-1).reshape(-1, 2)
    sample_positions = (cells + rng.random((drawn, 2))) / strata - 0.5
    triangles, disc_radius = _triangles(aperture, scale)
    program["size"].value = float(size)
    program["disc_radius"].value = disc_radius
    vertex_buffer = ctx.buffer(triangles.astype("f4").tobytes())
    offset_buffer = ctx.buffer((-sample_positions).astype("f4").tobytes())
    vao = ctx.vertex_array(program, [(vertex_buffer, "2f", "position"), (offset_buffer, "2f/i", "offset")])
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
        for resource in (vao, vertex_buffer, offset_buffer, framebuffer, target):
            resource.release()
    return data.reshape(size, size)[::-1].copy(), drawn
