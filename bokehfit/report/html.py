"""The ``compare`` report for people: one self-contained HTML page, images embedded.

It opens with the verdict and its confidence in words, then the fitted aperture
drawn in the aperture frame with its angle, the photo with every disc outlined
(used, usable, rejected in distinct colours with a legend), each fitted disc
beside its model and the residual (with a colour scale), the rendered kernel
(with its scale), the ranked candidate apertures, the metrics, the geometry and
the time each stage took. Every number is taken from ``Comparison.to_json``.
"""

from __future__ import annotations

import base64
import html
import math
from dataclasses import dataclass

import cv2
import numpy as np

from bokehfit.comparison import Comparison
from bokehfit.uncertainty import plus_minus
from bokehfit.words import (diameter_text, distance_text, evidence_words, fstop_text, kernel_words, place_text,
                            rejection_counts, table_candidates)
from bokehfit.fit.choice import MIN_SHARP_DISCS
from bokehfit.fit.disc_model import model_window
from bokehfit.fit.features import FEATURE_DELTA_BIC
from bokehfit.metrics import METRICS
from bokehfit.report.overlay import ROLE_BGR, disc_role, draw_disc_overlay

__all__ = ["build_html", "aperture_diagram", "MAX_OVERVIEW_PX", "DISC_TILE_PX", "DIAGRAM_PX", "RESIDUAL_SPAN"]

#: Longest side of the photo overview, pixels.
MAX_OVERVIEW_PX = 1600
#: Side of each disc tile (crop, model, residual) as shown, pixels (a smaller window is stored at its own pixels).
DISC_TILE_PX = 120
#: Discs shown with their model.
MAX_DISC_TILES = 12
#: Side of the aperture diagram, pixels.
DIAGRAM_PX = 220
#: Residual colour scale: its ends are ± this share of the disc's brightness (plateau − background).
RESIDUAL_SPAN = 0.2
#: About this many pixels across for the kernel picture (whole zoom factors, nearest neighbour).
KERNEL_VIEW_PX = 240

_STYLE = """
body { font: 14px/1.45 system-ui, sans-serif; margin: 24px auto; max-width: 1200px; color: #1d1d1f; }
h1 { font-size: 22px; } h2 { font-size: 17px; margin-top: 28px; border-bottom: 1px solid #ddd; }
table { border-collapse: collapse; } td, th { padding: 3px 10px; text-align: right; border-bottom: 1px solid #eee; }
th { background: #f5f5f7; } td:first-child, th:first-child { text-align: left; }
.verdict { font-size: 18px; padding: 12px 16px; border-radius: 6px; border-left: 6px solid; }
.details { color: #444; margin: 4px 0 12px; }
.fitted { background: #e9f6ef; border-color: #009e73; } .unsure { background: #fff4e5; border-color: #e69f00; }
.no_fit, .no_discs { background: #fdecea; border-color: #d55e00; }
.head { display: flex; gap: 24px; align-items: flex-start; } .head .facts { flex: 1; }
.tiles { display: flex; flex-wrap: wrap; gap: 14px; } .tile { text-align: center; font-size: 12px; }
.tile img { image-rendering: pixelated; }
.scale { display: inline-block; font-size: 12px; margin: 6px 18px 6px 0; }
.bar { width: 220px; height: 12px; border: 1px solid #999; }
.ticks { display: flex; justify-content: space-between; width: 222px; }
.legend span.swatch { display: inline-block; width: 14px; height: 14px; margin: 0 4px -2px 12px; border-radius: 3px; }
img.overview { max-width: 100%; border: 1px solid #ccc; }
"""


def _data_uri(image: np.ndarray, kind: str = ".png") -> str:
    ok, data = cv2.imencode(kind, image, [cv2.IMWRITE_JPEG_QUALITY, 88] if kind == ".jpg" else [])
    mime = "image/jpeg" if kind == ".jpg" else "image/png"
    return f"data:{mime};base64,{base64.b64encode(data.tobytes()).decode('ascii')}" if ok else ""


def grey8(linear: np.ndarray, low: float, high: float, size: int) -> np.ndarray:
    scaled = np.clip((linear - low) / max(high - low, 1e-9), 0.0, 1.0)
    image = np.round(np.sqrt(scaled) * 255).astype(np.uint8)  # a gamma of 2 shows the edges
    return cv2.resize(image, (size, size), interpolation=cv2.INTER_NEAREST)


#: Residual colours: blue (photo darker than the model), white (equal), red (brighter), as RGB.
_RESIDUAL_STOPS = ((0.0, (33, 102, 172)), (0.5, (247, 247, 247)), (1.0, (178, 24, 43)))


def residual8(residual: np.ndarray, span: float, size: int) -> np.ndarray:
    """Residual as colour on :data:`_RESIDUAL_STOPS`, ±``span`` at the ends (BGR)."""
    t = 0.5 + 0.5 * np.clip(residual / max(span, 1e-9), -1.0, 1.0)
    positions = [p for p, _ in _RESIDUAL_STOPS]
    rgb = np.stack([np.interp(t, positions, [c[i] for _, c in _RESIDUAL_STOPS]) for i in range(3)], axis=-1)
    bgr = np.round(rgb[..., ::-1]).astype(np.uint8)
    return cv2.resize(bgr, (size, size), interpolation=cv2.INTER_NEAREST)


def _colour_bar(title: str, stops: list[tuple[float, str]], ticks: list[str]) -> str:
    """A colour scale: a CSS gradient bar with its tick labels."""
    gradient = ", ".join(f"{colour} {100 * position:.0f}%" for position, colour in stops)
    labels = "".join(f"<span>{html.escape(t)}</span>" for t in ticks)
    return (f'<div class="scale">{html.escape(title)}<div class="bar" style="background: linear-gradient(to right, '
            f'{gradient})"></div><div class="ticks">{labels}</div></div>')


def _residual_bar(span_fraction: float) -> str:
    stops = [(p, "rgb({}, {}, {})".format(*c)) for p, c in _RESIDUAL_STOPS]
    return _colour_bar("residual (photo − model), share of the disc's brightness",
                       stops, [f"−{span_fraction:.0%} (darker)", "0", f"+{span_fraction:.0%} (brighter)"])


@dataclass(frozen=True)
class DiscWindow:
    """A fitted disc's square window of the photo (``left``, ``top``: its top-left pixel), the fitted
    model over it, and the levels the tiles are shown between (its background and plateau)."""

    item: object  #: the fit's entry for the disc (``ApertureFit.disc_fits``)
    fitted: object  #: the chosen family's fit of that disc
    left: int
    top: int
    crop: np.ndarray
    model: np.ndarray
    low: float
    high: float


def disc_windows(comparison: Comparison, most: int) -> list[DiscWindow]:
    """The windows of the first ``most`` fitted discs, each reaching 1.3 times the disc's outline (and
    2 px) around its fitted centre; discs whose window the frame cuts are left out."""
    fit = comparison.fit
    luminance = comparison.photo.luminance
    height, width = luminance.shape
    windows = []
    for item in fit.disc_fits[:most]:
        fitted = item.fits[fit.family.name]
        reach = float(np.max(np.hypot(*(item.disc.outline_xy - item.disc.center_xy).T)))
        half = int(math.ceil(1.3 * reach + 2))
        col, row = int(round(fitted.center_xy[0])), int(round(fitted.center_xy[1]))
        left, top = col - half, row - half
        if left < 0 or top < 0 or left + 2 * half + 1 > width or top + 2 * half + 1 > height:
            continue
        crop = luminance[top : top + 2 * half + 1, left : left + 2 * half + 1]
        model = model_window(fitted, left, top, 2 * half + 1)
        windows.append(DiscWindow(item, fitted, left, top, crop, model, fitted.background,
                                  max(fitted.plateau, fitted.background + 1e-6)))
    return windows


def _disc_tiles(comparison: Comparison, entries: dict[int, dict]) -> str:
    tiles = []
    for window in disc_windows(comparison, MAX_DISC_TILES):
        entry = entries[window.item.disc.index]
        crop, model, low, high = window.crop, window.model, window.low, window.high
        residual = crop - model
        # Every number in the caption is the JSON's (one disc, one diameter).
        caption = f"#{entry['index']}: fitted {entry['fit_diameter_px']:.2f} px"
        if entry["angle_deg"] is not None:
            caption += f", {entry['angle_deg']:.1f}°"
        if entry.get("iou") is not None:
            caption += f", IoU {entry['iou']:.2f}"
        # A window smaller than the tile is stored at its own pixels, which the browser enlarges as
        # they are (image-rendering: pixelated); a larger one is reduced to the tile.
        side = min(DISC_TILE_PX, crop.shape[0])
        images = "".join(
            f'<img src="{_data_uri(image)}" width="{DISC_TILE_PX}" height="{DISC_TILE_PX}" alt="{alt}" title="{alt}">'
            for image, alt in (
                (grey8(crop, low, high, side), "photo"),
                (grey8(model, low, high, side), "model"),
                (residual8(residual, RESIDUAL_SPAN * (high - low), side), "residual"),
            )
        )
        tiles.append(f'<div class="tile">{images}<br>{html.escape(caption)}</div>')
    return '<div class="tiles">' + "".join(tiles) + "</div>"


def aperture_diagram(aperture: dict, size: int = DIAGRAM_PX) -> str:
    """An inline SVG of the fitted aperture in the aperture frame, its angle drawn from +x.

    x runs right and y up as the photographer sees the lens from behind the
    camera (design.md §2); the angle is counter-clockwise from +x. ``aperture``
    is the JSON's ``aperture`` object.
    """
    from bokehfit.apertures import Aperture, aperture_to_image

    shape = Aperture.from_json(aperture)
    centre, radius = size / 2.0, 0.36 * size
    scale = radius / shape.extent()

    def svg_xy(x, y) -> tuple[float, float]:  # diagram pixels from the centre, aperture frame (y up) → SVG (y down)
        row, col = aperture_to_image((x, y))
        return centre + col, centre + row

    def point(x, y):  # a unit-area aperture point as SVG "x,y"
        svg_x, svg_y = svg_xy(scale * x, scale * y)
        return f"{svg_x:.1f},{svg_y:.1f}"

    if shape.is_circle:
        outline = f'<circle cx="{centre}" cy="{centre}" r="{scale / math.sqrt(math.pi):.1f}" class="shape"/>'
    else:
        outline = f'<polygon points="{" ".join(point(x, y) for x, y in shape.vertices())}" class="shape"/>'
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{size}" height="{size}" viewBox="0 0 {size} {size}" '
        f'role="img" aria-label="aperture diagram">',
        "<style>.shape{fill:#fde9c8;stroke:#444;stroke-width:1.5}.axis{stroke:#999;stroke-width:1}"
        ".ray{stroke:#d55e00;stroke-width:2}.arc{fill:none;stroke:#d55e00;stroke-width:1.5}"
        "text{font:12px system-ui,sans-serif;fill:#333}</style>",
        outline,
        f'<line x1="{centre}" y1="{centre}" x2="{size - 8}" y2="{centre}" class="axis"/>',
        f'<line x1="{centre}" y1="{centre}" x2="{centre}" y2="8" class="axis"/>',
        f'<text x="{size - 14}" y="{centre - 4}">x</text><text x="{centre + 4}" y="16">y</text>',
    ]
    angle = aperture["angle_deg"]
    if angle is None:
        parts.append(f'<text x="6" y="{size - 8}">round: no angle</text>')
    else:
        a = math.radians(angle)
        tip = point(radius / scale * math.cos(a) * 1.15, radius / scale * math.sin(a) * 1.15)
        parts.append(f'<line x1="{centre}" y1="{centre}" x2="{tip.split(",")[0]}" y2="{tip.split(",")[1]}" class="ray"/>')
        arc = 0.45 * radius
        end_x, end_y = svg_xy(arc * math.cos(a), arc * math.sin(a))
        large = 1 if angle > 180 else 0
        parts.append(f'<path d="M {centre + arc:.1f} {centre:.1f} A {arc:.1f} {arc:.1f} 0 {large} 0 {end_x:.1f} {end_y:.1f}" '
                     f'class="arc"/>')
        parts.append(f'<text x="6" y="{size - 8}">{angle:.2f}° counter-clockwise from x</text>')
    parts.append("</svg>")
    return "".join(parts)


def _table(header: list[str], rows: list[list[str]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _fmt(value, digits=3) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def _facts(data: dict) -> str:
    """The fitted aperture's numbers, rounded for people, from the JSON."""
    aperture = data["aperture"]
    from bokehfit.apertures import Aperture

    rows = [["shape", Aperture.from_json(aperture).display_name]]
    if aperture["angle_deg"] is not None:
        rows.append(["angle", plus_minus(aperture["angle_deg"], aperture["angle_uncertainty_deg"], unit="°")])
    if aperture["aspect"] is not None:
        rows.append(["aspect (width / height)", f"{aperture['aspect']:.2f}"])
    rows.append(["disc diameter", diameter_text(aperture)])
    rows.append(["f-stop", fstop_text(aperture)])
    if aperture.get("exif_fnumber") is not None:
        rows.append(["EXIF f-number", f"f/{aperture['exif_fnumber']:g}"])
        depths = [d["depth_m"] for d in data["discs"] if d["used"] and d.get("depth_m") is not None]
        if depths:
            focus = data["geometry"]["focus_distance_m"]
            median, low, high = (distance_text(d, focus) for d in (float(np.median(depths)), min(depths), max(depths)))
            spread = f"{low} for" if low == high else f"median {median} ({low}–{high}),"
            rows.append(["lights' distance from EXIF f-number",
                         f"{spread} {len(depths)} discs (on the overlay after each disc's number)"])
    if aperture.get("fstop_consistency"):
        rows.append(["inconsistent", aperture["fstop_consistency"]])
    rows.append(["discs fitted", str(aperture["discs_fitted"])])
    heading = "fitted" if data["status"] in ("fitted", "unsure") else "best model tried (not acceptable)"
    return _table(["", heading], rows)


def _candidate_rows(candidates: list[dict]) -> list[list[str]]:
    """The candidate table: "best" marks the chosen model only where its ΔBIC is the lowest; a model the
    pixels favour but the fit set aside (its notes say why) is marked as such."""
    chosen = candidates[0]
    lowest = min(c["delta_bic"] for c in candidates)
    rows = []
    for c in candidates:
        margin = c["delta_bic"] - chosen["delta_bic"]
        if c is chosen:
            words = "best" if c["delta_bic"] <= lowest else "chosen (a model with a lower ΔBIC was set aside)"
        elif margin < 0:
            words = "lower ΔBIC, set aside (see the notes)"
        else:
            words = evidence_words(margin) + (" (the same answer)" if c.get("role") == "same_answer" else "")
        rows.append([c["name"], _fmt(c["angle_deg"], 2), f"{c['delta_bic']:.0f}", words, _fmt(c["screen_rms"], 3),
                     _fmt(c["diameter_px"], 2)])
    return rows


def _not_discs(detection: dict) -> str:
    """The places measured that are no disc: each a person gave, with its reason; a search's counted by reason (the
    words before its numbers)."""
    if detection["places_given"]:
        if not detection["rejections"]:
            return ""
        rows = [[place_text(r), r["rejected_because"]] for r in detection["rejections"]]
        return "<h2>Places given that are no disc</h2>" + _table(["place (centre, diameter)", "why"], rows)
    rows = [[why, str(n)] for why, n in rejection_counts(detection)]
    if not rows:
        return ""
    return ("<h2>Candidates that are no disc</h2><p>Each place with its reason and numbers is in the JSON's "
            "<code>detection.rejections</code>.</p>" + _table(["why", "how many"], rows))


def build_html(comparison: Comparison, command_line: str) -> str:
    """The whole report as one HTML string, rendered from ``comparison.to_json`` on every outcome."""
    photo, fit = comparison.photo, comparison.fit
    data = comparison.to_json(command_line)
    entries = {entry["index"]: entry for entry in data["discs"]}
    used = {index for index, entry in entries.items() if entry["used"]}
    focus = data["geometry"]["focus_distance_m"]
    depths = {index: distance_text(entry["depth_m"], focus).replace("≈ ∞", "~inf")  # the overlay's font is ASCII
              for index, entry in entries.items() if entry.get("depth_m") is not None}
    detection = data["detection"]
    given_no_disc = [(tuple(r["center_xy"]), r["diameter_px"]) for r in detection["rejections"]] \
        if detection["places_given"] else []
    overlay = draw_disc_overlay(photo.display, comparison.search.discs, used=used, max_side=MAX_OVERVIEW_PX, labels=depths,
                                not_discs=given_no_disc)
    status = data["status"]
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>bokehfit: {html.escape(photo.path.name)}</title><style>{_STYLE}</style></head><body>",
        f"<h1>bokehfit compare: {html.escape(photo.path.name)}</h1>",
        f'<p class="verdict {status}">{html.escape(data["verdict"])}</p>',
    ]
    if data.get("verdict_details"):
        parts.append(f'<p class="details">{html.escape(data["verdict_details"])}</p>')
    aperture = data["aperture"]
    if aperture["shape"] is not None:
        note = f"<p>{html.escape(aperture['angle_note'])}</p>" if aperture["angle_note"] else ""
        parts.append(f'<div class="head"><div>{aperture_diagram(aperture)}</div><div class="facts">{_facts(data)}{note}'
                     f"<p><small>The diagram shows the aperture as seen from behind the camera: x to the right, "
                     f"y up, the angle counter-clockwise from x.</small></p></div></div>")
    counts = {role: sum(disc_role(d, used) == role for d in comparison.search.discs) for role in ROLE_BGR}
    legend = "".join(
        f'<span class="swatch" style="background: rgb({b[2]}, {b[1]}, {b[0]})"></span>{html.escape(text)} ({counts[role]})'
        for role, b, text in (
            ("used", ROLE_BGR["used"], "used in the fit"),
            ("usable", ROLE_BGR["usable"], "usable, not needed"),
            ("rejected", ROLE_BGR["rejected"], "rejected: cut by the frame, too little of it its own, or too small"),
        )
    )
    soft = sum(d.soft_edge for d in comparison.search.discs)
    if soft:
        b = ROLE_BGR["usable"]
        legend += (f'<span class="swatch" style="background: none; border: 2px dashed rgb({b[2]}, {b[1]}, {b[0]})">'
                   f"</span>dashed: soft-edged, the second tier (fitted only beside {MIN_SHARP_DISCS} sharp discs) ({soft})")
    if given_no_disc:
        b = ROLE_BGR["rejected"]
        legend += (f'<span class="swatch" style="background: rgb({b[2]}, {b[1]}, {b[0]})"></span>'
                   f"circle with a cross: a place given that is no disc ({len(given_no_disc)})")
    parts.append(f"<h2>Photo and discs</h2><p>{len(entries)} discs found.</p><p class='legend'>{legend}</p>")
    parts.append(f'<img class="overview" src="{_data_uri(overlay, ".jpg")}" alt="photo with disc outlines">')
    parts.append(_not_discs(detection))
    if fit:
        parts.append("<h2>Fitted discs: photo, model, residual</h2>" + _residual_bar(RESIDUAL_SPAN)
                     + _disc_tiles(comparison, entries))
    if comparison.kernel is not None:
        kernel = comparison.kernel.image
        peak = float(kernel.max())
        zoom = max(1, KERNEL_VIEW_PX // kernel.shape[0])
        kernel8 = np.round(kernel / peak * 255).astype(np.uint8)
        if kernel8.ndim == 3:  # a chromatic kernel, RGB: the coloured rims show (OpenCV writes BGR)
            kernel8 = np.ascontiguousarray(kernel8[..., ::-1])
        drawn = data["kernel"]
        angle = "" if drawn["angle_deg"] is None else f" at {drawn['angle_deg']:.2f}°"
        parts.append(
            f"<h2>Matched kernel</h2><p>The fitted aperture{html.escape(angle)}, {drawn['diameter_px']:.2f} px, "
            f"{html.escape(kernel_words(data))}, {drawn['time_s'] * 1000:.1f} ms.</p>"
            f'<img src="{_data_uri(cv2.resize(kernel8, None, fx=zoom, fy=zoom, interpolation=cv2.INTER_NEAREST))}" alt="kernel"><br>'
            + _colour_bar("share of the light per pixel", [(0.0, "#000"), (1.0, "#fff")], ["0", f"{peak:.2e}"])
        )
    if aperture["candidates"]:
        parts.append("<h2>Candidate apertures</h2><p>The chosen model first, then the runner-up the verdict names, then the "
                     "rest. ΔBIC: how much worse each model explains the discs' pixels than the one that explains them "
                     "best; the words say how strongly the chosen model is preferred.</p>"
                     + _table(["model", "angle °", "ΔBIC", "evidence for the chosen", "outline misfit", "diameter px"],
                              _candidate_rows(table_candidates(aperture))))
    if aperture.get("feature_trials") or aperture.get("features_not_tried"):
        rows = [[t["feature"], t.get("asked_because") or "", "yes" if t["kept"] else "no", t["reason"]]
                for t in aperture.get("feature_trials") or []]
        rows += [[t["feature"], t["reason"], "not tried", ""] for t in aperture.get("features_not_tried") or []]
        parts.append("<h2>Lens features tried</h2><p>Each feature of a real lens that the discs asked for (a bright rim "
                     "or centre, a cat-eye at the frame's edge, a squeeze), tried on the joint fit: kept where it gains "
                     f"ΔBIC {FEATURE_DELTA_BIC:.0f}, and as much with any one disc left out. Coloured rims: kept where the "
                     "discs' red and blue sizes differ from green's by more than chance.</p>"
                     + _table(["feature", "what the discs show", "kept", "why"], rows))
    if any(v is not None for v in data["metrics"].values()):
        metric_rows = [[name, _fmt(data["metrics"][name], 3), METRICS[name].better, METRICS[name].description] for name in METRICS]
        parts.append("<h2>Metrics: discs against the matched kernel (median)</h2>"
                     + _table(["metric", "value", "better", "meaning"], metric_rows))
    geometry = data["geometry"]
    geometry_rows = [[k, _fmt(geometry[k], 3), geometry["sources"].get(k, "")]
                     for k in ("focal_length_mm", "sensor_width_mm", "focus_distance_m", "light_distance_m")]
    if geometry.get("frame"):
        geometry_rows.append(["frame", "", geometry["frame"]])
    for ignored in data["input"]["exif"].get("ignored", []):
        geometry_rows.append(["EXIF value ignored", "", ignored])
    for note in data["input"]["notes"]:
        geometry_rows.append(["note on the file", "", note])
    parts.append("<h2>Geometry</h2>" + _table(["quantity", "value", "source"], geometry_rows))
    parts.append("<h2>Timing</h2>" + _table(["stage", "seconds"], [[k, f"{v:.2f}"] for k, v in data["timing_s"].items()]))
    parts.append(f"<p><small>{html.escape(command_line)}<br>input: {html.escape(photo.linearisation)}; "
                 f"kernel: {html.escape(kernel_words(data))}; status {html.escape(status)}</small></p>"
                 "</body></html>")
    return "\n".join(parts)
