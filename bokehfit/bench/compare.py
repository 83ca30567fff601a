"""Part (c) of ``bokehfit bench``: ``compare`` on a large photo, its time split by stage.

The photo (``BIG``: 6000 × 4000, 24 MP; quick: ``QUICK``, 4 MP) is a synthetic
JPEG of non-overlapping pentagon discs at 20° with log-uniform equal-area
diameters, brightness 0.3–0.9, on a 0.01 → 0.05 gradient with noise σ = 0.003.
It is made once and kept in a cache folder (``BOKEHFIT_CACHE_DIR``, else
``$XDG_CACHE_HOME/bokehfit`` or ``~/.cache/bokehfit``, else the temporary
folder), under a name that holds a hash of its recipe.

Three calls of :func:`bokehfit.compare.compare_photo`, all with the photo's
geometry (``GEOMETRY``):

1. **cold**: in a fresh Python process, the first call on the big photo. Its
   ``timing_s["total"]`` is ``cold_total_s`` (it pays for lazy imports, the GPU
   adapter and device, shader compilation); the import of
   ``bokehfit.compare`` before it (NumPy is already imported by then) and the
   process's whole life, interpreter start-up included, are reported beside it.
2. **warm-up**: in this process, one call on a small photo (``WARMUP``), so the
   GPU start-up and imports are paid for.
3. **warm**: in this process, the call on the big photo whose
   ``Comparison.timing_s`` (load, detect, fit, render, metrics, total) is reported.
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
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np

__all__ = ["BIG", "QUICK", "WARMUP", "GEOMETRY", "STAGES", "PhotoSpec", "cache_dir", "cached_photo", "compare_timing"]


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
RECIPE_VERSION = 1
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
    reach = make_aperture(spec.shape, spec.angle_deg).extent() * math.sqrt(math.pi) / 2  # per px of diameter
    discs: list = []
    for _ in range(MAX_PLACEMENT_TRIES):
        diameter = float(math.exp(rng.uniform(*np.log(spec.diameters_px))))
        r = reach * diameter
        centre = (float(rng.uniform(r + 10, spec.width - r - 10)), float(rng.uniform(r + 10, spec.height - r - 10)))
        if all(math.dist(centre, d.center_xy) > 1.5 * (r + reach * d.diameter_px) + 10 for d in discs):
            discs.append(SyntheticDisc(centre, diameter, spec.shape, spec.angle_deg,
                                       brightness=float(rng.uniform(0.3, 0.9))))
            if len(discs) == spec.discs:
                break
    if len(discs) < spec.discs:
        raise ValueError(f"could not place {spec.discs} discs on a {spec.width}×{spec.height} photo")
    background = np.linspace(0.01, 0.05, spec.width, dtype=np.float32)[None, :].repeat(spec.height, axis=0)
    linear = render_discs(spec.width, spec.height, discs, background=background, noise_sigma=0.003, seed=spec.seed + 1)
    write_jpeg(path, linear, spec.quality)


def cached_photo(spec: PhotoSpec) -> tuple[Path, float | None]:
    """The photo of ``spec`` from the cache, made first if missing; (path, seconds spent making it or None)."""
    key = hashlib.sha1(json.dumps([RECIPE_VERSION, asdict(spec)], sort_keys=True).encode()).hexdigest()[:12]
    path = cache_dir() / f"compare_{spec.width}x{spec.height}_{key}.jpg"
    if path.is_file():
        return path, None
    start = time.perf_counter()
    make_photo(spec, path)
    return path, time.perf_counter() - start


def _cold_child() -> None:
    """Runs in a fresh process: ``argv[1]`` the photo, ``argv[2]`` the geometry,
    ``argv[3]`` the adapter choice's (name, backend); one JSON line out."""
    start = time.perf_counter()
    from bokehfit.compare import compare_photo
    from bokehfit.gpu import AdapterChoice

    imported = time.perf_counter() - start
    comparison = compare_photo(sys.argv[1], **json.loads(sys.argv[2]), adapter=AdapterChoice(*json.loads(sys.argv[3])))
    print(json.dumps({"import_s": imported, "timing_s": comparison.timing_s, "process_s": time.perf_counter() - start}))


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
    return 4


def compare_timing(quick: bool = False, progress: Callable[[str], None] | None = None, adapter=None) -> dict:
    """Time ``compare`` on the big photo (quick: the 4-MP one): cold, then warm by stage.

    ``adapter`` (a :class:`bokehfit.gpu.AdapterChoice`) chooses the GPU of the kernel.

    Returns a dict with ``megapixels``, ``load_s``, ``detect_s``, ``fit_s``, ``render_s``,
    ``metrics_s``, ``total_s`` (the warm call), ``cold_total_s``, and beside them the
    photo, the cold call's import and process times, the warm-up call and what was found.
    """
    from bokehfit.compare import compare_photo

    notify = progress or (lambda what: None)
    spec = QUICK if quick else BIG
    path, made_s = cached_photo(spec)
    warmup_path, _ = cached_photo(WARMUP)
    notify(f"compare: {spec.megapixels:.0f}-MP photo ready")
    cold = cold_compare(path, adapter)
    notify("compare: cold call (fresh process)")
    warmup = compare_photo(warmup_path, **GEOMETRY, adapter=adapter)
    notify("compare: warm-up call")
    comparison = compare_photo(path, **GEOMETRY, adapter=adapter)
    notify("compare: warm call")
    fit = comparison.fit
    result = {"megapixels": round(spec.megapixels, 3)}
    result.update({f"{stage}_s": comparison.timing_s.get(stage) for stage in STAGES})
    result.update(
        cold_total_s=cold["timing_s"]["total"],
        cold_import_s=cold["import_s"],
        cold_process_s=cold["wall_s"],
        cold_stages_s={stage: cold["timing_s"].get(stage) for stage in STAGES},
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
        device=dict(comparison.device),
    )
    return result
