"""Run a survey: hash the photos, skip what the database holds, farm the rest out, store each result.

Two engines do the farming, both existing ones: :class:`concurrent.futures.ProcessPoolExecutor`
on this machine (each worker process imports bokehfit once, in its initializer, opens
the GPU only if a photo's kernel needs it, and runs its libraries' thread pools on its
share of the cores) and a Dask ``distributed`` cluster. Whichever runs the
photos, the parent process alone writes: the per-photo JSON and HTML reports
(atomically, through :mod:`bokehfit.outputs`), then the photo's row, committed
on its own, as each result arrives.

Stopping: the first Ctrl-C stops handing out photos, keeps every finished
photo (stored as it arrived) and stops the local workers at once, losing only
the photos in progress; a second Ctrl-C stops at once. Local workers share the
parent's process group and die with the parent, so a killed survey leaves no
worker behind.
"""

from __future__ import annotations

import collections
import concurrent.futures
import contextlib
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from bokehfit.errors import InputError
from bokehfit.output_temporaries import remove_stale_temporaries
from bokehfit.outputs import write_bytes_atomic, write_json
from bokehfit.surveys.files import content_hash
from bokehfit.surveys.scheduler import check_scheduler
from bokehfit.surveys.store import SurveyStore, reports_folder, row_from_record
from bokehfit.surveys.work import FAILURE_STATUSES, PhotoTask, init_worker, survey_photo, thread_environment
from bokehfit.text_encoding import encode_text

__all__ = ["SurveyRun", "run_survey", "IN_FLIGHT_PER_WORKER", "MAX_WORKER_CRASHES"]

#: Tasks handed out per worker at a time: one running, one waiting, so no worker idles
#: between results while few enough are out that a crash or Ctrl-C loses little.
IN_FLIGHT_PER_WORKER = 2
#: A photo whose worker process died this many times is recorded as an error (it is the likely cause).
MAX_WORKER_CRASHES = 2


@dataclass
class SurveyRun:
    """What one survey run did.

    Attributes
    ----------
    found : int
        Photo files named by the paths.
    skipped : int
        Already in the database (or the same content as another file of this run).
    done : int
        Rows written by this run.
    statuses : collections.Counter
        Rows written by this run, by status.
    seconds : float
        Wall-clock time of the run (hashing included).
    interrupted : bool
        Stopped by Ctrl-C; what was done is saved and a rerun resumes.
    """

    found: int = 0
    skipped: int = 0
    done: int = 0
    statuses: collections.Counter = field(default_factory=collections.Counter)
    seconds: float = 0.0
    interrupted: bool = False

    def summary(self) -> str:
        counts = ", ".join(f"{n} {status}" for status, n in sorted(self.statuses.items())) or "nothing new"
        rate = f", {self.done / self.seconds:.2f} photos/s" if self.done and self.seconds > 0 else ""
        head = "survey interrupted (rerun to resume)" if self.interrupted else "survey done"
        return f"{head}: {self.found} photos, {self.skipped} already done, {self.done} new ({counts}) in {self.seconds:.1f} s{rate}"


def _safe_stem(path: str) -> str:
    stem = "".join(c if c.isalnum() or c in "-_." else "_" for c in Path(path).stem)
    return stem[:80] or "photo"


class _Keeper:
    """The parent's one writer: per-photo reports, then the row.

    The reports folder is swept of killed writers' temporary files once, before the
    first report of the run, not before each: it holds two files a photo, and a sweep
    reads the whole folder (20 000 files: 14 ms of CPU, twice a photo).
    """

    def __init__(self, store: SurveyStore, sizes: dict[str, int | None]):
        self.store, self.sizes = store, sizes
        self.folder = reports_folder(store.path)
        self.swept = False

    def keep(self, record: dict) -> str:
        json_path = html_path = None
        document = record.get("document")
        if document is not None:
            self.folder.mkdir(exist_ok=True)
            if not self.swept:
                remove_stale_temporaries(self.folder)
                self.swept = True
            name = f"{_safe_stem(record['path'])}-{record['sha256'][:12]}"
            json_path = f"{self.folder.name}/{name}.json"
            write_json(self.store.path.parent / json_path, document, sweep=False)
            if record.get("html") is not None:
                html_path = f"{self.folder.name}/{name}.html"
                write_bytes_atomic(self.store.path.parent / html_path, encode_text(record["html"]), sweep=False)
        row = row_from_record(record, size_bytes=self.sizes.get(record["sha256"]), json_path=json_path, html_path=html_path)
        self.store.put(row)
        return row["status"]


def _failure(task: PhotoTask, status: str, reason: str) -> dict:
    return {"sha256": task.sha256, "path": task.path, "status": status, "reason": reason, "document": None,
            "html": None, "thumbnail": None, "warnings": [], "seconds": None, "worker": None}


@contextlib.contextmanager
def _unimportable_main_hidden():
    """While inside, a main script that can't be read again is hidden from the workers that start.

    A spawned worker first runs the parent's main script again from its path. A
    script read from stdin (``python - < survey.py``) has the path ``<stdin>``,
    which isn't a file, and every worker would die starting; hidden, the workers
    skip it, as they do for ``python -c`` and notebooks.
    """
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if path is None or getattr(main, "__spec__", None) is not None or os.path.isfile(path):
        yield
        return
    del main.__file__
    try:
        yield
    finally:
        main.__file__ = path


@contextlib.contextmanager
def _environment(variables: dict[str, str]):
    """While inside, ``os.environ`` also holds ``variables``: processes started inside inherit them."""
    saved = {name: os.environ.get(name) for name in variables}
    os.environ.update(variables)
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


class _LocalEngine:
    """A process pool on this machine, rebuilt if a worker process dies.

    Each worker runs BLAS on one thread and OpenCV and lavapipe on its share of the
    cores (:func:`~bokehfit.surveys.work.thread_environment`): the pools' sizes are read
    from the environment as each library loads, so they are set in the environment each
    worker process starts with (a spawned worker loads NumPy before its initializer runs).
    """

    def __init__(self, jobs: int, adapter):
        self.jobs, self.adapter = jobs, adapter
        self.threads = thread_environment(jobs)
        self.pool = self._new_pool()
        self.workers = jobs

    def _new_pool(self):
        # spawn: a fresh interpreter per worker (no threads of the parent's GPU or database inherited)
        with _sigint_blocked():
            return concurrent.futures.ProcessPoolExecutor(
                max_workers=self.jobs, mp_context=multiprocessing.get_context("spawn"),
                initializer=init_worker, initargs=(self.adapter, True, os.getpid(), self.jobs),
            )

    def submit(self, task: PhotoTask):
        # the pool starts its processes as tasks arrive: they start with SIGINT blocked, so a
        # Ctrl-C while one is starting can't stop it with a traceback before it ignores SIGINT,
        # and with their share of the cores in their environment
        with _unimportable_main_hidden(), _sigint_blocked(), _environment(self.threads):
            return self.pool.submit(survey_photo, task)

    def wait(self, futures):
        done, _ = concurrent.futures.wait(futures, return_when=concurrent.futures.FIRST_COMPLETED)
        return done

    def broken(self, error: BaseException) -> bool:
        """Whether ``error`` says a worker process died and took the pool with it."""
        return isinstance(error, concurrent.futures.process.BrokenProcessPool)

    def restart(self) -> None:
        self.pool.shutdown(wait=False, cancel_futures=True)
        self.pool = self._new_pool()

    def stop(self, futures) -> None:
        """Stop at once: kill the worker processes (their photos in progress are lost)."""
        # The pool's processes: no public way to stop them before Python 3.14's kill_workers().
        processes = list((getattr(self.pool, "_processes", None) or {}).values())
        for process in processes:
            with contextlib.suppress(Exception):
                process.kill()
        self.pool.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            with contextlib.suppress(Exception):
                process.join(timeout=5.0)

    def close(self, interrupted: bool) -> None:
        if interrupted:
            self.stop(())
        else:
            self.pool.shutdown(wait=True, cancel_futures=True)


class _DaskEngine:
    """A Dask ``distributed`` cluster: the photo's bytes travel with its task, so workers need no shared folder."""

    def __init__(self, scheduler, adapter, timeout_s: float):
        import distributed

        self.distributed = distributed
        self.own_client = not isinstance(scheduler, distributed.Client)
        if self.own_client:
            check_scheduler(scheduler)  # within a stated timeout, before Dask's own connect (which may wait forever)
        try:
            self.client = distributed.Client(scheduler, timeout=timeout_s) if self.own_client else scheduler
        except Exception as error:  # noqa: BLE001 - Dask raises many kinds (TLS without its configuration: TypeError)
            raise InputError(f"--scheduler {scheduler!r}: can't reach a Dask scheduler there ({' '.join(str(error).split())})") from None
        threads = self.client.nthreads()
        self.workers = max(1, sum(threads.values()))
        # each worker's thread pools get its share of its machine: the photos that machine's workers run at once
        hosts = collections.defaultdict(list)
        for address in threads:
            try:
                host = distributed.comm.get_address_host(address)
            except (ValueError, TypeError):  # an address Dask can't read: a machine of its own
                host = address
            hosts[host].append(address)
        for addresses in hosts.values():
            self.client.run(init_worker, adapter, False, None, sum(threads[a] for a in addresses), workers=addresses)

    def submit(self, task: PhotoTask):
        data = Path(task.path).read_bytes()
        return self.client.submit(survey_photo, task, self.client.scatter(data, hash=False), pure=False,
                                  key=f"bokehfit-survey-{task.sha256[:16]}-{time.monotonic_ns()}")

    def wait(self, futures):
        return self.distributed.wait(list(futures), return_when="FIRST_COMPLETED").done

    def broken(self, error: BaseException) -> bool:
        return False  # Dask reschedules a lost worker's tasks itself; KilledWorker ends up as an error row

    def restart(self) -> None:
        raise AssertionError("a Dask cluster is never restarted by the survey")

    def stop(self, futures) -> None:
        """Stop at once: cancel the photos still on the cluster."""
        with contextlib.suppress(Exception):
            self.client.cancel(list(futures))

    def close(self, interrupted: bool) -> None:
        if self.own_client:
            self.client.close()


@contextlib.contextmanager
def _sigint_blocked():
    """While inside, SIGINT waits (POSIX, main thread); processes started inside inherit it blocked."""
    if not hasattr(signal, "pthread_sigmask") or threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


class _Stopper:
    """The survey's SIGINT handler while it runs (main thread, default handler only).

    The first Ctrl-C raises ``KeyboardInterrupt`` in the loop while it waits for
    results (else as soon as the result in hand is stored), which keeps what is
    finished and stops the workers; a later one stops the workers at once, wherever
    the parent is, and raises again.
    """

    def __init__(self):
        self.count = 0
        self.waiting = False  #: the loop waits for results: a first Ctrl-C may raise there
        self.requested = False  #: a first Ctrl-C came while a result was being stored
        self.engine = None
        self.in_flight: dict = {}
        self.previous = None

    def __enter__(self):
        if threading.current_thread() is threading.main_thread() and \
                signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self.previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc):
        if self.previous is not None:
            signal.signal(signal.SIGINT, self.previous)
        return False

    def _handle(self, signum, frame):
        self.count += 1
        if self.count == 1:
            print("bokehfit: stopping; every finished photo is kept (Ctrl-C again to stop at once)", file=sys.stderr, flush=True)
            if not self.waiting:
                self.requested = True
                return
        elif self.engine is not None:
            self.engine.stop(list(self.in_flight))
        raise KeyboardInterrupt

    def wait(self, engine, futures):
        """``engine.wait(futures)``, where a first Ctrl-C stops the survey."""
        if self.requested:
            raise KeyboardInterrupt
        self.waiting = True
        try:
            return engine.wait(futures)
        finally:
            self.waiting = False


def run_survey(
    photos: list[Path],
    store: SurveyStore,
    *,
    options: dict | None = None,
    jobs: int = 1,
    scheduler=None,
    timeout_s: float | None = None,
    html: bool = True,
    retry_failed: bool = False,
    command_line: str = "",
    adapter=None,
    progress: bool | None = None,
    connect_timeout_s: float = 30.0,
    on_result: Callable[[dict], None] | None = None,
) -> SurveyRun:
    """Survey ``photos`` into ``store``; see :func:`bokehfit.survey` for the parameters.

    The first Ctrl-C (SIGINT, in the main thread) stops handing out photos, stores
    the results already back, stops the local workers at once (the photos in
    progress are done by the next run) and returns the run with ``interrupted``
    set; a second Ctrl-C raises ``KeyboardInterrupt`` at once.
    """
    started = time.perf_counter()
    options = dict(options or {})
    run = SurveyRun(found=len(photos))
    known = store.statuses()
    tasks: dict[str, PhotoTask] = {}
    sizes: dict[str, int | None] = {}
    keeper = _Keeper(store, sizes)
    for path in photos:
        try:
            sha256 = content_hash(path)
            sizes[sha256] = path.stat().st_size
        except OSError as error:  # can't even be read: a row keyed by its path
            sha256 = f"path:{os.path.abspath(path)}"
            if sha256 not in known or retry_failed:
                task = PhotoTask(str(path), sha256)
                run.statuses[keeper.keep(_failure(task, "unreadable", f"can't read the file: {error.strerror or error}"))] += 1
                run.done += 1
            else:
                run.skipped += 1
            continue
        status = known.get(sha256)
        if sha256 in tasks or (status is not None and not (retry_failed and status in FAILURE_STATUSES)):
            run.skipped += 1
            continue
        tasks[sha256] = PhotoTask(str(path), sha256, options, command_line, html, timeout_s)
    if not tasks:
        run.seconds = time.perf_counter() - started
        return run

    with _Stopper() as stopper:
        try:
            engine = _LocalEngine(jobs, adapter) if scheduler is None else _DaskEngine(scheduler, adapter, connect_timeout_s)
        except KeyboardInterrupt:
            run.interrupted = True
            run.seconds = time.perf_counter() - started
            return run
        stopper.engine = engine
        return _farm(engine, tasks, keeper, run, stopper, progress, on_result, started)


def _farm(engine, tasks, keeper, run, stopper, progress, on_result, started) -> SurveyRun:
    """Hand the tasks to ``engine`` and keep each result as it arrives, until done or Ctrl-C."""
    bar = None
    if progress if progress is not None else sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=len(tasks), unit="photo", desc="survey", file=sys.stderr, smoothing=0.1)
    waiting = collections.deque(tasks.values())
    in_flight: dict = {}
    stopper.in_flight = in_flight
    crashes: collections.Counter = collections.Counter()
    try:
        while waiting or in_flight:
            while waiting and len(in_flight) < IN_FLIGHT_PER_WORKER * engine.workers:
                task = waiting.popleft()
                try:
                    in_flight[engine.submit(task)] = task
                except Exception as error:
                    if not engine.broken(error):
                        raise
                    # a worker died since the last result: the pool refuses new work, and the
                    # photos it holds fail with it below; with none held, start a new pool now
                    waiting.appendleft(task)
                    if in_flight:
                        break
                    engine.restart()
            for future in stopper.wait(engine, in_flight):
                task = in_flight.pop(future)
                try:
                    record = future.result()
                except Exception as error:  # the worker, not the photo, failed
                    if engine.broken(error):
                        engine.restart()
                        # every task of the broken pool failed with it: those that ran may be the cause
                        for other in [task, *in_flight.values()]:
                            crashes[other.sha256] += 1
                        lost = [task, *in_flight.values()]
                        in_flight.clear()
                        for other in reversed(lost):
                            if crashes[other.sha256] >= MAX_WORKER_CRASHES:
                                record = _failure(other, "error", "the worker process died while surveying this photo")
                                run.statuses[keeper.keep(record)] += 1
                                run.done += 1
                                if bar is not None:
                                    bar.update()
                            else:
                                waiting.appendleft(other)
                        break
                    record = _failure(task, "error", f"{type(error).__name__}: {' '.join(str(error).split())}")
                run.statuses[keeper.keep(record)] += 1
                run.done += 1
                if on_result is not None:
                    on_result(record)
                if bar is not None:
                    bar.update()
                    bar.set_postfix_str(", ".join(f"{s} {n}" for s, n in sorted(run.statuses.items())), refresh=False)
    except KeyboardInterrupt:
        run.interrupted = True
        # the photos already back are kept; those in progress are dropped with their workers
        finished = [future for future in in_flight if future.done() and not future.cancelled()]
        engine.stop(list(in_flight))
        for future in finished:
            with contextlib.suppress(Exception):
                record = future.result()
                run.statuses[keeper.keep(record)] += 1
                run.done += 1
        in_flight.clear()
    finally:
        if bar is not None:
            bar.close()
        engine.close(run.interrupted)
        run.seconds = time.perf_counter() - started
    return run
