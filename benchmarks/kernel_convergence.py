"""Kernel error against time for one kernel: a thin wrapper over :mod:`bokehfit.bench.kernels`.

Usage::

    python benchmarks/kernel_convergence.py [--shape hexagon] [--angle 20] [--diameter-px 64] [--size 128]
        [--samples 1e4,1e5,1e6,1e7] [--repeats 3] [--json out.json]

Every kernel method (exact; mc with independent and stratified samples; raster)
renders the kernel at each sample count, after one warm-up render per method;
the table gives L1 to the exact reference and ``Kernel.time_s`` (the fastest of
``--repeats`` runs for points under 0.2 s), and the fitted convergence rates.
No count is skipped here (the whole-suite command ``bokehfit bench`` runs every
shape and size with a time cut-off; see :mod:`bokehfit.bench.kernels`).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from bokehfit.bench.kernels import kernel_sweep
from bokehfit.bench.report import kernel_table, markdown_table
from bokehfit.output_paths import check_output_path
from bokehfit.outputs import write_json


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--shape", default="hexagon")
    parser.add_argument("--angle", type=float, default=20.0)
    parser.add_argument("--diameter-px", type=float, default=64.0)
    parser.add_argument("--size", type=int, default=None, help="frame side (default: 1.25 × the outline + margin)")
    parser.add_argument("--samples", default="1e4,1e5,1e6,1e7")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", help="write the rows as JSON here")
    args = parser.parse_args()
    counts = [int(float(s)) for s in args.samples.split(",")]
    out = check_output_path(args.json, (".json",)) if args.json else None

    sweep = kernel_sweep([args.shape], [args.diameter_px], counts, angle_deg=args.angle, size=args.size,
                         repeats=args.repeats, max_point_s=math.inf)
    result = {"settings": {"samples": sorted(set(counts)), "angle_deg": args.angle}, "kernel": sweep["rows"],
              "rates": sweep["rates"], "kernel_skipped": sweep["skipped"]}
    for method, device in sweep["devices"].items():
        print(f"{method}: {device or 'CPU'}")
    print("cells: L1 to exact (render time, ms)")
    print(markdown_table(*kernel_table(result), left=4))
    for note in sweep["notes"]:
        print(f"note: {note}")
    if out:
        write_json(Path(out), {"shape": args.shape, "angle_deg": args.angle, "diameter_px": args.diameter_px, **sweep})
        print(f"wrote {out}")


if __name__ == "__main__":
    main()
