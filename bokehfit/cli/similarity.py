"""``bokehfit similarity``: every shape metric between two apertures; a table and JSON."""

from __future__ import annotations

import argparse
import sys

from bokehfit import __version__
from bokehfit.apertures import Aperture, make_aperture
from bokehfit.errors import InputError
from bokehfit.metrics import METRICS, angle_error, aperture_outline, best_rotation_deg, compare_outlines
from bokehfit.outputs import check_output_path, write_json

__all__ = ["add_parser", "run", "SCHEMA_VERSION"]

SCHEMA_VERSION = 1


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "similarity",
        help="compare two aperture shapes with every shape metric",
        description=(
            "Compare two unit-area aperture shapes: IoU and Hausdorff distance after the best rotation, "
            "elliptic Fourier and Hu moment distances, and the angle error when both are the same shape."
        ),
    )
    parser.add_argument("shape_a", metavar="SHAPE_A", help="circle, square, slit, triangle, pentagon, hexagon, star or ngon")
    parser.add_argument("shape_b", metavar="SHAPE_B", help="as SHAPE_A")
    for side in ("a", "b"):
        upper = side.upper()
        parser.add_argument(f"--angle-{side}", type=float, default=0.0, metavar="DEG", help=f"counter-clockwise rotation of {upper} (default 0)")
        parser.add_argument(f"--blades-{side}", type=int, default=None, metavar="N", help=f"blade count of {upper} when it is an ngon")
        parser.add_argument(f"--aspect-{side}", type=float, default=None, metavar="A", help=f"width/height of {upper} when it is a slit (default 0.3)")
    parser.add_argument("--json", metavar="OUT.json", help="write the metrics as JSON")
    parser.set_defaults(run=run)


def _aperture(args: argparse.Namespace, side: str) -> Aperture:
    try:
        return make_aperture(
            getattr(args, f"shape_{side}"),
            getattr(args, f"angle_{side}"),
            blades=getattr(args, f"blades_{side}"),
            aspect=getattr(args, f"aspect_{side}"),
        )
    except InputError as error:
        # make_aperture's messages open with the parameter's name: give the option's.
        message = str(error)
        name = message.split(" ", 1)[0]
        options = {"shape": f"SHAPE_{side.upper()}", "angle_deg": f"--angle-{side}", "blades": f"--blades-{side}", "aspect": f"--aspect-{side}"}
        if name in options:
            message = options[name] + message[len(name) :]
        raise InputError(message) from None


def _aperture_json(aperture: Aperture) -> dict:
    return {
        "shape": aperture.shape,
        "angle_deg": aperture.canonical_angle_deg,
        "blades": aperture.blades,
        "aspect": aperture.aspect,
        "symmetry_deg": aperture.symmetry_deg,
    }


def same_shape(a: Aperture, b: Aperture) -> bool:
    """Whether an angle error between ``a`` and ``b`` means anything: one family, one symmetry."""
    return a.spec.family == b.spec.family and a.symmetry_deg == b.symmetry_deg


def run(args: argparse.Namespace) -> dict:
    out = check_output_path(args.json, (".json",)) if args.json else None
    a, b = _aperture(args, "a"), _aperture(args, "b")
    outline_a, outline_b = aperture_outline(a), aperture_outline(b)
    metrics = compare_outlines(outline_a, outline_b)
    error = angle_error(a.angle_deg, b.angle_deg, a.symmetry_deg) if same_shape(a, b) else None
    # Rotating a circle changes nothing: no rotation is "best".
    if a.symmetry_deg is None or b.symmetry_deg is None:
        rotation = None
    else:
        # One of b's equivalent rotations: the smallest, in [−symmetry/2, symmetry/2).
        symmetry = b.symmetry_deg
        rotation = (best_rotation_deg(outline_a, outline_b) + symmetry / 2.0) % symmetry - symmetry / 2.0
    result = {
        "schema_version": SCHEMA_VERSION,
        "bokehfit_version": __version__,
        "command_line": " ".join(["bokehfit", *sys.argv[1:]]) if sys.argv else "bokehfit",
        "a": _aperture_json(a),
        "b": _aperture_json(b),
        "metrics": metrics,
        "angle_error_deg": error,
        "best_rotation_deg": rotation,
    }
    print(f"A: {a.describe()}    B: {b.describe()}    (both at unit area)")
    print(f"{'metric':<14} {'value':>10}  {'better':<7} description")
    for name, value in metrics.items():
        metric = METRICS[name]
        print(f"{name:<14} {value:>10.5f}  {metric.better:<7} {metric.description}, {metric.range}")
    if error is not None:
        meaning = f"|angle A − angle B| modulo the {a.symmetry_deg:g}° symmetry" if a.symmetry_deg else "0: a circle has no angle"
        print(f"{'angle_error':<14} {error:>9.3f}°  {'lower':<7} {meaning}, degrees")
    if rotation is None:
        print("best rotation of B: any (a circle looks the same at every angle)")
    else:
        print(f"best rotation of B: {rotation:.2f}° counter-clockwise (maximises the IoU; modulo {b.symmetry_deg:g}°)")
    if out is not None:
        write_json(out, result)
        print(f"wrote {out}")
    return result
