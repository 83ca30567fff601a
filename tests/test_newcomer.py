"""A newcomer's first steps (issue 26, point 4): the README says how to run what it installs, shows
``compare_photo`` from Python, needs no tool it does not install;
``help(bokehfit)`` lists the public API."""

from __future__ import annotations

import pydoc
import re
from pathlib import Path

import bokehfit

README = Path(__file__).resolve().parents[1] / "README.md"
#: The public API help(bokehfit) must name, each importable from bokehfit.
PUBLIC = ("compare_photo", "Comparison", "load_photo", "find_discs", "fit_aperture", "make_aperture",
          "compute_kernel", "survey")


def _readme() -> str:
    return README.read_text(encoding="utf-8")


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def test_help_lists_the_public_api():
    text = pydoc.render_doc(bokehfit, renderer=pydoc.plaintext)
    for name in PUBLIC:
        assert name in text, f"help(bokehfit) does not name {name}"
        assert name in bokehfit.__all__ and getattr(bokehfit, name) is not None
    assert bokehfit.compare_photo.__module__ == "bokehfit.compare"


def test_readme_says_how_to_run_the_command_the_quick_start_installs():
    text = _readme()
    quick = text.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    assert ".venv/bin/bokehfit" in quick and "source .venv/bin/activate" in quick
    assert "not on your `PATH`" in quick


def test_readme_shows_compare_photo_and_its_result_from_python():
    blocks = _python_blocks(_readme())
    example = next((block for block in blocks if "compare_photo(" in block), None)
    assert example is not None, "no ```python block calls compare_photo"
    for attribute in (".verdict", ".status", ".fstop", ".to_json("):
        assert attribute in example


def test_readme_needs_no_tool_it_does_not_install():
    for block in re.findall(r"^```sh\n(.*?)^```", _readme(), flags=re.S | re.M):
        for line in block.splitlines():
            assert not re.match(r"\s*duckdb\s", line), f"the duckdb command line is not installed: {line}"
