"""The thresholds the docs state are the code's constants, named where they are defined (docs/check_constants.py).

The check reads the constants of the ``bokehfit`` this suite imports: the installed wheel in CI.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

import bokehfit.discs.search
import bokehfit.fit.features
import bokehfit.fit.result
import bokehfit.judging
import bokehfit.validate
import bokehfit.view.photo

REPO = Path(__file__).resolve().parents[1]


def _load_script():
    spec = importlib.util.spec_from_file_location("check_constants", REPO / "docs" / "check_constants.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)  # dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


cc = _load_script()


def test_docs_state_the_code_constants():
    problems, markers = cc.check(cc.default_files(REPO))
    assert not problems, "docs disagree with the code (fix with python docs/check_constants.py --write):\n" + "\n".join(
        map(str, problems))
    assert markers >= 50, f"only {markers} marked thresholds found: were markers lost?"


@pytest.mark.parametrize("value, spec, written", [
    (0.85, "", "0.85"),
    (64.0, "", "64"),
    (3, "", "3"),
    (0.5, "%", "50"),
    (0.07, "%", "7"),
    (0.005, "%", "0.5"),
    (0.125, "%", "12.5"),
    (2000, ",", "2,000"),
    (250_000_000, "M", "250"),
    (8 << 20, "MiB", "8"),
    (3600.0, "h", "1"),
    (0.5, ".2f", "0.50"),
    (-1.0, "", "-1"),
])
def test_format_value(value, spec, written):
    assert cc.format_value(value, spec) == written


@pytest.mark.parametrize("value, spec", [("fast", ""), (True, ""), (float("inf"), ""), (0.5, "q")])
def test_format_value_refuses(value, spec):
    with pytest.raises(cc.ConstantError):
        cc.format_value(value, spec)


def test_resolve_reads_constants_fields_and_entries():
    assert cc.resolve("bokehfit.judging.MIN_SURE_IOU") == bokehfit.judging.MIN_SURE_IOU
    assert cc.resolve("bokehfit.fit.result.FitOptions.max_discs") == bokehfit.fit.result.FitOptions().max_discs
    assert cc.resolve("bokehfit.validate.RANGES[rim].low") == bokehfit.validate.RANGES["rim"].low
    assert cc.resolve("bokehfit.view.photo.KERNEL_SAMPLES[1]") == bokehfit.view.photo.KERNEL_SAMPLES[1]


@pytest.mark.parametrize("name, message", [
    ("bokehfit.compare.NO_SUCH_CONSTANT", "bokehfit.compare has no attribute NO_SUCH_CONSTANT"),
    # A re-export names the wrong line to change: the constant's own module is asked for.
    ("bokehfit.compare.MIN_SURE_IOU", "bokehfit.compare only imports MIN_SURE_IOU: name the module that defines it"),
    ("bokehfit.discs.MAX_CANDIDATES", "bokehfit.discs only imports MAX_CANDIDATES: name the module that defines it"),
    ("bokehfit.fit.FitOptions.max_discs", "bokehfit.fit only imports FitOptions: name bokehfit.fit.result"),
    ("bokehfit.no_such_module.LIMIT", "bokehfit has no attribute no_such_module"),
    ("bokehfit.validate.RANGES[no_such_range].low", "bokehfit.validate.RANGES has no item no_such_range"),
])
def test_missing_constant_is_named(name, message):
    with pytest.raises(cc.ConstantError, match=message.replace("[", r"\[").replace(".", r"\.")):
        cc.resolve(name)


def test_check_lists_every_mismatch_with_its_line(tmp_path):
    page = tmp_path / "page.md"
    page.write_text(
        "# A page\n"
        "sure from 999<!-- bokehfit.judging.MIN_SURE_IOU --> IoU, under 64<!-- bokehfit.fit.features.SMALL_DISC_PX --> px,\n"
        "faint below 7<!-- bokehfit.fit.features.FAINT_CONTRAST_REL:% --> %, at most 2000<!-- bokehfit.discs.search.MAX_CANDIDATES:, -->\n"
        "gone: 1<!-- bokehfit.judging.NO_SUCH_CONSTANT -->; in code `3<!-- bokehfit.fit.MIN_ELONGATED_DISCS -->`\n"
        "```\n5<!-- bokehfit.fit.FEATURE_DELTA_BIC -->\n```\n"
        "<!-- an ordinary comment -->\n",
        encoding="utf-8")
    problems, markers = cc.check([page])
    assert markers == 5  # those in code are examples, shown as text
    lines = [str(p) for p in problems]
    iou = cc.format_value(bokehfit.judging.MIN_SURE_IOU)
    faint = cc.format_value(bokehfit.fit.features.FAINT_CONTRAST_REL, "%")
    candidates = cc.format_value(bokehfit.discs.search.MAX_CANDIDATES, ",")
    assert lines[0] == f"{page}:2: wrote 999, constant bokehfit.judging.MIN_SURE_IOU is {iou}"
    assert lines[1] == f"{page}:3: wrote 7, constant bokehfit.fit.features.FAINT_CONTRAST_REL is {faint}"
    assert lines[2] == f"{page}:3: wrote 2000, constant bokehfit.discs.search.MAX_CANDIDATES is {candidates}"
    assert lines[3].startswith(f"{page}:4: wrote 1, constant bokehfit.judging.NO_SUCH_CONSTANT is unknown (")
    assert len(lines) == 4


def test_write_rewrites_the_numbers_in_place(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "path", list(sys.path))  # main() puts the checkout first
    page = tmp_path / "page.md"
    page.write_text("sure from 999<!-- bokehfit.judging.MIN_SURE_IOU --> IoU; 3 MP of 7<!-- "
                    "bokehfit.fit.features.FAINT_CONTRAST_REL:% --> %\n", encoding="utf-8")
    assert cc.main(["--check", str(page)]) == 1
    assert "wrote 999" in capsys.readouterr().err
    assert cc.main(["--write", str(page)]) == 0
    iou = cc.format_value(bokehfit.judging.MIN_SURE_IOU)
    faint = cc.format_value(bokehfit.fit.features.FAINT_CONTRAST_REL, "%")
    assert page.read_text(encoding="utf-8") == (f"sure from {iou}<!-- bokehfit.judging.MIN_SURE_IOU --> IoU; 3 MP of "
                                                f"{faint}<!-- bokehfit.fit.features.FAINT_CONTRAST_REL:% --> %\n")
    assert cc.main(["--check", str(page)]) == 0
    assert [p.name for p in tmp_path.iterdir()] == ["page.md"]  # no temporary left
