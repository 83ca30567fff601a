"""The viewer's local web server: the page, the path tracer's WGSL, its uniform layout and the scene.

The browser runs the same path tracer as ``bokehfit render``: ``/pathtrace.wgsl``
is ``shaders/pathtrace.wgsl`` with its includes resolved by
:func:`bokehfit.gpu.shaders.load_shader`, given the same generated includes as
the Python renderer (the struct declarations of
:mod:`bokehfit.scene.renderer` and :mod:`bokehfit.scene.geometry`, and the
scene as WGSL from :func:`bokehfit.scene.wgsl.scene_wgsl`). The uniform
record is never computed in JavaScript: ``/params.json`` returns every field
of ``RenderParams`` by name (a vector field as a list), filled by the
renderer's own code from a lens built by :func:`bokehfit.scene.make_lens`, and
``/config.json`` describes the layout (each field's name, WGSL type, scalar
type, component count and byte offset, and the padded size) from the one
:class:`bokehfit.gpu.layout.Struct` (:meth:`~bokehfit.gpu.layout.Struct.layout_json`),
so the page packs the bytes at the offsets NumPy uses.

Routes
------
``GET /``, ``/viewer.js``, ``/style.css``
    The page (package data of :mod:`bokehfit.view`).
``GET /pathtrace.wgsl``
    The path tracer's WGSL, every include resolved.
``GET /display.wgsl``
    The page's display pass (``shaders/display.wgsl``): the accumulation buffer
    through ``tone_map_srgb8`` of ``shaders/tonemap.wgsl``, the WGSL twin of the
    tone map that ``bokehfit render`` writes PNGs with, into RGBA8.
``GET /config.json``
    Uniform layout, entry points and workgroup sizes (read from the WGSL),
    scene sketch (walls, block, balls, camera), lens constants, shapes,
    slider ranges and the default settings.
``GET /params.json?shape=&angle=&fstop=&focus=&blades=&aspect=&width=&height=&mask=``
    The uniform record's values for these settings (tile = the whole image,
    sample_index 0), the lens as text and JSON, and the depth of field.
    ``mask`` names an uploaded mask (its digest) for shape ``mask``.
    Bad settings: 400 with ``{"error": message}``.
``POST /matched``
    Body (``application/json``): a ``bokehfit compare --json`` document; answer: the viewer
    settings of its fitted aperture (:func:`settings_from_compare`).
``POST /mask``
    Body (``image/png``): an image file (PNG) of transmission, the custom ``mask`` aperture
    of design.md §3b; the server builds its :class:`~bokehfit.apertures.MaskTable`
    (:func:`~bokehfit.apertures.mask.decode_mask`, the same code as
    ``--mask`` of the command line), keeps the last ``MAX_MASKS`` by digest
    and answers the digest, size and the URL of its tables.
``GET /mask_table?mask=DIGEST``
    The mask's CDF tables as little-endian float32 (``MaskTable.gpu_table``):
    the contents of the path tracer's ``mask_table`` binding, which the page
    uploads as they are.

``GET /photo``, ``/photo.js``; ``/photo/info.json``, ``/photo/image.jpg``
    With a photo (``bokehfit view PHOTO``, :mod:`bokehfit.view.photo`): its page,
    its name, size, sha256 and the shapes a refit may try, and its display copy.
    ``info.json`` also says how to run the kernel renderer (:func:`kernel_config`).
``GET /photo/kernel_mc.wgsl``
    The Monte-Carlo kernel renderer (``shaders/kernel_mc.wgsl``, every include
    resolved, as :mod:`bokehfit.kernels.mc` compiles it): the page draws each
    fitted disc's kernel with it, packing its ``KernelParams`` and ``ApertureParams``
    by the layouts in ``info.json``.
``GET /photo/job?job=N``, ``/photo/result.json?job=N``, ``/photo/tiles.json?job=N``, ``/photo/report.html?job=N``
    A compare's state (running with its stage, done, failed, cancelled); once
    done, its ``compare --json`` document, its disc tiles (with what the kernel
    needs: :func:`bokehfit.view.photo.kernel_tile`) and aperture diagram,
    and its HTML report (job 0, the default: the automatic compare).
``POST /photo/refit``, ``/photo/cancel``, ``/photo/discs-file``
    Start a compare on exactly the page's discs (``{"discs": [{"center_xy":
    [x, y], "diameter_px": D}], "shapes": [...]}``, checked by
    :func:`bokehfit.view.photo.refit_labels`; 202 with its job), stop the one
    running, or answer the picks as a discs file (the labels' format).
    Without a photo every ``/photo`` route answers 404.

Every other path answers 404, and a route asked with a method it does not
serve answers 405 with ``Allow``.

The server listens on 127.0.0.1 only. Its connections are served by
:mod:`bokehfit.view.transport` on one event loop: the whole request head must
arrive within ``REQUEST_TIMEOUT_S`` of the connection and a body within that
plus its length at ``MIN_TRANSFER_RATE`` (408 after; a connection that sent
nothing is closed); at most ``MAX_CONNECTIONS`` sockets, a new one closing the
oldest idle one; one request per connection. Complete requests are answered on
a few threads, bodies one at a time and at most ``BODY_MEMORY_BYTES`` of them
held at once.

Each request is checked in one place before any route sees it: exactly one
Host header, and it names the server (``127.0.0.1:PORT`` or
``localhost:PORT``; else 400 or 421), so that another web site cannot reach it
through a rebound DNS name; a method the path serves (else 405); a request line
and header block within their caps (414, 431); for POST, a write from the
viewer's own page (403 else): an Origin of the server itself (or
``Sec-Fetch-Site: same-origin``) and this run's random token, which the page
receives in its HTML and sends back in ``X-Bokehfit-Token``; the route's
content type (``application/json``, ``image/png``; 415 else), none of which a
page of another site can send without a preflight; a Content-Length within
``MAX_BODY_BYTES`` (411, 413), checked before a byte of the body is read. JSON
bodies are scanned in linear time for their nesting and number of values
before they are parsed (:func:`json_shape`, :func:`parse_json_body`); uploaded
PNGs keep only their pixel chunks (:func:`png_pixels_only`). Every request gets
a status line and a JSON ``{"error": message}`` body when refused; an
unexpected failure answers 500 and logs one line on stderr.
"""

from __future__ import annotations

import gc
import hmac
import io
import json
import math
import re
import secrets
import socket
import struct
import threading
import zlib
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler
from importlib import resources
from urllib.parse import parse_qs, urlsplit

import numpy as np
import orjson

from bokehfit import __version__
from bokehfit.apertures import SHAPES, Aperture, MaskTable, make_aperture
from bokehfit.apertures.mask import MAX_MASK_SIDE, decode_mask
from bokehfit.apertures.shapes import DEFAULT_SLIT_ASPECT, MAX_BLADES
from bokehfit.errors import InputError, check_finite
from bokehfit.gpu.compute import Binding, ComputeInterface
from bokehfit.gpu.layout import Struct
from bokehfit.gpu.shaders import load_shader
from bokehfit.scene import SCENES, Lens, Scene, build_scene, make_lens, make_settings
from bokehfit.scene.camera import FOCAL_LENGTH_MM, FSTOP_RANGE, MAX_IMAGE_SIDE, SENSOR_WIDTH_MM
from bokehfit.scene.renderer import PATHTRACE_INTERFACE, RENDER_PARAMS, render_params, set_tile
from bokehfit.scene.renderer import pathtrace_source as renderer_source
from bokehfit.scene.wgsl import scene_wgsl
from bokehfit.validate import RANGES
from bokehfit.view.transport import Limits, Transport, log_line

__all__ = [
    "COC_DIVISOR",
    "DISPLAY_INTERFACE",
    "DepthOfField",
    "JsonShape",
    "MaskStore",
    "ViewerServer",
    "depth_of_field",
    "display_source",
    "json_depth",
    "json_shape",
    "png_pixels_only",
    "mask_upload",
    "params_for_query",
    "parse_json_body",
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
#: Largest request body of POST /matched and POST /mask (bytes).
MAX_BODY_BYTES = 8 * 2**20
#: Uploaded masks the server keeps (the most recently used); an older one must be uploaded again.
MAX_MASKS = 8
#: Longest request line (method, target and version, bytes): 414 beyond.
MAX_REQUEST_LINE_BYTES = 8192
#: Largest header block (names, values and separators, bytes): 431 beyond. The
#: header parser (http.client) also stops at 100 lines of 64 KiB while reading.
MAX_HEADER_BYTES = 32768
#: Largest head as received (request line, headers, line breaks): the transport
#: stops reading there and the request is answered 431 (bytes).
MAX_HEAD_BYTES = MAX_REQUEST_LINE_BYTES + MAX_HEADER_BYTES + 1024
#: Deepest nesting of arrays and objects in a JSON body (a compare result nests 4 deep).
MAX_JSON_DEPTH = 32
#: Longest integer literal in a JSON body (digits; 2**64 has 20).
MAX_JSON_INT_DIGITS = 32
#: Numbers with an exponent of three digits read one by one for the float range;
#: a body with more is refused (a compare result has none or a few).
MAX_JSON_BIG_EXPONENTS = 1000
#: JSON's white space at the start of a document.
_JSON_SPACE = re.compile(r"[ \t\r\n]*")
#: Most values (and keys) in a JSON body. A compare result (written with indent=1)
#: spends at least 14 bytes a value: at most 600,000 in MAX_BODY_BYTES. A million
#: empty objects take 73 MB once parsed (2.9 MiB of text); MAX_BODY_BYTES of them
#: would take 200 MB.
MAX_JSON_VALUES = 1_000_000
#: The whole request head must arrive within this long of the connection; one
#: that sent nothing by then is closed (s).
REQUEST_TIMEOUT_S = 5.0
#: Slowest body or answer accepted: each has REQUEST_TIMEOUT_S plus its length
#: at this rate (bytes/s; loopback moves gigabytes a second).
MIN_TRANSFER_RATE = float(2**20)
#: Sockets open at once; a new one beyond closes the oldest idle one (at most
#: the process's file limit less a reserve: bokehfit.view.transport).
MAX_CONNECTIONS = 1024
LISTEN_BACKLOG = 256
#: Bodies held in memory at once, by declared length (bytes): the others wait
#: unread. One body at a time is parsed or decoded.
BODY_MEMORY_BYTES = 2 * MAX_BODY_BYTES
#: Threads that answer complete requests.
WORKERS = 4
#: After answering, the server reads what the client still sends (a body it
#: refused unread) for at most this long and this much before it closes the
#: socket, so that the close does not reset the connection before the client
#: has read the answer (s, bytes).
LINGER_S = 2.0
LINGER_BYTES = MAX_BODY_BYTES
#: The header that carries the page's token with every write, and the mark in
#: index.html that the server replaces with the token.
TOKEN_HEADER = "X-Bokehfit-Token"
TOKEN_PLACEHOLDER = b"%BOKEHFIT_TOKEN%"

_STATIC = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/index.html": ("index.html", "text/html; charset=utf-8"),
    "/viewer.js": ("viewer.js", "text/javascript; charset=utf-8"),
    "/style.css": ("style.css", "text/css; charset=utf-8"),
}
#: The pages of ``bokehfit view PHOTO`` (404 where the server has no photo).
_PHOTO_STATIC = {
    "/photo": ("photo.html", "text/html; charset=utf-8"),
    "/photo.js": ("photo.js", "text/javascript; charset=utf-8"),
}
#: The photo's routes: GET for the photo, its results and a refit's state; POST for the writes.
_PHOTO_GET = ("/photo/info.json", "/photo/image.jpg", "/photo/job", "/photo/result.json", "/photo/tiles.json", "/photo/report.html",
              "/photo/kernel_mc.wgsl")
_PHOTO_POST = ("/photo/refit", "/photo/cancel", "/photo/discs-file")
#: The scalar types whose components the page packs (viewer.js, ``Renderer.setValues``).
_PAGE_SCALARS = ("f32", "u32", "i32")
#: The methods each path serves (HEAD wherever GET); every other method answers 405.
_READ = ("GET", "HEAD")
_ROUTES = {
    **{path: _READ for path in _STATIC},
    "/pathtrace.wgsl": _READ,
    "/display.wgsl": _READ,
    "/config.json": _READ,
    "/params.json": _READ,
    "/favicon.ico": _READ,
    "/mask_table": _READ,
    "/matched": ("POST",),
    "/mask": ("POST",),
    **{path: _READ for path in _PHOTO_STATIC},
    **{path: _READ for path in _PHOTO_GET},
    **{path: ("POST",) for path in _PHOTO_POST},
}
#: What the body of each POST route must be, for the message when it is empty.
_POST_BODIES = {"/matched": "a `bokehfit compare --json` result", "/mask": "an image file (PNG) of transmission",
                "/photo/refit": 'the discs to fit ({"discs": [...], "shapes": [...]})', "/photo/cancel": "{}",
                "/photo/discs-file": 'the picked discs ({"discs": [...]})'}
#: The one content type each POST route takes: neither is one a page of another
#: site may send without a preflight (text/plain, forms).
_POST_TYPES = {"/matched": "application/json", "/mask": "image/png", **{path: "application/json" for path in _PHOTO_POST}}
_METHODS = ("GET", "HEAD", "POST")


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


def _shader_interface(source: str, interface: ComputeInterface = PATHTRACE_INTERFACE, filename: str = "pathtrace.wgsl",
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

    interface = _shader_interface(kernel_source(), KERNEL_INTERFACE, "kernel_mc.wgsl",
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


class MaskStore:
    """The masks uploaded to one server (``POST /mask``), by digest: the last ``capacity`` used, thread-safe."""

    def __init__(self, capacity: int = MAX_MASKS):
        self.capacity = capacity
        self._tables: dict[str, MaskTable] = {}
        self._bytes: dict[str, bytes] = {}
        self._lock = threading.Lock()

    def add(self, table: MaskTable) -> str:
        """Keep ``table`` (dropping the least recently used beyond capacity); returns its digest."""
        with self._lock:
            self._tables.pop(table.digest, None)
            self._tables[table.digest] = table
            while len(self._tables) > self.capacity:
                self._bytes.pop(self._tables.pop(next(iter(self._tables))).digest, None)
        return table.digest

    def gpu_bytes(self, digest) -> bytes:
        """``GET /mask_table``: the table of ``digest`` as little-endian float32, made once and shared by every answer."""
        table = self.get(digest)
        with self._lock:
            data = self._bytes.get(table.digest)
        if data is None:
            data = table.gpu_table().astype("<f4").tobytes()
            with self._lock:
                if table.digest in self._tables:
                    self._bytes[table.digest] = data
        return data

    def get(self, digest) -> MaskTable:
        """The table of ``digest``; ``InputError`` where none was uploaded (or it was dropped)."""
        with self._lock:
            table = self._tables.pop(digest, None) if isinstance(digest, str) else None
            if table is None:
                raise InputError(f"mask must name an uploaded mask (got {_brief(digest)}): upload the PNG again (POST /mask)")
            self._tables[digest] = table  # most recently used
            return table


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: The PNG chunks that make a mask's pixels (PNG 3rd edition §5.6; tRNS for palette
#: images); the others (profiles, texts, animation) are dropped unread.
_PNG_PIXEL_CHUNKS = (b"IHDR", b"PLTE", b"tRNS", b"IDAT", b"IEND")
#: Most chunks in an uploaded PNG (an encoder writes a few dozen).
MAX_PNG_CHUNKS = 100_000


def png_pixels_only(data: bytes | bytearray, name: str = "mask", source: str = "the uploaded file") -> bytes:
    """The PNG ``data`` with only the chunks that make its pixels: one pass over the chunk list.

    A PNG's compressed ancillary chunks (iCCP, zTXt, iTXt) are inflated one by
    one when it is opened; thousands of them in a few MiB cost seconds each
    time. A mask needs none of them, so they go before the image is decoded.
    """
    unreadable = f"{name} must be a readable image file (PNG) (got {source}: "
    if bytes(data[:8]) != _PNG_SIGNATURE:
        raise InputError(unreadable + "not a PNG)")
    view = memoryview(data)
    kept, offset, chunks = [view[:8]], 8, 0
    while offset + 12 <= len(data):
        length = int.from_bytes(view[offset : offset + 4], "big")
        kind = bytes(view[offset + 4 : offset + 8])
        end = offset + 12 + length
        if end > len(data):
            raise InputError(unreadable + f"chunk {kind!r} runs past the end of the file)")
        chunks += 1
        if chunks > MAX_PNG_CHUNKS:
            raise InputError(unreadable + f"more than {MAX_PNG_CHUNKS} chunks)")
        if kind in _PNG_PIXEL_CHUNKS:
            kept.append(view[offset:end])
        offset = end
        if kind == b"IEND":
            break
    return b"".join(kept)


def mask_upload(body: bytes | bytearray, store: MaskStore) -> dict:
    """``POST /mask``: the table of the uploaded PNG, kept in ``store``; its digest, size and tables' URL.

    The image is read by the command line's code (:func:`~bokehfit.apertures.mask.decode_mask`)
    from its pixel chunks (:func:`png_pixels_only`); a decoder's failure on a damaged file is one line.
    """
    pixels = png_pixels_only(body)
    try:
        table = decode_mask(pixels, source="the uploaded file")
    except InputError:
        raise
    except (ValueError, SyntaxError, EOFError, MemoryError, struct.error, zlib.error) as error:  # Pillow on damaged data
        raise InputError(f"mask must be a readable image file (PNG) (got the uploaded file: {_brief(str(error), 120)})") from None
    store.add(table)
    height, width = table.shape
    return {
        "mask": table.digest,
        "width": width,
        "height": height,
        "describe": table.describe(),
        "table_url": f"/mask_table?mask={table.digest}",
        "table_floats": int(table.gpu_table().size),
    }


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
    source = _pathtrace_source_cached(scene_name, False)
    focus_far = FOCUS_SLIDER_REACH * _deepest_point_m(scene)
    return {
        "bokehfit_version": __version__,
        "shader": {"url": "/pathtrace.wgsl", **_shader_interface(source)},
        "display": {"url": "/display.wgsl", **_shader_interface(display_source(), DISPLAY_INTERFACE, "display.wgsl")},
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


def _query_int(query: dict, name: str, default=None) -> int | None:
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


def params_for_query(query: dict, scene_name: str = "cornell", masks: MaskStore | None = None) -> dict:
    """``/params.json``: the uniform values, lens and depth of field for the page's settings.

    ``query`` maps names to lists of strings (as from :func:`urllib.parse.parse_qs`):
    shape, angle (degrees), fstop, focus (m), blades (ngon), aspect (slit), width, height,
    and the §3b features: roundness (n-gons), squeeze, rim, vignetting_radius with
    vignetting_shift (both, or neither: no vignetting), chromatic_red with chromatic_blue,
    and for shape ``mask`` the digest of a mask uploaded to ``masks``.
    """
    scene = build_scene(scene_name)
    shape = (query.get("shape") or ["circle"])[-1]
    spec = SHAPES.get(shape)
    pairs = {}
    for pair, keys in (("vignetting", ("radius", "shift")), ("chromatic", ("red", "blue"))):
        values = {key: _query_number(query, f"{pair}_{key}") for key in keys}
        given = [key for key, value in values.items() if value is not None]
        if given and len(given) < 2:
            missing = next(key for key in keys if key not in given)
            raise InputError(f"{pair}_{missing} must be given with {pair}_{given[0]}")
        pairs[pair] = values if given else None
    lens = make_lens(
        shape,
        _query_number(query, "angle", 0.0),
        fstop=_query_number(query, "fstop", 2.8),
        focus_distance_m=_query_number(query, "focus", scene.default_focus_m),
        blades=_query_int(query, "blades") if spec is not None and spec.takes_blades else None,
        aspect=_query_number(query, "aspect") if spec is not None and spec.takes_aspect else None,
        roundness=_query_number(query, "roundness", 0.0) if spec is not None and spec.rounds else 0.0,
        squeeze=_query_number(query, "squeeze", 1.0),
        rim=_query_number(query, "rim", 0.0),
        mask=_query_mask(query, masks) if spec is not None and spec.tabulated else None,
        **pairs,
    )
    width = _query_int(query, "width", DEFAULT_SIZE[0])
    height = _query_int(query, "height", DEFAULT_SIZE[1])
    settings = make_settings(width, height, 1)  # validates the size
    dof = depth_of_field(lens, settings.width, settings.height)
    return {
        "values": uniform_values(lens, settings.width, settings.height, scene),
        "lens": lens.to_json(),
        "describe": lens.describe(),
        "label": lens.aperture.label,
        # The shape's own options of `bokehfit render`, from the model's parameters (blades, aspect).
        "shape_flags": (f" --blades {lens.aperture.blades}" if lens.aperture.spec.takes_blades else "")
        + (f" --aspect {lens.aperture.aspect:g}" if "aspect" in lens.aperture.parameters else ""),
        "symmetry_deg": lens.aperture.symmetry_deg,
        "canonical_angle_deg": lens.aperture.canonical_angle_deg,
        "coc_px_at_infinity": lens.coc_px(math.inf, settings.width),
        "depth_of_field": dof.to_json(),
    }


def _brief(value, limit: int = 40) -> str:
    """``value`` described in one short line, for an error message (never a huge repr)."""
    if isinstance(value, list):
        return f"an array of {len(value)} items"
    if isinstance(value, dict):
        return f"an object of {len(value)} keys"
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 64:
        return f"an integer of {len(str(value)) if value.bit_length() < 10_000 else 'thousands of'} digits"
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _finite_number(name: str, value) -> float:
    """``value`` as a float, or ``InputError`` naming ``name`` where it is not a finite JSON number."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        try:
            number = float(value)
        except OverflowError:  # an int beyond the float range
            number = math.inf
        if math.isfinite(number):
            return number
    raise InputError(f"{name} must be a finite number (got {_brief(value)})")


#: Bytes the JSON scanner looks at in one step (its temporaries are a few times this).
_SCAN_CHUNK = 1 << 18
#: The classes of each byte value, one bit a class, so that one table lookup sorts a step's bytes.
_OPEN, _CLOSE, _SEPARATOR, _NUMBER, _QUOTE, _BACKSLASH, _DIGIT, _SIGN, _EXPONENT = (1 << i for i in range(9))
_BYTE_CLASS = np.zeros(256, dtype=np.uint16)
for _chars, _class in (
    (b"[{", _OPEN), (b"]}", _CLOSE), (b",:", _SEPARATOR), (b'"', _QUOTE), (b"\\", _BACKSLASH),
    (b".", _NUMBER), (b"0123456789", _NUMBER | _DIGIT), (b"+-", _NUMBER | _SIGN), (b"eE", _NUMBER | _EXPONENT),
):
    _BYTE_CLASS[list(_chars)] = _class


@dataclass(frozen=True)
class JsonShape:
    """What :func:`json_shape` counts in a JSON text, without parsing it."""

    depth: int  #: deepest nesting of arrays and objects
    values: int  #: an upper bound of the values and keys: separators and openings outside strings, plus one
    longest_number: int  #: characters of the longest run of number characters (0-9 + - . e E) outside strings
    longest_number_end: int  #: index just past that run
    #: Where an exponent of three digits or more starts outside strings (the only way a short
    #: number leaves the float range), the first MAX_JSON_BIG_EXPONENTS + 1 of them.
    big_exponents: tuple[int, ...]


def _run_ends(mask: np.ndarray, index: np.ndarray, carried: int) -> np.ndarray:
    """For each byte, the index of the last byte at or before it outside ``mask``; before the step, -1 - ``carried``.

    ``i - result[i]`` is then the length of the run of ``mask`` bytes ending at ``i``
    (counting the ``carried`` ones of the step before).
    """
    return np.maximum.accumulate(np.where(mask, np.int32(-1 - carried), index))


def json_shape(body: bytes | bytearray) -> JsonShape:
    """Nesting depth, number of values, longest number and large exponents of the JSON text ``body``, strings left out.

    One pass in fixed steps, linear in the length whatever the bytes: a quote
    is the end of a string unless an odd run of backslashes precedes it (the
    JSON escapes; outside strings a backslash is an error that parsing
    reports), so strings are found without a regular expression that could
    backtrack, and nothing is recursed into.
    """
    data = np.frombuffer(body, dtype=np.uint8)
    backslashes = 0  # the run of backslashes that ends the step before (its parity is what counts)
    number = 0  # the run of number characters that ends the step before
    inside = 0  # this step starts inside a string
    depth = deepest = values = longest = longest_end = 0
    big_exponents: list[int] = []
    for start in range(0, len(data), _SCAN_CHUNK):
        # The step and the 4 bytes after it: an exponent's digits may lie beyond the step.
        ahead = _BYTE_CLASS[data[start : start + _SCAN_CHUNK + 4]]
        kind = ahead[:_SCAN_CHUNK].copy()
        ahead = np.concatenate((ahead[1:], np.zeros(5 - (len(ahead) - len(kind)), dtype=ahead.dtype)))
        index = np.arange(len(kind), dtype=np.int32)
        last_other = _run_ends((kind & _BACKSLASH).astype(bool), index, backslashes & 1)
        run_before = index - 1 - np.concatenate(([np.int32(-1 - (backslashes & 1))], last_other[:-1]))
        quote = (kind & _QUOTE).astype(bool) & ((run_before & 1) == 0)
        in_string = ((np.cumsum(quote, dtype=np.int32) + inside) & 1).astype(bool)
        kind[in_string | quote] = 0  # what is left is outside strings
        opens = (kind & _OPEN).astype(bool)
        steps = opens.astype(np.int8) - (kind & _CLOSE).astype(bool)
        level = depth + np.cumsum(steps, dtype=np.int32)
        deepest = max(deepest, int(level.max()))
        depth = int(level[-1])
        values += int(np.count_nonzero(kind & (_OPEN | _SEPARATOR)))
        runs = index - _run_ends((kind & _NUMBER).astype(bool), index, number)
        end = int(np.argmax(runs))
        if runs[end] > longest:
            longest, longest_end = int(runs[end]), start + end + 1
        if len(big_exponents) <= MAX_JSON_BIG_EXPONENTS:
            # ahead[i + k] is the class of byte i + 1 + k: e or E, then a sign or not, then three digits.
            n = len(kind)
            digits = [(ahead[k : k + n] & _DIGIT).astype(bool) for k in range(4)]
            three = (digits[0] & digits[1] & digits[2]) | ((ahead[:n] & _SIGN).astype(bool) & digits[1] & digits[2] & digits[3])
            found = np.flatnonzero((kind & _EXPONENT).astype(bool) & three)
            big_exponents += (found[: MAX_JSON_BIG_EXPONENTS + 1 - len(big_exponents)] + start).tolist()
        inside = int(in_string[-1])
        backslashes = int(len(kind) - 1 - last_other[-1])
        number = int(runs[-1])
    return JsonShape(deepest, values + 1, longest, longest_end, tuple(big_exponents))


def json_depth(body: bytes | bytearray) -> int:
    """Deepest nesting of arrays and objects in the JSON text ``body`` (:func:`json_shape`)."""
    return json_shape(body).depth


@contextmanager
def _collector_paused():
    """The cyclic garbage collector off inside (unless it was off already).

    Parsed JSON holds no cycles: the collector's passes over a million new
    lists, during the parse and again while they are alive, are pure cost.
    Inside, objects are still freed as soon as the last reference goes.
    """
    collecting = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if collecting:
            gc.enable()


def _check_exponents(body: bytes | bytearray, positions: tuple[int, ...]) -> None:
    """Refuse a number whose exponent (at ``positions``, of three digits or more) leaves the float range (1e999).

    Each such number is read with ``float``; more than ``MAX_JSON_BIG_EXPONENTS``
    of them are refused unread. The numbers are short already (:func:`parse_json_body`).
    """
    if len(positions) > MAX_JSON_BIG_EXPONENTS:
        raise InputError(f"the body is not JSON: more than {MAX_JSON_BIG_EXPONENTS} numbers with exponents of three digits")
    for position in positions:
        start = end = position
        while start > 0 and _BYTE_CLASS[body[start - 1]] & _NUMBER:
            start -= 1
        while end < len(body) and _BYTE_CLASS[body[end]] & _NUMBER:
            end += 1
        token = bytes(body[start:end])
        try:
            finite = math.isfinite(float(token))
        except ValueError:
            continue  # not a number: parsing reports it
        if not finite:
            raise InputError(f"the body is not JSON: the number {token.decode('ascii')} is beyond the float range")


def parse_json_body(
    body: bytes | bytearray, *, max_depth: int = MAX_JSON_DEPTH, max_int_digits: int = MAX_JSON_INT_DIGITS, max_values: int = MAX_JSON_VALUES,
    object_only: bool = False,
):
    """A request body parsed as strict JSON, with bounded nesting, size and numbers, in time linear in its length.

    Parameters
    ----------
    body : bytes
        UTF-8 JSON text.
    max_depth : int
        Deepest nesting of arrays and objects accepted (see :func:`json_shape`).
    max_int_digits : int
        Longest integer literal accepted (digits).
    max_values : int
        Most values and keys accepted (:func:`json_shape`): what bounds the
        parse's time and memory, whatever the body's length.
    object_only : bool
        Refuse, before parsing, a document that is not a JSON object (a
        compare result is one): its values then cost no parse.

    Returns
    -------
    object
        The parsed value; every number in it is a finite float or a bounded int.

    Raises
    ------
    InputError
        One line where the body is not UTF-8, not JSON, nested too deep,
        holds too many values, or holds NaN, ±Infinity, a float beyond the
        float range (1e999) or a longer integer.

    Notes
    -----
    Every check runs on the bytes, before parsing, in time linear in the
    length: :func:`json_shape` gives the depth, the number of values and the
    longest number, which may have at most ``max_int_digits`` digits and a
    sign (a float's shortest repr has at most 24 characters); then the few
    numbers with an exponent of three digits, the only short ones that can
    leave the float range, are read one by one (at most
    ``MAX_JSON_BIG_EXPONENTS``). The body is then parsed by the standard
    orjson (the standard library's C parser where orjson refuses it, for its
    messages), numbers included (a Python hook per number would
    cost more than 0.1 s per MiB of short numbers), with the cyclic garbage
    collector paused (it would walk every new list again and again, for
    nothing: parsed JSON holds no cycles).
    """

    def no_constant(name: str):
        raise ValueError(f"{name} is not a JSON number")

    shape = json_shape(body)  # before decoding: a refused body costs no more memory
    if shape.depth > max_depth:
        raise InputError(f"the body nests {shape.depth} deep: at most {max_depth} is read")
    if shape.values > max_values:
        raise InputError(f"the body holds about {shape.values} values: at most {max_values} are read")
    if shape.longest_number > max_int_digits + 1:
        token = bytes(body[shape.longest_number_end - shape.longest_number : shape.longest_number_end])
        if re.fullmatch(rb"-?[0-9]+", token):
            raise InputError(f"the body is not JSON: an integer of {len(token.lstrip(b'-'))} digits (at most {max_int_digits})")
        raise InputError(f"the body is not JSON: a number of {len(token)} characters (at most {max_int_digits + 1})")
    _check_exponents(body, shape.big_exponents)
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError as error:
        raise InputError(f"the body is not JSON: it is not UTF-8 (byte {error.start})") from None
    start = _JSON_SPACE.match(text).end()
    if object_only and text[start : start + 1] != "{":
        raise InputError("the body must be a `bokehfit compare --json` result: a JSON object with an 'aperture' object")
    with _collector_paused():
        try:
            # orjson (strict RFC 8259: no NaN or Infinity) parses short numbers about four times
            # faster than the standard library; its refusals are read again by the standard
            # library's parser, whose messages name what is wrong in this module's words.
            return orjson.loads(text)
        except orjson.JSONDecodeError:
            pass
        try:
            return json.loads(text, parse_constant=no_constant)
        except RecursionError:  # not reached after the depth check; kept as the last guard
            raise InputError(f"the body nests deeper than {max_depth}: at most {max_depth} is read") from None
        except ValueError as error:  # JSONDecodeError and the hook's refusal
            raise InputError(f"the body is not JSON: {error}") from None


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
        raise InputError(f"compare results of schema_version 1 or 2 are understood (got {_brief(version)})")
    a = document["aperture"]
    shape = a.get("shape")
    if shape is None:
        raise InputError("the compare result fitted no aperture (aperture.shape is null)")
    if not isinstance(shape, str) or shape not in SHAPES:
        raise InputError(f"aperture.shape must be one of {', '.join(SHAPES)} (got {_brief(shape)})")
    spec = SHAPES[shape]
    angle = a.get("angle_deg")
    angle = 0.0 if angle is None else _finite_number("aperture.angle_deg", angle)
    blades = a.get("blades") if spec.takes_blades else None
    if blades is not None and (isinstance(blades, bool) or not isinstance(blades, int) or not 3 <= blades <= MAX_BLADES):
        raise InputError(f"aperture.blades must be an integer from 3 to {MAX_BLADES} (got {_brief(blades)})")
    aspect = a.get("aspect") if spec.takes_aspect else None
    aspect = None if aspect is None else _finite_number("aperture.aspect", aspect)
    for key in ("focus_side", "size_convention", "fstop_reason"):
        if a.get(key) is not None and not isinstance(a[key], str):
            raise InputError(f"aperture.{key} must be a string or null (got {_brief(a[key])})")
    features = {}
    for key, default in (("roundness", 0.0), ("squeeze", 1.0), ("rim", 0.0)):
        value = a.get(key)
        features[key] = default if value is None else _finite_number(f"aperture.{key}", value)
    for pair, keys in (("vignetting", ("radius", "shift")), ("chromatic", ("red", "blue"))):
        value = a.get(pair)
        if value is not None and not (isinstance(value, dict) and all(key in value for key in keys)):
            raise InputError(f"aperture.{pair} must be an object with keys {', '.join(keys)}, or null (got {_brief(value)})")
        features[pair] = None if value is None else {key: _finite_number(f"aperture.{pair}.{key}", value[key]) for key in keys}
    # validates their ranges
    aperture = make_aperture(shape, angle, blades=blades, aspect=aspect, **features)
    notes = []
    fstop = a.get("fstop")
    if fstop is not None:
        fstop = _finite_number("aperture.fstop", fstop)
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


# --- the HTTP server ------------------------------------------------------------------------


class _Refused(Exception):
    """A request answered with ``status`` and a one-line message instead of its route."""

    def __init__(self, status: HTTPStatus, message: str, headers: tuple[tuple[str, str], ...] = ()):
        super().__init__(message)
        self.status = status
        self.message = message
        self.headers = headers


@lru_cache(maxsize=None)
def _static_file(name: str) -> bytes:
    """A file of the page (package data), read once: every answer shares the one copy."""
    return resources.files("bokehfit.view").joinpath("static", name).read_bytes()


def _download_stem(name: str) -> str:
    """The photo's stem for a download's file name, in characters safe in a header."""
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", name.rsplit(".", 1)[0])[:80]
    return f"{stem or 'photo'}_bokehfit"


def _photo_json_bytes(result: dict) -> bytes:
    """A result's ``compare --json`` document as the command writes it (indent 1)."""
    return (json.dumps(result["json"], indent=1, allow_nan=False) + "\n").encode("utf-8")


@lru_cache(maxsize=8)
def _pathtrace_bytes(scene_name: str) -> bytes:
    return _pathtrace_source_cached(scene_name, False).encode("utf-8")


class _Site:
    """What every request of one server shares: its names, its token, its masks and its settings."""

    def __init__(self, port: int, scene_name: str, size: tuple[int, int], verbose: bool, photo=None):
        self.photo = photo
        self.scene_name = scene_name
        self.size = size
        self.verbose = verbose
        self.masks = MaskStore()
        self.own_hosts = (f"127.0.0.1:{port}", f"localhost:{port}")
        self.own_origins = tuple(f"http://{host}" for host in self.own_hosts)
        #: The per-run secret the page sends back with every write (in the page it is served).
        self.token = secrets.token_urlsafe(32)
        self.page = _static_file("index.html").replace(TOKEN_PLACEHOLDER, self.token.encode("ascii"))
        self.photo_page = _static_file("photo.html").replace(TOKEN_PLACEHOLDER, self.token.encode("ascii"))


class _Handler(BaseHTTPRequestHandler):
    """One request: its head checked in :meth:`begin` (on the event loop), its route run in :meth:`respond`.

    The standard library's request parsing and answering, on the bytes the
    transport (:mod:`bokehfit.view.transport`) collected: ``rfile`` holds the
    head, ``wfile`` collects the answer, which the transport sends.
    """

    server_version = f"bokehfit-view/{__version__}"

    def __init__(self, site: _Site):  # not BaseHTTPRequestHandler's: no socket, no handle() on construction
        self.server = site
        self.client_address = ("127.0.0.1", 0)
        self.rfile = io.BytesIO()
        self.wfile = io.BytesIO()
        self.command, self.requestline, self.request_version = "", "", "HTTP/1.0"
        self.close_connection = True  # one request per connection
        self._answered = False
        self._route = None
        self._body = b""  # the answer's body, sent after wfile's head (shared, never copied)

    def log_message(self, format, *args):  # quiet unless --verbose: keep the terminal clean
        if self.server.verbose:
            super().log_message(format, *args)

    # --- answering --------------------------------------------------------------------------

    def _send(self, status: int, body: bytes, content_type: str, headers: tuple[tuple[str, str], ...] = ()) -> None:
        self._answered = True
        self.send_response(status)
        for name, value in headers:
            self.send_header(name, value)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.send_header("Connection", "close")
        self.end_headers()
        if self.command != "HEAD":
            self._body = body

    def _json(self, status: int, data, headers: tuple[tuple[str, str], ...] = ()) -> None:
        body = json.dumps(data, allow_nan=False).encode("utf-8")
        self._send(status, body, "application/json; charset=utf-8", headers)

    def _error(self, status: int, message: str, headers: tuple[tuple[str, str], ...] = ()) -> None:
        self.log_message('"%s" %d %s', self.requestline[:200], int(status), message)
        self._json(status, {"error": message}, headers)

    def send_error(self, code, message=None, explain=None):
        """The standard library's refusals (bad request line or headers) as JSON like every other."""
        status = HTTPStatus(code)
        self.request_version = "HTTP/1.0"  # a status line even where the request line was unreadable
        self._error(status, f"{status.phrase}: {message}" if message else status.phrase)

    def _answer_late(self, status: HTTPStatus, message: str, headers: tuple[tuple[str, str], ...] = ()) -> None:
        """Answer a failure unless an answer has started."""
        if not self._answered:
            self._error(status, message, headers)

    def _internal(self, error: Exception) -> None:
        """A bug: one line on stderr, 500 to the client."""
        log_line(f"internal error answering {self.requestline[:200]!r}: {type(error).__name__}: {error}")
        self._answer_late(HTTPStatus.INTERNAL_SERVER_ERROR, f"internal error: {type(error).__name__} (see the terminal of `bokehfit view`)")

    # --- the transport's side (bokehfit.view.transport.Exchange) ----------------------------

    def begin(self, head: bytes, too_large: bool) -> int | None:
        """Read and check the head; the body's length to read (0: none), or None where the answer is ready."""
        self.rfile = io.BytesIO(head)
        try:
            self.raw_requestline = self.rfile.readline(MAX_REQUEST_LINE_BYTES + 1)
            if len(self.raw_requestline) > MAX_REQUEST_LINE_BYTES:
                raise _Refused(HTTPStatus.REQUEST_URI_TOO_LONG, f"the request line must be at most {MAX_REQUEST_LINE_BYTES} bytes")
            if not self.raw_requestline.endswith(b"\n"):
                raise _Refused(HTTPStatus.BAD_REQUEST, "the request line ended without a line break")
            if not self.raw_requestline.strip():
                raise _Refused(HTTPStatus.BAD_REQUEST, "the request line is empty")
            if too_large:
                raise _Refused(HTTPStatus.REQUEST_HEADER_FIELDS_TOO_LARGE, f"the headers must be at most {MAX_HEADER_BYTES} bytes")
            if not self.parse_request():
                return None  # parse_request answered through send_error
            if self.request_version == "HTTP/0.9":
                self.request_version = "HTTP/1.0"  # answer with a status line all the same
                raise _Refused(HTTPStatus.BAD_REQUEST, "the request line must end with HTTP/1.0 or HTTP/1.1")
            self._route, length = self._check_request()
            return length
        except _Refused as refused:
            self._answer_late(refused.status, refused.message, refused.headers)
        except Exception as error:
            self._internal(error)
        return None

    def respond(self, body: bytes | bytearray) -> None:
        """Run the route of a request that :meth:`begin` accepted, its body read."""
        try:
            self._route(body)
        except _Refused as refused:
            self._answer_late(refused.status, refused.message, refused.headers)
        except InputError as error:
            self._answer_late(HTTPStatus.BAD_REQUEST, str(error))
        except Exception as error:
            self._internal(error)

    def refuse(self, status: int, message: str) -> None:
        self._answer_late(HTTPStatus(status), message)

    def output(self) -> tuple[bytes, ...]:
        return self.wfile.getvalue(), self._body

    # --- the one gate -----------------------------------------------------------------------

    def _check_request(self):
        """The one gate before any route: Host, target, method, header size, body headers, writes.

        Returns the bound method that answers the request and the body's length; raises ``_Refused``.
        """
        hosts = self.headers.get_all("Host") or []
        if len(hosts) != 1:
            raise _Refused(HTTPStatus.BAD_REQUEST, f"a request must carry exactly one Host header (got {len(hosts)})")
        if hosts[0].strip().lower() not in self.server.own_hosts:
            raise _Refused(HTTPStatus.MISDIRECTED_REQUEST, "unknown Host: open the URL that `bokehfit view` printed")
        size = sum(len(name) + len(value) + 4 for name, value in self.headers.items())
        if size > MAX_HEADER_BYTES:
            raise _Refused(HTTPStatus.REQUEST_HEADER_FIELDS_TOO_LARGE, f"the headers must be at most {MAX_HEADER_BYTES} bytes (got {size})")
        try:
            url = urlsplit(self.path)
        except ValueError:  # e.g. an unbalanced [ in an authority
            url = None
        if url is None or not self.path.startswith("/") or url.netloc:
            raise _Refused(HTTPStatus.BAD_REQUEST, "the request target must be a path starting with /")
        allowed = _ROUTES.get(url.path)
        if self.command not in (allowed or _METHODS):
            allow = ", ".join(allowed or _METHODS)
            raise _Refused(HTTPStatus.METHOD_NOT_ALLOWED, f"{self.command[:20]} is not served here (Allow: {allow})", (("Allow", allow),))
        if allowed is None:
            raise _Refused(HTTPStatus.NOT_FOUND, f"no such page: {url.path[:200]}")
        if self.headers.get_all("Transfer-Encoding"):
            raise _Refused(HTTPStatus.LENGTH_REQUIRED, "send the body with a Content-Length (Transfer-Encoding is not read)")
        if self.command == "POST":
            self._check_write(url.path)
            return self._post, self._content_length()
        return self._get, 0

    def _one_header(self, name: str) -> str | None:
        """The value of header ``name``, None where absent; refused where it is given twice."""
        values = self.headers.get_all(name) or []
        if len(values) > 1:
            raise _Refused(HTTPStatus.BAD_REQUEST, f"a request must carry at most one {name} header (got {len(values)})")
        return values[0].strip() if values else None

    def _check_write(self, path: str) -> None:
        """A write comes from the viewer's own page: its Origin, its token and the route's content type.

        A page of another site can make the browser send a POST here (the
        browser names the right Host), but only a "simple" one: without
        custom headers and with a form or text content type, and with its own
        Origin. The token is in the served page only (another site cannot
        read it: no CORS), and any other content type or the token header
        would need a preflight (OPTIONS, answered 405).
        """
        origin = self._one_header("Origin")
        site = self._one_header("Sec-Fetch-Site")
        if origin is not None and origin.lower() not in self.server.own_origins:
            raise _Refused(HTTPStatus.FORBIDDEN, f"writes are taken from the viewer's own page only (Origin {_brief(origin)})")
        if site is not None and site.lower() != "same-origin":
            raise _Refused(HTTPStatus.FORBIDDEN, f"writes are taken from the viewer's own page only (Sec-Fetch-Site {_brief(site)})")
        if origin is None and site is None:
            raise _Refused(HTTPStatus.FORBIDDEN, "a write must carry the Origin of the viewer's page (or Sec-Fetch-Site: same-origin)")
        token = self._one_header(TOKEN_HEADER)
        if token is None or not hmac.compare_digest(token.encode("latin-1"), self.server.token.encode("latin-1")):
            raise _Refused(HTTPStatus.FORBIDDEN, f"a write must carry this run's {TOKEN_HEADER} of the page: reload the page")
        wanted = _POST_TYPES[path]
        given = self._one_header("Content-Type")
        if given is None or given.split(";")[0].strip().lower() != wanted:
            raise _Refused(HTTPStatus.UNSUPPORTED_MEDIA_TYPE, f"POST {path} takes Content-Type: {wanted} (got {_brief(given)})")

    def _content_length(self) -> int:
        """The POST body's declared length: one Content-Length, 1 byte to MAX_BODY_BYTES."""
        values = self.headers.get_all("Content-Length") or []
        if not values:
            raise _Refused(HTTPStatus.LENGTH_REQUIRED, "a POST request must carry a Content-Length")
        if len(values) != 1 or not values[0].strip().isdigit() or not values[0].strip().isascii():
            raise _Refused(HTTPStatus.BAD_REQUEST, "the Content-Length must be one decimal number")
        digits = values[0].strip()
        if len(digits) > 12 or int(digits) > MAX_BODY_BYTES:
            raise _Refused(HTTPStatus.REQUEST_ENTITY_TOO_LARGE, f"the body must be at most {MAX_BODY_BYTES >> 20} MiB")
        if int(digits) == 0:
            raise _Refused(HTTPStatus.BAD_REQUEST, f"the body is empty: send {_POST_BODIES[urlsplit(self.path).path]}")
        return int(digits)

    # --- the routes -------------------------------------------------------------------------

    def _get(self, body: bytes) -> None:
        url = urlsplit(self.path)
        try:
            if url.path in _STATIC:
                name, content_type = _STATIC[url.path]
                page = self.server.page if name == "index.html" else _static_file(name)
                return self._send(HTTPStatus.OK, page, content_type)
            if url.path == "/pathtrace.wgsl":
                return self._send(HTTPStatus.OK, _pathtrace_bytes(self.server.scene_name), "text/wgsl; charset=utf-8")
            if url.path == "/display.wgsl":
                return self._send(HTTPStatus.OK, display_source().encode("utf-8"), "text/wgsl; charset=utf-8")
            if url.path == "/config.json":
                return self._json(HTTPStatus.OK, viewer_config(self.server.scene_name, self.server.size))
            if url.path == "/params.json":
                return self._json(HTTPStatus.OK, params_for_query(parse_qs(url.query), self.server.scene_name, self.server.masks))
            if url.path == "/mask_table":
                table = self.server.masks.gpu_bytes((parse_qs(url.query).get("mask") or [None])[-1])
                return self._send(HTTPStatus.OK, table, "application/octet-stream")
            if url.path == "/favicon.ico":
                return self._send(HTTPStatus.NO_CONTENT, b"", "image/x-icon")
            if url.path in _PHOTO_STATIC or url.path in _PHOTO_GET:
                return self._photo_get(url)
        except InputError as error:
            return self._error(HTTPStatus.BAD_REQUEST, str(error))
        raise RuntimeError(f"route {url.path!r} is in _ROUTES but has no answer")

    def _photo_session(self):
        if self.server.photo is None:
            raise _Refused(HTTPStatus.NOT_FOUND, "no photo here: start `bokehfit view PHOTO` to compare one")
        return self.server.photo

    def _photo_get(self, url) -> None:
        session = self._photo_session()
        if url.path in _PHOTO_STATIC:
            name, content_type = _PHOTO_STATIC[url.path]
            return self._send(HTTPStatus.OK, self.server.photo_page if name == "photo.html" else _static_file(name), content_type)
        if url.path == "/photo/info.json":
            return self._json(HTTPStatus.OK, {**session.info(), "kernel": kernel_config()})
        if url.path == "/photo/kernel_mc.wgsl":
            return self._send(HTTPStatus.OK, kernel_source().encode("utf-8"), "text/wgsl; charset=utf-8")
        if url.path == "/photo/image.jpg":
            return self._send(HTTPStatus.OK, session.display_jpeg, "image/jpeg")
        query = parse_qs(url.query)
        job = _query_int(query, "job", session.auto_job)
        if url.path == "/photo/job":
            return self._json(HTTPStatus.OK, session.status(job))
        result = session.result(job)
        if url.path == "/photo/result.json":
            headers = (("Content-Disposition", f'inline; filename="{_download_stem(session.name)}.json"'),)
            return self._send(HTTPStatus.OK, _photo_json_bytes(result), "application/json; charset=utf-8", headers)
        if url.path == "/photo/tiles.json":
            from bokehfit.report.html import aperture_diagram

            aperture = result["json"]["aperture"]
            svg = aperture_diagram(aperture) if aperture.get("shape") is not None else None
            return self._json(HTTPStatus.OK, {"job": job, "tiles": result["tiles"], "aperture_svg": svg, "summary": result["summary"]})
        headers = (("Content-Disposition", f'inline; filename="{_download_stem(session.name)}.html"'),)
        return self._send(HTTPStatus.OK, result["html"].encode("utf-8"), "text/html; charset=utf-8", headers)

    def _photo_post(self, path: str, body: bytes | bytearray) -> None:
        session = self._photo_session()
        with _collector_paused():
            document = parse_json_body(body, object_only=True)
        if path == "/photo/refit":
            return self._json(HTTPStatus.ACCEPTED, {"job": session.refit(document)})
        if path == "/photo/cancel":
            return self._json(HTTPStatus.OK, session.cancel())
        from bokehfit.view.photo import discs_file, refit_labels

        labels, _ = refit_labels({"discs": document.get("discs")}, session.width, session.height)
        return self._json(HTTPStatus.OK, discs_file(labels, session.name, session.sha256, session.width, session.height))

    def _post(self, body: bytes | bytearray) -> None:  # /matched, /mask and the photo's writes
        # One body at a time reaches here (the transport answers bodies on one thread).
        if urlsplit(self.path).path in _PHOTO_POST:
            return self._photo_post(urlsplit(self.path).path, body)
        if urlsplit(self.path).path == "/mask":
            answer = mask_upload(body, self.server.masks)
        else:
            with _collector_paused():  # the document is dropped before the collector runs again
                answer = settings_from_compare(parse_json_body(body, object_only=True))
        self._json(HTTPStatus.OK, answer)


class ViewerServer:
    """The viewer's HTTP server on 127.0.0.1 (``port=0``: any free port).

    ``request_timeout_s``: the whole request head must arrive within this
    long of the connection (408 after; a connection that sent nothing is
    closed), and a body within this long plus its length at
    ``MIN_TRANSFER_RATE`` bytes/s. ``max_connections``: sockets open at once
    (idle ones are closed to make room). Use ``serve_forever()`` in the
    foreground, or ``start()`` for a background thread (tests); ``close()``
    stops it. A context manager.

    Examples
    --------
    >>> with ViewerServer(port=0).start() as server:  # doctest: +SKIP
    ...     print(server.url)
    http://127.0.0.1:54321/
    """

    def __init__(
        self,
        port: int = 0,
        *,
        scene: str = "cornell",
        size: tuple[int, int] = DEFAULT_SIZE,
        verbose: bool = False,
        request_timeout_s: float = REQUEST_TIMEOUT_S,
        max_connections: int = MAX_CONNECTIONS,
        photo=None,
    ):
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise InputError(f"port must be an integer from 0 to 65535 (got {port!r})")
        if check_finite("request_timeout_s", request_timeout_s) <= 0:
            raise InputError(f"request_timeout_s must be greater than 0 (got {request_timeout_s!r})")
        if isinstance(max_connections, bool) or not isinstance(max_connections, int) or max_connections < 1:
            raise InputError(f"max_connections must be a positive integer (got {max_connections!r})")
        if scene not in SCENES or not isinstance(build_scene(scene), Scene):
            raise InputError(f"the viewer path-traces the scene 'cornell' (got {scene!r})")
        make_settings(size[0], size[1], 1)  # validates the size
        # Build the shaders now: a broken install fails here, not in the browser.
        _pathtrace_source_cached(scene, False)
        display_source()
        session = None
        if photo is not None:  # read the photo first: a bad one is refused before the socket opens
            from bokehfit.view.photo import PhotoSession

            session = photo if isinstance(photo, PhotoSession) else PhotoSession(photo)
        try:
            self._listener = socket.create_server(("127.0.0.1", port), backlog=LISTEN_BACKLOG)
        except BaseException:
            if session is not None:
                session.close()
            raise
        self._site = _Site(self.port, scene, tuple(size), verbose, session)
        limits = Limits(
            request_timeout_s=float(request_timeout_s),
            min_rate_bytes_per_s=MIN_TRANSFER_RATE,
            max_head_bytes=MAX_HEAD_BYTES,
            max_connections=max_connections,
            body_memory_bytes=BODY_MEMORY_BYTES,
            workers=WORKERS,
            linger_s=LINGER_S,
            linger_bytes=LINGER_BYTES,
        )
        self._transport = Transport(self._listener, lambda: _Handler(self._site), limits, log_line)
        self._thread: threading.Thread | None = None

    @property
    def host(self) -> str:
        return self._listener.getsockname()[0]

    @property
    def port(self) -> int:
        return self._listener.getsockname()[1]

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/"

    @property
    def photo(self):
        """The :class:`~bokehfit.view.photo.PhotoSession` of ``bokehfit view PHOTO`` (None without a photo)."""
        return self._site.photo

    @property
    def photo_url(self) -> str | None:
        """The photo's page (None without a photo)."""
        return None if self._site.photo is None else f"{self.url}photo"

    @property
    def token(self) -> str:
        """This run's write token (the page receives it in its HTML)."""
        return self._site.token

    @property
    def max_connections(self) -> int:
        """Sockets open at once: ``max_connections``, or fewer where the process's file limit is lower."""
        return self._transport.cap

    def serve_forever(self) -> None:
        """Serve until :meth:`close` (from another thread) or Ctrl-C (KeyboardInterrupt)."""
        self._transport.run()

    def start(self) -> ViewerServer:
        """Serve from a daemon thread; returns self."""
        self._thread = threading.Thread(target=self.serve_forever, name="bokehfit-view", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop serving (if started in a thread) and close the socket."""
        self._transport.stop()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        self._listener.close()
        if self._site.photo is not None:
            self._site.photo.close()

    def __enter__(self) -> ViewerServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
