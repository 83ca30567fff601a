"""Write result files atomically, never over a file bokehfit did not write, and leave nothing behind.

Every output goes to a temporary file in the destination's folder and is then
renamed over the destination (:func:`write_atomic`), so a reader never sees half a
file. The writers here (bytes, JSON, PNG, OpenEXR, a kernel) all go through it.

The rooms around this one: whose file an existing one is, by bokehfit's mark, which the
writers add (:mod:`bokehfit.output_marks`); which output paths are refused, before any work
(:mod:`bokehfit.output_paths`); the temporary files' names and the removal of those that
killed processes left (:mod:`bokehfit.output_temporaries`); opening only regular files
(:mod:`bokehfit.regular_files`); text that a page or a report can hold
(:mod:`bokehfit.text_encoding`).

**Temporary files.** A failed write removes its own: on any exception, on Ctrl-C, and on
SIGTERM (which, while a write is under way in the main thread, becomes ``SystemExit(143)``).
Before a write, stale ones of killed processes in the folder are removed.

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
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from bokehfit import __version__
from bokehfit.errors import InputError, check_finite
from bokehfit.output_marks import GENERATOR, add_mark
from bokehfit.output_paths import check_replaceable
from bokehfit.output_temporaries import new_temporary, remove_stale_temporaries

__all__ = [
    "KERNEL_FORMATS",
    "WRITE_PAUSE_ENV",
    "write_atomic",
    "write_bytes_atomic",
    "write_exr",
    "write_json",
    "write_kernel_image",
    "write_png",
]

#: Kernel file formats by suffix.
KERNEL_FORMATS = (".npy", ".png", ".exr")

#: Environment variable of the test hook: seconds to wait before each rename.
WRITE_PAUSE_ENV = "BOKEHFIT_WRITE_PAUSE_S"


# --------------------------------------------------------------------------------------
# Atomic writing
# --------------------------------------------------------------------------------------


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
        temporary = new_temporary(path)
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


# --------------------------------------------------------------------------------------
# Writers
# --------------------------------------------------------------------------------------


def write_bytes_atomic(path: str | os.PathLike, data: bytes, *, sweep: bool = True) -> None:
    """Write ``data`` to ``path`` atomically, with bokehfit's mark added where the format has one.

    ``sweep``: as for :func:`write_atomic`.
    """
    path = Path(path)
    data = add_mark(path, data)
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
