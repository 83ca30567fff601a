"""``bokehfit view PHOTO``: one photo's compare in the browser, steered by a person.

The photo is fixed when the server starts (:class:`PhotoSession`): it is read
once, its sha256 and size kept, and a display copy (JPEG, downscaled where its
long side passes ``MAX_DISPLAY_SIDE``; ``scale`` says by how much) served to the
page. No path from the page is ever opened.

Every compare runs in a worker process of its own (:class:`_Worker`, started
with ``spawn``): the automatic one at start, then each refit on exactly the
discs the page sends, which are passed in memory as a
:class:`~bokehfit.discs.labels.DiscLabels` (``compare --discs`` semantics:
the usable discs, measured afresh at their places, and only those, are fitted).
A refit is bounded: at most ``MAX_REFIT_DISCS`` places, one at a time, killed
after ``MAX_REFIT_S``; the page polls its progress and may cancel it (the
worker is killed and a fresh one started). Each finished compare keeps its
``compare --json`` document, its HTML report (the same
:class:`~bokehfit.compare.Comparison` renders both) and, per fitted disc, the
photo's crop, the fitted model at that place and their residual as PNGs, and
what the page needs to draw that disc's kernel itself with the project's WGSL
kernel renderer (:func:`kernel_tile`; the PNGs are its fallback without WebGPU).
"""

from __future__ import annotations

import base64
import hashlib
import math
import multiprocessing
import threading
import time
from collections import OrderedDict
from pathlib import Path

import cv2
import numpy as np

from bokehfit.errors import InputError

__all__ = ["MAX_REFIT_DISCS", "MAX_REFIT_S", "MAX_DISPLAY_SIDE", "PhotoSession", "discs_file", "kernel_tile", "refit_labels"]

#: Most places in one refit (a photo's usable discs are tens; the fit uses at most 12 of them).
MAX_REFIT_DISCS = 64
#: Longest refit before the worker is killed (s).
MAX_REFIT_S = 120.0
#: Longest side of the photo as the page shows it (pixels); larger photos are downscaled.
MAX_DISPLAY_SIDE = 4096
#: Most shapes named in one refit.
MAX_REFIT_SHAPES = 32
#: Results kept for the page's undo and its saves (the automatic one is always kept).
MAX_RESULTS = 32
#: Disc tiles: side of each image (pixels) and the residual's span (share of the disc's brightness).
TILE_PX = 96
RESIDUAL_SPAN = 0.25
#: Tiles made per result (the fitted discs, largest first).
MAX_TILES = 16
#: Longest side of the crop the page draws the kernel on (pixels): wider crops are area-reduced
#: by an integer factor, the disc's size, centre and blur with them.
KERNEL_CROP_SIDE = 160
#: Monte-Carlo samples per pixel of the disc's area for the page's kernel, and their bounds.
KERNEL_SAMPLES_PER_PX = 256
KERNEL_SAMPLES = (2**16, 2**21)


# --- the work done in the worker process ------------------------------------------------------


def _png_uri(image: np.ndarray) -> str:
    ok, data = cv2.imencode(".png", image)
    return "data:image/png;base64," + base64.b64encode(data.tobytes()).decode("ascii") if ok else ""


def _tiles(comparison) -> dict[str, dict]:
    """Per fitted disc: the photo's crop, the fitted model at that place and the residual (PNG data URIs)."""
    from bokehfit.report.html import disc_windows, grey8, residual8

    if not comparison.fit:
        return {}
    tiles = {}
    for w in disc_windows(comparison, MAX_TILES):
        tiles[str(w.item.disc.index)] = {
            "photo": _png_uri(grey8(w.crop, w.low, w.high, TILE_PX)),
            "model": _png_uri(grey8(w.model, w.low, w.high, TILE_PX)),
            "residual": _png_uri(residual8(w.crop - w.model, RESIDUAL_SPAN * (w.high - w.low), TILE_PX)),
            "kernel": kernel_tile(w.fitted, w.crop, w.left, w.top),
        }
    return tiles


def kernel_tile(fitted, crop: np.ndarray, left: int, top: int) -> dict:
    """What the page needs to draw one fitted disc's kernel on the GPU (``kernel_mc.wgsl``) beside its crop.

    The crop (``left``, ``top``: its top-left pixel in the photo), area-reduced by an integer
    ``factor`` where it is wider than :data:`KERNEL_CROP_SIDE`, as uint16 between ``crop_range``
    (base64, rows top first); the disc in the reduced crop's pixels: its centre (pixel-centre
    coordinates, x right, y down), equal-area diameter, edge blur and the kernel's ``scale``
    (design.md §4: d·√π/2); its levels; and the fitted aperture's ``ApertureParams`` values at the
    disc's field position (:meth:`Aperture.shader_params`), which the page packs with the served
    layout. ``samples`` and ``strata``: the stratified Monte-Carlo count (m² samples).
    """
    side = crop.shape[0]
    factor = max(1, math.ceil(side / KERNEL_CROP_SIDE))
    size = side // factor
    reduced = crop[: size * factor, : size * factor].reshape(size, factor, size, factor).mean(axis=(1, 3))
    low, high = float(reduced.min()), float(reduced.max())
    quantised = np.round((reduced - low) / max(high - low, 1e-12) * 65535.0).astype("<u2")
    # Pixel (j) of the reduced crop averages full pixels j·f .. j·f + f − 1: its centre is at j·f + (f − 1)/2.
    centre = [(fitted.center_xy[0] - left - (factor - 1) / 2) / factor, (fitted.center_xy[1] - top - (factor - 1) / 2) / factor]
    diameter = fitted.diameter_px / factor
    strata = math.isqrt(int(min(max(KERNEL_SAMPLES_PER_PX * math.pi * diameter * diameter / 4, KERNEL_SAMPLES[0]),
                                KERNEL_SAMPLES[1])))
    values = fitted.aperture.shader_params(fitted.field_position)
    return {
        "size": size,
        "factor": factor,
        "left": left,
        "top": top,
        "center": centre,
        "diameter_px": diameter,
        "scale": diameter * math.sqrt(math.pi) / 2.0,
        "blur_px": fitted.blur_px / factor,
        "plateau": float(fitted.plateau),
        "background": float(fitted.background),
        "field_position": None if fitted.field_position is None else [float(v) for v in fitted.field_position],
        "aperture": {name: (list(value) if isinstance(value, tuple) else value) for name, value in values.items()},
        "chromatic": None if fitted.aperture.chromatic is None else [fitted.aperture.chromatic.red, fitted.aperture.chromatic.blue],
        "samples": strata * strata,
        "strata": strata,
        "crop": base64.b64encode(quantised.tobytes()).decode("ascii"),
        "crop_range": [low, high],
        "residual_span": RESIDUAL_SPAN * (max(fitted.plateau, fitted.background + 1e-6) - fitted.background),
    }


def _run_compare(path: str, labels, shapes, progress) -> dict:
    from bokehfit.compare import compare_photo
    from bokehfit.report.html import build_html

    comparison = compare_photo(path, discs=labels, shapes=shapes, progress=progress)
    where = "the page's discs" if labels is not None else "found discs"
    command = f"bokehfit view {Path(path).name} ({where}{'; shapes ' + ','.join(shapes) if shapes else ''})"
    return {"json": comparison.to_json(command), "html": build_html(comparison, command), "tiles": _tiles(comparison),
            "summary": comparison.summary()}


def _worker_main(connection, path: str) -> None:  # pragma: no cover (runs in the worker process)
    while True:
        try:
            request = connection.recv()
        except EOFError:
            return
        if request is None:
            return
        labels, shapes = request

        def progress(*args):
            connection.send(("progress", [a if isinstance(a, (int, float, str)) else str(a) for a in args]))

        try:
            connection.send(("done", _run_compare(path, labels, shapes, progress)))
        except InputError as error:
            connection.send(("error", str(error)))
        except Exception as error:  # one line for the page; the server logs it too
            connection.send(("error", f"internal error: {type(error).__name__}: {error}"))


class _Worker:
    """One spawned process that runs compares on the photo, one at a time."""

    def __init__(self, path: str):
        context = multiprocessing.get_context("spawn")
        self.connection, child = context.Pipe()
        self.process = context.Process(target=_worker_main, args=(child, path), name="bokehfit-view-compare", daemon=True)
        self.process.start()
        child.close()

    def kill(self) -> None:
        if self.process.is_alive():
            self.process.kill()
        self.process.join(5)
        self.connection.close()


# --- what the page sends and gets -------------------------------------------------------------


def _finite(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"{where} must be a finite number (got {str(value)[:40]})")
    return float(value)


def refit_labels(body, width: int, height: int):
    """The refit's places and shapes from the page's JSON, checked; ``InputError`` names the first fault.

    ``{"discs": [{"center_xy": [x, y], "diameter_px": D}, ...], "shapes": [...]}``: at
    most ``MAX_REFIT_DISCS`` discs, each centre inside the photo, each diameter from
    1 px to the photo's long side; shapes (optional) among those ``compare --shapes`` knows.
    """
    from bokehfit.discs.labels import DiscLabels, LabelledDisc
    from bokehfit.fit.families import families_for

    if not isinstance(body, dict) or not isinstance(body.get("discs"), list):
        raise InputError('a refit takes {"discs": [{"center_xy": [x, y], "diameter_px": D}, ...], "shapes": [...]}')
    unknown = sorted(set(body) - {"discs", "shapes"})
    if unknown:
        raise InputError(f"a refit takes discs and shapes only (got {', '.join(k[:20] for k in unknown[:3])})")
    entries = body["discs"]
    if not entries:
        raise InputError("a refit needs at least one disc: pick some, or reset to the automatic choice")
    if len(entries) > MAX_REFIT_DISCS:
        raise InputError(f"a refit takes at most {MAX_REFIT_DISCS} discs (got {len(entries)})")
    discs = []
    for i, entry in enumerate(entries):
        where = f"disc {i + 1}"
        if not isinstance(entry, dict) or not isinstance(entry.get("center_xy"), list) or len(entry["center_xy"]) != 2:
            raise InputError(f'{where} must be {{"center_xy": [x, y], "diameter_px": D}}')
        x = _finite(entry["center_xy"][0], f"{where}'s x")
        y = _finite(entry["center_xy"][1], f"{where}'s y")
        diameter = _finite(entry.get("diameter_px"), f"{where}'s diameter_px")
        if not (0 <= x <= width - 1 and 0 <= y <= height - 1):
            raise InputError(f"{where}'s centre ({x:g}, {y:g}) lies outside the {width}×{height} photo")
        if not 1 <= diameter <= max(width, height):
            raise InputError(f"{where}'s diameter_px must be from 1 to {max(width, height)} (got {diameter:g})")
        # At the discs file's precision (LabelledDisc.to_json): the saved file then refits to the same answer.
        discs.append(LabelledDisc((round(x, 2), round(y, 2)), round(diameter, 2)))
    shapes = body.get("shapes")
    if shapes is not None:
        if not isinstance(shapes, list) or len(shapes) > MAX_REFIT_SHAPES or not all(isinstance(s, str) and 0 < len(s) <= 20 for s in shapes):
            raise InputError(f"shapes must be a list of at most {MAX_REFIT_SHAPES} shape names")
        shapes = shapes or None
        families_for(shapes)  # InputError naming the unknown ones
    return DiscLabels(tuple(discs), width=width, height=height), shapes


def shape_choices() -> list[str]:
    """The names the page offers for "shapes to try" (as ``compare --shapes`` takes them)."""
    from bokehfit.fit.families import FAMILIES

    return [family.name for family in FAMILIES]


def discs_file(labels, name: str, sha256: str, width: int, height: int) -> dict:
    """A discs file (the labels' format) of the page's picks, for ``compare --discs``."""
    return {"file": name, "sha256": sha256, "width": width, "height": height,
            "discs": [disc.to_json() for disc in labels.discs], "junk": [], "complete_within": [],
            "notes": "picked in `bokehfit view`"}


class PhotoSession:
    """The photo of ``bokehfit view PHOTO``: read once at start, and its compares.

    Raises ``InputError`` (one line) where the photo cannot be read.
    """

    def __init__(self, path, *, max_refit_s: float = MAX_REFIT_S):
        from bokehfit.io import load_photo

        self.path = Path(path)
        photo = load_photo(self.path)  # InputError for anything unreadable
        self.name = self.path.name
        self.height, self.width = photo.luminance.shape
        digest = hashlib.sha256()
        with open(self.path, "rb") as file:
            for block in iter(lambda: file.read(1 << 20), b""):
                digest.update(block)
        self.sha256 = digest.hexdigest()
        display = photo.display
        self.scale = min(1.0, MAX_DISPLAY_SIDE / max(self.width, self.height))
        if self.scale < 1.0:
            size = (max(1, round(self.width * self.scale)), max(1, round(self.height * self.scale)))
            display = cv2.resize(display, size, interpolation=cv2.INTER_AREA)
        ok, data = cv2.imencode(".jpg", cv2.cvtColor(display, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 92])
        if not ok:
            raise InputError(f"{self.name}: the display copy could not be encoded")
        self.display_jpeg = data.tobytes()
        del photo, display
        self.max_refit_s = float(max_refit_s)
        self.shapes = shape_choices()
        self._lock = threading.Lock()
        self._results: OrderedDict[int, dict] = OrderedDict()
        self._jobs: dict[int, dict] = {}
        self._next = 0
        self._worker = _Worker(str(self.path))
        self._running: int | None = None
        self._closed = False
        self.auto_job = self._submit(None, None)

    # --- jobs ---

    def info(self) -> dict:
        return {"file": self.name, "width": self.width, "height": self.height, "sha256": self.sha256,
                "display_scale": self.scale, "auto_job": self.auto_job, "shapes": self.shapes,
                "max_discs": MAX_REFIT_DISCS, "max_refit_s": self.max_refit_s}

    def _submit(self, labels, shapes) -> int:
        with self._lock:
            if self._closed:
                raise InputError("the server is stopping")
            if self._running is not None:
                raise InputError("a refit is running: wait for it or cancel it")
            job = self._next
            self._next += 1
            self._running = job
            self._jobs[job] = {"job": job, "state": "running", "stage": "start", "done": None, "total": None,
                               "started": time.monotonic(), "error": None}
            worker = self._worker
        threading.Thread(target=self._wait, args=(job, worker, labels, shapes), name="bokehfit-view-job", daemon=True).start()
        return job

    def refit(self, body) -> int:
        labels, shapes = refit_labels(body, self.width, self.height)
        return self._submit(labels, shapes)

    def _wait(self, job: int, worker: _Worker, labels, shapes) -> None:
        state = self._jobs[job]
        outcome = None
        try:
            worker.connection.send((labels, shapes))
            deadline = state["started"] + self.max_refit_s
            while outcome is None:
                left = deadline - time.monotonic()
                if left <= 0:
                    outcome = ("error", f"the refit took longer than {self.max_refit_s:g} s and was stopped")
                    self._restart(worker)
                    break
                if not worker.connection.poll(min(left, 0.5)):
                    if state["state"] == "cancelled":
                        return
                    continue
                kind, value = worker.connection.recv()
                if kind == "progress":
                    if value and isinstance(value[0], str):
                        state["stage"] = value[0]
                    elif len(value) == 2:
                        state["done"], state["total"] = value
                else:
                    outcome = (kind, value)
        except (EOFError, OSError, BrokenPipeError):
            if state["state"] == "cancelled":
                return
            outcome = ("error", "the compare stopped unexpectedly")
            self._restart(worker)
        with self._lock:
            if outcome[0] == "done":
                self._results[job] = outcome[1]
                while len(self._results) > MAX_RESULTS:
                    oldest = next(k for k in self._results if k != self.auto_job)
                    del self._results[oldest]
                state["state"] = "done"
            else:
                state["state"], state["error"] = "failed", outcome[1]
            state["elapsed_s"] = round(time.monotonic() - state["started"], 3)
            if self._running == job:
                self._running = None

    def _restart(self, worker: _Worker) -> None:
        worker.kill()
        with self._lock:
            if self._worker is worker and not self._closed:
                self._worker = _Worker(str(self.path))

    def cancel(self) -> dict:
        with self._lock:
            job = self._running
            if job is None:
                return {"cancelled": None}
            self._jobs[job]["state"] = "cancelled"
            self._jobs[job]["elapsed_s"] = round(time.monotonic() - self._jobs[job]["started"], 3)
            self._running = None
            worker = self._worker
        self._restart(worker)
        return {"cancelled": job}

    def status(self, job) -> dict:
        state = self._jobs.get(job) if isinstance(job, int) else None
        if state is None:
            raise InputError(f"no such refit: {str(job)[:20]}")
        answer = {k: v for k, v in state.items() if k != "started"}
        if state["state"] == "running":
            answer["elapsed_s"] = round(time.monotonic() - state["started"], 3)
        return answer

    def result(self, job) -> dict:
        """The finished compare of ``job``; ``InputError`` where it is unknown, running, failed or dropped."""
        self.status(job)
        result = self._results.get(job)
        if result is None:
            raise InputError(f"refit {job} has no result ({self._jobs[job]['state']})")
        return result

    def wait(self, job: int, timeout_s: float = 300.0) -> dict:
        """The status of ``job`` once it ends (for tests and the command line)."""
        end = time.monotonic() + timeout_s
        while self.status(job)["state"] == "running" and time.monotonic() < end:
            time.sleep(0.05)
        return self.status(job)

    def close(self) -> None:
        with self._lock:
            self._closed = True
            worker = self._worker
        try:
            worker.connection.send(None)
        except (OSError, BrokenPipeError):
            pass
        worker.kill()
