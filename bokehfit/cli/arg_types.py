"""argparse ``type=`` functions for the command line: the checks of :mod:`bokehfit.validate`, argparse's way.

Each option of a quantity in ``bokehfit.validate.RANGES`` is parsed and checked by
:func:`~bokehfit.validate.check` under the option's name, so the command line and the
Python API accept the same values; a refusal is an ``argparse.ArgumentTypeError``,
which argparse prints as one line naming the option (``argument --spp: must be an
integer in [1, 65536] (got 0)``) before it exits with code 2.

They live here, not in :mod:`bokehfit.validate`, so that the library's ground floor
imports neither argparse nor the modules above it (``tests/test_layering.py``).
"""

from __future__ import annotations

import argparse

from bokehfit.apertures import parse_shape
from bokehfit.errors import InputError
from bokehfit.validate import RANGES, check

__all__ = ["arg_type", "cli_value", "interval", "pair_arg", "shape_arg"]


def cli_value(quantity: str, text: str, option: str):
    """Parse one command-line value and :func:`check` it under the option's name."""
    rule = RANGES[quantity]
    stripped = text.strip()
    try:
        value = int(stripped, 10) if rule.integer else float(stripped)
    except ValueError:
        raise InputError(f"{option} must be {rule.describe()} (got {text!r})") from None
    return check(quantity, value, name=option)


def arg_type(quantity: str, option: str):
    """An argparse ``type=`` for ``option``: the same check as the Python API.

    The error is an ``argparse.ArgumentTypeError``, so argparse prints it
    (``argument --spp: must be an integer in [1, 65536] (got 0)``) and exits
    with code 2, instead of its generic ``invalid value``.
    """

    def parse(text: str):
        try:
            return cli_value(quantity, text, option)
        except InputError as error:
            # argparse names the option itself ("argument --spp: ...").
            raise argparse.ArgumentTypeError(str(error).removeprefix(f"{option} ")) from None

    parse.__name__ = option.lstrip("-").replace("-", "_")
    return parse


def shape_arg(option: str):
    """An argparse ``type=`` for a shape option: ``bokehfit.apertures.parse_shape`` checks the text.

    The text is returned as given (``make_aperture`` reads it with the same parser).
    """

    def parse(text: str) -> str:
        try:
            parse_shape(text)
        except InputError as error:
            raise argparse.ArgumentTypeError(str(error).removeprefix("shape ")) from None
        return text

    parse.__name__ = option.lstrip("-").replace("-", "_")
    return parse


def interval(quantity: str) -> str:
    """The accepted interval of ``quantity`` for a help text, e.g. ``[1, 65536]``."""
    return RANGES[quantity].describe().split(" in ", 1)[1]


def pair_arg(option: str, quantities: tuple[str, str], metavar: str):
    """An argparse ``type=`` for ``option``: two comma-separated numbers, each checked against ``RANGES``.

    ``--vignetting 1.2,0.8`` → (1.2, 0.8); the error names the option and the
    expected form (``argument --vignetting: must be RADIUS,SHIFT ...``).
    """

    def parse(text: str) -> tuple[float, float]:
        parts = text.split(",")
        if len(parts) != 2:
            raise argparse.ArgumentTypeError(f"must be {metavar}, two numbers separated by a comma (got {text!r})")
        try:
            return tuple(cli_value(quantity, part, option) for quantity, part in zip(quantities, parts))
        except InputError as error:
            raise argparse.ArgumentTypeError(str(error).removeprefix(f"{option} ")) from None

    parse.__name__ = option.lstrip("-").replace("-", "_")
    return parse
