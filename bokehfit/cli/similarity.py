"""``bokehfit similarity``: every shape metric between two apertures; a table and JSON."""

from __future__ import annotations

import argparse

from bokehfit import __version__
from bokehfit.apertures import SHAPES, Aperture
from bokehfit.cli.aperture_args import add_feature_arguments, aperture_from_args
from bokehfit.cli.arg_types import pair_arg
from bokehfit.errors import InputError
from bokehfit.metrics import METRICS, angle_error, aperture_outline, best_rotation_deg, compare_outlines
from bokehfit.metrics.outlines import DEFAULT_POINTS, densify
from bokehfit.output_paths import check_output_path
from bokehfit.outputs import write_json

__all__ = ["add_parser", "run", "SCHEMA_VERSION"]

SCHEMA_VERSION = 1
#: Chord error of a vignetted outline's arcs before the metrics resample it (unit-area units).
OUTLINE_CHORD_ERROR = 1e-6


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "similarity",
        help="compare two aperture shapes with every shape metric",
        description=(
            "Compare two unit-area aperture shapes: IoU and Hausdorff distance after the best rotation, "
            "elliptic Fourier and Hu moment distances, and the angle error when both are the same shape."
        ),
    )
    parser.add_argument(
        "shape_a", metavar="SHAPE_A", help=f"{', '.join(SHAPES)} (with --blades-a) or ngon(N), e.g. ngon(9); required"
    )
    parser.add_argument("shape_b", metavar="SHAPE_B", help="as SHAPE_A; required")
    for side in ("a", "b"):
        upper = side.upper()
        parser.add_argument(f"--angle-{side}", type=float, default=0.0, metavar="DEG", help=f"counter-clockwise rotation of {upper} (default 0)")
        parser.add_argument(f"--blades-{side}", type=int, default=None, metavar="N", help=f"blade count of {upper} when it is an ngon (default: none)")
        parser.add_argument(f"--aspect-{side}", type=float, default=None, metavar="A", help=f"width/height of {upper} when it is a slit (default 0.3)")
        # Only the features that change the outline: rim and chromatic change the light, not the shape.
        add_feature_arguments(parser, suffix=f"-{side}", whose=f" of {upper}", outline_only=True, mask=True)
        parser.add_argument(
            f"--field-position-{side}", type=pair_arg(f"--field-position-{side}", ("field_position", "field_position"), "X,Y"),
            default=None, metavar="X,Y",
            help=f"position of {upper}'s disc from the image centre, half-diagonals, y up: where --vignetting-{side} cuts it (default 0,0)",
        )
    parser.add_argument("--json", metavar="OUT.json", help="write the metrics as JSON (default: none)")
    parser.set_defaults(run=run)


def _aperture(args: argparse.Namespace, side: str) -> Aperture:
    vignetting = getattr(args, f"vignetting_{side}")
    if getattr(args, f"field_position_{side}") is not None and vignetting is None:
        raise InputError(f"--field-position-{side} applies only with --vignetting-{side} (got no vignetting)")
    try:
        return aperture_from_args(args, side)
    except InputError as error:
        # make_aperture's messages open with the parameter's name: give the option's.
        message = str(error)
        name = message.split(" ", 1)[0]
        options = {"shape": f"SHAPE_{side.upper()}", "angle_deg": f"--angle-{side}", "blades": f"--blades-{side}", "aspect": f"--aspect-{side}",
                   "roundness": f"--roundness-{side}", "squeeze": f"--squeeze-{side}", "mask": f"--mask-{side}"}
        if name in options:
            message = options[name] + message[len(name) :]
        raise InputError(message) from None


def _field_position(args: argparse.Namespace, side: str):
    """Where side's vignetting cuts it: the option's value, (0, 0) by default; None without vignetting."""
    if getattr(args, f"vignetting_{side}") is None:
        return None
    return getattr(args, f"field_position_{side}") or (0.0, 0.0)


def _outline(aperture: Aperture, field_position):
    """The outline the metrics compare: the unit-area outline, or the vignetted one (it passes less light)."""
    if field_position is None:
        if len(aperture.outline().loops) != 1:  # a mask's 50 % transmission contour may fall apart
            raise InputError(
                f"the outline of {aperture.describe()} (its 50 % transmission contour) has {len(aperture.outline().loops)} "
                "pieces: the metrics compare one outline"
            )
        return aperture_outline(aperture)
    clipped = aperture.outline(field_position)
    if len(clipped.loops) != 1:
        raise InputError(
            f"the vignetting leaves {len(clipped.loops)} pieces of {aperture.describe()} at field position "
            f"{field_position[0]:g},{field_position[1]:g}: the metrics compare one outline"
        )
    return densify(clipped.polyline(OUTLINE_CHORD_ERROR), DEFAULT_POINTS)


def _aperture_json(aperture: Aperture, field_position=None) -> dict:
    vignetting = aperture.vignetting
    return {
        "shape": aperture.shape,
        "angle_deg": aperture.canonical_angle_deg,
        "blades": aperture.blades,
        "aspect": aperture.aspect,
        "symmetry_deg": aperture.symmetry_deg,
        "roundness": aperture.roundness,
        "squeeze": aperture.squeeze,
        "vignetting": None if vignetting is None else {"radius": vignetting.radius, "shift": vignetting.shift},
        "field_position": None if field_position is None else list(field_position),
    }


def same_shape(a: Aperture, b: Aperture) -> bool:
    """Whether an angle error between ``a`` and ``b`` means anything: one family, one symmetry."""
    return a.spec == b.spec and a.symmetry_deg == b.symmetry_deg


def run(args: argparse.Namespace) -> dict:
    out = check_output_path(args.json, (".json",)) if args.json else None
    a, b = _aperture(args, "a"), _aperture(args, "b")
    field_a, field_b = _field_position(args, "a"), _field_position(args, "b")
    outline_a, outline_b = _outline(a, field_a), _outline(b, field_b)
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
        "command_line": args.command_line,
        "a": _aperture_json(a, field_a),
        "b": _aperture_json(b, field_b),
        "metrics": metrics,
        "angle_error_deg": error,
        "best_rotation_deg": rotation,
    }
    clipped = " and field position" if field_a or field_b else ""
    print(f"A: {a.describe()}    B: {b.describe()}    (outlines at unit area{clipped}; the metrics compare them at equal area)")
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
