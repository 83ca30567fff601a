"""One photo of a survey, as a worker process (local pool or Dask worker) runs it.

The worker never writes anything: it returns a plain dict (picklable, small)
that the parent stores. Every outcome is a record: compare's four statuses,
and three of the survey's own (:data:`FAILURE_STATUSES`).
"""

from __future__ import annotations

import os
import signal
import sys
import tempfile
import threading
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

from bokehfit.threads import SINGLE_THREAD_VARIABLES

__all__ = [
    "PhotoTask",
    "FAILURE_STATUSES",
    "STATUSES",
    "init_worker",
    "survey_photo",
    "THUMBNAIL_PX",
    "PARENT_CHECK_S",
    "THREAD_VARIABLES",
    "SINGLE_THREAD_VARIABLES",
    "SHARED_THREAD_VARIABLES",
    "usable_cores",
    "worker_threads",
    "thread_environment",
]

#: Statuses of a survey row besides compare's (design.md §7b): the file could not be read as a
#: photo, compare raised (a bug or a lost GPU), or it ran past the per-photo time limit.
FAILURE_STATUSES = ("unreadable", "error", "timeout")
#: Every status a row can have: compare's, then the survey's own.
STATUSES = ("fitted", "unsure", "no_fit", "no_discs", *FAILURE_STATUSES)
#: Long side of the thumbnails kept in the database for the report.
THUMBNAIL_PX = 192
_THUMBNAIL_QUALITY = 80


@dataclass(frozen=True)
class PhotoTask:
    """What a worker needs for one photo.

    ``options`` are :func:`bokehfit.compare.compare_photo`'s
    keyword arguments; ``timeout_s`` is the per-photo limit (None: no limit).
    """

    path: str
    sha256: str
    options: dict = field(default_factory=dict)
    command_line: str = ""
    html: bool = True
    timeout_s: float | None = None


# Thread pools of one thread in every worker (:mod:`bokehfit.threads`: SINGLE_THREAD_VARIABLES): a
# second OpenBLAS thread does none of the fit's work and spins beside the worker (on a 512×384
# photo, 3 to 17 % more CPU time, the more so the idler the machine), and at one a photo's numbers
# depend neither on the machine's cores, nor on ``--jobs``, nor on Dask (whose nanny starts its
# workers with these three at 1 too).
#: Thread pools sized to a worker's share of the cores: OpenCV's and lavapipe's (the CPU Vulkan
#: driver); each starts a thread per core by default, so N workers on N cores would start N times
#: as many as there are cores. Their results do not depend on the count.
SHARED_THREAD_VARIABLES = ("OPENCV_FOR_THREADS_NUM", "LP_NUM_THREADS")
THREAD_VARIABLES = SINGLE_THREAD_VARIABLES + SHARED_THREAD_VARIABLES


def usable_cores() -> int:
    """The CPU cores this process may use."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def worker_threads(workers: int) -> int:
    """Threads each of ``workers`` photos run at once on this machine may use: its share of the usable cores, at least one."""
    return max(1, usable_cores() // max(1, workers))


def thread_environment(workers: int, environ=None) -> dict[str, str]:
    """The thread-pool sizes (:data:`THREAD_VARIABLES`) of a worker process, one of ``workers`` on this machine.

    Variables that ``environ`` (default ``os.environ``) already sets are left out: the user's word stands.
    """
    environ = os.environ if environ is None else environ
    sizes = {name: 1 for name in SINGLE_THREAD_VARIABLES} | {name: worker_threads(workers) for name in SHARED_THREAD_VARIABLES}
    return {name: str(size) for name, size in sizes.items() if name not in environ}


#: The adapter choice of this worker's survey, set by :func:`init_worker` (None: the best one found).
_ADAPTER = None


class PhotoTimeout(Exception):
    """A photo ran past its time limit."""


#: How often a local worker checks that its parent is alive (seconds), where the kernel can't tell it.
PARENT_CHECK_S = 0.5


def _die_with(parent_pid: int) -> None:
    """End this process when the process ``parent_pid`` (its parent) ends, however it ends.

    Linux sends SIGKILL at the parent's death (``PR_SET_PDEATHSIG``); elsewhere, and
    for a parent that died before that was set, a daemon thread checks the parent.
    """
    if os.getppid() != parent_pid:
        os._exit(1)
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):
            pass
        if os.getppid() != parent_pid:  # died before the kernel was told
            os._exit(1)

    def watch():
        while os.getppid() == parent_pid:
            time.sleep(PARENT_CHECK_S)
        os._exit(1)

    threading.Thread(target=watch, name="bokehfit-parent-watch", daemon=True).start()


def init_worker(adapter=None, ignore_sigint: bool = True, parent_pid: int | None = None, workers: int | None = None) -> None:
    """Per-process start-up: import bokehfit's pipeline once, note the GPU to use, size the thread pools.

    The GPU is not opened here: most photos' kernels are drawn exactly, on the CPU,
    and a worker whose photo needs one opens it then (:func:`bokehfit.gpu.get_gpu`
    keeps it for the process), so a worker pays a device's start-up (0.7 s of CPU on
    lavapipe, and a thread per core) only if a photo needs it. ``workers``, the photos
    this machine runs at once, sizes the OpenCV and lavapipe pools that the process's
    environment does not (:func:`thread_environment`; a local pool starts its workers
    with all of them set, a Dask nanny with the single-thread ones).

    In a local pool the worker also ignores SIGINT: Ctrl-C reaches the whole
    process group and the parent alone decides what stops (it starts the worker
    with SIGINT blocked, unblocked here once ignored). With ``parent_pid`` the
    worker ends when that process ends, so a killed survey leaves no worker behind.
    """
    global _ADAPTER

    if ignore_sigint and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        if hasattr(signal, "pthread_sigmask"):
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    if parent_pid is not None:
        _die_with(parent_pid)
    _ADAPTER = adapter
    if workers is not None:
        unset = thread_environment(workers)
        if "LP_NUM_THREADS" in unset:  # read when the Vulkan driver loads, with the GPU's first use
            os.environ["LP_NUM_THREADS"] = unset["LP_NUM_THREADS"]
        if "OPENCV_FOR_THREADS_NUM" in unset:  # OpenCV may be loaded: set its pool itself
            import cv2

            cv2.setNumThreads(int(unset["OPENCV_FOR_THREADS_NUM"]))
    import bokehfit.compare  # noqa: F401  (the pipeline, imported once per process)
    import bokehfit.report.html  # noqa: F401


class _Deadline:
    """SIGALRM after ``seconds`` raises :class:`PhotoTimeout` (main thread of a POSIX process only)."""

    def __init__(self, seconds: float | None):
        self.active = bool(seconds) and hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()
        self.seconds = seconds

    def __enter__(self):
        if self.active:
            def expire(signum, frame):
                raise PhotoTimeout(f"stopped after the per-photo limit of {self.seconds:g} s")

            self.previous = signal.signal(signal.SIGALRM, expire)
            signal.setitimer(signal.ITIMER_REAL, self.seconds)
        return self

    def __exit__(self, *exc):
        if self.active:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, self.previous)
        return False


def _thumbnail(display) -> bytes | None:
    """A small JPEG of the photo as displayed (RGB uint8), for the survey report."""
    import cv2

    height, width = display.shape[:2]
    scale = min(1.0, THUMBNAIL_PX / max(height, width))
    size = (max(1, round(width * scale)), max(1, round(height * scale)))
    small = cv2.resize(display, size, interpolation=cv2.INTER_AREA) if scale < 1.0 else display
    ok, encoded = cv2.imencode(".jpg", cv2.cvtColor(small, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, _THUMBNAIL_QUALITY])
    return encoded.tobytes() if ok else None


def _one_line(error: BaseException) -> str:
    text = " ".join(str(error).split()) or type(error).__name__
    return text if len(text) <= 500 else text[:497] + "..."


def _compare(task: PhotoTask, path: str) -> dict:
    from bokehfit.compare import compare_photo
    from bokehfit.report.html import build_html

    comparison = compare_photo(path, **task.options, adapter=_ADAPTER)
    document = comparison.to_json(task.command_line)
    document["input"]["path"] = task.path
    return {
        "status": comparison.status,
        "reason": comparison.reason,
        "document": document,
        "html": build_html(comparison, task.command_line) if task.html else None,
        "thumbnail": _thumbnail(comparison.photo.display),
    }


def survey_photo(task: PhotoTask, data: bytes | None = None) -> dict:
    """Run compare on one photo and return its record; never raises for the photo's sake.

    Parameters
    ----------
    task : PhotoTask
        The photo and how to compare it.
    data : bytes, optional
        The file's bytes, where the worker can't be assumed to see the parent's
        files (a Dask cluster); they are written under the photo's own name in a
        private temporary folder. None: the worker reads ``task.path``.

    Returns
    -------
    dict
        ``sha256``, ``path``, ``status`` (one of :data:`STATUSES`), ``reason``
        (None when fitted), ``document`` (compare's JSON, None for the survey's
        own statuses), ``html`` (the report, or None), ``thumbnail`` (JPEG bytes
        or None), ``warnings`` (list of str), ``seconds``, ``worker`` (host:pid).
    """
    from bokehfit.errors import InputError

    started = time.perf_counter()
    record = {"sha256": task.sha256, "path": task.path, "document": None, "html": None, "thumbnail": None}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            with _Deadline(task.timeout_s), tempfile.TemporaryDirectory(prefix="bokehfit-survey-") as scratch:
                path = task.path
                if data is not None:
                    path = os.path.join(scratch, Path(task.path).name)
                    Path(path).write_bytes(data)
                record.update(_compare(task, path))
        except PhotoTimeout as error:
            record.update(status="timeout", reason=_one_line(error))
        except InputError as error:
            record.update(status="unreadable", reason=_one_line(error))
        except Exception as error:  # a photo's failure is a row, never the survey's end
            record.update(status="error", reason=f"{type(error).__name__}: {_one_line(error)}")
    record["warnings"] = sorted({_one_line(w.message) for w in caught})
    record["seconds"] = time.perf_counter() - started
    record["worker"] = f"{os.uname().nodename}:{os.getpid()}" if hasattr(os, "uname") else str(os.getpid())
    if record["status"] not in STATUSES:  # compare gained a status this module does not know
        record["reason"] = f"unknown status {record['status']!r}: {record['reason']}"
        record["status"] = "error"
    return record
