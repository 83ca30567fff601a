"""Independent test renders: Blender Cycles with apertures made by geometry.

The renders in ``tests/data/cycles/`` test bokehfit on images that no part of
bokehfit made: Blender's path tracer renders point-like lights through a
camera whose aperture is a hole in a thin plate, so every disc's shape comes
from the geometry below and its ground truth from the derivations below, never
from bokehfit's own model or code.

Run it with a Python that has Blender's ``bpy`` module (Blender 5.0, CPython
3.11), outside the project's environment; CI does not need it::

    python3.11 -m venv ~/bpyvenv
    ~/bpyvenv/bin/pip install bpy==5.0.1 numpy
    ~/bpyvenv/bin/python benchmarks/cycles/make_renders.py [--out tests/data/cycles] [--only NAME ...]
        [--samples N] [--threads N] [--list]

It writes each render (8-bit sRGB PNG, and for some a 16-bit PNG too) and
``truth.json``; ``--only`` renders some of them and merges their entries into
an existing ``truth.json``; ``--truth-only`` rewrites ``truth.json`` from the
files there. Rendering is on the CPU, without denoising; the full set took
about 30 minutes on two busy cores (each render's time is in ``truth.json``).

Scene and derivations
---------------------
Lengths in metres unless the name says ``_mm``; the camera sits at the origin
and looks along −z, camera x to the right and y up, which is the aperture frame
of design.md §2 (x right, y up, seen from behind the camera).

*Camera.* Cycles' thin-lens camera (``dof``) with a round lens of radius
``R_L`` at z = 0 focused on the plane z = −d_f: a camera ray starts at a lens
point ``a`` and passes through the point ``F`` of the focus plane that the
pixel's pinhole ray hits. The sensor is ``SENSOR_WIDTH_MM`` wide (horizontal
fit, square pixels) at focal length ``f``, so the pinhole image of a point
``P = (X, Y, −d)`` is at ``f·(X, Y)/d`` mm from the sensor's centre, and the
image is not mirrored (camera x is image right, camera y image up).

*Aperture stop.* An opaque plate at z = −ε (``EPS``) with a hole ``H`` (a
rounded n-gon or a circle centred on the axis); the lens disc is larger than
the hole (``R_L`` > the hole's circumradius + ε·tan θ_max), so the hole is the
stop. A ray from lens point ``a`` through point light ``P`` crosses the plate
at ``u = a(1 − ε/d) + P ε/d``; it reaches the sensor at
``F f/d_f`` with ``F = a(1 − d_f/d) + P d_f/d``. Eliminating ``a``::

    sensor offset from the pinhole image = (u − P ε/d) (1 − d_f/d) / (1 − ε/d) · f/d_f

so the disc is the hole ``H`` scaled by ``k = (1 − d_f/d)/(1 − ε/d) · f/d_f``:
upright for a far light (d > d_f, k > 0), turned by 180° for a near one
(k < 0), as design.md §2 says. Its equal-area diameter on the sensor is
``|k|·2R0`` (``R0`` the radius of the circle with the hole's area) and its
centroid sits ``−P ε/(d − ε) (1 − d_f/d) f/d_f`` from the pinhole image (a
fraction of a pixel here). ``angle_deg``, ``roundness`` and ``blades`` of the
truth are those of ``H`` in this frame, which a far disc shows unchanged.

*Equal-area f-stop* (design.md §4): ``N = f / (2 R0)``.

*Rounded n-gon* (design.md §3b): vertices at circumradius ``R`` and angles
``angle + 360°·k/n`` (a vertex on +x at angle 0); each edge an arc of radius
``ρ = R/roundness`` through its two vertices, bulging outward. With
``s = roundness·sin(π/n)`` and ``α = asin(s)`` (the arc's half-angle), the area
is ``R²[(n/2) sin(2π/n) + n(α − sin α cos α)/roundness²]`` (polygon plus n
circular segments), which gives ``R`` for the chosen ``R0``.

*Cat-eye* (design.md §3b vignetting). A second opaque plate at z = −D with a
round hole of radius ``r2`` on the axis. The ray through ``u`` crosses it at
``a(1 − D/d) + P D/d``; substituting ``a`` from ``u``, the ray passes when
``|u − c| < r2 (d − ε)/(d − D)`` with ``c = −(P/d)·d(D − ε)/(d − D)``.
``P/d`` is the pinhole image over ``f``, i.e. ``q·h/f`` for field position ``q``
(units of the half-diagonal ``h``, y up), so in units of ``R0``::

    radius = r2 (d − ε) / ((d − D) R0)
    shift  = −(D − ε) d / (d − D) · h / (f R0)

The cat-eye renders hold far lights at one distance, so one pair describes
every disc; ``truth.json`` also gives the pair per light.

*Rim* (design.md §3b). The hole of the rim renders is a circle of radius
``R0`` filled with a transparent film whose transmission at radius ``r`` is
``T = (1 + rim (2 (r/R0)² − 1)) / (1 + |rim|)``, the §3b weight scaled to a
largest value of 1. A far disc therefore shows ``rim``. A film does not flip
across the focus plane (spherical aberration does, which §3b models), so the
rim renders hold far lights only.

*Lights* are emissive spheres of radius ``r_s``: their pinhole image is
``LIGHT_PINHOLE_PX`` wide, which blurs each disc's outline by that much. A
pixel inside a disc sees a light through the part of the lens of radius
``r_s d_f/|d − d_f|``, a fraction ``(r_s d_f/|d − d_f|)²/R_L²`` of the lens, so an
emission of ``level·R_L²(|d − d_f|/(r_s d_f))²`` gives the linear level
``level`` inside the disc. Levels above 1 clip in the 8-bit output
(``saturated`` in the truth).

*Bars* are black cylinders in the focus plane, ``BAR_WIDTH_PX`` wide in the
image: they block all light from behind them, a sharp dark line across discs.

The film is Blender's "Standard" view (the sRGB curve, no tone mapping), a
1-pixel box filter, no dithering, no denoising; adaptive sampling only stops
pixels whose noise is already below ``ADAPTIVE_THRESHOLD``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

WIDTH_PX, HEIGHT_PX = 480, 320
FOCAL_LENGTH_MM = 50.0
SENSOR_WIDTH_MM = 36.0
FOCUS_DISTANCE_M = 0.5
#: Radius of the circle with the hole's area: 2·R0 = 40 mm, f/1.25 equal-area.
HOLE_R0_M = 0.020
#: Distance of the hole plate in front of the lens.
EPS_M = 0.001
#: Far and near light distances.
FAR_M = 4.0
NEAR_M = 0.3
#: Width of a light's pinhole image (its sphere's blur of the disc outline).
LIGHT_PINHOLE_PX = 3.0
BAR_WIDTH_PX = 2.0
#: Second plate of the cat-eye renders.
CATEYE_PLATE_M = 0.06
CATEYE_HOLE_M = 0.024
WORLD_LEVEL = 0.0
SAMPLES = 8192
ADAPTIVE_THRESHOLD = 0.002
ADAPTIVE_MIN_SAMPLES = 1024
#: Points per hole edge (each edge's arc, or straight segment, is cut into this many).
#: 64 points per edge leave a straight chord at most 0.0005 px from a rounded edge's arc here.
POINTS_PER_EDGE = 64
CIRCLE_POINTS = 480
#: Growth of the plates' mesh rings (see ``_holed_plate``).
RING_FACTOR = 1.04


@dataclass
class Light:
    """A point-like light, placed by its pinhole image (x right, y up from the image centre, px)."""

    x_px: float
    y_px: float
    side: str  # "far" or "near"
    level: float  # linear level inside its disc; > 1 clips in 8 bits


@dataclass
class Render:
    name: str
    what: str
    shape: str  # "ngon" or "circle"
    blades: int | None
    roundness: float
    angle_deg: float
    lights: list
    bars: list = field(default_factory=list)  # (x_px, y_px, angle_deg): through that image point, CCW from +x
    cateye: bool = False
    rim: float = 0.0
    sixteen_bit: bool = False
    #: Samples per pixel when not SAMPLES (the film makes every sample dearer).
    samples: int | None = None


def _grid(nx, ny, margin_x, margin_y, side="far", level=0.6, jitter=0.0, seed=0):
    rng = np.random.default_rng(seed)
    half_w, half_h = WIDTH_PX / 2, HEIGHT_PX / 2
    xs = np.linspace(-half_w + margin_x, half_w - margin_x, nx)
    ys = np.linspace(-half_h + margin_y, half_h - margin_y, ny)
    lights = []
    for y in ys:
        for x in xs:
            dx, dy = rng.uniform(-jitter, jitter, 2)
            lights.append(Light(float(x + dx), float(y + dy), side, float(level * rng.uniform(0.7, 1.0))))
    return lights


def _mixed(pattern: str, seed: int, level=0.6):
    """A 4 × 3 grid, top row first; each letter says whether that light is far (F) or near (N)."""
    rng = np.random.default_rng(seed)
    lights = []
    for y, row in zip((95, 5, -90), pattern.split()):
        for x, letter in zip((-170, -60, 60, 170), row):
            lights.append(Light(float(x), float(y), "far" if letter == "F" else "near",
                                float(level * rng.uniform(0.7, 1.0))))
    return lights


def renders() -> list[Render]:
    """The set: shapes, rotations, roundness, near and far, saturated, overlapping, bars, cat-eye, rims."""
    out = []
    out.append(Render("ngon5_round0_angle0", "5 blades, straight, a vertex on +x; far and near lights",
                      "ngon", 5, 0.0, 0.0,
                      _mixed("FFFF FNFN NFNF", seed=1)))
    out.append(Render("ngon6_round03_angle15", "6 blades, roundness 0.3, turned 15°; one bar across a disc",
                      "ngon", 6, 0.3, 15.0, _grid(4, 3, 60, 50, seed=2, jitter=8), bars=[(-57, 0, -60.0)],
                      sixteen_bit=True))
    out.append(Render("ngon7_round06_angle40", "7 blades, roundness 0.6, turned 40°; far and near lights",
                      "ngon", 7, 0.6, 40.0,
                      _mixed("NFNF FFFF FNFN", seed=3)))
    out.append(Render("ngon8_round0_angle10", "8 blades, straight, turned 10°", "ngon", 8, 0.0, 10.0,
                      _grid(4, 3, 60, 50, seed=4, jitter=8)))
    out.append(Render("ngon9_round03_angle25", "9 blades, roundness 0.3, turned 25°", "ngon", 9, 0.3, 25.0,
                      _grid(4, 3, 60, 50, seed=5, jitter=8)))
    out.append(Render("ngon5_round1_angle0", "5 blades at roundness 1: the circle", "ngon", 5, 1.0, 0.0,
                      _grid(4, 3, 60, 50, seed=6, jitter=8)))
    out.append(Render("ngon6_round0_angle50_saturated", "6 blades, straight, turned 50°; clipped lights, "
                      "overlapping discs, bars", "ngon", 6, 0.0, 50.0,
                      [Light(-160, 85, "far", 4.0), Light(-130, 70, "far", 0.6), Light(-40, 80, "far", 6.0),
                       Light(60, 85, "far", 0.6), Light(160, 80, "far", 3.0), Light(-150, -60, "far", 0.6),
                       Light(-60, -70, "far", 8.0), Light(30, -60, "far", 0.5), Light(60, -75, "far", 0.5),
                       Light(160, -70, "far", 0.6)],
                      bars=[(60, 85, -100.0), (-60, -70, -20.0)], sixteen_bit=True))
    out.append(Render("cateye_ngon6_round03", "6 blades, roundness 0.3, turned 30°; a second plate: cat-eyes",
                      "ngon", 6, 0.3, 30.0, _grid(5, 3, 40, 40, seed=8), cateye=True))
    out.append(Render("cateye_circle", "circle; a second plate: cat-eyes", "circle", None, 1.0, 0.0,
                      _grid(5, 3, 40, 40, seed=9), cateye=True))
    out.append(Render("rim_bright_circle", "circle, bright rim (rim +0.6)", "circle", None, 1.0, 0.0,
                      _grid(4, 3, 60, 50, seed=10, jitter=8, level=0.5), rim=0.6, sixteen_bit=True,
                      samples=4096))
    out.append(Render("rim_dark_circle", "circle, bright centre (rim −0.6)", "circle", None, 1.0, 0.0,
                      _grid(4, 3, 60, 50, seed=11, jitter=8, level=0.5), rim=-0.6, samples=4096))
    # The second set: the ends of the blade range, and rounder blades.
    out.append(Render("ngon3_round0_angle20", "3 straight blades, turned 20°; far and near lights",
                      "ngon", 3, 0.0, 20.0, _mixed("FFNF FNFF NFFN", seed=12)))
    out.append(Render("ngon4_round05_angle10", "4 blades, roundness 0.5, turned 10°", "ngon", 4, 0.5, 10.0,
                      _grid(4, 3, 60, 50, seed=13, jitter=8)))
    out.append(Render("ngon10_round02_angle5", "10 blades, roundness 0.2, turned 5°", "ngon", 10, 0.2, 5.0,
                      _grid(4, 3, 60, 50, seed=14, jitter=8)))
    out.append(Render("ngon12_round0_angle7", "12 straight blades, turned 7°", "ngon", 12, 0.0, 7.0,
                      _grid(4, 3, 60, 50, seed=15, jitter=8)))
    out.append(Render("ngon6_round08_angle20", "6 blades, roundness 0.8, turned 20°: nearly round", "ngon", 6, 0.8, 20.0,
                      _grid(4, 3, 60, 50, seed=16, jitter=8)))
    return out


# --- exact geometry -----------------------------------------------------------------------------

def ngon_area_factor(n: int, roundness: float) -> float:
    """Area of the rounded n-gon of circumradius 1 (see the module docstring)."""
    polygon = 0.5 * n * math.sin(2 * math.pi / n)
    if roundness == 0:
        return polygon
    alpha = math.asin(roundness * math.sin(math.pi / n))
    return polygon + n * (alpha - math.sin(alpha) * math.cos(alpha)) / roundness**2


def circumradius(render: Render) -> float:
    if render.shape == "circle":
        return HOLE_R0_M
    return HOLE_R0_M * math.sqrt(math.pi / ngon_area_factor(render.blades, render.roundness))


def hole_outline(render: Render) -> np.ndarray:
    """The hole's outline, counter-clockwise, (K, 2) metres in the aperture frame."""
    if render.shape == "circle" or render.roundness == 1.0:
        phi = np.linspace(0, 2 * np.pi, CIRCLE_POINTS, endpoint=False) + math.radians(render.angle_deg)
        return circumradius(render) * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    n, k = render.blades, render.roundness
    big_r = circumradius(render)
    points = []
    for i in range(n):
        mid = math.radians(render.angle_deg) + (i + 0.5) * 2 * math.pi / n
        if k == 0:
            v0 = mid - math.pi / n
            v1 = mid + math.pi / n
            t = np.linspace(0, 1, POINTS_PER_EDGE, endpoint=False)[:, None]
            a = big_r * np.array([math.cos(v0), math.sin(v0)])
            b = big_r * np.array([math.cos(v1), math.sin(v1)])
            points.append(a + t * (b - a))
        else:
            rho = big_r / k
            alpha = math.asin(k * math.sin(math.pi / n))
            # The arc's centre lies on the edge's bisector, rho·cos(alpha) inside the chord.
            centre_dist = big_r * math.cos(math.pi / n) - rho * math.cos(alpha)
            beta = np.linspace(-alpha, alpha, POINTS_PER_EDGE, endpoint=False)
            centre = centre_dist * np.array([math.cos(mid), math.sin(mid)])
            points.append(centre + rho * np.stack([np.cos(mid + beta), np.sin(mid + beta)], axis=1))
    return np.concatenate(points)


def polygon_area_centroid(xy: np.ndarray) -> tuple[float, np.ndarray]:
    x, y = xy[:, 0], xy[:, 1]
    cross = x * np.roll(y, -1) - np.roll(x, -1) * y
    area = cross.sum() / 2
    cx = ((x + np.roll(x, -1)) * cross).sum() / (6 * area)
    cy = ((y + np.roll(y, -1)) * cross).sum() / (6 * area)
    return float(area), np.array([cx, cy])


def clip_convex(subject: np.ndarray, clip: np.ndarray) -> np.ndarray:
    """The part of polygon ``subject`` inside convex polygon ``clip`` (both counter-clockwise; Sutherland–Hodgman)."""
    out = subject
    for a, b in zip(clip, np.roll(clip, -1, axis=0)):
        if len(out) == 0:
            break
        edge = b - a
        side = edge[0] * (out[:, 1] - a[1]) - edge[1] * (out[:, 0] - a[0])  # > 0: inside (left of a→b)
        nxt = np.roll(out, -1, axis=0)
        side_next = np.roll(side, -1)
        points = []
        for p, q, sp, sq in zip(out, nxt, side, side_next):
            if sp >= 0:
                points.append(p)
            if (sp >= 0) != (sq >= 0):
                points.append(p + (q - p) * (sp / (sp - sq)))
        out = np.array(points)
    return out


def px_per_mm() -> float:
    return WIDTH_PX / SENSOR_WIDTH_MM


def half_diagonal_mm() -> float:
    return 0.5 * math.hypot(SENSOR_WIDTH_MM, SENSOR_WIDTH_MM * HEIGHT_PX / WIDTH_PX)


def light_distance(light: Light) -> float:
    return FAR_M if light.side == "far" else NEAR_M


def light_position(light: Light) -> np.ndarray:
    """World position of a light whose pinhole image is at (x_px, y_px) from the image centre."""
    d = light_distance(light)
    t = np.array([light.x_px, light.y_px]) / px_per_mm() / FOCAL_LENGTH_MM  # P/d
    return np.array([t[0] * d, t[1] * d, -d])


def light_truth(render: Render, light: Light, index: int) -> dict:
    d = light_distance(light)
    f_m = FOCAL_LENGTH_MM / 1000
    k = (1 - FOCUS_DISTANCE_M / d) / (1 - EPS_M / d) * f_m / FOCUS_DISTANCE_M  # sensor m per aperture m
    t = np.array([light.x_px, light.y_px]) / px_per_mm() / FOCAL_LENGTH_MM
    # Disc centroid: the hole's centroid u_c seen from P, i.e. (u_c − P ε/d)·k.
    _, u_c = polygon_area_centroid(hole_outline(render))
    offset_m = (u_c - t * EPS_M) * k
    centre_xy = np.array([light.x_px, light.y_px]) + offset_m * 1000 * px_per_mm()
    col = (WIDTH_PX - 1) / 2 + centre_xy[0]
    row = (HEIGHT_PX - 1) / 2 - centre_xy[1]
    entry = {
        "index": index,
        "side": light.side,
        "distance_m": d,
        "position_m": [round(float(v), 9) for v in light_position(light)],
        "pinhole_xy": [round((WIDTH_PX - 1) / 2 + light.x_px, 4), round((HEIGHT_PX - 1) / 2 - light.y_px, 4)],
        "center_xy": [round(float(col), 4), round(float(row), 4)],
        "diameter_px": round(abs(k) * 2 * HOLE_R0_M * 1000 * px_per_mm(), 4),
        "level": light.level,
        "saturated": light.level > 1.0,
    }
    if render.cateye:
        # The disc this light shows: the hole clipped by the second plate's circle (module docstring).
        vignetting = cateye_truth(d)
        phi = np.linspace(0, 2 * np.pi, CIRCLE_POINTS, endpoint=False)
        cut = (vignetting["radius"] * HOLE_R0_M * np.stack([np.cos(phi), np.sin(phi)], axis=1)
               + vignetting["shift"] * HOLE_R0_M * np.array([light.x_px, light.y_px]) / px_per_mm()
               / half_diagonal_mm())
        clipped = clip_convex(hole_outline(render), cut)
        area, centroid = polygon_area_centroid(clipped)
        offset_m = (centroid - t * EPS_M) * k
        seen = np.array([light.x_px, light.y_px]) + offset_m * 1000 * px_per_mm()
        entry["unclipped_center_xy"] = entry["center_xy"]
        entry["unclipped_diameter_px"] = entry["diameter_px"]
        entry["center_xy"] = [round((WIDTH_PX - 1) / 2 + float(seen[0]), 4),
                              round((HEIGHT_PX - 1) / 2 - float(seen[1]), 4)]
        entry["diameter_px"] = round(abs(k) * 2 * math.sqrt(area / math.pi) * 1000 * px_per_mm(), 4)
        entry["vignetting"] = vignetting
        entry["field_q"] = [round(float(v), 6) for v in np.array([light.x_px, light.y_px]) / px_per_mm()
                            / half_diagonal_mm()]
    return entry


def cateye_truth(d: float) -> dict:
    radius = CATEYE_HOLE_M * (d - EPS_M) / ((d - CATEYE_PLATE_M) * HOLE_R0_M)
    shift = -(CATEYE_PLATE_M - EPS_M) * d / (d - CATEYE_PLATE_M) * half_diagonal_mm() / (FOCAL_LENGTH_MM * HOLE_R0_M)
    return {"radius": round(radius, 6), "shift": round(shift, 6)}


def lens_radius(render: Render) -> float:
    """Cycles' lens radius: the hole's circumradius plus the hole's largest shift ε·tan θ, plus 3 %."""
    tan_max = half_diagonal_mm() / FOCAL_LENGTH_MM
    return 1.03 * circumradius(render) + EPS_M * tan_max * 1.2


def sphere_radius(d: float) -> float:
    return LIGHT_PINHOLE_PX / 2 / px_per_mm() / FOCAL_LENGTH_MM * d


def emission(render: Render, light: Light) -> float:
    d = light_distance(light)
    footprint = sphere_radius(d) * FOCUS_DISTANCE_M / abs(d - FOCUS_DISTANCE_M)
    return light.level * (lens_radius(render) / footprint) ** 2


def overlaps(render: Render, truths: list) -> list[bool]:
    """Whether each light's disc (its circumscribed circle) touches another's, a bar, or the frame."""
    scale = circumradius(render) / HOLE_R0_M
    out = []
    for i, a in enumerate(truths):
        ra = a["diameter_px"] / 2 * scale
        hit = False
        for j, b in enumerate(truths):
            if i != j and math.dist(a["center_xy"], b["center_xy"]) < ra + b["diameter_px"] / 2 * scale + 2:
                hit = True
        cx, cy = a["center_xy"]
        if cx - ra < 1 or cy - ra < 1 or cx + ra > WIDTH_PX - 2 or cy + ra > HEIGHT_PX - 2:
            hit = True
        for bx, by, angle in render.bars:
            px, py = (WIDTH_PX - 1) / 2 + bx, (HEIGHT_PX - 1) / 2 - by
            nx, ny = -math.sin(math.radians(angle)), -math.cos(math.radians(angle))  # image-frame normal
            if abs((cx - px) * nx + (cy - py) * ny) < ra + BAR_WIDTH_PX:
                hit = True
        out.append(hit)
    return out


# --- Blender ---------------------------------------------------------------------------------------

def build_scene(render: Render, samples: int, threads: int, seed: int):
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = samples
    cycles.use_adaptive_sampling = True
    cycles.adaptive_threshold = ADAPTIVE_THRESHOLD
    cycles.adaptive_min_samples = min(ADAPTIVE_MIN_SAMPLES, samples)
    cycles.use_denoising = False
    cycles.max_bounces = 0
    cycles.diffuse_bounces = 0
    cycles.glossy_bounces = 0
    cycles.transmission_bounces = 0
    cycles.transparent_max_bounces = 8
    cycles.pixel_filter_type = "BOX"
    cycles.filter_width = 1.0
    cycles.seed = seed
    cycles.sample_clamp_direct = 0.0
    cycles.sample_clamp_indirect = 0.0
    scene.render.resolution_x = WIDTH_PX
    scene.render.resolution_y = HEIGHT_PX
    scene.render.resolution_percentage = 100
    scene.render.dither_intensity = 0.0
    scene.render.film_transparent = False
    if threads:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = threads
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.display_settings.display_device = "sRGB"

    world = bpy.data.worlds.new("world")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (1, 1, 1, 1)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = WORLD_LEVEL
    scene.world = world

    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = FOCAL_LENGTH_MM
    cam_data.sensor_fit = "HORIZONTAL"
    cam_data.sensor_width = SENSOR_WIDTH_MM
    cam_data.clip_start = 1e-4
    cam_data.clip_end = 100.0
    cam_data.dof.use_dof = True
    cam_data.dof.focus_distance = FOCUS_DISTANCE_M
    # Cycles' lens radius is f / (2 N) (f in metres): choose N for the radius wanted.
    cam_data.dof.aperture_fstop = (FOCAL_LENGTH_MM / 1000) / (2 * lens_radius(render))
    cam_data.dof.aperture_blades = 0
    cam_data.dof.aperture_ratio = 1.0
    camera = bpy.data.objects.new("camera", cam_data)
    scene.collection.objects.link(camera)
    scene.camera = camera  # at the origin, looking along −z, y up

    black = _emission_material("black", 0.0)
    outline = hole_outline(render)
    plate_materials = [black]
    if render.rim:
        plate_materials.append(_rim_material(render.rim))
    _holed_plate("stop", outline, 0.1, -EPS_M, plate_materials, fill=bool(render.rim))
    if render.cateye:
        phi = np.linspace(0, 2 * np.pi, CIRCLE_POINTS, endpoint=False)
        circle = CATEYE_HOLE_M * np.stack([np.cos(phi), np.sin(phi)], axis=1)
        _holed_plate("cateye", circle, 0.3, -CATEYE_PLATE_M, [black])

    for i, light in enumerate(render.lights):
        _sphere(f"light{i}", light_position(light), sphere_radius(light_distance(light)),
                _emission_material(f"emit{i}", emission(render, light)))
    for i, (bx, by, angle) in enumerate(render.bars):
        _bar(f"bar{i}", bx, by, angle, black)
    return scene


def _emission_material(name: str, strength: float):
    import bpy

    material = bpy.data.materials.new(name)
    material.use_nodes = True
    nodes = material.node_tree.nodes
    nodes.clear()
    node = nodes.new("ShaderNodeEmission")
    node.inputs["Color"].default_value = (1, 1, 1, 1)
    node.inputs["Strength"].default_value = strength
    out = nodes.new("ShaderNodeOutputMaterial")
    material.node_tree.links.new(node.outputs["Emission"], out.inputs["Surface"])
    return material


def _rim_material(rim: float):
    """Transparent film: transmission (1 + rim (2 (r/R0)² − 1)) / (1 + |rim|), r from the object's axis."""
    import bpy

    material = bpy.data.materials.new("rim")
    material.use_nodes = True
    tree = material.node_tree
    nodes, links = tree.nodes, tree.links
    nodes.clear()
    coords = nodes.new("ShaderNodeTexCoord")
    length = nodes.new("ShaderNodeVectorMath")
    length.operation = "LENGTH"  # the plate lies in its local z = 0 plane
    links.new(coords.outputs["Object"], length.inputs[0])
    square = nodes.new("ShaderNodeMath")
    square.operation = "MULTIPLY"
    links.new(length.outputs["Value"], square.inputs[0])
    links.new(length.outputs["Value"], square.inputs[1])
    weight = nodes.new("ShaderNodeMath")
    weight.operation = "MULTIPLY_ADD"  # r² · (2 rim / R0²) + (1 − rim)
    links.new(square.outputs["Value"], weight.inputs[0])
    weight.inputs[1].default_value = 2 * rim / HOLE_R0_M**2
    weight.inputs[2].default_value = 1 - rim
    scale = nodes.new("ShaderNodeMath")
    scale.operation = "DIVIDE"
    links.new(weight.outputs["Value"], scale.inputs[0])
    scale.inputs[1].default_value = 1 + abs(rim)
    colour = nodes.new("ShaderNodeCombineColor")
    for channel in ("Red", "Green", "Blue"):
        links.new(scale.outputs["Value"], colour.inputs[channel])
    transparent = nodes.new("ShaderNodeBsdfTransparent")
    links.new(colour.outputs["Color"], transparent.inputs["Color"])
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(transparent.outputs["BSDF"], out.inputs["Surface"])
    return material


def _holed_plate(name, outline, outer_radius, z, materials, fill=False):
    """An opaque plate with the hole ``outline``; ``fill`` closes the hole with material 1.

    The plate is meshed as rings: the outline scaled by ``RING_FACTOR`` again and
    again out to ``outer_radius`` (the outline is star-shaped about the axis, so
    the rings nest), giving near-square quads; long slivers from the hole to the
    plate's edge would overlap in the ray-tracing hierarchy and slow every ray.
    The filled hole is meshed the same way inwards, closed by a small fan.
    """
    import bpy

    count = len(outline)
    reach = float(np.max(np.hypot(outline[:, 0], outline[:, 1])))
    out_factors = [1.0]
    while reach * out_factors[-1] < outer_radius:
        out_factors.append(out_factors[-1] * RING_FACTOR)
    in_factors = [1.0]
    if fill:
        while in_factors[-1] > 0.02:
            in_factors.append(in_factors[-1] / RING_FACTOR)
    verts, faces, indices = [], [], []

    def rings(factors, material):
        first = len(verts)
        for factor in factors:
            verts.extend((float(x), float(y), 0.0) for x, y in outline * factor)
        for ring in range(len(factors) - 1):
            a, b = first + ring * count, first + (ring + 1) * count
            faces.extend((a + i, a + (i + 1) % count, b + (i + 1) % count, b + i) for i in range(count))
            indices.extend([material] * count)
        return first + (len(factors) - 1) * count  # the last ring's first vertex

    rings(out_factors, 0)
    if fill:
        last = rings(in_factors, 1)
        verts.append((0.0, 0.0, 0.0))
        centre = len(verts) - 1
        faces.extend((centre, last + (i + 1) % count, last + i) for i in range(count))
        indices.extend([1] * count)
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    for material in materials:
        mesh.materials.append(material)
    mesh.polygons.foreach_set("material_index", indices)
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = (0.0, 0.0, z)
    bpy.context.scene.collection.objects.link(obj)


def _sphere(name, position, radius, material):
    import bmesh
    import bpy

    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=32, v_segments=16, radius=radius)
    bm.to_mesh(mesh)
    bm.free()
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    obj.location = tuple(float(v) for v in position)
    bpy.context.scene.collection.objects.link(obj)


def _bar(name, x_px, y_px, angle_deg, material):
    """A black cylinder in the focus plane through image point (x_px, y_px), at angle_deg from +x."""
    import bpy

    scale = FOCUS_DISTANCE_M / (FOCAL_LENGTH_MM * px_per_mm())  # metres in the focus plane per pixel
    radius = BAR_WIDTH_PX / 2 * scale
    bpy.ops.mesh.primitive_cylinder_add(vertices=24, radius=radius, depth=0.3,
                                        location=(x_px * scale, y_px * scale, -FOCUS_DISTANCE_M))
    obj = bpy.context.active_object
    obj.name = name
    # The cylinder's axis is z: turned about y into +x, then about z (the view axis) by angle_deg.
    obj.rotation_mode = "XYZ"
    obj.rotation_euler = (0.0, math.pi / 2, math.radians(angle_deg))
    obj.data.materials.append(material)


# --- truth ------------------------------------------------------------------------------------

def render_truth(render: Render) -> dict:
    lights = [light_truth(render, light, i) for i, light in enumerate(render.lights)]
    for entry, crowded in zip(lights, overlaps(render, lights)):
        entry["isolated"] = not crowded
    area, _ = polygon_area_centroid(hole_outline(render))
    angle = None
    if render.shape == "ngon" and render.roundness < 1:
        angle = render.angle_deg % (360 / render.blades)
    truth = {
        "what": render.what,
        "shape": "circle" if render.shape == "circle" or render.roundness == 1 else "ngon",
        "blades": render.blades if render.shape == "ngon" and render.roundness < 1 else None,
        "hole_blades": render.blades,
        "roundness": render.roundness if render.shape == "ngon" else 1.0,
        "angle_deg": angle,
        "vignetting": cateye_truth(FAR_M) if render.cateye else None,
        "rim": render.rim,
        "rim_sign": int(np.sign(render.rim)),
        "fstop": round(FOCAL_LENGTH_MM / (2 * HOLE_R0_M * 1000), 6),
        "focal_length_mm": FOCAL_LENGTH_MM,
        "focus_distance_m": FOCUS_DISTANCE_M,
        "sensor_width_mm": SENSOR_WIDTH_MM,
        "width": WIDTH_PX,
        "height": HEIGHT_PX,
        "geometry": {
            "hole_r0_m": HOLE_R0_M,
            "hole_circumradius_m": round(circumradius(render), 9),
            "hole_mesh_area_m2": area,
            "hole_plate_distance_m": EPS_M,
            "cycles_lens_radius_m": round(lens_radius(render), 9),
            "cateye_plate_distance_m": CATEYE_PLATE_M if render.cateye else None,
            "cateye_hole_radius_m": CATEYE_HOLE_M if render.cateye else None,
            "half_diagonal_mm": half_diagonal_mm(),
            "bars": [{"through_xy": [(WIDTH_PX - 1) / 2 + bx, (HEIGHT_PX - 1) / 2 - by],
                      "angle_deg": angle_b, "width_px": BAR_WIDTH_PX} for bx, by, angle_b in render.bars],
            "light_pinhole_px": LIGHT_PINHOLE_PX,
        },
        "lights": lights,
    }
    return truth


def _file_entry(path: Path, bits: int) -> dict:
    data = path.read_bytes()
    return {"file": path.name, "bits": bits, "size": len(data), "sha256": hashlib.sha256(data).hexdigest()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(Path(__file__).resolve().parents[2] / "tests" / "data" / "cycles"))
    parser.add_argument("--only", nargs="*", help="render only these (merged into truth.json)")
    parser.add_argument("--samples", type=int, help=f"samples per pixel (default: each render's, mostly {SAMPLES})")
    parser.add_argument("--threads", type=int, default=0, help="0: Blender's choice")
    parser.add_argument("--list", action="store_true", help="list the renders and stop")
    parser.add_argument("--truth-only", action="store_true", help="rewrite truth.json from the existing files")
    args = parser.parse_args(argv)

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    truth_path = out / "truth.json"
    chosen = [r for r in renders() if not args.only or r.name in args.only]
    if args.list:
        for r in renders():
            print(f"{r.name:36s} {r.what}")
        return 0
    if args.only and len(chosen) != len(args.only):
        print(f"--only: unknown render name among {args.only}", file=sys.stderr)
        return 2
    truth = json.loads(truth_path.read_text()) if truth_path.exists() else {}
    renders_truth = truth.get("renders", {})
    for index, render in enumerate(renders()):
        if render not in chosen:
            continue
        entry = render_truth(render)
        files = [out / f"{render.name}.png"] + ([out / f"{render.name}_16bit.png"] if render.sixteen_bit else [])
        if not args.truth_only:
            import bpy

            samples = args.samples or render.samples or SAMPLES
            scene = build_scene(render, samples, args.threads, seed=index + 1)
            start = time.perf_counter()
            bpy.ops.render.render(write_still=False)
            seconds = time.perf_counter() - start
            image = bpy.data.images["Render Result"]
            for path, depth in zip(files, ("8", "16")):
                settings = scene.render.image_settings
                settings.file_format = "PNG"
                settings.color_mode = "RGB"
                settings.color_depth = depth
                settings.compression = 100
                image.save_render(str(path), scene=scene)
            entry["render_seconds"] = round(seconds, 1)
            print(f"{render.name}: {seconds:.1f} s", flush=True)
            entry["samples"] = samples
        else:  # keep what the existing entry says about how the file was rendered
            old = renders_truth.get(render.name, {})
            entry["render_seconds"] = old.get("render_seconds")
            entry["samples"] = old.get("samples", render.samples or SAMPLES)
        entry["files"] = [_file_entry(path, 8 if i == 0 else 16) for i, path in enumerate(files)]
        renders_truth[render.name] = entry
    truth = {
        "about": "Ground truth of the Cycles renders; made by benchmarks/cycles/make_renders.py, whose "
                 "docstring derives every value. Frames and keys as docs/conventions.md §2, §3b, §4.",
        "blender": _blender_version(),
        "renders": {r.name: renders_truth[r.name] for r in renders() if r.name in renders_truth},
    }
    truth_path.write_text(json.dumps(truth, indent=1, ensure_ascii=False) + "\n")
    return 0


def _blender_version() -> str | None:
    try:
        import bpy
    except ImportError:
        return None
    return bpy.app.version_string


if __name__ == "__main__":
    sys.exit(main())
