"""``bokehfit survey`` on a small library made here: rows, statuses, resume after SIGKILL, Dask, the report.

The library: renders with known apertures (a circle at f/2, a hexagon at f/4)
whose disc sizes follow the thin-lens formula for the f-number written into
their EXIF, plus a file that is not a photo and a photo with no disc. Small
images and two shapes to try keep each compare around a second on a CPU adapter.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from html.parser import HTMLParser
from pathlib import Path

import duckdb
import numpy as np
import pyarrow.parquet
import pytest
from PIL import Image

import bokehfit
from bokehfit.apertures import make_aperture
from bokehfit.surveys.files import find_photos
from bokehfit.synthetic import SyntheticDisc, encode_srgb8, render_discs

WIDTH_PX, HEIGHT_PX = 200, 140
FOCAL_LENGTH_MM, FOCUS_DISTANCE_MM = 50.0, 2000.0
#: f/2 gives 40 px discs: c = f² / (N (d_f − f)) on the sensor (design.md §4), scaled by width / sensor width.
SENSOR_WIDTH_MM = FOCAL_LENGTH_MM**2 / (2.0 * (FOCUS_DISTANCE_MM - FOCAL_LENGTH_MM)) * WIDTH_PX / 40.0
CAMERA, LENS = "Survey Cam", "Survey 50mm"
#: (file name, EXIF f-number, aperture shape) of the rendered photos.
RENDERS = (("a_f2.jpg", 2.0, "circle"), ("b_f2.jpg", 2.0, "circle"), ("c_f4.jpg", 4.0, "hexagon"), ("d_f4.jpg", 4.0, "hexagon"))
NOT_A_PHOTO, NO_DISCS = "garbage.jpg", "flat.png"
EXPECTED_STATUS = {**{name: "fitted" for name, _, _ in RENDERS}, NOT_A_PHOTO: "unreadable", NO_DISCS: "no_discs"}
FSTOP_TOL_REL = 0.03
COMPARE_OPTIONS = ["--shapes", "circle,hexagon", "--sensor-width-mm", f"{SENSOR_WIDTH_MM:.6f}", "--focus-distance-m",
                   f"{FOCUS_DISTANCE_MM / 1000:g}"]
API_OPTIONS = {"shapes": ["circle", "hexagon"], "sensor_width_mm": round(SENSOR_WIDTH_MM, 6),
               "focus_distance_m": FOCUS_DISTANCE_MM / 1000}
#: Columns that must agree between two surveys of the same photos (timing, worker and paths aside).
SAME_COLUMNS = ("sha256", "status", "reason", "camera", "lens", "exif_fnumber", "shape", "blades", "angle_deg",
                "diameter_px", "fstop", "discs_found", "discs_fitted")


def disc_diameter_px(fnumber: float) -> float:
    coc_mm = FOCAL_LENGTH_MM**2 / (fnumber * (FOCUS_DISTANCE_MM - FOCAL_LENGTH_MM))
    return coc_mm * WIDTH_PX / SENSOR_WIDTH_MM


def write_render(path: Path, fnumber: float, shape: str, seed: int) -> None:
    diameter = disc_diameter_px(fnumber)
    centres = [(40.0 + seed % 3, 40.0), (100.0, 40.0), (160.0, 40.0), (40.0, 100.0), (100.0, 100.0), (160.0, 100.0)]
    discs = [SyntheticDisc(c, diameter, make_aperture(shape, 15.0)) for c in centres[: 4 if diameter > 30 else 6]]
    linear = render_discs(WIDTH_PX, HEIGHT_PX, discs, background=0.03, noise_sigma=0.002, seed=seed)
    exif = Image.Exif()
    exif[0x0110] = CAMERA  # Model
    sub = exif.get_ifd(0x8769)
    sub[0x829D] = fnumber  # FNumber
    sub[0xA434] = LENS  # LensModel
    sub[0x920A] = FOCAL_LENGTH_MM  # FocalLength
    Image.fromarray(encode_srgb8(linear)).convert("RGB").save(path, exif=exif.tobytes(), quality=92)


def make_library(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for seed, (name, fnumber, shape) in enumerate(RENDERS):
        write_render(folder / name, fnumber, shape, seed)
    (folder / NOT_A_PHOTO).write_bytes(b"this is not a JPEG\n" * 8)
    Image.fromarray(np.full((80, 80, 3), 40, np.uint8)).save(folder / NO_DISCS)
    (folder / "notes.txt").write_text("not a photo suffix: a folder walk leaves it out\n")
    return folder


def survey_cli(*args, cwd: Path, **popen):
    """``python -m bokehfit survey ARGS`` in ``cwd``: the CompletedProcess (or the Popen with ``popen``)."""
    command = [sys.executable, "-m", "bokehfit", "survey", *map(str, args)]
    if popen:
        return subprocess.Popen(command, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen)
    return subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=300)


def rows(db: Path) -> dict[str, dict]:
    """The database's rows by file name, read as any DuckDB client would."""
    with duckdb.connect(str(db), read_only=True) as connection:
        cursor = connection.execute("SELECT * FROM photos")
        names = [d[0] for d in cursor.description]
        return {Path(row[names.index("path")]).name: dict(zip(names, row)) for row in cursor.fetchall()}


def same_part(table: dict[str, dict]) -> dict[str, tuple]:
    return {name: tuple(row[c] for c in SAME_COLUMNS) for name, row in table.items()}


@pytest.fixture(scope="module")
def surveyed(tmp_path_factory, gpu):
    """The library surveyed once with ``--jobs 2``, with the report and the Parquet export."""
    folder = tmp_path_factory.mktemp("survey")
    make_library(folder / "lib")
    done = survey_cli("lib", "--db", "lens.duckdb", "--jobs", 2, "--report", "lens.html", "--parquet", "lens.parquet",
                      *COMPARE_OPTIONS, cwd=folder)
    assert done.returncode == 0, done.stderr
    return {"folder": folder, "done": done, "rows": rows(folder / "lens.duckdb")}


# --------------------------------------------------------------------------------------
# One row per photo, with the right status
# --------------------------------------------------------------------------------------


def test_one_row_per_photo_with_its_status(surveyed):
    table = surveyed["rows"]
    assert {name: row["status"] for name, row in table.items()} == EXPECTED_STATUS
    assert "6 new (4 fitted, 1 no_discs, 1 unreadable)" in surveyed["done"].stdout
    assert "not a JPEG, PNG, TIFF or camera raw" in table[NOT_A_PHOTO]["reason"]
    assert table[NO_DISCS]["reason"].startswith("no bokeh disc found")


def test_rows_hold_the_known_apertures_and_exif(surveyed):
    for name, fnumber, shape in RENDERS:
        row = surveyed["rows"][name]
        assert (row["camera"], row["lens"], row["exif_fnumber"]) == (CAMERA, LENS, fnumber)
        assert row["shape"] == shape, name
        assert abs(row["fstop"] / fnumber - 1) < FSTOP_TOL_REL, (name, row["fstop"])
        # Straight blades: roundness 0, estimated (a circle has none: null); no disc far enough out for vignetting.
        assert row["roundness"] == (0.0 if shape == "hexagon" else None) and row["vignetting_radius"] is None


def test_each_row_is_keyed_by_the_content_hash_and_has_its_reports(surveyed):
    import hashlib

    folder = surveyed["folder"]
    for name, row in surveyed["rows"].items():
        assert row["sha256"] == hashlib.sha256((folder / "lib" / name).read_bytes()).hexdigest()
        if row["status"] == "unreadable":
            assert row["json_path"] is None
            continue
        document = json.loads((folder / row["json_path"]).read_text())
        assert document["schema_version"] == 2 and document["status"] == row["status"]
        assert Path(document["input"]["path"]).name == name
        assert json.loads(row["result"]) == document
        assert (folder / row["html_path"]).read_text().startswith("<!DOCTYPE html>")


def test_rerun_skips_what_is_done(surveyed):
    folder = surveyed["folder"]
    done = survey_cli("lib", "--db", "lens.duckdb", *COMPARE_OPTIONS, cwd=folder)
    assert done.returncode == 0, done.stderr
    assert "6 photos, 6 already done, 0 new" in done.stdout
    assert rows(folder / "lens.duckdb") == surveyed["rows"]  # not one row touched


# --------------------------------------------------------------------------------------
# The report and the export
# --------------------------------------------------------------------------------------


class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.links, self.images, self.text, self.group_rows, self._row = [], [], [], [], None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "a":
            self.links.append(attrs.get("href"))
        if tag == "img":
            self.images.append(attrs.get("src", ""))
        if tag == "tr" and attrs.get("class") == "group":
            self._row = []
        if tag == "td" and self._row is not None:
            self._row.append("")

    def handle_endtag(self, tag):
        if tag == "tr" and self._row is not None:
            self.group_rows.append(self._row)
            self._row = None

    def handle_data(self, data):
        self.text.append(data)
        if self._row:
            self._row[-1] += data


def test_report_shows_the_groups(surveyed):
    folder = surveyed["folder"]
    page = _Page()
    page.feed((folder / "lens.html").read_text())
    text = " ".join(page.text)
    assert f"{CAMERA} · {LENS}" in text
    assert "circle at f/2, hexagon at f/4" in text
    shapes = {cells[0]: cells[3] for cells in page.group_rows}
    assert shapes["f/2"] == "circle (2/2)" and shapes["f/4"] == "hexagon (2/2)"
    assert shapes["f/?"] == "—"  # the two files without EXIF: one unreadable, one without discs
    assert sum(src.startswith("data:image/png;base64,") for src in page.images) == 2  # shape and f-stop plots
    assert sum(src.startswith("data:image/jpeg;base64,") for src in page.images) == 5  # a thumbnail per read photo
    assert len(page.links) == 5 and all((folder / link).is_file() for link in page.links)


def test_fstop_bounds_are_stored_and_shown_as_bounds(surveyed):
    # the lights' distance is unknown: each fitted f-stop is the largest the discs allow
    fitted = [row for row in surveyed["rows"].values() if row["status"] == "fitted"]
    assert fitted and all(row["fstop_bound"] == "upper" for row in fitted)
    page = _Page()
    page.feed((surveyed["folder"] / "lens.html").read_text())
    from bokehfit.surveys.report import SUMMARISED

    column = 4 + [name for name, _, _ in SUMMARISED].index("fstop")  # after f-number, photos, statuses, shape
    shown = {cells[0]: cells[column] for cells in page.group_rows}
    assert shown["f/2"].startswith("≤ 2.0") and shown["f/4"].startswith("≤ 4.0"), shown


def test_a_group_of_one_photo_shows_its_value_not_a_spread(tmp_path):
    from bokehfit.surveys.report import build_report

    row = {"sha256": "a" * 64, "path": "one.jpg", "status": "fitted", "camera": CAMERA, "lens": LENS, "exif_fnumber": 2.0,
           "shape": "circle", "blades": None, "fstop": 2.0, "fstop_uncertainty": 0.0, "fstop_bound": "upper",
           "diameter_px": 40.0, "html_path": None}
    page = build_report([row], {}, report_path=tmp_path / "r.html", db_path=tmp_path / "s.duckdb")
    cells = page.split("<tr class='group'>")[1].split("</tr>")[0]
    assert "±" not in cells and "(1 photo)" in cells and "≤ 2.00" in cells, cells


def test_parquet_export_holds_the_table(surveyed):
    table = pyarrow.parquet.read_table(surveyed["folder"] / "lens.parquet")
    assert table.num_rows == 6 and "thumbnail" not in table.column_names
    by_name = {Path(r["path"]).name: r for r in table.to_pylist()}
    assert {n: r["status"] for n, r in by_name.items()} == EXPECTED_STATUS
    assert table.schema.metadata[b"bokehfit_version"] == bokehfit.__version__.encode()


def test_report_alone_from_the_database(surveyed, tmp_path):
    folder = surveyed["folder"]
    done = survey_cli("--db", folder / "lens.duckdb", "--report", tmp_path / "again.html", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "circle at f/2, hexagon at f/4" in (tmp_path / "again.html").read_text()


# --------------------------------------------------------------------------------------
# Killed mid-run, then resumed
# --------------------------------------------------------------------------------------


def test_sigkill_mid_run_then_rerun_loses_nothing_and_repeats_nothing(tmp_path, gpu):
    make_library(tmp_path / "lib")
    survey = survey_cli("lib", "--db", "s.duckdb", "--jobs", 1, *COMPARE_OPTIONS, cwd=tmp_path, start_new_session=True)
    reports = tmp_path / "s_reports"
    deadline = time.monotonic() + 240
    try:  # kill once two photos' reports are written and before the survey ends
        while len(list(reports.glob("*.json"))) < 2 and survey.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert survey.poll() is None, "the survey ended before it could be killed"
        os.killpg(survey.pid, signal.SIGKILL)  # the parent and its worker processes, at once
    finally:
        survey.communicate(timeout=60)
    assert survey.returncode == -signal.SIGKILL
    before = rows(tmp_path / "s.duckdb")  # opens: the database is valid after the kill
    assert 1 <= len(before) < len(EXPECTED_STATUS)
    done = survey_cli("lib", "--db", "s.duckdb", "--jobs", 1, *COMPARE_OPTIONS, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert f"{len(before)} already done, {len(EXPECTED_STATUS) - len(before)} new" in done.stdout
    after = rows(tmp_path / "s.duckdb")
    assert {name: row["status"] for name, row in after.items()} == EXPECTED_STATUS
    for name, row in before.items():  # what was stored before the kill was neither lost nor redone
        assert after[name]["finished_at"] == row["finished_at"] and after[name]["worker"] == row["worker"]
    with duckdb.connect(str(tmp_path / "s.duckdb"), read_only=True) as connection:
        assert connection.execute("SELECT count(*), count(DISTINCT sha256) FROM photos").fetchone() == (6, 6)


def test_a_killed_worker_process_is_replaced_and_the_survey_completes(tmp_path, gpu):
    import psutil

    make_library(tmp_path / "lib")
    survey = survey_cli("lib", "--db", "w.duckdb", "--jobs", 1, *COMPARE_OPTIONS, cwd=tmp_path, start_new_session=True)
    deadline = time.monotonic() + 240
    try:
        while not list((tmp_path / "w_reports").glob("*.json")) and survey.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        workers = [p for p in psutil.Process(survey.pid).children(recursive=True)
                   if any("spawn_main" in part for part in p.cmdline())]
        assert len(workers) == 1 and survey.poll() is None, "no worker process to kill mid-run"
        workers[0].kill()  # as the kernel's OOM killer or a crash in a driver would
        out, err = survey.communicate(timeout=240)
    finally:
        if survey.poll() is None:
            os.killpg(survey.pid, signal.SIGKILL)
            survey.communicate(timeout=60)
    assert survey.returncode == 0, err
    assert {name: row["status"] for name, row in rows(tmp_path / "w.duckdb").items()} == EXPECTED_STATUS
    assert len({row["worker"] for row in rows(tmp_path / "w.duckdb").values() if row["worker"]}) == 2  # a new process


# --------------------------------------------------------------------------------------
# Stopped with Ctrl-C (SIGINT to the process group), or the parent killed alone
# --------------------------------------------------------------------------------------

#: A survey whose photo named ``0_stuck.jpg`` never finishes in its worker (it sleeps); spawned workers
#: run this script again (as ``__mp_main__``), so the stand-in reaches them. Other photos run as usual.
STUCK_SCRIPT = """\
import functools, os, sys, time
import bokehfit.compare

_real = bokehfit.compare.compare_photo

@functools.wraps(_real)
def _stuck(path, **options):
    if os.path.basename(str(path)).startswith("0_stuck"):
        time.sleep(3600)
    return _real(path, **options)

bokehfit.compare.compare_photo = _stuck

if __name__ == "__main__":
    from bokehfit.cli import entry_point

    sys.argv = ["bokehfit", "survey", *sys.argv[1:]]
    entry_point()
"""
#: Wall-clock limits, generous for a busy machine: the old survey took minutes (it waited for the stuck photo).
STOP_LIMIT_S, ORPHAN_LIMIT_S = 20.0, 20.0


def _start_stuck_survey(tmp_path: Path):
    """A survey of the library plus a stuck photo, started in its own process group; returns it once the
    other photos' reports are written, with the worker processes (psutil) it has then."""
    import psutil

    library = make_library(tmp_path / "lib")
    write_render(library / "0_stuck.jpg", 2.0, "circle", 7)
    (tmp_path / "stuck.py").write_text(STUCK_SCRIPT)
    command = [sys.executable, "stuck.py", "lib", "--db", "s.duckdb", "--jobs", 2, *COMPARE_OPTIONS]
    survey = subprocess.Popen(list(map(str, command)), cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True, start_new_session=True)
    reports = tmp_path / "s_reports"
    deadline = time.monotonic() + 240
    while len(list(reports.glob("*.json"))) < 5 and survey.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)  # the 4 renders and the photo with no disc have reports; the stuck photo never will
    assert survey.poll() is None, survey.communicate()
    workers = [p for p in psutil.Process(survey.pid).children(recursive=True)
               if any("spawn_main" in part for part in p.cmdline())]
    assert len(workers) == 2, workers
    return survey, workers


def _gone_within(processes, seconds: float) -> list:
    import psutil

    _, alive = psutil.wait_procs(processes, timeout=seconds)
    return alive


def _ctrl_c(survey, times: int) -> tuple[str, str, float]:
    """Ctrl-C ``times`` times (50 ms apart) to the survey's process group, as a terminal sends it:
    its stdout, stderr and how long it took to stop (killed after STOP_LIMIT_S)."""
    try:
        started = time.monotonic()
        for i in range(times):
            if i:
                time.sleep(0.05)
            os.killpg(survey.pid, signal.SIGINT)  # Ctrl-C in a terminal reaches the whole group
        out, err = survey.communicate(timeout=STOP_LIMIT_S)
        return out, err, time.monotonic() - started
    finally:
        if survey.poll() is None:
            os.killpg(survey.pid, signal.SIGKILL)
            survey.communicate(timeout=60)


def test_ctrl_c_stops_within_seconds_and_keeps_every_finished_photo(tmp_path, gpu):
    survey, workers = _start_stuck_survey(tmp_path)
    finished = {p.name for p in (tmp_path / "s_reports").glob("*.json")}
    out, err, stop_s = _ctrl_c(survey, 1)
    print(f"first Ctrl-C: stopped in {stop_s:.2f} s")
    assert survey.returncode == 130, err
    assert "Traceback" not in err, err
    assert "survey interrupted (rerun to resume)" in out, out
    assert not _gone_within(workers, 5.0), "worker processes outlived the survey"
    stored = rows(tmp_path / "s.duckdb")
    assert "0_stuck.jpg" not in stored  # in progress: dropped, not stored half done
    kept = {Path(row["json_path"]).name for row in stored.values() if row["json_path"]}
    assert finished <= kept, "a photo finished before Ctrl-C was not stored"
    assert {name: row["status"] for name, row in stored.items()} == EXPECTED_STATUS


def test_a_second_ctrl_c_stops_at_once_without_a_traceback(tmp_path, gpu):
    survey, workers = _start_stuck_survey(tmp_path)
    out, err, stop_s = _ctrl_c(survey, 2)
    print(f"two Ctrl-C: stopped in {stop_s:.2f} s")
    assert survey.returncode in (130, -signal.SIGINT), err  # the second may come after the first's exit began
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert not _gone_within(workers, 5.0), "worker processes outlived the survey"
    rows(tmp_path / "s.duckdb")  # the database opens


def test_killing_the_parent_alone_leaves_no_worker_behind(tmp_path, gpu):
    survey, workers = _start_stuck_survey(tmp_path)
    try:
        assert all(os.getpgid(p.pid) == survey.pid for p in workers), "workers left the survey's process group"
        survey.kill()  # the parent only, as an OOM killer or `kill -9 PID` would
        survey.communicate(timeout=60)
        alive = _gone_within(workers, ORPHAN_LIMIT_S)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(survey.pid, signal.SIGKILL)
    assert not alive, f"orphaned workers: {alive}"


# --------------------------------------------------------------------------------------
# A Dask cluster gives the same rows
# --------------------------------------------------------------------------------------


class _PoolThatBreaks:
    """A stand-in for the local engine whose worker "dies" while it holds its second photo.

    Its first photo comes back; the second fails with the pool, and from then on the
    pool refuses new work with ``BrokenProcessPool``, as
    :class:`concurrent.futures.ProcessPoolExecutor` does. This makes the race of the
    test above (a worker dying between a result and the next submit) deterministic.
    """

    def __init__(self, jobs, adapter):
        self.workers, self.pools, self.submitted = jobs, 1, 0

    def submit(self, task):
        import concurrent.futures
        from concurrent.futures.process import BrokenProcessPool

        from bokehfit.surveys.run import _failure

        n, self.submitted = self.submitted, self.submitted + 1
        if self.pools == 1 and n >= 2:
            raise BrokenProcessPool("A child process terminated abruptly")
        future = concurrent.futures.Future()
        if self.pools == 1 and n == 1:
            future.set_exception(BrokenProcessPool("A child process terminated abruptly"))
        else:
            future.set_result(_failure(task, "no_discs", f"stand-in result from pool {self.pools}"))
        return future

    def wait(self, futures):
        return {next(iter(futures))}  # one at a time, oldest first

    def broken(self, error):
        from concurrent.futures.process import BrokenProcessPool

        return isinstance(error, BrokenProcessPool)

    def restart(self):
        self.pools += 1

    def close(self, interrupted):
        pass


def test_a_pool_broken_between_a_result_and_the_next_submit_is_restarted(tmp_path, monkeypatch):
    from bokehfit.surveys import run as survey_run
    from bokehfit.surveys.store import SurveyStore

    photos = []
    for k in range(4):
        photos.append(tmp_path / f"p{k}.png")
        photos[-1].write_bytes(f"photo {k}".encode())
    engines = []

    def engine(jobs, adapter):
        engines.append(_PoolThatBreaks(jobs, adapter))
        return engines[-1]

    monkeypatch.setattr(survey_run, "_LocalEngine", engine)
    with SurveyStore(tmp_path / "s.duckdb") as store:
        run = survey_run.run_survey(photos, store, jobs=1, html=False, progress=False)
    assert run.done == 4 and run.statuses == {"no_discs": 4}, run.summary()
    assert engines[0].pools == 2, "the broken pool was not replaced"
    reasons = {name: row["reason"] for name, row in rows(tmp_path / "s.duckdb").items()}
    assert reasons == {"p0.png": "stand-in result from pool 1", **{f"p{k}.png": "stand-in result from pool 2" for k in (1, 2, 3)}}


def test_local_workers_run_blas_on_one_thread_and_open_no_gpu_unasked(tmp_path):
    """Each local worker starts with BLAS on one thread and OpenCV and lavapipe on its share of the
    cores, the user's own settings kept; the parent's environment is left as it was; a worker whose
    photos need no GPU opens none (no lavapipe threads)."""
    import psutil

    from bokehfit.surveys.run import _LocalEngine
    from bokehfit.surveys.work import THREAD_VARIABLES, PhotoTask, thread_environment

    before = {name: os.environ.get(name) for name in THREAD_VARIABLES}
    (tmp_path / "g.jpg").write_bytes(b"this is not a JPEG\n")
    engine = _LocalEngine(2, None)
    try:
        futures = [engine.submit(PhotoTask(str(tmp_path / "g.jpg"), f"sha{k}")) for k in range(2)]
        assert [future.result(timeout=240)["status"] for future in futures] == ["unreadable", "unreadable"]
        processes = list(engine.pool._processes.values())
        assert len(processes) == 2
        wanted = {**thread_environment(2, environ={}), **{n: v for n, v in before.items() if v is not None}}
        for process in processes:
            environ = psutil.Process(process.pid).environ()
            assert {name: environ.get(name) for name in THREAD_VARIABLES} == wanted
            tasks = Path(f"/proc/{process.pid}/task")
            if tasks.is_dir():
                names = [(task / "comm").read_text().strip() for task in tasks.iterdir()]
                assert not [name for name in names if name.startswith("llvmpipe")], names
    finally:
        engine.close(False)
    assert {name: os.environ.get(name) for name in THREAD_VARIABLES} == before


def test_thread_environment_shares_the_cores_out(monkeypatch):
    from bokehfit.surveys import work

    monkeypatch.setattr(work, "usable_cores", lambda: 8)
    assert work.thread_environment(2, environ={}) == {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                                                     "OPENCV_FOR_THREADS_NUM": "4", "LP_NUM_THREADS": "4"}
    assert work.thread_environment(16, environ={})["OPENCV_FOR_THREADS_NUM"] == "1"
    assert "OPENBLAS_NUM_THREADS" not in work.thread_environment(2, environ={"OPENBLAS_NUM_THREADS": "8"})


def test_the_reports_folder_is_swept_once_a_run(tmp_path, monkeypatch):
    """Killed writers' temporary files are removed from the reports folder before the run's first report,
    and the reports are written without reading the folder again (two files a photo: a sweep each would
    cost a survey time that grows with the square of its photos)."""
    from bokehfit import outputs
    from bokehfit.surveys import run as survey_run
    from bokehfit.surveys.store import SurveyStore, reports_folder

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    folder = reports_folder(tmp_path / "s.duckdb")
    folder.mkdir()
    stale = folder / f".old.json.bokehfit-tmp-{dead.pid}-0123abcd.json"
    stale.write_text("{")
    sweeps = []
    real = outputs.remove_stale_temporaries
    monkeypatch.setattr(outputs, "remove_stale_temporaries", lambda f: sweeps.append(("writer", f)) or real(f))
    monkeypatch.setattr(survey_run, "remove_stale_temporaries", lambda f: sweeps.append(("keeper", f)) or real(f))
    with SurveyStore(tmp_path / "s.duckdb") as store:
        keeper = survey_run._Keeper(store, {})
        for k in range(3):
            record = survey_run._failure(survey_run.PhotoTask(f"p{k}.jpg", f"{k:064x}"), "no_discs", "none")
            keeper.keep({**record, "document": {"status": "no_discs"}, "html": "<p>none</p>"})
    assert sweeps == [("keeper", folder)]
    assert not stale.exists()
    assert len(list(folder.glob("*.json"))) == 3 and len(list(folder.glob("*.html"))) == 3


def test_dask_local_cluster_gives_the_same_rows(surveyed, tmp_path):
    from distributed import LocalCluster

    shutil.copytree(surveyed["folder"] / "lib", tmp_path / "lib")
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None, worker_dashboard_address=None) as cluster:
        table = bokehfit.survey([tmp_path / "lib"], tmp_path / "dask.duckdb", scheduler=cluster.scheduler_address,
                                compare_options=API_OPTIONS)
    assert table.num_rows == 6
    assert same_part(rows(tmp_path / "dask.duckdb")) == same_part(surveyed["rows"])
    workers = {row["worker"] for row in table.to_pylist() if row["worker"]}
    assert workers and all(not w.endswith(f":{os.getpid()}") for w in workers)  # ran on the cluster's processes


# --------------------------------------------------------------------------------------
# Failures are rows; bad input is one line and exit code 2
# --------------------------------------------------------------------------------------


def test_photo_past_its_time_limit_is_a_timeout_row(surveyed, tmp_path):
    shutil.copy(surveyed["folder"] / "lib" / RENDERS[0][0], tmp_path / "slow.jpg")
    table = bokehfit.survey([tmp_path / "slow.jpg"], tmp_path / "t.duckdb", jobs=1, timeout_s=0.01,
                            compare_options=API_OPTIONS)
    (row,) = table.to_pylist()
    assert row["status"] == "timeout" and "0.01 s" in row["reason"]


def test_survey_from_a_script_read_on_stdin(surveyed, tmp_path):
    # Worker processes start by running the parent's main script again; "<stdin>" is no file.
    shutil.copy(surveyed["folder"] / "lib" / RENDERS[0][0], tmp_path / "one.jpg")
    script = ("import bokehfit\n"
              f"table = bokehfit.survey(['one.jpg'], 'stdin.duckdb', jobs=1, compare_options={API_OPTIONS!r})\n"
              "print(table.select(['status', 'reason']).to_pylist())\n")
    done = subprocess.run([sys.executable, "-"], input=script, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[{'status': 'fitted', 'reason': None}]", done.stdout + done.stderr


def test_find_photos_walks_folders_globs_and_files(tmp_path):
    library = make_library(tmp_path / "lib")
    (library / "deeper").mkdir()
    shutil.copy(library / "a_f2.jpg", library / "deeper" / "e.JPG")
    walked = {p.name for p in find_photos([library])}
    assert walked == set(EXPECTED_STATUS) | {"e.JPG"}
    assert {p.name for p in find_photos([str(tmp_path / "lib" / "**" / "*_f4.jpg")])} == {"c_f4.jpg", "d_f4.jpg"}
    assert [p.name for p in find_photos([library / "notes.txt", library / "notes.txt"])] == ["notes.txt"]


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (("nowhere", "--db", "x.duckdb"), "PATH 'nowhere' is not a file, a folder or a glob pattern"),
        (("--db", "x.duckdb"), "give PATHs"),
        ((".", "--db", "x.sqlite"), "--db must end in .duckdb, .db"),
        ((".", "--db", "x.duckdb", "--jobs", "0"), "--jobs must be an integer >= 1"),
        ((".", "--db", "x.duckdb", "--timeout-s", "-1"), "--timeout-s must be greater than 0"),
        ((".", "--db", "x.duckdb", "--shapes", "circle,hexgon"), "--shapes must name shapes"),
        ((".", "--db", "x.duckdb", "--report", "x.txt"), "--report: output file must end in .html"),
    ],
)
def test_usage_errors_exit_2_on_one_line(tmp_path, args, needle):
    done = survey_cli(*args, cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], done.stderr
    assert not (tmp_path / "x.duckdb").exists()


def test_another_programs_database_is_refused(tmp_path):
    with duckdb.connect(str(tmp_path / "theirs.duckdb")) as connection:
        connection.execute("CREATE TABLE accounts (id INTEGER)")
    (tmp_path / "p.png").write_bytes(b"")
    done = survey_cli("p.png", "--db", "theirs.duckdb", cwd=tmp_path)
    assert done.returncode == 2 and "bokehfit did not make" in done.stderr
    with duckdb.connect(str(tmp_path / "theirs.duckdb"), read_only=True) as connection:
        tables = {r[0] for r in connection.execute("SELECT table_name FROM information_schema.tables").fetchall()}
    assert tables == {"accounts"}
    assert re.fullmatch(r"bokehfit: error: .*\n", done.stderr)
