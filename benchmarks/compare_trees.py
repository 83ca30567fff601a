"""``compare`` on the bench's 24-MP photo with the bokehfit of several source trees, back to back.

Usage::

    git worktree add /tmp/before <commit>
    python benchmarks/compare_trees.py /tmp/before . [--rounds 2]

``bokehfit bench --parts c`` measures the tree it runs in; comparing two commits needs both
measured in one run on one machine (a shared machine's speed drifts by 20 % within an hour).
The photos are the bench's own (:data:`bokehfit.bench.compare.BIG`, warmed up on
:data:`~bokehfit.bench.compare.WARMUP`), made by this tree. For each tree, in turn and
``--rounds`` times: a fresh process imports that tree's bokehfit, times one warm-up call and one
``compare_photo`` of the big photo by stage, and the bare ``cv2.imread`` of it (best of 3); then
a fresh ``python -m bokehfit compare`` of it is timed start to exit, with its peak RSS. Only the
public ``compare_photo`` and its ``timing_s`` are used, which every tree since the first
benchmarks has. The script prints figures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from bokehfit.bench.compare import BIG, WARMUP, cached_photo

TIMED = """
import json, sys, time, cv2
from bokehfit.compare import compare_photo
big, small = sys.argv[1], sys.argv[2]
decode = min((lambda t: (cv2.imread(big), time.perf_counter() - t)[1])(time.perf_counter()) for _ in range(3))
compare_photo(small)
timing = compare_photo(big).timing_s
print(json.dumps({"decode": decode, **timing}))
"""
#: A fresh process running ``bokehfit compare`` as its only child: start to exit, and the child's peak RSS (KiB).
COLD = """
import resource, subprocess, sys, time
start = time.perf_counter()
subprocess.run([sys.executable, "-m", "bokehfit", "compare", sys.argv[1], "--no-html"], capture_output=True)
print(time.perf_counter() - start, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
"""


def measure(tree: Path, big: Path, small: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    # Run in the tree: ``python -c`` and ``-m`` put the current folder first on sys.path.
    done = subprocess.run([sys.executable, "-c", TIMED, str(big), str(small)], env=env, cwd=tree, capture_output=True,
                          text=True)
    if done.returncode != 0:
        raise SystemExit(f"{tree}: {done.stderr.strip().splitlines()[-1] if done.stderr.strip() else done.returncode}")
    figures = json.loads(done.stdout.strip().splitlines()[-1])
    cold = subprocess.run([sys.executable, "-c", COLD, str(big)], env=env, cwd=tree, capture_output=True, text=True)
    seconds, peak_kib = cold.stdout.split()
    figures["cold_process"], figures["peak_rss_mib"] = float(seconds), int(peak_kib) / 1024
    return figures


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("trees", nargs="+", help="source trees (folders holding bokehfit/), e.g. a git worktree and .")
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args(argv)
    big, _ = cached_photo(BIG)
    small, _ = cached_photo(WARMUP)
    print("| round | tree | load | detect | fit | render | metrics | warm | / decode | cold process | peak RSS MiB |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for round_ in range(1, args.rounds + 1):
        for tree in args.trees:
            f = measure(Path(tree).resolve(), big, small)
            print(f"| {round_} | {tree} | {f['load']:.3f} | {f['detect']:.3f} | {f['fit']:.3f} | {f.get('render', 0):.3f} | "
                  f"{f.get('metrics', 0):.3f} | {f['total']:.2f} s | {f['total'] / f['decode']:.1f}× | "
                  f"{f['cold_process']:.2f} s | {f['peak_rss_mib']:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
