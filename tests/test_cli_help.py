"""``--help``: every option of the command line says what it does, and its default where it has one.

The check walks the parser that ``bokehfit`` runs (:func:`bokehfit.cli.build_parser`):
the top-level parser and every subcommand in :data:`bokehfit.cli.SUBCOMMANDS`.
"""

from __future__ import annotations

import argparse

import pytest

from bokehfit.cli import SUBCOMMANDS, build_parser

#: Every subcommand is held to the rule (its name is its module's last part).
CHECKED_SUBCOMMANDS = tuple(module.__name__.rsplit(".", 1)[-1] for module in SUBCOMMANDS)


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def help_problems(parser: argparse.ArgumentParser) -> list[str]:
    """One line per option of ``parser`` without help text, or with a default its help does not state."""
    problems = []
    for action in parser._actions:
        name = "/".join(action.option_strings) or action.dest
        text = action.help
        if not text or text == argparse.SUPPRESS or not str(text).strip():
            problems.append(f"{parser.prog} {name}: no help text")
            continue
        # Flags (store_true, version, help) have no value to default; others state a real default.
        takes_value = action.nargs != 0
        has_default = action.default is not None and action.default is not argparse.SUPPRESS
        if takes_value and has_default and "default" not in parser._get_formatter()._expand_help(action):
            problems.append(f"{parser.prog} {name}: help does not state the default {action.default!r}")
    return problems


def test_top_level_options_have_help():
    assert help_problems(build_parser()) == []


@pytest.mark.parametrize("command", CHECKED_SUBCOMMANDS)
def test_subcommand_options_have_help_and_defaults(command):
    subcommand = _subparsers(build_parser())[command]
    assert help_problems(subcommand) == []


def test_help_formats_with_defaults():
    # %(default)s and friends must expand without errors.
    parser = build_parser()
    assert "bench" in parser.format_help()
    for command in CHECKED_SUBCOMMANDS:
        text = _subparsers(parser)[command].format_help()
        assert "usage:" in text
