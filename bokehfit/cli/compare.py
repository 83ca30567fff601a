"""``bokehfit compare``: fit the aperture behind a photo's bokeh and report how well it matches."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from bokehfit.compare import Comparison, compare_photo
from bokehfit.discs.measure import RESOLVABLE_PX
from bokehfit.errors import InputError, NoResultError, check_positive
from bokehfit.fit import FOCUS_SIDES
from bokehfit.optics import LENS_MODELS, SIZE_CONVENTIONS
from bokehfit.outputs import check_output_path, write_bytes_atomic, write_json

__all__ = ["add_parser", "run", "summary"]


def _distance(text: str) -> float:
    if text.strip().lower() in ("inf", "infinity"):
        return math.inf
    return check_positive("--light-distance-m", text)


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "compare",
        help="fit the aperture behind a photo's bokeh and report the match",
        description="Find the bokeh discs of a photo, fit the aperture (shape, angle, f-stop), render its "
        "kernel on the GPU and report how well shape and kernel match.",
    )
    parser.add_argument("photo", help="JPEG, PNG, TIFF or camera raw file")
    parser.add_argument("--json", metavar="OUT.json", help="write the result as JSON (schema_version 1); creates its folder")
    parser.add_argument("--out-dir", metavar="DIR", help="folder for report.html, created if missing (default: the JSON's folder)")
    parser.add_argument("--no-html", action="store_true", help="write no HTML report")
    parser.add_argument("--shapes", help="comma-separated shapes to try (default: all), e.g. circle,hexagon,ngon(9)")
    parser.add_argument("--focus-side", choices=FOCUS_SIDES, default="unknown", help="lights behind (far) or before (near) the focus plane")
    parser.add_argument("--lens-model", choices=LENS_MODELS, default="thin", help="thin (photos) or pinhole (renderers)")
    parser.add_argument("--size-convention", choices=SIZE_CONVENTIONS, default="equal-area")
    parser.add_argument("--focal-length-mm", type=float)
    parser.add_argument("--sensor-width-mm", type=float, help="the sensor's long side")
    parser.add_argument("--focus-distance-m", type=float)
    parser.add_argument("--light-distance-m", type=_distance, default=math.inf, help="a number or inf (default)")
    parser.add_argument("--min-diameter-px", type=float, default=RESOLVABLE_PX,
                        help=f"smallest disc sought (default {RESOLVABLE_PX:g}: smaller ones cannot show a shape)")
    parser.add_argument("--max-diameter-px", type=float, default=500.0)
    parser.set_defaults(run=run)


def summary(comparison: Comparison) -> str:
    """The result in a few lines for the terminal."""
    fit, search = comparison.fit, comparison.search
    lines = [f"{comparison.photo.path.name}: {comparison.photo.width}×{comparison.photo.height}, "
             f"{len(search.discs)} discs ({sum(d.usable for d in search.discs)} clean enough to fit)"]
    if not fit:
        return "\n".join(lines + [f"no aperture fitted: {fit.message}"])
    aperture = comparison.aperture_json()
    angle = "" if aperture["angle_deg"] is None else f", angle {aperture['angle_deg']:.2f}° ± {aperture['angle_uncertainty_deg']:.2f}°"
    lines.append(f"aperture: {fit.aperture.describe()}{angle}, disc {aperture['diameter_px']:.2f} px")
    if comparison.doubts:
        lines.append("unsure: " + "; ".join(comparison.doubts))
    if aperture["fstop"] is None:
        lines.append(f"f-stop: unknown: {aperture['fstop_reason']}")
    else:
        lines.append(f"f-stop: f/{aperture['fstop']:.2f} ± {aperture['fstop_uncertainty']:.2f} "
                     f"({aperture['size_convention']}, {aperture['lens_model']} lens)")
    if aperture["angle_note"]:
        lines.append(aperture["angle_note"])
    ranked = ", ".join(f"{c['name']} (ΔBIC {c['delta_bic']:.0f})" for c in aperture["candidates"][1:])
    lines.append(f"runners-up: {ranked or 'none'}")
    lines.append("metrics (discs vs kernel, median): " + ", ".join(
        f"{k} {v:.4f}" for k, v in comparison.metrics.items() if v is not None))
    lines.append("time: " + ", ".join(f"{k} {v:.2f} s" for k, v in comparison.timing_s.items())
                 + f"; kernel on {comparison.device.get('adapter')}")
    return "\n".join(lines)


class _Progress:
    """A stage-by-stage progress bar on the terminal (nothing when stderr is not a terminal)."""

    STAGES = ("load", "detect", "fit", "render", "metrics")

    def __init__(self):
        self.bar = None
        if sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=len(self.STAGES), desc="compare", unit="stage", leave=False, file=sys.stderr)

    def __call__(self, *args):
        if self.bar is None:
            return
        if len(args) == 1:
            self.bar.set_description(f"compare: {args[0]}")
            self.bar.n = self.STAGES.index(args[0])
        else:
            done, total = args
            self.bar.set_description(f"compare: fit disc {done}/{total}")
        self.bar.refresh()

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _make_folder(folder: Path) -> None:
    """Create an output folder (and its parents) if it is missing."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise InputError(f"cannot create the output folder {str(folder)!r}: {error.strerror}") from None


def run(args: argparse.Namespace) -> Comparison:
    if not Path(args.photo).is_file():
        raise InputError(f"{args.photo} does not exist or is not a file")
    json_path = None
    if args.json:
        _make_folder(Path(args.json).parent)
        json_path = check_output_path(args.json, (".json",), inputs=[args.photo])
    html_path = None
    if not args.no_html:
        folder = Path(args.out_dir) if args.out_dir else (json_path.parent if json_path else None)
        if folder is not None:
            _make_folder(folder)
            html_path = check_output_path(folder / "report.html", (".html",), inputs=[args.photo])
    shapes = [s.strip() for s in args.shapes.split(",") if s.strip()] if args.shapes else None
    progress = _Progress()
    try:
        comparison = compare_photo(
            args.photo,
            shapes=shapes,
            focus_side=args.focus_side,
            lens_model=args.lens_model,
            size_convention=args.size_convention,
            focal_length_mm=args.focal_length_mm,
            sensor_width_mm=args.sensor_width_mm,
            focus_distance_m=args.focus_distance_m,
            light_distance_m=args.light_distance_m,
            min_diameter_px=args.min_diameter_px,
            max_diameter_px=args.max_diameter_px,
            progress=progress,
        )
    finally:
        progress.close()
    command_line = " ".join(["bokehfit", *sys.argv[1:]])
    print(summary(comparison))
    if not comparison.search:
        raise NoResultError(f"no bokeh disc found in {comparison.photo.path.name}: {comparison.search.reason}")
    if not comparison.fit:
        raise NoResultError(comparison.fit.message)
    if comparison.rejection:
        raise NoResultError(comparison.rejection)
    if json_path:
        write_json(json_path, comparison.to_json(command_line))
        print(f"wrote {json_path}")
    if html_path:
        from bokehfit.report.html import build_html

        write_bytes_atomic(html_path, build_html(comparison, command_line).encode("utf-8"))
        print(f"wrote {html_path}")
    return comparison
