"""How long ``compare`` takes on each reference photo, against a clean 24-megapixel photo, by stage and fit step.

Usage::

    BOKEHFIT_REFERENCE_DIR=path/to/reference_photos python benchmarks/real_speed.py [--json out.json] [--only 05 14]
        [--coverages]

In one process: a warm-up call on the small synthetic photo (``bokehfit.bench.compare.WARMUP``),
then the clean synthetic 24-MP photo of ``bokehfit bench`` (``BIG``: 50 pentagons on a dark
gradient, made once and cached), then every reference photo of ``reference_photos/manifest.json``
(with its EXIF only, as ``bokehfit compare PHOTO`` runs it), then the 24-MP photo again. Each
call is timed by wall clock (``time.perf_counter``) and by the process's CPU time
(``time.process_time``); the yardstick is the mean of the two 24-MP calls, so a photo's ratio
compares calls of the same run on the same machine, and the CPU ratio is the steadier one on a
machine shared with other work.

Per photo the table gives those ratios, ``compare``'s stages (``Comparison.timing_s``: load,
detect, fit, render, metrics), the disc search's steps (``DiscSearch.timing_s``: the candidates,
their measurement, the circles through edges, the circles of the sizes found, the own steps) and
the fit's steps (``ApertureFit.timing_s``: choose, screen, the per-family fits summed, joint,
features, the rest). ``--json`` also keeps each photo's answer
(status, shape, angle, features, diameter) so that two runs can be checked for the same answers.

``--coverages`` times nothing: per photo it counts the exact coverages the fit computes (plain and
with the rim profile: ``bokehfit.fit.disc_model``'s calls of ``coverage`` and ``rim_coverage``)
and how many of them are taken for the Jacobian (scipy's finite differences, or the fit's own
Jacobian, on the stack); where the tree has them, also the exact coverages with their slopes
(``coverage_slopes``) that the fit's own Jacobian takes for a disc's centre, size and angle.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from real_photos import MANIFEST, find_photo  # noqa: E402

from bokehfit.bench.compare import BIG, GEOMETRY, WARMUP, cached_photo  # noqa: E402
from bokehfit.compare import compare_photo  # noqa: E402

STAGES = ("load", "detect", "fit", "render", "metrics")
#: Frames on the stack while a Jacobian is taken: scipy's finite differences (trees before the fit
#: had a Jacobian of its own) and the fit's own (``bokehfit.fit.objective.jacobian``).
JACOBIAN_FRAMES = ("approx_derivative", "jac")
#: The fit's steps shown as columns; ``families`` sums the ``family <name>`` steps, ``other`` the rest.
STEPS = ("choose", "screen", "families", "joint", "features")
#: The disc search's steps shown as columns (``DiscSearch.timing_s``; its result's making is left in "detect").
SEARCH_STEPS = ("candidates", "measure", "edge circles", "sized circles", "own steps")


def timed(path: Path, **kwargs) -> dict:
    """One ``compare_photo`` call: wall and CPU seconds, stages, fit steps and the answer."""
    wall, cpu = time.perf_counter(), time.process_time()
    comparison = compare_photo(path, **kwargs)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    fit = comparison.fit
    steps = dict(getattr(fit, "timing_s", {}) or {})
    families = {k[len("family "):]: v for k, v in steps.items() if k.startswith("family ")}
    grouped = {k: v for k, v in steps.items() if not k.startswith("family ")}
    grouped["families"] = sum(families.values())
    answer = comparison.aperture_json() or {}
    return {
        "wall_s": wall,
        "cpu_s": cpu,
        "stages_s": {k: comparison.timing_s.get(k, 0.0) for k in STAGES},
        "fit_steps_s": grouped,
        "search_steps_s": dict(comparison.search.timing_s),
        "family_fits_s": families,
        "answer": {
            "status": comparison.status,
            "shape": answer.get("shape"),
            "blades": answer.get("blades"),
            "angle_deg": answer.get("angle_deg"),
            "diameter_px": answer.get("diameter_px"),
            **{k: answer.get(k) for k in ("roundness", "squeeze", "vignetting", "rim", "aspect")},
            "discs_fitted": answer.get("discs_fitted"),
        },
    }


def table(rows: dict, reference: dict) -> list[str]:
    head = ["photo", "wall s", "× 24 MP", "CPU s", "CPU × 24 MP", *STAGES, *(f"find: {s}" for s in SEARCH_STEPS),
            *(f"fit: {s}" for s in STEPS), "fit: other"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, row in rows.items():
        steps = row["fit_steps_s"]
        other = sum(v for k, v in steps.items() if k not in STEPS)
        cells = [name, f"{row['wall_s']:.2f}", f"{row['wall_s'] / reference['wall_s']:.2f}", f"{row['cpu_s']:.2f}",
                 f"{row['cpu_s'] / reference['cpu_s']:.2f}", *(f"{row['stages_s'][s]:.2f}" for s in STAGES),
                 *(f"{row['search_steps_s'].get(s, 0.0):.2f}" for s in SEARCH_STEPS),
                 *(f"{steps.get(s, 0.0):.2f}" for s in STEPS), f"{other:.2f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def count_coverages(entries: list[dict]) -> None:
    """Per photo, the fit's exact coverages, and the share of them taken for a finite-difference Jacobian."""
    import traceback

    import bokehfit.fit.disc_model as disc_model

    counts: dict[str, int] = {}

    def counted(kind, function):
        def wrapper(*args, **kwargs):
            jacobian = any(frame.name in JACOBIAN_FRAMES for frame in traceback.extract_stack())
            key = f"{kind}, {'Jacobian' if jacobian else 'step'}"
            counts[key] = counts.get(key, 0) + 1
            return function(*args, **kwargs)
        return wrapper

    disc_model.coverage = counted("plain", disc_model.coverage)
    disc_model.rim_coverage = counted("rim", disc_model.rim_coverage)
    kinds = ["plain", "rim"]
    if hasattr(disc_model, "coverage_slopes"):  # the model's own slopes (a coverage and its derivatives)
        disc_model.coverage_slopes = counted("slopes", disc_model.coverage_slopes)
        kinds.append("slopes")
    print("| photo | " + " | ".join(f"{k}: steps | {k}: Jacobian" for k in kinds) + " | share for the Jacobian |")
    print("|---|" + "---|---|" * len(kinds) + "---|")
    for entry in entries:
        path = find_photo(entry)
        if path is None:
            print(f"{entry['file']}: missing", file=sys.stderr)
            continue
        counts.clear()
        compare_photo(path)
        cells = [counts.get(f"{kind}, {when}", 0) for kind in kinds for when in ("step", "Jacobian")]
        total = sum(cells)
        share = "-" if not total else f"{sum(cells[1::2]) / total:.0%}"
        print(f"| {entry['file'][:2]} | " + " | ".join(str(c) for c in cells) + f" | {share} |", flush=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, help="write the figures and answers here")
    parser.add_argument("--only", nargs="*", help="photo numbers (01 … 17) to run")
    parser.add_argument("--coverages", action="store_true",
                        help="count the fit's exact coverages, and those taken for a finite-difference Jacobian")
    args = parser.parse_args(argv)

    entries = json.loads(MANIFEST.read_text(encoding="utf-8"))["photos"]
    if args.only:
        entries = [e for e in entries if e["file"][:2] in args.only]
    if args.coverages:
        count_coverages(entries)
        return 0
    warmup, _ = cached_photo(WARMUP)
    big, _ = cached_photo(BIG)
    compare_photo(warmup, **GEOMETRY)
    first = timed(big, **GEOMETRY)
    rows: dict = {}
    for entry in entries:
        path = find_photo(entry)
        if path is None:
            print(f"{entry['file']}: missing", file=sys.stderr)
            continue
        rows[entry["file"][:2]] = timed(path)
        row = rows[entry["file"][:2]]
        print(f"{entry['file'][:2]}: {row['wall_s']:.2f} s wall, {row['cpu_s']:.2f} s CPU, {row['answer']}", file=sys.stderr)
    last = timed(big, **GEOMETRY)
    reference = {k: 0.5 * (first[k] + last[k]) for k in ("wall_s", "cpu_s")}
    synthetic = {"24 MP (first)": first, "24 MP (last)": last}
    lines = table({**synthetic, **rows}, reference)
    total = {k: sum(r[k] for r in rows.values()) for k in ("wall_s", "cpu_s")}
    lines.append("")
    lines.append(f"24-MP yardstick: {reference['wall_s']:.2f} s wall, {reference['cpu_s']:.2f} s CPU (mean of two calls); "
                 f"the {len(rows)} photos: {total['wall_s']:.1f} s wall, {total['cpu_s']:.1f} s CPU")
    print("\n".join(lines))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"reference": reference, "synthetic": synthetic, "photos": rows}, indent=1),
                             encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
