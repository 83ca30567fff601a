"""The whole-photo answers are pinned (``tests/data/answers.json``, written by
``benchmarks/pin_answers.py --write``): a change of the code's structure leaves every one as it is,
and a change meant to move answers rewrites the file in the same commit, so that the answers it
moved are in the diff (issue: behaviour unchanged, checked by a test).

The reference photos' comparisons are the session's (the ``compared`` fixture the other reference
tests share), so pinning them costs no compare of its own.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("pin_answers", ROOT / "benchmarks" / "pin_answers.py")
pin = importlib.util.module_from_spec(spec)
spec.loader.exec_module(pin)
PINNED = json.loads(pin.PINNED.read_text(encoding="utf-8"))
MANIFEST = json.loads((ROOT / "reference_photos" / "manifest.json").read_text(encoding="utf-8"))


def test_every_reference_photo_and_the_example_is_pinned():
    names = {"example/" + pin.EXAMPLE.name} | {entry["file"] for entry in MANIFEST["photos"]}
    assert set(PINNED) == names


@pytest.mark.parametrize("name", [entry["file"] for entry in MANIFEST["photos"]])
def test_the_reference_photos_answer_is_the_pinned_one(compared, name):
    assert not pin.differences(PINNED[name], pin.pinned(compared(name))), pin.pinned(compared(name))


def test_the_example_photos_answer_is_the_pinned_one(gpu):
    from bokehfit.compare import compare_photo

    name = "example/" + pin.EXAMPLE.name
    seen = pin.pinned(compare_photo(pin.EXAMPLE))
    assert not pin.differences(PINNED[name], seen), seen


@pytest.mark.parametrize("change, moved", [({"angle_deg": 15.05}, False), ({"angle_deg": 15.2}, True),
                                           ({"diameter_px": 55.5}, False), ({"diameter_px": 57.0}, True),
                                           ({"features": ["rim"]}, True), ({"status": "unsure"}, True)])
def test_a_moved_answer_is_told_from_the_same_one(change, moved):
    base = {"status": "fitted", "shape": "hexagon", "blades": 6, "features": [], "angle_deg": 15.0,
            "diameter_px": 55.07, "roundness": 0.0}
    assert bool(pin.differences(base, {**base, **change})) == moved
