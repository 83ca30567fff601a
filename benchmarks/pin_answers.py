"""The whole-photo answers that a change of the code's structure must leave as they are.

Usage::

    BOKEHFIT_REFERENCE_DIR=path/to/reference_photos python benchmarks/pin_answers.py [--write]

For the photo that ships in ``examples/`` and every reference photo of
``reference_photos/manifest.json`` found (by sha256), ``compare``'s answer read
as :func:`pinned`: the status, the shape and its blades, the features, the
angle (0.1°), the diameter (1 %), the roundness (0.02). Without ``--write`` it
prints where today's answers differ from ``tests/data/answers.json``; with it,
it writes today's (atomically). ``tests/test_answers_pinned.py`` checks them.

A change meant to change answers (a better finder, a better fit) rewrites the
file in the same commit, so that the answers it moved are in the diff.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PINNED = ROOT / "tests" / "data" / "answers.json"
EXAMPLE = ROOT / "examples" / "hexagon_85mm_f2.jpg"
#: How far a pinned number may move and still be the same answer.
TOLERANCE = {"angle_deg": 0.1, "diameter_rel": 0.01, "roundness": 0.02}


def pinned(comparison) -> dict:
    """What a person reads of a comparison: the status, the shape, its features and its numbers."""
    aperture = comparison.to_json("").get("aperture") or {}
    features = sorted(name for name in ("aspect", "squeeze", "vignetting", "rim", "chromatic")
                      if aperture.get(name) is not None)
    return {
        "status": comparison.status,
        "shape": aperture.get("shape"),
        "blades": aperture.get("blades"),
        "features": features,
        "angle_deg": aperture.get("angle_deg"),
        "diameter_px": aperture.get("diameter_px"),
        "roundness": aperture.get("roundness"),
    }


def differences(expected: dict, seen: dict) -> list[str]:
    """Where ``seen`` is not ``expected`` beyond :data:`TOLERANCE` (empty: the same answer)."""
    out = []
    for key in ("status", "shape", "blades", "features"):
        if expected.get(key) != seen.get(key):
            out.append(f"{key} {expected.get(key)} -> {seen.get(key)}")
    for key, limit in (("angle_deg", TOLERANCE["angle_deg"]), ("roundness", TOLERANCE["roundness"])):
        a, b = expected.get(key), seen.get(key)
        if (a is None) != (b is None) or (a is not None and abs(a - b) > limit):
            out.append(f"{key} {a} -> {b}")
    a, b = expected.get("diameter_px"), seen.get("diameter_px")
    if (a is None) != (b is None) or (a is not None and abs(b / a - 1.0) > TOLERANCE["diameter_rel"]):
        out.append(f"diameter_px {a} -> {b}")
    return out


def photos() -> list[tuple[str, Path]]:
    """The example photo and the reference photos present here (by sha256)."""
    sys.path.insert(0, str(ROOT / "tests"))
    from photo_factory import find_reference_photo

    found = [("example/" + EXAMPLE.name, EXAMPLE)]
    manifest = json.loads((ROOT / "reference_photos" / "manifest.json").read_text(encoding="utf-8"))
    for entry in manifest["photos"]:
        path, _ = find_reference_photo(entry["file"])
        if path is not None:
            found.append((entry["file"], path))
    return found


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", action="store_true", help=f"write today's answers to {PINNED.relative_to(ROOT)}")
    args = parser.parse_args(argv)
    from bokehfit.compare import compare_photo

    old = json.loads(PINNED.read_text(encoding="utf-8")) if PINNED.is_file() else {}
    answers, changed = {}, 0
    for name, path in photos():
        answers[name] = pinned(compare_photo(path))
        moved = differences(old[name], answers[name]) if name in old else ["new"]
        changed += bool(moved)
        print(f"{name}: {answers[name]['status']} {answers[name]['shape']} {answers[name]['features']}"
              + (f"  [{'; '.join(moved)}]" if moved else ""), flush=True)
    print(f"{changed} of {len(answers)} answers differ from {PINNED.relative_to(ROOT)}")
    if args.write:
        PINNED.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile("w", dir=PINNED.parent, suffix=".tmp", delete=False, encoding="utf-8") as out:
            json.dump(answers, out, indent=1, sort_keys=True)
            out.write("\n")
        os.replace(out.name, PINNED)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
