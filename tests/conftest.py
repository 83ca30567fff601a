"""Shared fixtures: the GPU context and small WGSL harnesses for the twin tests.

The ``gpu`` fixture skips GPU tests where no WebGPU adapter exists, and says
why; under CI (``CI=true``) it fails instead, so a runner without lavapipe
cannot pass by skipping the GPU path (style.md, wgpu-py ``EXPECT_LAVAPIPE``).

The harnesses build a one-line compute shader around the package's own WGSL
(``rng.wgsl``, the generated ``shape_ids``, ``apertures.wgsl``, ``tonemap.wgsl``), loaded through
:func:`bokehfit.gpu.shaders.load_shader` from the installed package, so a
``.wgsl`` file missing from the wheel fails here too.

The ``reference_photo`` fixture finds the real photos of
``reference_photos/manifest.json`` (in ``$BOKEHFIT_REFERENCE_DIR``); where one
is missing, the test skips and says where to get them.
"""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

#: Threads per workgroup of the harness shaders.
WORKGROUP = 64

_HARNESS = """\
// test harness: evaluates one expression of the package's WGSL per element.
// #include "rng.wgsl"
// #include "shape_ids"
// #include "apertures.wgsl"
// #include "tonemap.wgsl"

@group(0) @binding(0) var<storage, read> inputs: array<{in_type}>;
@group(0) @binding(1) var<storage, read_write> outputs: array<{out_type}>;

@compute @workgroup_size({workgroup})
fn main(@builtin(global_invocation_id) gid: vec3u) {{
    let i = gid.x;
    if (i >= arrayLength(&inputs)) {{
        return;
    }}
    let {name} = inputs[i];
    outputs[i] = {expr};
}}
"""

#: WGSL element type -> (NumPy dtype, components per element).
_TYPES = {
    "u32": (np.uint32, 1),
    "f32": (np.float32, 1),
    "vec2f": (np.float32, 2),
    "vec4f": (np.float32, 4),
    "vec4u": (np.uint32, 4),
}

_pipelines: dict[str, object] = {}


def pytest_configure(config):
    """Give SIGINT back its default handler when the run started with it ignored.

    A job started in the background by a non-interactive shell (``bash .ci/run &``)
    inherits SIGINT ignored, and so would every process the tests start, which
    then cannot be stopped with it (the viewer's server is). A handled signal,
    unlike an ignored one, is back to its default in the processes started from here.
    """
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(scope="session")
def reference_photo():
    """``reference_photo(name)`` -> path of a photo of reference_photos/manifest.json, checked by sha256.

    The test skips where the photo is missing (or has another sha256), with a reason that
    says where to get the photos; each photo is checked once per session.
    """
    from photo_factory import reference_photo as find

    found = {}

    def get(name: str):
        if name not in found:
            found[name] = find(name)
        return found[name]

    return get


@pytest.fixture(scope="session")
def compared(reference_photo, gpu):
    """``compared(name)`` -> ``compare_photo`` of a reference photo, run once per session (the
    reference photos' tests share it: each compare of a real photo takes seconds)."""
    from bokehfit.compare import compare_photo

    done = {}

    def get(name: str):
        if name not in done:
            done[name] = compare_photo(reference_photo(name))
        return done[name]

    return get


@pytest.fixture(scope="session")
def gpu():
    """The package's GPU context; skip (fail under CI=true) where there is none."""
    from bokehfit.cli import adapter_from_environment
    from bokehfit.errors import GPUUnavailableError
    from bokehfit.gpu import get_gpu

    try:
        return get_gpu(adapter_from_environment())  # BOKEHFIT_ADAPTER/BACKEND, as the command line reads them
    except GPUUnavailableError as error:
        if os.environ.get("CI") == "true":
            pytest.fail(f"CI=true but no WebGPU adapter could be opened: {error}", pytrace=False)
        pytest.skip(f"no WebGPU adapter: {error}")


def _pipeline(gpu, code: str):
    import wgpu

    if code not in _pipelines:
        module = gpu.device.create_shader_module(label="test_harness", code=code)
        _pipelines[code] = gpu.device.create_compute_pipeline(
            layout=wgpu.AutoLayoutMode.auto, compute={"module": module, "entry_point": "main"}
        )
    return _pipelines[code]


def run_wgsl(gpu, expr: str, inputs: np.ndarray, in_type: str, out_type: str, name: str = "v") -> np.ndarray:
    """Evaluate the WGSL expression ``expr`` once per element of ``inputs``.

    In ``expr`` the element is ``name`` (default ``v``, of WGSL type ``in_type``) and its index
    ``i``; the result has WGSL type ``out_type``. Returns a NumPy array of
    shape (N,) or (N, components).
    """
    import wgpu

    from bokehfit.gpu.compute import bind_buffers, dispatch
    from bokehfit.gpu.shaders import load_shader

    in_dtype, in_comp = _TYPES[in_type]
    out_dtype, out_comp = _TYPES[out_type]
    data = np.ascontiguousarray(inputs, dtype=in_dtype)
    n = data.size // in_comp
    if n == 0 or data.size != n * in_comp:
        raise ValueError(f"inputs must hold a positive whole number of {in_type} (got shape {data.shape})")
    text = _HARNESS.format(in_type=in_type, out_type=out_type, workgroup=WORKGROUP, expr=expr, name=name)
    code = load_shader("harness", {"harness": text})
    pipeline = _pipeline(gpu, code)
    device = gpu.device
    in_buffer = device.create_buffer_with_data(data=data.tobytes(), usage=wgpu.BufferUsage.STORAGE)
    out_buffer = device.create_buffer(
        size=n * out_comp * 4, usage=wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.COPY_SRC
    )
    groups = -(-n // WORKGROUP)
    limit = device.limits["max-compute-workgroups-per-dimension"]
    if groups > limit:
        raise ValueError(f"at most {limit * WORKGROUP} elements per harness call (got {n})")
    dispatch(device, pipeline, bind_buffers(device, pipeline, in_buffer, out_buffer), groups)
    out = np.frombuffer(device.queue.read_buffer(out_buffer), dtype=out_dtype).copy()
    return out.reshape(n, out_comp) if out_comp > 1 else out


def _run_wgsl_sampler(gpu, call_expr: str, u: np.ndarray) -> np.ndarray:
    """WGSL ``call_expr`` of ``u: vec2f`` (e.g. ``sample_ngon(u, 7u)``) on each row of ``u``: (N, 2) float32."""
    u = np.asarray(u, dtype=np.float32).reshape(-1, 2)
    return run_wgsl(gpu, call_expr, u, "vec2f", "vec2f", name="u")


def _run_wgsl_u32(gpu, expr: str, values, out_type: str = "u32") -> np.ndarray:
    """WGSL ``expr`` of one u32 ``v`` (e.g. ``pcg_hash(v)``) on each value."""
    return run_wgsl(gpu, expr, np.asarray(values, dtype=np.uint32).ravel(), "u32", out_type)


def _run_wgsl_u32x3(gpu, expr: str, triples, out_type: str = "u32") -> np.ndarray:
    """WGSL ``expr`` of (``v.x``, ``v.y``, ``v.z``) on each row of an (N, 3) uint32 array."""
    triples = np.asarray(triples, dtype=np.uint32).reshape(-1, 3)
    padded = np.zeros((len(triples), 4), dtype=np.uint32)
    padded[:, :3] = triples
    return run_wgsl(gpu, expr, padded, "vec4u", out_type)


@pytest.fixture(scope="session")
def run_wgsl_sampler():
    """``run_wgsl_sampler(gpu, call_expr, u)`` -> (N, 2) float32 of the WGSL sampler."""
    return _run_wgsl_sampler


@pytest.fixture(scope="session")
def run_wgsl_u32():
    """``run_wgsl_u32(gpu, expr, values, out_type="u32")``: ``expr`` of ``v: u32`` per value."""
    return _run_wgsl_u32


@pytest.fixture(scope="session")
def run_wgsl_u32x3():
    """``run_wgsl_u32x3(gpu, expr, triples, out_type="u32")``: ``expr`` of ``v.x, v.y, v.z`` per row."""
    return _run_wgsl_u32x3
