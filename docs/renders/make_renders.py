"""Remake the real-lens aperture renders of docs/render.md (design.md §3b), with the package's own renderer.

Run from anywhere with bokehfit installed::

    python docs/renders/make_renders.py [--out DIR] [--spp N]

It writes, beside this file by default (8-bit sRGB PNGs, 384 px wide):

``points_ngon9_straight.png``, ``points_ngon9_rounded.png``
    The "strong bokeh" look: a scatter of coloured point lights far behind a
    close focus, through a 9-blade lens with straight blades and with rounded
    ones (roundness 0.6).
``points_cat_eye.png``
    A grid of point lights at infinity filling the frame, through a circular
    aperture at f/2 with cat-eye vignetting (barrel radius 1.15, shift 1.5): the discs
    are cut into cat's eyes towards the corners.
``points_soap_bubble.png``, ``points_chromatic.png``
    Lights behind the focus plane (top row) and in front of it (bottom row):
    soap-bubble discs (rim 0.6; the near ones show −0.6, a bright centre), and
    longitudinal colour (red 0.04, blue −0.04: far discs with a red rim, near
    ones with a blue one).

Each render is a points scene (every disc the aperture's exact coverage
kernel, splatted) and takes a few seconds on a CPU adapter.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from bokehfit.apertures import make_aperture
from bokehfit.scene import PointLight, PointScene, make_lens, make_settings, render, write_render

#: Width and height of every render (pixels).
SIZE = (384, 256)
#: Aperture samples per pixel of each disc.
DEFAULT_SPP = 64
#: The lens of every render: 35 mm at f/1.4 focused at 0.15 m (a light at infinity: a 56 px disc).
LENS = dict(fstop=1.4, focus_distance_m=0.15)
#: Warm and cool tints of the scattered lights (linear RGB plateaus).
TINTS = ((1.0, 0.62, 0.25), (1.0, 0.82, 0.45), (0.55, 0.7, 1.0), (1.0, 0.45, 0.35), (0.85, 0.9, 1.0))


def strong_bokeh_scene(seed: int = 7, count: int = 40) -> PointScene:
    """Coloured lights scattered over the frame at 0.2 m to infinity, dim enough that overlaps add up."""
    rng = np.random.default_rng(seed)
    lights = []
    for _ in range(count):
        x, y = rng.uniform(0.05, 0.95), rng.uniform(0.08, 0.92)
        inverse_depth = rng.uniform(0.0, 5.0)  # 1/d uniform: 0.2 m to infinity, discs of 14 to 56 px
        depth = math.inf if inverse_depth == 0.0 else 1.0 / inverse_depth
        tint = np.asarray(TINTS[rng.integers(len(TINTS))]) * rng.uniform(0.3, 0.6)
        lights.append(PointLight(x, y, depth, tuple(float(c) for c in tint)))
    return PointScene("strong bokeh", tuple(lights))


def grid_scene(columns: int = 7, rows: int = 5, depth_m: float = math.inf) -> PointScene:
    """A regular grid of white lights at ``depth_m`` reaching into the frame's corners."""
    lights = tuple(
        PointLight((i + 0.5) / columns, (j + 0.5) / rows, depth_m, (0.8, 0.8, 0.8)) for j in range(rows) for i in range(columns)
    )
    return PointScene("grid", lights)


def near_and_far_scene(columns: int = 4, level: float = 0.9) -> PointScene:
    """A row of lights at infinity (top) and one at half the focus distance (bottom): the same blur, either side."""
    near = LENS["focus_distance_m"] / 2.0
    grey = (level, level, level)
    lights = [PointLight((i + 0.5) / columns, 0.27, math.inf, grey) for i in range(columns)]
    lights += [PointLight((i + 0.5) / columns, 0.73, near, grey) for i in range(columns)]
    return PointScene("near and far", tuple(lights))


def renders() -> dict[str, tuple[PointScene, dict]]:
    """File name → (scene, aperture and lens keywords of :func:`bokehfit.scene.render` beyond :data:`LENS`)."""
    nine = dict(shape="ngon", blades=9, angle_deg=90.0)
    return {
        "points_ngon9_straight.png": (strong_bokeh_scene(), nine),
        "points_ngon9_rounded.png": (strong_bokeh_scene(), dict(nine, roundness=0.6)),
        "points_cat_eye.png": (grid_scene(), dict(shape="circle", vignetting=dict(radius=1.15, shift=1.5), fstop=2.0)),
        # The rim profile reaches 1.6 times the plateau: a dimmer light keeps it below white.
        "points_soap_bubble.png": (near_and_far_scene(level=0.55), dict(shape="circle", rim=0.6)),
        "points_chromatic.png": (near_and_far_scene(), dict(shape="circle", chromatic=dict(red=0.04, blue=-0.04))),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent, help="folder of the PNGs (default: beside this script)")
    parser.add_argument("--spp", type=int, default=DEFAULT_SPP, help=f"aperture samples per disc pixel (default {DEFAULT_SPP})")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    width, height = SIZE
    for name, (scene, aperture) in renders().items():
        params = {**LENS, **aperture}
        fstop, focus = params.pop("fstop"), params.pop("focus_distance_m")
        angle = params.pop("angle_deg", 0.0)
        lens = make_lens(make_aperture(params.pop("shape"), angle, **params), fstop=fstop, focus_distance_m=focus)
        result = render(scene, lens, make_settings(width, height, args.spp))
        write_render(args.out / name, result.image)
        print(f"{name}: {result.lens.describe()}, {result.time_s:.2f} s on {result.adapter}")


if __name__ == "__main__":
    main()
