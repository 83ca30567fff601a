"""One aperture model: consumers ask the model, they never compare shape or feature names (issues 11, 24).

The package's files are read from the installed package (``bokehfit.__file__``).
Comparisons of shape names and of the §3b features' names belong in
``bokehfit/apertures/`` only (the shape registry, the features' records); the
allow-lists below name, file by file, what is left elsewhere, each with its
reason, so that they can only shrink.
"""

from __future__ import annotations

import ast
import math
import re
from pathlib import Path

import numpy as np
import pytest

import bokehfit
from bokehfit.apertures import FEATURES, SHADER_FAMILIES, SHAPES, Aperture, make_aperture
from bokehfit.errors import InputError

PACKAGE = Path(bokehfit.__file__).resolve().parent
#: The one place that may compare shape names.
MODEL_FOLDER = "apertures"
#: Every name a shape goes by: the registry's and the sampler families'.
SHAPE_NAMES = frozenset(SHAPES) | frozenset(SHADER_FAMILIES) | {"mask"}

#: Every name of a §3b feature (design.md §3b) and of a shape's own parameters: the fit loops over the
#: features' records (``bokehfit.apertures.FEATURE_SPECS``) and asks the model (``has_aspect``,
#: ``has_roundness``, ``spec.takes_blades``) instead of comparing these.
FEATURE_NAMES = frozenset(FEATURES) | {"blades", "aspect", "mask"}

#: (file relative to the package, a regular expression its offending line matches, why it is still there).
ALLOWED: tuple[tuple[str, str, str], ...] = ()  # (file, line pattern, why): none left
#: The same for feature-name comparisons.
FEATURE_ALLOWED: tuple[tuple[str, str, str], ...] = ()  # (file, line pattern, why): none left

_JS_COMPARISON = re.compile(
    r"""(?:===|!==|==|!=)\s*["'](?P<a>[a-z]+)["']|["'](?P<b>[a-z]+)["']\s*(?:===|!==|==|!=)"""
)


def _is_name_of(node: ast.AST, names: frozenset[str]) -> bool:
    """A string constant among ``names``, or a tuple/list/set holding one."""
    if isinstance(node, ast.Constant):
        return isinstance(node.value, str) and node.value in names
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return any(_is_name_of(item, names) for item in node.elts)
    return False


def _is_shape_name(node: ast.AST) -> bool:
    """A string constant naming a shape, or a tuple/list/set holding one."""
    return _is_name_of(node, SHAPE_NAMES)


def _compares_family(node: ast.AST) -> bool:
    """``<x>.family`` (a ShapeSpec's sampler family, a name)."""
    return isinstance(node, ast.Attribute) and node.attr == "family"


def _is_vertices_call(node: ast.AST) -> bool:
    return isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "vertices"


def python_offences(source: str) -> list[int]:
    """Line numbers of shape-name comparisons in Python ``source``.

    A comparison with a shape's name (``== "circle"``, ``in ("triangle", ...)``,
    ``case "slit":``), of a ``.family`` attribute (``spec.family == ...``), or
    the circle told apart by ``vertices() is None``.
    """
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare):
            operands = [node.left, *node.comparators]
            names = any(_is_shape_name(o) for o in operands)
            family = any(_compares_family(o) for o in operands) and not all(
                isinstance(op, (ast.Is, ast.IsNot)) for op in node.ops
            )
            vertices = any(_is_vertices_call(o) for o in operands) and any(
                isinstance(o, ast.Constant) and o.value is None for o in operands
            )
            if names or family or vertices:
                lines.append(node.lineno)
        elif isinstance(node, ast.MatchValue) and _is_shape_name(node.value):
            lines.append(node.lineno)
    return sorted(set(lines))


def python_feature_offences(source: str) -> list[int]:
    """Line numbers of feature-name comparisons in Python ``source``: a comparison with a §3b feature's
    name or a shape parameter's (``feature == "rim"``, ``"aspect" in aperture.parameters``,
    ``name in ("vignetting", ...)``, ``case "squeeze":``)."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare) and any(_is_name_of(o, FEATURE_NAMES) for o in [node.left, *node.comparators]):
            lines.append(node.lineno)
        elif isinstance(node, ast.MatchValue) and _is_name_of(node.value, FEATURE_NAMES):
            lines.append(node.lineno)
    return sorted(set(lines))


def javascript_offences(source: str) -> list[int]:
    """Line numbers of JavaScript comparisons with a shape's name (``=== "ngon"``)."""
    found = []
    for number, line in enumerate(source.splitlines(), 1):
        for match in _JS_COMPARISON.finditer(line):
            if (match.group("a") or match.group("b")) in SHAPE_NAMES:
                found.append(number)
                break
    return found


def javascript_feature_offences(source: str) -> list[int]:
    """Line numbers of JavaScript comparisons with a feature's name (``=== "rim"``)."""
    return [n for n, line in enumerate(source.splitlines(), 1)
            if any((m.group("a") or m.group("b")) in FEATURE_NAMES for m in _JS_COMPARISON.finditer(line))]


def package_offences(python=python_offences, javascript=javascript_offences) -> list[tuple[str, int, str]]:
    """(file, line number, line) of every comparison the scans find outside the model's folder
    (shape names by default; ``javascript`` None: Python files only)."""
    found = []
    for path in sorted(PACKAGE.rglob("*")):
        relative = path.relative_to(PACKAGE).as_posix()
        if relative.split("/")[0] == MODEL_FOLDER or path.suffix not in (".py", ".js"):
            continue
        scan = python if path.suffix == ".py" else javascript
        if scan is None:
            continue
        source = path.read_text(encoding="utf-8")
        lines = source.splitlines()
        found.extend((relative, n, lines[n - 1].strip()) for n in scan(source))
    return found


def _feature_offences() -> list[tuple[str, int, str]]:
    return package_offences(python_feature_offences, javascript_feature_offences)


def _allowed(relative: str, line: str, allowed=ALLOWED) -> bool:
    return any(relative == file and re.search(pattern, line) for file, pattern, _ in allowed)


def test_no_shape_name_comparisons_outside_the_model():
    offences = [f"{file}:{n}: {line}" for file, n, line in package_offences() if not _allowed(file, line)]
    assert not offences, "shape names compared outside bokehfit/apertures (ask the Aperture instead):\n" + "\n".join(
        offences
    )


def test_no_feature_name_comparisons_outside_the_model():
    offences = [f"{file}:{n}: {line}" for file, n, line in _feature_offences()
                if not _allowed(file, line, FEATURE_ALLOWED)]
    assert not offences, ("feature names compared outside bokehfit/apertures (loop over FEATURE_SPECS, or ask the "
                          "Aperture):\n" + "\n".join(offences))


@pytest.mark.parametrize("allowed, scan", [(ALLOWED, package_offences), (FEATURE_ALLOWED, _feature_offences)],
                         ids=["shapes", "features"])
def test_allow_list_has_no_stale_entries(allowed, scan):
    """Each allowed comparison is still there; remove the entry once its file asks the model."""
    found = scan()
    stale = [
        f"{file}: {pattern} ({why})"
        for file, pattern, why in allowed
        if not any(f == file and re.search(pattern, line) for f, _, line in found)
    ]
    assert not stale, "allow-list entries that match nothing any more:\n" + "\n".join(stale)


@pytest.mark.parametrize(
    "source, expected",
    [
        ('if shape == "circle":\n    pass\n', [1]),
        ('x = a if "slit" != b else c\n', [1]),
        ('ok = name in ("triangle", "pentagon")\n', [1]),
        ("same = a.spec.family == b.spec.family\n", [1]),
        ("edges = 4 if aperture.vertices() is None else 3\n", [1]),
        ('match shape:\n    case "star":\n        pass\n', [2]),
        ("if array.shape != (2,):\n    pass\n", []),  # an ndarray's shape is not a shape name
        ('if method == "exact":\n    pass\n', []),
        ("if s.family is winner:\n    pass\n", []),  # identity of a fit family, not a name
    ],
)
def test_the_scan_finds_name_comparisons_and_nothing_else(source, expected):
    assert python_offences(source) == expected


@pytest.mark.parametrize(
    "source, expected",
    [
        ('if feature == "squeeze":\n    pass\n', [1]),
        ('visible = feature != "rim" or abs(rim) >= 0.05\n', [1]),
        ('aspect = 0.3 if "aspect" in aperture.parameters else None\n', [1]),
        ('on = name not in ("vignetting", "chromatic")\n', [1]),
        ('x = 1\nmatch feature:\n    case "roundness":\n        pass\n', [3]),
        ('if "blades" in given:\n    pass\n', [1]),
        ("start = aperture.replace(rim=0.2)\n", []),  # a keyword, not a name compared
        ('spec = FEATURE_SPECS["rim"]\n', []),  # a lookup in the registry
        ('tried = ["rim", "squeeze"]\n', []),  # named, not compared
        ('if name == "angle_deg":\n    pass\n', []),  # not a feature
        ("if aperture.has_aspect:\n    pass\n", []),
    ],
)
def test_the_feature_scan_finds_name_comparisons_and_nothing_else(source, expected):
    assert python_feature_offences(source) == expected


def test_the_javascript_scan():
    source = 'const a = l.shape === "ngon" ? 1 : 2;\nconst b = mode === "exact";\nif ("slit" !== s) {}\n'
    assert javascript_offences(source) == [1, 3]
    features = 'if (name === "rim") {}\nconst r = p.rim;\nconst c = "chromatic" != k;\n'
    assert javascript_feature_offences(features) == [1, 3]


# --- what the consumers ask the model ---------------------------------------------


@pytest.mark.parametrize(
    "text, label, display, has_angle",
    [
        ("circle", "circle", "circle", False),
        ("hexagon", "hexagon", "hexagon", True),
        ("ngon(9)", "ngon(9)", "9-blade polygon", True),
        ("slit", "slit", "slit", True),
        ("star", "star", "star", True),
    ],
)
def test_names_and_angle_from_the_model(text, label, display, has_angle):
    aperture = make_aperture(text, 10.0)
    assert (aperture.label, aperture.display_name, aperture.has_angle) == (label, display, has_angle)
    assert aperture.is_named(label)


def test_is_named_matches_ngon_names_by_geometry():
    hexagon, nine = make_aperture("hexagon"), make_aperture("ngon(9)")
    assert hexagon.is_named("ngon(6)") and hexagon.is_named("Hexagon")
    assert nine.is_named("ngon") and not nine.is_named("ngon(8)")
    assert not make_aperture("square").is_named("ngon(4)")  # the square has its own sampler and angle
    with pytest.raises(InputError, match="shape must be one of"):
        hexagon.is_named("hexgon")


def test_is_circle_only_for_the_plain_circle():
    assert make_aperture("circle").is_circle
    squeezed = make_aperture("circle", squeeze=2.0)
    assert not squeezed.is_circle and squeezed.vertices() is not None
    assert not make_aperture("ngon(12)").is_circle


def test_values_are_the_parameters_and_replace_them_back():
    aperture = make_aperture("slit", 33.0, aspect=0.4).with_features("vignetting", "chromatic")
    values = aperture.values
    assert list(values) == list(aperture.parameters)
    assert values["angle_deg"] == 33.0 and values["aspect"] == 0.4
    assert aperture.replace(**values) == aperture


@pytest.mark.parametrize("aperture", [
    make_aperture("circle"),
    make_aperture("slit", 33.0, aspect=0.4).with_features("vignetting", "chromatic"),
    make_aperture("ngon(7)", 5.0, roundness=0.3, squeeze=1.4, rim=0.2).with_features("roundness"),
    make_aperture("star", 12.0, vignetting={"radius": 1.5, "shift": -0.4}),
    make_aperture("mask", mask=np.eye(8)),
])
def test_a_turn_is_the_aperture_rebuilt_at_the_new_angle(aperture):
    """replace(angle_deg=...) alone skips make_aperture's checks of the fields it keeps: the same
    aperture as one rebuilt through them, and a refused angle is still refused."""
    for angle in (0.0, -721.5, 1e9):
        turned = aperture.replace(angle_deg=angle)
        assert turned == aperture.replace(angle_deg=angle, squeeze=aperture.squeeze)  # rebuilt by make_aperture
        assert turned.features == aperture.features and isinstance(turned.angle_deg, float)
    with pytest.raises(InputError, match="angle_deg must be"):
        aperture.replace(angle_deg=float("nan"))


@pytest.mark.parametrize("text", ["circle", "square", "slit", "triangle", "star", "ngon(9)"])
def test_from_json_round_trip(text):
    aperture = make_aperture(text, 17.0)
    data = {"shape": aperture.shape, "blades": aperture.blades, "aspect": aperture.aspect,
            "angle_deg": aperture.canonical_angle_deg, "roundness": None, "squeeze": None}
    assert Aperture.from_json(data) == make_aperture(text, aperture.canonical_angle_deg or 0.0)


def test_from_json_refuses_what_is_not_an_aperture():
    with pytest.raises(InputError, match="aperture must be a mapping with a 'shape' key"):
        Aperture.from_json({"angle_deg": 3.0})


# --- the fit takes its parameters from the model ----------------------------------


def test_family_parameters_count_the_apertures():
    from bokehfit.fit.families import DISC_PARAMETERS, FAMILIES

    for family in FAMILIES:
        aperture = family.aperture
        expected = DISC_PARAMETERS + len(aperture.parameters) + int(aperture.spec.takes_blades)
        assert family.parameters == expected, family.name
    by_name = {f.name: f.parameters for f in FAMILIES}
    assert (by_name["circle"], by_name["hexagon"], by_name["slit"], by_name["ngon(9)"]) == (6, 7, 8, 8)


def test_pixel_fit_varies_the_apertures_named_parameters():
    """A slit's fit varies and reports angle_deg and aspect by name, from Aperture.parameters."""
    from bokehfit.discs import find_discs
    from bokehfit.fit.families import FAMILIES
    from bokehfit.fit.pixels import fit_disc_pixels
    from bokehfit.fit.vector import DISC_NAMES
    from bokehfit.synthetic import SyntheticDisc, render_discs

    truth = SyntheticDisc((40.3, 39.6), 30.0, make_aperture("slit", 25.0, aspect=0.4))
    image = render_discs(80, 80, [truth], noise_sigma=0.002, seed=3)
    (disc,) = [d for d in find_discs(image, np.zeros(image.shape, bool)).discs if d.usable]
    family = next(f for f in FAMILIES if f.aperture.is_named("slit"))
    fit = fit_disc_pixels(image, disc, family, family.at(angle_deg=20.0, aspect=0.5))
    assert list(fit.uncertainty) == list(DISC_NAMES) + list(family.aperture.parameters)
    assert fit.aspect == pytest.approx(0.4, abs=0.01)
    assert fit.angle_deg == pytest.approx(25.0, abs=0.5)
    assert fit.diameter_px == pytest.approx(30.0, rel=0.01)
    assert math.dist(fit.center_xy, truth.center_xy) < 0.1


# --- one y-flip: image rows run down, aperture y runs up (design.md §2) --------------

#: (regular expression, why it is a hand-written flip). Python files outside the model's
#: folder and the WGSL sources are scanned; the conversions are image_to_aperture,
#: aperture_to_image and aperture_rows_to_image (shapes.py) and their WGSL twins (apertures.wgsl).
FLIP_PATTERNS: tuple[tuple[str, str], ...] = (
    (r"\[\s*::\s*-1\s*,", "reverses the rows of a 2-D grid: use aperture_rows_to_image"),
    (r"np\.flipud\(|np\.flip\([^)]*axis\s*=\s*0", "flips the rows of a grid: use aperture_rows_to_image"),
    (r"\.reshape\([^)]*\)\s*\[\s*::\s*-1\s*\]", "reverses the rows of a read-back image: use aperture_rows_to_image"),
    (r"meshgrid\([^)]*,\s*-", "a y-up grid made by negating the row coordinate: use image_to_aperture"),
    (r"vec2f\(\s*[\w.]+\.x\s*,\s*-\s*[\w.]+\.y\s*\)", "(x, −y) by hand: use image_to_aperture / aperture_to_image"),
    (r"\brow\s*=.*-\s*[\w.]+\.y\b", "an image row from −y by hand: use aperture_to_image"),
    (r"\(\s*1\.0\s*-\s*(?:2\.0\s*\*\s*)?[\w.]+\.y\s*\)", "NDC y from an image row by hand: use image_to_aperture"),
    (r"1\.0\s*-\s*2\.0\s*\*\s*[\w.]+\.y\b", "NDC y from an image row by hand: use image_to_aperture"),
)


def flip_offences(source: str) -> list[tuple[int, str]]:
    """(line number, reason) of every hand-written y-flip in ``source`` (Python or WGSL)."""
    found = []
    for number, line in enumerate(source.splitlines(), 1):
        code = line.split("#")[0] if not line.lstrip().startswith("//") else ""
        for pattern, why in FLIP_PATTERNS:
            if re.search(pattern, code):
                found.append((number, why))
                break
    return found


def _flip_sources():
    from bokehfit.gpu.shaders import shader_dir

    for path in sorted(PACKAGE.rglob("*.py")):
        relative = path.relative_to(PACKAGE).as_posix()
        if relative.split("/")[0] != MODEL_FOLDER:
            yield relative, path.read_text(encoding="utf-8")
    for entry in sorted(shader_dir().iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".wgsl"):
            yield f"shaders/{entry.name}", entry.read_text(encoding="utf-8")


def test_no_hand_written_y_flips():
    offences = [f"{file}:{n}: {why}" for file, source in _flip_sources() for n, why in flip_offences(source)]
    assert not offences, "image rows flipped by hand (go through the one conversion):\n" + "\n".join(offences)


@pytest.mark.parametrize(
    "source, expected",
    [
        ("    return np.clip(cells[::-1, :], 0.0, 1.0)\n", [1]),
        ("    return data.reshape(size, size)[::-1].copy(), drawn\n", [1]),
        ("x, y = np.meshgrid(coordinates, -coordinates)\n", [1]),
        ("image = np.flipud(image)\n", [1]),
        ("slope_y=(1.0 - 2.0 * light.y) * tan_y,\n", [1]),
        ("    return vec2f(offset.x, -offset.y) / (0.5 * length(size));\n", [1]),
        ("        let row = floor(centre - p.y + 0.5);\n", [1]),
        ("        0.5 * (1.0 - ndc.y) * f32(params.image_height),\n", [1]),
        ("        return r0 + int(len(flat) - np.argmin(flat[::-1]))\n", []),  # a 1-D search from the end
        ("    x, y = image_to_aperture(outline[:, ::-1]).T\n", []),  # (x, y) columns to (row, col): no flip
        ("    let z = sqrt(max(0.0, 1.0 - dot(d, d)));\n", []),
        ("    return vec2f(offset_rc.y, -offset_rc.x);\n", []),  # the conversion itself
        ("    // the old code did vec2f(offset.x, -offset.y)\n", []),
    ],
)
def test_the_flip_scan_finds_flips_and_nothing_else(source, expected):
    assert [n for n, _ in flip_offences(source)] == expected


def test_wgsl_image_frame_conversions_are_the_numpy_ones(gpu, run_wgsl_sampler):
    from bokehfit.apertures import aperture_to_image, image_to_aperture

    points = np.random.default_rng(11).uniform(-40.0, 40.0, (257, 2)).astype(np.float32)
    for name, twin in (("image_to_aperture", image_to_aperture), ("aperture_to_image", aperture_to_image)):
        np.testing.assert_array_equal(run_wgsl_sampler(gpu, f"{name}(u)", points), twin(points).astype(np.float32), name)
    round_trip = run_wgsl_sampler(gpu, "aperture_to_image(image_to_aperture(u))", points)
    np.testing.assert_array_equal(round_trip, points)


def test_aperture_rows_to_image_puts_aperture_y_up():
    from bokehfit.apertures import aperture_rows_to_image, aperture_to_image

    ys = np.array([-1.0, 0.0, 2.0])  # rows of a y-up grid, lowest first
    grid = np.repeat(ys[:, None], 2, axis=1)
    image = aperture_rows_to_image(grid)
    rows = aperture_to_image(np.stack([np.zeros(3), image[:, 0]], axis=-1))[:, 0]
    assert np.all(np.diff(rows) > 0)  # image rows run down
    assert image.flags.c_contiguous


# --- bindings and workgroup sizes: described once, where the shader is dispatched ---------

#: Attributes a shader file may not write as numbers: the generated include "interface"
#: (bokehfit.gpu.compute.ComputeInterface) declares them from the Python side.
HAND_WRITTEN_INTERFACE = (
    (r"@binding\(\s*\d", "a binding index written by hand: declare it in the ComputeInterface"),
    (r"@workgroup_size\(\s*\d", "a workgroup size written by hand: use WORKGROUP_SIZE_* of the ComputeInterface"),
)


def _interfaces():
    from bokehfit.kernels.mc import KERNEL_INTERFACE
    from bokehfit.scene.renderer import PATHTRACE_INTERFACE, POINTS_INTERFACE
    from bokehfit.view.wgsl import DISPLAY_INTERFACE

    return {
        "kernel_mc.wgsl": KERNEL_INTERFACE,
        "pathtrace.wgsl": PATHTRACE_INTERFACE,
        "points.wgsl": POINTS_INTERFACE,
        "display.wgsl": DISPLAY_INTERFACE,
    }


def test_no_shader_file_writes_bindings_or_workgroup_sizes():
    offences = []
    for file, source in _flip_sources():
        if file.startswith("shaders/"):
            for number, line in enumerate(source.splitlines(), 1):
                offences += [f"{file}:{number}: {why}" for pattern, why in HAND_WRITTEN_INTERFACE if re.search(pattern, line)]
    assert not offences, "\n".join(offences)


@pytest.mark.parametrize("filename", ["kernel_mc.wgsl", "pathtrace.wgsl", "points.wgsl", "display.wgsl"])
def test_every_dispatched_shader_takes_its_interface(filename):
    """Each dispatched shader includes the generated interface: without it, it cannot be built."""
    from bokehfit.gpu.shaders import shader_source

    assert '// #include "interface"' in shader_source(filename)
    interface = _interfaces()[filename]
    text = interface.wgsl()
    for axis, n in zip("XYZ", interface.workgroup_size):
        assert f"const WORKGROUP_SIZE_{axis}: u32 = {n}u;" in text
    for i, binding in enumerate(interface.bindings):
        assert f"@group(0) @binding({i}) var<{binding.address_space}> {binding.name}: {binding.wgsl_type};" in text


def test_compute_interface_refuses_what_it_cannot_bind():
    from bokehfit.gpu.compute import Binding, ComputeInterface

    with pytest.raises(ValueError, match="address_space of x must be one of"):
        Binding("x", "storage", "f32")
    with pytest.raises(ValueError, match="workgroup_size must be 1 to 3 positive integers"):
        ComputeInterface((), workgroup_size=(0,))
    with pytest.raises(ValueError, match="binding names must be unique"):
        ComputeInterface((Binding("a", "uniform", "f32"), Binding("a", "uniform", "f32")), workgroup_size=(1,))
    interface = ComputeInterface((Binding("a", "uniform", "f32"),), workgroup_size=(4, 2))
    assert interface.threads == 8
    with pytest.raises(ValueError, match="buffers must be among the bindings a"):
        interface.bind(None, None, b=None)


def test_mc_kernel_follows_the_python_workgroup_size(gpu, monkeypatch):
    """Another workgroup size in Python alone changes the compiled shader and the dispatch, and every sample is still counted."""
    from dataclasses import replace

    from bokehfit.kernels import mc

    changed = replace(mc.KERNEL_INTERFACE, workgroup_size=(64,))
    monkeypatch.setattr(mc, "KERNEL_INTERFACE", changed)
    mc.prepare_pipeline.cache_clear()
    try:
        histogram, drawn = mc.mc_counts(make_aperture("triangle"), 9.0, 21, 50_000, 1, "independent")
    finally:
        mc.prepare_pipeline.cache_clear()
    assert drawn == 50_000 and histogram.sum() == drawn
