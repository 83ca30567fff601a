"""The lens fingerprint: a survey's rows grouped by camera, lens and f-number, as one HTML page.

Per group the aperture found (shape, blades, angle, and the real-lens keys of
design.md §3b: roundness, squeeze, vignetting, rim, chromatic) with its spread
and counts; per lens a plot of disc shape against f-number and one of the
fitted f-stop against EXIF ``FNumber``; per group the photos behind it, as
thumbnails linking to their compare reports.

Spread is the median absolute deviation (MAD) around the median, robust to
the odd photo that fits badly; a value is shown with the number of photos it
rests on.
"""

from __future__ import annotations

import base64
import collections
import html
import io
import os
from pathlib import Path

import numpy as np

from bokehfit import __version__
from bokehfit.surveys.work import STATUSES

__all__ = ["group_rows", "shape_label", "fingerprint_sentence", "build_report", "FITTED_STATUSES", "THUMBNAILS_PER_GROUP", "FSTOP_TICKS"]

#: Rows whose aperture counts in the fingerprint: sure and unsure fits.
FITTED_STATUSES = ("fitted", "unsure")
#: Thumbnails shown per group (the rest are counted).
THUMBNAILS_PER_GROUP = 24
#: Numeric columns summarised per group: (column, heading, digits).
SUMMARISED = (
    ("blades", "blades", 0),
    ("angle_deg", "angle °", 1),
    ("roundness", "roundness", 2),
    ("squeeze", "squeeze", 3),
    ("vignetting_radius", "vignetting radius", 2),
    ("vignetting_shift", "vignetting shift", 2),
    ("rim", "rim", 2),
    ("chromatic_red", "chromatic red", 3),
    ("chromatic_blue", "chromatic blue", 3),
    ("fstop", "fitted f-stop", 2),
    ("diameter_px", "disc px", 1),
)

_STYLE = """
body { font: 14px/1.45 system-ui, sans-serif; margin: 24px auto; max-width: 1300px; color: #1d1d1f; }
h1 { font-size: 22px; } h2 { font-size: 18px; margin-top: 32px; border-bottom: 1px solid #ddd; } h3 { font-size: 15px; }
table { border-collapse: collapse; } td, th { padding: 3px 8px; text-align: right; border-bottom: 1px solid #eee; }
th { background: #f5f5f7; } td:first-child, th:first-child { text-align: left; }
.sentence { font-size: 16px; padding: 8px 12px; background: #eef4fb; border-left: 5px solid #0072b2; }
.thumbs { display: flex; flex-wrap: wrap; gap: 6px; } .thumbs figure { margin: 0; font-size: 11px; text-align: center; }
.thumbs img { height: 72px; border: 1px solid #ccc; } .plots img { max-width: 48%; }
"""


def shape_label(row: dict) -> str | None:
    """A row's aperture in words: ``circle``, ``hexagon``, ``9-blade polygon``, ``rounded hexagon``;
    None where nothing was fitted."""
    from bokehfit.apertures import Aperture

    if row.get("shape") is None or row.get("status") not in FITTED_STATUSES:
        return None
    aperture = Aperture.from_json({"shape": row["shape"], "blades": row.get("blades")})
    rounded = (row.get("roundness") or 0) > 0 and aperture.spec.rounds
    return f"rounded {aperture.display_name}" if rounded else aperture.display_name


def _key(value):
    return (value is None, value if value is not None else 0)


def group_rows(rows: list[dict]) -> dict[tuple, dict[float | None, list[dict]]]:
    """(camera, lens) → EXIF f-number → rows, each level sorted (unknown last)."""
    lenses: dict = collections.defaultdict(lambda: collections.defaultdict(list))
    for row in rows:
        lenses[(row.get("camera"), row.get("lens"))][row.get("exif_fnumber")].append(row)
    return {
        lens: {f: lenses[lens][f] for f in sorted(lenses[lens], key=_key)}
        for lens in sorted(lenses, key=lambda k: (_key(k[0]), _key(k[1])))
    }


def _spread(values: list[float]) -> tuple[float, float, int] | None:
    """(median, MAD, count) of the non-null values, or None."""
    data = np.array([v for v in values if v is not None], dtype=float)
    if data.size == 0:
        return None
    median = float(np.median(data))
    return median, float(np.median(np.abs(data - median))), int(data.size)


def modal_shape(rows: list[dict]) -> tuple[str | None, int, int]:
    """The most common :func:`shape_label` among the rows' fits: (label, its count, fits)."""
    labels = collections.Counter(label for label in map(shape_label, rows) if label)
    if not labels:
        return None, 0, 0
    label, count = labels.most_common(1)[0]
    return label, count, sum(labels.values())


def _fnumber(value: float | None) -> str:
    return "f/?" if value is None else f"f/{value:g}"


def fingerprint_sentence(by_fnumber: dict[float | None, list[dict]]) -> str:
    """How the shape changes with the f-number, e.g. ``circle at f/1.4–f/2.8, hexagon at f/4–f/8``."""
    runs: list[list] = []
    for fnumber, rows in by_fnumber.items():
        if fnumber is None:
            continue
        label = modal_shape(rows)[0] or "no fit"
        if runs and runs[-1][0] == label:
            runs[-1][2] = fnumber
        else:
            runs.append([label, fnumber, fnumber])
    if not runs:
        return "no photo of this lens has an EXIF f-number"
    return ", ".join(f"{label} at {_fnumber(a)}" + (f"–{_fnumber(b)}" if b != a else "") for label, a, b in runs)


#: Full stops (and f/1.2, f/3.5 lenses' common wide ends) for the f-number axes' ticks.
FSTOP_TICKS = (1.0, 1.2, 1.4, 2.0, 2.8, 3.5, 4.0, 5.6, 8.0, 11.0, 16.0, 22.0, 32.0, 45.0, 64.0)


def _fstop_axis(axis, low: float, high: float) -> None:
    """A log₂ f-number axis from ``low`` to ``high`` ticked at the usual stops, labelled ``f/2.8``."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

    ticks = [t for t in FSTOP_TICKS if low <= t <= high] or [low, high]
    axis.set_major_locator(FixedLocator(ticks))
    axis.set_minor_locator(NullLocator())
    axis.set_major_formatter(FuncFormatter(lambda value, _: f"f/{value:g}"))


def _png(figure) -> str:
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=90, bbox_inches="tight")
    return "data:image/png;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


def _plots(by_fnumber: dict[float | None, list[dict]]) -> str:
    """Disc shape against f-number, and fitted f-stop against EXIF FNumber, as two inline PNGs."""
    from matplotlib.figure import Figure

    points = [(f, shape_label(row), row.get("fstop"), is_bound(row)) for f, rows in by_fnumber.items() if f is not None
              for row in rows]
    fitted = [(f, label) for f, label, _, _ in points if label]
    if not fitted:
        return "<p>No fitted photo with an EXIF f-number: nothing to plot.</p>"
    labels = sorted({label for _, label in fitted})
    shape_figure = Figure(figsize=(5.5, 0.6 + 0.45 * len(labels) + 1.2), layout="constrained")
    axes = shape_figure.add_subplot()
    counts = collections.Counter(fitted)
    for (f, label), n in counts.items():
        axes.scatter([f], [labels.index(label)], s=30 + 12 * n, color="#0072b2", alpha=0.8)
        axes.annotate(str(n), (f, labels.index(label)), xytext=(6, 4), textcoords="offset points", fontsize=8)
    axes.set_xscale("log", base=2)
    fnumbers = [f for f, _ in fitted]
    axes.set_xlim(min(fnumbers) / 1.25, max(fnumbers) * 1.25)
    _fstop_axis(axes.xaxis, min(fnumbers) / 1.25, max(fnumbers) * 1.25)
    axes.set_yticks(range(len(labels)), labels)
    axes.set_ylim(-0.6, len(labels) - 0.4)
    axes.set_xlabel("EXIF f-number")
    axes.set_title("disc shape against f-number (dot: photos)")
    fstops = [(f, s, bound) for f, _, s, bound in points if s is not None]
    parts = [f'<img alt="disc shape against f-number" src="{_png(shape_figure)}">']
    if fstops:
        fstop_figure = Figure(figsize=(4.2, 3.8), layout="constrained")
        axes = fstop_figure.add_subplot()
        x, y, bound = (np.array(column, dtype=float) for column in zip(*fstops))
        bound = bound.astype(bool)
        top = max(x.max(), y.max()) * 1.15
        low = min(x.min(), y.min()) / 1.15
        axes.plot([low, top], [low, top], color="#999", lw=1, label="fitted = EXIF")
        if (~bound).any():
            axes.scatter(x[~bound], y[~bound], color="#d55e00", s=22, label="photo: fitted f-stop")
        if bound.any():  # a bound is drawn as one: a bar down from the largest f-stop the discs allow
            axes.scatter(x[bound], y[bound], color="#0072b2", marker="_", s=80, label="photo: at most (upper bound)")
            axes.errorbar(x[bound], y[bound], yerr=y[bound] * 0.2, uplims=True, fmt="none", ecolor="#0072b2", lw=1)
        axes.set_xscale("log", base=2)
        axes.set_yscale("log", base=2)
        axes.set_xlim(low, top)
        axes.set_ylim(low, top)
        _fstop_axis(axes.xaxis, low, top)
        _fstop_axis(axes.yaxis, low, top)
        axes.set_xlabel("EXIF FNumber")
        axes.set_ylabel("fitted f-stop")
        axes.legend(fontsize=8)
        axes.set_title("fitted f-stop (or its upper bound) against EXIF")
        parts.append(f'<img alt="fitted f-stop against EXIF FNumber" src="{_png(fstop_figure)}">')
    else:
        parts.append("<p>No fitted f-stop (the geometry was unknown): give focal length, sensor width and focus "
                     "distance to compare.</p>")
    return '<div class="plots">' + "".join(parts) + "</div>"


def _cell(stats: tuple[float, float, int] | None, digits: int, prefix: str = "") -> str:
    """median ± MAD (count); a single photo's value alone, with no spread to show."""
    if stats is None:
        return "—"
    median, mad, n = stats
    if n == 1:
        return f"{prefix}{median:.{digits}f} <small>(1 photo)</small>"
    return f"{prefix}{median:.{digits}f} ± {mad:.{digits}f} <small>({n})</small>"


def is_bound(row: dict) -> bool:
    """Whether a row's ``fstop`` is an upper bound (the lights' distance unknown), not the f-stop itself."""
    return row.get("fstop_bound") == "upper"


def _fstop_cell(fits: list[dict]) -> str:
    """The fitted f-stops of a group: values as values, upper bounds as "≤" (each summarised apart)."""
    values = _spread([row.get("fstop") for row in fits if not is_bound(row)])
    bounds = _spread([row.get("fstop") for row in fits if is_bound(row)])
    if values is None or bounds is None:
        return _cell(values, 2) if bounds is None else _cell(bounds, 2, "≤ ")
    return f"{_cell(values, 2)}; {_cell(bounds, 2, '≤ ')}"


def _thumbs(rows: list[dict], thumbnails: dict[str, bytes], report_folder: Path, db_folder: Path) -> str:
    items = []
    for row in rows[:THUMBNAILS_PER_GROUP]:
        name = html.escape(Path(row["path"]).name)
        data = thumbnails.get(row["sha256"])
        image = (f'<img alt="{name}" src="data:image/jpeg;base64,{base64.b64encode(data).decode("ascii")}">'
                 if data else f"<span>{name}</span>")
        if row.get("html_path"):
            target = os.path.relpath(db_folder / row["html_path"], report_folder)
            image = f'<a href="{html.escape(Path(target).as_posix())}">{image}</a>'
        items.append(f'<figure>{image}<figcaption>{html.escape(row["status"])}</figcaption></figure>')
    more = len(rows) - THUMBNAILS_PER_GROUP
    if more > 0:
        items.append(f"<p>and {more} more</p>")
    return '<div class="thumbs">' + "".join(items) + "</div>"


def build_report(rows: list[dict], thumbnails: dict[str, bytes], *, report_path: str | os.PathLike,
                 db_path: str | os.PathLike, command_line: str = "") -> str:
    """The fingerprint page as one HTML string (plots and thumbnails inline, links to the compare reports).

    Parameters
    ----------
    rows : list of dict
        The ``photos`` table's rows (:meth:`bokehfit.surveys.store.SurveyStore.table`, as Python dicts).
    thumbnails : dict
        sha256 → JPEG bytes.
    report_path, db_path : path-like
        Where the page and the database are, for the relative links to the per-photo reports.
    """
    report_folder, db_folder = Path(report_path).resolve().parent, Path(db_path).resolve().parent
    statuses = collections.Counter(row["status"] for row in rows)
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>bokehfit survey: {html.escape(Path(db_path).name)}</title><style>{_STYLE}</style></head><body>",
        f"<h1>bokehfit survey: {html.escape(Path(db_path).name)}</h1>",
        f"<p>{len(rows)} photos: " + ", ".join(f"{statuses[s]} {s}" for s in STATUSES if statuses[s])
        + f". bokehfit {html.escape(__version__)}; {html.escape(command_line)}</p>",
        "<p>Each value is the median ± the median absolute deviation over the group's fitted photos "
        "(sure and unsure), with their number; — where nothing was fitted. ≤ f/N: an upper bound on the f-stop "
        "(the lights' distance is unknown: lights nearer than infinity need a smaller f-stop).</p>",
    ]
    for (camera, lens), by_fnumber in group_rows(rows).items():
        title = f"{camera or 'unknown camera'} · {lens or 'unknown lens'}"
        count = sum(len(r) for r in by_fnumber.values())
        parts.append(f"<section class='lens'><h2>{html.escape(title)} <small>({count} photos)</small></h2>")
        parts.append(f"<p class='sentence'>{html.escape(fingerprint_sentence(by_fnumber))}</p>")
        parts.append(_plots(by_fnumber))
        head = "".join(f"<th>{html.escape(heading)}</th>" for _, heading, _ in SUMMARISED)
        parts.append(f"<table><tr><th>f-number</th><th>photos</th><th>statuses</th><th>shape</th>{head}</tr>")
        for fnumber, group in by_fnumber.items():
            fits = [row for row in group if row["status"] in FITTED_STATUSES]
            label, n, total = modal_shape(group)
            shape = f"{label} ({n}/{total})" if label else "—"
            counts = collections.Counter(row["status"] for row in group)
            status_text = ", ".join(f"{counts[s]} {s}" for s in STATUSES if counts[s])
            cells = "".join(f"<td>{_fstop_cell(fits) if column == 'fstop' else _cell(_spread([row.get(column) for row in fits]), digits)}</td>"
                            for column, _, digits in SUMMARISED)
            parts.append(f"<tr class='group'><td>{_fnumber(fnumber)}</td><td>{len(group)}</td><td>{status_text}</td>"
                         f"<td>{html.escape(shape)}</td>{cells}</tr>")
        parts.append("</table>")
        for fnumber, group in by_fnumber.items():
            parts.append(f"<h3>{html.escape(title)} at {_fnumber(fnumber)}</h3>")
            parts.append(_thumbs(group, thumbnails, report_folder, db_folder))
        parts.append("</section>")
    parts.append("</body></html>")
    return "\n".join(parts)
