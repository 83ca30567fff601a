"""Part (c) of ``bokehfit bench``: ``compare`` on a large photo, its time split by stage.

The photo (``BIG``: 6000 × 4000, 24 MP; quick: ``QUICK``, 4 MP) is a synthetic
camera-like JPEG: RGB, sRGB-encoded, 4:2:0 chroma, quality 90, of
non-overlapping pentagon discs at 20° with log-uniform equal-area diameters,
each in the colour of a light (``LIGHT_COLOURS``, brightest channel 0.3–0.9)
on a dusk-coloured gradient (``BACKGROUND``, luminance about 0.01 → 0.05) with
noise σ = 0.003 per channel. It is made once and kept in a cache folder
(``BOKEHFIT_CACHE_DIR``, else ``$XDG_CACHE_HOME/bokehfit`` or
``~/.cache/bokehfit``, else the temporary folder), under a name that holds a
hash of its recipe.

Beside the calls of :func:`bokehfit.compare.compare_photo` (all with the
photo's geometry, ``GEOMETRY``), the bare decode of the same file,
``cv2.imread``, best of ``DECODE_REPEATS``, is the yardstick:

1. **cold**: in a fresh Python process, the first call on the big photo. Its
   ``timing_s`` by stage is reported, with the import of ``bokehfit.compare``
   before it and the process's whole life, interpreter start-up included
   (``cold_process_s``, the figure the target is for). The process also
   reports its peak memory: its peak resident set size after the call
   (Linux ``VmHWM``) minus its resident set size before it (``VmRSS``, after
   the imports, before the photo is opened), over the photo's pixel count
   (``peak_bytes_per_px``).
2. **warm-up**: in this process, one call on a small photo (``WARMUP``), so the
   imports and any GPU start-up are paid for.
3. **warm**: in this process, the call on the big photo whose
   ``Comparison.timing_s`` (load, detect, fit, render, metrics, total) is reported.

``TARGETS`` are the aims of the 24-MP photo on two CPU cores, printed beside
the figures and judged only where that photo was measured: ``--quick``'s 4-MP
photo spends a larger share in costs that do not shrink with the pixels (the
imports, the fit of each disc), so it is judged against no target
(``targets`` is empty and ``targets_note`` says why).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

__all__ = [
    "BIG",
    "QUICK",
    "WARMUP",
    "GEOMETRY",
    "STAGES",
    "TARGETS",
    "PhotoSpec",
    "cache_dir",
    "cached_photo",
    "compare_timing",
    "decode_time",
]


@dataclass(frozen=True)
class PhotoSpec:
    """The recipe of one synthetic timing photo (the cache key is its hash)."""

    width: int
    height: int
    discs: int
    diameters_px: tuple[float, float]
    seed: int
    shape: str = "pentagon"
    angle_deg: float = 20.0
    quality: int = 90

    @property
    def megapixels(self) -> float:
        return self.width * self.height / 1e6


BIG = PhotoSpec(6000, 4000, 50, (15.0, 150.0), seed=24)
QUICK = PhotoSpec(2448, 1632, 20, (15.0, 100.0), seed=4)
WARMUP = PhotoSpec(640, 480, 6, (15.0, 40.0), seed=1)
#: Camera geometry passed to compare_photo, so that the f-stop stage runs too.
GEOMETRY = dict(focal_length_mm=50.0, sensor_width_mm=36.0, focus_distance_m=2.0)
STAGES = ("load", "detect", "fit", "render", "metrics", "total")
#: Bump when the way the photo is drawn changes (invalidates the cache).
#: 2: RGB, coloured lights on a coloured gradient, 4:2:0 (1 was grey).
RECIPE_VERSION = 2
#: Linear RGB of the lights, brightest channel 1 (scaled by each disc's brightness):
#: sodium lamp, tungsten, white LED, blue LED, green and red traffic lights.
LIGHT_COLOURS = ((1.0, 0.55, 0.15), (1.0, 0.72, 0.42), (0.95, 0.97, 1.0), (0.45, 0.65, 1.0),
                 (0.35, 1.0, 0.6), (1.0, 0.25, 0.2))
#: Linear RGB of the background at the left and right edges (a dusk sky: luminance ≈ 0.011 → 0.05).
BACKGROUND = ((0.012, 0.010, 0.020), (0.060, 0.045, 0.040))
#: Decodes of the photo timed; the fastest is the yardstick.
DECODE_REPEATS = 3
#: Aims for the 24-MP photo on two CPU cores (issue 14): seconds, ratios to the bare decode, bytes per pixel.
TARGETS = {
    "warm_s": 1.5,
    "warm_over_decode": 13.0,
    "cold_process_s": 2.5,
    "load_detect_over_decode": 3.0,
    "peak_bytes_per_px": 12.0,
}
#: Disc centres tried before giving up on placing all discs without overlap.
MAX_PLACEMENT_TRIES = 100_000


def cache_dir() -> Path:
    """Folder for the generated photos, created if missing (see the module notes)."""
    candidates = []
    if os.environ.get("BOKEHFIT_CACHE_DIR"):
        candidates.append(Path(os.environ["BOKEHFIT_CACHE_DIR"]))
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    candidates += [Path(base) / "bokehfit", Path(tempfile.gettempdir()) / "bokehfit-cache"]
    for folder in candidates:
        folder = folder / "bench"
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError:
            continue
        if os.access(folder, os.W_OK):
            return folder
    raise OSError(f"no writable cache folder among {', '.join(str(c) for c in candidates)}")


def make_photo(spec: PhotoSpec, path: Path) -> None:
    """Draw the photo of ``spec`` and write it as JPEG at ``path`` (atomically)."""
    from bokehfit.apertures import make_aperture
    from bokehfit.bench.fit import write_jpeg
    from bokehfit.synthetic import SyntheticDisc, render_discs

    rng = np.random.default_rng(spec.seed)
    aperture = make_aperture(spec.shape, spec.angle_deg)
    reach = aperture.extent() * math.sqrt(math.pi) / 2  # per px of diameter
    discs: list = []
    colours: list = []
    for _ in range(MAX_PLACEMENT_TRIES):
        diameter = float(math.exp(rng.uniform(*np.log(spec.diameters_px))))
        r = reach * diameter
        centre = (float(rng.uniform(r + 10, spec.width - r - 10)), float(rng.uniform(r + 10, spec.height - r - 10)))
        if all(math.dist(centre, d.center_xy) > 1.5 * (r + reach * d.diameter_px) + 10 for d in discs):
            discs.append(SyntheticDisc(centre, diameter, aperture, brightness=float(rng.uniform(0.3, 0.9))))
            colours.append(LIGHT_COLOURS[int(rng.integers(len(LIGHT_COLOURS)))])
            if len(discs) == spec.discs:
                break
    if len(discs) < spec.discs:
        raise ValueError(f"could not place {spec.discs} discs on a {spec.width}×{spec.height} photo")
    linear = np.empty((spec.height, spec.width, 3), dtype=np.float32)
    for channel in range(3):
        left, right = BACKGROUND[0][channel], BACKGROUND[1][channel]
        background = np.linspace(left, right, spec.width, dtype=np.float32)[None, :].repeat(spec.height, axis=0)
        tinted = [replace(disc, brightness=disc.brightness * colour[channel]) for disc, colour in zip(discs, colours)]
        linear[..., channel] = render_discs(spec.width, spec.height, tinted, background=background, noise_sigma=0.003,
                                            seed=spec.seed + 1 + channel)
    write_jpeg(path, linear, spec.quality)


def decode_time(path: Path, repeats: int = DECODE_REPEATS) -> float:
    """Seconds of the fastest of ``repeats`` bare decodes of ``path`` with ``cv2.imread``."""
    import cv2

    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        image = cv2.imread(str(path))
        best = min(best, time.perf_counter() - start)
        if image is None:
            raise OSError(f"cv2.imread could not decode {path}")
        del image
    return best


def cached_photo(spec: PhotoSpec) -> tuple[Path, float | None]:
    """The photo of ``spec`` from the cache, made first if missing; (path, seconds spent making it or None)."""
    key = hashlib.sha1(json.dumps([RECIPE_VERSION, asdict(spec)], sort_keys=True).encode()).hexdigest()[:12]
    path = cache_dir() / f"compare_{spec.width}x{spec.height}_{key}.jpg"
    if path.is_file():
        return path, None
    start = time.perf_counter()
    make_photo(spec, path)
    return path, time.perf_counter() - start


def _memory_bytes() -> tuple[int, int]:
    """(resident set size now, its peak so far) of this process, in bytes.

    Linux: ``VmRSS`` and ``VmHWM`` of ``/proc/self/status`` (both of this
    process's own memory map, so a child started with exec doesn't inherit its
    parent's peak, as ``ru_maxrss`` does); elsewhere ``getrusage``'s
    ``ru_maxrss`` (bytes on macOS) for both.
    """
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            fields = dict(line.split(":", 1) for line in status if ":" in line)
        return int(fields["VmRSS"].split()[0]) * 1024, int(fields["VmHWM"].split()[0]) * 1024
    except (OSError, KeyError, ValueError):
        import resource

        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        peak = int(peak if sys.platform == "darwin" else peak * 1024)
        return peak, peak


def _cold_child() -> None:
    """Runs in a fresh process: ``argv[1]`` the photo, ``argv[2]`` the geometry,
    ``argv[3]`` the adapter choice's (name, backend); one JSON line out."""
    start = time.perf_counter()
    from bokehfit.compare import compare_photo
    from bokehfit.gpu import AdapterChoice

    imported = time.perf_counter() - start
    before, _ = _memory_bytes()
    comparison = compare_photo(sys.argv[1], **json.loads(sys.argv[2]), adapter=AdapterChoice(*json.loads(sys.argv[3])))
    print(json.dumps({"import_s": imported, "timing_s": comparison.timing_s, "process_s": time.perf_counter() - start,
                      "rss_before_bytes": before, "rss_peak_bytes": _memory_bytes()[1],
                      "kernel_method": comparison.kernel.method if comparison.kernel is not None else None}))


def cold_compare(path: Path, adapter=None) -> dict:
    """The first compare_photo call of a fresh Python process on ``path``, on ``adapter``."""
    code = "from bokehfit.bench.compare import _cold_child; _cold_child()"
    choice = json.dumps([adapter.name, adapter.backend] if adapter is not None else ["", ""])
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", code, str(path), json.dumps(GEOMETRY), choice],
                          capture_output=True, text=True, timeout=1800)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"the cold compare process failed (exit {done.returncode}):\n{done.stderr.strip()}")
    result = json.loads(done.stdout.strip().splitlines()[-1])
    result["wall_s"] = wall
    return result


def compare_steps() -> int:
    """Steps of :func:`compare_timing`, for a progress bar."""
    return 5


def _ratio(numerator: float | None, denominator: float) -> float | None:
    return None if numerator is None or not denominator > 0 else numerator / denominator


def compare_timing(quick: bool = False, progress: Callable[[str], None] | None = None, adapter=None) -> dict:
    """Time ``compare`` on the big photo (quick: the 4-MP one): cold, then warm by stage, beside the bare decode.

    ``adapter`` (a :class:`bokehfit.gpu.AdapterChoice`) chooses the GPU of the kernel
    when its method is one that runs on a GPU.

    Returns a dict with ``megapixels``, ``load_s``, ``detect_s``, ``fit_s``, ``render_s``,
    ``metrics_s``, ``total_s`` (the warm call), ``cold_total_s``, ``decode_s`` (the bare
    ``cv2.imread``, best of :data:`DECODE_REPEATS`), ``warm_over_decode``,
    ``load_detect_over_decode``, ``peak_bytes_per_px`` (module notes), ``targets``, and
    beside them the photo, the cold call's import and process times, the warm-up call,
    the kernel's method and what was found.
    """
    from bokehfit.compare import compare_photo

    notify = progress or (lambda what: None)
    spec = QUICK if quick else BIG
    path, made_s = cached_photo(spec)
    warmup_path, _ = cached_photo(WARMUP)
    notify(f"compare: {spec.megapixels:.0f}-MP photo ready")
    decode_s = decode_time(path)
    notify("compare: bare decode")
    cold = cold_compare(path, adapter)
    notify("compare: cold call (fresh process)")
    warmup = compare_photo(warmup_path, **GEOMETRY, adapter=adapter)
    notify("compare: warm-up call")
    comparison = compare_photo(path, **GEOMETRY, adapter=adapter)
    notify("compare: warm call")
    fit = comparison.fit
    timing = comparison.timing_s
    pixels = spec.width * spec.height
    result = {"megapixels": round(spec.megapixels, 3)}
    result.update({f"{stage}_s": timing.get(stage) for stage in STAGES})
    result.update(
        cold_total_s=cold["timing_s"]["total"],
        cold_import_s=cold["import_s"],
        cold_process_s=cold["wall_s"],
        cold_stages_s={stage: cold["timing_s"].get(stage) for stage in STAGES},
        decode_s=decode_s,
        warm_over_decode=_ratio(timing.get("total"), decode_s),
        load_detect_over_decode=_ratio(timing.get("load", 0.0) + timing.get("detect", 0.0), decode_s),
        peak_bytes=cold["rss_peak_bytes"] - cold["rss_before_bytes"],
        peak_bytes_per_px=(cold["rss_peak_bytes"] - cold["rss_before_bytes"]) / pixels,
        rss_before_bytes=cold["rss_before_bytes"],
        rss_peak_bytes=cold["rss_peak_bytes"],
        targets=dict(TARGETS) if spec == BIG else {},
        targets_photo=f"{BIG.megapixels:.0f} MP ({BIG.width}×{BIG.height})",
        targets_note=None if spec == BIG else (
            f"the targets are set for the {BIG.megapixels:.0f}-MP photo of `bokehfit bench`; this run measured a "
            f"{spec.megapixels:.1f}-MP photo, so none is judged (run `bokehfit bench --parts c` to judge them)"),
        warmup_total_s=warmup.timing_s["total"],
        warmup_megapixels=round(WARMUP.megapixels, 3),
        width=spec.width,
        height=spec.height,
        discs_drawn=spec.discs,
        discs_found=len(comparison.search.discs),
        discs_usable=sum(d.usable for d in comparison.search.discs),
        discs_fitted=len(fit.disc_fits) if fit else 0,
        aperture=fit.aperture.describe() if fit else None,
        truth=f"{spec.shape} {spec.angle_deg:g}°",
        photo=str(path),
        photo_bytes=path.stat().st_size,
        photo_made_s=made_s,
        colour="RGB, 4:2:0",
        kernel_method=comparison.kernel.method if comparison.kernel is not None else None,
        cold_kernel_method=cold["kernel_method"],
        device=dict(comparison.device),
    )
    return result
