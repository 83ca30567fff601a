"""Speed of ``bokehfit compare`` on a 24-MP photo, and fit accuracy against the disc budget.

Usage::

    python benchmarks/compare_speed.py [--quick] [--json out.json]

1. 24-megapixel timing (skipped by ``--quick``). A 6000×4000 synthetic JPEG
   (quality 90) with ``BIG_DISCS`` pentagon discs at 20° of log-uniform
   equal-area diameters 15–150 px, brightness 0.3–0.9, on a 0.01 → 0.05
   gradient with noise σ = 0.003, none overlapping, is written once to a
   temporary folder. A fresh Python process (nothing imported yet) then calls
   :func:`bokehfit.compare.compare_photo` twice on it with the photo's geometry
   (50 mm, 36 mm sensor, focus 2 m): the first call is *cold* (it pays for
   lazy imports, the GPU adapter and device, shader compilation, the first
   kernel pipeline), the second *warm*. The table gives
   ``Comparison.timing_s`` (load, detect, fit, render, metrics, total) for
   each, the import of ``bokehfit.compare`` and the child's whole wall time.
2. Fit accuracy against the disc budget. A fixed synthetic set: one photo
   per shape of ``SHAPES`` and per replicate (``REPLICATES``; ``--quick``:
   ``QUICK_SHAPES`` × 1), each with ``DISCS_PER_PHOTO`` discs of one size
   (lights at one distance, as the f-stop assumes; the size log-uniform in
   ``FIT_DIAMETERS``) and one random angle, brightness 0.15–0.9 (so the
   discs' SNR differs), noise σ = ``FIT_NOISE``, through a
   quality-``FIT_QUALITY`` JPEG and ``load_photo`` (fixed seeds). Discs are
   found once per photo; then for each value of ``bokehfit.fit.MAX_FIT_DISCS``
   in ``BUDGETS`` (the module constant is replaced for the call)
   :func:`bokehfit.fit.fit_aperture` runs over all families. Per budget: shape
   accuracy; the median and largest error of the aperture angle (modulo
   symmetry; photos whose family is right, circles left out); the median and
   largest |fitted − true| / true of the aperture's diameter
   (``ApertureFit.diameter_px``, the median over the fitted discs, which the
   f-stop is computed from); the mean and largest fit time per photo.

The script prints tables and asserts nothing; ``--json`` also writes the figures.
Timings are single runs on one machine.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

BIG_SIZE = (6000, 4000)
BIG_DISCS = 50
BIG_DIAMETERS = (15.0, 150.0)
BIG_SHAPE, BIG_ANGLE = "pentagon", 20.0
BIG_QUALITY = 90
BIG_GEOMETRY = dict(focal_length_mm=50.0, sensor_width_mm=36.0, focus_distance_m=2.0)
STAGES = ("load", "detect", "fit", "render", "metrics", "total")

SHAPES = (("circle", None), ("square", None), ("slit", None), ("triangle", None), ("pentagon", None),
          ("hexagon", None), ("star", None), ("ngon", 9))
QUICK_SHAPES = (("circle", None), ("hexagon", None), ("star", None), ("ngon", 9))
REPLICATES = 2
BUDGETS = (2, 4, 8, 12)
DISCS_PER_PHOTO = 14
FIT_DIAMETERS = (10.0, 40.0)
FIT_BRIGHTNESS = (0.15, 0.9)
FIT_NOISE = 0.012
FIT_QUALITY = 70
SLIT_ASPECT = 0.3
#: A disc's square cell is this many times its reach (largest outline radius), plus CELL_MARGIN_PX.
CELL_FACTOR = 2.8
CELL_MARGIN_PX = 12


def family_name(shape: str, blades: int | None) -> str:
    return f"ngon({blades})" if shape == "ngon" else shape


def grid_layout(shape, blades, aspect, angle, diameters, rng, brightness=(0.3, 0.9)):
    """Discs in a square grid of equal cells sized for the largest; returns (truth, width, height)."""
    from bokehfit.apertures import make_aperture
    from bokehfit.synthetic import SyntheticDisc

    aperture = make_aperture(shape, angle, blades=blades, aspect=aspect)
    cell = math.ceil(CELL_FACTOR * aperture.extent() * max(diameters) * math.sqrt(math.pi) / 2) + CELL_MARGIN_PX
    columns = math.ceil(math.sqrt(len(diameters)))
    rows = math.ceil(len(diameters) / columns)
    truth = []
    for i, diameter in enumerate(diameters):
        row, column = divmod(i, columns)
        centre = ((column + 0.5) * cell + rng.uniform(-2, 2), (row + 0.5) * cell + rng.uniform(-2, 2))
        truth.append(SyntheticDisc(centre, float(diameter), shape, angle, blades, aspect,
                                   brightness=float(rng.uniform(*brightness))))
    return truth, columns * cell, rows * cell


def write_jpeg(path: Path, linear: np.ndarray, quality: int) -> None:
    import cv2

    from bokehfit.synthetic import encode_srgb8

    ok, data = cv2.imencode(".jpg", encode_srgb8(linear), [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise RuntimeError("cv2.imencode failed")
    path.write_bytes(data.tobytes())


# --------------------------------------------------------------------------------------
# 1. The 24-MP photo, cold and warm
# --------------------------------------------------------------------------------------


def make_big_photo(path: Path) -> dict:
    from bokehfit.apertures import make_aperture
    from bokehfit.synthetic import SyntheticDisc, render_discs

    width, height = BIG_SIZE
    rng = np.random.default_rng(24)
    reach = make_aperture(BIG_SHAPE, BIG_ANGLE).extent() * math.sqrt(math.pi) / 2  # per px of diameter
    discs: list = []
    while len(discs) < BIG_DISCS:
        diameter = float(math.exp(rng.uniform(*np.log(BIG_DIAMETERS))))
        r = reach * diameter
        centre = (float(rng.uniform(r + 10, width - r - 10)), float(rng.uniform(r + 10, height - r - 10)))
        if all(math.dist(centre, d.center_xy) > 1.5 * (r + reach * d.diameter_px) + 10 for d in discs):
            discs.append(SyntheticDisc(centre, diameter, BIG_SHAPE, BIG_ANGLE, brightness=float(rng.uniform(0.3, 0.9))))
    background = np.linspace(0.01, 0.05, width, dtype=np.float32)[None, :].repeat(height, axis=0)
    start = time.perf_counter()
    linear = render_discs(width, height, discs, background=background, noise_sigma=0.003, seed=25)
    write_jpeg(path, linear, BIG_QUALITY)
    return {"discs": len(discs), "bytes": path.stat().st_size, "make_s": time.perf_counter() - start}


def child(path: str) -> None:
    """Runs in a fresh process: two compare_photo calls, timings as one JSON line on stdout."""
    start = time.perf_counter()
    from bokehfit.compare import compare_photo

    imported = time.perf_counter() - start
    calls = []
    for _ in range(2):
        begin = time.perf_counter()
        comparison = compare_photo(path, **BIG_GEOMETRY)
        fit = comparison.fit
        calls.append({
            "timing_s": dict(comparison.timing_s),
            "wall_s": time.perf_counter() - begin,
            "discs": len(comparison.search.discs),
            "usable": sum(d.usable for d in comparison.search.discs),
            "fitted": len(fit.disc_fits),
            "aperture": fit.aperture.describe() if fit else None,
            "fstop": comparison.fstop.value,
            "device": comparison.device.get("adapter"),
        })
    print(json.dumps({"import_s": imported, "calls": calls, "process_s": time.perf_counter() - start}))


def big_photo_timing() -> dict:
    with tempfile.TemporaryDirectory(prefix="bokehfit_compare_bench_") as tmp:
        path = Path(tmp) / "24mp.jpg"
        made = make_big_photo(path)
        print(f"24-MP photo: {BIG_SIZE[0]}×{BIG_SIZE[1]}, {made['discs']} {BIG_SHAPE} discs at {BIG_ANGLE:g}°, "
              f"{BIG_DIAMETERS[0]:g}–{BIG_DIAMETERS[1]:g} px, JPEG q{BIG_QUALITY} {made['bytes'] / 1e6:.1f} MB "
              f"(made in {made['make_s']:.1f} s)")
        start = time.perf_counter()
        done = subprocess.run([sys.executable, __file__, "--child", str(path)], capture_output=True, text=True,
                              timeout=1800)
        process_wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"the timing process failed:\n{done.stderr}")
    result = json.loads(done.stdout.strip().splitlines()[-1])
    result["process_wall_s"] = process_wall
    result["photo"] = made
    cold, warm = result["calls"]
    print(f"found {cold['discs']} discs ({cold['usable']} clean), fitted {cold['fitted']}: {cold['aperture']}; "
          f"kernel on {cold['device']}")
    print()
    print("| call | " + " | ".join(STAGES) + " | call wall |")
    print("|---|" + "---:|" * (len(STAGES) + 1))
    for name, call in (("cold (1st in process)", cold), ("warm (2nd)", warm)):
        print(f"| {name} | " + " | ".join(f"{call['timing_s'].get(s, math.nan):.2f}" for s in STAGES)
              + f" | {call['wall_s']:.2f} |")
    print()
    print(f"import bokehfit.compare: {result['import_s']:.2f} s; child process, start to exit: "
          f"{process_wall:.2f} s (interpreter start, imports, two calls)")
    return result


# --------------------------------------------------------------------------------------
# 2. Fit accuracy against the disc budget
# --------------------------------------------------------------------------------------


def fit_set(shapes, replicates, folder: Path) -> list[dict]:
    """The fixed synthetic photos, each loaded from its JPEG and searched once."""
    from bokehfit.discs import find_discs
    from bokehfit.io import load_photo
    from bokehfit.synthetic import render_discs

    photos = []
    for replicate in range(replicates):
        for index, (shape, blades) in enumerate(shapes):
            rng = np.random.default_rng(1000 * replicate + index)
            aspect = SLIT_ASPECT if shape == "slit" else None
            angle = float(rng.uniform(0.0, 360.0))
            diameter = float(np.exp(rng.uniform(*np.log(FIT_DIAMETERS))))
            truth, width, height = grid_layout(shape, blades, aspect, angle, [diameter] * DISCS_PER_PHOTO, rng,
                                               FIT_BRIGHTNESS)
            background = np.linspace(0.01, 0.05, width, dtype=np.float32)[None, :].repeat(height, axis=0)
            linear = render_discs(width, height, truth, background=background, noise_sigma=FIT_NOISE,
                                  seed=5000 + 100 * replicate + index)
            path = folder / f"{family_name(shape, blades)}_{replicate}.jpg"
            write_jpeg(path, linear, FIT_QUALITY)
            photo = load_photo(path)
            search = find_discs(photo.luminance, photo.clipped)
            photos.append(dict(name=family_name(shape, blades), shape=shape, angle=angle, diameter=diameter,
                               luminance=photo.luminance, discs=search.discs,
                               usable=sum(d.usable for d in search.discs), size=(width, height)))
    return photos


def score(fit, photo) -> dict:
    from bokehfit.metrics import angle_error

    if not fit:
        return dict(correct=False, angle_error=None, diameter_error=None)
    correct = fit.family.name == photo["name"]
    angle = None
    if correct and fit.aperture.symmetry_deg is not None:
        angle = angle_error(fit.aperture.angle_deg, photo["angle"], fit.aperture.symmetry_deg)
    return dict(correct=correct, angle_error=angle, diameter_error=abs(fit.diameter_px - photo["diameter"]) / photo["diameter"])


def budget_sweep(quick: bool) -> dict:
    import bokehfit.fit as fitting

    shapes, replicates = (QUICK_SHAPES, 1) if quick else (SHAPES, REPLICATES)
    with tempfile.TemporaryDirectory(prefix="bokehfit_fit_bench_") as tmp:
        photos = fit_set(shapes, replicates, Path(tmp))
    usable = [p["usable"] for p in photos]
    print(f"{len(photos)} photos ({', '.join(family_name(*s) for s in shapes)} × {replicates}), "
          f"{DISCS_PER_PHOTO} discs each of one size in {FIT_DIAMETERS[0]:g}–{FIT_DIAMETERS[1]:g} px, noise σ {FIT_NOISE}, "
          f"JPEG q{FIT_QUALITY}; clean discs found per photo: {min(usable)}–{max(usable)}")
    original = fitting.MAX_FIT_DISCS
    rows = []
    misses = {}
    try:
        for budget in BUDGETS:
            fitting.MAX_FIT_DISCS = budget
            results, times = [], []
            for photo in photos:
                start = time.perf_counter()
                fit = fitting.fit_aperture(photo["luminance"], photo["discs"])
                times.append(time.perf_counter() - start)
                result = score(fit, photo)
                results.append(result)
                if not result["correct"]:
                    misses.setdefault(budget, []).append(f"{photo['name']}→{fit.family.name if fit else 'none'}")
            angles = [r["angle_error"] for r in results if r["angle_error"] is not None]
            diameters = [r["diameter_error"] for r in results if r["diameter_error"] is not None]
            rows.append(dict(
                max_fit_discs=budget,
                correct=sum(r["correct"] for r in results),
                photos=len(results),
                median_angle_error_deg=float(np.median(angles)) if angles else math.nan,
                max_angle_error_deg=float(np.max(angles)) if angles else math.nan,
                median_diameter_error=float(np.median(diameters)) if diameters else math.nan,
                max_diameter_error=float(np.max(diameters)) if diameters else math.nan,
                mean_fit_s=float(np.mean(times)),
                max_fit_s=float(np.max(times)),
            ))
    finally:
        fitting.MAX_FIT_DISCS = original
    print()
    print("| MAX_FIT_DISCS | shape right | angle error (°) median | max | "
          "diameter error median | max | fit time / photo (s) mean | max |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for row in rows:
        print(f"| {row['max_fit_discs']} | {row['correct']}/{row['photos']} | {row['median_angle_error_deg']:.3f} | "
              f"{row['max_angle_error_deg']:.3f} | {100 * row['median_diameter_error']:.2f} % | "
              f"{100 * row['max_diameter_error']:.2f} % | "
              f"{row['mean_fit_s']:.2f} | {row['max_fit_s']:.2f} |")
    for budget, names in misses.items():
        print(f"wrong shape at MAX_FIT_DISCS={budget}: {', '.join(names)}")
    return dict(rows=rows, misses=misses, photos=len(photos))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="skip the 24-MP timing; fewer photos in the sweep")
    parser.add_argument("--json", metavar="OUT.json", help="also write the figures as JSON")
    parser.add_argument("--child", metavar="PHOTO", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.child)
        return
    import bokehfit

    print(f"bokehfit {bokehfit.__version__}, Python {platform.python_version()}, {platform.machine()}, "
          f"{os.cpu_count()} CPUs")
    report: dict = {"bokehfit_version": bokehfit.__version__, "quick": args.quick}
    if not args.quick:
        print("\n## compare on a 24-MP JPEG\n")
        report["big_photo"] = big_photo_timing()
    print("\n## Fit accuracy against the disc budget (bokehfit.fit.MAX_FIT_DISCS)\n")
    report["budget"] = budget_sweep(args.quick)
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=1, default=float) + "\n")
        print(f"\nwrote {args.json}")


if __name__ == "__main__":
    main()
