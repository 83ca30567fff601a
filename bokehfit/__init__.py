"""bokehfit: find bokeh discs in photos, fit the aperture that made them, render its kernel.

The main job, in Python (the command line is ``bokehfit compare PHOTO``)::

    from bokehfit import compare_photo

    result = compare_photo("examples/hexagon_85mm_f2.jpg")
    print(result.verdict)              # one sentence: what the aperture is, how sure, why
    print(result.summary())            # the numbers: shape, angle, disc size, f-stop, runners-up
    document = result.to_json("")      # the JSON of ``compare --json`` (design.md §7b)

Public API (each also importable from its module; imported on first use):

compare_photo(path, ...) -> Comparison
    Every stage on one photo: discs, fitted aperture, kernel, metrics (:mod:`bokehfit.compare`).
    ``Comparison`` has ``status`` (fitted, unsure, no_fit, no_discs), ``reason``, ``verdict``,
    ``verdict_details``, ``fit``, ``fstop``, ``search`` (the discs), ``kernel``, ``metrics``,
    ``summary()``, ``to_json()``.
load_photo(path) -> Photo
    Any JPEG, PNG, TIFF or camera raw file, linearised, with its EXIF (:mod:`bokehfit.io`).
find_discs(luminance, ...) -> DiscSearch
    The bokeh discs of an image (:mod:`bokehfit.discs`).
fit_aperture(luminance, discs, ...) -> ApertureFit or FailedFit
    The aperture that explains the discs, with the candidates tried (:mod:`bokehfit.fit`).
make_aperture(shape, angle_deg, ...) -> Aperture
    An aperture of design.md §3 and §3b (:mod:`bokehfit.apertures`).
compute_kernel(aperture, diameter_px, ...) -> Kernel
    The point-light defocus kernel of an aperture (:mod:`bokehfit.kernels`).
survey(paths, db, ...) -> pyarrow.Table
    ``compare`` on a photo library into a DuckDB database (defined here; the work is in :mod:`bokehfit.surveys`).

The command line: ``bokehfit --help`` (``compare``, ``discs``, ``kernel``, ``similarity``,
``render``, ``view``, ``bench``, ``survey``).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("bokehfit")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

#: Public name → the module that holds it (imported on first use, so ``import bokehfit`` stays light).
_LAZY = {
    "compare_photo": "bokehfit.compare",
    "Comparison": "bokehfit.compare",
    "load_photo": "bokehfit.io",
    "find_discs": "bokehfit.discs",
    "fit_aperture": "bokehfit.fit",
    "make_aperture": "bokehfit.apertures",
    "compute_kernel": "bokehfit.kernels",
}

__all__ = ["__version__", "survey", *_LAZY]


def __getattr__(name):
    """``bokehfit.compare_photo(...)``, ``bokehfit.load_photo(...)``, ... without importing them with bokehfit."""
    import importlib

    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'bokehfit' has no attribute {name!r}")


def survey(
    paths: Iterable[str | os.PathLike] = (),
    db: str | os.PathLike = "survey.duckdb",
    *,
    files_from: str | os.PathLike | None = None,
    jobs: int | None = None,
    scheduler=None,
    timeout_s: float | None = None,
    html: bool = True,
    retry_failed: bool = False,
    compare_options: dict | None = None,
    report: str | os.PathLike | None = None,
    parquet: str | os.PathLike | None = None,
    progress: bool | None = None,
    adapter=None,
    command_line: str | None = None,
):
    """Survey photos into a database and return the whole table.

    Parameters
    ----------
    paths : iterable of str or path-like
        Files, folders (walked) and glob patterns (:func:`bokehfit.surveys.files.find_photos`).
    db : str or path-like
        The DuckDB file (``.duckdb`` or ``.db``), created if missing; the
        per-photo compare JSON and HTML go to ``NAME_reports/`` beside it.
    files_from : path-like, optional
        A text file listing more photos, one a line.
    jobs : int, optional
        Worker processes on this machine (default: the usable CPU cores).
        Ignored with ``scheduler``.
    scheduler : str or distributed.Client, optional
        A Dask scheduler's address (``tcp://host:8786``) or a connected client:
        the photos run on that cluster instead.
    timeout_s : float, optional
        Per-photo limit; a photo past it is a ``timeout`` row. Enforced in local
        worker processes (POSIX); Dask has no per-task limit.
    html : bool
        Write each photo's HTML report beside its JSON.
    retry_failed : bool
        Run again the photos stored as ``unreadable``, ``error`` or ``timeout``.
    compare_options : dict, optional
        Keywords of :func:`bokehfit.compare.compare_photo` (``shapes``,
        ``focus_side``, ``sensor_width_mm``, ...), the same for every photo.
    report, parquet : path-like, optional
        Also write the fingerprint page (:func:`bokehfit.surveys.write_report`) and the
        Parquet export (:func:`bokehfit.surveys.export_parquet`).
    progress : bool, optional
        Show a progress bar with rate and ETA (default: when stderr is a terminal).
    adapter : bokehfit.gpu.AdapterChoice, optional
        The GPU the workers use.

    Returns
    -------
    pyarrow.Table
        Every row of the database (not only this run's), ordered by path, without the
        bulky ``result`` (compare's JSON) and ``thumbnail`` columns.

    Examples
    --------
    >>> import bokehfit
    >>> table = bokehfit.survey(["photos/"], "lens.duckdb", jobs=2)  # doctest: +SKIP
    >>> table.group_by(["lens", "exif_fnumber"]).aggregate([("fstop", "mean")])  # doctest: +SKIP
    """
    from bokehfit.surveys import export_parquet, prepare_survey, write_report
    from bokehfit.surveys.run import run_survey
    from bokehfit.surveys.store import SurveyStore

    prepared = prepare_survey(paths, files_from=files_from, jobs=jobs, timeout_s=timeout_s, compare_options=compare_options)
    with SurveyStore(db) as store:
        run_survey(store=store, scheduler=scheduler, html=html, retry_failed=retry_failed, progress=progress,
                   adapter=adapter, command_line=command_line or "", **prepared)
        table = store.table()
    if report is not None:
        write_report(db, report, command_line=command_line or "")
    if parquet is not None:
        export_parquet(db, parquet)
    return table


def __dir__():
    return sorted(set(globals()) | set(__all__))
