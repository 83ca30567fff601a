"""The ``bokehfit`` command: ``main(argv)`` does the work, ``entry_point`` maps errors to exit codes.

Exit codes: 0 success, 1 no acceptable result, 2 usage or input error, 3 an
internal error (a bug: the message asks for a report; ``BOKEHFIT_DEBUG=1``
shows the traceback). Every
subcommand is a module of this package with ``add_parser(subparsers)`` and
``run(args) -> result``; adding one is one entry in ``SUBCOMMANDS``.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings

from bokehfit import __version__
from bokehfit.cli import bench, compare, discs, kernel, render, similarity, view
from bokehfit.errors import BokehfitError

__all__ = ["main", "entry_point", "build_parser"]

SUBCOMMANDS = (bench, compare, discs, kernel, render, similarity, view)


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (exit code 2)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="bokehfit",
        description="Find bokeh discs in photos, fit the aperture that made them, render its defocus kernel.",
    )
    parser.add_argument("--version", action="version", version=f"bokehfit {__version__}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)
    for module in SUBCOMMANDS:
        module.add_parser(subparsers)
    return parser


def main(argv: list[str] | None = None):
    """Parse ``argv`` and run the subcommand; returns its result, raises on errors."""
    args = build_parser().parse_args(argv)
    return args.run(args)


def entry_point() -> None:
    """Console entry point: one-line messages and exit codes, never a traceback."""
    def show_warning(message, category, filename, lineno, file=None, line=None):
        print(f"bokehfit: warning: {message}", file=sys.stderr)

    warnings.showwarning = show_warning
    try:
        main()
    except BokehfitError as error:
        print(f"bokehfit: error: {error}", file=sys.stderr)
        sys.exit(error.exit_code)
    except KeyboardInterrupt:
        print("bokehfit: interrupted", file=sys.stderr)
        sys.exit(130)
    except OSError as error:
        print(f"bokehfit: error: {error.strerror or error} ({error.filename or 'I/O'})", file=sys.stderr)
        sys.exit(2)
    except Exception as error:  # a bug: one line for people, the traceback on request
        if os.environ.get("BOKEHFIT_DEBUG"):
            raise
        print(
            f"bokehfit: internal error: {type(error).__name__}: {error} "
            "(please report it; BOKEHFIT_DEBUG=1 shows the traceback)",
            file=sys.stderr,
        )
        sys.exit(3)
