"""``bokehfit compare``: fit the aperture behind a photo's bokeh and report how well it matches.

Every outcome (fitted, unsure, no_fit, no_discs) writes its JSON and its HTML
report where outputs were asked for: ``--json OUT.json`` puts ``OUT.html``
beside it; ``--out-dir DIR`` alone writes ``DIR/<photo stem>.json`` and
``DIR/<photo stem>.html``. With neither, nothing is written and the summary
says so. Exit code 0 for fitted and unsure, 1 for no_fit and no_discs.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from bokehfit.cli.arg_types import arg_type
from bokehfit.compare import compare_photo
from bokehfit.comparison import Comparison
from bokehfit.discs import COMPARE_MIN_DIAMETER_PX, DEFAULT_MAX_DIAMETER_PX, DEFAULT_MIN_DIAMETER_PX
from bokehfit.errors import InputError, NoResultError, check_positive
from bokehfit.fit import FOCUS_SIDES
from bokehfit.optics import LENS_MODELS, SIZE_CONVENTIONS
from bokehfit.output_paths import check_output_path, make_folder
from bokehfit.outputs import write_bytes_atomic, write_json
from bokehfit.text_encoding import encode_text

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
    parser.add_argument("--json", metavar="OUT.json",
                        help="write the result as JSON (schema_version 2) on every outcome, and the report beside it "
                             "as OUT.html; creates its folder")
    parser.add_argument("--out-dir", metavar="DIR",
                        help="folder for the report (default: the JSON's folder), created if missing; without --json "
                             "it gets PHOTO_STEM.json and PHOTO_STEM.html. With neither option nothing is written")
    parser.add_argument("--no-html", action="store_true", help="write no HTML report")
    parser.add_argument("--shapes", help="comma-separated shapes to try (default: all), e.g. circle,hexagon,ngon(9)")
    parser.add_argument("--focus-side", choices=FOCUS_SIDES, default="unknown", help="lights behind (far) or before (near) the focus plane; unknown reports both readings of odd shapes (default: %(default)s)")
    parser.add_argument("--lens-model", choices=LENS_MODELS, default="thin", help="thin (photos) or pinhole (renderers with a pinhole camera and a shaped aperture) (default: %(default)s)")
    parser.add_argument("--size-convention", choices=SIZE_CONVENTIONS, default="equal-area",
                        help="what f/N fixes: the area of a circle of diameter f/N (equal-area) or the diameter of the "
                             "shape's circumscribed circle (circumscribed, as Blender Cycles) (default: %(default)s)")
    parser.add_argument("--focal-length-mm", type=arg_type("focal_length_mm", "--focal-length-mm"), help="the lens's focal length (default: from EXIF)")
    parser.add_argument("--sensor-width-mm", type=arg_type("sensor_width_mm", "--sensor-width-mm"), help="the sensor's long side (default: from EXIF)")
    parser.add_argument("--focus-distance-m", type=arg_type("focus_distance_m", "--focus-distance-m"), help="focus distance (default: from EXIF)")
    parser.add_argument("--light-distance-m", type=arg_type("light_distance_m", "--light-distance-m"), default=math.inf, help="the lights' distance, a number or inf; without it the f-stop printed is an upper bound "
                        "(its value for lights at infinity) (default: %(default)s)")
    parser.add_argument("--min-diameter-px", type=float, default=COMPARE_MIN_DIAMETER_PX,
                        help=f"smallest disc sought (default {COMPARE_MIN_DIAMETER_PX:g}: the smallest that can show a "
                             f"shape; {DEFAULT_MIN_DIAMETER_PX:g} counts the smaller glints as `bokehfit discs` does, "
                             f"reported but not fitted, at about twice the search time on a large photo)")
    parser.add_argument("--discs", metavar="DISCS.json",
                        help="fit exactly these discs instead of finding them: a JSON file in the disc labels' format "
                             "({\"discs\": [{\"center_xy\": [x, y], \"diameter_px\": D}, ...]}; entries with "
                             "\"usable\": false and \"junk\" are ignored), each measured afresh at its place")
    parser.add_argument("--max-diameter-px", type=float, default=DEFAULT_MAX_DIAMETER_PX,
                        help="largest disc sought, pixels, or inf for no limit (default %(default)g, as for `bokehfit discs`)")
    parser.set_defaults(run=run)


def summary(comparison: Comparison) -> str:
    """The result in a few lines for the terminal (:meth:`Comparison.summary`)."""
    return comparison.summary()


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


def _output_paths(args: argparse.Namespace) -> tuple[Path | None, Path | None]:
    """The JSON and the HTML report to write (None where not asked for), checked before the work.

    Missing folders are made only when the outputs are written (a refused photo leaves none).
    """
    json_path = html_path = None
    stem = Path(args.photo).stem
    if args.json:
        json_path = check_output_path(args.json, (".json",), inputs=[args.photo], folder_may_be_missing=True)
        stem = json_path.stem
    elif args.out_dir:
        json_path = check_output_path(Path(args.out_dir) / f"{stem}.json", (".json",), inputs=[args.photo],
                                      folder_may_be_missing=True)
    if not args.no_html and json_path is not None:
        folder = Path(args.out_dir) if args.out_dir else json_path.parent
        html_path = check_output_path(folder / f"{stem}.html", (".html",), inputs=[args.photo], folder_may_be_missing=True)
    return json_path, html_path


def run(args: argparse.Namespace) -> Comparison:
    if not Path(args.photo).is_file():
        raise InputError(f"{args.photo} does not exist or is not a file")
    json_path, html_path = _output_paths(args)
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
            discs=args.discs,
            progress=progress,
            adapter=args.adapter,
        )
    finally:
        progress.close()
    command_line = args.command_line
    print(summary(comparison))
    if json_path:
        make_folder(json_path.parent)
        write_json(json_path, comparison.to_json(command_line))
        print(f"wrote {json_path}")
    if html_path:
        from bokehfit.report.html import build_html

        make_folder(html_path.parent)
        write_bytes_atomic(html_path, encode_text(build_html(comparison, command_line)))
        print(f"wrote {html_path}")
    if json_path is None:
        print("no files written (give --json OUT.json or --out-dir DIR for the JSON and the HTML report)")
    if comparison.status == "no_fit":
        raise NoResultError(f"no acceptable fit: {comparison.reason}")
    if comparison.status == "no_discs":
        raise NoResultError(comparison.reason)
    return comparison
