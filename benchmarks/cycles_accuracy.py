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
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bokehfit.apertures import Aperture, make_aperture

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
    aperture = result.get("aperture") or {}
    shape, blades = aperture.get("shape"), aperture.get("blades")
    row = {"status": result.get("status"), "fit": None, "blades_right": None, "angle_error_deg": None,
           "roundness_error": None, "vignetting": None, "rim": None, "seconds": round(result["seconds"], 1)}
    if "message" in result:
        row["status"] = f"{row['status']}: {result['message'].splitlines()[-1] if result['message'] else ''}"
    if shape is None:
        return row
    row["fit"] = f"ngon({blades})" if shape == "ngon" else shape
    if render["shape"] == "circle":
        row["blades_right"] = shape == "circle"
    else:
        row["blades_right"] = blades == render["blades"]
        if row["blades_right"]:
            # The rotation between the outlines, whatever each shape's angle convention (a square's).
            truth = make_aperture("ngon", render["angle_deg"], blades=render["blades"], roundness=render["roundness"])
            row["angle_error_deg"] = Aperture.from_json(aperture).misalignment_deg(truth)
    roundness = 1.0 if shape == "circle" else aperture.get("roundness")
    if roundness is not None:
        row["roundness_error"] = abs(roundness - render["roundness"])
    if render["vignetting"] is not None:
        row["vignetting"] = {"fitted": aperture.get("vignetting"), "true": render["vignetting"]}
    if render["rim"]:
        row["rim"] = {"fitted": aperture.get("rim"), "true": render["rim"]}
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


def _median(values: list[float]) -> float | None:
    values = sorted(values)
    if not values:
        return None
    middle = len(values) // 2
    return values[middle] if len(values) % 2 else 0.5 * (values[middle - 1] + values[middle])


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
                          if render["shape"] == "ngon" else ""), **score(render, result)}
                rows.append(row)
                print(f"{row['file']:44s} {row['truth']:22s} {_fmt(row['status']):9s} fit {_fmt(row['fit']):12s} "
                      f"blades {_fmt(row['blades_right']):5s} angle err {_fmt(row['angle_error_deg'])}° "
                      f"roundness err {_fmt(row['roundness_error'])}"
                      + (f" vignetting {_fmt(row['vignetting'])}" if row["vignetting"] else "")
                      + (f" rim {_fmt(row['rim'])}" if row["rim"] else "")
                      + f"  [{row['seconds']} s]", flush=True)
    judged = [row for row in rows if row["blades_right"] is not None]
    share = sum(bool(row["blades_right"]) for row in rows) / len(rows) if rows else math.nan
    angle = _median([row["angle_error_deg"] for row in rows if row["angle_error_deg"] is not None])
    roundness = _median([row["roundness_error"] for row in rows if row["roundness_error"] is not None])
    print()
    print(f"files {len(rows)}, fitted a shape {len(judged)}")
    print(f"blade count right: {share:.0%} of files (target ≥ {TARGET_BLADES:.0%})")
    print(f"median angle error: {_fmt(angle)}° (target ≤ {TARGET_ANGLE_DEG:g}°)")
    print(f"median roundness error: {_fmt(roundness)} (target ≤ {TARGET_ROUNDNESS:g})")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
