"""Aperture fit accuracy on the independent Cycles renders of ``tests/data/cycles``.

Usage::

    python benchmarks/cycles_accuracy.py [--data tests/data/cycles] [--json out.json] [--only NAME ...]

Runs ``bokehfit compare`` (a subprocess per file, as a user would, with
``--json``) on every render that ``truth.json`` lists, 8- and 16-bit, giving it
what a camera's EXIF would: focal length, sensor width, focus distance, the
renderer's pinhole lens model and the far lights' distance; the side of focus
is left ``unknown``. Each render's truth comes from the scene's geometry
(``benchmarks/cycles/make_renders.py``), never from bokehfit.

The table gives per file: the status; the blade count right or wrong (a
circle is right when the fit says circle); the angle error modulo the true
symmetry (null when the blade count is wrong or the truth is a circle); the
roundness error (null until the fit reports a roundness; a fitted circle
counts as roundness 1); the fitted vignetting and rim beside their truth where
the render has them. Then the issue's targets: blade count right on ≥ 95 % of
the files, median angle error ≤ 1°, median roundness error ≤ 0.1. The script
prints figures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bokehfit.apertures import Aperture, make_aperture
from bokehfit.fit.signature import misalignment_deg

DATA = Path(__file__).resolve().parents[1] / "tests" / "data" / "cycles"
TARGET_BLADES = 0.95
TARGET_ANGLE_DEG = 1.0
TARGET_ROUNDNESS = 0.1


def compare(path: Path, render: dict, out: Path) -> dict:
    far = [light["distance_m"] for light in render["lights"] if light["side"] == "far"]
    command = [
        sys.executable, "-m", "bokehfit", "compare", str(path), "--json", str(out), "--no-html",
        "--focal-length-mm", str(render["focal_length_mm"]),
        "--sensor-width-mm", str(render["sensor_width_mm"]),
        "--focus-distance-m", str(render["focus_distance_m"]),
        "--lens-model", "pinhole",
    ]
    if far:
        command += ["--light-distance-m", str(far[0])]
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if not out.exists():
        return {"status": f"error (exit {done.returncode})", "message": done.stderr.strip()[-300:], "seconds": seconds}
    result = json.loads(out.read_text())
    result["seconds"] = seconds
    return result


def score(render: dict, result: dict) -> dict:
    """One render's row: the status, the fitted shape, and its errors against the truth, judged
    through the aperture model (a round hole: the circle; blades: their count, the rotation
    between the outlines whatever the shape's angle convention, the roundness, a circle being 1)."""
    row = {"status": result.get("status"), "fit": None, "blades_right": None, "angle_error_deg": None,
           "roundness_error": None, "vignetting": None, "rim": None, "seconds": round(result["seconds"], 1)}
    if "message" in result:
        row["status"] = f"{row['status']}: {result['message'].splitlines()[-1] if result['message'] else ''}"
    data = result.get("aperture") or {}
    if data.get("shape") is None:
        return row
    fitted = Aperture.from_json(data)
    row["fit"] = fitted.label
    if render["blades"] is None:  # a round hole
        row["blades_right"] = fitted.is_circle
    else:
        row["blades_right"] = fitted.blades == render["blades"]
        if row["blades_right"]:
            truth = make_aperture("ngon", render["angle_deg"], blades=render["blades"], roundness=render["roundness"])
            row["angle_error_deg"] = misalignment_deg(fitted, truth)
    row["roundness_error"] = abs((1.0 if fitted.is_circle else fitted.roundness) - render["roundness"])
    if render["vignetting"] is not None:
        row["vignetting"] = {"fitted": data.get("vignetting"), "true": render["vignetting"]}
    if render["rim"]:
        row["rim"] = {"fitted": data.get("rim"), "true": render["rim"]}
    return row


def _fmt(value, digits=2) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "right" if value else "WRONG"
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    if isinstance(value, dict):
        fitted = value["fitted"]
        if isinstance(fitted, dict):
            fitted = "{" + ", ".join(f"{k} {_fmt(v)}" for k, v in fitted.items()) + "}"
        true = value["true"]
        if isinstance(true, dict):
            true = "{" + ", ".join(f"{k} {_fmt(v)}" for k, v in true.items()) + "}"
        return f"{_fmt(fitted) if not isinstance(fitted, str) else fitted} (true {true})"
    return str(value)


def summary(rows: list[dict]) -> dict:
    """The figures of a set of scored rows: how many, blade counts right, sure answers that are
    wrong, unsure or failed answers, and the median angle and roundness errors (None where none)."""
    def median(values):
        values = [v for v in values if v is not None]
        return statistics.median(values) if values else None

    return {
        "files": len(rows),
        "fitted_a_shape": sum(row["blades_right"] is not None for row in rows),
        "blades_right": sum(bool(row["blades_right"]) for row in rows),
        "sure_and_wrong": sum(row["status"] == "fitted" and row["blades_right"] is False for row in rows),
        "not_sure": sum(row["status"] != "fitted" for row in rows),
        "angle_error_deg": median(row["angle_error_deg"] for row in rows),
        "roundness_error": median(row["roundness_error"] for row in rows),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(DATA))
    parser.add_argument("--json", help="write the rows as JSON")
    parser.add_argument("--only", nargs="*", help="only these renders")
    args = parser.parse_args(argv)
    data = Path(args.data)
    truth = json.loads((data / "truth.json").read_text(encoding="utf-8"))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, render in truth["renders"].items():
            if args.only and name not in args.only:
                continue
            for entry in render["files"]:
                result = compare(data / entry["file"], render, Path(tmp) / f"{Path(entry['file']).stem}.json")
                row = {"file": entry["file"], "truth": f"{render['shape']}"
                       + (f"({render['blades']}) r{render['roundness']:g} {render['angle_deg']:g}°"
                          if render["blades"] is not None else ""), **score(render, result)}
                rows.append(row)
                print(f"{row['file']:44s} {row['truth']:22s} {_fmt(row['status']):9s} fit {_fmt(row['fit']):12s} "
                      f"blades {_fmt(row['blades_right']):5s} angle err {_fmt(row['angle_error_deg'])}° "
                      f"roundness err {_fmt(row['roundness_error'])}"
                      + (f" vignetting {_fmt(row['vignetting'])}" if row["vignetting"] else "")
                      + (f" rim {_fmt(row['rim'])}" if row["rim"] else "")
                      + f"  [{row['seconds']} s]", flush=True)
    figures = summary(rows)
    share = figures["blades_right"] / figures["files"] if rows else math.nan
    print()
    print(f"files {figures['files']}, fitted a shape {figures['fitted_a_shape']}")
    print(f"blade count right: {share:.0%} of files (target ≥ {TARGET_BLADES:.0%})")
    print(f"median angle error: {_fmt(figures['angle_error_deg'])}° (target ≤ {TARGET_ANGLE_DEG:g}°)")
    print(f"median roundness error: {_fmt(figures['roundness_error'])} (target ≤ {TARGET_ROUNDNESS:g})")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
