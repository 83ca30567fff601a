"""The console's stdout when its reader leaves early (``bokehfit compare photo.jpg | head -1``).

A closed pipe makes the next print raise ``BrokenPipeError``. A run that has found its answer
should still write every file it was asked for (the JSON and the HTML report are written after
the summary is printed): :func:`reader_may_leave` sends whatever is printed after the reader has
gone to the null device, so the run goes on and ends with its own exit code.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator

__all__ = ["reader_may_leave", "ReaderMayLeave"]


class ReaderMayLeave:
    """A text stream that, once its reader has closed the pipe, writes to the null device instead.

    Every other attribute is the wrapped stream's. ``reader_left`` tells whether it happened.
    """

    def __init__(self, stream):
        self._stream = stream
        self.reader_left = False

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._to_null_device()
            return self._stream.write(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._to_null_device()
            self._stream.flush()

    def _to_null_device(self) -> None:
        """The stream's file descriptor made the null device's, so that its buffer and what follows go there."""
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, self._stream.fileno())
        finally:
            os.close(null)
        self.reader_left = True

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


@contextlib.contextmanager
def reader_may_leave() -> Iterator[ReaderMayLeave | None]:
    """``sys.stdout`` wrapped in :class:`ReaderMayLeave` while the block runs, restored after it.

    Yields None, and wraps nothing, where stdout has no file descriptor (a test's captured stream).
    """
    stream = sys.stdout
    try:
        stream.fileno()
    except (AttributeError, OSError, ValueError):
        yield None
        return
    guard = ReaderMayLeave(stream)
    sys.stdout = guard
    try:
        yield guard
    finally:
        if sys.stdout is guard:
            sys.stdout = stream
        with contextlib.suppress(OSError):
            guard.flush()
