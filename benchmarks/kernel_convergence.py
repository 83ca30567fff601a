"""Kernel error against time: L1 distance to ``exact`` for ``mc`` and ``raster``.

Usage::

    python benchmarks/kernel_convergence.py [--shape hexagon] [--diameter-px 64] [--size 128]
        [--samples 1e4,1e5,1e6,1e7] [--repeats 3] [--json out.json]

For every sample count it renders the kernel with each sampling method (after
one warm-up call, so pipeline compilation is not timed), reports the best of
``--repeats`` wall times and the L1 error, and fits the convergence rate
(slope of log L1 against log samples). All figures come from one run on one
machine, so ratios between methods are comparable.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

from bokehfit.kernels import compute_kernel

VARIANTS = (("mc", "stratified"), ("mc", "independent"), ("raster", "stratified"))


def measure(shape, angle, diameter, size, method, sampling, samples, repeats):
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        kernel = compute_kernel(shape, angle, diameter, size, method=method, samples=samples, sampling=sampling, seed=7)
        best = min(best, time.perf_counter() - start)
    return kernel, best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--shape", default="hexagon")
    parser.add_argument("--angle", type=float, default=20.0)
    parser.add_argument("--diameter-px", type=float, default=64.0)
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--samples", default="1e4,1e5,1e6,1e7")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", help="write the rows as JSON here")
    args = parser.parse_args()
    counts = [int(float(s)) for s in args.samples.split(",")]

    start = time.perf_counter()
    exact = compute_kernel(args.shape, args.angle, args.diameter_px, args.size, method="exact")
    exact_time = time.perf_counter() - start
    rows = []
    devices = {}
    for method, sampling in VARIANTS:
        compute_kernel(args.shape, args.angle, args.diameter_px, args.size, method=method, samples=1000)  # warm-up
        for samples in counts:
            kernel, seconds = measure(
                args.shape, args.angle, args.diameter_px, args.size, method, sampling, samples, args.repeats
            )
            devices[method] = kernel.device
            l1 = float(np.abs(kernel.image.astype(np.float64) - exact.image).sum())
            rows.append(dict(method=method, sampling=sampling, samples=kernel.samples, time_s=seconds, l1=l1))

    print(f"{args.shape} {args.angle:g}°, {args.diameter_px:g} px in {args.size}×{args.size}; exact: {exact_time * 1e3:.2f} ms")
    for method, device in devices.items():
        print(f"  {method}: {device}")
    print(f"{'method':<8}{'sampling':<13}{'samples':>12}{'time ms':>11}{'L1':>12}")
    for row in rows:
        print(f"{row['method']:<8}{row['sampling']:<13}{row['samples']:>12}{row['time_s'] * 1e3:>11.2f}{row['l1']:>12.3e}")
    rates = {}
    for method, sampling in VARIANTS:
        chosen = [r for r in rows if r["method"] == method and r["sampling"] == sampling]
        slope = np.polyfit(np.log([r["samples"] for r in chosen]), np.log([r["l1"] for r in chosen]), 1)[0]
        rates[f"{method}/{sampling}"] = float(slope)
        print(f"convergence {method}/{sampling}: L1 ∝ N^{slope:.2f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(dict(shape=args.shape, diameter_px=args.diameter_px, size=args.size, exact_time_s=exact_time,
                           devices=devices, rows=rows, rates=rates), f, indent=1)


if __name__ == "__main__":
    main()
