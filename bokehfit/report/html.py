"""The ``compare`` report for people: one self-contained HTML page, images embedded.

It shows the photo with every disc outlined, each fitted disc beside its
fitted model and the residual, the rendered kernel, the ranked candidate
apertures, the metrics, the f-stop with its geometry, and the time each stage took.
"""

from __future__ import annotations

import base64
import html
import math

import cv2
import numpy as np

from bokehfit.compare import Comparison
from bokehfit.fit.pixels import model_window
from bokehfit.metrics import METRICS
from bokehfit.report.overlay import draw_disc_overlay

__all__ = ["build_html", "MAX_OVERVIEW_PX", "DISC_TILE_PX"]

#: Longest side of the photo overview, pixels.
MAX_OVERVIEW_PX = 1600
#: Side of each disc tile (crop, model, residual), pixels.
DISC_TILE_PX = 120
#: Discs shown with their model.
MAX_DISC_TILES = 12

_STYLE = """
body { font: 14px/1.45 system-ui, sans-serif; margin: 24px auto; max-width: 1200px; color: #1d1d1f; }
h1 { font-size: 22px; } h2 { font-size: 17px; margin-top: 28px; border-bottom: 1px solid #ddd; }
table { border-collapse: collapse; } td, th { padding: 3px 10px; text-align: right; border-bottom: 1px solid #eee; }
th { background: #f5f5f7; } td:first-child, th:first-child { text-align: left; }
.summary { font-size: 16px; background: #f5f5f7; padding: 10px 14px; border-radius: 6px; }
.tiles { display: flex; flex-wrap: wrap; gap: 14px; } .tile { text-align: center; font-size: 12px; }
img.overview { max-width: 100%; border: 1px solid #ccc; } .unsure { color: #b25000; }
"""


def _data_uri(image: np.ndarray, kind: str = ".png") -> str:
    ok, data = cv2.imencode(kind, image, [cv2.IMWRITE_JPEG_QUALITY, 88] if kind == ".jpg" else [])
    mime = "image/jpeg" if kind == ".jpg" else "image/png"
    return f"data:{mime};base64,{base64.b64encode(data.tobytes()).decode('ascii')}" if ok else ""


def _grey8(linear: np.ndarray, low: float, high: float, size: int) -> np.ndarray:
    scaled = np.clip((linear - low) / max(high - low, 1e-9), 0.0, 1.0)
    image = np.round(np.sqrt(scaled) * 255).astype(np.uint8)  # a gamma of 2 shows the edges
    return cv2.resize(image, (size, size), interpolation=cv2.INTER_NEAREST)


def _residual8(residual: np.ndarray, span: float, size: int) -> np.ndarray:
    """Residual as colour: red where the photo is brighter than the model, blue where darker."""
    t = np.clip(residual / max(span, 1e-9), -1.0, 1.0)
    rgb = np.stack([np.clip(1 + np.minimum(t, 0), 0, 1), 1 - np.abs(t), np.clip(1 - np.maximum(t, 0), 0, 1)], axis=-1)
    bgr = np.round(rgb[..., ::-1] * 255).astype(np.uint8)
    return cv2.resize(bgr, (size, size), interpolation=cv2.INTER_NEAREST)


def _disc_tiles(comparison: Comparison) -> str:
    fit = comparison.fit
    luminance = comparison.photo.luminance
    height, width = luminance.shape
    tiles = []
    for item in fit.disc_fits[:MAX_DISC_TILES]:
        fitted = item.fits[fit.family.name]
        reach = float(np.max(np.hypot(*(item.disc.outline_xy - item.disc.center_xy).T)))
        half = int(math.ceil(1.3 * reach + 2))
        col, row = int(round(fitted.center_xy[0])), int(round(fitted.center_xy[1]))
        left, top = col - half, row - half
        if left < 0 or top < 0 or left + 2 * half + 1 > width or top + 2 * half + 1 > height:
            continue
        crop = luminance[top : top + 2 * half + 1, left : left + 2 * half + 1]
        model = model_window(fitted, left, top, 2 * half + 1)
        low, high = fitted.background, max(fitted.plateau, fitted.background + 1e-6)
        residual = crop - model
        metrics = comparison.disc_metrics.get(item.disc.index, {})
        caption = f"#{item.disc.index}: {fitted.diameter_px:.1f} px"
        if fitted.angle_deg is not None:
            caption += f", {fitted.angle_deg:.1f}°"
        if "iou" in metrics:
            caption += f", IoU {metrics['iou']:.3f}"
        images = "".join(
            f'<img src="{_data_uri(image)}" width="{DISC_TILE_PX}" height="{DISC_TILE_PX}" alt="{alt}">'
            for image, alt in (
                (_grey8(crop, low, high, DISC_TILE_PX), "photo"),
                (_grey8(model, low, high, DISC_TILE_PX), "model"),
                (_residual8(residual, 0.2 * (high - low), DISC_TILE_PX), "residual"),
            )
        )
        tiles.append(f'<div class="tile">{images}<br>{html.escape(caption)}</div>')
    return '<div class="tiles">' + "".join(tiles) + "</div>"


def _table(header: list[str], rows: list[list[str]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _fmt(value, digits=3) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def build_html(comparison: Comparison, command_line: str) -> str:
    """The whole report as one HTML string."""
    photo, fit = comparison.photo, comparison.fit
    data = comparison.to_json(command_line) if fit else None
    overlay = draw_disc_overlay(photo.display, comparison.search.discs)
    scale = min(1.0, MAX_OVERVIEW_PX / max(overlay.shape[:2]))
    if scale < 1.0:
        overlay = cv2.resize(overlay, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>bokehfit: {html.escape(photo.path.name)}</title><style>{_STYLE}</style></head><body>",
        f"<h1>bokehfit compare: {html.escape(photo.path.name)}</h1>",
    ]
    if fit:
        aperture = data["aperture"]
        fstop = "f-stop unknown: " + aperture["fstop_reason"] if aperture["fstop"] is None else (
            f"f/{aperture['fstop']:.2f} ± {aperture['fstop_uncertainty']:.2f} ({aperture['size_convention']}, {aperture['lens_model']} lens)"
        )
        sure = "".join(f'<br><span class="unsure">unsure: {html.escape(d)}</span>' for d in comparison.doubts)
        parts.append(f'<p class="summary"><b>{html.escape(fit.aperture.describe())}</b>{sure}<br>'
                     f"{html.escape(fit.message)}<br>{html.escape(fstop)}</p>")
        if aperture["angle_note"]:
            parts.append(f"<p>{html.escape(aperture['angle_note'])}</p>")
    else:
        parts.append(f'<p class="summary unsure">No aperture fitted: {html.escape(fit.message)}</p>')
    parts.append(f"<h2>Photo and discs</h2><p>{len(comparison.search.discs)} discs found "
                 f"({sum(d.usable for d in comparison.search.discs)} clean enough to fit; green: used or usable, "
                 f"orange: saturated, cut by the frame, overlapping or small).</p>")
    parts.append(f'<img class="overview" src="{_data_uri(overlay, ".jpg")}" alt="photo with disc outlines">')
    if fit:
        parts.append("<h2>Fitted discs: photo, model, residual</h2>" + _disc_tiles(comparison))
        kernel = comparison.kernel.image
        kernel8 = np.round(kernel / kernel.max() * 255).astype(np.uint8)
        parts.append(
            f"<h2>Matched kernel</h2><p>{comparison.kernel.samples} samples on {html.escape(comparison.kernel.device or '')}, "
            f"{comparison.kernel.time_s * 1000:.1f} ms.</p>"
            f'<img src="{_data_uri(cv2.resize(kernel8, None, fx=max(1, 240 // kernel8.shape[0]), fy=max(1, 240 // kernel8.shape[0]), interpolation=cv2.INTER_NEAREST))}" alt="kernel">'
        )
        rows = [[c["name"], _fmt(c["angle_deg"], 2), f"{c['delta_bic']:.0f}", _fmt(c["screen_rms"], 4), _fmt(c["diameter_px"], 2)]
                for c in data["aperture"]["candidates"]]
        parts.append("<h2>Candidate apertures</h2>" + _table(["model", "angle °", "ΔBIC", "outline misfit", "diameter px"], rows))
        metric_rows = [[name, _fmt(data["metrics"][name], 4), METRICS[name].better, METRICS[name].description] for name in METRICS]
        parts.append("<h2>Metrics: discs against the matched kernel (median)</h2>"
                     + _table(["metric", "value", "better", "meaning"], metric_rows))
        geometry = data["geometry"]
        geometry_rows = [[k, _fmt(geometry[k], 3) if geometry[k] is not None else "—", geometry["sources"].get(k, "")]
                         for k in ("focal_length_mm", "sensor_width_mm", "focus_distance_m", "light_distance_m")]
        parts.append("<h2>Geometry</h2>" + _table(["quantity", "value", "source"], geometry_rows))
    parts.append("<h2>Timing</h2>" + _table(["stage", "seconds"], [[k, f"{v:.3f}"] for k, v in comparison.timing_s.items()]))
    parts.append(f"<p><small>{html.escape(command_line)}<br>input: {html.escape(photo.linearisation)}; "
                 f"device: {html.escape(str(comparison.device.get('adapter')))}</small></p></body></html>")
    return "\n".join(parts)
