"""CPU seconds of a survey worker's photo in several source trees, taken in turns on the same photos.

Usage::

    python benchmarks/photo_turns.py --trees DIR DIR [...] [--count 30] [--rounds 2] [--json out.json]

``survey_speed.py`` times whole surveys one tree after the other; on a machine shared with other
work its figures move by a third from one run to the next, more than a change of a few per cent.
This script starts one worker process per tree (``PYTHONPATH`` the tree, a folder holding
``bokehfit/``, e.g. a ``git worktree`` of an older commit and ``.``), each set up as a survey's
worker is (:func:`bokehfit.surveys.work.init_worker`, one photo at a time), on the library of
``survey_speed.py`` (512×384 JPEGs, 8 discs each: circles at f/2, hexagons at f/4). Then photo
after photo, each tree's worker runs ``survey_photo`` on the same photo in turn (the order
alternating), and the CPU seconds each took are summed (``time.process_time`` in the worker). A
slow spell of the machine falls on both trees alike, so the ratio of the sums is the trees' own;
the seconds themselves are the machine's of the moment. Each worker first runs two photos that are
not counted (imports and first-call set-up). The script prints the table and asserts nothing.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from survey_speed import COMPARE_ARGS, FOCUS_DISTANCE_MM, SENSOR_WIDTH_MM, make_library  # noqa: E402


def worker(library: Path) -> None:
    """One tree's worker: reads photo indices on stdin, answers each with the CPU seconds of its survey_photo."""
    from bokehfit.surveys.work import PhotoTask, init_worker, survey_photo

    paths = sorted(library.glob("*.jpg"))
    init_worker(ignore_sigint=False, workers=1)
    shapes = COMPARE_ARGS[COMPARE_ARGS.index("--shapes") + 1].split(",")
    options = {"shapes": shapes, "sensor_width_mm": float(SENSOR_WIDTH_MM), "focus_distance_m": FOCUS_DISTANCE_MM / 1000.0}
    tasks = [PhotoTask(str(p), hashlib.sha256(p.read_bytes()).hexdigest(), options, "bokehfit survey") for p in paths]
    for task in tasks[:2]:
        survey_photo(task)
    print("ready", flush=True)
    for line in sys.stdin:
        started = time.process_time()
        row = survey_photo(tasks[int(line)])
        print(f"{time.process_time() - started} {row['status']}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trees", nargs="+", required=True, metavar="DIR", help="source trees to compare (two or more)")
    parser.add_argument("--count", type=int, default=30, help="photos in the library (default 30)")
    parser.add_argument("--rounds", type=int, default=2, help="times each photo is run in each tree (default 2)")
    parser.add_argument("--json", metavar="OUT.json", help="also write the figures as JSON")
    parser.add_argument("--worker", metavar="LIBRARY", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(Path(args.worker))
        return
    if len(args.trees) < 2 or args.count < 2 or args.rounds < 1:
        raise SystemExit("--trees needs two or more folders, --count at least 2, --rounds at least 1")
    trees = [Path(tree).resolve() for tree in args.trees]
    missing = [str(tree) for tree in trees if not (tree / "bokehfit" / "__init__.py").is_file()]
    if missing:
        raise SystemExit(f"not a source tree (no bokehfit/__init__.py): {', '.join(missing)}")
    print(f"Python {platform.python_version()}, {os.cpu_count()} cores, {args.count} photos, {args.rounds} rounds", flush=True)
    with tempfile.TemporaryDirectory(prefix="bokehfit-turns-") as scratch:
        library = Path(scratch) / "lib"
        make_library(library, args.count)
        workers = [subprocess.Popen([sys.executable, __file__, "--trees", *map(str, trees), "--worker", str(library)],
                                    env={**os.environ, "PYTHONPATH": str(tree)}, stdin=subprocess.PIPE,
                                    stdout=subprocess.PIPE, text=True) for tree in trees]
        try:
            for process in workers:
                if process.stdout.readline().strip() != "ready":
                    raise SystemExit("a worker did not start")
            seconds = [0.0] * len(trees)
            statuses = [dict() for _ in trees]
            for turn in range(args.rounds * args.count):
                order = range(len(trees)) if turn % 2 == 0 else reversed(range(len(trees)))
                for k in order:
                    workers[k].stdin.write(f"{turn % args.count}\n")
                    workers[k].stdin.flush()
                    spent, status = workers[k].stdout.readline().split()
                    seconds[k] += float(spent)
                    statuses[k][status] = statuses[k].get(status, 0) + 1
        finally:
            for process in workers:
                process.stdin.close()
                process.wait()
    runs = args.rounds * args.count
    print("\n| tree | CPU s per photo | × the first tree | photos by status |\n|---|---:|---:|---|")
    for tree, spent, status in zip(trees, seconds, statuses):
        print(f"| {tree} | {spent / runs:.3f} | {spent / seconds[0]:.3f} | "
              + ", ".join(f"{n} {s}" for s, n in sorted(status.items())) + " |")
    if args.json:
        from bokehfit.output_paths import check_output_path
        from bokehfit.outputs import write_json

        write_json(Path(check_output_path(args.json, (".json",))),
                   {"photos": args.count, "rounds": args.rounds,
                    "trees": [{"tree": str(t), "cpu_per_photo_s": s / runs, "ratio": s / seconds[0], "statuses": st}
                              for t, s, st in zip(trees, seconds, statuses)]})
        print(f"\nwrote {args.json}")


if __name__ == "__main__":
    main()
