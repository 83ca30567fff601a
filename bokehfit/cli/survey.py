"""``bokehfit survey``: compare on every photo of a library, each result kept in a DuckDB database.

``bokehfit survey PATH... --db survey.duckdb`` walks folders, expands glob
patterns and reads ``--files-from`` lists; it runs compare on each photo in
``--jobs`` worker processes (or on a Dask cluster with ``--scheduler``) and
commits each photo's row as its result arrives, keyed by the file's SHA-256,
so that a rerun skips what is done and an interrupted survey resumes.
``--report OUT.html`` writes the lens fingerprint page and ``--parquet`` the
table; both work without PATH, from the database alone.

Exit code 0 when the survey ran to its end (photos that failed are rows with
their status), 130 on Ctrl-C (what was done is saved), 2 for usage or input errors.
"""

from __future__ import annotations

import argparse
import math
import os
import signal

from bokehfit.cli.arg_types import arg_type
from bokehfit.errors import InputError, check_positive
from bokehfit.fit import FOCUS_SIDES
from bokehfit.optics import LENS_MODELS, SIZE_CONVENTIONS

__all__ = ["add_parser", "run", "DEFAULT_TIMEOUT_S"]

#: Per-photo limit by default: far beyond a normal photo (seconds), short enough that a stuck one doesn't hold a worker for long.
DEFAULT_TIMEOUT_S = 600.0


def _jobs(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"--jobs must be an integer >= 1 (got {text!r})")
    return value


def _seconds(text: str) -> float:
    try:
        return check_positive("--timeout-s", text)
    except InputError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def _distance(text: str) -> float:
    if text.strip().lower() in ("inf", "infinity"):
        return math.inf
    return arg_type("light_distance_m", "--light-distance-m")(text)


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "survey",
        help="run compare on every photo of a library into a database; report the lens fingerprint",
        description="Run compare on every photo (JPEG, PNG, TIFF, raw) that PATHs name, in parallel or on a Dask "
        "cluster, storing each result in a DuckDB database as it completes (a rerun skips what is done). "
        "--report groups the results by camera, lens and f-number.",
    )
    parser.add_argument("paths", nargs="*", metavar="PATH", help="photo files, folders (walked) and glob patterns (quote them)")
    parser.add_argument("--db", required=True, metavar="SURVEY.duckdb",
                        help="the survey database, created if missing; per-photo reports go to SURVEY_reports/ beside it")
    parser.add_argument("--files-from", metavar="LIST", help="a text file of photo paths, one a line")
    parser.add_argument("--jobs", type=_jobs, default=None,
                        help="worker processes on this machine (default: the usable CPU cores)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="run on a Dask cluster, e.g. tcp://10.0.0.5:8786 (see `dask scheduler`, `dask worker`); "
                             "it must answer within 10 s")
    parser.add_argument("--timeout-s", type=_seconds, default=DEFAULT_TIMEOUT_S,
                        help=f"per-photo limit in seconds, past which the photo is a timeout row (default {DEFAULT_TIMEOUT_S:g}; "
                             "local workers only)")
    parser.add_argument("--retry-failed", action="store_true", help="run again the photos stored as unreadable, error or timeout")
    parser.add_argument("--no-html", action="store_true", help="write no per-photo HTML report (the JSON still)")
    parser.add_argument("--report", metavar="OUT.html", help="write the fingerprint page: results by camera, lens and f-number")
    parser.add_argument("--parquet", metavar="OUT.parquet", help="export the table as Parquet")
    compare = parser.add_argument_group("compare options (as for `bokehfit compare`, the same for every photo)")
    compare.add_argument("--shapes", help="comma-separated shapes to try (default: all), e.g. circle,hexagon,ngon(9)")
    compare.add_argument("--focus-side", choices=FOCUS_SIDES, default="unknown",
                         help="lights behind (far) or before (near) the focus plane (default: %(default)s)")
    compare.add_argument("--lens-model", choices=LENS_MODELS, default="thin",
                         help="thin (photos) or pinhole (renderers) (default: %(default)s)")
    compare.add_argument("--size-convention", choices=SIZE_CONVENTIONS, default="equal-area",
                         help="how the f-stop sizes the aperture (default: %(default)s)")
    compare.add_argument("--focal-length-mm", type=arg_type("focal_length_mm", "--focal-length-mm"), help="default: from EXIF")
    compare.add_argument("--sensor-width-mm", type=arg_type("sensor_width_mm", "--sensor-width-mm"), help="default: from EXIF")
    compare.add_argument("--focus-distance-m", type=arg_type("focus_distance_m", "--focus-distance-m"), help="default: from EXIF")
    compare.add_argument("--light-distance-m", type=_distance, default=math.inf, help="a number or inf (default inf)")
    compare.add_argument("--min-diameter-px", type=arg_type("min_diameter_px", "--min-diameter-px"),
                         help="smallest disc sought (default: as for `bokehfit compare`)")
    compare.add_argument("--max-diameter-px", type=arg_type("max_diameter_px", "--max-diameter-px"),
                         help="largest disc sought (default: as for `bokehfit compare`)")
    parser.set_defaults(run=run)


def compare_options(args: argparse.Namespace) -> dict:
    """The compare keywords the command line gives (those left at compare's defaults are left out)."""
    options = {
        "shapes": [s.strip() for s in args.shapes.split(",") if s.strip()] if args.shapes else None,
        "focus_side": args.focus_side,
        "lens_model": args.lens_model,
        "size_convention": args.size_convention,
        "focal_length_mm": args.focal_length_mm,
        "sensor_width_mm": args.sensor_width_mm,
        "focus_distance_m": args.focus_distance_m,
        "light_distance_m": args.light_distance_m,
        "min_diameter_px": args.min_diameter_px,
        "max_diameter_px": args.max_diameter_px,
    }
    return {name: value for name, value in options.items() if value is not None}


def _stop_at_once(signum, frame):
    """A Ctrl-C after the survey stopped: end now (every stored row is committed)."""
    os.write(2, b"bokehfit: stopped\n")
    os._exit(130)


def run(args: argparse.Namespace):
    from bokehfit.output_paths import check_output_path
    from bokehfit.surveys import export_parquet, prepare_survey, write_report
    from bokehfit.surveys.run import run_survey
    from bokehfit.surveys.store import SurveyStore

    if not (args.paths or args.files_from or args.report or args.parquet):
        raise InputError("give PATHs (or --files-from) to survey, or --report/--parquet to write from the database")
    if args.scheduler and args.jobs is not None:
        raise InputError("--jobs is for workers on this machine; with --scheduler the cluster's workers run the photos")
    for option, value, suffix in (("--report", args.report, ".html"), ("--parquet", args.parquet, ".parquet")):
        if value:  # refuse a bad output before hours of work, not after
            try:
                check_output_path(value, (suffix,), inputs=[args.db])
            except InputError as error:
                raise InputError(f"{option}: {error}") from None
    if args.scheduler:
        from bokehfit.surveys.scheduler import check_scheduler

        check_scheduler(args.scheduler)  # before any photo is hashed or the database is made
    run_ = None
    if args.paths or args.files_from:
        prepared = prepare_survey(args.paths, files_from=args.files_from, jobs=args.jobs, timeout_s=args.timeout_s,
                                  compare_options=compare_options(args))  # all checked before the database is made
        with SurveyStore(args.db) as store:
            run_ = run_survey(
                store=store, scheduler=args.scheduler, html=not args.no_html, retry_failed=args.retry_failed,
                adapter=args.adapter, command_line=args.command_line, **prepared,
            )
            if run_.interrupted:  # its workers are stopped: another Ctrl-C ends the process at once
                signal.signal(signal.SIGINT, _stop_at_once)
            total = store.count()
        print(run_.summary())
        print(f"{args.db}: {total} photos in all")
        if run_.interrupted:
            raise KeyboardInterrupt
    if args.report:
        print(f"wrote {write_report(args.db, args.report, command_line=args.command_line)}")
    if args.parquet:
        print(f"wrote {export_parquet(args.db, args.parquet)}")
    return run_
