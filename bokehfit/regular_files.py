"""Open a file for reading only if it is a regular file, and say what a file is in words.

Every file bokehfit reads without knowing what it is goes through :func:`open_regular`
(an output it may replace, a list of photos, a photo it hashes). The file is opened
with ``O_NONBLOCK`` after a ``stat``: a path naming a FIFO, a device or a socket is
refused without being read (opening a FIFO to read would wait for a writer forever).
"""

from __future__ import annotations

import errno
import os
import stat

__all__ = ["file_kind", "open_regular"]


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
