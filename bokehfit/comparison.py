"""The result of ``compare``: :class:`Comparison`, and the JSON document and summary rendered from it.

A :class:`Comparison` holds everything :func:`bokehfit.compare.compare_photo` found
on every outcome (``fitted``, ``unsure``, ``no_fit``, ``no_discs``): the photo, the
discs, the fit, the kernel, the geometry and f-stop, the metrics, the doubts. The
JSON document (schema_version 2, design.md §7b), the text summary and the HTML
report are all rendered from it, so one quantity has one number everywhere.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bokehfit import __version__
from bokehfit.discs import Disc, DiscSearch
from bokehfit.discs.measure import RESOLVABLE_PX
from bokehfit.fit import LENS_FEATURES, ApertureFit, FailedFit
from bokehfit.io import Photo
from bokehfit.judging import MIN_ACCEPTABLE_IOU, short_doubts
from bokehfit.kernels import Kernel
from bokehfit.optics import FStop, Geometry
from bokehfit.uncertainty import measurable, unmeasurable_reason
from bokehfit.words import (angle_note, article, clip_headline, describe, diameter_text, disc_problems, distance_text,
                            evidence_words, feature_trial_lines, fstop_text, geometry_lines, kernel_words, rejection_lines,
                            runners_up_line, shape_words, table_candidates, unfitted_lines, used_as)

__all__ = ["SCHEMA_VERSION", "Comparison"]

SCHEMA_VERSION = 2


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
            why = "no other shape comes close" if runner_up is not None else _alone(fit)
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
            evidence = _alone(fit)
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
                          "resolvable_px": RESOLVABLE_PX, "places_given": self.search.given,
                          "rejections": [r.to_json() for r in self.search.rejections],
                          "timing_s": {k: round(v, 4) for k, v in self.search.timing_s.items()}},
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
        lines.extend(rejection_lines(data["detection"]))
        if self.fit:
            lines.extend(unfitted_lines(discs, self.fit.options.max_discs))
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
        lines.append(runners_up_line(table_candidates(aperture)))
        lines.extend(feature_trial_lines(aperture))
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


def _alone(fit) -> str:
    """Why a fit names no runner-up: only one shape was tried, or the others' outlines were too far off to fit."""
    return "no other shape fits the outlines" if fit.others_screened else "only one shape was tried"


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
