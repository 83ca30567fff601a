"""The ``bokehfit compare`` command with BLAS on one thread (its default) against BLAS's own pools.

Usage::

    [BOKEHFIT_REFERENCE_DIR=path/to/reference_photos] python benchmarks/cli_threads.py [--rounds 1] [--only 04 07]

Each photo (the reference photos of ``reference_photos/manifest.json`` found through
``BOKEHFIT_REFERENCE_DIR``, else ``examples/hexagon_85mm_f2.jpg``) is compared by a fresh
``python -m bokehfit compare PHOTO --json …`` process twice, the two ways interleaved:

- **one thread**: as a user runs it (no thread variable set): the command limits BLAS and OpenMP
  to one thread while it works (:mod:`bokehfit.threads`);
- **library default**: ``OPENBLAS_NUM_THREADS`` (and the other two) set to the machine's usable
  cores, which the command leaves as the user set them: OpenBLAS's own default, a thread per core.

It prints per photo the wall-clock and CPU seconds (the child's user + system time) of each way
and their ratios, and whether the two JSON answers agree (status, shape, angle to 0.01°, diameter
to 0.1 %). Ratios are of one run on one machine.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from real_photos import MANIFEST, find_photo  # noqa: E402

from bokehfit.threads import SINGLE_THREAD_VARIABLES  # noqa: E402  (the tree the script lies in)


def photos(only: list[str] | None) -> list[Path]:
    found = []
    if os.environ.get("BOKEHFIT_REFERENCE_DIR"):
        for entry in json.loads(MANIFEST.read_text())["photos"]:
            if only and not any(entry["file"].startswith(prefix) for prefix in only):
                continue
            path = find_photo(entry)
            if path is not None:
                found.append(path)
    return found or [ROOT / "examples" / "hexagon_85mm_f2.jpg"]


def run(photo: Path, threads: int | None, out: Path) -> dict:
    """One ``compare`` process: wall and CPU seconds and the answer's key numbers."""
    env = {k: v for k, v in os.environ.items() if k not in SINGLE_THREAD_VARIABLES}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    if threads is not None:
        env.update({name: str(threads) for name in SINGLE_THREAD_VARIABLES})
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    wall = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "bokehfit", "compare", str(photo), "--json", str(out), "--no-html"],
                          capture_output=True, text=True, env=env)
    wall = time.perf_counter() - wall
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if done.returncode not in (0, 1):
        raise SystemExit(f"compare failed on {photo.name}: {done.stderr.strip().splitlines()[-1:]}")
    document = json.loads(out.read_text())
    aperture = document.get("aperture") or {}
    answer = (document.get("status"), aperture.get("shape"), aperture.get("angle_deg"), aperture.get("diameter_px"))
    return {"wall": wall, "cpu": cpu, "answer": answer}


def same(a: tuple, b: tuple) -> bool:
    if a[:2] != b[:2]:
        return False
    for x, y, tolerance in ((a[2], b[2], 0.01), (a[3], b[3], None)):
        if (x is None) != (y is None):
            return False
        if x is not None and abs(x - y) > (tolerance if tolerance is not None else 1e-3 * abs(y)):
            return False
    return True


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=1, help="times each photo is run each way (default 1)")
    parser.add_argument("--only", nargs="*", help="photos whose file names start with these")
    args = parser.parse_args(argv)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    print(f"{cores} usable cores; 'default' sets {', '.join(SINGLE_THREAD_VARIABLES)}={cores}")
    print("| photo | one thread: wall s | CPU s | default: wall s | CPU s | wall, default / one | CPU, default / one | same answer |")
    print("|---|---:|---:|---:|---:|---:|---:|---|")
    totals = {"one": [0.0, 0.0], "default": [0.0, 0.0]}
    with tempfile.TemporaryDirectory() as folder:
        for photo in photos(args.only):
            results = {"one": [], "default": []}
            for r in range(args.rounds):
                order = (("one", None), ("default", cores)) if r % 2 == 0 else (("default", cores), ("one", None))
                for name, threads in order:
                    results[name].append(run(photo, threads, Path(folder) / f"{name}.json"))
            mean = {name: [sum(x[key] for x in runs) / len(runs) for key in ("wall", "cpu")] for name, runs in results.items()}
            for name in totals:
                totals[name][0] += mean[name][0]
                totals[name][1] += mean[name][1]
            agree = all(same(a["answer"], b["answer"]) for a, b in zip(results["one"], results["default"]))
            print(f"| {photo.name[:2] if photo.name[:2].isdigit() else photo.name} | {mean['one'][0]:.2f} | {mean['one'][1]:.2f} "
                  f"| {mean['default'][0]:.2f} | {mean['default'][1]:.2f} | {mean['default'][0] / mean['one'][0]:.2f} "
                  f"| {mean['default'][1] / mean['one'][1]:.2f} | {'yes' if agree else 'NO'} |", flush=True)
    one, default = totals["one"], totals["default"]
    print(f"| all | {one[0]:.1f} | {one[1]:.1f} | {default[0]:.1f} | {default[1]:.1f} | {default[0] / one[0]:.2f} "
          f"| {default[1] / one[1]:.2f} | |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
