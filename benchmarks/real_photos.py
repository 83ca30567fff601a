"""What ``bokehfit compare`` answers on the real reference photos and on the independent Cycles renders.

Usage::

    BOKEHFIT_REFERENCE_DIR=path/to/reference_photos python benchmarks/real_photos.py [--json out.json] [--only 04 09] [--no-renders]

Part 1, the reference photos of ``reference_photos/manifest.json`` (found in
``$BOKEHFIT_REFERENCE_DIR`` or in ``reference_photos/``, checked by sha256;
a missing photo is listed as missing). Each runs through ``bokehfit compare``
in a subprocess, as a user would, with its EXIF only. Per photo: the label
(a person's reading from zoomed crops: round discs, the rim's sign where they
show one, cat-eye vignetting, a weak case), the answer and its status, the
discs seen, used (and as what: plateau, saturated outline, ring) and left out
with the reasons. The verdict:

- ``right``: fitted, and the shape is round (a circle, or a rounded polygon
  with roundness ≥ 0.8), the rim positive where the label says so, a cat-eye
  vignetting where the label calls it strong, no slit;
- ``right, unsure`` / ``honest``: unsure with a right answer / unsure with an
  answer the label does not share, or no_fit / no_discs, with the reason given;
- ``WRONG``: fitted, and the answer contradicts the label.

Part 2, the Cycles renders: ``benchmarks/cycles_accuracy.py`` (blade count,
angle, roundness, vignetting and rim against the renders' ground truth).
The script prints figures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from bokehfit.apertures import Aperture
from bokehfit.fit import ROUND_ENOUGH  # blades this round count as round (the bar)

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "reference_photos" / "manifest.json"


def find_photo(entry: dict) -> Path | None:
    folders = [Path(os.environ["BOKEHFIT_REFERENCE_DIR"])] if os.environ.get("BOKEHFIT_REFERENCE_DIR") else []
    folders.append(ROOT / "reference_photos")
    for folder in folders:
        path = folder / entry["file"]
        if path.is_file() and hashlib.sha256(path.read_bytes()).hexdigest() == entry["sha256"]:
            return path
    return None


def run_compare(path: Path, out: Path) -> dict:
    command = [sys.executable, "-m", "bokehfit", "compare", str(path), "--json", str(out), "--no-html"]
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if not out.exists():
        return {"status": f"error (exit {done.returncode})", "reason": done.stderr.strip()[-300:], "seconds": seconds}
    result = json.loads(out.read_text(encoding="utf-8"))
    result["seconds"] = seconds
    return result


def answer(aperture: dict) -> str:
    """The answer in a few words (from the JSON only)."""
    if not aperture or aperture.get("shape") is None:
        return "none"
    words = [Aperture.from_json(aperture).label]
    if aperture.get("aspect") is not None:
        words.append(f"aspect {aperture['aspect']:.2f}")
    if aperture.get("roundness"):
        words.append(f"roundness {aperture['roundness']:.2f}")
    if aperture.get("rim"):
        words.append(f"rim {aperture['rim']:+.2f}")
    if aperture.get("vignetting"):
        words.append("vignetting {radius:.2f}/{shift:+.2f}".format(**aperture["vignetting"]))
    return " ".join(words)


def agrees(label: dict, aperture: dict) -> tuple[bool, str]:
    """Whether the answer shares the label, and what it gets wrong."""
    wrong = []
    is_round = aperture.get("symmetry_deg") is None and aperture.get("aspect") is None
    if label["round"] and not is_round and (aperture.get("roundness") or 0.0) < ROUND_ENOUGH:
        wrong.append("not round")
    if aperture.get("aspect") is not None:
        wrong.append("an elongated aperture")
    if label.get("rim") == "positive" and not (aperture.get("rim") or 0.0) > 0.0:
        wrong.append("no bright rim")
    if label.get("vignetting") == "strong" and not aperture.get("vignetting"):
        wrong.append("no cat-eye vignetting")  # a mild one may hide in the discs' scatter; a strong one does not
    return not wrong, ", ".join(wrong)


def judge(label: dict, result: dict) -> str:
    status = result.get("status")
    if status == "fitted":
        right, why = agrees(label, result["aperture"])
        return "right" if right else f"WRONG ({why})"
    if status == "unsure":
        right, why = agrees(label, result["aperture"])
        return "right, unsure" if right else f"honest: unsure ({why})"
    if status in ("no_fit", "no_discs"):
        return f"honest: {status}"
    return str(status)


def photos(only: list[str] | None, json_rows: list) -> None:
    manifest = json.loads(MANIFEST.read_text(encoding="utf-8"))
    verdicts = Counter()
    with tempfile.TemporaryDirectory() as tmp:
        for entry in manifest["photos"]:
            if only and not any(entry["file"].startswith(o) for o in only):
                continue
            label = entry["label"]
            path = find_photo(entry)
            if path is None:
                print(f"{entry['file']}: missing (set BOKEHFIT_REFERENCE_DIR)")
                continue
            result = run_compare(path, Path(tmp) / f"{Path(entry['file']).stem}.json")
            discs = result.get("discs", [])
            used = [d for d in discs if d.get("used")]
            # "outline (saturated: 12 clipped pixels ...)" and the like, counted by their kind
            as_what = Counter((d.get("used_as") or "").split(" (")[0] for d in used)
            left_out = Counter(reason for d in discs if not d.get("used") for reason in d.get("rejected_because", []))
            verdict = judge(label, result)
            verdicts[verdict.split(" (")[0]] += 1
            wanted = ["round"] + ([f"rim {label['rim']}"] if label.get("rim") else []) \
                + ([f"vignetting {label['vignetting']}"] if label.get("vignetting") else []) + (["weak"] if label.get("weak") else [])
            print(f"\n{entry['file']}  [{result['seconds']:.1f} s]")
            print(f"  label:   {', '.join(wanted)}")
            print(f"  answer:  {answer(result.get('aperture'))}  status {result.get('status')}  -> {verdict}")
            if result.get("reason"):
                print(f"  reason:  {result['reason']}")
            print(f"  discs:   {len(discs)} seen, {len(used)} used "
                  f"({', '.join(f'{n} {what}' for what, n in as_what.most_common()) or 'none'}), "
                  f"{len(discs) - len(used)} not used")
            for reason, n in left_out.most_common(6):
                print(f"           {n} × {reason}")
            json_rows.append({"file": entry["file"], "label": label, "answer": answer(result.get("aperture")),
                              "status": result.get("status"), "verdict": verdict, "reason": result.get("reason"),
                              "discs_seen": len(discs), "discs_used": len(used), "used_as": dict(as_what),
                              "left_out": dict(left_out), "seconds": round(result["seconds"], 1)})
    print("\nverdicts: " + ", ".join(f"{n} {v}" for v, n in verdicts.most_common()))
    print("target: no WRONG (a fitted answer is never wrong)")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", help="write the photo rows as JSON")
    parser.add_argument("--only", nargs="*", help="only photos whose names start so (e.g. 04 09)")
    parser.add_argument("--no-renders", action="store_true", help="skip part 2 (the Cycles renders)")
    args = parser.parse_args(argv)
    rows: list = []
    print("Part 1: reference photos")
    photos(args.only, rows)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    if not args.no_renders:
        print("\nPart 2: independent Cycles renders (benchmarks/cycles_accuracy.py)")
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        import cycles_accuracy

        cycles_accuracy.main([])
    return 0


if __name__ == "__main__":
    sys.exit(main())
