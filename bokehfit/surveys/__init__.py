"""Survey a photo library: compare on every photo, each result kept in a DuckDB database.

The work behind :func:`bokehfit.survey` (``bokehfit.survey(paths, db="survey.duckdb")``),
which runs :func:`bokehfit.compare.compare_photo` on every photo that ``paths`` name
(folders walked, glob patterns, files), in worker processes on this machine or on a
Dask cluster, and returns the database's table as a ``pyarrow.Table``. Each
photo is one row keyed by the SHA-256 of its bytes, committed as its result
arrives: a rerun skips what is done, an interrupted survey resumes, and a photo
that fails is a row with its status and reason (:data:`STATUSES`).

Modules: :mod:`~bokehfit.surveys.files` (which files), :mod:`~bokehfit.surveys.work`
(one photo, in a worker), :mod:`~bokehfit.surveys.store` (the database),
:mod:`~bokehfit.surveys.run` (the engines and the loop), :mod:`~bokehfit.surveys.report`
(the lens fingerprint page).
"""

from __future__ import annotations

import inspect
import os
from pathlib import Path

from bokehfit.errors import InputError, check_positive
from bokehfit.surveys.store import SURVEY_SCHEMA_VERSION, SurveyStore, reports_folder
from bokehfit.surveys.work import FAILURE_STATUSES, STATUSES, usable_cores

__all__ = [
    "survey_table",
    "write_report",
    "export_parquet",
    "check_compare_options",
    "prepare_survey",
    "default_jobs",
    "STATUSES",
    "FAILURE_STATUSES",
    "SURVEY_SCHEMA_VERSION",
    "reports_folder",
]


def default_jobs() -> int:
    """Worker processes by default: the CPU cores this process may use."""
    return usable_cores()


def check_compare_options(options: dict | None) -> dict:
    """``options`` for :func:`~bokehfit.compare.compare_photo`, checked once before any photo runs.

    A bad option would otherwise fail every photo of the survey; here it is one
    ``InputError`` naming it.
    """
    from bokehfit.compare import compare_photo
    from bokehfit.fit import FOCUS_SIDES
    from bokehfit.fit.families import families_for
    from bokehfit.optics import LENS_MODELS, SIZE_CONVENTIONS
    from bokehfit.validate import RANGES, check

    options = dict(options or {})
    allowed = set(inspect.signature(compare_photo).parameters) - {"path", "progress", "adapter"}
    unknown = sorted(set(options) - allowed)
    if unknown:
        raise InputError(f"compare_options must be keywords of compare_photo ({', '.join(sorted(allowed))}) (got {', '.join(unknown)})")
    for name, choices in (("focus_side", FOCUS_SIDES), ("lens_model", LENS_MODELS), ("size_convention", SIZE_CONVENTIONS)):
        if name in options and options[name] not in choices:
            raise InputError(f"{name} must be one of {', '.join(choices)} (got {options[name]!r})")
    if options.get("shapes") is not None:
        families_for(list(options["shapes"]))
    for name, value in options.items():
        if name in RANGES and value is not None:
            options[name] = check(name, value)
    return options


def prepare_survey(paths=(), *, files_from=None, jobs=None, timeout_s=None, compare_options=None) -> dict:
    """Check a survey's arguments and find its photos, before any database is opened or created.

    Returns the keywords of :func:`bokehfit.surveys.run.run_survey` that depend on them:
    ``photos``, ``jobs``, ``timeout_s`` and ``options``. Raises ``InputError`` naming a bad one.
    """
    from bokehfit.surveys.files import find_photos, read_file_list

    if jobs is None:
        jobs = default_jobs()
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise InputError(f"jobs must be an integer >= 1 (got {jobs!r})")
    if timeout_s is not None:
        timeout_s = check_positive("timeout_s", timeout_s)
    options = check_compare_options(compare_options)
    listed = list(paths) + (read_file_list(files_from) if files_from is not None else [])
    return {"photos": find_photos(listed), "jobs": jobs, "timeout_s": timeout_s, "options": options}


def survey_table(db: str | os.PathLike):
    """The database's table (as :func:`bokehfit.survey` returns it), read without running anything."""
    with SurveyStore(db, read_only=True) as store:
        return store.table()


def write_report(db: str | os.PathLike, report: str | os.PathLike, *, command_line: str = "") -> Path:
    """Write the lens fingerprint page (:mod:`bokehfit.surveys.report`) of a survey database, atomically."""
    from bokehfit.output_paths import check_output_path
    from bokehfit.outputs import write_bytes_atomic
    from bokehfit.surveys.report import build_report
    from bokehfit.text_encoding import encode_text

    path = check_output_path(report, (".html",), inputs=[db])
    with SurveyStore(db, read_only=True) as store:
        rows, thumbnails = store.table().to_pylist(), store.thumbnails()
    page = build_report(rows, thumbnails, report_path=path, db_path=db, command_line=command_line)
    write_bytes_atomic(path, encode_text(page))
    return path


def export_parquet(db: str | os.PathLike, parquet: str | os.PathLike) -> Path:
    """Write the survey's table (without thumbnails, with compare's JSON as ``result``) as Parquet, atomically."""
    import pyarrow.parquet

    from bokehfit import __version__
    from bokehfit.output_paths import check_output_path
    from bokehfit.outputs import write_atomic

    path = check_output_path(parquet, (".parquet",), inputs=[db])
    with SurveyStore(db, read_only=True) as store:
        table = store.table()
        results = store.connection.sql("SELECT result FROM photos ORDER BY path, sha256").to_arrow_table()
    table = table.append_column("result", results.column("result"))
    metadata = {b"bokehfit_version": __version__.encode(), b"survey_schema_version": str(SURVEY_SCHEMA_VERSION).encode()}
    table = table.replace_schema_metadata({**(table.schema.metadata or {}), **metadata})
    write_atomic(path, lambda temporary: pyarrow.parquet.write_table(table, temporary))
    return path
