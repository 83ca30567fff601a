"""The survey database: one DuckDB file, one row per photo, keyed by the file's SHA-256.

DuckDB rather than SQLite: the table is read as columns (the report groups and
aggregates, the API returns an Arrow table, the export is Parquet), which is
what DuckDB is built for and has built in, with no pandas in between. The
parent process is the database's only writer and commits each row in its own
transaction as the photo's result arrives; DuckDB's write-ahead log makes a
committed row survive a killed process (it is replayed on the next open).
"""

from __future__ import annotations

import json
import os
import stat
from datetime import datetime, timezone
from pathlib import Path

from bokehfit import __version__
from bokehfit.errors import InputError

__all__ = ["SURVEY_SCHEMA_VERSION", "DB_SUFFIXES", "COLUMNS", "SurveyStore", "reports_folder", "row_from_record"]

#: Version of the ``photos`` table's layout; columns are added, never renamed, within one version.
SURVEY_SCHEMA_VERSION = 1
DB_SUFFIXES = (".duckdb", ".db")

#: The ``photos`` table: name and DuckDB type of each column, in order.
COLUMNS = (
    ("sha256", "VARCHAR PRIMARY KEY"),
    ("path", "VARCHAR NOT NULL"),
    ("size_bytes", "BIGINT"),
    ("status", "VARCHAR NOT NULL"),
    ("reason", "VARCHAR"),
    ("camera", "VARCHAR"),
    ("lens", "VARCHAR"),
    ("exif_fnumber", "DOUBLE"),
    ("focal_length_mm", "DOUBLE"),
    ("width", "INTEGER"),
    ("height", "INTEGER"),
    ("shape", "VARCHAR"),
    ("blades", "INTEGER"),
    ("angle_deg", "DOUBLE"),
    ("symmetry_deg", "DOUBLE"),
    ("diameter_px", "DOUBLE"),
    ("fstop", "DOUBLE"),
    ("fstop_uncertainty", "DOUBLE"),
    ("focus_side", "VARCHAR"),
    ("roundness", "DOUBLE"),
    ("squeeze", "DOUBLE"),
    ("vignetting_radius", "DOUBLE"),
    ("vignetting_shift", "DOUBLE"),
    ("rim", "DOUBLE"),
    ("chromatic_red", "DOUBLE"),
    ("chromatic_blue", "DOUBLE"),
    ("discs_found", "INTEGER"),
    ("discs_fitted", "INTEGER"),
    ("iou", "DOUBLE"),
    ("json_path", "VARCHAR"),
    ("html_path", "VARCHAR"),
    ("warnings", "VARCHAR"),
    ("seconds", "DOUBLE"),
    ("worker", "VARCHAR"),
    ("finished_at", "TIMESTAMP"),
    ("bokehfit_version", "VARCHAR"),
    ("result", "VARCHAR"),
    ("thumbnail", "BLOB"),
    # added within schema 1 (at the end, where ALTER TABLE puts them in an older database):
    ("fstop_bound", "VARCHAR"),  # "upper" where ``fstop`` is the largest f-stop the discs allow (compare's fstop_bound)
)
_NAMES = [name for name, _ in COLUMNS]
#: Columns added within schema 1, after the first release of the table: an older database gets them on opening.
_ADDED = ("fstop_bound",)

#: DuckDB settings of every connection: the survey needs no extension and no file but its own,
#: so none is loaded or downloaded (an SQLite file given as ``--db`` would otherwise make DuckDB
#: fetch its sqlite extension from the network).
CONNECTION_CONFIG = {
    "autoload_known_extensions": False,
    "autoinstall_known_extensions": False,
    "allow_community_extensions": False,
}
#: The first bytes of an SQLite database, for a helpful refusal.
_SQLITE_MAGIC = b"SQLite format 3\x00"
#: DuckDB's magic number, bytes 8 to 12 of its file header.
_DUCKDB_MAGIC = b"DUCK"


def _log_of(path: Path) -> Path:
    """DuckDB's write-ahead log beside a database file."""
    return path.with_name(path.name + ".wal")


def _one_line(error: Exception) -> str:
    text = " ".join(str(error).split())
    return text if len(text) <= 200 else text[:197] + "..."


def _check_database_file(path: Path, read_only: bool) -> None:
    """``InputError`` unless ``path`` can be a survey database: a UTF-8 name, a regular DuckDB file or none.

    Checked with ``stat`` and a read of the header (``O_NONBLOCK``) before DuckDB sees the file,
    so that a FIFO, a device, an SQLite or other file is refused in one line, never opened by DuckDB.
    """
    from bokehfit.regular_files import file_kind, open_regular

    try:
        os.fsencode(path).decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"--db {str(path)!r}: the name is not valid UTF-8, which DuckDB needs; rename it") from None
    if read_only and not os.path.lexists(path):
        raise InputError(f"--db {str(path)!r} does not exist (run a survey into it first)")
    if not path.parent.is_dir():
        raise InputError(f"--db folder {str(path.parent)!r} does not exist")
    for file in (path, _log_of(path)):
        try:
            mode = os.stat(file).st_mode
        except FileNotFoundError:
            if os.path.lexists(file):
                raise InputError(f"--db {str(file)!r} is a broken symbolic link; remove it or choose another name") from None
            continue
        except OSError as error:
            raise InputError(f"--db {str(file)!r} can't be read: {error.strerror or error}") from None
        if not stat.S_ISREG(mode):
            raise InputError(f"--db {str(file)!r} is {file_kind(mode)}, not a database file; choose another name")
    if not path.exists():
        return
    try:
        with open_regular(path) as file:
            head = file.read(16)
    except OSError as error:
        raise InputError(f"--db {str(path)!r} can't be read: {error.strerror or error}") from None
    if head.startswith(_SQLITE_MAGIC):
        raise InputError(f"--db {str(path)!r} is an SQLite database, not a survey database (DuckDB); choose another name")
    if head and head[8:12] != _DUCKDB_MAGIC:
        raise InputError(f"--db {str(path)!r} is not a DuckDB database (a survey database); choose another name")
#: Columns left out of the table that :meth:`SurveyStore.table` returns and the Parquet export.
_BULKY = ("result", "thumbnail")


def reports_folder(db_path: str | os.PathLike) -> Path:
    """Where the per-photo compare JSON and HTML go: ``NAME_reports/`` beside ``NAME.duckdb``."""
    db_path = Path(db_path)
    return db_path.with_name(f"{db_path.stem}_reports")


def _number(value):
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def _part(value, key):
    """``value[key]`` of an object-valued real-lens key (vignetting, chromatic), None when not fitted."""
    return _number(value.get(key)) if isinstance(value, dict) else None


def row_from_record(record: dict, *, size_bytes: int | None, json_path: str | None, html_path: str | None) -> dict:
    """A ``photos`` row (column name → value) from a worker's record (:func:`bokehfit.surveys.work.survey_photo`)."""
    document = record.get("document") or {}
    source = document.get("input") or {}
    exif = source.get("exif") or {}
    aperture = document.get("aperture") or {}
    discs = document.get("discs") or []
    metrics = document.get("metrics") or {}
    blades = aperture.get("blades")
    row = {
        "sha256": record["sha256"],
        "path": record["path"],
        "size_bytes": size_bytes,
        "status": record["status"],
        "reason": record.get("reason"),
        "camera": exif.get("camera"),
        "lens": exif.get("lens"),
        "exif_fnumber": _number(exif.get("fnumber")),
        "focal_length_mm": _number(exif.get("focal_length_mm")),
        "width": source.get("width"),
        "height": source.get("height"),
        "shape": aperture.get("shape"),
        "blades": blades if isinstance(blades, int) else None,
        "angle_deg": _number(aperture.get("angle_deg")),
        "symmetry_deg": _number(aperture.get("symmetry_deg")),
        "diameter_px": _number(aperture.get("diameter_px")),
        "fstop": _number(aperture.get("fstop")),
        "fstop_uncertainty": _number(aperture.get("fstop_uncertainty")),
        "fstop_bound": aperture.get("fstop_bound") if aperture.get("fstop") is not None else None,
        "focus_side": aperture.get("focus_side"),
        "roundness": _number(aperture.get("roundness")),
        "squeeze": _number(aperture.get("squeeze")),
        "vignetting_radius": _part(aperture.get("vignetting"), "radius"),
        "vignetting_shift": _part(aperture.get("vignetting"), "shift"),
        "rim": _number(aperture.get("rim")),
        "chromatic_red": _part(aperture.get("chromatic"), "red"),
        "chromatic_blue": _part(aperture.get("chromatic"), "blue"),
        "discs_found": len(discs) if document else None,
        "discs_fitted": aperture.get("discs_fitted") if document else None,
        "iou": _number(metrics.get("iou")),
        "json_path": json_path,
        "html_path": html_path,
        "warnings": "\n".join(record.get("warnings") or []) or None,
        "seconds": _number(record.get("seconds")),
        "worker": record.get("worker"),
        "finished_at": datetime.now(timezone.utc).replace(tzinfo=None),
        "bokehfit_version": __version__,
        "result": json.dumps(document, allow_nan=False) if document else None,
        "thumbnail": record.get("thumbnail"),
    }
    return {name: _storable(value) for name, value in row.items()}


def _storable(value):
    """Text that DuckDB can store: a file name's undecodable bytes (lone surrogates) become U+FFFD."""
    if isinstance(value, str):
        try:
            value.encode("utf-8")
        except UnicodeEncodeError:
            from bokehfit.text_encoding import replace_surrogates

            return replace_surrogates(value)
    return value


class SurveyStore:
    """The open survey database (a context manager; closing checkpoints it).

    Parameters
    ----------
    path : str or path-like
        ``NAME.duckdb`` (or ``.db``); created with its table if missing. An
        existing file must be a survey database that bokehfit made.
    read_only : bool
        Open for reading (the report, the API's table) without taking the write lock.

    Raises
    ------
    InputError
        Naming ``--db`` when the file is not a DuckDB database, is another
        program's database, is in use by another survey, or can't be created.

    Notes
    -----
    Before DuckDB sees the file: its name must be UTF-8, it and its log must be
    regular files (``stat``), and its header DuckDB's (an SQLite file is named as
    one). DuckDB then loads and installs no extension (:data:`CONNECTION_CONFIG`).
    An existing database must hold the ``photos`` table with exactly
    :data:`COLUMNS`, every block of which is read once (a file cut short fails
    here, not halfway through a survey), and a write-ahead log left beside it
    must fold in at a checkpoint: DuckDB skips one it can't replay without a
    word, and its rows would be lost unseen.
    """

    def __init__(self, path: str | os.PathLike, *, read_only: bool = False):
        self.path = Path(path)
        self.connection = None
        if self.path.suffix.lower() not in DB_SUFFIXES:
            raise InputError(f"--db must end in {', '.join(DB_SUFFIXES)} (got {str(self.path)!r})")
        _check_database_file(self.path, read_only)
        existed = self.path.exists()
        if read_only and _log_of(self.path).exists():
            self._open_checked(existed, False, read_only_use=True)  # fold in (and check) an interrupted survey's log
            self.close()
        self._open_checked(existed, read_only)

    def _open_checked(self, existed: bool, read_only: bool, read_only_use: bool = False) -> None:
        self._open(read_only)
        try:
            self._guarded(self._check_or_create, existed, read_only or read_only_use)
            if not read_only:
                self._guarded(self._check_log_folded)
        except BaseException:
            self.connection.close()
            self.connection = None
            raise

    def _open(self, read_only: bool) -> None:
        import duckdb

        try:
            self.connection = duckdb.connect(str(self.path), read_only=read_only, config=CONNECTION_CONFIG)
        except duckdb.Error as error:
            raise InputError(f"--db {str(self.path)!r} can't be opened as a survey database: {_one_line(error)}") from None

    def _guarded(self, work, *args):
        """``work(*args)``, a database error in it made one ``InputError`` naming the file (a damaged database)."""
        import duckdb

        try:
            return work(*args)
        except duckdb.Error as error:
            raise InputError(f"--db {str(self.path)!r} is damaged or not a survey database ({_one_line(error)}); "
                             "start a new database") from None

    def _check_log_folded(self) -> None:
        """``InputError`` if a write-ahead log is left after a checkpoint: DuckDB could not replay it (damaged)."""
        log = _log_of(self.path)
        if not log.exists():
            return
        self.connection.execute("CHECKPOINT")
        if log.exists() and log.stat().st_size > 0:
            raise InputError(
                f"--db {str(self.path)!r}: its write-ahead log {log.name!r} is damaged (DuckDB could not replay it); "
                f"move {log.name!r} away to open the database without the rows it held"
            )

    def _check_or_create(self, existed: bool, read_only: bool) -> None:
        tables = {row[0] for row in self.connection.execute("SELECT table_name FROM information_schema.tables").fetchall()}
        if "survey_meta" in tables:
            meta = dict(self.connection.execute("SELECT key, value FROM survey_meta").fetchall())
            version = meta.get("schema_version")
            if version != str(SURVEY_SCHEMA_VERSION):
                raise InputError(
                    f"--db {str(self.path)!r} is a survey database of schema {version}; this bokehfit reads schema "
                    f"{SURVEY_SCHEMA_VERSION}: start a new database"
                )
            columns = self.connection.execute(
                "SELECT column_name FROM information_schema.columns WHERE table_name = 'photos' ORDER BY ordinal_position"
            ).fetchall()
            names = [name for (name,) in columns]
            missing = _NAMES[len(names):] if names == _NAMES[:len(names)] else None
            if missing and set(missing) <= set(_ADDED):  # an older bokehfit's table: the added columns are null
                if not read_only:
                    for name in missing:
                        self.connection.execute(f"ALTER TABLE photos ADD COLUMN {name} {dict(COLUMNS)[name]}")
                    missing = []
                self._missing = list(missing)
                names = _NAMES
            if names != _NAMES:
                what = "no photos table" if not columns else "a photos table with other columns than this bokehfit writes"
                raise InputError(f"--db {str(self.path)!r} is a survey database with {what}; start a new database")
            # every block of every column read once: a damaged (cut) file fails here, not halfway through a survey
            self.connection.execute("SELECT count(*), min(hash(COLUMNS(*))) FROM photos").fetchall()
            return
        if tables or (existed and read_only):
            raise InputError(f"--db {str(self.path)!r} is a DuckDB database that bokehfit did not make; choose another name")
        columns = ", ".join(f"{name} {kind}" for name, kind in COLUMNS)
        self.connection.execute("BEGIN TRANSACTION")
        self.connection.execute("CREATE TABLE survey_meta (key VARCHAR PRIMARY KEY, value VARCHAR)")
        self.connection.executemany(
            "INSERT INTO survey_meta VALUES (?, ?)",
            [["schema_version", str(SURVEY_SCHEMA_VERSION)], ["created_by", f"bokehfit {__version__}"]],
        )
        self.connection.execute(f"CREATE TABLE photos ({columns})")
        self.connection.execute("COMMIT")

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def close(self) -> None:
        """Checkpoint (fold the log into the file) and close; safe to call twice."""
        if getattr(self, "connection", None) is None:
            return
        if self.connection is not None:
            import duckdb

            try:
                self.connection.execute("CHECKPOINT")
            except duckdb.Error:
                pass  # read-only, or nothing to fold in
            self.connection.close()
            self.connection = None

    def put(self, row: dict) -> None:
        """Store one photo's row (replacing an earlier row of the same photo), in its own transaction."""
        self._guarded(self._put, row)

    def _put(self, row: dict) -> None:
        placeholders = ", ".join("?" for _ in _NAMES)
        self.connection.execute("BEGIN TRANSACTION")
        try:
            self.connection.execute(
                f"INSERT OR REPLACE INTO photos ({', '.join(_NAMES)}) VALUES ({placeholders})", [row[name] for name in _NAMES]
            )
        except BaseException:
            self.connection.execute("ROLLBACK")
            raise
        self.connection.execute("COMMIT")

    def statuses(self) -> dict[str, str]:
        """sha256 → status of every photo stored."""
        return dict(self._guarded(lambda: self.connection.execute("SELECT sha256, status FROM photos").fetchall()))

    def count(self) -> int:
        return self._guarded(lambda: self.connection.execute("SELECT count(*) FROM photos").fetchone()[0])

    def table(self, *, bulky: bool = False):
        """The ``photos`` table as a ``pyarrow.Table`` ordered by path (without ``result`` and ``thumbnail`` unless ``bulky``)."""
        names = _NAMES if bulky else [name for name in _NAMES if name not in _BULKY]
        missing = getattr(self, "_missing", ())  # an older database opened read-only
        names = [f"NULL::{dict(COLUMNS)[name]} AS {name}" if name in missing else name for name in names]
        query = f"SELECT {', '.join(names)} FROM photos ORDER BY path, sha256"
        return self._guarded(lambda: self.connection.sql(query).to_arrow_table())

    def thumbnails(self) -> dict[str, bytes]:
        """sha256 → JPEG thumbnail of the photos that have one."""
        query = "SELECT sha256, thumbnail FROM photos WHERE thumbnail IS NOT NULL"
        rows = self._guarded(lambda: self.connection.execute(query).fetchall())
        return {sha: bytes(data) for sha, data in rows}
