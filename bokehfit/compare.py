"""The main job: photo → discs → fitted aperture → rendered kernel → metrics (design.md §7).

:func:`compare_photo` runs the stages and returns a :class:`Comparison`, which
converts to the ``bokehfit compare --json`` document (schema_version 1).
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field

import numpy as np
from skimage import measure

from bokehfit import __version__
from bokehfit.discs import DiscSearch, find_discs
from bokehfit.discs.measure import RESOLVABLE_PX
from bokehfit.errors import InputError
from bokehfit.fit import ApertureFit, fit_aperture
from bokehfit.io import Photo, load_photo
from bokehfit.kernels import Kernel, compute_kernel
from bokehfit.metrics import METRICS, angle_error, compare_outlines
from bokehfit.metrics.outlines import resample
from bokehfit.optics import LENS_MODELS, SIZE_CONVENTIONS, circumscribed_fstop, fstop_from_coc, pixel_pitch_mm

__all__ = ["SCHEMA_VERSION", "Geometry", "FStop", "Comparison", "compare_photo", "estimate_fstop", "judge", "resolve_geometry"]

SCHEMA_VERSION = 1
#: L1 tolerance of the matched kernel rendered on the GPU: its 50 % outline is
#: what the metrics use, and the sample count follows from the convergence model.
KERNEL_TOLERANCE = 0.01
#: Points each outline is resampled to (evenly along its length) before the metrics.
METRIC_POINTS = 256
#: A fit is acceptable when the discs match the kernel at least this well (median IoU) ...
MIN_ACCEPTABLE_IOU = 0.6
#: ... and sure when, besides a clear BIC margin, they match this well with at least MIN_SURE_DISCS discs.
MIN_SURE_IOU = 0.85
MIN_SURE_DISCS = 3
#: The kernel is drawn at the fitted angle, so each disc's best alignment with
#: it is searched within this many degrees.
ALIGNMENT_SEARCH_DEG = 10.0


@dataclass(frozen=True)
class Geometry:
    """What the f-stop needs, with where each value came from."""

    focal_length_mm: float | None
    sensor_width_mm: float | None
    focus_distance_m: float | None
    light_distance_m: float
    sources: dict[str, str]

    def to_json(self) -> dict:
        return {
            "focal_length_mm": self.focal_length_mm,
            "sensor_width_mm": self.sensor_width_mm,
            "focus_distance_m": self.focus_distance_m,
            "light_distance_m": None if math.isinf(self.light_distance_m) else self.light_distance_m,
            "sources": self.sources,
        }


@dataclass(frozen=True)
class FStop:
    """The f-stop estimate, or None with the reason."""

    value: float | None
    uncertainty: float | None
    reason: str | None
    convention: str
    lens_model: str


@dataclass
class Comparison:
    """Everything ``compare`` found; ``to_json`` gives the design.md §7 document."""

    photo: Photo
    search: DiscSearch
    fit: ApertureFit
    kernel: Kernel | None
    geometry: Geometry
    fstop: FStop
    disc_metrics: dict[int, dict[str, float]] = field(default_factory=dict)
    metrics: dict[str, float | None] = field(default_factory=dict)
    timing_s: dict[str, float] = field(default_factory=dict)
    device: dict[str, str | None] = field(default_factory=dict)
    doubts: list[str] = field(default_factory=list)  #: why the fit is unsure (empty when sure)
    rejection: str | None = None  #: why no acceptable fit was found (None when there is one)

    @property
    def acceptable(self) -> bool:
        return bool(self.fit) and self.rejection is None

    def aperture_json(self) -> dict:
        fit = self.fit
        aperture = fit.aperture
        symmetry = aperture.symmetry_deg
        blades = aperture.blades
        return {
            "shape": aperture.shape,
            "blades": blades,
            "aspect": aperture.aspect,
            "angle_deg": None if symmetry is None else round(aperture.canonical_angle_deg, 3),
            "symmetry_deg": symmetry,
            "angle_uncertainty_deg": None if fit.angle_uncertainty_deg is None else round(fit.angle_uncertainty_deg, 4),
            "diameter_px": round(fit.diameter_px, 3),
            "diameter_uncertainty_px": round(fit.diameter_uncertainty_px, 3),
            "edge_blur_px": round(fit.blur_px, 3),
            "fstop": None if self.fstop.value is None else round(self.fstop.value, 3),
            "fstop_uncertainty": None if self.fstop.uncertainty is None else round(self.fstop.uncertainty, 3),
            "fstop_reason": self.fstop.reason,
            "size_convention": self.fstop.convention,
            "lens_model": self.fstop.lens_model,
            "focus_side": fit.focus_side,
            "angle_note": _angle_note(fit),
            "sure": not self.doubts,
            "doubts": self.doubts,
            "message": fit.message,
            "candidates": [c.to_json() for c in fit.candidates],
        }

    def to_json(self, command_line: str) -> dict:
        used = {item.disc.index for item in self.fit.disc_fits}
        discs = []
        for disc in self.search.discs:
            fitted = self.fit.disc_fit(disc)
            entry = disc.to_json()
            entry["used"] = disc.index in used
            if fitted is not None:
                entry["angle_deg"] = None if fitted.angle_deg is None else round(fitted.angle_deg, 3)
                entry["fit_diameter_px"] = round(fitted.diameter_px, 3)
            entry.update({k: _round(v) for k, v in self.disc_metrics.get(disc.index, {}).items()})
            discs.append(entry)
        return {
            "schema_version": SCHEMA_VERSION,
            "bokehfit_version": __version__,
            "command_line": command_line,
            "input": self.photo.input_json(),
            "geometry": self.geometry.to_json(),
            "aperture": self.aperture_json(),
            "discs": discs,
            "metrics": {k: _round(v) for k, v in self.metrics.items()},
            "timing_s": {k: round(v, 4) for k, v in self.timing_s.items()},
            "device": self.device,
        }


def _round(value):
    return None if value is None or not math.isfinite(value) else round(float(value), 5)


def _angle_note(fit: ApertureFit) -> str | None:
    aperture = fit.aperture
    symmetry = aperture.symmetry_deg
    if symmetry is None or fit.focus_side != "unknown" or (180.0 % symmetry) == 0.0:
        return None
    other = (aperture.angle_deg + 180.0) % symmetry
    return (
        f"odd symmetry: lights behind the focus plane give {aperture.canonical_angle_deg:.2f}°, "
        f"lights in front of it {other:.2f}° (pass --focus-side to choose)"
    )


def resolve_geometry(
    photo: Photo,
    *,
    focal_length_mm: float | None = None,
    sensor_width_mm: float | None = None,
    focus_distance_m: float | None = None,
    light_distance_m: float = math.inf,
) -> Geometry:
    """The geometry from the command line where given, else from EXIF."""
    exif = photo.exif
    sources = {}

    def pick(name, given, from_exif, exif_source):
        if given is not None:
            sources[name] = "command line"
            return float(given)
        if from_exif is not None:
            sources[name] = exif_source
            return float(from_exif)
        sources[name] = "unknown"
        return None

    focal = pick("focal_length_mm", focal_length_mm, exif.focal_length_mm, "EXIF FocalLength")
    sensor = pick("sensor_width_mm", sensor_width_mm, exif.sensor_width_mm, f"EXIF: {exif.sensor_width_source}")
    focus = pick("focus_distance_m", focus_distance_m, exif.focus_distance_m, "EXIF focus distance")
    sources["light_distance_m"] = "command line" if not math.isinf(light_distance_m) else "default (infinity)"
    return Geometry(focal, sensor, focus, light_distance_m, sources)


def estimate_fstop(fit: ApertureFit, photo: Photo, geometry: Geometry, lens_model: str, convention: str) -> FStop:
    """The aperture's f-stop from the fitted diameter, or None with the reason."""
    if lens_model not in LENS_MODELS:
        raise InputError(f"lens model must be one of {', '.join(LENS_MODELS)} (got {lens_model!r})")
    if convention not in SIZE_CONVENTIONS:
        raise InputError(f"size convention must be one of {', '.join(SIZE_CONVENTIONS)} (got {convention!r})")
    missing = [name for name in ("focal_length_mm", "sensor_width_mm", "focus_distance_m") if getattr(geometry, name) is None]
    if missing:
        flags = ", ".join("--" + name.replace("_", "-") for name in missing)
        return FStop(None, None, f"unknown {', '.join(missing)} (give {flags})", convention, lens_model)
    pitch = pixel_pitch_mm(geometry.sensor_width_mm, photo.width, photo.height)
    value = fstop_from_coc(
        fit.diameter_px * pitch, geometry.focal_length_mm, geometry.focus_distance_m, geometry.light_distance_m, lens_model
    )
    if convention == "circumscribed":
        value = circumscribed_fstop(value, fit.aperture)
    relative = fit.diameter_uncertainty_px / fit.diameter_px if fit.diameter_px else 0.0
    return FStop(value, value * relative, None, convention, lens_model)


def _kernel_outline(kernel: Kernel) -> np.ndarray:
    """The kernel's 50 % outline as (x, y) = (column, row) points."""
    image = kernel.image
    area_px = math.pi * kernel.diameter_px**2 / 4.0
    contours = measure.find_contours(np.pad(image, 1), 0.5 / area_px)
    longest = max(contours, key=len)
    return resample(longest[:, ::-1] - 1.0, METRIC_POINTS)


def disc_metrics(comparison_fit: ApertureFit, kernel_outline: np.ndarray) -> dict[int, dict[str, float]]:
    """Every metric between each fitted disc's outline and the matched kernel's outline."""
    out = {}
    symmetry = comparison_fit.aperture.symmetry_deg
    seen = comparison_fit.candidates[0].angle_deg
    for item in comparison_fit.disc_fits:
        values = compare_outlines(
            resample(item.disc.outline_xy, METRIC_POINTS), kernel_outline, rotation_within_deg=ALIGNMENT_SEARCH_DEG
        )
        fitted = item.fits[comparison_fit.family.name]
        if symmetry is not None and fitted.angle_deg is not None and seen is not None:
            values["angle_error_deg"] = angle_error(fitted.angle_deg, seen, symmetry)
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
    min_diameter_px: float = RESOLVABLE_PX,
    max_diameter_px: float = 500.0,
    progress=None,
) -> Comparison:
    """Run every stage of ``bokehfit compare`` on one photo.

    ``progress``, when given, is called with a stage name as each one starts
    and with (done, total) while discs are fitted.
    Raises ``InputError`` for unreadable input; a photo with no fittable disc
    returns a Comparison whose ``fit`` is falsy.
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
    search = find_discs(photo.luminance, photo.clipped, min_diameter_px=min_diameter_px, max_diameter_px=max_diameter_px)
    timing["detect"] = search.time_s
    notify("fit")
    fit = fit_aperture(photo.luminance, search.discs, shapes=shapes, focus_side=focus_side, progress=progress)
    timing["fit"] = fit.time_s
    kernel = None
    fstop = FStop(None, None, "no aperture was fitted", size_convention, lens_model)
    metrics: dict[str, float | None] = {name: None for name in METRICS}
    per_disc: dict[int, dict[str, float]] = {}
    device = {"adapter": None, "backend": None}
    if fit:
        fstop = estimate_fstop(fit, photo, geometry, lens_model, size_convention)
        notify("render")
        aperture = fit.aperture
        seen_angle = fit.candidates[0].angle_deg or 0.0
        scale = fit.diameter_px * math.sqrt(math.pi) / 2.0
        size = 2 * math.ceil(aperture.extent() * scale) + 9
        kernel = compute_kernel(
            aperture.shape,
            seen_angle,
            fit.diameter_px,
            size,
            method="mc",
            tolerance=KERNEL_TOLERANCE,
            blades=aperture.blades if aperture.shape == "ngon" else None,
            aspect=aperture.aspect,
        )
        timing["render"] = kernel.time_s + kernel.setup_s
        adapter, _, backend = (kernel.device or "").rpartition(" (")
        device = {"adapter": adapter or None, "backend": backend.rstrip(")") or None}
        notify("metrics")
        started = time.perf_counter()
        per_disc = disc_metrics(fit, _kernel_outline(kernel))
        for name in METRICS:
            metrics[name] = float(np.median([values[name] for values in per_disc.values()]))
        timing["metrics"] = time.perf_counter() - started
    timing["total"] = time.perf_counter() - start
    comparison = Comparison(photo, search, fit, kernel, geometry, fstop, per_disc, metrics, timing, device)
    if fit:
        comparison.doubts, comparison.rejection = judge(fit, metrics)
    return comparison


def judge(fit: ApertureFit, metrics: dict[str, float | None]) -> tuple[list[str], str | None]:
    """Doubts about a fit, and the reason to reject it, from the evidence (stated thresholds)."""
    doubts = []
    if not fit.sure:
        doubts.append(f"the runner-up ({fit.candidates[1].family.name}) fits almost as well")
    if len(fit.disc_fits) < MIN_SURE_DISCS:
        doubts.append(f"only {len(fit.disc_fits)} disc(s) could be fitted")
    iou = metrics.get("iou")
    if iou is not None and iou < MIN_SURE_IOU:
        doubts.append(f"the discs match the kernel loosely (median IoU {iou:.2f} < {MIN_SURE_IOU})")
    rejection = None
    if iou is not None and iou < MIN_ACCEPTABLE_IOU:
        rejection = (
            f"no acceptable fit: the discs match the best model ({fit.family.name}) poorly "
            f"(median IoU {iou:.2f} < {MIN_ACCEPTABLE_IOU})"
        )
    return doubts, rejection
