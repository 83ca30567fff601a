"""Part (b) of ``bokehfit bench``: fit error against the time spent fitting.

A fixed synthetic set: one photo per shape of ``SHAPES`` and per replicate
(``REPLICATES``; quick: ``QUICK_SHAPES`` × 1), each with ``DISCS_PER_PHOTO``
discs of one size (lights at one distance, as the f-stop assumes; the size
log-uniform in ``FIT_DIAMETERS``) and one random angle, brightness
``FIT_BRIGHTNESS`` (so the discs' SNR differs), noise σ = ``FIT_NOISE``, through
a quality-``FIT_QUALITY`` JPEG and :func:`bokehfit.io.load_photo` (fixed seeds).
Discs are found once per photo. The budget knob is
``FitOptions.max_discs`` (the most discs fitted): for each value of
``BUDGETS``, :func:`bokehfit.fit.fit_aperture` runs over all families on every
photo with ``options=FitOptions(max_discs=budget)``.

Per budget: ``budget_s``, the mean wall time of one ``fit_aperture`` call
per photo; ``shape_accuracy``, the share of photos whose
family is right; the median (and largest) error of the aperture angle modulo
its symmetry (photos whose family is right, circles left out); the median (and
largest) |fitted − true| / true of the aperture's equal-area diameter
(``ApertureFit.diameter_px``, which the f-stop is computed from).
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np

__all__ = [
    "BUDGETS",
    "QUICK_BUDGETS",
    "QUICK_SHAPES",
    "SHAPES",
    "budget_sweep",
    "fit_photo",
    "fit_set",
    "fit_steps",
    "grid_layout",
    "score",
    "write_jpeg",
]

#: (shape, blades) of the full set, and of the quick one.
SHAPES = (("circle", None), ("square", None), ("slit", None), ("triangle", None), ("pentagon", None),
          ("hexagon", None), ("star", None), ("ngon", 9))
QUICK_SHAPES = (("hexagon", None), ("star", None))
REPLICATES = 2
QUICK_REPLICATES = 1
BUDGETS = (2, 4, 8, 12)
QUICK_BUDGETS = (2, 6)
DISCS_PER_PHOTO = 14
FIT_DIAMETERS = (10.0, 40.0)
FIT_BRIGHTNESS = (0.15, 0.9)
FIT_NOISE = 0.012
FIT_QUALITY = 70
SLIT_ASPECT = 0.3
#: A disc's square cell is this many times its reach (largest outline radius), plus CELL_MARGIN_PX.
CELL_FACTOR = 2.8
CELL_MARGIN_PX = 12


def family_name(shape: str, blades: int | None) -> str:
    """The fit's name of a shape: ``hexagon``, ``ngon(9)`` (:attr:`bokehfit.apertures.Aperture.label`)."""
    from bokehfit.apertures import make_aperture

    return make_aperture(shape, blades=blades).label


def grid_layout(shape, blades, aspect, angle, diameters, rng, brightness=(0.3, 0.9)):
    """Discs in a square grid of equal cells sized for the largest; returns (truth, width, height)."""
    from bokehfit.apertures import make_aperture
    from bokehfit.synthetic import SyntheticDisc

    aperture = make_aperture(shape, angle, blades=blades, aspect=aspect)
    cell = math.ceil(CELL_FACTOR * aperture.extent() * max(diameters) * math.sqrt(math.pi) / 2) + CELL_MARGIN_PX
    columns = math.ceil(math.sqrt(len(diameters)))
    rows = math.ceil(len(diameters) / columns)
    truth = []
    for i, diameter in enumerate(diameters):
        row, column = divmod(i, columns)
        centre = ((column + 0.5) * cell + rng.uniform(-2, 2), (row + 0.5) * cell + rng.uniform(-2, 2))
        truth.append(SyntheticDisc(centre, float(diameter), aperture, brightness=float(rng.uniform(*brightness))))
    return truth, columns * cell, rows * cell


def write_jpeg(path: Path, linear: np.ndarray, quality: int) -> None:
    """Encode a linear-light image, (H, W) grey or (H, W, 3) RGB, as an sRGB JPEG of the given quality, atomically."""
    import cv2

    from bokehfit.outputs import write_bytes_atomic
    from bokehfit.synthetic import encode_srgb8

    encoded = encode_srgb8(linear)
    options = [cv2.IMWRITE_JPEG_QUALITY, quality]
    if encoded.ndim == 3:
        encoded = np.ascontiguousarray(encoded[..., ::-1])  # RGB → OpenCV's BGR
        options += [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420]  # chroma halved, as cameras do
    ok, data = cv2.imencode(".jpg", encoded, options)
    if not ok:
        raise OSError(f"could not encode {path} as JPEG")
    write_bytes_atomic(Path(path), data.tobytes())


def fit_photo(shape: str, blades: int | None, replicate: int, index: int, folder: Path) -> dict:
    """One photo of the set (seeded by replicate and index), written as JPEG, loaded and searched."""
    from bokehfit.apertures import make_aperture
    from bokehfit.discs import find_discs
    from bokehfit.io import load_photo
    from bokehfit.synthetic import render_discs

    rng = np.random.default_rng(1000 * replicate + index)
    aspect = SLIT_ASPECT if make_aperture(shape, blades=blades).has_aspect else None
    angle = float(rng.uniform(0.0, 360.0))
    diameter = float(np.exp(rng.uniform(*np.log(FIT_DIAMETERS))))
    truth, width, height = grid_layout(shape, blades, aspect, angle, [diameter] * DISCS_PER_PHOTO, rng, FIT_BRIGHTNESS)
    background = np.linspace(0.01, 0.05, width, dtype=np.float32)[None, :].repeat(height, axis=0)
    linear = render_discs(width, height, truth, background=background, noise_sigma=FIT_NOISE,
                          seed=5000 + 100 * replicate + index)
    path = Path(folder) / f"{family_name(shape, blades)}_{replicate}.jpg"
    write_jpeg(path, linear, FIT_QUALITY)
    photo = load_photo(path)
    search = find_discs(photo.luminance, photo.clipped)
    return dict(name=family_name(shape, blades), shape=shape, angle=angle, diameter=diameter,
                luminance=photo.luminance, discs=search.discs,
                usable=sum(d.usable for d in search.discs), size=(width, height))


def fit_set(shapes, replicates, folder: Path, progress: Callable[[str], None] | None = None) -> list[dict]:
    """The fixed synthetic photos (see the module notes), in the order replicate, shape."""
    photos = []
    for replicate in range(replicates):
        for index, (shape, blades) in enumerate(shapes):
            photos.append(fit_photo(shape, blades, replicate, index, folder))
            if progress is not None:
                progress(f"fit set: {family_name(shape, blades)} #{replicate}")
    return photos


def score(fit, photo) -> dict:
    """Right family?, angle error (degrees, modulo symmetry) and relative diameter error of one fit."""
    from bokehfit.metrics import angle_error

    if not fit:
        return dict(correct=False, angle_error=None, diameter_error=None)
    correct = fit.aperture.is_named(photo["name"])
    angle = None
    if correct and fit.aperture.has_angle:
        angle = angle_error(fit.aperture.angle_deg, photo["angle"], fit.aperture.symmetry_deg)
    return dict(correct=correct, angle_error=angle, diameter_error=abs(fit.diameter_px - photo["diameter"]) / photo["diameter"])


def fit_steps(quick: bool) -> int:
    """Steps of :func:`budget_sweep` (photos made, then fits), for a progress bar."""
    shapes, replicates, budgets = _plan(quick)
    photos = len(shapes) * replicates
    return photos * (len(budgets) + 1)


def _plan(quick: bool):
    return (QUICK_SHAPES, QUICK_REPLICATES, QUICK_BUDGETS) if quick else (SHAPES, REPLICATES, BUDGETS)


def _median_max(values: list[float]) -> tuple[float | None, float | None]:
    return (float(np.median(values)), float(np.max(values))) if values else (None, None)


def budget_sweep(quick: bool = False, progress: Callable[[str], None] | None = None) -> dict:
    """Make the fit set, then fit it at every budget; returns rows, misses and the set's description.

    Each row holds ``budget_s``, ``max_fit_discs``, ``shape_accuracy``, ``angle_err_deg``,
    ``diameter_err`` (medians) and ``correct``, ``photos``, ``angle_err_max_deg``,
    ``diameter_err_max``, ``fit_max_s``. Angle and diameter errors are None where no
    photo qualifies.
    """
    import bokehfit.fit as fitting

    notify = progress or (lambda what: None)
    shapes, replicates, budgets = _plan(quick)
    with tempfile.TemporaryDirectory(prefix="bokehfit_bench_fit_") as tmp:
        photos = fit_set(shapes, replicates, Path(tmp), notify)
    rows, misses = [], {}
    for budget in budgets:
        results, times = [], []
        options = fitting.FitOptions(max_discs=budget)
        for photo in photos:
            start = time.perf_counter()
            fit = fitting.fit_aperture(photo["luminance"], photo["discs"], options=options)
            times.append(time.perf_counter() - start)
            result = score(fit, photo)
            results.append(result)
            if not result["correct"]:
                misses.setdefault(str(budget), []).append(f"{photo['name']}→{fit.family.name if fit else 'none'}")
            notify(f"fit {photo['name']} at max_discs={budget}")
        angle, angle_max = _median_max([r["angle_error"] for r in results if r["angle_error"] is not None])
        diameter, diameter_max = _median_max([r["diameter_error"] for r in results if r["diameter_error"] is not None])
        correct = sum(r["correct"] for r in results)
        rows.append(dict(
            budget_s=float(np.mean(times)),
            max_fit_discs=budget,
            shape_accuracy=correct / len(results),
            angle_err_deg=angle,
            diameter_err=diameter,
            correct=correct,
            photos=len(results),
            angle_err_max_deg=angle_max,
            diameter_err_max=diameter_max,
            fit_max_s=float(np.max(times)),
        ))
    usable = [p["usable"] for p in photos]
    description = (
        f"{len(photos)} photos ({', '.join(family_name(*s) for s in shapes)} × {replicates}), "
        f"{DISCS_PER_PHOTO} discs each of one size in {FIT_DIAMETERS[0]:g}–{FIT_DIAMETERS[1]:g} px, "
        f"noise σ {FIT_NOISE}, JPEG q{FIT_QUALITY}; clean discs found per photo: {min(usable)}–{max(usable)}"
    )
    return dict(rows=rows, misses=misses, photos=len(photos), description=description)
