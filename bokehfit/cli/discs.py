"""``bokehfit discs``: find the bokeh discs of a photo; a table, JSON and an overlay."""

from __future__ import annotations

import argparse
import sys
import time

from bokehfit import __version__
from bokehfit.discs import DEFAULT_MAX_DIAMETER_PX, DEFAULT_MIN_DIAMETER_PX, DiscSearch, find_discs
from bokehfit.errors import InputError, NoResultError
from bokehfit.io import load_photo
from bokehfit.output_paths import check_output_path
from bokehfit.outputs import write_json, write_png
from bokehfit.words import rejection_lines

__all__ = ["add_parser", "run", "SCHEMA_VERSION"]

SCHEMA_VERSION = 1
#: Rows of the table printed on the terminal (all are in the JSON).
TABLE_ROWS = 40


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "discs",
        help="find the bokeh discs of a photo",
        description="Find the bokeh discs of a photo: centre, equal-area diameter, sub-pixel outline and flags.",
    )
    parser.add_argument("photo", help="JPEG, PNG, TIFF or camera raw file")
    parser.add_argument("--json", metavar="OUT.json", help="write the discs as JSON (schema_version 1)")
    parser.add_argument("--overlay", metavar="OUT.png", help="write the photo with the outlines drawn on it")
    parser.add_argument(
        "--min-diameter-px",
        type=float,
        default=DEFAULT_MIN_DIAMETER_PX,
        metavar="PX",
        help="smallest equal-area disc diameter to look for, pixels (default: %(default)g)",
    )
    parser.add_argument(
        "--max-diameter-px",
        type=float,
        default=DEFAULT_MAX_DIAMETER_PX,
        metavar="PX",
        help="largest equal-area disc diameter to look for, pixels (default: %(default)g)",
    )
    parser.add_argument(
        "--max-discs", type=int, default=None, metavar="N", help="keep the largest N discs (default: all of them)"
    )
    parser.set_defaults(run=run)


def disc_table(search: DiscSearch, rows: int = TABLE_ROWS) -> str:
    """The discs as a fixed-width table for the terminal."""
    lines = [f"{'#':>4} {'x':>8} {'y':>8} {'diam px':>8} {'snr':>6}  flags"]
    for disc in search.discs[:rows]:
        flags = [name for name in ("saturated", "clipped", "overlaps") if getattr(disc, name)]
        if disc.soft_edge:
            flags.append("soft edge")
        if not disc.resolvable:
            flags.append("small")
        lines.append(
            f"{disc.index:>4} {disc.center_xy[0]:>8.1f} {disc.center_xy[1]:>8.1f} {disc.diameter_px:>8.2f} "
            f"{disc.snr:>6.1f}  {', '.join(flags) or 'usable'}"
        )
    if len(search.discs) > rows:
        lines.append(f"     … and {len(search.discs) - rows} more (all are in the JSON)")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> DiscSearch:
    outputs = {}
    for name, suffixes in (("json", (".json",)), ("overlay", (".png",))):
        if getattr(args, name):
            outputs[name] = check_output_path(getattr(args, name), suffixes, inputs=[args.photo])
    if args.max_discs is not None and args.max_discs < 1:
        raise InputError(f"--max-discs must be at least 1 (got {args.max_discs})")
    progress = sys.stderr.isatty()
    start = time.perf_counter()
    photo = load_photo(args.photo, progress=progress)
    loaded = time.perf_counter()
    search = find_discs(
        photo.luminance,
        photo.clipped,
        min_diameter_px=args.min_diameter_px,
        max_diameter_px=args.max_diameter_px,
        max_discs=args.max_discs,
        progress=progress,
        rgb=photo.linear_rgb,
    )
    print(f"{photo.path.name}: {photo.width}×{photo.height}, {photo.colour_space}; {photo.linearisation}")
    for note in (*photo.notes, *search.notes):
        print(f"note: {note}")
    detection = {
        "candidates": search.candidates,
        "rejected": dict(search.rejected),
        "min_diameter_px": args.min_diameter_px,
        "max_diameter_px": args.max_diameter_px,
        "places_given": search.given,
        "rejections": [r.to_json() for r in search.rejections],
    }
    if "json" in outputs:
        write_json(
            outputs["json"],
            {
                "schema_version": SCHEMA_VERSION,
                "bokehfit_version": __version__,
                "command_line": args.command_line,
                "input": photo.input_json(),
                "detection": detection,
                "discs": [disc.to_json() for disc in search.discs],
                "timing_s": {"load": round(loaded - start, 4), "detect": round(search.time_s, 4)},
            },
        )
        print(f"wrote {outputs['json']}")
    if "overlay" in outputs:
        from bokehfit.report import draw_disc_overlay

        write_png(outputs["overlay"], draw_disc_overlay(photo.display, search.discs))
        print(f"wrote {outputs['overlay']}")
    if not search:
        raise NoResultError(f"no bokeh disc found in {photo.path.name}: {search.reason}")
    used = sum(d.usable for d in search.discs)
    print(disc_table(search))
    for line in rejection_lines(detection):
        print(line)
    print(  # the last line: what was found, and in how long
        f"{len(search.discs)} discs ({used} clean enough to fit) from {search.candidates} candidates "
        f"in {search.time_s:.2f} s (loading {loaded - start:.2f} s)"
    )
    return search
