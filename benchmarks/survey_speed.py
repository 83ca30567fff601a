"""Photos per second of ``bokehfit survey`` against a shell loop of ``bokehfit compare``.

Usage::

    python benchmarks/survey_speed.py [--photos 16] [--jobs 1,2] [--dask-workers 2] [--json out.json]

Makes a library of synthetic photos (512×384 JPEGs, 8 discs each: circles at
f/2, hexagons at f/4, with FNumber, LensModel and FocalLength in EXIF) in a
temporary folder, then times, each from a cold start and over the same photos:

- a shell loop, ``for f in lib/*.jpg; do python -m bokehfit compare "$f" --out-dir loop; done``;
- ``bokehfit survey lib --db ...`` with each ``--jobs N`` (a fresh database each time);
- the same survey on a Dask ``LocalCluster`` (loopback, ``--dask-workers`` processes of one
  thread), timed once the cluster is up (a cluster is long-lived); its start-up is shown apart.

Every survey writes the per-photo JSON and HTML like the loop. The per-photo overhead is
the loop's time per photo less the ``--jobs 1`` survey's: a process start and bokehfit's
import and GPU set-up, paid per photo by the loop and once per worker by the survey.
The script prints a table and asserts nothing; ``--json`` also writes the figures.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

import bokehfit
from bokehfit.apertures import make_aperture
from bokehfit.outputs import check_output_path, write_json
from bokehfit.synthetic import SyntheticDisc, encode_srgb8, render_discs

WIDTH_PX, HEIGHT_PX = 512, 384
FOCAL_LENGTH_MM, FOCUS_DISTANCE_MM = 50.0, 2000.0
#: Sensor width that makes f/2 discs 48 px wide (thin lens, lights at infinity: c = f² / (N (d_f − f))).
SENSOR_WIDTH_MM = FOCAL_LENGTH_MM**2 / (2.0 * (FOCUS_DISTANCE_MM - FOCAL_LENGTH_MM)) * WIDTH_PX / 48.0
COMPARE_ARGS = ["--shapes", "circle,hexagon,pentagon", "--sensor-width-mm", f"{SENSOR_WIDTH_MM:.6f}",
                "--focus-distance-m", f"{FOCUS_DISTANCE_MM / 1000:g}"]


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
    """Median seconds of compare per photo inside the workers, and the rows by status, from the survey's database."""
    import duckdb

    with duckdb.connect(str(db), read_only=True) as connection:
        median = connection.execute("SELECT median(seconds) FROM photos").fetchone()[0]
        statuses = dict(connection.execute("SELECT status, count(*) FROM photos GROUP BY status").fetchall())
    return {"median_photo_s": median, "statuses": statuses}


def timed(command: list[str], cwd: Path) -> float:
    started = time.perf_counter()
    done = subprocess.run(command, cwd=cwd, capture_output=True, text=True)
    seconds = time.perf_counter() - started
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command[:6])} ... failed ({done.returncode}): {done.stderr.strip()[-400:]}")
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--photos", type=int, default=16, help="photos in the library (default 16)")
    parser.add_argument("--jobs", default="1,2", help="comma-separated --jobs values to time (default 1,2)")
    parser.add_argument("--dask-workers", type=int, default=2, help="LocalCluster worker processes; 0 skips Dask (default 2)")
    parser.add_argument("--json", metavar="OUT.json", help="also write the figures as JSON")
    args = parser.parse_args()
    out = check_output_path(args.json, (".json",)) if args.json else None
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(f"bokehfit {bokehfit.__version__}, Python {platform.python_version()}, {platform.machine()}, {cores} usable cores, "
          f"{args.photos} photos of {WIDTH_PX}×{HEIGHT_PX}")
    python = sys.executable
    rows = []
    with tempfile.TemporaryDirectory(prefix="bokehfit-survey-bench-") as scratch:
        root = Path(scratch)
        photos = make_library(root / "lib", args.photos)
        loop = ('for f in "$@"; do "$PYTHON" -m bokehfit compare "$f" --out-dir loop '
                + " ".join(COMPARE_ARGS) + " > /dev/null || exit 1; done")
        env_python = {**os.environ, "PYTHON": python}
        started = time.perf_counter()
        done = subprocess.run(["bash", "-c", loop, "loop", *map(str, photos)], cwd=root, env=env_python,
                              capture_output=True, text=True)
        loop_s = time.perf_counter() - started
        if done.returncode != 0:
            raise SystemExit(f"the compare loop failed: {done.stderr.strip()[-400:]}")
        rows.append({"run": "shell loop of `bokehfit compare`", "seconds": loop_s})
        for jobs in [int(j) for j in args.jobs.split(",") if j.strip()]:
            seconds = timed([python, "-m", "bokehfit", "survey", "lib", "--db", f"jobs{jobs}.duckdb", "--jobs", str(jobs),
                             *COMPARE_ARGS], root)
            rows.append({"run": f"survey --jobs {jobs}", "seconds": seconds, "jobs": jobs, **in_worker(root / f"jobs{jobs}.duckdb")})
        if args.dask_workers > 0:
            from distributed import LocalCluster

            started = time.perf_counter()
            with LocalCluster(n_workers=args.dask_workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                              dashboard_address=None, worker_dashboard_address=None) as cluster:
                cluster_s = time.perf_counter() - started
                seconds = timed([python, "-m", "bokehfit", "survey", "lib", "--db", "dask.duckdb", "--scheduler",
                                 cluster.scheduler_address, *COMPARE_ARGS], root)
            rows.append({"run": f"survey --scheduler (LocalCluster, {args.dask_workers} workers)", "seconds": seconds,
                         "cluster_start_s": cluster_s, **in_worker(root / "dask.duckdb")})
    for row in rows:
        row["photos_per_s"] = args.photos / row["seconds"]
        row["vs_loop"] = loop_s / row["seconds"]
    print("\n| run | seconds | photos/s | × the loop | compare per photo in a worker, median s | rows |\n|---|---:|---:|---:|---:|---|")
    for row in rows:
        median = f"{row['median_photo_s']:.2f}" if row.get("median_photo_s") is not None else "—"
        statuses = ", ".join(f"{n} {s}" for s, n in sorted(row.get("statuses", {}).items())) or "—"
        print(f"| {row['run']} | {row['seconds']:.1f} | {row['photos_per_s']:.2f} | {row['vs_loop']:.2f} | {median} | {statuses} |")
    one = next((row for row in rows if row.get("jobs") == 1), None)
    if one is not None:
        overhead = (loop_s - one["seconds"]) / args.photos
        print(f"\nper-photo overhead of a process per photo (loop − survey --jobs 1, per photo): {overhead:.2f} s; "
              f"the loop's time per photo less compare's median in a worker: {loop_s / args.photos - one['median_photo_s']:.2f} s")
    for row in rows:
        if "cluster_start_s" in row:
            print(f"LocalCluster start-up (not in the survey's time): {row['cluster_start_s']:.1f} s")
    if out:
        write_json(Path(out), {"bokehfit_version": bokehfit.__version__, "photos": args.photos, "cores": cores,
                               "size_px": [WIDTH_PX, HEIGHT_PX], "rows": rows})
        print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
