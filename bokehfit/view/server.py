"""The viewer's local web server: the page, the path tracer's WGSL, its uniform layout and the scene.

The browser runs the same path tracer as ``bokehfit render``: ``/pathtrace.wgsl``
is ``shaders/pathtrace.wgsl`` with its includes resolved by
:func:`bokehfit.gpu.shaders.load_shader`, given the same generated includes as
the Python renderer (the struct declarations of
:mod:`bokehfit.scene.renderer` and :mod:`bokehfit.scene.geometry`, and the
scene as WGSL from :func:`bokehfit.scene.wgsl.scene_wgsl`). The uniform
record is never computed in JavaScript: ``/params.json`` returns every field
of ``RenderParams`` by name, filled by the renderer's own code from a lens
built by :func:`bokehfit.scene.make_lens`, and ``/config.json`` describes the
layout (the field names and types in order, 4 bytes each, and the padded
size) from the one :class:`bokehfit.gpu.layout.Struct`, so the page packs the
bytes from the same description as NumPy does.

Routes
------
``GET /``, ``/viewer.js``, ``/style.css``
    The page (package data of :mod:`bokehfit.view`).
``GET /pathtrace.wgsl``
    The path tracer's WGSL, every include resolved.
``GET /config.json``
    Uniform layout, entry point and workgroup size (read from the WGSL),
    scene sketch (walls, block, balls, camera), lens constants, shapes,
    slider ranges and the default settings.
``GET /params.json?shape=&angle=&fstop=&focus=&blades=&aspect=&width=&height=``
    The uniform record's values for these settings (tile = the whole image,
    sample_index 0), the lens as text and JSON, and the depth of field.
    Bad settings: 400 with ``{"error": message}``.
``POST /matched``
    Body: a ``bokehfit compare --json`` document; answer: the viewer
    settings of its fitted aperture (:func:`settings_from_compare`).

The server listens on 127.0.0.1 only and answers only requests whose Host
header names it (``127.0.0.1:PORT`` or ``localhost:PORT``), so that another
web site cannot reach it through a rebound DNS name.
"""

from __future__ import annotations

import json
import math
import re
import threading
from dataclasses import dataclass
from functools import lru_cache
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from urllib.parse import parse_qs, urlsplit

import numpy as np

from bokehfit import __version__
from bokehfit.apertures import SHAPES, make_aperture
from bokehfit.apertures.shapes import DEFAULT_SLIT_ASPECT, MAX_BLADES
from bokehfit.errors import InputError, check_finite
from bokehfit.gpu.layout import Struct
from bokehfit.scene import SCENES, Lens, Scene, build_scene, make_lens, make_settings
from bokehfit.scene.camera import FOCAL_LENGTH_MM, FSTOP_RANGE, MAX_IMAGE_SIDE, SENSOR_WIDTH_MM
from bokehfit.scene.renderer import RENDER_PARAMS, render_params, set_tile
from bokehfit.scene.renderer import pathtrace_source as renderer_source
from bokehfit.scene.wgsl import scene_wgsl

__all__ = [
    "COC_DIVISOR",
    "DepthOfField",
    "ViewerServer",
    "depth_of_field",
    "params_for_query",
    "pathtrace_source",
    "settings_from_compare",
    "uniform_layout",
    "uniform_values",
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
#: Largest request body of POST /matched (bytes).
MAX_BODY_BYTES = 8 * 2**20

_STATIC = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/index.html": ("index.html", "text/html; charset=utf-8"),
    "/viewer.js": ("viewer.js", "text/javascript; charset=utf-8"),
    "/style.css": ("style.css", "text/css; charset=utf-8"),
}
_WGSL_TYPES = ("f32", "u32", "i32")


# --- what the page needs, computed by the renderer's own code -------------------------------


@lru_cache(maxsize=8)
def _pathtrace_source_cached(scene_name: str, mirror_nee: bool) -> str:
    return pathtrace_source(build_scene(scene_name), mirror_nee=mirror_nee)


def pathtrace_source(scene: Scene, *, mirror_nee: bool = False) -> str:
    """The WGSL the Python renderer compiles for ``scene``, every include resolved.

    The same call as :mod:`bokehfit.scene.renderer` makes: ``pathtrace.wgsl``
    through :func:`~bokehfit.gpu.shaders.load_shader`, with the generated
    struct declarations (RenderParams, Material, Quad, Box, Sphere) and the
    scene (:func:`~bokehfit.scene.wgsl.scene_wgsl`).
    """
    return renderer_source(scene_wgsl(scene, mirror_nee=mirror_nee))


def _shader_interface(source: str) -> dict:
    """Entry point, workgroup size and bindings of the compute shader, read from its text."""
    entry = re.search(r"@compute\s+@workgroup_size\(\s*(\d+)\s*(?:,\s*(\d+)\s*)?(?:,\s*(\d+)\s*)?\)\s*fn\s+(\w+)", source)
    if entry is None:
        raise RuntimeError("pathtrace.wgsl has no @compute entry point with a @workgroup_size")
    size = [int(v) if v else 1 for v in entry.groups()[:3]]
    bindings = {
        name: {"group": int(group), "binding": int(binding), "space": space}
        for group, binding, space, name in re.findall(
            r"@group\((\d+)\)\s*@binding\((\d+)\)\s*var<\s*(\w+)[^>]*>\s*(\w+)\s*:", source
        )
    }
    for name in ("params", "accum"):
        if name not in bindings:
            raise RuntimeError(f"pathtrace.wgsl declares no binding {name!r}")
    return {"entry_point": entry.group(4), "workgroup_size": size, "bindings": bindings}


def uniform_layout(struct: Struct = RENDER_PARAMS) -> dict:
    """The uniform's layout as JSON: fields in order (4 bytes each), padded size, WGSL declaration."""
    dtype = struct.dtype
    fields = []
    for name, kind in struct.fields:
        if kind not in _WGSL_TYPES:
            raise RuntimeError(f"{struct.name}.{name}: the page packs only 4-byte scalars (got {kind})")
        fields.append({"name": name, "type": kind, "offset": dtype.fields[name][1]})
    return {"name": struct.name, "fields": fields, "size_bytes": dtype.itemsize, "wgsl": struct.wgsl()}


def uniform_values(lens: Lens, width: int, height: int, scene: Scene) -> dict[str, float | int]:
    """Every RenderParams field by name, as the Python renderer fills it, for the whole image as one tile.

    ``sample_index`` is 0 (the page sets it per sample); seed 0 and the
    default path lengths of :func:`bokehfit.scene.make_settings`.
    """
    settings = make_settings(width, height, 1)
    record = render_params(lens, settings, scene.pose)
    set_tile(record, (0, 0, width, height))
    return {name: record[name].item() for name, _ in RENDER_PARAMS.fields}


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
    entries = []
    for name, spec in SHAPES.items():
        entries.append(
            {
                "name": name,
                "family": spec.family,
                "takes_blades": spec.takes_blades,
                "takes_aspect": spec.takes_aspect,
                "fixed_blades": spec.fixed_blades,
                "has_angle": spec.family != "circle",
            }
        )
    return entries


def viewer_config(scene_name: str = "cornell", size: tuple[int, int] = DEFAULT_SIZE) -> dict:
    """The page's description of the renderer, the scene and its controls (``/config.json``)."""
    scene = build_scene(scene_name)
    if not isinstance(scene, Scene):
        raise InputError(f"the viewer path-traces only scenes made of shapes (got {scene_name!r})")
    source = _pathtrace_source_cached(scene_name, False)
    focus_far = FOCUS_SLIDER_REACH * _deepest_point_m(scene)
    return {
        "bokehfit_version": __version__,
        "shader": {"url": "/pathtrace.wgsl", **_shader_interface(source)},
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
        },
        "defaults": {
            "shape": "circle",
            "angle_deg": 0.0,
            "fstop": 2.8,
            "focus_distance_m": float(scene.default_focus_m),
            "blades": 7,
            "aspect": DEFAULT_SLIT_ASPECT,
            "width": size[0],
            "height": size[1],
        },
        "exposure_ev": 0.0,
        "coc_divisor": COC_DIVISOR,
        "fallback_command": f"bokehfit render --scene {scene_name} --out frame.png",
    }


def _query_number(query: dict, name: str, default=None) -> float | None:
    values = query.get(name)
    if not values or values[-1] == "":
        return default
    return check_finite(name, values[-1])


def _query_int(query: dict, name: str, default=None) -> int | None:
    value = _query_number(query, name, default)
    if value is None:
        return None
    if value != int(value):
        raise InputError(f"{name} must be an integer (got {value!r})")
    return int(value)


def params_for_query(query: dict, scene_name: str = "cornell") -> dict:
    """``/params.json``: the uniform values, lens and depth of field for the page's settings.

    ``query`` maps names to lists of strings (as from :func:`urllib.parse.parse_qs`):
    shape, angle (degrees), fstop, focus (m), blades (ngon), aspect (slit), width, height.
    """
    scene = build_scene(scene_name)
    shape = (query.get("shape") or ["circle"])[-1]
    spec = SHAPES.get(shape)
    lens = make_lens(
        shape,
        _query_number(query, "angle", 0.0),
        fstop=_query_number(query, "fstop", 2.8),
        focus_distance_m=_query_number(query, "focus", scene.default_focus_m),
        blades=_query_int(query, "blades") if spec is not None and spec.takes_blades else None,
        aspect=_query_number(query, "aspect") if spec is not None and spec.takes_aspect else None,
    )
    width = _query_int(query, "width", DEFAULT_SIZE[0])
    height = _query_int(query, "height", DEFAULT_SIZE[1])
    settings = make_settings(width, height, 1)  # validates the size
    dof = depth_of_field(lens, settings.width, settings.height)
    return {
        "values": uniform_values(lens, settings.width, settings.height, scene),
        "lens": lens.to_json(),
        "describe": lens.describe(),
        "symmetry_deg": lens.aperture.symmetry_deg,
        "canonical_angle_deg": lens.aperture.canonical_angle_deg,
        "coc_px_at_infinity": lens.coc_px(math.inf, settings.width),
        "depth_of_field": dof.to_json(),
    }


def settings_from_compare(document: dict) -> dict:
    """The viewer settings of the aperture fitted in a ``bokehfit compare --json`` document.

    Returns ``{"shape", "angle_deg", "blades", "aspect", "fstop", "notes"}``:
    blades only for ``ngon``, aspect only for ``slit``, fstop None where the
    document has none (the photo's geometry was unknown). A circumscribed
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
    if version is not None and version != 1:
        raise InputError(f"compare results of schema_version 1 are understood (got {version!r})")
    a = document["aperture"]
    shape = a.get("shape")
    if shape is None:
        raise InputError("the compare result fitted no aperture (aperture.shape is null)")
    if shape not in SHAPES:
        raise InputError(f"aperture.shape must be one of {', '.join(SHAPES)} (got {shape!r})")
    spec = SHAPES[shape]
    angle = a.get("angle_deg")
    angle = 0.0 if angle is None else check_finite("aperture.angle_deg", angle)
    blades = a.get("blades") if spec.takes_blades else None
    aspect = a.get("aspect") if spec.takes_aspect else None
    aperture = make_aperture(shape, angle, blades=blades, aspect=aspect)  # validates them
    notes = []
    fstop = a.get("fstop")
    if fstop is not None:
        fstop = check_finite("aperture.fstop", fstop)
        if a.get("size_convention") == "circumscribed":
            fstop = fstop * aperture.extent() * math.sqrt(math.pi)
            notes.append("f-stop converted from the circumscribed to the equal-area convention")
        low, high = FSTOP_RANGE
        if not low <= fstop <= high:
            notes.append(f"f-stop {fstop:g} is outside {low:g} to {high:g}: kept the current one")
            fstop = None
    else:
        notes.append(a.get("fstop_reason") or "the compare result has no f-stop: kept the current one")
    odd = spec.family == "star" or (spec.family == "ngon" and aperture.blades % 2 == 1)
    if odd and a.get("focus_side") == "unknown":
        notes.append("odd symmetry and unknown side of focus: the angle is known only modulo half the symmetry")
    return {
        "shape": shape,
        "angle_deg": angle,
        "blades": aperture.blades if spec.takes_blades else None,
        "aspect": aperture.aspect,
        "fstop": fstop,
        "describe": aperture.describe(),
        "notes": notes,
    }


# --- the HTTP server ------------------------------------------------------------------------


class _Handler(BaseHTTPRequestHandler):
    server: _HTTPServer
    server_version = f"bokehfit-view/{__version__}"

    def log_message(self, format, *args):  # quiet: the page polls nothing, but keep stdout clean
        if self.server.verbose:
            super().log_message(format, *args)

    def _host_ok(self) -> bool:
        host = (self.headers.get("Host") or "").lower()
        port = self.server.server_address[1]
        return host in (f"127.0.0.1:{port}", f"localhost:{port}")

    def _send(self, status: int, body: bytes, content_type: str, cache: bool = False) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "max-age=60" if cache else "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, status: int, data) -> None:
        self._send(status, json.dumps(data, allow_nan=False).encode("utf-8"), "application/json; charset=utf-8")

    def _error(self, status: int, message: str) -> None:
        self._json(status, {"error": message})

    def do_HEAD(self):
        self.do_GET()

    def do_GET(self):
        if not self._host_ok():
            return self._error(HTTPStatus.FORBIDDEN, "unknown Host: open the URL that `bokehfit view` printed")
        url = urlsplit(self.path)
        try:
            if url.path in _STATIC:
                name, content_type = _STATIC[url.path]
                body = resources.files("bokehfit.view").joinpath("static", name).read_bytes()
                return self._send(HTTPStatus.OK, body, content_type)
            if url.path == "/pathtrace.wgsl":
                body = _pathtrace_source_cached(self.server.scene_name, False).encode("utf-8")
                return self._send(HTTPStatus.OK, body, "text/wgsl; charset=utf-8")
            if url.path == "/config.json":
                return self._json(HTTPStatus.OK, viewer_config(self.server.scene_name, self.server.size))
            if url.path == "/params.json":
                return self._json(HTTPStatus.OK, params_for_query(parse_qs(url.query), self.server.scene_name))
            if url.path == "/favicon.ico":
                return self._send(HTTPStatus.NO_CONTENT, b"", "image/x-icon")
        except InputError as error:
            return self._error(HTTPStatus.BAD_REQUEST, str(error))
        return self._error(HTTPStatus.NOT_FOUND, f"no such page: {url.path}")

    def do_POST(self):
        if not self._host_ok():
            return self._error(HTTPStatus.FORBIDDEN, "unknown Host: open the URL that `bokehfit view` printed")
        if urlsplit(self.path).path != "/matched":
            return self._error(HTTPStatus.NOT_FOUND, f"no such page: {self.path}")
        try:
            length = int(self.headers.get("Content-Length") or 0)
        except ValueError:
            length = -1
        if not 0 < length <= MAX_BODY_BYTES:
            return self._error(HTTPStatus.BAD_REQUEST, f"the compare result must be 1 byte to {MAX_BODY_BYTES >> 20} MiB")
        try:
            document = json.loads(self.rfile.read(length).decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as error:
            return self._error(HTTPStatus.BAD_REQUEST, f"the file is not JSON: {error}")
        try:
            return self._json(HTTPStatus.OK, settings_from_compare(document))
        except InputError as error:
            return self._error(HTTPStatus.BAD_REQUEST, str(error))


class _HTTPServer(ThreadingHTTPServer):
    daemon_threads = True
    allow_reuse_address = True

    def __init__(self, address, scene_name: str, size: tuple[int, int], verbose: bool):
        self.scene_name = scene_name
        self.size = size
        self.verbose = verbose
        super().__init__(address, _Handler)


class ViewerServer:
    """The viewer's HTTP server on 127.0.0.1 (``port=0``: any free port).

    Use ``serve_forever()`` in the foreground, or ``start()`` for a
    background thread (tests); ``close()`` stops it. A context manager.

    Examples
    --------
    >>> with ViewerServer(port=0).start() as server:  # doctest: +SKIP
    ...     print(server.url)
    http://127.0.0.1:54321/
    """

    def __init__(self, port: int = 0, *, scene: str = "cornell", size: tuple[int, int] = DEFAULT_SIZE, verbose: bool = False):
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise InputError(f"port must be an integer from 0 to 65535 (got {port!r})")
        if scene not in SCENES or not isinstance(build_scene(scene), Scene):
            raise InputError(f"the viewer path-traces the scene 'cornell' (got {scene!r})")
        make_settings(size[0], size[1], 1)  # validates the size
        # Build the shader now: a broken install fails here, not in the browser.
        _pathtrace_source_cached(scene, False)
        self._httpd = _HTTPServer(("127.0.0.1", port), scene, tuple(size), verbose)
        self._thread: threading.Thread | None = None

    @property
    def port(self) -> int:
        return self._httpd.server_address[1]

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/"

    def serve_forever(self) -> None:
        self._httpd.serve_forever(poll_interval=0.2)

    def start(self) -> ViewerServer:
        """Serve from a daemon thread; returns self."""
        self._thread = threading.Thread(target=self.serve_forever, name="bokehfit-view", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop serving (if started in a thread) and close the socket."""
        if self._thread is not None:
            self._httpd.shutdown()
            self._thread.join()
            self._thread = None
        self._httpd.server_close()

    def __enter__(self) -> ViewerServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
