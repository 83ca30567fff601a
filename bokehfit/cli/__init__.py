"""The ``bokehfit`` command: ``main(argv)`` does the work, ``entry_point`` maps errors to exit codes.

Exit codes: 0 success, 1 no acceptable result, 2 usage or input error, 3 an
internal error (a bug: the message asks for a report; ``BOKEHFIT_DEBUG=1``
shows the traceback). Every
subcommand is a module of this package with ``add_parser(subparsers)`` and
``run(args) -> result``; adding one is one entry in ``SUBCOMMANDS``.

:func:`main` gives every subcommand, besides its options, ``args.command_line``
(the argv it was given, shell-quoted, for the JSON reports) and
``args.adapter``, the :class:`~bokehfit.gpu.AdapterChoice` made from the
environment variables ``BOKEHFIT_ADAPTER`` and ``BOKEHFIT_BACKEND``. This is
the only place that reads them; the library takes the choice as an argument.
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import warnings
from collections.abc import Mapping, Sequence

from bokehfit import __version__
from bokehfit.cli import bench, compare, discs, kernel, render, similarity, survey, view
from bokehfit.cli.console import reader_may_leave
from bokehfit.errors import BokehfitError, InputError
from bokehfit.gpu import BACKENDS, AdapterChoice
from bokehfit.threads import one_thread

__all__ = ["main", "entry_point", "build_parser", "adapter_from_environment", "ADAPTER_ENV", "BACKEND_ENV"]

#: Environment variables that choose the WebGPU adapter: a case-insensitive
#: part of its name (e.g. ``llvmpipe``) and a backend (``vulkan``, ``metal``,
#: ``d3d12`` or ``gl``); see :class:`bokehfit.gpu.AdapterChoice`.
ADAPTER_ENV = "BOKEHFIT_ADAPTER"
BACKEND_ENV = "BOKEHFIT_BACKEND"

SUBCOMMANDS = (bench, compare, discs, kernel, render, similarity, survey, view)


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
    subparsers = parser.add_subparsers(
        dest="command",
        required=True,
        metavar="COMMAND",
        parser_class=_Parser,
        help="what to do; `bokehfit COMMAND --help` lists its options",
    )
    for module in SUBCOMMANDS:
        module.add_parser(subparsers)
    return parser


def adapter_from_environment(environ: Mapping[str, str] | None = None) -> AdapterChoice:
    """The adapter choice that ``BOKEHFIT_ADAPTER`` and ``BOKEHFIT_BACKEND`` ask for.

    Parameters
    ----------
    environ : mapping, optional
        The environment to read; ``os.environ`` by default. Unset or empty
        variables leave the choice to :func:`bokehfit.gpu.get_gpu`.

    Raises
    ------
    InputError
        Naming ``BOKEHFIT_BACKEND`` when it is not one of ``bokehfit.gpu.BACKENDS``.
    """
    environ = os.environ if environ is None else environ
    name, backend = environ.get(ADAPTER_ENV, ""), environ.get(BACKEND_ENV, "")
    if backend.strip() and backend.strip().lower() not in BACKENDS:
        raise InputError(f"{BACKEND_ENV} must be one of {', '.join(BACKENDS)} or unset (got {backend!r})")
    return AdapterChoice(name, backend)


def main(argv: Sequence[str] | None = None, environ: Mapping[str, str] | None = None):
    """Parse ``argv`` and run the subcommand; returns its result, raises on errors.

    Parameters
    ----------
    argv : sequence of str, optional
        The arguments after the program name; ``sys.argv[1:]`` by default.
        Reports record exactly these as their ``command_line``.
    environ : mapping, optional
        Where the adapter choice is read (:func:`adapter_from_environment`);
        ``os.environ`` by default.
    """
    argv = sys.argv[1:] if argv is None else [str(word) for word in argv]
    args = build_parser().parse_args(argv)
    args.command_line = shlex.join(["bokehfit", *argv])
    args.adapter = adapter_from_environment(environ)
    return args.run(args)


def _show_warning_one_line(message, category, filename, lineno, file=None, line=None):
    """``warnings.showwarning`` for the console: ``bokehfit: warning: <message>`` on stderr."""
    print(f"bokehfit: warning: {message}", file=sys.stderr)


def entry_point() -> None:
    """Console entry point: one-line messages and exit codes, never a traceback.

    Warnings are printed as one line while the command runs; the process's
    warning handler and filters are restored afterwards (also on exit). BLAS and
    OpenMP run on one thread meanwhile, unless the environment sizes them
    (:func:`bokehfit.threads.one_thread`). A reader that closes stdout early
    (``| head -1``) does not stop the run: the rest of what it prints goes to
    the null device and its files are still written
    (:func:`bokehfit.cli.console.reader_may_leave`).
    """
    _unencodable_text_escaped()
    with warnings.catch_warnings(), one_thread(), reader_may_leave():
        warnings.showwarning = _show_warning_one_line
        _run_with_exit_codes()


def _unencodable_text_escaped() -> None:
    """stdout and stderr write what their encoding can't hold as backslash escapes instead of failing.

    A file name that is not valid UTF-8 (lone surrogates in Python) or a "×" on an ASCII
    terminal would otherwise end a finished run with an encoding error while it prints.
    """
    for stream in (sys.stdout, sys.stderr):
        if hasattr(stream, "reconfigure") and getattr(stream, "errors", None) == "strict":
            try:
                stream.reconfigure(errors="backslashreplace")
            except (ValueError, OSError):
                pass


def _run_with_exit_codes() -> None:
    """Run :func:`main` on ``sys.argv``, mapping errors to one line on stderr and an exit code."""
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
