"""Loading and disc detection: time and peak memory per photo, beside a bare ``cv2.imread``.

Usage::

    python benchmarks/detect_speed.py [--repeat N] [--json out.json] [PHOTO ...]
    BOKEHFIT_REFERENCE_DIR=/path/to/photos python benchmarks/detect_speed.py

Without photos named, every JPEG, PNG and TIFF in ``BOKEHFIT_REFERENCE_DIR`` (when
set) and the 24-MP photo of ``bokehfit bench`` part (c) (:data:`bokehfit.bench.compare.BIG`,
made once and cached) are measured.

Each photo is measured in a fresh Python process (this script run with ``--child``):

1. the peak resident set size (``resource.getrusage(RUSAGE_SELF).ru_maxrss``) after
   the imports and a load and search of a small photo (so that what is set up on first
   use is not counted), after :func:`bokehfit.io.load_photo` and after
   :func:`bokehfit.discs.find_discs` on the loaded photo (as ``bokehfit compare``
   calls it); the peaks over the first, minus the first, per pixel, are the memory
   figures (``load B/px``, ``peak B/px``);
2. then load and detect ``N`` more times, and ``cv2.imread`` of the same file ``N``
   times: the best of each is the time reported (the machine may be shared), and
   ``ratio`` is (load + detect) / imread.

The script prints a table and asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SUFFIXES = (".jpg", ".jpeg", ".png", ".tif", ".tiff")


def _peak_rss_bytes() -> int:
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak if sys.platform == "darwin" else peak * 1024)


def child(path: str, repeat: int) -> dict:
    """Runs in a fresh process: memory of the first load and search, then the best times."""
    import cv2

    import numpy as np

    from bokehfit.discs import find_discs
    from bokehfit.io import load_photo

    # A small photo first, so that what is imported or set up on first use is not counted.
    with tempfile.TemporaryDirectory() as folder:
        small = Path(folder) / "small.jpg"
        rng = np.random.default_rng(0)
        cv2.imwrite(str(small), rng.integers(0, 256, (96, 128, 3), dtype=np.uint8))
        warm = load_photo(small)
        find_discs(warm.luminance, warm.clipped)
        del warm
    before = _peak_rss_bytes()
    start = time.perf_counter()
    photo = load_photo(path)
    load_s = [time.perf_counter() - start]
    after_load = _peak_rss_bytes()
    search = find_discs(photo.luminance, photo.clipped)
    detect_s = [search.time_s]
    after_detect = _peak_rss_bytes()
    pixels = photo.width * photo.height
    found = len(search.discs)
    usable = sum(d.usable for d in search.discs)
    del photo, search
    for _ in range(repeat):
        start = time.perf_counter()
        photo = load_photo(path)
        load_s.append(time.perf_counter() - start)
        detect_s.append(find_discs(photo.luminance, photo.clipped).time_s)
        del photo
    imread_s = []
    for _ in range(max(1, repeat)):
        start = time.perf_counter()
        cv2.imread(path)
        imread_s.append(time.perf_counter() - start)
    return {
        "photo": Path(path).name,
        "pixels": pixels,
        "imread_s": min(imread_s),
        "load_s": min(load_s),
        "detect_s": min(detect_s),
        "load_bytes_per_px": (after_load - before) / pixels,
        "peak_bytes_per_px": (after_detect - before) / pixels,
        "rss_before_bytes": before,
        "discs": found,
        "usable": usable,
    }


def photos_to_measure(named: list[str]) -> list[Path]:
    if named:
        return [Path(p) for p in named]
    paths = []
    folder = os.environ.get("BOKEHFIT_REFERENCE_DIR")
    if folder:
        paths += sorted(p for p in Path(folder).iterdir() if p.suffix.lower() in SUFFIXES)
    from bokehfit.bench.compare import BIG, cached_photo

    paths.append(cached_photo(BIG)[0])
    return paths


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("photos", nargs="*", help="photos to measure (default: see the module notes)")
    parser.add_argument("--repeat", type=int, default=3, help="timed repeats per photo (best taken), default 3")
    parser.add_argument("--json", metavar="OUT.json", help="also write the figures as JSON")
    parser.add_argument("--child", metavar="PHOTO", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.child, args.repeat)))
        return
    print(f"Python {platform.python_version()}, {platform.machine()}, {os.cpu_count()} CPUs, best of {args.repeat}")
    header = f"{'photo':52s} {'MP':>5s} {'imread':>7s} {'load':>6s} {'detect':>7s} {'ratio':>6s} {'load B/px':>9s} " \
             f"{'peak B/px':>9s} {'discs':>5s}"
    print(header)
    rows = []
    for path in photos_to_measure(args.photos):
        done = subprocess.run([sys.executable, __file__, "--child", str(path), "--repeat", str(args.repeat)],
                              capture_output=True, text=True)
        if done.returncode != 0:
            print(f"{path.name}: failed (exit {done.returncode}): {done.stderr.strip().splitlines()[-1:]}")
            continue
        row = json.loads(done.stdout.strip().splitlines()[-1])
        rows.append(row)
        ratio = (row["load_s"] + row["detect_s"]) / row["imread_s"]
        print(f"{row['photo'][:52]:52s} {row['pixels'] / 1e6:5.1f} {row['imread_s']:7.3f} {row['load_s']:6.3f} "
              f"{row['detect_s']:7.3f} {ratio:6.1f} {row['load_bytes_per_px']:9.1f} {row['peak_bytes_per_px']:9.1f} "
              f"{row['discs']:5d}", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
