"""Rooms of one job (issue 24): no file of the package or its shaders over MAX_FILE_LINES lines, and no
function over MAX_FUNCTION_LINES lines in the fit, the disc search and ``compare``'s pipeline.

Read from the checkout (the shaders are not part of the wheel), with ``ast`` for the functions: a
function's lines run from its first decorator to its last line, docstring included.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MAX_FILE_LINES = 600
MAX_FUNCTION_LINES = 80
#: The rooms whose functions are held to MAX_FUNCTION_LINES.
FUNCTION_ROOMS = ("bokehfit/fit", "bokehfit/discs", "bokehfit/compare.py")
#: The files held to MAX_FILE_LINES: the package's code and pages, and the shaders.
FILE_PATTERNS = ("bokehfit/**/*.py", "bokehfit/**/*.js", "bokehfit/**/*.html", "shaders/*.wgsl")


def _files() -> list[Path]:
    return sorted({path for pattern in FILE_PATTERNS for path in ROOT.glob(pattern)})


def _room_sources() -> list[Path]:
    found = []
    for room in FUNCTION_ROOMS:
        path = ROOT / room
        found += sorted(path.rglob("*.py")) if path.is_dir() else [path]
    return found


def long_functions(source: str, limit: int) -> list[tuple[str, int]]:
    """(name, lines) of the functions and methods in ``source`` longer than ``limit`` lines."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            start = min([node.lineno] + [d.lineno for d in node.decorator_list])
            lines = node.end_lineno - start + 1
            if lines > limit:
                found.append((node.name, lines))
    return found


def test_the_rooms_are_found():
    assert len(_files()) > 100 and all(p.is_file() for p in _room_sources())


def test_no_file_of_the_package_or_its_shaders_is_over_600_lines():
    long = [f"{p.relative_to(ROOT)}: {n} lines" for p in _files()
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_FILE_LINES]
    assert not long, "split these into modules of one job:\n" + "\n".join(long)


def test_no_function_of_the_fit_the_disc_search_or_compare_is_over_80_lines():
    long = [f"{p.relative_to(ROOT)}: {name}, {n} lines" for p in _room_sources()
            for name, n in long_functions(p.read_text(encoding="utf-8"), MAX_FUNCTION_LINES)]
    assert not long, "split these into named steps:\n" + "\n".join(long)


@pytest.mark.parametrize(
    "source, expected",
    [
        ("def f():\n" + "    x = 1\n" * 80, [("f", 81)]),
        ("def f():\n" + "    x = 1\n" * 79, []),
        ("@decorator\ndef f():\n" + "    x = 1\n" * 79, [("f", 81)]),  # the decorator counts
        ("class A:\n    def m(self):\n" + "        x = 1\n" * 80, [("m", 81)]),  # methods too
    ],
)
def test_the_function_count(source, expected):
    assert long_functions(source, MAX_FUNCTION_LINES) == expected
