"""``bokehfit bench --quick``: the JSON's keys, the kernels' convergence, the HTML's plots.

One run of ``bokehfit bench --quick --json out.json --html out.html`` (through
``bokehfit.cli.main``, so warnings are errors; about 30 s on two cores with
lavapipe) serves every test. The generated photos go to a temporary cache folder.
"""

from __future__ import annotations

import base64
import io
import json
import re
from collections import defaultdict

import numpy as np
import pytest
from PIL import Image

import bokehfit
from bokehfit.bench.kernels import BENCH_APERTURES

#: Largest L1 of the exact method against the reference: float32 storage of the image
#: (the reference is the same integral in float64 on a 2× finer grid) gives ~4e-8.
EXACT_MAX_L1 = 1e-6
#: The convergence rate of independent Monte Carlo is N^-1/2 in theory; a fit over two
#: decades with a few per cent of seed noise in L1 lands within ±0.02 of it, so ±0.1 is loose.
INDEPENDENT_RATE = -0.5
INDEPENDENT_RATE_TOLERANCE = 0.1
#: Plots the HTML report must embed at least (L1 against time, L1 against samples, ...).
MIN_PLOTS = 2
MIN_PLOT_SIDE_PX = 100


@pytest.fixture(scope="module")
def bench(gpu, tmp_path_factory):
    from bokehfit.cli import main

    folder = tmp_path_factory.mktemp("bench")
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(folder)
        patch.setenv("BOKEHFIT_CACHE_DIR", str(folder / "cache"))
        main(["bench", "--quick", "--json", "out.json", "--html", "out.html"])
    return folder


@pytest.fixture(scope="module")
def result(bench):
    return json.loads((bench / "out.json").read_text(encoding="utf-8"))


def _series(rows):
    """Sampled kernel rows by (method, sampling, shape, diameter), sorted by samples."""
    series = defaultdict(list)
    for row in rows:
        if row["method"] != "exact":
            series[(row["method"], row["sampling"], row["shape"], row["diameter_px"])].append(row)
    return {key: sorted(rows, key=lambda r: r["samples"]) for key, rows in series.items()}


def test_json_has_the_documented_keys(result):
    assert result["schema_version"] == 1
    assert result["bokehfit_version"] == bokehfit.__version__
    assert result["command_line"] == "bokehfit bench --quick --json out.json --html out.html"
    assert set(result["device"]) >= {"adapter", "backend"} and result["device"]["adapter"]
    kernel_keys = {"method", "sampling", "shape", "diameter_px", "samples", "time_s", "l1"}
    assert result["kernel"] and all(set(row) >= kernel_keys for row in result["kernel"])
    assert {row["method"] for row in result["kernel"]} == {"exact", "mc", "raster"}
    mc_samplings = {row["sampling"] for row in result["kernel"] if row["method"] == "mc"}
    assert mc_samplings == {"independent", "stratified"}
    assert {row["shape"] for row in result["kernel"]} == set(BENCH_APERTURES)
    assert {row["diameter_px"] for row in result["kernel"]} == {64.0}
    rate_keys = {"method", "sampling", "shape", "diameter_px", "rate"}
    assert result["rates"] and all(set(row) >= rate_keys for row in result["rates"])
    fit_keys = {"budget_s", "max_fit_discs", "shape_accuracy", "angle_err_deg", "diameter_err"}
    assert [row["max_fit_discs"] for row in result["fit"]] == [2, 6]
    assert all(set(row) >= fit_keys and row["budget_s"] > 0 for row in result["fit"])
    compare_keys = {"megapixels", "load_s", "detect_s", "fit_s", "render_s", "metrics_s", "total_s", "cold_total_s"}
    assert set(result["compare"]) >= compare_keys
    assert 3.5 < result["compare"]["megapixels"] < 4.5


def test_quick_sweep_is_complete(result):
    """1e3 … 1e6 samples for every sampled series: nothing skipped or merged at 64 px."""
    assert not result["kernel_skipped"]
    series = _series(result["kernel"])
    assert len(series) == 3 * len(BENCH_APERTURES)  # (mc independent, mc stratified, raster) × apertures
    for key, rows in series.items():
        assert [r["requested_samples"] for r in rows] == [10**3, 10**4, 10**5, 10**6], key


def test_l1_decreases_with_samples(result):
    # Strictly, without tolerance: the counts are a decade apart, so L1 falls by
    # 10^0.5 ≈ 3.2 (independent) to 10^0.75 ≈ 5.6 (stratified, raster) from one to the
    # next, far beyond its seed-to-seed spread (a few per cent: L1 sums thousands of pixels).
    for key, rows in _series(result["kernel"]).items():
        l1 = [r["l1"] for r in rows]
        assert all(b < a for a, b in zip(l1, l1[1:])), f"{key}: L1 {l1} at samples {[r['samples'] for r in rows]}"


def test_exact_l1_is_rounding_only(result):
    exact = [row for row in result["kernel"] if row["method"] == "exact"]
    assert len(exact) == len(BENCH_APERTURES)
    for row in exact:
        assert row["samples"] is None and row["sampling"] is None
        assert row["l1"] <= (row["error_bound"] or EXACT_MAX_L1), row  # the tabulated rim: its stated bound


def test_stratified_mc_converges_faster_than_independent(result):
    rates = {(r["method"], r["sampling"], r["shape"]): r["rate"] for r in result["rates"]}
    for shape in ("circle", "hexagon", "star"):
        stratified, independent = rates[("mc", "stratified", shape)], rates[("mc", "independent", shape)]
        assert stratified < independent, f"{shape}: stratified N^{stratified:.2f}, independent N^{independent:.2f}"
        assert abs(independent - INDEPENDENT_RATE) < INDEPENDENT_RATE_TOLERANCE, f"{shape}: N^{independent:.2f}"


def test_compare_stages_add_up(result):
    c = result["compare"]
    stages = sum(c[f"{s}_s"] for s in ("load", "detect", "fit", "render", "metrics"))
    assert 0 < stages <= c["total_s"] * 1.001
    assert c["cold_total_s"] > 0 and c["discs_fitted"] > 0


def test_compare_beside_the_bare_decode_and_the_targets(result, bench):
    from bokehfit.bench.compare import TARGETS

    c = result["compare"]
    assert result["parts"] == "abc"
    assert 0 < c["decode_s"] < c["total_s"]
    assert c["warm_over_decode"] == pytest.approx(c["total_s"] / c["decode_s"])
    assert c["load_detect_over_decode"] == pytest.approx((c["load_s"] + c["detect_s"]) / c["decode_s"])
    # Peak memory: the cold process's peak RSS over its RSS before the call, per pixel of the photo.
    assert 0 < c["rss_before_bytes"] < c["rss_peak_bytes"]
    assert c["peak_bytes_per_px"] == pytest.approx(
        (c["rss_peak_bytes"] - c["rss_before_bytes"]) / (c["width"] * c["height"]))
    # --quick measures a 4-MP photo: the 24-MP photo's targets are stated, not judged on it
    assert TARGETS and c["targets"] == {} and "24-MP photo" in c["targets_note"]
    from bokehfit.bench.report import target_table

    header, rows = target_table(result)
    assert "24 MP" in header[2] and [row[3] for row in rows] == ["not judged"] * len(TARGETS)
    big = dict(result, compare=dict(c, targets=dict(TARGETS)))  # the full run judges them
    assert {row[3] for row in target_table(big)[1]} <= {"yes", "no"}
    assert c["cold_process_s"] >= c["cold_total_s"] + c["cold_import_s"]
    # The photo is a colour JPEG, as a camera writes one.
    with Image.open(c["photo"]) as photo:
        assert photo.format == "JPEG" and photo.mode == "RGB"
        rgb = np.asarray(photo.convert("RGB"), dtype=np.float64)
    assert np.abs(rgb[..., 0] - rgb[..., 2]).mean() > 1.0  # not grey
    # The kernel of these discs is drawn exactly (no GPU started), and the report says which.
    assert c["kernel_method"] == c["cold_kernel_method"] == "exact"
    page = (bench / "out.html").read_text(encoding="utf-8")
    assert "warm compare / bare decode" in page and "B/px" in page


def test_parts_are_checked_before_anything_runs():
    from bokehfit.bench import run_bench
    from bokehfit.errors import InputError

    for parts in ("", "d", "ac x"):
        with pytest.raises(InputError, match=r"^parts must be one or more of the letters a, b, c"):
            run_bench(True, parts=parts)


def test_html_embeds_decodable_png_plots(bench):
    page = (bench / "out.html").read_text(encoding="utf-8")
    assert "<script" not in page and "http://" not in page and "https://" not in page  # self-contained
    plots = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    assert len(plots) >= MIN_PLOTS
    for data in plots:
        with Image.open(io.BytesIO(base64.b64decode(data, validate=True))) as image:
            image.load()
            assert image.format == "PNG" and min(image.size) >= MIN_PLOT_SIDE_PX


def test_no_temporary_files_left(bench):
    assert not list(bench.glob(".out.*")), "temporary files left behind"
