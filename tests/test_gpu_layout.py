"""GPU buffer layouts (bokehfit.gpu.layout.Struct): WGSL's alignment rules, the generated
declaration, and the adapter's own reading of the bytes NumPy packs.

WGSL places each field at the next multiple of its alignment (4 for a scalar,
8 for a vec2, 16 for a vec3 or vec4; a vec3 is 12 bytes, so a scalar may
follow in its last 4) and rounds the struct's size up to its largest
alignment; a uniform buffer's value is padded to 16 bytes. The round-trip
tests compile a shader that copies every component of a uniform (and of a
storage array) out by bitcast, so the offsets are checked against the shader
compiler itself, not against this module's reading of the specification.
"""

from __future__ import annotations

import numpy as np
import pytest

from bokehfit.gpu.layout import WGSL_TYPES, Struct

#: One field of every kind a Struct takes, in an order that needs padding before most vectors.
EVERY_KIND = Struct(
    "EveryKind",
    (
        ("a", "f32"),
        ("b", "vec3f"),
        ("c", "u32"),
        ("d", "vec2f"),
        ("e", "i32"),
        ("f", "vec4f"),
        ("g", "vec2u"),
        ("h", "vec3i"),
        ("i", "vec3u"),
        ("j", "vec2i"),
        ("k", "vec4u"),
        ("l", "u32"),
        ("m", "vec4i"),
        ("n", "f32"),
    ),
)


# --- offsets, sizes, dtype ------------------------------------------------------------------


def test_vec3_after_a_scalar_starts_at_16_and_a_scalar_fills_its_last_4_bytes():
    s = Struct("S", (("a", "f32"), ("b", "vec3f"), ("c", "u32")))
    assert s.offsets == {"a": 0, "b": 16, "c": 28}
    assert (s.align, s.size, s.buffer_size, s.padding) == (16, 32, 32, 12)


def test_vec2_aligns_to_8():
    s = Struct("S", (("a", "f32"), ("b", "vec2f"), ("c", "vec2u"), ("d", "u32"), ("e", "vec2i")))
    assert s.offsets == {"a": 0, "b": 8, "c": 16, "d": 24, "e": 32}
    assert (s.align, s.size, s.buffer_size) == (8, 40, 48)


def test_size_rounds_to_the_largest_alignment_and_the_buffer_to_16():
    assert (Struct("S", (("a", "f32"), ("b", "f32"), ("c", "f32"))).size, Struct("S", (("a", "f32"),) * 1).buffer_size) == (12, 16)
    s = Struct("S", (("a", "vec2f"), ("b", "f32")))
    assert (s.size, s.buffer_size) == (16, 16)
    s = Struct("S", (("a", "f32"), ("b", "vec2f"), ("c", "f32")))
    assert (s.size, s.buffer_size) == (24, 32)
    s = Struct("S", (("a", "vec4f"), ("b", "f32")))
    assert (s.size, s.buffer_size) == (32, 32)
    assert EVERY_KIND.offsets == dict(a=0, b=16, c=28, d=32, e=40, f=48, g=64, h=80, i=96, j=112, k=128, l=144, m=160, n=176)
    assert (EVERY_KIND.size, EVERY_KIND.buffer_size) == (192, 192)


def test_every_wgsl_vector_kind_has_the_specified_alignment_and_size():
    for kind, (scalar, n, align, size) in WGSL_TYPES.items():
        assert scalar in ("f32", "u32", "i32") and size == 4 * n
        assert align == {1: 4, 2: 8, 3: 16, 4: 16}[n], kind


def test_dtype_places_every_component_at_its_offset():
    s = Struct("S", (("a", "f32"), ("p", "vec3f"), ("k", "u32"), ("q", "vec2i")))
    assert s.dtype.itemsize == s.buffer_size == 48
    assert {name: s.dtype.fields[name][1] for name in s.offsets} == s.offsets
    data = s.pack(a=1.5, p=(2.0, 3.0, 4.0), k=7, q=(-1, 9))
    words = np.frombuffer(data, dtype="<u4")
    floats = np.frombuffer(data, dtype="<f4")
    assert floats[0] == 1.5 and list(floats[4:7]) == [2.0, 3.0, 4.0] and words[7] == 7
    assert list(np.frombuffer(data, dtype="<i4")[8:10]) == [-1, 9]
    assert not words[1:4].any() and not words[10:].any()  # the padding stays zero


def test_values_are_checked():
    s = Struct("S", (("a", "f32"), ("p", "vec3f")))
    with pytest.raises(ValueError, match=r"S.p is a vec3f: give 3 values"):
        s.pack(a=1.0, p=(1.0, 2.0))
    with pytest.raises(ValueError, match=r"missing fields \['p'\], unknown fields \['q'\]"):
        s.pack(a=1.0, q=(1.0, 2.0, 3.0))
    with pytest.raises(ValueError, match="must be one of f32, u32, i32, vec2f"):
        Struct("S", (("a", "f64"),))
    with pytest.raises(ValueError, match="must be one of"):
        Struct("S", (("a", "vec3<f32>"),))
    with pytest.raises(ValueError, match="field names must be unique"):
        Struct("S", (("a", "f32"), ("a", "u32")))
    with pytest.raises(ValueError, match="not a WGSL identifier"):
        Struct("S", (("a b", "f32"),))


# --- WGSL text ------------------------------------------------------------------------------


def test_wgsl_declaration_and_constructor():
    s = Struct("Light", (("intensity", "f32"), ("position", "vec3f"), ("index", "u32")))
    text = s.wgsl()
    assert text.startswith("struct Light {") and text.rstrip().endswith("}")
    assert "position: vec3f,  // offset 16" in text and "index: u32,  " in text and "// offset 28" in text
    assert s.wgsl_value(intensity=0.5, position=(1, -2.5, 3), index=4) == "Light(0.5f, vec3f(1.0f, -2.5f, 3.0f), 4u)"
    s.check_wgsl(text)


def test_check_wgsl_reads_a_hand_written_declaration_and_names_the_difference():
    s = Struct("Light", (("intensity", "f32"), ("position", "vec3f"), ("index", "u32")))
    s.check_wgsl("// a comment\nstruct Other { x: f32 }\nstruct Light {\n  intensity: f32, // watts\n  position: vec3<f32>,\n  index: u32\n};")
    with pytest.raises(ValueError, match="declares no struct Light"):
        s.check_wgsl("struct Lights { intensity: f32 }")
    with pytest.raises(ValueError, match=r"differs from its layout: declared \['intensity: f32', 'position: vec4f'"):
        s.check_wgsl("struct Light { intensity: f32, position: vec4f, index: u32 }")
    with pytest.raises(ValueError, match="has an attribute"):
        s.check_wgsl("struct Light { intensity: f32, @align(16) position: vec3f, index: u32 }")


def _layouts():
    from bokehfit.gpu.shaders import APERTURE_PARAMS
    from bokehfit.kernels.mc import KERNEL_PARAMS
    from bokehfit.scene.geometry import BOX, MATERIAL, QUAD, SPHERE
    from bokehfit.scene.renderer import POINT_PARAMS, RENDER_PARAMS

    return (RENDER_PARAMS, POINT_PARAMS, KERNEL_PARAMS, APERTURE_PARAMS, MATERIAL, QUAD, BOX, SPHERE)


def _compiled_sources() -> dict[str, str]:
    """The WGSL every dispatched shader is compiled from, includes resolved."""
    from bokehfit.kernels.mc import kernel_mc_source
    from bokehfit.scene import cornell_box
    from bokehfit.scene.renderer import pathtrace_source, points_source
    from bokehfit.scene.wgsl import scene_wgsl
    from bokehfit.view.wgsl import display_source

    return {
        "pathtrace.wgsl": pathtrace_source(scene_wgsl(cornell_box())),
        "points.wgsl": points_source(),
        "kernel_mc.wgsl": kernel_mc_source(),
        "display.wgsl": display_source(),
    }


def test_the_shaders_declare_the_generated_structs_and_no_others_of_their_names():
    from bokehfit.gpu.shaders import shader_dir

    sources = _compiled_sources()
    for struct in _layouts():
        users = [name for name, source in sources.items() if f"struct {struct.name} " in source]
        assert users, f"no shader declares {struct.name}"
        for name in users:
            struct.check_wgsl(sources[name])
            assert sources[name].count(f"struct {struct.name} ") == 1, name
    hand_written = {struct.name for struct in _layouts()}
    for entry in shader_dir().iterdir():
        if entry.name.endswith(".wgsl"):
            text = entry.read_text(encoding="utf-8")
            declared = {name for name in hand_written if f"struct {name} " in text or f"struct {name}{{" in text}
            assert not declared, f"{entry.name} declares {declared} by hand: include the generated struct"


def test_no_layout_has_hand_written_padding_or_split_vectors():
    for struct in _layouts():
        for name, _ in struct.fields:
            assert not name.startswith("pad"), f"{struct.name}.{name}: the layout pads itself"
            assert not name.endswith(("_x", "_y", "_z", "_r", "_g", "_b")), f"{struct.name}.{name}: use a vector field"


# --- the adapter's own reading -----------------------------------------------------------------


def _component_values(struct: Struct, rng) -> dict:
    values = {}
    for m in struct.members:
        if m.scalar == "f32":
            v = rng.uniform(-100.0, 100.0, m.components).astype(np.float32)
        elif m.scalar == "u32":
            v = rng.integers(0, 2**32, m.components, dtype=np.uint64).astype(np.uint32)
        else:
            v = rng.integers(-(2**31), 2**31, m.components, dtype=np.int64).astype(np.int32)
        values[m.name] = v[0] if m.components == 1 else v
    return values


def _copy_out(struct: Struct, source: str) -> list[str]:
    """WGSL statements writing every component of ``source`` (a struct value) to out[k], in member order."""
    lines, k = [], 0
    for m in struct.members:
        parts = [f"{source}.{m.name}"] if m.components == 1 else [f"{source}.{m.name}[{i}]" for i in range(m.components)]
        for part in parts:
            lines.append(f"    out[{k}u] = bitcast<u32>({part});")
            k += 1
    return lines


def _expected_words(struct: Struct, record) -> np.ndarray:
    data = np.frombuffer(np.asarray(record).tobytes(), dtype="<u4")
    return np.array([data[m.offset // 4 + i] for m in struct.members for i in range(m.components)], dtype=np.uint32)


def _run(gpu, code: str, buffers: list[tuple[bytes, str]], words: int) -> np.ndarray:
    import wgpu

    from bokehfit.gpu.compute import bind_buffers, dispatch

    device = gpu.device
    module = device.create_shader_module(label="layout_test", code=code)
    pipeline = device.create_compute_pipeline(layout=wgpu.AutoLayoutMode.auto, compute={"module": module, "entry_point": "main"})
    usage = {"uniform": wgpu.BufferUsage.UNIFORM, "storage": wgpu.BufferUsage.STORAGE}
    inputs = [device.create_buffer_with_data(data=data, usage=usage[kind]) for data, kind in buffers]
    out = device.create_buffer(size=4 * words, usage=wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.COPY_SRC)
    dispatch(device, pipeline, bind_buffers(device, pipeline, *inputs, out), 1)
    return np.frombuffer(device.queue.read_buffer(out), dtype=np.uint32).copy()


@pytest.mark.parametrize("name", ["EveryKind", "RenderParams", "PointParams", "KernelParams", "ApertureParams"])
def test_the_shader_compiler_reads_each_uniform_field_where_numpy_packed_it(name, gpu):
    struct = {s.name: s for s in (EVERY_KIND, *_layouts())}[name]
    values = _component_values(struct, np.random.default_rng(len(name)))
    record = struct.record(**values)
    expected = _expected_words(struct, record)
    code = "\n".join(
        [
            struct.wgsl(),
            f"@group(0) @binding(0) var<uniform> p: {struct.name};",
            "@group(0) @binding(1) var<storage, read_write> out: array<u32>;",
            "@compute @workgroup_size(1)",
            "fn main() {",
            *_copy_out(struct, "p"),
            "}",
        ]
    )
    np.testing.assert_array_equal(_run(gpu, code, [(record.tobytes(), "uniform")], len(expected)), expected)


@pytest.mark.parametrize("name", ["Material", "Quad", "Box", "Sphere"])
def test_a_numpy_array_of_records_has_the_wgsl_array_stride(name, gpu):
    struct = {s.name: s for s in _layouts()}[name]
    rng = np.random.default_rng(len(name))
    records = np.zeros(3, dtype=struct.dtype)
    for i in range(3):
        records[i] = struct.record(**_component_values(struct, rng))
    expected = np.concatenate([_expected_words(struct, r) for r in records])
    code = "\n".join(
        [
            struct.wgsl(),
            f"@group(0) @binding(0) var<storage, read> p: array<{struct.name}>;",
            "@group(0) @binding(1) var<storage, read_write> out: array<u32>;",
            "@compute @workgroup_size(1)",
            "fn main() {",
            *[line.replace("out[", f"out[{i * len(expected) // 3}u + ") for i in range(3) for line in _copy_out(struct, f"p[{i}]")],
            "}",
        ]
    )
    np.testing.assert_array_equal(_run(gpu, code, [(records.tobytes(), "storage")], len(expected)), expected)
