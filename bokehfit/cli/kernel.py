"""``bokehfit kernel``: render one point-light defocus kernel to a file."""

from __future__ import annotations

import argparse

import numpy as np

from bokehfit.apertures import SHAPES
from bokehfit.kernels import DEFAULT_SAMPLES, METHODS, SAMPLINGS, SIDES, Kernel, compute_kernel
from bokehfit.kernels.accuracy import MIN_TOLERANCE
from bokehfit.errors import InputError
from bokehfit.output_paths import check_output_path
from bokehfit.outputs import KERNEL_FORMATS, write_exr, write_kernel_image, write_png
from bokehfit.cli.aperture_args import add_feature_arguments, aperture_from_args
from bokehfit.cli.arg_types import arg_type, interval, pair_arg, shape_arg

__all__ = ["add_parser", "run"]


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "kernel",
        help="render a point-light defocus kernel",
        description="Render the defocus kernel (PSF) of one point light seen through a shaped aperture.",
    )
    parser.add_argument(
        "--shape", type=shape_arg("--shape"), default="hexagon",
        help=f"aperture shape: {', '.join(SHAPES)} (with --blades) or ngon(N) (default hexagon)",
    )
    parser.add_argument("--angle", type=arg_type("angle_deg", "--angle"), default=0.0, metavar="DEG", help="counter-clockwise rotation (default 0)")
    parser.add_argument(
        "--diameter-px", type=arg_type("diameter_px", "--diameter-px"), default=64.0, metavar="D",
        help=f"equal-area diameter of the disc, {interval('diameter_px')} (default 64)",
    )
    parser.add_argument("--size", type=arg_type("kernel_size", "--size"), default=128, metavar="N", help=f"frame side, {interval('kernel_size')} (default 128)")
    parser.add_argument("--side", choices=SIDES, default="far", help="light behind (far) or before (near) the focus plane (default far)")
    parser.add_argument(
        "--method", choices=list(METHODS), default=None,
        help="exact, mc (WGSL) or raster (OpenGL) (default: exact, or with --tolerance the cheapest that meets it)",
    )
    parser.add_argument(
        "--tolerance", type=arg_type("tolerance", "--tolerance"), default=None, metavar="L1",
        help=f"largest L1 error wanted, at least {MIN_TOLERANCE:.2g}: picks the method and sample count (default: none)",
    )
    parser.add_argument(
        "--samples", type=arg_type("kernel_samples", "--samples"), default=None, metavar="N",
        help=f"point samples over the disc for mc and raster, {interval('kernel_samples')} (default {DEFAULT_SAMPLES})",
    )
    parser.add_argument("--sampling", choices=SAMPLINGS, default="stratified", help="mc sample pattern (default stratified)")
    parser.add_argument("--blades", type=arg_type("blades", "--blades"), default=None, metavar="N", help=f"blade count of an ngon, {interval('blades')} (default: none)")
    parser.add_argument("--aspect", type=arg_type("aspect", "--aspect"), default=None, metavar="A", help="width/height of a slit (default 0.3)")
    parser.add_argument("--seed", type=arg_type("seed", "--seed"), default=0, metavar="S", help="random seed; the same seed gives the same kernel (default 0)")
    add_feature_arguments(parser, chromatic_help="; writes a 3-channel kernel", mask=True)
    parser.add_argument(
        "--field-position", type=pair_arg("--field-position", ("field_position", "field_position"), "X,Y"), default=None, metavar="X,Y",
        help=f"the disc's position from the image centre, half-diagonals, y up, each {interval('field_position')}: "
        "where --vignetting cuts it (default 0,0)",
    )
    parser.add_argument(
        "--out", required=True,
        help=f"output file ({', '.join(KERNEL_FORMATS)}); with --chromatic an RGB kernel: .npy (H, W, 3), "
        ".png RGB 16-bit, .exr R, G, B; required",
    )
    parser.set_defaults(run=run)


def _write_kernel(path, image) -> None:
    """One channel through :func:`write_kernel_image`; red, green, blue as .npy (H, W, 3), 16-bit RGB PNG or RGB EXR."""
    if image.ndim == 2 or path.suffix.lower() == ".npy":
        write_kernel_image(path, image)
    elif path.suffix.lower() == ".png":
        peak = float(image.max())  # one scale for the three channels keeps their balance
        scaled = np.round(image / peak * 65535.0) if peak > 0 else np.zeros_like(image)
        write_png(path, scaled[..., ::-1].astype(np.uint16))  # OpenCV orders channels BGR
    else:
        write_exr(path, {name: image[..., i] for i, name in enumerate("RGB")})


def run(args: argparse.Namespace) -> Kernel:
    out = check_output_path(args.out, KERNEL_FORMATS)
    if args.field_position is not None and args.vignetting is None:
        raise InputError("--field-position applies only with --vignetting (the kernel is the same everywhere without it)")
    kernel = compute_kernel(
        aperture_from_args(args),
        args.diameter_px,
        args.size,
        side=args.side,
        method=args.method,
        samples=args.samples,
        field_position=args.field_position,
        sampling=args.sampling,
        seed=args.seed,
        tolerance=args.tolerance,
        adapter=args.adapter,
    )
    _write_kernel(out, kernel.image)
    line = f"{kernel.aperture.describe()}, {kernel.diameter_px:g} px, {kernel.side}: method {kernel.method}"
    if kernel.samples is not None:
        line += f", {kernel.samples} samples"
    if kernel.predicted_l1 is not None:
        line += f" (tolerance {args.tolerance:g}: expected L1 {kernel.predicted_l1:.2g})"
    if kernel.error_bound is not None:
        line += f" (tabulated rim: L1 ≤ {kernel.error_bound:.2g})"
    if kernel.aperture.vignetting is not None:
        line += f", field position {kernel.field_position[0]:g},{kernel.field_position[1]:g}: {100 * kernel.transmitted:.3g}% of the light passes"
    if kernel.image.ndim == 3:
        line += ", channels red, green, blue"
    line += f", {kernel.time_s * 1000:.1f} ms"
    if kernel.setup_s > 0.01:
        line += f" (+{kernel.setup_s * 1000:.0f} ms start-up)"
    if kernel.device is not None:
        line += f", on {kernel.device}"
    print(line)
    print(f"wrote {out}")
    return kernel
