"""What the path tracer's scenes are made of, and their GPU buffer layouts.

A :class:`Scene` is a list of analytic shapes (quads, boxes turned about the
vertical axis, spheres), named materials, and the camera's pose. Only what a
Cornell box needs: no meshes, no BVH. The buffers follow ``shaders/scene.wgsl``;
each layout is one :class:`bokehfit.gpu.layout.Struct` (points and
directions are ``vec3f`` fields) whose WGSL size is a multiple of 16 bytes, so
that the NumPy record (padded to 16 bytes) and the WGSL array stride agree.

World space is right-handed, y up, metres. The camera's right is
``forward × up`` (as in Mitsuba's ``look_at``, whose "left" is ``up × forward``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bokehfit.errors import InputError
from bokehfit.gpu.layout import Struct

__all__ = [
    "MATERIAL_KINDS",
    "MATERIAL",
    "QUAD",
    "BOX",
    "SPHERE",
    "Material",
    "Quad",
    "Box",
    "Sphere",
    "Pose",
    "Scene",
    "scene_buffers",
]

#: Material kinds, in the order of the MATERIAL_* constants of scene.wgsl.
MATERIAL_KINDS = ("diffuse", "mirror", "emitter")

MATERIAL = Struct(
    "Material",
    (
        ("kind", "u32"),
        ("albedo", "vec3f"),
        ("emission", "vec3f"),
        ("checker_size", "f32"),
        ("checker_contrast", "f32"),
        ("line_spacing", "f32"),
        ("line_width", "f32"),
        ("line_albedo", "f32"),
    ),
)
QUAD = Struct("Quad", (("origin", "vec3f"), ("u", "vec3f"), ("v", "vec3f"), ("material", "u32")))
#: ``axis_xz``: the box's local x axis (cos a, sin a) in world (x, z).
BOX = Struct("Box", (("center", "vec3f"), ("half", "vec3f"), ("axis_xz", "vec2f"), ("material", "u32")))
SPHERE = Struct("Sphere", (("center", "vec3f"), ("radius", "f32"), ("material", "u32")))

for _struct in (MATERIAL, QUAD, BOX, SPHERE):
    # A NumPy array of records strides by the dtype's 16-byte multiple, a WGSL array by SizeOf.
    assert _struct.size == _struct.dtype.itemsize, f"{_struct.name}: its WGSL size must be a multiple of 16 bytes"

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Material:
    """A surface: Lambertian ``diffuse`` (optionally textured), perfect ``mirror``, or ``emitter``.

    ``albedo`` is the diffuse albedo or the mirror's reflectance; ``emission``
    the emitter's radiance (W·sr⁻¹·m⁻², per channel). The texture (diffuse only)
    darkens every other ``checker_size`` square by ``checker_contrast`` and
    draws lines ``line_width`` wide of albedo ``line_albedo`` every
    ``line_spacing`` metres along both edges of the quad.
    """

    name: str
    kind: str
    albedo: Vec3 = (0.0, 0.0, 0.0)
    emission: Vec3 = (0.0, 0.0, 0.0)
    checker_size: float = 0.0
    checker_contrast: float = 1.0
    line_spacing: float = 0.0
    line_width: float = 0.0
    line_albedo: float = 0.0

    def __post_init__(self):
        if self.kind not in MATERIAL_KINDS:
            raise InputError(f"material kind must be one of {', '.join(MATERIAL_KINDS)} (got {self.kind!r})")

    def albedo_at(self, uv: np.ndarray) -> np.ndarray:
        """Diffuse albedo at texture coordinates ``uv`` (..., 2) in metres: (..., 3).

        NumPy twin of ``surface_albedo`` in scene.wgsl.
        """
        uv = np.asarray(uv, dtype=np.float64)
        albedo = np.broadcast_to(np.asarray(self.albedo, dtype=np.float64), uv.shape[:-1] + (3,)).copy()
        if self.checker_size > 0.0:
            cell = np.floor(uv / self.checker_size)
            odd = np.abs(cell[..., 0] + cell[..., 1]) % 2.0 == 1.0
            albedo[odd] *= self.checker_contrast
        if self.line_spacing > 0.0:
            along = (uv / self.line_spacing - np.floor(uv / self.line_spacing)) * self.line_spacing
            on_line = (along[..., 0] < self.line_width) | (along[..., 1] < self.line_width)
            albedo[on_line] = self.line_albedo
        return albedo


@dataclass(frozen=True)
class Quad:
    """Parallelogram ``origin + α·u + β·v`` (0 ≤ α, β ≤ 1); an emitter emits along ``u × v``."""

    origin: Vec3
    u: Vec3
    v: Vec3
    material: str

    @property
    def normal(self) -> np.ndarray:
        n = np.cross(self.u, self.v)
        return n / np.linalg.norm(n)

    @property
    def area(self) -> float:
        return float(np.linalg.norm(np.cross(self.u, self.v)))


@dataclass(frozen=True)
class Box:
    """Box of half-size ``half`` about ``center``, turned by ``angle_deg`` about +y.

    Its local x axis points along (cos a, 0, sin a) in world (x, z).
    """

    center: Vec3
    half: Vec3
    angle_deg: float
    material: str


@dataclass(frozen=True)
class Sphere:
    center: Vec3
    radius: float
    material: str


@dataclass(frozen=True)
class Pose:
    """Where the camera stands and looks (unit ``forward``; ``up`` need not be exactly perpendicular)."""

    position: Vec3
    forward: Vec3 = (0.0, 0.0, 1.0)
    up: Vec3 = (0.0, 1.0, 0.0)

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Orthonormal (right, up, forward) with right = forward × up."""
        forward = np.asarray(self.forward, dtype=np.float64)
        forward = forward / np.linalg.norm(forward)
        right = np.cross(forward, self.up)
        right = right / np.linalg.norm(right)
        up = np.cross(right, forward)
        return right, up, forward

    def depth(self, point) -> float:
        """Distance of ``point`` from the camera along the view axis (metres)."""
        return float(np.dot(np.asarray(point, dtype=np.float64) - self.position, self.basis()[2]))


@dataclass(frozen=True)
class Scene:
    """A path-traced scene: shapes, materials by name, the camera's pose and a default focus."""

    name: str
    materials: tuple[Material, ...]
    quads: tuple[Quad, ...] = ()
    boxes: tuple[Box, ...] = ()
    spheres: tuple[Sphere, ...] = ()
    pose: Pose = field(default_factory=lambda: Pose((0.0, 0.0, 0.0)))
    default_focus_m: float = 1.0

    def material(self, name: str) -> Material:
        for m in self.materials:
            if m.name == name:
                return m
        raise InputError(f"scene {self.name!r} has no material {name!r}")

    @property
    def lights(self) -> tuple[Quad, ...]:
        """The emitting quads (next-event estimation samples these)."""
        return tuple(q for q in self.quads if self.material(q.material).kind == "emitter")


def _records(struct: Struct, rows: list[dict]) -> np.ndarray:
    # A binding may not be empty: an absent kind of shape still gets one zero record
    # (the shader's count keeps it unused).
    array = np.zeros(max(1, len(rows)), dtype=struct.dtype)
    for i, row in enumerate(rows):
        for key, value in row.items():
            array[i][key] = value
    return array


def scene_buffers(scene: Scene) -> dict[str, object]:
    """The scene's storage-buffer contents (NumPy records) and counts.

    Emitting quads come first, in the order given, so the shader can pick one
    of the first ``light_count`` quads for next-event estimation; the planar
    mirrors follow (``mirror_count``), which it reaches lights through.
    """
    index = {m.name: i for i, m in enumerate(scene.materials)}
    for shape in (*scene.quads, *scene.boxes, *scene.spheres):
        if shape.material not in index:
            raise InputError(f"scene {scene.name!r}: unknown material {shape.material!r}")
    for quad in scene.quads:
        if not quad.area > 0.0:
            raise InputError(f"scene {scene.name!r}: a quad has zero area ({quad})")
    for sphere in scene.spheres:
        if not sphere.radius > 0.0:
            raise InputError(f"scene {scene.name!r}: a sphere has radius {sphere.radius!r}")
    lights = scene.lights
    mirrors = [q for q in scene.quads if scene.material(q.material).kind == "mirror"]
    quads = list(lights) + mirrors + [q for q in scene.quads if q not in lights and q not in mirrors]
    materials = [
        dict(
            kind=MATERIAL_KINDS.index(m.kind),
            albedo=m.albedo,
            emission=m.emission,
            checker_size=m.checker_size,
            checker_contrast=m.checker_contrast,
            line_spacing=m.line_spacing,
            line_width=m.line_width,
            line_albedo=m.line_albedo,
        )
        for m in scene.materials
    ]
    quad_rows = [dict(origin=q.origin, u=q.u, v=q.v, material=index[q.material]) for q in quads]
    box_rows = [
        dict(
            center=b.center,
            half=b.half,
            axis_xz=(math.cos(math.radians(b.angle_deg)), math.sin(math.radians(b.angle_deg))),
            material=index[b.material],
        )
        for b in scene.boxes
    ]
    sphere_rows = [dict(center=s.center, radius=s.radius, material=index[s.material]) for s in scene.spheres]
    return dict(
        materials=_records(MATERIAL, materials),
        quads=_records(QUAD, quad_rows),
        boxes=_records(BOX, box_rows),
        spheres=_records(SPHERE, sphere_rows),
        quad_count=len(quads),
        box_count=len(scene.boxes),
        sphere_count=len(scene.spheres),
        light_count=len(lights),
        mirror_count=len(mirrors),
    )
