"""``bokehfit bench``: speed against error for kernels, fit and compare; tables, JSON and HTML."""

from __future__ import annotations

import argparse
import sys

from bokehfit.output_paths import check_output_path
from bokehfit.outputs import write_bytes_atomic, write_json
from bokehfit.text_encoding import encode_text

__all__ = ["add_parser", "run"]


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "bench",
        help="measure speed against error: kernel methods, the fit, compare on a 24-MP photo",
        description=(
            "One run that measures, side by side: (a) kernel error (L1 to exact) against render time for "
            "every kernel method from 1e3 to 1e8 samples, with convergence rates; (b) fit error against "
            "fit time on a fixed synthetic set; (c) compare on a 24-MP JPEG, its time by stage."
        ),
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="the CI size: samples 1e3-1e6 at 64 px, a 2-photo fit set, a 4-MP photo, under a minute "
        "(default: the full size, 1e3-1e8 samples and a 24-MP photo)",
    )
    parser.add_argument(
        "--parts",
        default="abc",
        metavar="LETTERS",
        help="run only these parts, e.g. --parts c for compare alone (default abc: all three)",
    )
    parser.add_argument("--json", metavar="OUT.json", help="write every figure as JSON (schema_version 1)")
    parser.add_argument("--html", metavar="OUT.html", help="write the report with its plots as one HTML page")
    parser.set_defaults(run=run)


class _Progress:
    """One progress bar over every step, on stderr when it is a terminal (else nothing)."""

    def __init__(self):
        self.bar = None
        if sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=1, desc="bench", unit="step", leave=False, file=sys.stderr)

    def __call__(self, done: int, total: int, what: str) -> None:
        if self.bar is None:
            return
        self.bar.total = total
        self.bar.n = done
        self.bar.set_description(f"bench: {what}", refresh=False)
        self.bar.refresh()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def run(args: argparse.Namespace) -> dict:
    json_path = check_output_path(args.json, (".json",)) if args.json else None
    html_path = check_output_path(args.html, (".html",)) if args.html else None
    from bokehfit.bench import run_bench
    from bokehfit.bench.report import build_html, format_tables

    progress = _Progress()
    try:
        result = run_bench(args.quick, progress=progress, command_line=args.command_line, adapter=args.adapter,
                           parts=args.parts)
    finally:
        progress.close()
    print(format_tables(result))
    if json_path:
        write_json(json_path, result)
        print(f"wrote {json_path}")
    if html_path:
        write_bytes_atomic(html_path, encode_text(build_html(result)))
        print(f"wrote {html_path}")
    return result
