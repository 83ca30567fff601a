"""The hostile-input corpus through every subcommand: how many cases end in each outcome.

Usage::

    python benchmarks/hostile_corpus.py [--sweep] [--jobs N] [--only WORD,WORD] [--json out.json]

Generates the corpus of ``tests/hostile/corpus.py`` in a temporary folder (damaged,
crafted and absurd inputs; outputs over the user's files; SIGKILL during a write;
files that are not files, link loops, damaged survey databases, fake Dask schedulers,
names that are not UTF-8, absurd EXIF geometry, stale temporaries),
runs each case in a subprocess bounded in time, and prints the count of cases per
outcome (ok; hang; internal error; absurd result, an f-stop no lens has; file lost or
overwritten; leftovers; wrong exit code; noisy stderr), the same per group, and every
case that is not ok with the reason. ``--sweep`` adds the slow cases the tests leave out (a 120,000-disc photo,
an 8192-px Monte-Carlo kernel). The package tested is the one ``python -m
bokehfit`` imports, so ``PYTHONPATH=OTHER_CHECKOUT`` measures another version.
The script asserts nothing.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from hostile.corpus import OUTCOMES, build_cases, generate_inputs, run_cases  # noqa: E402


def _table(rows: list[list[str]]) -> str:
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(cell.ljust(w) if i == 0 else cell.rjust(w) for i, (cell, w) in enumerate(zip(row, widths)))
             for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sweep", action="store_true", help="also the slow cases (minutes)")
    parser.add_argument("--jobs", type=int, default=1, help="cases run at once (default 1)")
    parser.add_argument("--only", default=None, help="only cases whose name contains one of these (comma-separated)")
    parser.add_argument("--json", metavar="OUT.json", help="also write every outcome as JSON")
    args = parser.parse_args()
    import bokehfit

    print(f"bokehfit {bokehfit.__version__} from {Path(bokehfit.__file__).parent.parent.name}/, "
          f"Python {platform.python_version()}, {os.cpu_count()} CPUs")
    wanted = [word for word in (args.only or "").split(",") if word]
    cases = [c for c in build_cases(args.sweep) if not wanted or any(word in c.name for word in wanted)]
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bokehfit-hostile-") as tmp:
        inputs = generate_inputs(Path(tmp) / "inputs", sweep=args.sweep)

        def report(outcome):
            print(f"  {outcome.case:<44} {outcome.outcome:<24} {outcome.time_s:7.2f} s", file=sys.stderr, flush=True)

        outcomes = list(run_cases(cases, inputs, Path(tmp) / "cases", args.jobs, args.sweep, report).values())
    total_s = time.perf_counter() - start

    counts = collections.Counter(o.outcome for o in outcomes)
    print(f"\n{len(outcomes)} cases in {total_s:.0f} s\n")
    print(_table([["outcome", "cases"]] + [[name, str(counts[name])] for name in OUTCOMES]))
    groups = sorted({o.group for o in outcomes})
    by_group = collections.Counter((o.group, o.outcome) for o in outcomes)
    print()
    print(_table([["group", *OUTCOMES]] + [[g, *(str(by_group[g, name]) for name in OUTCOMES)] for g in groups]))
    bad = [o for o in outcomes if o.outcome != "ok"]
    if bad:
        print("\nnot ok:")
        for o in bad:
            print(f"  {o.case}: {o.outcome}: {o.detail}")
    if args.json:
        Path(args.json).write_text(json.dumps(
            {"cases": len(outcomes), "time_s": round(total_s, 1), "counts": dict(counts),
             "outcomes": [o.__dict__ for o in outcomes]}, indent=1) + "\n")


if __name__ == "__main__":
    main()
