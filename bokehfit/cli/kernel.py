"""``bokehfit kernel``: render one point-light defocus kernel to a file."""

from __future__ import annotations

import argparse

from bokehfit.apertures import SHAPES
from bokehfit.kernels import METHODS, SAMPLINGS, SIDES, Kernel, compute_kernel
from bokehfit.outputs import KERNEL_FORMATS, check_output_path, write_kernel_image

__all__ = ["add_parser", "run"]


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "kernel",
        help="render a point-light defocus kernel",
        description="Render the defocus kernel (PSF) of one point light seen through a shaped aperture.",
    )
    parser.add_argument("--shape", choices=list(SHAPES), default="hexagon")
    parser.add_argument("--angle", type=float, default=0.0, metavar="DEG", help="counter-clockwise rotation (default 0)")
    parser.add_argument("--diameter-px", type=float, default=64.0, help="equal-area diameter of the disc (default 64)")
    parser.add_argument("--size", type=int, default=128, help="frame side in pixels (default 128)")
    parser.add_argument("--side", choices=SIDES, default="far", help="light behind (far) or before (near) the focus plane")
    parser.add_argument("--method", choices=list(METHODS), default=None, help="default exact, or with --tolerance the cheapest")
    parser.add_argument("--tolerance", type=float, default=None, help="largest L1 error wanted: picks method and samples")
    parser.add_argument("--samples", type=int, default=None, help="point samples over the disc (mc, raster; default 2^22)")
    parser.add_argument("--sampling", choices=SAMPLINGS, default="stratified", help="mc sample pattern")
    parser.add_argument("--blades", type=int, default=None, help="blade count of an ngon")
    parser.add_argument("--aspect", type=float, default=None, help="width/height of a slit (default 0.3)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", required=True, help=f"output file ({', '.join(KERNEL_FORMATS)})")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> Kernel:
    out = check_output_path(args.out, KERNEL_FORMATS)
    kernel = compute_kernel(
        args.shape,
        args.angle,
        args.diameter_px,
        args.size,
        side=args.side,
        method=args.method,
        samples=args.samples,
        blades=args.blades,
        aspect=args.aspect,
        sampling=args.sampling,
        seed=args.seed,
        tolerance=args.tolerance,
    )
    write_kernel_image(out, kernel.image)
    line = f"{kernel.aperture.describe()}, {kernel.diameter_px:g} px, {kernel.side}: method {kernel.method}"
    if kernel.samples is not None:
        line += f", {kernel.samples} samples"
    if kernel.predicted_l1 is not None:
        line += f" (tolerance {args.tolerance:g}: expected L1 {kernel.predicted_l1:.2g})"
    line += f", {kernel.time_s * 1000:.1f} ms"
    if kernel.setup_s > 0.01:
        line += f" (+{kernel.setup_s * 1000:.0f} ms start-up)"
    if kernel.device is not None:
        line += f", on {kernel.device}"
    print(line)
    print(f"wrote {out}")
    return kernel
