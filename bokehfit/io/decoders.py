"""The decoders, called quietly: what they print becomes a note of the photo or its ``InputError``.

libjpeg, libpng and LibRaw print to file descriptor 2, tifffile and rawpy log through Python's
logging: :func:`library_messages`, :func:`quietly` and :func:`imdecode` keep that text off the
terminal and hand it back, for a one-line note (:func:`damage_note`) or error of our own.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from bokehfit.io.linear import BLOCK_ROWS, Photo, photo_array

__all__ = ["damage_note", "imdecode", "library_messages", "quietly", "short"]

#: Most text kept from a decoder's messages in a note.
_MESSAGE_MAX_CHARS = 120


@contextlib.contextmanager
def library_messages():
    """Collect what C libraries write to file descriptor 2 meanwhile, instead of showing it.

    libjpeg prints its warnings ("Corrupt JPEG data: premature end of data segment") with
    ``fprintf(stderr, ...)``, which no Python or OpenCV setting reaches. The lines are
    yielded as a list, filled when the block ends, for a one-line note of our own.
    """
    lines: list[str] = []
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no descriptor 2 to redirect: let the library print
        yield lines
        return
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            text = sink.read(1 << 16).decode("utf-8", "replace")
            lines.extend(line.strip() for line in text.splitlines() if line.strip())


class _LogLines(logging.Handler):
    """A logging handler that keeps each record's message."""

    def __init__(self, lines: list[str]):
        super().__init__(logging.DEBUG)
        self.lines = lines

    def emit(self, record):
        with contextlib.suppress(Exception):
            self.lines.append(record.getMessage())


#: Python loggers of the decoders bokehfit calls, whose records are kept off the terminal like C libraries' text.
_DECODER_LOGGERS = ("tifffile", "rawpy", "imagecodecs")


def quietly(path: Path, load, *args) -> Photo:
    """``load(*args)`` with what the decoders print (LibRaw on file descriptor 2, tifffile through logging) captured.

    A damaged TIFF or raw file makes LibRaw and tifffile print lines of their own; they
    become one note of the photo (``Photo.notes``), or, where the file is refused, the
    ``InputError`` alone is shown, never the libraries' text.
    """
    logged: list[str] = []
    handler = _LogLines(logged)
    loggers = [logging.getLogger(name) for name in _DECODER_LOGGERS]
    states = [(logger.propagate, logger.level) for logger in loggers]
    for logger in loggers:
        logger.addHandler(handler)
        logger.propagate = False
    try:
        with library_messages() as printed:
            photo = load(*args)
    finally:
        for logger, (propagate, level) in zip(loggers, states):
            logger.removeHandler(handler)
            logger.propagate = propagate
    messages = [" ".join(m.split()) for m in logged + printed if m.strip()]
    if not messages:
        return photo
    said = messages[0] if len(messages[0]) <= _MESSAGE_MAX_CHARS else messages[0][: _MESSAGE_MAX_CHARS - 3] + "..."
    more = f" (+{len(messages) - 1} more)" if len(messages) > 1 else ""
    note = f"{path.name}: the decoder warned ({said}{more}); the image decoded in full"
    return replace(photo, notes=(*photo.notes, note))


def imdecode(data: bytes, path: Path | None = None, shape: tuple[int, ...] | None = None):
    """``cv2.imdecode`` as stored (no orientation, native depth), and the decoder's messages.

    libjpeg/libpng/libtiff complaints would go to stderr, through OpenCV's logger or the
    libraries' own ``fprintf``; they are returned instead, for our own one-line note or
    ``InputError``. The log level is restored afterwards.

    With ``path`` and the ``shape`` its header gives (8-bit samples), the file is decoded
    straight into an array of that shape (``cv2.imread`` with ``dst``): ``cv2.imdecode``
    hands its result over as a copy, twice the image's memory at the peak. Where that
    read fails or cannot be tried (a name OpenCV cannot open or take), ``data`` is decoded
    instead.
    """
    import cv2

    flags = cv2.IMREAD_UNCHANGED | cv2.IMREAD_IGNORE_ORIENTATION
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    pixels = None
    try:
        name = os.fspath(path) if path is not None and shape is not None else None
        if name is not None and _utf8(name):  # OpenCV's bindings crash on a name that is not valid text
            with library_messages() as messages:
                try:
                    pixels = cv2.imread(name, photo_array(shape, np.uint8), flags)
                except cv2.error:
                    pixels = None
            if pixels is not None and pixels.size:
                return pixels, messages
        with library_messages() as messages:
            try:
                pixels = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
            except cv2.error:
                pixels = None
    finally:
        cv2.utils.logging.setLogLevel(level)
    return pixels, messages


def _utf8(name: str) -> bool:
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:  # undecodable bytes of the file system's name, kept as surrogates
        return False
    return True


def _fill_start_row(pixels: np.ndarray) -> int:
    """First row of the flat fill at the bottom of an image (its height if there is none).

    Where libjpeg runs out of data it fills the rest of the image with one flat colour
    (grey, code 128); rows that are wholly that colour, up to the bottom, are the fill.
    """
    height = pixels.shape[0]
    fill = pixels[-1, 0]
    for r1 in range(height, 0, -BLOCK_ROWS):
        r0 = max(0, r1 - BLOCK_ROWS)
        block = pixels[r0:r1].reshape(r1 - r0, -1, *pixels.shape[2:3])
        flat = np.all(block == fill, axis=tuple(range(1, block.ndim)))
        if not flat.all():
            return r0 + int(len(flat) - np.argmin(flat[::-1]))
    return 0


def damage_note(name: str, kind: str, pixels: np.ndarray, messages: list[str]) -> str:
    """One line: the file is damaged, what the decoder said, and which rows were decoded."""
    said = " ".join(messages[0].split())
    if len(said) > _MESSAGE_MAX_CHARS:
        said = said[: _MESSAGE_MAX_CHARS - 3] + "..."
    more = f" (+{len(messages) - 1} more)" if len(messages) > 1 else ""
    height = pixels.shape[0]
    start = _fill_start_row(pixels)
    if start < height:
        read = f"rows 0–{start - 1} of {height} decoded (as stored), the rest is flat fill" if start else "nothing decoded"
    else:
        read = f"all {height} rows decoded, but parts may be wrong"
    return f"{name} is a damaged {kind} file ({said}{more}): {read}; re-export it if you can"


def short(error: Exception) -> str:
    text = " ".join(str(error).split()) or type(error).__name__
    return text if len(text) <= 120 else text[:117] + "..."
