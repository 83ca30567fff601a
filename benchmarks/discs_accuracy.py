"""Disc finder accuracy and speed: synthetic discs with known truth, a 24-MP timing, real photos.

Usage::

    python benchmarks/discs_accuracy.py [--quick] [--replicates N] [--json out.json]
    BOKEHFIT_REFERENCE_DIR=/path/to/jpegs python benchmarks/discs_accuracy.py

1. Synthetic accuracy. Every aperture of ``bokehfit.apertures.SHAPES`` (``ngon``
   with 9 blades, ``slit`` at its default aspect) at diameters 6 … 200 px, with
   random angles, brightness and sub-pixel centres, shelf-packed without
   overlaps (cells of 3.2 × the aperture's reach + 16 px) on a 0.01 → 0.08
   horizontal gradient with Gaussian noise σ = 0.003 (linear), one image per
   replicate (fixed seeds). Each image is searched three ways: the linear float
   array itself (baseline, no quantisation), and through the real pipeline:
   ``encode_srgb8`` → ``cv2.imencode`` JPEG at quality 95 and 70 → file →
   ``bokehfit.io.load_photo`` → ``find_discs(photo.luminance, photo.clipped)``.
   Found discs are matched to the truth as in ``tests/test_discs.py`` (nearest
   found centre within max(2 px, d/4)). Per condition and diameter band
   (6–9, 14–22, 35–56, 90–200 px) the table gives recall, precision (an
   unmatched found disc counts against the band its measured diameter falls in,
   bands split at the geometric means of their neighbours' limits), the median
   and 95th percentile of |found − true| / true diameter, the median centre
   error (px) and the share of matched discs flagged usable. A second table
   gives the same per shape over all diameters. The 6–9 px slits are only
   1.6–2.4 px wide, so their 50 % outline is widened by the 0.6-px edge blur;
   the "6–9 no slit" row leaves them out.
2. Time per megapixel (skipped by ``--quick``). A 6000×4000 synthetic JPEG
   (quality 90) with 50 discs of 10–200 px, mixed shapes, on a gradient with
   noise; ``load_photo`` and ``find_discs`` are timed in a fresh process (from a
   forkserver started before any image was made: ``ru_maxrss`` survives fork
   and exec on Linux), whose peak RSS (``resource.getrusage(...).ru_maxrss``,
   KiB on Linux) is read before loading, after loading and after the search.
3. Real photos, when the environment variable ``BOKEHFIT_REFERENCE_DIR`` names a
   folder: every JPEG in it (sorted) is loaded and searched; the table gives
   discs found, usable, saturated, overlapping, the median diameter and times.

``--quick`` uses circle, hexagon and star at 9, 35 and 140 px, 3 replicates instead of 8,
and skips the 24-MP timing. The script prints figures; it asserts nothing.
All timings come from one process on one machine, single run each.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import itertools
import json
import math
import multiprocessing
import multiprocessing.forkserver
import os
import platform
import resource
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from bokehfit.apertures import SHAPES, make_aperture
from bokehfit.discs import find_discs
from bokehfit.io import load_photo
from bokehfit.synthetic import SyntheticDisc, encode_srgb8, render_discs

DIAMETERS = (6, 9, 14, 22, 35, 56, 90, 140, 200)
QUICK_SHAPES = ("circle", "hexagon", "star")
QUICK_DIAMETERS = (9, 35, 140)
BANDS = ((6, 9), (14, 22), (35, 56), (90, 200))
QUALITIES = (95, 70)
NOISE_SIGMA = 0.003
EDGE_BLUR_PX = 0.6
GRADIENT = (0.01, 0.08)
BRIGHTNESS = (0.3, 0.9)
#: A disc's square cell: this many times its reach (largest outline radius), plus CELL_MARGIN_PX.
CELL_FACTOR = 3.2
CELL_MARGIN_PX = 16
TIMING_SIZE = (6000, 4000)
TIMING_DISCS = 50
TIMING_DIAMETERS = (10.0, 200.0)
TIMING_QUALITY = 90


def shape_kwargs(shape: str) -> dict:
    return dict(shape=shape, blades=9) if shape == "ngon" else dict(shape=shape)


def reach_px(disc_kwargs: dict, angle: float, diameter: float) -> float:
    aperture = make_aperture(disc_kwargs["shape"], angle, blades=disc_kwargs.get("blades"))
    return aperture.extent() * diameter * math.sqrt(math.pi) / 2.0


def gradient(width: int, height: int, low: float = GRADIENT[0], high: float = GRADIENT[1]) -> np.ndarray:
    return np.linspace(low, high, width, dtype=np.float32)[None, :].repeat(height, axis=0)


def shelf_layout(shapes, diameters, seed):
    """Every shape at every diameter, largest cells first, packed in rows; returns (truth, width, height)."""
    rng = np.random.default_rng(seed)
    items = []
    for shape in shapes:
        for diameter in diameters:
            kwargs = shape_kwargs(shape)
            angle = float(rng.uniform(0.0, 360.0))
            cell = math.ceil(CELL_FACTOR * (reach_px(kwargs, angle, diameter) + 2.0 * EDGE_BLUR_PX)) + CELL_MARGIN_PX
            items.append((cell, diameter, kwargs, angle, float(rng.uniform(*BRIGHTNESS))))
    items.sort(key=lambda item: -item[0])
    width = max(items[0][0], math.ceil(1.05 * math.sqrt(sum(item[0] ** 2 for item in items))))
    truth = []
    x = y = row_height = 0
    for cell, diameter, kwargs, angle, brightness in items:
        if x + cell > width:
            x, y, row_height = 0, y + row_height, 0
        row_height = max(row_height, cell)
        centre = (x + cell / 2 + rng.uniform(-0.5, 0.5), y + cell / 2 + rng.uniform(-0.5, 0.5))
        aperture = make_aperture(angle_deg=angle, **kwargs)
        truth.append(SyntheticDisc(centre, float(diameter), aperture, brightness=brightness))
        x += cell
    return truth, width, y + row_height


def match(found, truth):
    """Pairs (true disc, found disc or None): nearest found centre within max(2, d/4), as in the tests."""
    pairs = []
    for t in truth:
        best = min(found, key=lambda d: math.dist(d.center_xy, t.center_xy), default=None)
        if best is not None and math.dist(best.center_xy, t.center_xy) <= max(2.0, t.diameter_px / 4):
            pairs.append((t, best))
        else:
            pairs.append((t, None))
    return pairs


def band_of(diameter: float) -> str:
    """The band a diameter falls in, bands split at the geometric means of neighbouring limits."""
    for (low, high), (next_low, _) in itertools.pairwise(BANDS):
        if diameter < math.sqrt(high * next_low):
            return f"{low}–{high}"
    return f"{BANDS[-1][0]}–{BANDS[-1][1]}"


def jpeg_bytes(linear: np.ndarray, quality: int) -> bytes:
    ok, data = cv2.imencode(".jpg", encode_srgb8(linear), [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise RuntimeError("cv2.imencode failed")
    return data.tobytes()


def search_condition(condition: str, linear: np.ndarray, workdir: Path, name: str):
    """(search, load_s) for one image through one condition."""
    if condition == "linear":
        return find_discs(linear, linear >= 1.0), 0.0
    quality = int(condition.removeprefix("jpeg q"))
    path = workdir / f"{name}_q{quality}.jpg"
    path.write_bytes(jpeg_bytes(linear, quality))
    start = time.perf_counter()
    photo = load_photo(path)
    load_s = time.perf_counter() - start
    return find_discs(photo.luminance, photo.clipped), load_s


def summarise(records, false_positives):
    """One row of figures for a set of per-true-disc records and the unmatched found discs counted against it."""
    matched = [r for r in records if r["found"]]
    errors = [r["rel_error"] for r in matched]
    centres = [r["centre_error_px"] for r in matched]
    n_found = len(matched) + false_positives
    return dict(
        n=len(records),
        matched=len(matched),
        false_positives=false_positives,
        recall=len(matched) / len(records) if records else math.nan,
        precision=len(matched) / n_found if n_found else math.nan,
        median_rel_error=float(np.median(errors)) if errors else math.nan,
        p95_rel_error=float(np.percentile(errors, 95)) if errors else math.nan,
        median_centre_error_px=float(np.median(centres)) if centres else math.nan,
        usable_share=sum(r["usable"] for r in matched) / len(matched) if matched else math.nan,
    )


def synthetic(shapes, diameters, replicates):
    conditions = ["linear"] + [f"jpeg q{q}" for q in QUALITIES]
    records, unmatched = [], []
    stats = {c: dict(load_s=0.0, detect_s=0.0, megapixels=0.0, candidates=0, beyond_limit=0) for c in conditions}
    with tempfile.TemporaryDirectory(prefix="bokehfit_discs_bench_") as tmp:
        for replicate in range(replicates):
            truth, width, height = shelf_layout(shapes, diameters, seed=100 + replicate)
            linear = render_discs(
                width, height, truth, background=gradient(width, height), edge_blur_px=EDGE_BLUR_PX,
                noise_sigma=NOISE_SIGMA, seed=200 + replicate,
            )
            for condition in conditions:
                search, load_s = search_condition(condition, linear, Path(tmp), f"r{replicate}")
                stats[condition]["load_s"] += load_s
                stats[condition]["detect_s"] += search.time_s
                stats[condition]["megapixels"] += width * height / 1e6
                stats[condition]["candidates"] += search.candidates
                stats[condition]["beyond_limit"] += search.rejected.get("beyond the candidate limit", 0)
                pairs = match(search.discs, truth)
                used = set()
                for t, f in pairs:
                    record = dict(
                        condition=condition, replicate=replicate, shape=t.aperture.shape, diameter_px=t.diameter_px,
                        angle_deg=round(t.aperture.angle_deg, 3), brightness=round(t.brightness, 4),
                        found=f is not None,
                    )
                    if f is not None:
                        used.add(id(f))
                        record.update(
                            found_diameter_px=float(f.diameter_px),
                            rel_error=abs(f.diameter_px - t.diameter_px) / t.diameter_px,
                            centre_error_px=math.dist(f.center_xy, t.center_xy),
                            usable=bool(f.usable), saturated=bool(f.saturated), clipped=bool(f.clipped),
                            overlaps=bool(f.overlaps),
                        )
                    records.append(record)
                for f in search.discs:
                    if id(f) not in used:
                        unmatched.append(dict(condition=condition, replicate=replicate, center_xy=list(map(float, f.center_xy)),
                                              diameter_px=float(f.diameter_px)))
    band_rows, shape_rows = [], []
    for condition in conditions:
        mine = [r for r in records if r["condition"] == condition]
        extra = [u for u in unmatched if u["condition"] == condition]
        for low, high in BANDS:
            name = f"{low}–{high}"
            chosen = [r for r in mine if low <= r["diameter_px"] <= high]
            if not chosen:
                continue
            fp = sum(band_of(u["diameter_px"]) == name for u in extra)
            band_rows.append(dict(condition=condition, band=name, **summarise(chosen, fp)))
            if low == BANDS[0][0] and any(r["shape"] == "slit" for r in chosen):
                no_slit = [r for r in chosen if r["shape"] != "slit"]
                band_rows.append(dict(condition=condition, band=f"{name} no slit", **summarise(no_slit, fp)))
        band_rows.append(dict(condition=condition, band="all", **summarise(mine, len(extra))))
        for shape in shapes:
            chosen = [r for r in mine if r["shape"] == shape]
            shape_rows.append(dict(condition=condition, shape=shape, **summarise(chosen, 0)))
    return band_rows, shape_rows, records, unmatched, stats


def finite_or_none(value):
    """JSON-safe copy: NaN → None, numpy scalars → Python numbers."""
    if isinstance(value, dict):
        return {k: finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_none(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def fmt(value, spec):
    return "—" if value is None or (isinstance(value, float) and math.isnan(value)) else format(value, spec)


def print_band_table(rows):
    print(f"{'condition':<10}{'band px':<14}{'n':>5}{'recall':>8}{'prec':>7}{'FP':>4}"
          f"{'|Δd|/d med':>12}{'p95':>8}{'ctr px med':>12}{'usable':>8}")
    for r in rows:
        print(f"{r['condition']:<10}{r['band']:<14}{r['n']:>5}{fmt(r['recall'], '.3f'):>8}{fmt(r['precision'], '.3f'):>7}"
              f"{r['false_positives']:>4}{fmt(r['median_rel_error'], '.2%'):>12}{fmt(r['p95_rel_error'], '.2%'):>8}"
              f"{fmt(r['median_centre_error_px'], '.3f'):>12}{fmt(r['usable_share'], '.0%'):>8}")


def print_shape_table(rows):
    print(f"{'condition':<10}{'shape':<10}{'n':>5}{'recall':>8}{'|Δd|/d med':>12}{'p95':>8}{'ctr px med':>12}{'usable':>8}")
    for r in rows:
        print(f"{r['condition']:<10}{r['shape']:<10}{r['n']:>5}{fmt(r['recall'], '.3f'):>8}"
              f"{fmt(r['median_rel_error'], '.2%'):>12}{fmt(r['p95_rel_error'], '.2%'):>8}"
              f"{fmt(r['median_centre_error_px'], '.3f'):>12}{fmt(r['usable_share'], '.0%'):>8}")


def timing_scene(seed=11):
    """About TIMING_DISCS discs, log-uniform diameters, cycling shapes, placed at random without overlaps."""
    rng = np.random.default_rng(seed)
    width, height = TIMING_SIZE
    shapes = [name for name, spec in SHAPES.items() if not spec.tabulated]  # a mask needs its image: outlines only
    placed, truth = [], []
    attempts = 0
    while len(truth) < TIMING_DISCS and attempts < 100_000:
        attempts += 1
        diameter = float(math.exp(rng.uniform(*np.log(TIMING_DIAMETERS))))
        kwargs = shape_kwargs(shapes[len(truth) % len(shapes)])
        angle = float(rng.uniform(0, 360))
        reach = reach_px(kwargs, angle, diameter) + 2.0
        centre = (float(rng.uniform(reach + 4, width - reach - 4)), float(rng.uniform(reach + 4, height - reach - 4)))
        if any(math.dist(centre, c) < 1.6 * (reach + r) + 8 for c, r in placed):
            continue
        placed.append((centre, reach))
        aperture = make_aperture(angle_deg=angle, **kwargs)
        truth.append(SyntheticDisc(centre, diameter, aperture, brightness=float(rng.uniform(*BRIGHTNESS))))
    return truth, width, height


def _timed_load_and_search(path: str) -> dict:
    """Runs in a fresh process: peak RSS (KiB) before, after loading, after searching; times; found discs."""
    def peak():
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss

    before = peak()
    start = time.perf_counter()
    photo = load_photo(path)
    load_s = time.perf_counter() - start
    after_load = peak()
    search = find_discs(photo.luminance, photo.clipped)
    after_detect = peak()
    return dict(
        width=photo.width, height=photo.height, load_s=load_s, detect_s=search.time_s, candidates=search.candidates,
        rejected=dict(search.rejected),
        peak_rss_kib_before=before, peak_rss_kib_after_load=after_load, peak_rss_kib_after_detect=after_detect,
        discs=[dict(center_xy=list(map(float, d.center_xy)), diameter_px=float(d.diameter_px), usable=d.usable)
               for d in search.discs],
    )


def timing_24mp():
    truth, width, height = timing_scene()
    start = time.perf_counter()
    linear = render_discs(width, height, truth, background=gradient(width, height), edge_blur_px=EDGE_BLUR_PX,
                          noise_sigma=NOISE_SIGMA, seed=12)
    data = jpeg_bytes(linear, TIMING_QUALITY)
    del linear
    make_s = time.perf_counter() - start
    with tempfile.TemporaryDirectory(prefix="bokehfit_discs_bench_") as tmp:
        path = Path(tmp) / "timing_24mp.jpg"
        path.write_bytes(data)
        # A forkserver started before anything large was allocated: ru_maxrss survives fork and exec on
        # Linux, so a child forked or spawned from this process would report this process's peak.
        context = multiprocessing.get_context("forkserver")
        with concurrent.futures.ProcessPoolExecutor(max_workers=1, mp_context=context) as pool:
            result = pool.submit(_timed_load_and_search, str(path)).result()
    megapixels = result["width"] * result["height"] / 1e6

    class Found:  # match() wants objects with center_xy
        def __init__(self, d):
            self.center_xy = tuple(d["center_xy"])

    discs = result.pop("discs")
    pairs = match([Found(d) for d in discs], truth)
    result.update(
        megapixels=megapixels, jpeg_bytes=len(data), true_discs=len(truth), make_s=make_s, discs_found=len(discs),
        matched=sum(f is not None for _, f in pairs), detect_s_per_mp=result["detect_s"] / megapixels,
        load_s_per_mp=result["load_s"] / megapixels,
    )
    return result


def real_photos(folder: Path):
    rows = []
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".jpg", ".jpeg") and p.is_file())
    for path in files:
        start = time.perf_counter()
        photo = load_photo(path)
        load_s = time.perf_counter() - start
        search = find_discs(photo.luminance, photo.clipped)
        discs = search.discs
        rows.append(dict(
            file=path.name, width=photo.width, height=photo.height, colour_space=photo.colour_space,
            candidates=search.candidates, found=len(discs), usable=sum(d.usable for d in discs),
            saturated=sum(d.saturated for d in discs), overlapping=sum(d.overlaps for d in discs),
            median_diameter_px=float(np.median([d.diameter_px for d in discs])) if discs else math.nan,
            load_s=load_s, detect_s=search.time_s,
            rejected=dict(search.rejected),
        ))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="3 shapes × 3 diameters, no 24-MP timing")
    parser.add_argument("--replicates", type=int, help="synthetic images per condition (default 8, --quick 3)")
    parser.add_argument("--json", help="write all rows as JSON here")
    args = parser.parse_args()
    shapes = QUICK_SHAPES if args.quick else tuple(SHAPES)
    diameters = QUICK_DIAMETERS if args.quick else DIAMETERS
    replicates = args.replicates or (3 if args.quick else 8)
    total_start = time.perf_counter()
    if not args.quick:
        multiprocessing.forkserver.ensure_running()  # before the big allocations (see timing_24mp)

    print(f"bokehfit disc finder benchmark{' (--quick)' if args.quick else ''}")
    print(f"  {platform.python_implementation()} {platform.python_version()}, numpy {np.__version__}, "
          f"OpenCV {cv2.__version__} ({cv2.getNumThreads()} threads), {os.cpu_count()} CPUs, {platform.machine()}")

    start = time.perf_counter()
    band_rows, shape_rows, records, unmatched, stats = synthetic(shapes, diameters, replicates)
    synthetic_s = time.perf_counter() - start
    print()
    print(f"1. Synthetic: {len(shapes)} shapes × {len(diameters)} diameters × {replicates} replicate(s), "
          f"gradient {GRADIENT[0]}→{GRADIENT[1]}, noise σ {NOISE_SIGMA}, edge blur {EDGE_BLUR_PX} px "
          f"({synthetic_s:.1f} s)")
    for condition, s in stats.items():
        print(f"  {condition:<9}{s['megapixels']:.2f} MP searched, load {s['load_s']:.2f} s, "
              f"detect {s['detect_s']:.2f} s ({s['detect_s'] / s['megapixels']:.3f} s/MP), "
              f"{s['candidates']} candidates measured, {s['beyond_limit']} beyond the limit")
    print()
    print_band_table(band_rows)
    print()
    print_shape_table(shape_rows)

    timing = None
    print()
    if args.quick:
        print("2. 24-MP timing: skipped (--quick)")
    else:
        timing = timing_24mp()
        t = timing
        print(f"2. Time per megapixel: {t['width']}×{t['height']} ({t['megapixels']:.1f} MP) JPEG q{TIMING_QUALITY}, "
              f"{t['jpeg_bytes'] / 1e6:.1f} MB, {t['true_discs']} discs of {TIMING_DIAMETERS[0]:g}–{TIMING_DIAMETERS[1]:g} px "
              f"(made in {t['make_s']:.1f} s), fresh process")
        print(f"  load_s {t['load_s']:.2f}  detect_s {t['detect_s']:.2f}  detect {t['detect_s_per_mp']:.3f} s/MP  "
              f"load {t['load_s_per_mp']:.3f} s/MP")
        print(f"  discs found {t['discs_found']}, matched {t['matched']}/{t['true_discs']}; candidates measured "
              f"{t['candidates']}; rejected: " + ", ".join(f"{n} {why}" for why, n in t["rejected"].items()))
        print(f"  peak RSS (ru_maxrss): before load {t['peak_rss_kib_before'] / 1024:.0f} MiB, "
              f"after load {t['peak_rss_kib_after_load'] / 1024:.0f} MiB, "
              f"after detect {t['peak_rss_kib_after_detect'] / 1024:.0f} MiB")

    real = None
    print()
    folder = os.environ.get("BOKEHFIT_REFERENCE_DIR")
    if not folder:
        print("3. Real photos: skipped (set BOKEHFIT_REFERENCE_DIR to a folder of JPEGs)")
    elif not Path(folder).is_dir():
        print(f"3. Real photos: skipped ({folder} is not a folder)")
    else:
        real = real_photos(Path(folder))
        print(f"3. Real photos in {folder}")
        print(f"{'file':<52}{'size':>11}{'cands':>6}{'found':>7}{'usable':>8}{'satur':>7}{'overlap':>9}{'med d px':>10}"
              f"{'load_s':>8}{'detect_s':>10}")
        for r in real:
            print(f"{r['file'][:51]:<52}{r['width']:>5}×{r['height']:<5}{r['candidates']:>6}{r['found']:>7}{r['usable']:>8}{r['saturated']:>7}"
                  f"{r['overlapping']:>9}{fmt(r['median_diameter_px'], '.1f'):>10}{r['load_s']:>8.2f}{r['detect_s']:>10.2f}")

    total_s = time.perf_counter() - total_start
    print()
    print(f"total {total_s:.1f} s")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(finite_or_none(dict(
                quick=args.quick, shapes=list(shapes), diameters=list(diameters), replicates=replicates,
                noise_sigma=NOISE_SIGMA, edge_blur_px=EDGE_BLUR_PX, gradient=list(GRADIENT), qualities=list(QUALITIES),
                synthetic_bands=band_rows, synthetic_shapes=shape_rows, synthetic_stats=stats,
                synthetic_discs=records, synthetic_unmatched=unmatched, timing_24mp=timing, real_photos=real,
                total_s=total_s,
            )), f, indent=1)


if __name__ == "__main__":
    main()
