"""The package's import layering (issue 24): no import cycles, and nothing imports upward.

The modules are read with ``ast`` (nothing is imported), from the package the suite runs
against, an installed wheel or the checkout. An import counts where it runs: "at import"
(the module's own body, inside ``if``/``try``/``with`` too, but not ``if TYPE_CHECKING``)
or "deferred" (inside a function or class). The package ``bokehfit`` itself is the public
façade: its deferred imports load the public API on first use and are left out, as they
point at everything (``bokehfit.survey(...)`` runs ``bokehfit.surveys``).

The floors: ``bokehfit.errors`` and ``bokehfit.validate`` are the ground floor and import no
other bokehfit module; only the command line (``bokehfit.cli``, ``python -m bokehfit``)
imports ``argparse`` or ``bokehfit.cli``.
"""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

import pytest

PACKAGE = "bokehfit"
#: The ground floor: imported by every layer, importing no other bokehfit module.
GROUND = {"bokehfit.errors", "bokehfit.validate"}
#: The command line: the only modules (with their submodules) that may import argparse or bokehfit.cli.
COMMAND_LINE = ("bokehfit.cli", "bokehfit.__main__")


def _package_dir() -> Path:
    spec = importlib.util.find_spec(PACKAGE)
    assert spec is not None and spec.submodule_search_locations, "bokehfit is not importable as a package"
    return Path(next(iter(spec.submodule_search_locations)))


def _modules() -> dict[str, Path]:
    """Dotted name → source file, for every module of the package."""
    root = _package_dir()
    modules = {}
    for path in sorted(root.rglob("*.py")):
        parts = (PACKAGE, *path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        modules[".".join(parts)] = path
    return modules


MODULES = _modules()


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _imports(tree: ast.Module):
    """Each import statement of a module with ``True`` when it runs at import, ``False`` when deferred."""
    pending = [(node, True) for node in tree.body]
    while pending:
        node, at_import = pending.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node, at_import
            continue
        if isinstance(node, ast.If) and _is_type_checking(node):
            continue  # annotations only, never run
        inner = at_import and not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Lambda))
        pending.extend((child, inner) for child in ast.iter_child_nodes(node))


def _targets(module: str, node: ast.Import | ast.ImportFrom) -> list[str]:
    """The absolute names an import statement imports (a ``from X import Y`` of a submodule Y names X.Y)."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    base = node.module or ""
    if node.level:
        package = module.split(".") if MODULES[module].name == "__init__.py" else module.split(".")[:-1]
        package = package[: len(package) - (node.level - 1)]
        base = ".".join([*package, *([node.module] if node.module else [])])
    return [f"{base}.{alias.name}" if f"{base}.{alias.name}" in MODULES else base for alias in node.names]


def _owner(name: str) -> str | None:
    """The bokehfit module that ``name`` (a module or a name in one) lives in, or None outside bokehfit."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _graph(*, deferred: bool) -> dict[str, set[str]]:
    """Module → the bokehfit modules it imports (at import; with ``deferred`` also inside functions)."""
    graph = {}
    for module, path in MODULES.items():
        edges = set()
        for node, at_import in _imports(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if not at_import and (not deferred or module == PACKAGE):
                continue
            for target in _targets(module, node):
                owner = _owner(target)
                if owner is not None and owner != module:
                    edges.add(owner)
        graph[module] = edges
    return graph


def _find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle (``[a, b, ..., a]``), or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    for start in sorted(graph):
        if state.get(start):
            continue
        path, stack = [start], [iter(sorted(graph[start]))]
        state[start] = 1
        while stack:
            following = next(stack[-1], None)
            if following is None:
                state[path.pop()] = 2
                stack.pop()
            elif state.get(following) == 1:
                return path[path.index(following):] + [following]
            elif not state.get(following):
                state[following] = 1
                path.append(following)
                stack.append(iter(sorted(graph[following])))
    return None


def _within(name: str, packages) -> bool:
    """``name`` is one of ``packages`` or inside one."""
    return any(name == package or name.startswith(package + ".") for package in packages)


def _all_imports(module: str) -> set[str]:
    """Every name ``module`` imports, at import or deferred, absolute."""
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    return {target for node, _ in _imports(tree) for target in _targets(module, node)}


def test_the_package_is_found_whole():
    assert {PACKAGE, "bokehfit.validate", "bokehfit.errors", "bokehfit.cli", "bokehfit.apertures"} <= set(MODULES)


@pytest.mark.parametrize("deferred", [False, True], ids=["at-import", "with-deferred"])
def test_no_import_cycle(deferred):
    cycle = _find_cycle(_graph(deferred=deferred))
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


@pytest.mark.parametrize("module", sorted(GROUND))
def test_the_ground_floor_imports_no_layer_above(module):
    imported = _all_imports(module)
    assert "argparse" not in imported, f"{module} imports argparse (command-line code belongs in bokehfit.cli)"
    upward = sorted(name for name in imported if _owner(name) is not None and _owner(name) not in GROUND)
    assert not upward, f"{module} imports {', '.join(upward)}: the ground floor imports only {', '.join(sorted(GROUND))}"


def test_only_the_command_line_imports_argparse_or_the_cli():
    found = []
    for module in MODULES:
        if _within(module, COMMAND_LINE):
            continue
        found += [f"{module} imports {name}" for name in sorted(_all_imports(module)) if _within(name, ("argparse", "bokehfit.cli"))]
    assert not found, "\n".join(found)
