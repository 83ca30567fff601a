"""The Cycles renders of ``tests/data/cycles`` made worse, as photos are: smaller, noisy, JPEG.

Usage::

    python benchmarks/cycles_degraded.py [--modes noise half quarter] [--json out.json]

Each render's first file is decoded to linear light (the sRGB formula) and degraded by a
mode, then written as a JPEG (quality 80) and run through ``bokehfit compare`` with the
render's geometry, as ``benchmarks/cycles_accuracy.py`` does:

- ``noise``: full size, a grey floor (1.5 % of white) and Gaussian sensor noise of σ 0.01;
- ``half``: the same after an area-average to half size (discs of 18–23 px);
- ``quarter``: to 0.28 of the size (discs of 10–13 px, where rounded blades are a tenth of
  a pixel from the circle).

Per mode: how many renders get their blade count right (a circle for a round hole), how many
get a *fitted* (sure) answer that is wrong, how many an unsure, no_fit or no_discs answer, and
the median angle error where the count is right. The script prints figures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import cycles_accuracy  # noqa: E402  (the benchmark beside this one)

MODES = {"noise": 1.0, "half": 0.5, "quarter": 0.28}
FLOOR = 0.015
NOISE_SIGMA = 0.01
JPEG_QUALITY = 80


def degrade(source: Path, scale: float, out: Path, rng: np.random.Generator) -> None:
    """``source`` (8-bit sRGB) area-averaged by ``scale`` in linear light, with the floor and the noise, as a JPEG."""
    encoded = cv2.imread(str(source), cv2.IMREAD_COLOR).astype(np.float32) / 255.0
    linear = np.where(encoded <= 0.04045, encoded / 12.92, ((encoded + 0.055) / 1.055) ** 2.4)
    if scale != 1.0:
        linear = cv2.resize(linear, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    linear = linear + FLOOR + rng.normal(0.0, NOISE_SIGMA, linear.shape).astype(np.float32)
    srgb = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * np.clip(linear, 0.0, None) ** (1 / 2.4) - 0.055)
    ok, data = cv2.imencode(".jpg", np.clip(srgb * 255.0 + 0.5, 0, 255).astype(np.uint8),
                            [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise OSError(f"could not encode {out}")
    out.write_bytes(data.tobytes())


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modes", nargs="*", default=list(MODES), choices=list(MODES))
    parser.add_argument("--json", help="write the rows as JSON")
    args = parser.parse_args(argv)
    truth = json.loads((cycles_accuracy.DATA / "truth.json").read_text(encoding="utf-8"))["renders"]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for mode in args.modes:
            rng = np.random.default_rng(0)
            for name, render in sorted(truth.items()):
                path = Path(tmp) / f"{mode}_{name}.jpg"
                degrade(cycles_accuracy.DATA / render["files"][0]["file"], MODES[mode], path, rng)
                result = cycles_accuracy.compare(path, render, Path(tmp) / f"{mode}_{name}.json")
                row = {"mode": mode, "render": name, **cycles_accuracy.score(render, result)}
                rows.append(row)
                print(f"{mode:8s} {name:32s} {row['status']:9s} fit {str(row['fit']):12s} "
                      f"blades {cycles_accuracy._fmt(row['blades_right']):5s} "
                      f"angle err {cycles_accuracy._fmt(row['angle_error_deg'])}°", flush=True)
    print()
    print("| mode | renders | blade count right | fitted and wrong | unsure, no_fit or no_discs | median angle error |")
    print("|---|---:|---:|---:|---:|---:|")
    for mode in args.modes:
        f = cycles_accuracy.summary([row for row in rows if row["mode"] == mode])
        print(f"| {mode} | {f['files']} | {f['blades_right']} | {f['sure_and_wrong']} | {f['not_sure']} | "
              f"{cycles_accuracy._fmt(f['angle_error_deg'])}° |")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
