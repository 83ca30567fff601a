"""``bokehfit bench``: speed against error, measured side by side in one run.

(a) :mod:`bokehfit.bench.kernels`: kernel error (L1 against the exact
kernel) against render time for every kernel method, and each method's
convergence rate; (b) :mod:`bokehfit.bench.fit`: fit error (shape accuracy,
angle error, diameter error) against the time spent fitting, on a fixed
synthetic set; (c) :mod:`bokehfit.bench.compare`: ``compare`` on a 24-MP JPEG,
its time split by stage, warm and cold. :mod:`bokehfit.bench.report` prints the
tables and builds the HTML page with the plots.

:func:`run_bench` returns the whole result as plain JSON data (``schema_version``
:data:`SCHEMA_VERSION`). ``quick=True`` is the CI size: samples 1e3–1e6, one disc
size, a 2-photo fit set with two budgets and a 4-MP photo; it finishes in well
under a minute on two CPU cores with lavapipe. ``parts`` runs only some of
(a), (b), (c): a part not run leaves its keys empty (lists empty, ``compare`` None).

Example
-------
>>> from bokehfit.bench import run_bench
>>> result = run_bench(quick=True)  # doctest: +SKIP
>>> sorted(result)[:3]  # doctest: +SKIP
['bokehfit_version', 'command_line', 'compare']
"""

from __future__ import annotations

import math
import os
import platform
import time
from typing import Callable

from bokehfit.errors import InputError

__all__ = ["PARTS", "SCHEMA_VERSION", "run_bench"]

#: Version of the result layout; keys are added, never renamed, within one version.
SCHEMA_VERSION = 1
#: The parts of the bench, by letter (module notes).
PARTS = "abc"


def _device(adapter=None) -> dict:
    from bokehfit.gpu import get_gpu
    from bokehfit.kernels.raster import gl_renderer

    gpu = get_gpu(adapter)
    return {"adapter": gpu.adapter_name, "backend": gpu.backend, "gl_renderer": gl_renderer()}


def run_bench(
    quick: bool = False,
    *,
    progress: Callable[[int, int, str], None] | None = None,
    command_line: str | None = None,
    max_point_s: float | None = None,
    adapter=None,
    parts: str = PARTS,
) -> dict:
    """Run parts (a), (b) and (c) and return every figure as a JSON-ready dict.

    Parameters
    ----------
    quick : bool
        The CI size (see the module notes).
    progress : callable, optional
        Called with (done, total, what) after each step.
    command_line : str, optional
        Recorded in the result (default ``"bokehfit bench"`` plus ``--quick``).
    max_point_s : float, optional
        Cut-off of one kernel's predicted render time (default
        :data:`bokehfit.bench.kernels.MAX_POINT_S`).
    adapter : bokehfit.gpu.AdapterChoice, optional
        The WebGPU adapter of the GPU kernels and of compare (the best one found by default).
    parts : str
        The parts to run, letters of ``PARTS`` (default all: ``"abc"``; ``"c"`` only compare).

    Returns
    -------
    dict
        ``schema_version``, ``bokehfit_version``, ``command_line``, ``quick``,
        ``parts``, ``platform``, ``device`` {adapter, backend, gl_renderer}, ``settings``,
        ``kernel`` (rows), ``rates``, ``kernel_skipped``, ``kernel_devices``,
        ``fit`` (rows), ``fit_set``, ``fit_misses``, ``compare``, ``notes`` and
        ``runtime_s`` {kernel, fit, compare (those run), total}.

    Raises
    ------
    InputError
        When ``parts`` is empty or holds a letter other than a, b, c.
    """
    if not isinstance(parts, str) or not parts or set(parts) - set(PARTS):
        raise InputError(f"parts must be one or more of the letters {', '.join(PARTS)} (got {parts!r})")
    from bokehfit import __version__
    from bokehfit.bench import compare as compare_part
    from bokehfit.bench import fit as fit_part
    from bokehfit.bench import kernels as kernel_part

    started = time.perf_counter()
    shapes = kernel_part.BENCH_APERTURES
    diameters = kernel_part.QUICK_DIAMETERS_PX if quick else kernel_part.DIAMETERS_PX
    samples = kernel_part.QUICK_SAMPLES if quick else kernel_part.SAMPLES
    cut_off = kernel_part.MAX_POINT_S if max_point_s is None else max_point_s
    total = ((kernel_part.kernel_steps(shapes, diameters, samples) if "a" in parts else 0)
             + (fit_part.fit_steps(quick) if "b" in parts else 0)
             + (compare_part.compare_steps() if "c" in parts else 0))
    done = 0

    def step(what: str) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(min(done, total), total, what)

    device = _device(adapter)
    runtime = {}
    kernels = {"rows": [], "rates": [], "skipped": [], "devices": {}, "notes": []}
    fits = {"rows": [], "description": "", "misses": {}}
    compared = None
    if "a" in parts:
        clock = time.perf_counter()
        kernels = kernel_part.kernel_sweep(shapes, diameters, samples, max_point_s=cut_off, progress=step, adapter=adapter)
        runtime["kernel"] = time.perf_counter() - clock
    if "b" in parts:
        clock = time.perf_counter()
        fits = fit_part.budget_sweep(quick, progress=step)
        runtime["fit"] = time.perf_counter() - clock
    if "c" in parts:
        clock = time.perf_counter()
        compared = compare_part.compare_timing(quick, progress=step, adapter=adapter)
        runtime["compare"] = time.perf_counter() - clock
    runtime["total"] = time.perf_counter() - started
    return {
        "schema_version": SCHEMA_VERSION,
        "bokehfit_version": __version__,
        "command_line": command_line or ("bokehfit bench --quick" if quick else "bokehfit bench"),
        "quick": quick,
        "parts": "".join(part for part in PARTS if part in parts),
        "platform": {"python": platform.python_version(), "machine": platform.machine(), "cpus": os.cpu_count()},
        "device": device,
        "settings": {
            "shapes": list(shapes),
            "diameters_px": list(diameters),
            "samples": list(samples),
            "angle_deg": kernel_part.ANGLE_DEG,
            "max_point_s": cut_off if math.isfinite(cut_off) else None,
            "budgets": list(fit_part.QUICK_BUDGETS if quick else fit_part.BUDGETS),
        },
        "kernel": kernels["rows"],
        "rates": kernels["rates"],
        "kernel_skipped": kernels["skipped"],
        "kernel_devices": kernels["devices"],
        "fit": fits["rows"],
        "fit_set": fits["description"],
        "fit_misses": fits["misses"],
        "compare": compared,
        "notes": kernels["notes"],
        "runtime_s": runtime,
    }
