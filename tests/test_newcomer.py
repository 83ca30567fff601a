"""A newcomer's first steps (issue 26, point 4): the README says how to run what it installs, shows
``compare_photo`` from Python, needs no tool it does not install;
``help(bokehfit)`` lists the public API."""

from __future__ import annotations

import pydoc
import re
from pathlib import Path

import bokehfit

README = Path(__file__).resolve().parents[1] / "README.md"
#: The pages the README links to for everything past the quick start.
DOCS = README.parent / "docs"
#: The most characters README.md may hold (issue 24): past the quick start, text goes to docs/.
README_MAX_CHARS = 10_000
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


def _pages() -> list[Path]:
    return [README, *sorted(DOCS.glob("*.md"))]


def test_readme_and_docs_need_no_tool_they_do_not_install():
    for page in _pages():
        for block in re.findall(r"^```sh\n(.*?)^```", page.read_text(encoding="utf-8"), flags=re.S | re.M):
            for line in block.splitlines():
                assert not re.match(r"\s*duckdb\s", line), f"{page.name}: the duckdb command line is not installed: {line}"


def test_readme_is_a_page_a_person_reads():
    length = len(_readme())
    assert length <= README_MAX_CHARS, (f"README.md holds {length} characters, more than {README_MAX_CHARS}: "
                                        "move the detail to its page in docs/ and link it")


def _anchors(page: Path) -> set[str]:
    """The anchors of a page's headings, as GitHub makes them (lower case, punctuation dropped)."""
    headings = re.findall(r"^#+ (.+)$", page.read_text(encoding="utf-8"), flags=re.M)
    return {re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-") for heading in headings}


def test_readme_and_docs_links_resolve():
    for page in _pages():
        for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text(encoding="utf-8")):
            if re.match(r"[a-z]+://", target):
                continue
            path, _, anchor = target.partition("#")
            linked = page.parent / path if path else page
            assert linked.exists(), f"{page.name} links to {target}, which does not exist"
            if anchor and linked.suffix == ".md":
                assert anchor in _anchors(linked), f"{page.name} links to {target}: no such heading"
