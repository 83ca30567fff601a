"""The main job, the pipeline: photo → discs → fitted aperture → rendered kernel → metrics (design.md §7).

:func:`compare_photo` runs the stages in turn (load, detect, fit, render, metrics),
judges the fit (:func:`bokehfit.judging.judge`) and returns a
:class:`~bokehfit.comparison.Comparison`: the one result object that the JSON
document, the text summary and the HTML report are all rendered from, on every
outcome. :func:`disc_metrics` measures each fitted disc's outline against the
matched kernel's. The f-stop is :mod:`bokehfit.optics`'s, the words a person reads
:mod:`bokehfit.words`'s.
"""

from __future__ import annotations

import hashlib
import math
import os
import time

import numpy as np
from skimage import measure

from bokehfit.comparison import Comparison
from bokehfit.discs import COMPARE_MIN_DIAMETER_PX, DiscSearch, find_discs, measure_discs_at
from bokehfit.discs.labels import DiscLabels, read_labels
from bokehfit.errors import InputError
from bokehfit.fit import ApertureFit, FitOptions, fit_aperture
from bokehfit.fit.features import FAINT_CONTRAST_REL, SMALL_DISC_PX
from bokehfit.gpu import AdapterChoice
from bokehfit.io import Photo, load_photo
from bokehfit.io.colour import luminance_weights
from bokehfit.judging import MIN_ACCEPTABLE_IOU, MIN_SURE_DISCS, MIN_SURE_IOU, judge
from bokehfit.kernels import AUTO, Kernel, compute_kernel
from bokehfit.kernels.exact import coverage
from bokehfit.metrics import METRICS, MetricOptions, angle_error, compare_outlines
from bokehfit.metrics.outlines import resample
from bokehfit.optics import FStop, estimate_fstop, resolve_geometry

__all__ = [
    "ALIGNMENT_SEARCH_DEG",
    "FAINT_CONTRAST_REL",
    "KERNEL_TOLERANCE",
    "METRIC_POINTS",
    "MIN_ACCEPTABLE_IOU",
    "MIN_SURE_DISCS",
    "MIN_SURE_IOU",
    "SMALL_DISC_PX",
    "Comparison",
    "compare_photo",
    "disc_metrics",
    "judge",
]

#: L1 tolerance of the matched kernel: its 50 % outline is what the metrics use. It is
#: drawn by the cheapest method that meets it, the start-up of a GPU included
#: (``method="auto"``: ``exact`` for any usual disc, which starts no GPU), and a
#: sampling method's sample count follows from its convergence model.
KERNEL_TOLERANCE = 0.01
#: Points each outline is resampled to (evenly along its length) before the metrics.
METRIC_POINTS = 256
#: The kernel is drawn at the fitted angle, so each disc's best alignment with
#: it is searched within this many degrees (not at all where the aperture's
#: outline turns alike: :attr:`bokehfit.apertures.Aperture.turns_alike`).
ALIGNMENT_SEARCH_DEG = 10.0
# The thresholds that judge a fit (MIN_SURE_IOU, ...) are bokehfit.judging's, those of small and faint discs
# (SMALL_DISC_PX, FAINT_CONTRAST_REL) bokehfit.fit.features', read by the pipeline's judge and by the result's
# verdict alike; they are importable from here too.


def _kernel_outline(kernel: Kernel) -> np.ndarray:
    """The kernel's 50 % outline as (x, y) = (column, row) points: a chromatic kernel's luminance,
    which the discs' outlines were measured in (the channels with sRGB's weights, summing to 1)."""
    image = kernel.image if kernel.image.ndim == 2 else kernel.image @ np.asarray(luminance_weights("sRGB"), np.float32)
    return _half_outline(image, kernel.diameter_px)


def _half_outline(image: np.ndarray, diameter_px: float) -> np.ndarray:
    """The 50 % outline of a unit-sum disc image of equal-area ``diameter_px``, as (x, y) points."""
    area_px = math.pi * diameter_px**2 / 4.0
    contours = measure.find_contours(np.pad(image / max(float(image.sum()), 1e-300), 1), 0.5 / area_px)
    longest = max(contours, key=len)
    return resample(longest[:, ::-1] - 1.0, METRIC_POINTS)


def _shown_outline(fitted, diameter_px: float) -> np.ndarray:
    """The 50 % outline of the aperture as one disc shows it: at its place in the frame (the
    vignetting's cut) and turned where the disc is (a near disc of an odd shape), exact coverage."""
    scale = diameter_px * math.sqrt(math.pi) / 2.0
    size = 2 * math.ceil(fitted.aperture.extent() * scale) + 9
    where = fitted.field_position if fitted.aperture.vignetting is not None else None
    return _half_outline(coverage(fitted.aperture, scale, size, field_position=where), diameter_px)


def disc_metrics(comparison_fit: ApertureFit, kernel_outline: np.ndarray) -> dict[int, dict[str, float]]:
    """Every metric between each fitted disc's outline and the matched kernel's outline.

    Where the kernel is not what a disc shows (the vignetting cuts it at its place
    in the frame; a near disc of an odd shape shows it turned), the disc is
    compared with its own exact outline of the fitted aperture instead. Each disc is turned to
    its best alignment with that outline (within ``ALIGNMENT_SEARCH_DEG``) where the outline has
    a rotation to align: not a plain circle's (:attr:`bokehfit.apertures.Aperture.turns_alike`).
    """
    out = {}
    symmetry = comparison_fit.aperture.symmetry_deg
    seen = comparison_fit.seen_angle_deg
    for item in comparison_fit.disc_fits:
        fitted = item.fits[comparison_fit.family.name]
        # the kernel's colours do not change its (luminance) outline
        own = fitted.aperture != comparison_fit.seen_aperture.replace(chromatic=None) or fitted.aperture.vignetting is not None
        reference = _shown_outline(fitted, comparison_fit.diameter_px) if own else kernel_outline
        # A round outline needs no alignment: its rotation search was 57 % of a disc's metrics.
        options = MetricOptions(align=not fitted.aperture.turns_alike, rotation_within_deg=ALIGNMENT_SEARCH_DEG)
        values = compare_outlines(resample(item.disc.outline_xy, METRIC_POINTS), reference, options=options)
        own = item.own if item.own is not None else fitted
        if symmetry is not None and own.angle_deg is not None and seen is not None:
            shown = seen + (180.0 if item.turned else 0.0)
            values["angle_error_deg"] = angle_error(own.angle_deg, shown, symmetry)
        out[item.disc.index] = values
    return out


def compare_photo(
    path: str | os.PathLike,
    *,
    shapes: list[str] | None = None,
    focus_side: str = "unknown",
    lens_model: str = "thin",
    size_convention: str = "equal-area",
    focal_length_mm: float | None = None,
    sensor_width_mm: float | None = None,
    focus_distance_m: float | None = None,
    light_distance_m: float = math.inf,
    min_diameter_px: float = COMPARE_MIN_DIAMETER_PX,
    max_diameter_px: float = 500.0,
    fit_options: FitOptions | None = None,
    discs: str | os.PathLike | DiscLabels | None = None,
    progress=None,
    adapter: AdapterChoice | None = None,
) -> Comparison:
    """Run every stage of ``bokehfit compare`` on one photo.

    ``progress``, when given, is called with a stage name as each one starts
    and with (done, total) while discs are fitted. ``min_diameter_px`` is the
    detection's: by default the smallest disc that shows a shape (``RESOLVABLE_PX``);
    with ``bokehfit discs``'s 4 px both find the same discs, and those under
    ``RESOLVABLE_PX`` are found but not usable. ``fit_options`` is
    the fit's budget (:class:`bokehfit.fit.FitOptions`); ``adapter`` chooses
    the GPU of the kernel (:func:`bokehfit.gpu.get_gpu`). ``discs`` (a discs
    file in the labels' format, :mod:`bokehfit.discs.labels`, or its
    :class:`DiscLabels`) replaces the search: its usable discs, and only
    those, are measured afresh at their places and fitted.
    Raises ``InputError`` for unreadable input; every other outcome is a
    Comparison with its ``status`` and ``reason``.
    """
    notify = progress or (lambda *args: None)
    timing = {}
    start = time.perf_counter()
    notify("load")
    photo = load_photo(path)
    geometry = resolve_geometry(
        photo,
        focal_length_mm=focal_length_mm,
        sensor_width_mm=sensor_width_mm,
        focus_distance_m=focus_distance_m,
        light_distance_m=light_distance_m,
    )
    timing["load"] = time.perf_counter() - start
    notify("detect")
    search = _detect(photo, discs, min_diameter_px, max_diameter_px)
    timing["detect"] = search.time_s
    notify("fit")
    fit = fit_aperture(photo.luminance, search.discs, shapes=shapes, focus_side=focus_side, options=fit_options,
                       progress=progress, clipped=photo.clipped, rgb=photo.linear_rgb)
    timing["fit"] = fit.time_s
    kernel = None
    fstop = FStop(None, None, "no aperture was fitted", size_convention, lens_model, exif_fnumber=photo.exif.fnumber)
    metrics: dict[str, float | None] = {name: None for name in METRICS}
    per_disc: dict[int, dict[str, float]] = {}
    device = {"adapter": None, "backend": None}
    if fit:
        fstop = estimate_fstop(fit, photo, geometry, lens_model, size_convention, focus_side)
        notify("render")
        kernel = _matched_kernel(fit, adapter)
        timing["render"] = kernel.time_s + kernel.setup_s
        device = _device(kernel)
        notify("metrics")
        started = time.perf_counter()
        per_disc, metrics = _matched_metrics(fit, kernel)
        timing["metrics"] = time.perf_counter() - started
    timing["total"] = time.perf_counter() - start
    comparison = Comparison(photo, search, fit, kernel, geometry, fstop, per_disc, metrics, timing, device)
    if fit:
        comparison.doubts, comparison.rejection = judge(fit, metrics)
    return comparison


def _detect(photo: Photo, discs: str | os.PathLike | DiscLabels | None, min_diameter_px: float,
            max_diameter_px: float) -> DiscSearch:
    """The photo's discs: found by the search, or (given a discs file) measured afresh at its usable discs' places."""
    if discs is None:
        return find_discs(photo.luminance, photo.clipped, min_diameter_px=min_diameter_px,
                          max_diameter_px=max_diameter_px, rgb=photo.linear_rgb)
    labels = discs if isinstance(discs, DiscLabels) else read_labels(discs)
    _check_labels_photo(labels, photo)
    return measure_discs_at(photo.luminance, photo.clipped,
                            [(disc.center_xy, disc.diameter_px) for disc in labels.usable])


def _matched_kernel(fit: ApertureFit, adapter: AdapterChoice | None) -> Kernel:
    """The kernel of the reported aperture as the discs show it: the consensus angle (turned back for
    near discs), drawn by the cheapest method that meets :data:`KERNEL_TOLERANCE`."""
    scale = fit.diameter_px * math.sqrt(math.pi) / 2.0
    size = 2 * math.ceil(fit.aperture.extent() * scale) + 9
    return compute_kernel(
        fit.seen_aperture,
        diameter_px=fit.diameter_px,
        size=size,
        method=AUTO,
        tolerance=KERNEL_TOLERANCE,
        adapter=adapter,
    )


def _matched_metrics(fit: ApertureFit, kernel: Kernel) -> tuple[dict[int, dict[str, float]], dict[str, float | None]]:
    """Every metric between each fitted disc and the matched kernel, and each one's median over the discs."""
    per_disc = disc_metrics(fit, _kernel_outline(kernel))
    return per_disc, {name: float(np.median([values[name] for values in per_disc.values()])) for name in METRICS}


def _device(kernel: Kernel) -> dict[str, str | None]:
    """The adapter and backend that drew the kernel (both None on the CPU), from its "adapter (backend)"."""
    adapter, _, backend = (kernel.device or "").rpartition(" (")
    return {"adapter": adapter or None, "backend": backend.rstrip(")") or None}


def _check_labels_photo(labels: DiscLabels, photo: Photo) -> None:
    """``InputError`` where a discs file names another photo (its size or its sha256)."""
    height, width = photo.luminance.shape
    if labels.width is not None and labels.height is not None and (labels.width, labels.height) != (width, height):
        raise InputError(f"the discs file is for a {labels.width}×{labels.height} photo; "
                         f"{photo.path.name} is {width}×{height}")
    if labels.sha256 is not None:
        digest = hashlib.sha256()
        with open(photo.path, "rb") as file:
            for block in iter(lambda: file.read(1 << 20), b""):
                digest.update(block)
        if digest.hexdigest() != labels.sha256.lower():
            raise InputError(f"the discs file is for another photo (its sha256 is not {photo.path.name}'s)")
