"""The ``bokehfit bench`` report for people: text tables, and one self-contained HTML page.

The page holds the tables and log-log plots (matplotlib, PNG embedded as
base64): kernel L1 against render time and against samples (with the fitted
rates), fit error against the fit time per photo, and ``compare``'s time by stage.
"""

from __future__ import annotations

import base64
import html
import io
import math

__all__ = ["build_html", "compare_table", "fit_table", "format_tables", "kernel_table", "markdown_table", "target_table"]

#: Line colour and marker of each kernel variant, by label.
_STYLES = {
    "exact": ("#222222", "*"),
    "mc independent": ("#d62728", "o"),
    "mc stratified": ("#1f77b4", "s"),
    "raster": ("#2ca02c", "^"),
}
_CSS = """
body { font: 14px/1.45 system-ui, sans-serif; margin: 24px auto; max-width: 1200px; color: #1d1d1f; }
h1 { font-size: 22px; } h2 { font-size: 17px; margin-top: 28px; border-bottom: 1px solid #ddd; }
table { border-collapse: collapse; margin: 8px 0; } td, th { padding: 3px 10px; text-align: right; border-bottom: 1px solid #eee; }
th { background: #f5f5f7; } td:first-child, th:first-child { text-align: left; }
.summary { font-size: 15px; background: #f5f5f7; padding: 10px 14px; border-radius: 6px; }
img.plot { max-width: 100%; border: 1px solid #ddd; } .note { color: #555; }
"""
STAGES = ("load", "detect", "fit", "render", "metrics", "total")


def _label(method: str, sampling: str | None) -> str:
    return method if sampling is None else f"{method} {sampling}"


def _series(rows: list[dict]) -> dict:
    """Kernel rows grouped by (shape, diameter) then variant label, in run order."""
    groups: dict = {}
    for row in rows:
        frame = groups.setdefault((row["shape"], row["diameter_px"]), {})
        frame.setdefault(_label(row["method"], row["sampling"]), []).append(row)
    return groups


def _rate(result: dict, shape: str, diameter: float, label: str) -> float | None:
    for r in result["rates"]:
        if (r["shape"], r["diameter_px"], _label(r["method"], r["sampling"])) == (shape, diameter, label):
            return r["rate"]
    return None


def _num(value, fmt: str, missing: str = "—") -> str:
    return missing if value is None or (isinstance(value, float) and not math.isfinite(value)) else format(value, fmt)


# --------------------------------------------------------------------------------------
# Tables (lists of rows, shared by the text and the HTML)
# --------------------------------------------------------------------------------------


def kernel_table(result: dict) -> tuple[list[str], list[list[str]]]:
    """(header, rows): per shape, size and variant, "L1 (ms)" at each requested sample count, and the rate."""
    counts = result["settings"]["samples"]
    header = ["shape", "d px", "frame", "method"] + [f"{n:.0e}" for n in counts] + ["rate"]
    rows = []
    for (shape, diameter), variants in _series(result["kernel"]).items():
        for label, series in variants.items():
            cells = [""] * len(counts)
            for row in series:
                column = 0 if row["requested_samples"] is None else counts.index(row["requested_samples"])
                cells[column] = f"{row['l1']:.2e} ({row['time_s'] * 1e3:.2f})"
            for skipped in result.get("kernel_skipped", []):
                if (skipped["shape"], skipped["diameter_px"], _label(skipped["method"], skipped["sampling"])) == (shape, diameter, label):
                    cells[counts.index(skipped["requested_samples"])] = "skipped"
            if label != "exact":
                cells = [cell or "(= left)" for cell in cells]  # rounded to the previous count's samples
            rate = _rate(result, shape, diameter, label)
            rows.append([shape, f"{diameter:g}", str(series[0]["size"]), label, *cells,
                         "—" if rate is None else f"{rate:.2f}"])
    return header, rows


def fit_table(result: dict) -> tuple[list[str], list[list[str]]]:
    header = ["max_discs", "budget_s (mean fit s/photo)", "max s", "shape right", "angle err ° median", "max",
              "diameter err median", "max"]
    rows = [[str(r["max_fit_discs"]), f"{r['budget_s']:.3f}", f"{r['fit_max_s']:.3f}",
             f"{r['correct']}/{r['photos']} ({100 * r['shape_accuracy']:.0f} %)",
             _num(r["angle_err_deg"], ".3f"), _num(r["angle_err_max_deg"], ".3f"),
             _num(None if r["diameter_err"] is None else 100 * r["diameter_err"], ".2f") + " %",
             _num(None if r["diameter_err_max"] is None else 100 * r["diameter_err_max"], ".2f") + " %"]
            for r in result["fit"]]
    return header, rows


def compare_table(result: dict) -> tuple[list[str], list[list[str]]]:
    c = result["compare"]
    header = ["call", *STAGES]
    rows = [
        ["warm (after a warm-up call)", *(_num(c.get(f"{s}_s"), ".3f") for s in STAGES)],
        ["cold (1st call, fresh process)", *(_num(c["cold_stages_s"].get(s), ".3f") for s in STAGES)],
    ]
    return header, rows


#: (label, key in the compare result, format, unit) of :func:`target_table`, in the order of ``TARGETS``.
_TARGET_ROWS = (
    ("warm compare", "total_s", ".2f", " s"),
    ("warm compare / bare decode", "warm_over_decode", ".1f", "×"),
    ("cold process, start to exit", "cold_process_s", ".2f", " s"),
    ("(load + detect) / bare decode, warm", "load_detect_over_decode", ".1f", "×"),
    ("peak memory of the cold process", "peak_bytes_per_px", ".1f", " B/px"),
)
_TARGET_KEYS = ("warm_s", "warm_over_decode", "cold_process_s", "load_detect_over_decode", "peak_bytes_per_px")


def target_table(result: dict) -> tuple[list[str], list[list[str]]]:
    """(header, rows): each figure the targets speak of, measured, beside its target and whether it is met.

    The targets are for one photo size (``targets_photo``); a run that measured another size (``--quick``)
    has none, and its rows say "not judged" rather than comparing figures of different sizes.
    """
    c = result["compare"]
    targets = c.get("targets", {})
    header = ["figure", "measured", f"target ({c.get('targets_photo', '24 MP')}, 2 cores)", "met"]
    rows = []
    for (label, key, fmt, unit), target_key in zip(_TARGET_ROWS, _TARGET_KEYS):
        value, target = c.get(key), targets.get(target_key)
        if not targets:
            rows.append([label, _num(value, fmt) + unit, "— (not this photo's size)", "not judged"])
            continue
        met = "—" if value is None or target is None else ("yes" if value <= target else "no")
        rows.append([label, _num(value, fmt) + unit, "—" if target is None else f"≤ {target:g}{unit}", met])
    return header, rows


def _memory_line(c: dict) -> str:
    if c.get("peak_bytes") is None:
        return ""
    return (f"bare decode (cv2.imread, best of 3): {c['decode_s']:.3f} s; peak memory: the cold process's peak RSS "
            f"(VmHWM) after compare minus its RSS before it (after the imports), {c['peak_bytes'] / 2**20:.0f} MiB "
            f"over {c['width'] * c['height'] / 1e6:.1f} M pixels ({c['rss_before_bytes'] / 2**20:.0f} MiB before, "
            f"{c['rss_peak_bytes'] / 2**20:.0f} MiB at the peak)")


def _cut_off_line(result: dict) -> str:
    limit = result["settings"].get("max_point_s")
    if limit is None:
        return "cut-off: none (every count rendered)"
    skipped = len(result.get("kernel_skipped", []))
    return (f"cut-off: a count whose predicted render time (the previous count's, scaled) exceeds {limit:g} s "
            f"is skipped with all larger ones; {skipped or 'none'} skipped in this run")


def markdown_table(header: list[str], rows: list[list[str]], left: int = 1) -> str:
    """A Markdown table; the first ``left`` columns are left-aligned, the rest right-aligned."""
    lines = ["| " + " | ".join(header) + " |",
             "|" + "".join("---|" if i < left else "---:|" for i in range(len(header)))]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def format_tables(result: dict) -> str:
    """The whole result as text (Markdown tables) for the terminal."""
    device, c = result["device"], result["compare"]
    runtime = result["runtime_s"]
    parts = result.get("parts", "abc")
    out = [
        f"bokehfit {result['bokehfit_version']} bench{' --quick' if result['quick'] else ''}: "
        f"{device['adapter']} ({device['backend']}); OpenGL: {device['gl_renderer']}; "
        f"Python {result['platform']['python']}, {result['platform']['cpus']} CPUs",
    ]
    if "a" in parts:
        out += [
            "",
            f"## (a) Kernel error against time: L1 to the exact kernel (render time, ms), {result['settings']['angle_deg']:g}°",
            "",
            markdown_table(*kernel_table(result), left=4),
            "",
            "rate: slope of log L1 against log samples over the points with ≥ 1 sample per disc pixel; counts are "
            "requested samples (mc stratified rounds up to m², raster to whole passes: the JSON has the drawn ones)",
            _cut_off_line(result),
        ]
        out += [f"note: {note}" for note in result["notes"]]
    if "b" in parts:
        out += [
            "",
            "## (b) Fit error against fit time (budget knob: FitOptions.max_discs)",
            "",
            result["fit_set"],
            "",
            markdown_table(*fit_table(result)),
        ]
        for budget, names in result["fit_misses"].items():
            out.append(f"wrong shape at max_discs={budget}: {', '.join(names)}")
    if "c" in parts:
        out += [
            "",
            f"## (c) compare on a {c['megapixels']:.1f}-MP {c.get('colour', 'grey')} JPEG ({c['width']}×{c['height']}, "
            f"{c['discs_drawn']} {c['truth']} discs), seconds",
            "",
            markdown_table(*compare_table(result)),
            "",
            f"found {c['discs_found']} discs ({c['discs_usable']} clean), fitted {c['discs_fitted']}: {c['aperture']}; "
            f"kernel {c.get('kernel_method')} (cold: {c.get('cold_kernel_method')}); warm-up call on a "
            f"{c['warmup_megapixels']:.2f}-MP photo: {c['warmup_total_s']:.2f} s; cold process: import "
            f"bokehfit.compare {c['cold_import_s']:.2f} s, start to exit {c['cold_process_s']:.2f} s",
        ]
        if "decode_s" in c:
            out += ["", markdown_table(*target_table(result))] + (["", c["targets_note"]] if c.get("targets_note") else [])
            out += ["", _memory_line(c)]
    ran = ", ".join(f"{name} {runtime[name]:.1f} s" for name in ("kernel", "fit", "compare") if name in runtime)
    out += ["", f"bench run time: {ran}, total {runtime['total']:.1f} s"]
    return "\n".join(out)


# --------------------------------------------------------------------------------------
# Plots
# --------------------------------------------------------------------------------------


def _png(figure) -> str:
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=100, bbox_inches="tight")
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def _kernel_figure(result: dict, x_key: str):
    from matplotlib.figure import Figure

    groups = _series(result["kernel"])
    shapes = result["settings"]["shapes"]
    diameters = result["settings"]["diameters_px"]
    figure = Figure(figsize=(4.2 * len(shapes), 3.4 * len(diameters)), layout="constrained")
    axes = figure.subplots(len(diameters), len(shapes), squeeze=False, sharex=True, sharey=True)
    for i, diameter in enumerate(diameters):
        for j, shape in enumerate(shapes):
            ax = axes[i][j]
            for label, series in groups.get((shape, diameter), {}).items():
                colour, marker = _STYLES.get(label, ("#777777", "o"))
                points = [(r[x_key], r["l1"]) for r in series if r[x_key] is not None and r["l1"] > 0]
                if not points:
                    continue
                xs, ys = zip(*points)
                name = label
                if x_key == "samples":
                    rate = _rate(result, shape, diameter, label)
                    name += "" if rate is None else f" (N^{rate:.2f})"
                ax.plot(xs, ys, marker=marker, color=colour, label=name, linestyle="-" if len(xs) > 1 else "none",
                        markersize=9 if marker == "*" else 5)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.grid(True, which="major", alpha=0.3)
            ax.set_title(f"{shape}, {diameter:g} px", fontsize=10)
            if i == len(diameters) - 1:
                ax.set_xlabel("render time (s)" if x_key == "time_s" else "samples drawn")
            if j == 0:
                ax.set_ylabel("L1 to exact")
            if x_key == "samples":
                ax.legend(fontsize=7, loc="lower left")
    if x_key != "samples":
        handles, labels = axes[0][0].get_legend_handles_labels()
        figure.legend(handles, labels, fontsize=8, ncols=len(labels), loc="outside upper center")
    return figure


def _fit_figure(result: dict):
    from matplotlib.figure import Figure

    rows = result["fit"]
    figure = Figure(figsize=(13, 3.8), layout="constrained")
    axes = figure.subplots(1, 3)
    panels = (
        ("shape accuracy", (("share right", "shape_accuracy", "-"),), False),
        ("angle error (°)", (("median", "angle_err_deg", "-"), ("largest", "angle_err_max_deg", "--")), True),
        ("diameter error (relative)", (("median", "diameter_err", "-"), ("largest", "diameter_err_max", "--")), True),
    )
    for ax, (title, series, log_y) in zip(axes, panels):
        plotted = False
        for name, key, style in series:
            points = [(r["budget_s"], r[key], r["max_fit_discs"]) for r in rows
                      if r[key] is not None and r["budget_s"] > 0 and (r[key] > 0 or not log_y)]
            if not points:
                continue
            xs, ys, knobs = zip(*points)
            ax.plot(xs, ys, marker="o", linestyle=style, color="#1f77b4", label=name)
            for x, y, knob in points:
                ax.annotate(str(knob), (x, y), textcoords="offset points", xytext=(4, 4), fontsize=8)
            plotted = True
        if plotted:
            ax.set_xscale("log")
            if log_y:
                ax.set_yscale("log")
                ax.legend(fontsize=8)
        else:
            ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
        if not log_y:
            ax.set_ylim(-0.05, 1.05)
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("fit time per photo, budget_s (s)")
        ax.grid(True, which="major", alpha=0.3)
    figure.suptitle("Fit error against fit time (point labels: FitOptions.max_discs)", fontsize=11)
    return figure


def _compare_figure(result: dict):
    from matplotlib.figure import Figure

    c = result["compare"]
    figure = Figure(figsize=(10, 2.6), layout="constrained")
    ax = figure.subplots()
    colours = ("#8c564b", "#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd")
    calls = (("warm", {s: c.get(f"{s}_s") for s in STAGES}), ("cold (fresh process)", c["cold_stages_s"]))
    for y, (_, stages) in enumerate(calls):
        left = 0.0
        for stage, colour in zip(STAGES[:-1], colours):
            width = stages.get(stage) or 0.0
            ax.barh(y, width, left=left, color=colour, label=stage if y == 0 else None)
            left += width
        total = stages.get("total") or left
        ax.text(total, y, f" {total:.2f} s", va="center", fontsize=9)
    ax.set_yticks(range(len(calls)), [name for name, _ in calls])
    ax.invert_yaxis()
    ax.set_xlabel("seconds")
    ax.set_title(f"compare on a {c['megapixels']:.1f}-MP JPEG, by stage", fontsize=10)
    figure.legend(fontsize=8, ncols=5, loc="outside lower center")
    return figure


# --------------------------------------------------------------------------------------
# HTML
# --------------------------------------------------------------------------------------


def _table(header: list[str], rows: list[list[str]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _img(figure, alt: str) -> str:
    return f'<p><img class="plot" src="data:image/png;base64,{_png(figure)}" alt="{html.escape(alt)}"></p>'


def build_html(result: dict) -> str:
    """The whole report as one self-contained HTML string (plots as base64 PNG)."""
    device, c, runtime = result["device"], result["compare"], result["runtime_s"]
    title = f"bokehfit bench{' --quick' if result['quick'] else ''}"
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>{html.escape(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{html.escape(title)}: speed against error</h1>",
        f"<p class='summary'>WebGPU: {html.escape(device['adapter'])} ({html.escape(device['backend'])}); "
        f"OpenGL: {html.escape(device['gl_renderer'])}; Python {html.escape(result['platform']['python'])}, "
        f"{result['platform']['cpus']} CPUs. Run time {runtime['total']:.1f} s.</p>",
    ]
    parts_run = result.get("parts", "abc")
    if "a" in parts_run:
        parts += [
            "<h2>(a) Kernel error against render time</h2>",
            "<p>L1 distance of each kernel to the exact one, against <code>Kernel.time_s</code> (after a warm-up "
            "render per method). The exact method is the star: its error is only float32 rounding.</p>",
            _img(_kernel_figure(result, "time_s"), "kernel L1 against render time"),
            "<p>The same errors against the samples drawn; the legend gives the fitted convergence rate "
            "(slope of log L1 against log samples, from one sample per disc pixel up).</p>",
            _img(_kernel_figure(result, "samples"), "kernel L1 against samples"),
            "<p>Cells: L1 (render time in ms) at each requested sample count.</p>",
            _table(*kernel_table(result)),
        ]
        parts += [f"<p class='note'>{html.escape(line)}</p>" for line in [_cut_off_line(result), *result["notes"]]]
    if "b" in parts_run:
        parts += [
            "<h2>(b) Fit error against fit time</h2>",
            f"<p>{html.escape(result['fit_set'])}. The budget knob is <code>FitOptions.max_discs</code>; "
            "budget_s is the mean measured fit time per photo.</p>",
            _img(_fit_figure(result), "fit error against fit time"),
            _table(*fit_table(result)),
        ]
    if "c" in parts_run:
        parts += [
            f"<h2>(c) compare on a {c['megapixels']:.1f}-MP JPEG</h2>",
            f"<p>{c['width']}×{c['height']} {html.escape(c.get('colour', 'grey'))}, {c['discs_drawn']} "
            f"{html.escape(c['truth'])} discs; found {c['discs_found']} ({c['discs_usable']} clean), fitted "
            f"{c['discs_fitted']}: {html.escape(str(c['aperture']))}; kernel {html.escape(str(c.get('kernel_method')))}. "
            f"The warm call follows a warm-up call on a {c['warmup_megapixels']:.2f}-MP photo; the cold one is the "
            f"first call of a fresh process (import of bokehfit.compare before it: {c['cold_import_s']:.2f} s).</p>",
            _img(_compare_figure(result), "compare time by stage"),
            _table(*compare_table(result)),
        ]
        if "decode_s" in c:
            parts += [_table(*target_table(result))]
            if c.get("targets_note"):
                parts.append(f"<p class='note'>{html.escape(c['targets_note'])}</p>")
            parts.append(f"<p class='note'>{html.escape(_memory_line(c))}</p>")
    parts += [
        f"<p><small>{html.escape(result['command_line'])}; bokehfit {html.escape(result['bokehfit_version'])}, "
        f"schema_version {result['schema_version']}</small></p></body></html>",
    ]
    return "\n".join(parts)
