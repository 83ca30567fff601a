"""Photos per second of ``bokehfit survey`` against a shell loop of ``bokehfit compare``.

Usage::

    python benchmarks/survey_speed.py [--count 100] [--loop-count 16] [--jobs 1,2] [--dask-workers 0]
                                      [--trees DIR ...] [--json out.json]

Makes a library of ``--count`` synthetic photos (512×384 JPEGs, 8 discs each: circles at
f/2, hexagons at f/4, each photo with its own noise and disc places, with FNumber, LensModel
and FocalLength in EXIF) in a temporary folder, then times, each from a cold start:

- a shell loop, ``for f in lib/*.jpg; do python -m bokehfit compare "$f" --out-dir loop; done``,
  over the first ``--loop-count`` photos (a process per photo: the slow way, so fewer photos);
- ``bokehfit survey lib --db ...`` over all the photos, with each ``--jobs N`` (a fresh database each time);
- with ``--dask-workers N``, the same survey on a Dask ``LocalCluster`` (loopback, N processes of one
  thread), timed once the cluster is up (a cluster is long-lived); its start-up is shown apart.

Every survey writes the per-photo JSON and HTML like the loop. Each run's figures: photos per
second of wall-clock time, CPU seconds per photo of every process it started (what a shared
machine's load does not inflate much), the median seconds of compare per photo inside a
worker (from the database), and the rows by status. The per-photo overhead of a process per
photo is the loop's time per photo less compare's median in a worker.

Every process runs the bokehfit of a source tree (``PYTHONPATH``): by default the one this
script imports. ``--trees`` times several (folders holding ``bokehfit/``, e.g. a ``git worktree``
of an older commit and ``.``) one after the other within each run, so that a before/after ratio is
measured on one machine in one sitting; the surveys' rows (timing columns left out) are
compared between the trees. The script prints tables and asserts nothing; ``--json`` also
writes the figures. On 2 cores the defaults take about 6½ minutes per tree.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

import bokehfit
from bokehfit.apertures import make_aperture
from bokehfit.output_paths import check_output_path
from bokehfit.outputs import write_json
from bokehfit.synthetic import SyntheticDisc, encode_srgb8, render_discs

WIDTH_PX, HEIGHT_PX = 512, 384
FOCAL_LENGTH_MM, FOCUS_DISTANCE_MM = 50.0, 2000.0
#: Sensor width that makes f/2 discs 48 px wide (thin lens, lights at infinity: c = f² / (N (d_f − f))).
SENSOR_WIDTH_MM = FOCAL_LENGTH_MM**2 / (2.0 * (FOCUS_DISTANCE_MM - FOCAL_LENGTH_MM)) * WIDTH_PX / 48.0
COMPARE_ARGS = ["--shapes", "circle,hexagon,pentagon", "--sensor-width-mm", f"{SENSOR_WIDTH_MM:.6f}",
                "--focus-distance-m", f"{FOCUS_DISTANCE_MM / 1000:g}"]
#: Columns of a survey row that differ from run to run whatever the photo (left out when trees' rows are compared).
RUN_COLUMNS = {"seconds", "worker", "finished_at", "bokehfit_version", "json_path", "html_path", "result", "thumbnail"}


#: A Dask LocalCluster in a process of its own: prints the scheduler's address, stops when its stdin closes.
CLUSTER = """
import sys
from distributed import LocalCluster
with LocalCluster(n_workers=int(sys.argv[1]), threads_per_worker=1, processes=True, host="127.0.0.1",
                  dashboard_address=None, worker_dashboard_address=None) as cluster:
    print(cluster.scheduler_address, flush=True)
    sys.stdin.read()
"""


def make_library(folder: Path, count: int) -> list[Path]:
    """``count`` JPEGs alternating f/2 circles and f/4 hexagons, each with its own noise."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(7)
    paths = []
    for i in range(count):
        fnumber, shape = (2.0, "circle") if i % 2 == 0 else (4.0, "hexagon")
        diameter = FOCAL_LENGTH_MM**2 / (fnumber * (FOCUS_DISTANCE_MM - FOCAL_LENGTH_MM)) * WIDTH_PX / SENSOR_WIDTH_MM
        centres = [(64 + 128 * c + rng.uniform(-4, 4), 96 + 192 * r + rng.uniform(-4, 4)) for r in range(2) for c in range(4)]
        aperture = make_aperture(shape, 15.0)
        linear = render_discs(WIDTH_PX, HEIGHT_PX, [SyntheticDisc(xy, diameter, aperture) for xy in centres],
                              background=0.03, noise_sigma=0.002, seed=i)
        exif = Image.Exif()
        exif[0x0110] = "Bench Cam"
        sub = exif.get_ifd(0x8769)
        sub[0x829D], sub[0xA434], sub[0x920A] = fnumber, "Bench 50mm", FOCAL_LENGTH_MM
        path = folder / f"photo_{i:03d}.jpg"
        Image.fromarray(encode_srgb8(linear)).convert("RGB").save(path, exif=exif.tobytes(), quality=92)
        paths.append(path)
    return paths


def in_worker(db: Path) -> dict:
    """Median seconds of compare per photo inside the workers, the rows by status and the rows themselves."""
    import duckdb

    with duckdb.connect(str(db), read_only=True) as connection:
        median = connection.execute("SELECT median(seconds) FROM photos").fetchone()[0]
        statuses = dict(connection.execute("SELECT status, count(*) FROM photos GROUP BY status").fetchall())
        cursor = connection.execute("SELECT * FROM photos ORDER BY sha256")
        names = [column[0] for column in cursor.description]
        rows = [{n: v for n, v in zip(names, row) if n not in RUN_COLUMNS} for row in cursor.fetchall()]
    return {"median_photo_s": median, "statuses": statuses, "rows": rows}


def children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def timed(command: list[str], cwd: Path, env: dict) -> tuple[float, float]:
    """Wall-clock and CPU seconds (of every process it started and waited for) of ``command``."""
    cpu, started = children_cpu_s(), time.perf_counter()
    done = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True)
    seconds, cpu = time.perf_counter() - started, children_cpu_s() - cpu
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command[:6])} ... failed ({done.returncode}): {done.stderr.strip()[-400:]}")
    return seconds, cpu


def same_rows(a: list[dict], b: list[dict]) -> str:
    """'same' or which columns differ between two runs' rows (compared by photo, on the columns both have)."""
    if [row["sha256"] for row in a] != [row["sha256"] for row in b]:
        return "other photos"
    columns = sorted({name for row, other in zip(a, b) for name in row.keys() & other.keys() if row[name] != other[name]})
    return "same" if not columns else "differ in " + ", ".join(columns)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", "--photos", type=int, default=100, help="photos in the library, surveyed by each run (default 100)")
    parser.add_argument("--loop-count", type=int, default=16, help="photos of the compare loop, the first of the library (default 16)")
    parser.add_argument("--jobs", default="1,2", help="comma-separated --jobs values to time (default 1,2)")
    parser.add_argument("--dask-workers", type=int, default=0, help="LocalCluster worker processes; 0 skips Dask (default 0)")
    parser.add_argument("--trees", nargs="+", metavar="DIR", help="source trees to time in turn (default: the bokehfit this script imports)")
    parser.add_argument("--json", metavar="OUT.json", help="also write the figures as JSON")
    args = parser.parse_args()
    if args.count < 1 or not 0 <= args.loop_count <= args.count:
        raise SystemExit("--count must be >= 1 and --loop-count between 0 and --count")
    out = check_output_path(args.json, (".json",)) if args.json else None
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(f"bokehfit {bokehfit.__version__}, Python {platform.python_version()}, {platform.machine()}, {cores} usable cores, "
          f"{args.count} photos of {WIDTH_PX}×{HEIGHT_PX} (the loop: {args.loop_count})", flush=True)
    python = sys.executable
    # every process runs the tree's bokehfit: by default the one this script imports
    trees = [Path(tree).resolve() for tree in args.trees] if args.trees else [Path(bokehfit.__file__).resolve().parents[1]]
    envs = {tree: {**os.environ, "PYTHONPATH": str(tree), "PYTHON": python} for tree in trees}
    rows = []

    def add(row: dict, photos: int) -> None:
        cpu = None if row["cpu_s"] is None else row["cpu_s"] / photos
        row.update(photos=photos, photos_per_s=photos / row["seconds"], cpu_per_photo_s=cpu)
        rows.append(row)
        print(f"  {row['tree']}: {row['run']}: {row['seconds']:.1f} s, {row['photos_per_s']:.2f} photos/s"
              + ("" if cpu is None else f", {cpu:.2f} CPU s per photo"), flush=True)

    with tempfile.TemporaryDirectory(prefix="bokehfit-survey-bench-") as scratch:
        root = Path(scratch)
        photos = make_library(root / "lib", args.count)
        if args.loop_count:
            loop = ('for f in "$@"; do "$PYTHON" -m bokehfit compare "$f" --out-dir loop '
                    + " ".join(COMPARE_ARGS) + " > /dev/null || exit 1; done")
            for tree in trees:
                seconds, cpu = timed(["bash", "-c", loop, "loop", *map(str, photos[: args.loop_count])], root, envs[tree])
                add({"tree": str(tree), "run": "shell loop of `bokehfit compare`", "seconds": seconds, "cpu_s": cpu},
                    args.loop_count)
        for jobs in [int(j) for j in args.jobs.split(",") if j.strip()]:
            for k, tree in enumerate(trees):
                db = f"jobs{jobs}-{k}.duckdb"
                seconds, cpu = timed([python, "-m", "bokehfit", "survey", "lib", "--db", db, "--jobs", str(jobs),
                                      *COMPARE_ARGS], root, envs[tree])
                add({"tree": str(tree), "run": f"survey --jobs {jobs}", "jobs": jobs, "seconds": seconds, "cpu_s": cpu,
                     **in_worker(root / db)}, args.count)
        for k, tree in enumerate(trees if args.dask_workers > 0 else []):
            # the cluster runs in a process of its own that imports the tree's bokehfit (a spawned
            # worker gets its parent's sys.path: it must be the tree's)
            started = time.perf_counter()
            cluster = subprocess.Popen([python, "-c", CLUSTER, str(args.dask_workers)], cwd=root, env=envs[tree],
                                       stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
            try:
                address = cluster.stdout.readline().strip()
                if not address:
                    raise SystemExit("the LocalCluster did not start")
                cluster_s = time.perf_counter() - started
                seconds, _ = timed([python, "-m", "bokehfit", "survey", "lib", "--db", f"dask-{k}.duckdb", "--scheduler",
                                    address, *COMPARE_ARGS], root, envs[tree])
            finally:
                cluster.stdin.close()
                cluster.wait()
            # the cluster's processes work for the survey but are not its children: no CPU time is counted
            add({"tree": str(tree), "run": f"survey --scheduler (LocalCluster, {args.dask_workers} workers)", "seconds": seconds,
                 "cpu_s": None, "cluster_start_s": cluster_s, **in_worker(root / f"dask-{k}.duckdb")}, args.count)
    loop_rate = {row["tree"]: row["photos_per_s"] for row in rows if row["run"].startswith("shell loop")}
    print("\n| tree | run | photos | seconds | photos/s | × the loop | CPU s per photo | compare per photo in a worker, median s | rows |\n"
          "|---|---|---:|---:|---:|---:|---:|---:|---|")
    for row in rows:
        median = f"{row['median_photo_s']:.2f}" if row.get("median_photo_s") is not None else "—"
        statuses = ", ".join(f"{n} {s}" for s, n in sorted(row.get("statuses", {}).items())) or "—"
        ratio = f"{row['photos_per_s'] / loop_rate[row['tree']]:.2f}" if row["tree"] in loop_rate else "—"
        cpu = "—" if row["cpu_per_photo_s"] is None else f"{row['cpu_per_photo_s']:.2f}"
        print(f"| {row['tree']} | {row['run']} | {row['photos']} | {row['seconds']:.1f} | {row['photos_per_s']:.2f} | {ratio} | "
              f"{cpu} | {median} | {statuses} |")
    for row in rows:
        if row["run"].startswith("shell loop") and row["tree"] in loop_rate:
            one = next((r for r in rows if r["tree"] == row["tree"] and r.get("jobs") == 1), None)
            if one is not None and one["median_photo_s"] is not None:
                print(f"\n{row['tree']}: the loop's time per photo less compare's median in a worker (a process per photo): "
                      f"{1 / row['photos_per_s'] - one['median_photo_s']:.2f} s")
        if "cluster_start_s" in row:
            print(f"{row['tree']}: LocalCluster start-up (not in the survey's time): {row['cluster_start_s']:.1f} s")
    surveyed = [row for row in rows if "rows" in row]
    if len(surveyed) > 1:
        first = surveyed[0]
        print(f"\nrows against {first['tree']} {first['run']}: "
              + "; ".join(f"{row['tree']} {row['run']}: {same_rows(first['rows'], row['rows'])}" for row in surveyed[1:]))
    if out:
        write_json(Path(out), {"bokehfit_version": bokehfit.__version__, "photos": args.count, "loop_photos": args.loop_count,
                               "cores": cores, "size_px": [WIDTH_PX, HEIGHT_PX],
                               "rows": [{k: v for k, v in row.items() if k != "rows"} for row in rows]})
        print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
