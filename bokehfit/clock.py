"""Seconds by step of one piece of work (the fit's steps, the disc search's), for the timings the results report."""

from __future__ import annotations

import time

__all__ = ["Clock"]


class Clock:
    """Seconds by step (perf_counter), for ``ApertureFit.timing_s`` and ``DiscSearch.timing_s``.

    Calling it with a step's name adds the time since the last call (or since the clock was made)
    to that step; :meth:`elapsed` is the time since the clock was made.
    """

    def __init__(self) -> None:
        self.start = time.perf_counter()
        self._last = self.start
        self.timing: dict[str, float] = {}

    def __call__(self, step: str) -> None:
        now = time.perf_counter()
        self.timing[step] = self.timing.get(step, 0.0) + now - self._last
        self._last = now

    def elapsed(self) -> float:
        return time.perf_counter() - self.start
