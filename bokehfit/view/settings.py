"""The viewer's settings: what the page may set, what a setting gives, and the settings of a fitted aperture.

``/config.json`` (:func:`viewer_config`) describes the renderer, the scene's
top-down sketch (walls, block, balls, camera), the lens constants, the shapes,
the sliders' ranges and the default settings; ``/params.json``
(:func:`params_for_query`) answers, for the page's settings, the uniform
record's values, the lens and its depth of field (:func:`depth_of_field`);
``POST /matched`` (:func:`settings_from_compare`) turns a ``bokehfit compare
--json`` document into the settings of its fitted aperture. Every lens is
built and checked by the model's own code (:func:`bokehfit.scene.make_lens`,
:func:`bokehfit.apertures.make_aperture`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bokehfit import __version__
from bokehfit.apertures import SHAPES, Aperture, MaskTable, make_aperture
from bokehfit.apertures.mask import MAX_MASK_SIDE
from bokehfit.apertures.shapes import DEFAULT_SLIT_ASPECT, MAX_BLADES
from bokehfit.errors import InputError, check_finite
from bokehfit.scene import Lens, Scene, build_scene, make_lens, make_settings
from bokehfit.scene.camera import FOCAL_LENGTH_MM, FSTOP_RANGE, MAX_IMAGE_SIDE, SENSOR_WIDTH_MM
from bokehfit.scene.renderer import RENDER_PARAMS
from bokehfit.validate import RANGES
from bokehfit.view.bodies import MAX_BODY_BYTES, brief, finite_number
from bokehfit.view.masks import MaskStore
from bokehfit.view.wgsl import (
    DISPLAY_INTERFACE,
    display_source,
    pathtrace_source_cached,
    shader_interface,
    uniform_layout,
    uniform_values,
)

__all__ = [
    "COC_DIVISOR",
    "DepthOfField",
    "aperture_for_query",
    "depth_of_field",
    "params_for_query",
    "settings_from_compare",
    "viewer_config",
]

#: Depth-of-field criterion: the acceptable circle of confusion is the sensor's
#: diagonal over this number (the usual "d/1500", e.g. 0.029 mm on a 36 × 24 mm sensor).
COC_DIVISOR = 1500.0
#: Image size of the page when the URL names none (pixels).
DEFAULT_SIZE = (512, 512)
#: Slider ranges of the page (the lens accepts more: FSTOP_RANGE, FOCUS_RANGE_M).
FSTOP_SLIDER = (1.0, 22.0)
ASPECT_SLIDER = (0.05, 1.0)
#: The nearest focus on the slider (m), and how far beyond the farthest wall the
#: slider reaches, as a multiple of that wall's depth (reflections in a mirror
#: rear wall lie up to twice as deep).
FOCUS_SLIDER_NEAR_M = 0.1
FOCUS_SLIDER_REACH = 2.0
#: Slider ranges of the real-lens features (design.md §3b), inside what the model
#: accepts (bokehfit.validate.RANGES): anamorphic lenses squeeze 1.33 to 2, real
#: barrels shift within ±3, and longitudinal colour is a few per cent.
FEATURE_SLIDERS = {
    "roundness": (RANGES["roundness"].low, RANGES["roundness"].high),
    "squeeze": (0.5, 2.0),
    "vignetting_radius": (RANGES["vignetting_radius"].low, 3.0),
    "vignetting_shift": (-3.0, 3.0),
    "rim": (RANGES["rim"].low, RANGES["rim"].high),
    "chromatic_red": (-0.1, 0.1),
    "chromatic_blue": (-0.1, 0.1),
}
#: Where the vignetting sliders start when the barrel is switched on (it is off by default).
VIGNETTING_START = {"radius": 1.5, "shift": 1.0}
#: The header that carries the page's token with every write (``/config.json`` names it;
#: :mod:`bokehfit.view.handler` checks it).
TOKEN_HEADER = "X-Bokehfit-Token"


@dataclass(frozen=True)
class DepthOfField:
    """Near and far limits of acceptable sharpness for one lens and circle-of-confusion criterion.

    Notes
    -----
    The renderer camera's blur (design.md §4, :meth:`bokehfit.scene.Lens.coc_mm`)
    is ``c = (f²/N)·|1/d_f − 1/d|``, so the depths with blur ``c`` are
    ``1/d = 1/d_f ± c·N/f²``: the near limit with +, the far limit with −
    (infinite where 1/d_f ≤ c·N/f², i.e. focused at or beyond the hyperfocal
    distance f²/(N·c)).
    """

    coc_mm: float  #: the criterion: the sensor's diagonal / COC_DIVISOR
    near_m: float
    far_m: float  #: math.inf beyond the hyperfocal distance
    hyperfocal_m: float

    def to_json(self) -> dict:
        return {
            "coc_mm": self.coc_mm,
            "coc_rule": f"sensor diagonal / {COC_DIVISOR:g}",
            "near_m": self.near_m,
            "far_m": None if math.isinf(self.far_m) else self.far_m,
            "hyperfocal_m": self.hyperfocal_m,
            "formula": "c = (f²/N)·|1/d_f − 1/d| (renderer camera, design.md §4)",
        }


def depth_of_field(lens: Lens, width_px: int, height_px: int, coc_divisor: float = COC_DIVISOR) -> DepthOfField:
    """Depth of field of ``lens`` for c = sensor diagonal / ``coc_divisor``; see :class:`DepthOfField`.

    The sensor is ``lens.sensor_width_mm`` wide and as tall as the image's aspect makes it.
    """
    sensor_height_mm = lens.sensor_width_mm * height_px / width_px
    coc = math.hypot(lens.sensor_width_mm, sensor_height_mm) / coc_divisor
    f = lens.focal_length_mm
    # c·N/f² in mm⁻¹, times 1000: in m⁻¹, the unit of 1/d.
    k = coc * lens.fstop / (f * f) * 1000.0
    inverse_focus = 1.0 / lens.focus_distance_m
    near = 1.0 / (inverse_focus + k)
    far = 1.0 / (inverse_focus - k) if inverse_focus > k else math.inf
    return DepthOfField(coc, near, far, 1.0 / k)


def _vec(v) -> list[float]:
    return [float(x) for x in v]


def _scene_sketch(scene: Scene) -> dict:
    """What the top-down sketch draws, in world coordinates (metres, y up).

    Quads as their four corners and unit normal; boxes as the four corners of
    their top face (the box's local x axis is (cos a, 0, sin a), its local z
    axis (−sin a, 0, cos a): geometry.Box, scene.wgsl ``intersect_box``);
    spheres as centre and radius; the camera as position and basis.
    """
    right, up, forward = scene.pose.basis()
    materials = {}
    for m in scene.materials:
        colour = np.asarray(m.emission if m.kind == "emitter" else m.albedo, dtype=np.float64)
        materials[m.name] = {"kind": m.kind, "colour": _vec(colour / max(colour.max(), 1.0))}
    quads = []
    for q in scene.quads:
        o, u, v = (np.asarray(x, dtype=np.float64) for x in (q.origin, q.u, q.v))
        quads.append({"corners": [_vec(o), _vec(o + u), _vec(o + u + v), _vec(o + v)], "normal": _vec(q.normal), "material": q.material})
    boxes = []
    for b in scene.boxes:
        a = math.radians(b.angle_deg)
        c = np.asarray(b.center, dtype=np.float64)
        ax = np.array([math.cos(a), 0.0, math.sin(a)]) * b.half[0]
        az = np.array([-math.sin(a), 0.0, math.cos(a)]) * b.half[2]
        top = c + np.array([0.0, b.half[1], 0.0])
        boxes.append({"corners": [_vec(top + sx * ax + sz * az) for sx, sz in ((1, 1), (1, -1), (-1, -1), (-1, 1))], "material": b.material})
    return {
        "name": scene.name,
        "materials": materials,
        "quads": quads,
        "boxes": boxes,
        "spheres": [{"center": _vec(s.center), "radius": float(s.radius), "material": s.material} for s in scene.spheres],
        "camera": {"position": _vec(scene.pose.position), "right": _vec(right), "up": _vec(up), "forward": _vec(forward)},
        "default_focus_m": float(scene.default_focus_m),
    }


def _deepest_point_m(scene: Scene) -> float:
    """Largest depth (along the view axis) of any corner of the scene's quads."""
    corners = []
    for q in scene.quads:
        o, u, v = (np.asarray(x, dtype=np.float64) for x in (q.origin, q.u, q.v))
        corners += [o, o + u, o + v, o + u + v]
    return max((scene.pose.depth(c) for c in corners), default=scene.default_focus_m)


def _shape_entries() -> list[dict]:
    """The shapes of the page's menu; ``tabulated`` ones (``mask``) need an uploaded image first."""
    entries = []
    for name, spec in SHAPES.items():
        example = make_aperture(name, blades=3 if spec.takes_blades else None, mask=[[1.0]] if spec.tabulated else None)
        entries.append(
            {
                "name": name,
                "family": spec.family,
                "takes_blades": spec.takes_blades,
                "takes_aspect": spec.takes_aspect,
                "rounds": spec.rounds,
                "fixed_blades": spec.fixed_blades,
                "tabulated": spec.tabulated,
                "has_angle": example.has_angle,
            }
        )
    return entries



def _feature_defaults() -> dict:
    """The sliders' defaults of the §3b features: the aperture model's neutral values (design.md §3b).

    Vignetting and colour are off (``vignetting``/``chromatic`` False); their
    sliders start at :data:`VIGNETTING_START` and at no colour.
    """
    neutral = Aperture("circle")
    return {
        "roundness": neutral.roundness,
        "squeeze": neutral.squeeze,
        "rim": neutral.rim,
        "vignetting": neutral.vignetting is not None,
        "vignetting_radius": VIGNETTING_START["radius"],
        "vignetting_shift": VIGNETTING_START["shift"],
        "chromatic_red": 0.0,
        "chromatic_blue": 0.0,
    }


def viewer_config(scene_name: str = "cornell", size: tuple[int, int] = DEFAULT_SIZE) -> dict:
    """The page's description of the renderer, the scene and its controls (``/config.json``)."""
    scene = build_scene(scene_name)
    if not isinstance(scene, Scene):
        raise InputError(f"the viewer path-traces only scenes made of shapes (got {scene_name!r})")
    source = pathtrace_source_cached(scene_name, False)
    focus_far = FOCUS_SLIDER_REACH * _deepest_point_m(scene)
    return {
        "bokehfit_version": __version__,
        "shader": {"url": "/pathtrace.wgsl", **shader_interface(source)},
        "display": {"url": "/display.wgsl", **shader_interface(display_source(), DISPLAY_INTERFACE, "display.wgsl")},
        "uniform": uniform_layout(RENDER_PARAMS),
        "scene": _scene_sketch(scene),
        "lens": {"focal_length_mm": FOCAL_LENGTH_MM, "sensor_width_mm": SENSOR_WIDTH_MM, "size_convention": "equal-area"},
        "shapes": _shape_entries(),
        "ranges": {
            "fstop": list(FSTOP_SLIDER),
            "focus_distance_m": [FOCUS_SLIDER_NEAR_M, round(focus_far, 3)],
            "blades": [3, MAX_BLADES],
            "aspect": list(ASPECT_SLIDER),
            "angle_deg": [0.0, 360.0],
            "image_side": [8, MAX_IMAGE_SIDE],
            **{name: list(bounds) for name, bounds in FEATURE_SLIDERS.items()},
        },
        "defaults": {
            "shape": "circle",
            "angle_deg": 0.0,
            "fstop": 2.8,
            "focus_distance_m": float(scene.default_focus_m),
            "blades": 7,
            "aspect": DEFAULT_SLIT_ASPECT,
            **_feature_defaults(),
            "mask": None,
            "width": size[0],
            "height": size[1],
        },
        "exposure_ev": 0.0,
        "coc_divisor": COC_DIVISOR,
        "mask_upload": {"url": "/mask", "max_bytes": MAX_BODY_BYTES, "max_side": MAX_MASK_SIDE},
        "write_token_header": TOKEN_HEADER,
        "fallback_command": f"bokehfit render --scene {scene_name} --out frame.png",
    }


def _query_number(query: dict, name: str, default=None) -> float | None:
    values = query.get(name)
    if not values or values[-1] == "":
        return default
    return check_finite(name, values[-1])


def query_int(query: dict, name: str, default=None) -> int | None:
    value = _query_number(query, name, default)
    if value is None:
        return None
    if value != int(value):
        raise InputError(f"{name} must be an integer (got {value!r})")
    return int(value)


def _query_mask(query: dict, masks: MaskStore | None) -> MaskTable:
    """The uploaded mask that ``mask`` names."""
    values = query.get("mask")
    if not values or values[-1] == "":
        raise InputError("mask is required for shape 'mask': upload a PNG of transmission first")
    return (masks or MaskStore()).get(values[-1])


def aperture_for_query(query: dict, masks: MaskStore | None = None) -> Aperture:
    """The aperture of the page's settings, built once by :func:`~bokehfit.apertures.make_aperture`.

    ``query`` maps names to lists of strings (as from :func:`urllib.parse.parse_qs`):
    shape, angle (degrees), blades (ngon), aspect (slit), and the §3b features:
    roundness (n-gons), squeeze, rim, vignetting_radius with vignetting_shift
    (both, or neither: no vignetting), chromatic_red with chromatic_blue, and for
    shape ``mask`` the digest of a mask uploaded to ``masks``.
    """
    shape = (query.get("shape") or ["circle"])[-1]
    spec = SHAPES.get(shape)
    angle = _query_number(query, "angle", 0.0)
    pairs = {}
    for pair, keys in (("vignetting", ("radius", "shift")), ("chromatic", ("red", "blue"))):
        values = {key: _query_number(query, f"{pair}_{key}") for key in keys}
        given = [key for key, value in values.items() if value is not None]
        if given and len(given) < 2:
            missing = next(key for key in keys if key not in given)
            raise InputError(f"{pair}_{missing} must be given with {pair}_{given[0]}")
        pairs[pair] = values if given else None
    return make_aperture(
        shape,
        angle,
        blades=query_int(query, "blades") if spec is not None and spec.takes_blades else None,
        aspect=_query_number(query, "aspect") if spec is not None and spec.takes_aspect else None,
        roundness=_query_number(query, "roundness", 0.0) if spec is not None and spec.rounds else 0.0,
        squeeze=_query_number(query, "squeeze", 1.0),
        rim=_query_number(query, "rim", 0.0),
        mask=_query_mask(query, masks) if spec is not None and spec.tabulated else None,
        **pairs,
    )


def params_for_query(query: dict, scene_name: str = "cornell", masks: MaskStore | None = None) -> dict:
    """``/params.json``: the uniform values, lens and depth of field for the page's settings.

    ``query`` maps names to lists of strings (as from :func:`urllib.parse.parse_qs`):
    fstop, focus (m), width, height, and the aperture's settings of
    :func:`aperture_for_query`.
    """
    scene = build_scene(scene_name)
    lens = make_lens(
        aperture_for_query(query, masks),
        fstop=_query_number(query, "fstop", 2.8),
        focus_distance_m=_query_number(query, "focus", scene.default_focus_m),
    )
    width = query_int(query, "width", DEFAULT_SIZE[0])
    height = query_int(query, "height", DEFAULT_SIZE[1])
    settings = make_settings(width, height, 1)  # validates the size
    dof = depth_of_field(lens, settings.width, settings.height)
    return {
        "values": uniform_values(lens, settings.width, settings.height, scene),
        "lens": lens.to_json(),
        "describe": lens.describe(),
        "label": lens.aperture.label,
        # The shape's own options of `bokehfit render`, from the model's parameters (blades, aspect).
        "shape_flags": (f" --blades {lens.aperture.blades}" if lens.aperture.spec.takes_blades else "")
        + (f" --aspect {lens.aperture.aspect:g}" if lens.aperture.has_aspect else ""),
        "symmetry_deg": lens.aperture.symmetry_deg,
        "canonical_angle_deg": lens.aperture.canonical_angle_deg,
        "coc_px_at_infinity": lens.coc_px(math.inf, settings.width),
        "depth_of_field": dof.to_json(),
    }



def settings_from_compare(document: dict) -> dict:
    """The viewer settings of the aperture fitted in a ``bokehfit compare --json`` document.

    Returns ``{"shape", "angle_deg", "blades", "aspect", "fstop", "notes"}`` and the
    §3b features ``roundness``, ``squeeze``, ``rim``, ``vignetting`` (``{radius, shift}``
    or None) and ``chromatic`` (``{red, blue}`` or None), each at its default where
    the document has null or lacks it (schema 1): blades only for ``ngon``,
    aspect only for ``slit``, fstop None where the document has none (the
    photo's geometry was unknown). A circumscribed
    f-stop (``size_convention``) is converted to the renderer's equal-area one,
    N_eq = N_circ·R·√π (R: the unit-area shape's circumradius; bokehfit.optics).

    Raises
    ------
    InputError
        Where the document is not a compare result or fitted no aperture.
    """
    if not isinstance(document, dict) or not isinstance(document.get("aperture"), dict):
        raise InputError("the file must be a `bokehfit compare --json` result (it has no 'aperture' object)")
    version = document.get("schema_version")
    if version is not None and (isinstance(version, bool) or version not in (1, 2)):
        raise InputError(f"compare results of schema_version 1 or 2 are understood (got {brief(version)})")
    a = document["aperture"]
    shape = a.get("shape")
    if shape is None:
        raise InputError("the compare result fitted no aperture (aperture.shape is null)")
    if not isinstance(shape, str) or shape not in SHAPES:
        raise InputError(f"aperture.shape must be one of {', '.join(SHAPES)} (got {brief(shape)})")
    spec = SHAPES[shape]
    angle = a.get("angle_deg")
    angle = 0.0 if angle is None else finite_number("aperture.angle_deg", angle)
    blades = a.get("blades") if spec.takes_blades else None
    if blades is not None and (isinstance(blades, bool) or not isinstance(blades, int) or not 3 <= blades <= MAX_BLADES):
        raise InputError(f"aperture.blades must be an integer from 3 to {MAX_BLADES} (got {brief(blades)})")
    aspect = a.get("aspect") if spec.takes_aspect else None
    aspect = None if aspect is None else finite_number("aperture.aspect", aspect)
    for key in ("focus_side", "size_convention", "fstop_reason"):
        if a.get(key) is not None and not isinstance(a[key], str):
            raise InputError(f"aperture.{key} must be a string or null (got {brief(a[key])})")
    features = {}
    for key, default in (("roundness", 0.0), ("squeeze", 1.0), ("rim", 0.0)):
        value = a.get(key)
        features[key] = default if value is None else finite_number(f"aperture.{key}", value)
    for pair, keys in (("vignetting", ("radius", "shift")), ("chromatic", ("red", "blue"))):
        value = a.get(pair)
        if value is not None and not (isinstance(value, dict) and all(key in value for key in keys)):
            raise InputError(f"aperture.{pair} must be an object with keys {', '.join(keys)}, or null (got {brief(value)})")
        features[pair] = None if value is None else {key: finite_number(f"aperture.{pair}.{key}", value[key]) for key in keys}
    # validates their ranges
    aperture = make_aperture(shape, angle, blades=blades, aspect=aspect, **features)
    notes = []
    fstop = a.get("fstop")
    if fstop is not None:
        fstop = finite_number("aperture.fstop", fstop)
        if a.get("size_convention") == "circumscribed":
            fstop = fstop * aperture.extent() * math.sqrt(math.pi)
            notes.append("f-stop converted from the circumscribed to the equal-area convention")
        low, high = FSTOP_RANGE
        if not low <= fstop <= high:
            notes.append(f"f-stop {fstop:g} is outside {low:g} to {high:g}: kept the current one")
            fstop = None
    else:
        notes.append(a.get("fstop_reason") or "the compare result has no f-stop: kept the current one")
    if aperture.odd_symmetry and a.get("focus_side") == "unknown":
        notes.append("odd symmetry and unknown side of focus: the angle is known only modulo half the symmetry")
    return {
        "shape": shape,
        "angle_deg": angle,
        "blades": aperture.blades if spec.takes_blades else None,
        "aspect": aperture.aspect,
        "roundness": aperture.roundness,
        "squeeze": aperture.squeeze,
        "rim": aperture.rim,
        "vignetting": None if aperture.vignetting is None else {"radius": aperture.vignetting.radius, "shift": aperture.vignetting.shift},
        "chromatic": None if aperture.chromatic is None else {"red": aperture.chromatic.red, "blue": aperture.chromatic.blue},
        "fstop": fstop,
        "describe": aperture.describe(),
        "notes": notes,
    }
