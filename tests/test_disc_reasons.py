"""Why there is no disc is a :class:`~bokehfit.discs.reasons.Reason`, not a string compared by its words (issue 24).

A measurement answers ``Measurement | NoDisc``; the disc search branches on ``isinstance(m, NoDisc)``
and compares members. The words leave the package unchanged: ``rejected_because``, the counts by
reason and the JSON are the same plain text as before there were members. The package's files are
read from the installed package (``bokehfit.__file__``); the allow-list names, file by file, what is
left, each with its reason, so that it can only shrink.
"""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import numpy as np
import pytest

import bokehfit
from bokehfit.discs import Rejection, measure_discs_at
from bokehfit.discs.reasons import NoDisc, Reason

PACKAGE = Path(bokehfit.__file__).resolve().parent
DISCS = PACKAGE / "discs"
REPO = Path(__file__).resolve().parents[1]
#: Every reason's words.
WORDS = frozenset(reason.value for reason in Reason)
#: (file relative to bokehfit/discs, the offending line's text matches this, why it is still there).
ALLOWED: tuple[tuple[str, str, str], ...] = (
    ("labels.py", r"^DISC_KINDS = ", "a person's label of a disc (a faint disc), not a reason there is none"),
    ("labels.py", r"isinstance\(.*, str\)", "a person's labels file read: its JSON's text fields checked"),
)


def _is_words(node: ast.AST) -> bool:
    """A string constant that is a reason's words."""
    return isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in WORDS


def _docstrings(tree: ast.AST) -> set[int]:
    """ids of the constants that are docstrings (a module's, a class's, a function's)."""
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                ids.add(id(first.value))
    return ids


def _unions_str_with_measurement(annotation: ast.AST | None) -> bool:
    """An annotation such as ``Measurement | str``: a reason passed as its words."""
    if annotation is None:
        return False
    names = {n.id for n in ast.walk(annotation) if isinstance(n, ast.Name)}
    text = {n.value for n in ast.walk(annotation) if isinstance(n, ast.Constant) and isinstance(n.value, str)}
    return ("Measurement" in names or any("Measurement" in t for t in text)) and (
        "str" in names or any(re.search(r"\bstr\b", t) for t in text)
    )


def reason_words(source: str) -> list[int]:
    """Line numbers where ``source`` writes a reason as its words, or passes one as a string.

    A string constant equal to a reason's words anywhere but a docstring: compared (``m == "faint"``,
    ``in ("faint", ...)``, ``case "faint":``), returned, assigned, a key (``rejected["..."]``) or an
    argument; a measurement told from a reason by ``isinstance(m, str)``; an annotation
    ``Measurement | str``. Words inside a longer string (an f-string's sentence, a message) are not
    a reason's and are left alone.
    """
    tree = ast.parse(source)
    docstrings = _docstrings(tree)
    lines = set()
    for node in ast.walk(tree):
        if _is_words(node) and id(node) not in docstrings:
            lines.add(node.lineno)
        elif isinstance(node, ast.MatchValue) and _is_words(node.value):
            lines.add(node.lineno)
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "isinstance" \
                and len(node.args) == 2 and isinstance(node.args[1], ast.Name) and node.args[1].id == "str":
            lines.add(node.lineno)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            annotations = [node.returns] + [a.annotation for a in (*node.args.args, *node.args.kwonlyargs)]
            if any(_unions_str_with_measurement(a) for a in annotations):
                lines.add(node.lineno)
    return sorted(lines)


@pytest.mark.parametrize(
    "source",
    [
        'if found == "faint":\n    pass\n',
        'if found in ("faint", "no outline") and hollow:\n    pass\n',
        'ok = "soft edge" != m.reason\n',
        'def f():\n    return "no outline"\n',
        'reason = "too small"\n',
        'RAYS_AFTER = ("faint",)\n',
        'rejected["beyond the candidate limit"] += 1\n',
        'r = Rejection(xy, d, "not a cluster")\n',
        'm = replace(m, reason="elongated")\n',
        'match why:\n    case "line-like":\n        pass\n',
        'if isinstance(m, str):\n    pass\n',
        'def f(x) -> Measurement | str:\n    pass\n',
        'def f(x) -> "Measurement | str":\n    pass\n',
        'def f(m: Measurement | str, xy):\n    pass\n',
    ],
)
def test_the_scan_finds_a_reason_written_as_its_words(source):
    assert reason_words(source), source


@pytest.mark.parametrize(
    "source",
    [
        '"""A candidate is "faint" when its plateau ..."""\n',
        'def f():\n    """Returns "no outline" no more."""\n    return NoDisc(Reason.NO_OUTLINE)\n',
        'if m.reason in (Reason.FAINT, Reason.NO_OUTLINE):\n    pass\n',
        'reason = Reason.TOO_SMALL\n',
        'if isinstance(m, NoDisc):\n    pass\n',
        'note = f"the outline measured there ({d:.0f} px) is not a disc of about {e:.0f} px"\n',
        'label = "a faint disc"\n',
        'x = "faintly"  # "faint" in a comment\n',
        'def f(x) -> Measurement | NoDisc:\n    pass\n',
        'def f(x) -> str | None:\n    pass\n',
    ],
)
def test_the_scan_leaves_members_and_prose_alone(source):
    assert not reason_words(source), source


def _allowed(path: Path, line: str) -> bool:
    return any(path.name == name and re.search(pattern, line.strip()) for name, pattern, _ in ALLOWED)


def test_no_reason_is_written_as_its_words_in_the_disc_search():
    """Only :mod:`bokehfit.discs.reasons` holds the words; the rest of the package names members."""
    offences = []
    for path in sorted(DISCS.glob("*.py")):
        if path.name == "reasons.py":
            continue
        source = path.read_text(encoding="utf-8")
        text = source.splitlines()
        offences += [f"discs/{path.name}:{n}: {text[n - 1].strip()}"
                     for n in reason_words(source) if not _allowed(path, text[n - 1])]
    assert not offences, "compare Reason members and return NoDisc, not words:\n" + "\n".join(offences)


def test_the_allow_list_has_nothing_stale():
    for name, pattern, _ in ALLOWED:
        path = DISCS / name
        source = path.read_text(encoding="utf-8")
        text = source.splitlines()
        assert any(re.search(pattern, text[n - 1].strip()) for n in reason_words(source)), (name, pattern)


def _listed(module: str) -> set[str]:
    """The reasons a module's Notes list: the ````words```` that open a line of its docstring."""
    doc = ast.get_docstring(ast.parse((DISCS / module).read_text(encoding="utf-8"))) or ""
    return set(re.findall(r"^``([^`]+)``\s", doc, flags=re.MULTILINE))


def _named(module: str) -> set[str]:
    """The words of the reasons a module's code names (``Reason.FAINT``)."""
    tree = ast.parse((DISCS / module).read_text(encoding="utf-8"))
    return {Reason[n.attr].value for n in ast.walk(tree)
            if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) and n.value.id == "Reason"}


@pytest.mark.parametrize("module", ["verdict.py", "outlines.py"])
def test_the_notes_list_the_reasons_their_module_gives(module):
    listed, named = _listed(module), _named(module)
    assert listed <= WORDS, f"{module}'s Notes list reasons that are not Reason members: {listed - WORDS}"
    assert named <= listed, f"{module} gives reasons its Notes do not list: {named - listed}"


def test_every_reason_is_in_the_docs():
    page = (REPO / "docs" / "discs.md").read_text(encoding="utf-8")
    missing = [reason.value for reason in Reason if f"`{reason.value}`" not in page]
    assert not missing, f"docs/discs.md does not list these reasons: {missing}"


def test_a_reason_reads_as_its_words():
    assert str(Reason.SOFT_EDGE) == f"{Reason.SOFT_EDGE}" == "%s" % Reason.SOFT_EDGE == "soft edge"
    assert f"{Reason.FAINT:>7}" == "  faint"
    assert json.dumps({Reason.FAINT: [Reason.NO_OUTLINE]}) == '{"faint": ["no outline"]}'
    assert Reason("too small") is Reason.TOO_SMALL


def test_no_disc_is_falsy_and_reads_as_its_detail_or_reason():
    assert not NoDisc(Reason.FAINT) and str(NoDisc(Reason.FAINT)) == "faint"
    detail = "the outline measured there (41 px at 120, 88) is not a disc of about 98 px"
    assert str(NoDisc(Reason.NOT_THE_DISC_ASKED, detail)) == detail


def test_a_rejection_holds_plain_words():
    """What leaves the package is the text it always was: a plain ``str``, in the record and the JSON."""
    rejection = Rejection.of((1.0, 2.0), 3.0, NoDisc(Reason.FAINT))
    assert type(rejection.rejected_because) is str and rejection.rejected_because == "faint"
    assert Rejection.of((1.0, 2.0), 3.0, Reason.NOT_A_CLUSTER).to_json()["rejected_because"] == "not a cluster"


def test_a_place_with_no_disc_is_rejected_in_words():
    image = np.full((80, 80), 0.05, np.float32)
    search = measure_discs_at(image, None, [((-5.0, 10.0), 20.0), ((40.0, 40.0), 20.0)])
    assert not search.discs
    reasons = [r.rejected_because for r in search.rejections]
    assert reasons[0] == "outside the photo" and all(type(r) is str for r in reasons), reasons
    assert all(type(key) is str for key in search.rejected), search.rejected
    assert sum(search.rejected.values()) == 2 and search.rejected["outside the photo"] == 1
