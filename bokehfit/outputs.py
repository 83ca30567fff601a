"""Write result files atomically, never over a file bokehfit did not write, and leave nothing behind.

Every output goes to a temporary file in the destination's folder and is then
renamed over the destination, so a reader never sees half a file.

**Whose file it is.** An existing file is replaced only if it is one of
bokehfit's own outputs. Every file bokehfit writes carries a mark, and
:func:`is_bokehfit_output` looks for it (the writers here add it):

========  =====================================================================
``.json``  a ``"bokehfit_version"`` key in the first 64 KiB (every JSON output has one)
``.html``  ``<meta name="generator" content="bokehfit VERSION">`` in the first 64 KiB
``.png``   a ``tEXt`` chunk ``Software`` = ``bokehfit VERSION`` before the image data
``.jpg``   a comment (``COM``) segment ``bokehfit VERSION`` before the image data
``.npy``   ``# bokehfit VERSION`` in the header's padding, a comment to ``numpy.load``
``.exr``   a string attribute ``software`` = ``bokehfit VERSION`` in the header
``.parquet``  a ``bokehfit_version`` key in the footer's key-value metadata (the survey's export)
========  =====================================================================

Only regular files are ever opened to look for the mark, with ``O_NONBLOCK`` after a
``stat`` (:func:`open_regular`): an output path naming a FIFO, a device or a socket is
refused without being opened (opening a FIFO to read would wait for a writer forever).
Any other existing file (a photo, notes, another program's output, a file of
another type) is refused: :func:`check_output_path` and the writers raise
:class:`~bokehfit.errors.InputError` naming it, and the user moves it or chooses
another name. bokehfit never picks another name by itself.

**Temporary files** are named ``.NAME.bokehfit-tmp-PID-TOKEN.SUFFIX``. A failed
write removes its own: on any exception, on Ctrl-C, and on SIGTERM (which, while
a write is under way in the main thread, becomes ``SystemExit(143)``). One left
by a process that was killed outright (SIGKILL, a crash, a power cut) is removed
by the next run that checks an output in that folder (:func:`check_output_path`, before
any work) or writes there, once no process with that PID is running, or the process now
holding that PID started after the file was last written (Linux; the PID was reused).
Elsewhere than POSIX systems they are left alone.

**Text** written into a page or a report goes through :func:`encode_text`: a file name
that is not valid UTF-8 (lone surrogates in Python) becomes U+FFFD instead of failing.

**Test hook.** ``BOKEHFIT_WRITE_PAUSE_S=SECONDS`` makes every write wait that
long between finishing its temporary file and renaming it, so that a test can
interrupt a write at a known moment. It changes nothing else.
"""

from __future__ import annotations

import contextlib
import errno
import io
import json
import os
import re
import secrets
import signal
import stat
import struct
import threading
import time
import zlib
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from bokehfit import __version__
from bokehfit.errors import InputError, check_finite

__all__ = [
    "GENERATOR",
    "HTML_GENERATOR_META",
    "KERNEL_FORMATS",
    "WRITE_PAUSE_ENV",
    "check_output_path",
    "check_replaceable",
    "encode_text",
    "file_kind",
    "is_bokehfit_output",
    "make_folder",
    "open_regular",
    "remove_stale_temporaries",
    "replace_surrogates",
    "write_atomic",
    "write_bytes_atomic",
    "write_exr",
    "write_json",
    "write_png",
    "write_kernel_image",
]

#: Kernel file formats by suffix.
KERNEL_FORMATS = (".npy", ".png", ".exr")

#: The mark of bokehfit's outputs (the program and its version).
GENERATOR = f"bokehfit {__version__}"

#: The element that marks an HTML page as bokehfit's; added to every ``.html`` written here.
HTML_GENERATOR_META = f'<meta name="generator" content="{GENERATOR}">'

#: Environment variable of the test hook: seconds to wait before each rename.
WRITE_PAUSE_ENV = "BOKEHFIT_WRITE_PAUSE_S"

#: How much of a file is read to find the mark.
_HEAD_BYTES = 1 << 16

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_NPY_MAGIC = b"\x93NUMPY"
_EXR_MAGIC = b"\x76\x2f\x31\x01"
_TEMPORARY = re.compile(r"^\..+\.bokehfit-tmp-(?P<pid>\d+)-[0-9a-f]+(\.[^.]*)?$")


# --------------------------------------------------------------------------------------
# The mark: one recogniser and one stamp per format
# --------------------------------------------------------------------------------------


def _png_chunks(data: bytes):
    """(kind, body) of each PNG chunk before the image data (bodies may be cut at the end of ``data``)."""
    i = len(_PNG_SIGNATURE)
    while i + 8 <= len(data):
        length, kind = struct.unpack(">I4s", data[i : i + 8])
        if kind in (b"IDAT", b"IEND"):
            return
        yield kind, data[i + 8 : i + 8 + length]
        i += 12 + length


def _jpeg_segments(data: bytes):
    """(marker, body) of each JPEG segment before the scan."""
    i = 2
    while i + 4 <= len(data) and data[i] == 0xFF:
        marker = data[i + 1]
        if marker in (0xDA, 0xD9):  # start of scan, end of image
            return
        (length,) = struct.unpack(">H", data[i + 2 : i + 4])
        yield marker, data[i + 4 : i + 2 + length]
        i += 2 + length


def _npy_header(data: bytes) -> tuple[str, int, bytes] | None:
    """(struct format of the header length, header start, header) of a ``.npy`` file, or None."""
    if not data.startswith(_NPY_MAGIC) or len(data) < 10:
        return None
    size_format, start = ("<H", 10) if data[6] == 1 else ("<I", 12)
    if len(data) < start:
        return None
    (length,) = struct.unpack_from(size_format, data, 8)
    return size_format, start, data[start : start + length]


def _json_is_ours(head: bytes) -> bool:
    return b'"bokehfit_version"' in head


def _html_is_ours(head: bytes) -> bool:
    return b'<meta name="generator" content="bokehfit ' in head


def _png_is_ours(head: bytes) -> bool:
    return head.startswith(_PNG_SIGNATURE) and any(
        kind == b"tEXt" and body.startswith(b"Software\x00bokehfit ") for kind, body in _png_chunks(head)
    )


def _jpeg_is_ours(head: bytes) -> bool:
    return head.startswith(b"\xff\xd8") and any(
        marker == 0xFE and body.startswith(b"bokehfit ") for marker, body in _jpeg_segments(head)
    )


def _npy_is_ours(head: bytes) -> bool:
    header = _npy_header(head)
    return header is not None and b"# bokehfit " in header[2]


def _exr_is_ours(head: bytes) -> bool:
    # Attributes are name\0 type\0 size (int32) value: software\0 string\0 <size> bokehfit ...
    return head.startswith(_EXR_MAGIC) and re.search(rb"software\x00string\x00.{4}bokehfit ", head, re.DOTALL) is not None


def _stamp_html(data: bytes) -> bytes:
    if _html_is_ours(data[:_HEAD_BYTES]):
        return data
    meta = HTML_GENERATOR_META.encode("utf-8")
    head = re.search(rb"<head(\s[^>]*)?>", data[:_HEAD_BYTES], re.IGNORECASE)
    at = head.end() if head else 0
    return data[:at] + meta + data[at:]


def _stamp_png(data: bytes) -> bytes:
    if not data.startswith(_PNG_SIGNATURE) or data[12:16] != b"IHDR" or _png_is_ours(data[:_HEAD_BYTES]):
        return data
    body = b"Software\x00" + GENERATOR.encode("latin-1", "replace")
    chunk = struct.pack(">I", len(body)) + b"tEXt" + body + struct.pack(">I", zlib.crc32(b"tEXt" + body))
    end = 8 + 12 + struct.unpack(">I", data[8:12])[0]  # after IHDR
    return data[:end] + chunk + data[end:]


def _stamp_jpeg(data: bytes) -> bytes:
    if not data.startswith(b"\xff\xd8") or _jpeg_is_ours(data[:_HEAD_BYTES]):
        return data
    text = GENERATOR.encode("ascii", "replace")
    return data[:2] + b"\xff\xfe" + struct.pack(">H", len(text) + 2) + text + data[2:]


def _stamp_npy(data: bytes) -> bytes:
    """The header's padding gains a comment; the header stays a multiple of 64 bytes long (NEP 1)."""
    parsed = _npy_header(data)
    if parsed is None or b"# bokehfit " in parsed[2]:
        return data
    size_format, start, header = parsed
    header = header.rstrip(b" \n") + f" # {GENERATOR}".encode("ascii", "replace")
    header += b" " * (-(start + len(header) + 1) % 64) + b"\n"
    return data[:8] + struct.pack(size_format, len(header)) + header + data[start + len(parsed[2]) :]


_RECOGNISERS: dict[str, Callable[[bytes], bool]] = {
    ".json": _json_is_ours,
    ".html": _html_is_ours,
    ".htm": _html_is_ours,
    ".png": _png_is_ours,
    ".jpg": _jpeg_is_ours,
    ".jpeg": _jpeg_is_ours,
    ".npy": _npy_is_ours,
    ".exr": _exr_is_ours,
}

_STAMPS: dict[str, Callable[[bytes], bytes]] = {
    ".html": _stamp_html,
    ".htm": _stamp_html,
    ".png": _stamp_png,
    ".jpg": _stamp_jpeg,
    ".jpeg": _stamp_jpeg,
    ".npy": _stamp_npy,
}


#: Parquet files end in their footer: its length (int32, little-endian) and the magic ``PAR1``.
_PARQUET_MAGIC = b"PAR1"
#: Largest Parquet footer read when looking for the mark (a survey's is a few kB).
_PARQUET_FOOTER_MAX_BYTES = 1 << 20


def open_regular(path: str | os.PathLike):
    """``path`` opened for reading in binary, or ``OSError`` if it is not a regular file.

    The file is opened with ``O_NONBLOCK`` and checked with ``fstat`` before a byte is
    read: opening a FIFO this way returns at once (a plain ``open`` waits for a writer),
    and a FIFO, a device (``/dev/zero``), a socket or a folder is refused, symbolic links
    to them included. Every file bokehfit reads without knowing what it is goes through
    here (an output it may replace, a list of photos, a photo it hashes).
    """
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_BINARY", 0)
    descriptor = os.open(path, flags)
    try:
        mode = os.fstat(descriptor).st_mode
        if not stat.S_ISREG(mode):
            raise OSError(errno.EINVAL, f"not a regular file ({file_kind(mode)})", str(path))
        if hasattr(os, "set_blocking"):
            os.set_blocking(descriptor, True)
        return os.fdopen(descriptor, "rb")
    except BaseException:
        os.close(descriptor)
        raise


def file_kind(mode: int) -> str:
    """What a ``st_mode`` is, in words: ``a FIFO``, ``a character device``, ..."""
    for test, words in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
                        (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISREG, "a regular file")):
        if test(mode):
            return words
    return "not a regular file"


def _parquet_is_ours(path: str | os.PathLike) -> bool:
    """The footer's key-value metadata (uncompressed Thrift) holds the key ``bokehfit_version``."""
    with open_regular(path) as file:
        if not file.read(4) == _PARQUET_MAGIC:
            return False
        size = file.seek(0, os.SEEK_END)
        if size < 12:
            return False
        file.seek(size - 8)
        footer_length, magic = struct.unpack("<i4s", file.read(8))
        if magic != _PARQUET_MAGIC or not 0 < footer_length <= min(_PARQUET_FOOTER_MAX_BYTES, size - 12):
            return False
        file.seek(size - 8 - footer_length)
        return b"bokehfit_version" in file.read(footer_length)


#: Formats whose mark is in a footer: the recogniser reads the file itself, within a stated bound.
_FOOTER_RECOGNISERS: dict[str, Callable[[str | os.PathLike], bool]] = {".parquet": _parquet_is_ours}


def is_bokehfit_output(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a file that bokehfit wrote (it carries bokehfit's mark; see the module notes).

    Parameters
    ----------
    path : str or path-like
        Any path; a folder, a missing or unreadable file, or a type bokehfit does not write give False.

    Examples
    --------
    >>> is_bokehfit_output("holiday.jpg")  # doctest: +SKIP
    False
    """
    suffix = Path(path).suffix.lower()
    recognise = _RECOGNISERS.get(suffix)
    try:
        if suffix in _FOOTER_RECOGNISERS:  # the mark is at the file's end, not in its head
            return _FOOTER_RECOGNISERS[suffix](path)
        if recognise is None:
            return False
        with open_regular(path) as file:
            return recognise(file.read(_HEAD_BYTES))
    except OSError:
        return False


def check_replaceable(path: str | os.PathLike) -> None:
    """``InputError`` if something that bokehfit did not write is at ``path``; nothing if it is free or ours."""
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except OSError:
        mode = None  # missing (or a dangling link: refused below, as another's file)
    if mode is not None and stat.S_ISDIR(mode):
        raise InputError(f"output {str(path)!r} is a folder")
    if mode is not None and not stat.S_ISREG(mode):
        raise InputError(f"output {str(path)!r} is {file_kind(mode)}, not a regular file; choose a file name")
    if os.path.lexists(path) and not is_bokehfit_output(path):
        raise InputError(
            f"output {str(path)!r} already exists and was not written by bokehfit; move it away or choose another name"
        )


def check_output_path(
    path: str | os.PathLike, suffixes: Iterable[str], inputs: Iterable[str | os.PathLike] = (), *, folder_may_be_missing: bool = False
) -> Path:
    """``path`` as a Path, or ``InputError`` if it can't be written, names an input or holds a file not ours.

    Nothing is created or opened for writing here: with ``folder_may_be_missing`` a missing
    folder is accepted where it could be made (its nearest existing parent is a folder), and
    the writer makes it (:func:`make_folder`) only when it writes, so a run that fails first
    leaves no folder behind. Stale temporary files of killed bokehfit processes in the
    folder are removed (:func:`remove_stale_temporaries`).
    """
    path = Path(path)
    suffixes = tuple(suffixes)
    if path.suffix.lower() not in suffixes:
        raise InputError(f"output file must end in {', '.join(suffixes)} (got {str(path)!r})")
    if not path.parent.is_dir():
        if not folder_may_be_missing:
            raise InputError(f"output folder {str(path.parent)!r} does not exist")
        _check_folder_can_be_made(path.parent)
        return path
    if path.is_dir():
        raise InputError(f"output {str(path)!r} is a folder")
    for source in inputs:
        if Path(source).exists() and path.exists() and path.samefile(source):
            raise InputError(f"output {str(path)!r} would overwrite the input; choose another name")
    check_replaceable(path)
    remove_stale_temporaries(path.parent)
    return path


def _check_folder_can_be_made(folder: Path) -> None:
    """``InputError`` unless the nearest existing parent of the missing ``folder`` is a folder."""
    parent = folder
    while not os.path.lexists(parent) and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise InputError(f"output folder {str(folder)!r} can't be made: {str(parent)!r} is not a folder")


def make_folder(folder: str | os.PathLike) -> Path:
    """Create an output folder (and its parents) if missing; ``InputError`` if that fails."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise InputError(f"cannot create the output folder {str(folder)!r}: {error.strerror or error}") from None
    return folder


# --------------------------------------------------------------------------------------
# Temporary files
# --------------------------------------------------------------------------------------


def _process_running(pid: int) -> bool:
    """Whether a process ``pid`` may be running (True where that can't be told)."""
    if pid == os.getpid() or os.name != "posix":
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except (OverflowError, ValueError):  # no process can have that number
        return False
    return True


def _process_started_at(pid: int) -> float | None:
    """When process ``pid`` started (seconds since the epoch), where the system says (Linux); else None."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as file:
            fields = file.read().rsplit(b")", 1)[1].split()
        with open("/proc/stat", "rb") as file:
            boot = next(float(line.split()[1]) for line in file if line.startswith(b"btime "))
        return boot + int(fields[19]) / os.sysconf("SC_CLK_TCK")  # field 22 of stat: start time in clock ticks
    except (OSError, ValueError, IndexError, StopIteration):
        return None


#: Slack (seconds) when comparing a process's start with a file's time: /proc/stat's boot time is whole seconds.
_CLOCK_SLACK_S = 2.0


def _temporary_is_stale(path: str, pid: int) -> bool:
    """Whether the temporary file ``path`` named for process ``pid`` belongs to no running process.

    It does when no process ``pid`` runs, or when the process now called ``pid`` started after
    the file was last written (the writer was killed and its number given to another process).
    """
    if not _process_running(pid):
        return True
    if pid == os.getpid():
        return False
    started = _process_started_at(pid)
    try:
        written = os.lstat(path).st_mtime
    except OSError:
        return False
    return started is not None and started > written + _CLOCK_SLACK_S


def remove_stale_temporaries(folder: str | os.PathLike) -> list[Path]:
    """Remove the temporary files that killed bokehfit processes left in ``folder``; returns them.

    Only files of bokehfit's own naming (``.NAME.bokehfit-tmp-PID-TOKEN.SUFFIX``) that are
    regular files and belong to no running process (:func:`_temporary_is_stale`) are removed.
    """
    removed = []
    try:
        with os.scandir(folder) as scan:
            entries = [entry for entry, _ in zip(scan, range(_SCAN_MAX_ENTRIES))]
    except OSError:
        return removed
    for entry in entries:
        match = _TEMPORARY.match(entry.name)
        if match and entry.is_file(follow_symlinks=False) and _temporary_is_stale(entry.path, int(match["pid"])):
            with contextlib.suppress(OSError):
                os.unlink(entry.path)
                removed.append(Path(entry.path))
    return removed


#: Most entries of one folder looked at for stale temporary files (a folder of a million files is not scanned whole).
_SCAN_MAX_ENTRIES = 100_000


def _new_temporary(path: Path) -> Path:
    """Create an empty temporary file for ``path`` in its folder (usual permissions: 0o666 less the umask)."""
    for _ in range(16):
        temporary = path.parent / f".{path.name[:180]}.bokehfit-tmp-{os.getpid()}-{secrets.token_hex(4)}{path.suffix}"
        try:
            os.close(os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            return temporary
        except FileExistsError:
            continue
    raise OSError(f"could not create a temporary file beside {path}")


@contextlib.contextmanager
def _sigterm_raises():
    """While inside, SIGTERM raises ``SystemExit(143)`` (main thread, default handler only), so cleanup runs."""
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL:
        yield
        return

    def terminate(signum, frame):
        raise SystemExit(128 + signum)

    signal.signal(signal.SIGTERM, terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _pause_for_tests() -> None:
    value = os.environ.get(WRITE_PAUSE_ENV)
    if value:
        seconds = check_finite(WRITE_PAUSE_ENV, value)
        if seconds < 0:
            raise InputError(f"{WRITE_PAUSE_ENV} must be a number of seconds >= 0 (got {value!r})")
        time.sleep(seconds)


# --------------------------------------------------------------------------------------
# Writers
# --------------------------------------------------------------------------------------


def write_atomic(path: str | os.PathLike, write: Callable[[Path], None], *, sweep: bool = True) -> None:
    """Call ``write(temporary_path)``, then rename the temporary file to ``path``.

    Raises ``InputError`` (and writes nothing) if a file that bokehfit did not
    write is at ``path``. The temporary file is removed if anything fails; stale
    ones of killed processes in the same folder are removed first, unless ``sweep``
    is false: a writer of many files into one folder calls :func:`remove_stale_temporaries`
    on it once instead (a folder's scan costs about 0.7 ms of CPU per 1000 files).
    """
    path = Path(path)
    if sweep:
        remove_stale_temporaries(path.parent)
    check_replaceable(path)
    with _sigterm_raises():
        temporary = _new_temporary(path)
        try:
            try:
                write(temporary)
            except OSError as error:  # a full disk, a quota: named by the output, not the temporary file
                raise OSError(error.errno, error.strerror or str(error), str(path)) from None
            _pause_for_tests()
            check_replaceable(path)  # a file that appeared while we wrote
            os.replace(temporary, path)
        except BaseException:
            temporary.unlink(missing_ok=True)
            raise


def encode_text(text: str) -> bytes:
    """``text`` as UTF-8, where characters UTF-8 can't hold become U+FFFD.

    A file name that is not valid UTF-8 reaches Python as lone surrogates (PEP 383);
    written into a page or a report they would make the whole text unencodable.
    """
    try:
        return text.encode("utf-8")
    except UnicodeEncodeError:
        return replace_surrogates(text).encode("utf-8")


def replace_surrogates(text: str) -> str:
    """``text`` with every lone surrogate (an undecodable byte of a file name, PEP 383) made U+FFFD."""
    return _SURROGATE.sub("\ufffd", text)


_SURROGATE = re.compile("[\ud800-\udfff]")


def write_bytes_atomic(path: str | os.PathLike, data: bytes, *, sweep: bool = True) -> None:
    """Write ``data`` to ``path`` atomically, with bokehfit's mark added where the format has one.

    ``sweep``: as for :func:`write_atomic`.
    """
    path = Path(path)
    stamp = _STAMPS.get(path.suffix.lower())
    data = stamp(bytes(data)) if stamp else bytes(data)
    write_atomic(path, lambda tmp: tmp.write_bytes(data), sweep=sweep)


def write_json(path: str | os.PathLike, data: dict, *, sweep: bool = True) -> None:
    """Write ``data`` as indented JSON, atomically (``sweep``: :func:`write_atomic`).

    ``bokehfit_version``, the mark of JSON outputs, is added first where ``data`` lacks it.
    """
    if "bokehfit_version" not in data:
        data = {"bokehfit_version": __version__, **data}
    write_bytes_atomic(path, (json.dumps(data, indent=1, allow_nan=False) + "\n").encode("utf-8"), sweep=sweep)


def write_png(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an 8- or 16-bit image (grey, or BGR as OpenCV orders it) as PNG, atomically."""
    import cv2

    ok, encoded = cv2.imencode(".png", image)
    if not ok:
        raise OSError(f"could not encode {path} as PNG")
    write_bytes_atomic(path, encoded.tobytes())


def write_exr(path: str | os.PathLike, channels: dict[str, np.ndarray]) -> None:
    """Write float32 channels (``{"Y": ...}`` or ``{"R": ..., "G": ..., "B": ...}``) as ZIP-compressed OpenEXR."""
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, "software": GENERATOR}
    planes = {name: np.ascontiguousarray(plane, dtype=np.float32) for name, plane in channels.items()}

    def write(tmp: Path) -> None:
        try:
            with OpenEXR.File(header, planes) as exr:
                exr.write(str(tmp))
        except RuntimeError as error:  # OpenEXR reports a full disk and other I/O failures as RuntimeError
            text = str(error)
            code = errno.ENOSPC if "No space left" in text else errno.EIO
            raise OSError(code, os.strerror(code) if code == errno.ENOSPC else text.split(". ")[0], str(tmp)) from None

    write_atomic(path, write)


def write_kernel_image(path: str | os.PathLike, kernel: np.ndarray) -> None:
    """Save a kernel: ``.npy`` raw float32, ``.png`` 16-bit scaled to its peak, ``.exr`` float32."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".npy":
        buffer = io.BytesIO()
        np.save(buffer, kernel.astype(np.float32))
        write_bytes_atomic(path, buffer.getvalue())
    elif suffix == ".png":
        peak = float(kernel.max())
        scaled = np.round(kernel / peak * 65535.0) if peak > 0 else np.zeros_like(kernel)
        write_png(path, scaled.astype(np.uint16))
    elif suffix == ".exr":
        write_exr(path, {"Y": kernel})
    else:
        raise InputError(f"kernel file must end in {', '.join(KERNEL_FORMATS)} (got {str(path)!r})")
