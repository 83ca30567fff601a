"""The main job: photo → discs → fitted aperture → rendered kernel → metrics (design.md §7).

:func:`compare_photo` runs the stages and returns a :class:`Comparison`: the
one result object that the JSON document (schema_version 2, design.md §7b), the
text summary and the HTML report are all rendered from, on every outcome
(``fitted``, ``unsure``, ``no_fit``, ``no_discs``), so one quantity has one
number everywhere. The f-stop is :mod:`bokehfit.optics`'s, the words a person reads
:mod:`bokehfit.words`'s.
"""

from __future__ import annotations

import hashlib
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np
from skimage import measure

from bokehfit import __version__
from bokehfit.discs import COMPARE_MIN_DIAMETER_PX, Disc, DiscSearch, find_discs, measure_discs_at
from bokehfit.discs.labels import DiscLabels, read_labels
from bokehfit.discs.measure import RESOLVABLE_PX
from bokehfit.errors import InputError
from bokehfit.fit import LENS_FEATURES, REGULAR_OUTLINE_MISFIT, ApertureFit, FailedFit, FitOptions, fit_aperture
from bokehfit.gpu import AdapterChoice
from bokehfit.io import Photo, load_photo
from bokehfit.io.colour import luminance_weights
from bokehfit.kernels import AUTO, Kernel, compute_kernel
from bokehfit.kernels.exact import coverage
from bokehfit.metrics import METRICS, angle_error, compare_outlines
from bokehfit.metrics.outlines import resample
from bokehfit.optics import FStop, Geometry, estimate_fstop, resolve_geometry
from bokehfit.uncertainty import measurable, unmeasurable_reason
from bokehfit.words import (angle_note, article, clip_headline, describe, diameter_text, disc_problems, distance_text,
                            evidence_words, fstop_text, geometry_lines, kernel_words, shape_words, table_candidates,
                            used_as)

__all__ = [
    "SCHEMA_VERSION",
    "Comparison",
    "compare_photo",
    "judge",
]

SCHEMA_VERSION = 2
#: L1 tolerance of the matched kernel: its 50 % outline is what the metrics use. It is
#: drawn by the cheapest method that meets it, the start-up of a GPU included
#: (``method="auto"``: ``exact`` for any usual disc, which starts no GPU), and a
#: sampling method's sample count follows from its convergence model.
KERNEL_TOLERANCE = 0.01
#: Points each outline is resampled to (evenly along its length) before the metrics.
METRIC_POINTS = 256
#: A fit is acceptable when the discs match the kernel at least this well (median IoU) ...
MIN_ACCEPTABLE_IOU = 0.6
#: ... and sure when, besides a clear BIC margin, they match this well with at least MIN_SURE_DISCS discs.
MIN_SURE_IOU = 0.85
MIN_SURE_DISCS = 3
#: ... and the discs are not both small and faint: under SMALL_DISC_PX (median) and standing less than
#: FAINT_CONTRAST_REL of their background above it (median), an outline of a few hundred pixels is set
#: by a few code values of the photo's tone curve, grain and compression as much as by the aperture.
SMALL_DISC_PX = 64.0
FAINT_CONTRAST_REL = 0.5
#: ... and the discs' outlines follow the shape: median radial misfit (in equal-area radii) at most
#: :data:`bokehfit.fit.REGULAR_OUTLINE_MISFIT`, the fit's "regular" outline.
#: The kernel is drawn at the fitted angle, so each disc's best alignment with
#: it is searched within this many degrees.
ALIGNMENT_SEARCH_DEG = 10.0


@dataclass
class Comparison:
    """Everything ``compare`` found: the one result that the JSON, summary and report render.

    ``status`` is ``fitted`` (a sure fit), ``unsure`` (a fit with ``doubts``),
    ``no_fit`` (discs were found but no model explains them) or ``no_discs``
    (nothing usable was found); ``reason`` says why in one sentence (None when fitted).
    """

    photo: Photo
    search: DiscSearch
    fit: ApertureFit | FailedFit
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

    @property
    def status(self) -> str:
        if not self.fit:
            return "no_discs"
        if self.rejection:
            return "no_fit"
        return "unsure" if self.doubts else "fitted"

    @property
    def usable_discs(self) -> list[Disc]:
        """The discs found that the fit could use (:attr:`Disc.usable`)."""
        return [disc for disc in self.search.discs if disc.usable]

    @property
    def used_discs(self) -> list[Disc]:
        """The discs the fit used (fitted and kept by the consensus)."""
        return [disc for disc in self.search.discs if self.fit.disc_fit(disc) is not None]

    @property
    def reason(self) -> str | None:
        """Why the result is not a sure fit, in one sentence (None when it is)."""
        status = self.status
        if status == "no_discs":
            if not self.search:
                return f"no bokeh disc found in {self.photo.path.name}: {self.search.reason}"
            return self.fit.reason
        if status == "no_fit":
            return self.rejection
        if status == "unsure":
            return "unsure because " + " and ".join(self.doubts)
        return None

    @property
    def verdict(self) -> str:
        """The verdict in one short sentence for people: what the aperture is, how sure, why (the report's first line).

        It aims at :data:`HEADLINE_CHARS` characters; the numbers behind it are :attr:`verdict_details`.
        """
        status = self.status
        if status == "no_discs":
            return clip_headline(f"No usable disc: {self.reason}.")
        if status == "no_fit":
            iou = self.metrics.get("iou")
            match = "" if iou is None else f" (overlap {iou:.2f}, {MIN_ACCEPTABLE_IOU} needed)"
            return clip_headline(f"No fit: no aperture shape explains these discs; the best tried was {article(self.fit.family.aperture.display_name)}"
                         f"{match}.")
        fit = self.fit
        aperture = self.aperture_json()
        what = shape_words(aperture)
        count = len(fit.disc_fits)
        if status == "fitted":
            runner_up = self._runner_up()
            why = "only one shape was tried" if runner_up is None else "no other shape comes close"
            return clip_headline(f"Sure: {what}, from {count} discs that agree; {why}.")
        return clip_headline(f"Unsure: probably {article(what)}, but {self.short_doubts[0] if self.short_doubts else 'see the doubts'}.")

    @property
    def verdict_details(self) -> str:
        """The numbers behind :attr:`verdict`: the aperture with its uncertainties, the evidence, every doubt."""
        status = self.status
        if status == "no_discs":  # the whole reason, where the first sentence had to cut it
            return "" if self.verdict == f"No usable disc: {self.reason}." else f"{self.reason[:1].upper()}{self.reason[1:]}."
        if status == "no_fit":
            return f"{self.rejection}."
        fit = self.fit
        aperture = self.aperture_json()
        what = describe(aperture)
        margin = fit.margin_bic
        runner_up = self._runner_up()
        count = len(fit.disc_fits)
        discs = f"{count} disc{'s' if count != 1 else ''} fitted"
        if margin is None or runner_up is None:
            evidence = "only one shape was tried"
        elif margin < 0:  # set aside by the consensus or the outlines, whatever the pixels say (the notes say why)
            evidence = f"the pixels alone favour {article(runner_up['display_name'])} (ΔBIC {-margin:.0f})"
        elif status == "fitted":
            evidence = f"{evidence_words(margin)} evidence over {article(runner_up['display_name'])} (ΔBIC {margin:.0f})"
        else:
            evidence = f"ΔBIC {margin:.0f} over {article(runner_up['display_name'])}"
        details = f"{what}; {discs}; {evidence}"
        if status == "unsure":
            details += "; unsure because " + " and ".join(self.doubts)
        return details + "."

    @property
    def short_doubts(self) -> list[str]:
        """Each doubt in a few words, for the verdict's first sentence (most telling first)."""
        if not self.fit or not self.doubts:
            return []
        return short_doubts(self.fit, self.metrics)

    def _runner_up(self) -> dict | None:
        """The runner-up's candidate entry (the JSON's), the one the verdict and the tables name."""
        return next((c for c in self.aperture_json()["candidates"] if c.get("role") == "runner_up"), None)

    def kernel_json(self) -> dict | None:
        """The kernel drawn and measured: the reported aperture, at the angle the discs show."""
        kernel = self.kernel
        if kernel is None:
            return None
        drawn = kernel.aperture
        return {
            "shape": drawn.shape,
            "blades": drawn.blades,
            "angle_deg": None if drawn.symmetry_deg is None else round(drawn.canonical_angle_deg, 3),
            "diameter_px": round(kernel.diameter_px, 3),
            "size_px": int(kernel.image.shape[0]),
            "method": kernel.method,
            "samples": None if kernel.samples is None else int(kernel.samples),
            "time_s": round(kernel.time_s, 4),
        }

    def aperture_json(self) -> dict:
        """design.md §7 ``aperture`` with the §7b keys; every fitted key is null when nothing was fitted."""
        fit = self.fit
        fstop = {
            "fstop": None if self.fstop.value is None else round(self.fstop.value, 3),
            "fstop_uncertainty": None if self.fstop.uncertainty is None else round(self.fstop.uncertainty, 3),
            "fstop_reason": self.fstop.reason,
            "fstop_bound": self.fstop.bound,
            "fstop_meaning": self.fstop.meaning,
            "exif_fnumber": self.fstop.exif_fnumber,
            "fstop_consistency": self.fstop.consistency,
            "size_convention": self.fstop.convention,
            "lens_model": self.fstop.lens_model,
        }
        if not fit:
            data = {key: None for key in ("shape", "blades", "aspect", "angle_deg", "symmetry_deg",
                                           "angle_uncertainty_deg", "diameter_px", "diameter_uncertainty_px",
                                           "edge_blur_px", "angle_note", "message")}
            for name in LENS_FEATURES:
                data[name] = data[f"{name}_uncertainty"] = None
            data.update(fstop, focus_side=None, sure=False, doubts=[], discs_fitted=0, candidates=[], runner_up=None,
                        runners_up=[], diameter_reason=None)
            return data
        data = fit.to_json()
        data.update(fstop, angle_note=angle_note(fit), sure=not self.doubts, doubts=self.doubts)
        data["diameter_reason"] = None
        if not measurable(data["diameter_px"], data["diameter_uncertainty_px"]):
            data["diameter_reason"] = unmeasurable_reason(f"{data['diameter_px']:.2f} px", data["diameter_uncertainty_px"],
                                                          "the discs' sizes disagree (lights at many distances)")
            data["diameter_px"] = None
        data["candidates"], data["runner_up"] = _with_roles(fit, data["candidates"])
        data["runners_up"] = [c["name"] for c in table_candidates(data)[1:]]
        return data

    def disc_json(self, disc: Disc) -> dict:
        """One disc: as ``bokehfit discs`` reports it, plus ``used`` (fitted) and its fit."""
        fitted = self.fit.disc_fit(disc)
        entry = disc.to_json()
        entry["usable"] = bool(disc.usable)
        entry["used"] = fitted is not None
        entry["used_as"] = None if fitted is None else used_as(disc, fitted)
        entry["rejected_because"] = disc_problems(disc)
        if disc.index in self.fit.rejected:
            entry["rejected_because"].append(self.fit.rejected[disc.index])
        entry["fit_diameter_px"] = None if fitted is None else round(fitted.diameter_px, 3)
        item = self.fit.disc_item(disc)
        own = None if item is None else item.own
        if own is not None and own.angle_deg is not None:
            entry["angle_deg"] = round(own.angle_deg, 3)
        entry.update({k: _round(v) for k, v in self.disc_metrics.get(disc.index, {}).items()})
        depth = self.fstop.light_distances_m.get(disc.index) if fitted is not None else None
        entry["depth_m"] = None if depth is None else round(depth, 4)
        return entry

    def to_json(self, command_line: str) -> dict:
        """The ``compare --json`` document, schema_version 2 (design.md §7b), on every outcome."""
        return {
            "schema_version": SCHEMA_VERSION,
            "bokehfit_version": __version__,
            "command_line": command_line,
            "status": self.status,
            "reason": self.reason,
            "verdict": self.verdict,
            "verdict_details": self.verdict_details,
            "input": self.photo.input_json(),
            "geometry": self.geometry.to_json(),
            "detection": {"candidates": self.search.candidates, "rejected": dict(self.search.rejected),
                          "resolvable_px": RESOLVABLE_PX},
            "aperture": self.aperture_json(),
            "kernel": self.kernel_json(),
            "discs": [self.disc_json(disc) for disc in self.search.discs],
            "metrics": {k: _round(v) for k, v in self.metrics.items()},
            "timing_s": {k: round(v, 4) for k, v in self.timing_s.items()},
            "device": self.device,
        }

    def summary(self) -> str:
        """The result in a few lines for the terminal, rendered from :meth:`to_json`'s numbers."""
        data = self.to_json("")
        photo, discs = data["input"], data["discs"]
        usable, used = sum(d["usable"] for d in discs), sum(d["used"] for d in discs)
        lines = [self.verdict] + ([self.verdict_details] if self.verdict_details else []) + [
                 f"{self.photo.path.name}: {photo['width']}×{photo['height']}, {len(discs)} discs "
                 f"({usable} usable, {used} used in the fit, {len(discs) - usable} rejected)"]
        lines.extend(f"note: {note}" for note in photo["notes"])
        lines.extend(geometry_lines(data))
        aperture = data["aperture"]
        if aperture["shape"] is None:
            if aperture["exif_fnumber"] is not None:
                lines.append(f"EXIF: f/{aperture['exif_fnumber']:g} (no f-stop fitted: {aperture['fstop_reason']})")
            return "\n".join(lines)
        lines.append(f"aperture: {describe(aperture)}, disc {diameter_text(aperture)}")
        lines.append("f-stop: " + fstop_text(aperture))
        lines.extend(self.fstop_lines(data))
        if aperture["angle_note"]:
            lines.append(aperture["angle_note"])
        ranked = ", ".join(f"{c['display_name']} (ΔBIC {c['delta_bic']:.0f}{', the same answer' if c['role'] == 'same_answer' else ''})"
                           for c in table_candidates(aperture)[1:])
        lines.append(f"runners-up: {ranked or 'none'}")
        lines.append("metrics (discs vs kernel, median): " + ", ".join(
            f"{k} {v:.4f}" for k, v in data["metrics"].items() if v is not None))
        lines.append("time: " + ", ".join(f"{k} {v:.2f} s" for k, v in data["timing_s"].items())
                     + f"; kernel: {kernel_words(data)}")
        return "\n".join(lines)


    def fstop_lines(self, data: dict) -> list[str]:
        """EXIF's FNumber beside the fitted f-stop, the light distances it implies, and any disagreement."""
        aperture, exif = data["aperture"], data["input"]["exif"]
        lines = []
        if aperture["exif_fnumber"] is not None:
            lens = f", lens {exif['lens']}" if exif.get("lens") else ""
            lines.append(f"EXIF: f/{aperture['exif_fnumber']:g}{lens}")
            depths = [d["depth_m"] for d in data["discs"] if d["used"]]
            known = [d for d in depths if d is not None]
            if known:
                focus = data["geometry"]["focus_distance_m"]
                median, low, high = (distance_text(d, focus) for d in (float(np.median(known)), min(known), max(known)))
                spread = f"{low} for" if low == high else f"median {median}, {low}–{high} over"
                lines.append(f"lights' distance implied by EXIF f/{aperture['exif_fnumber']:g}: {spread} {len(known)} of "
                             f"{len(depths)} fitted discs (per disc: depth_m in the JSON)")
        if aperture["fstop_consistency"]:
            lines.append("inconsistent: " + aperture["fstop_consistency"])
        return lines


def _small_and_faint(fit: ApertureFit) -> tuple[float, float] | None:
    """The fitted discs' median diameter and median contrast over their background (a share of it), where
    both are under SMALL_DISC_PX and FAINT_CONTRAST_REL; else None."""
    discs = [item.disc for item in fit.disc_fits]
    if not discs:
        return None
    diameter = float(np.median([d.diameter_px for d in discs]))
    contrast = float(np.median([(d.plateau - d.background) / max(d.background, 1e-6) for d in discs]))
    return (diameter, contrast) if diameter < SMALL_DISC_PX and contrast < FAINT_CONTRAST_REL else None


def short_doubts(fit: ApertureFit, metrics: dict[str, float | None]) -> list[str]:
    """The doubts of :func:`judge` in a few words each, most telling first (for the verdict's first sentence)."""
    words = []
    if fit.close_runner_up:
        words.append(f"{article(fit.runner_up.family.aperture.display_name)} fits almost as well")
    fitted = len(fit.disc_fits)
    if fitted < MIN_SURE_DISCS:
        words.append(f"only {fitted} disc{' is' if fitted == 1 else 's are'} clean enough")
    if fit.outline_misfit > REGULAR_OUTLINE_MISFIT:
        words.append("the discs' outlines are irregular")
    iou = metrics.get("iou")
    if iou is not None and iou < MIN_SURE_IOU:
        words.append("the discs match it only loosely")
    if _small_and_faint(fit):
        words.append("the discs are small and faint")
    if fit.notes:
        words.append("a better-fitting shape was set aside (see the notes)")
    return words


def _with_roles(fit: ApertureFit, candidates: list[dict]) -> tuple[list[dict], dict | None]:
    """The candidates (the fit's order, best first), each with its ``role``: ``chosen``, ``runner_up``
    (the best model with another answer: the one the verdict names), ``same_answer`` (the chosen
    shape rounded, or round enough to be the circle) or ``other``; and the runner-up's entry."""
    runner_up = fit.runner_up
    name = None if runner_up is None else runner_up.family.name
    same = {m.family.name for m in fit.candidates[1:] if fit.candidates[0].same_answer(m)}
    entries = []
    for i, c in enumerate(candidates):
        role = "chosen" if i == 0 else "runner_up" if c["name"] == name else "same_answer" if c["name"] in same else "other"
        entries.append({**c, "role": role})
    return entries, next((c for c in entries if c["role"] == "runner_up"), None)


def _round(value):
    return None if value is None or not math.isfinite(value) else round(float(value), 5)


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
    compared with its own exact outline of the fitted aperture instead.
    """
    out = {}
    symmetry = comparison_fit.aperture.symmetry_deg
    seen = comparison_fit.seen_angle_deg
    for item in comparison_fit.disc_fits:
        fitted = item.fits[comparison_fit.family.name]
        # the kernel's colours do not change its (luminance) outline
        own = fitted.aperture != comparison_fit.seen_aperture.replace(chromatic=None) or fitted.aperture.vignetting is not None
        reference = _shown_outline(fitted, comparison_fit.diameter_px) if own else kernel_outline
        values = compare_outlines(
            resample(item.disc.outline_xy, METRIC_POINTS), reference, rotation_within_deg=ALIGNMENT_SEARCH_DEG
        )
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
    if discs is None:
        search = find_discs(photo.luminance, photo.clipped, min_diameter_px=min_diameter_px,
                            max_diameter_px=max_diameter_px)
    else:
        labels = discs if isinstance(discs, DiscLabels) else read_labels(discs)
        _check_labels_photo(labels, photo)
        search = measure_discs_at(photo.luminance, photo.clipped,
                                  [(disc.center_xy, disc.diameter_px) for disc in labels.usable])
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
        aperture = fit.aperture
        # The reported aperture as the discs show it: the consensus angle (turned back for near discs).
        seen_angle = fit.seen_angle_deg or 0.0
        scale = fit.diameter_px * math.sqrt(math.pi) / 2.0
        size = 2 * math.ceil(aperture.extent() * scale) + 9
        kernel = compute_kernel(
            fit.seen_aperture,
            diameter_px=fit.diameter_px,
            size=size,
            method=AUTO,
            tolerance=KERNEL_TOLERANCE,
            adapter=adapter,
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


def judge(fit: ApertureFit, metrics: dict[str, float | None]) -> tuple[list[str], str | None]:
    """Doubts about a fit, and the reason to reject it, from the evidence (stated thresholds)."""
    doubts = []
    if fit.close_runner_up:
        doubts.append(f"the runner-up ({fit.runner_up.family.aperture.display_name}) fits almost as well")
    doubts.extend(fit.notes)
    if fit.outline_misfit > REGULAR_OUTLINE_MISFIT:
        doubts.append(f"the discs' outlines are irregular (median misfit {fit.outline_misfit:.2f} of their radius to the "
                      f"best shape, {REGULAR_OUTLINE_MISFIT} for a sure fit): blobs that say little about the aperture")
    fitted = len(fit.disc_fits)
    if fitted < MIN_SURE_DISCS:
        doubts.append(f"only {fitted} disc{' was' if fitted == 1 else 's were'} clean enough to fit")
    iou = metrics.get("iou")
    if iou is not None and iou < MIN_SURE_IOU:
        doubts.append(f"the discs match the kernel only loosely (median overlap IoU {iou:.2f}, {MIN_SURE_IOU} for a sure fit)")
    faint = _small_and_faint(fit)
    if faint:
        doubts.append(f"the discs are small and faint (median {faint[0]:.0f} px, {faint[1]:.0%} above their background;"
                      f" {SMALL_DISC_PX:.0f} px or {FAINT_CONTRAST_REL:.0%} for a sure fit): their outlines follow the"
                      " photo's tone curve, grain and compression as much as the aperture")
    rejection = None
    if iou is not None and iou < MIN_ACCEPTABLE_IOU:
        rejection = (
            f"the discs' outlines do not match even the best model ({fit.family.name}) "
            f"(median overlap IoU {iou:.2f}, at least {MIN_ACCEPTABLE_IOU} needed)"
        )
    return doubts, rejection
