"""Keep the thresholds the docs state equal to the code's constants.

A threshold in a page of ``docs/`` (or the README) is written as its number followed, with no
space, by an HTML comment naming the constant it restates; the rendered page shows only the number::

    discs under 64<!-- bokehfit.fit.features.SMALL_DISC_PX --> px
    less than 50<!-- bokehfit.fit.features.FAINT_CONTRAST_REL:% --> % above their background
    at most 2,000<!-- bokehfit.discs.search.MAX_CANDIDATES:, --> candidates
    bodies of 8<!-- bokehfit.view.bodies.MAX_BODY_BYTES:MiB --> MiB at most

The comment holds a dotted name, a module of bokehfit then attributes and items: a constant
(``bokehfit.judging.MIN_SURE_IOU``), a class attribute such as a dataclass field's default
(``bokehfit.fit.result.FitOptions.max_discs``) or an entry (``bokehfit.validate.RANGES[rim].low``,
``bokehfit.view.photo.KERNEL_SAMPLES[0]``: a key of digits is an index). The module is the one
that defines the constant (or the class, or the table): a module that only imports it, such as
a package's ``__init__`` (``bokehfit.discs.MAX_CANDIDATES``), is refused, so that a marker leads
to the line to change and does not outlive the constant's move. It may be followed by
``:`` and a spec: an optional unit (``%`` times 100; ``k``, ``M`` over 10³, 10⁶; ``KiB``,
``MiB``, ``GiB`` over 2¹⁰, 2²⁰, 2³⁰; ``h`` seconds in hours), then an optional Python format
spec (``,`` for thousands separators, ``.2f``, …). Without a format spec an integral value is
written as an integer and any other in Python's shortest form (``0.85``). Code (a fenced block
or a code span) shows a comment as text: a marker there is an example, not checked.

    python docs/check_constants.py --check [FILE ...]   # exit 1 listing every mismatch
    python docs/check_constants.py --write [FILE ...]   # rewrite the numbers from the constants

Without files it reads ``README.md`` and ``docs/*.md`` of the repository holding this script.
Run as a script it reads the constants of this checkout's ``bokehfit/``; the test suite runs the
check (``tests/test_docs_constants.py``) on the ``bokehfit`` it imports, the installed wheel in CI.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import inspect
import math
import os
import re
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Units a spec may start with (longest first), and what the constant is divided by.
UNITS = (("KiB", 2**10), ("MiB", 2**20), ("GiB", 2**30), ("%", 0.01), ("k", 1e3), ("M", 1e6), ("h", 3600))

#: A number directly followed by a marker: ``<number><!-- bokehfit.name[:spec] -->``.
MARKER = re.compile(
    r"(?P<number>[-−]?\d[\d,]*(?:\.\d+)?(?:[eE][-+]?\d+)?)?"
    r"<!--\s*(?P<name>bokehfit(?:\.\w+|\[[\w.-]+\])+)(?::(?P<spec>[^\s>]*))?\s*-->"
)
FENCE = re.compile(r"^\s*(```|~~~)")


class ConstantError(ValueError):
    """A marker names a constant that cannot be read or formatted."""


@dataclass(frozen=True)
class Mismatch:
    path: Path
    line: int
    written: str
    name: str
    expected: str  #: the constant's formatted value, or why there is none

    def __str__(self) -> str:
        return f"{_shown(self.path)}:{self.line}: wrote {self.written or '(nothing)'}, constant {self.name} is {self.expected}"


def _shown(path: Path) -> str:
    try:
        return str(path.resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


def resolve(name: str):
    """The value of a marker's name: the longest importable module prefix, then attributes and
    items (``bokehfit.validate.RANGES[rim].low``: a key of digits is an index, any other a string).
    The first attribute must be one the module defines (:func:`defined_names`), not a re-export."""
    dotted, _, rest = name.partition("[")
    parts = dotted.split(".")
    steps = re.findall(r"\.(\w+)|\[([\w.-]+)\]", "[" + rest if rest else "")
    for cut in range(len(parts) - 1, 0, -1):
        module_name = ".".join(parts[:cut])
        try:
            value = importlib.import_module(module_name)
        except ModuleNotFoundError as error:
            if error.name is not None and module_name.startswith(error.name):
                continue  # not a module: try a shorter prefix
            raise ConstantError(f"{name}: importing {module_name} failed: {error}") from error
        reached = ".".join(parts[:cut])
        if hasattr(value, parts[cut]) and parts[cut] not in defined_names(value):
            home = getattr(getattr(value, parts[cut]), "__module__", None)  # a class's or function's own module
            where = home if isinstance(home, str) and home != reached else "the module that defines it"
            raise ConstantError(f"{name}: {reached} only imports {parts[cut]}: name {where}")
        for attribute, key in [(part, "") for part in parts[cut:]] + steps:
            if attribute:
                if not hasattr(value, attribute):
                    raise ConstantError(f"{name}: {reached} has no attribute {attribute}")
                value = getattr(value, attribute)
                reached += "." + attribute
            else:
                try:
                    value = value[int(key) if key.isdigit() else key]
                except (KeyError, IndexError, TypeError) as error:
                    raise ConstantError(f"{name}: {reached} has no item {key}") from error
                reached += f"[{key}]"
        return value
    raise ConstantError(f"{name}: no module of it can be imported")


def defined_names(module) -> set[str]:
    """The names ``module``'s own source binds at its top level (assignments, classes, functions), not its imports."""
    try:
        tree = ast.parse(inspect.getsource(module))
    except (OSError, TypeError) as error:
        raise ConstantError(f"the source of {module.__name__} cannot be read: {error}") from error
    names: set[str] = set()

    def bind(target: ast.expr) -> None:
        if isinstance(target, ast.Name):
            names.add(target.id)
        elif isinstance(target, (ast.Tuple, ast.List)):
            for element in target.elts:
                bind(element)

    def visit(body: list[ast.stmt]) -> None:
        for node in body:
            if isinstance(node, ast.Assign):
                for target in node.targets:
                    bind(target)
            elif isinstance(node, (ast.AnnAssign, ast.AugAssign)):
                bind(node.target)
            elif isinstance(node, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
                names.add(node.name)
            elif isinstance(node, (ast.If, ast.Try, ast.With)):  # a block of the module's top level
                for block in ("body", "orelse", "finalbody"):
                    visit(getattr(node, block, []))
                for handler in getattr(node, "handlers", []):
                    visit(handler.body)

    visit(tree.body)
    return names


def format_value(value, spec: str = "") -> str:
    """``value`` as the docs write it under ``spec`` (an optional unit, then a Python format spec)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConstantError(f"not a number: {value!r}")
    for unit, size in UNITS:
        if spec.startswith(unit):
            value, spec = value / size, spec[len(unit):]
            break
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ConstantError(f"not a finite number: {value!r}")
        value = float(f"{value:.12g}")  # 0.07 * 100 is 7.000000000000001
        if value.is_integer():
            value = int(value)
    try:
        return format(value, spec) if spec else (str(value) if isinstance(value, int) else repr(value))
    except ValueError as error:
        raise ConstantError(f"bad format spec {spec!r}: {error}") from error


def _code_spans(line: str) -> list[tuple[int, int]]:
    """The [start, end) ranges of a line's inline code spans (backtick runs of equal length)."""
    spans, i = [], 0
    while (start := line.find("`", i)) >= 0:
        ticks = len(line[start:]) - len(line[start:].lstrip("`"))
        end = line.find("`" * ticks, start + ticks)
        if end < 0:
            break
        spans.append((start, end + ticks))
        i = end + ticks
    return spans


def scan(path: Path, write: bool = False) -> tuple[list[Mismatch], int]:
    """Check (and with ``write``, rewrite atomically) the markers of one file.

    Returns the mismatches left (all of them when checking; when writing, only those a rewrite
    cannot fix: an unknown constant, a marker without a number) and the markers seen.
    """
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines(keepends=True)
    problems: list[Mismatch] = []
    markers = 0
    in_fence = False
    for number, line in enumerate(lines, 1):
        if FENCE.match(line):
            in_fence = not in_fence
        if "<!--" not in line:
            continue
        spans = [(0, len(line))] if in_fence else _code_spans(line)

        def replace(match: re.Match) -> str:
            nonlocal markers
            if any(start <= match.start() < end for start, end in spans):
                return match[0]  # code shows the comment: an example of a marker
            markers += 1
            name, spec, written = match["name"], match["spec"] or "", match["number"] or ""
            try:
                expected = format_value(resolve(name), spec)
            except ConstantError as error:
                problems.append(Mismatch(path, number, written, name, f"unknown ({error})"))
                return match[0]
            if not written:
                problems.append(Mismatch(path, number, written, name, expected + " (no number before the marker)"))
                return match[0]
            if written.replace("−", "-") == expected:
                return match[0]
            if not write:
                problems.append(Mismatch(path, number, written, name, expected))
            return expected + match[0][len(written):]

        lines[number - 1] = MARKER.sub(replace, line)
    new = "".join(lines)
    if write and new != text:
        _write_atomically(path, new)
    return problems, markers


def _write_atomically(path: Path, text: str) -> None:
    fd, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as file:
            file.write(text)
        os.chmod(temporary, path.stat().st_mode & 0o7777)
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def default_files(root: Path = ROOT) -> list[Path]:
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


def check(files: list[Path] | None = None, write: bool = False) -> tuple[list[Mismatch], int]:
    """Every mismatch over ``files`` (default: README.md and docs/*.md), and the markers seen."""
    problems, markers = [], 0
    for path in files if files is not None else default_files():
        found, seen = scan(Path(path), write=write)
        problems += found
        markers += seen
    return problems, markers


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--check", action="store_true", help="list every mismatch; exit 1 if any")
    mode.add_argument("--write", action="store_true", help="rewrite the numbers from the constants")
    parser.add_argument("files", nargs="*", type=Path, help="Markdown files (default: README.md, docs/*.md)")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT))  # this checkout's bokehfit, not an installed one
    problems, markers = check(args.files or None, write=args.write)
    for problem in problems:
        print(problem, file=sys.stderr)
    if problems:
        return 1
    print(f"{markers} thresholds {'written from' if args.write else 'agree with'} the code's constants")
    return 0


if __name__ == "__main__":
    sys.exit(main())
