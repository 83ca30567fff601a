"""bokehfit's mark on its outputs: one recogniser and one stamp per format, and :func:`is_bokehfit_output`.

An existing file is replaced only if it is one of bokehfit's own outputs
(:mod:`bokehfit.output_paths` refuses any other). Every file bokehfit writes carries a
mark, and :func:`is_bokehfit_output` looks for it (the writers of :mod:`bokehfit.outputs`
add it, through :func:`add_mark`, or write it themselves):

========  =====================================================================
``.json``  a ``"bokehfit_version"`` key in the first 64 KiB (every JSON output has one)
``.html``  ``<meta name="generator" content="bokehfit VERSION">`` in the first 64 KiB
``.png``   a ``tEXt`` chunk ``Software`` = ``bokehfit VERSION`` before the image data
``.jpg``   a comment (``COM``) segment ``bokehfit VERSION`` before the image data
``.npy``   ``# bokehfit VERSION`` in the header's padding, a comment to ``numpy.load``
``.exr``   a string attribute ``software`` = ``bokehfit VERSION`` in the header
``.parquet``  a ``bokehfit_version`` key in the footer's key-value metadata (the survey's export)
========  =====================================================================

Only regular files are ever opened to look for the mark
(:func:`bokehfit.regular_files.open_regular`).
"""

from __future__ import annotations

import os
import re
import struct
import zlib
from collections.abc import Callable
from pathlib import Path

from bokehfit import __version__
from bokehfit.regular_files import open_regular

__all__ = ["GENERATOR", "HTML_GENERATOR_META", "add_mark", "is_bokehfit_output"]

#: The mark of bokehfit's outputs (the program and its version).
GENERATOR = f"bokehfit {__version__}"

#: The element that marks an HTML page as bokehfit's; added to every ``.html`` written by bokehfit.
HTML_GENERATOR_META = f'<meta name="generator" content="{GENERATOR}">'

#: How much of a file is read to find the mark.
_HEAD_BYTES = 1 << 16

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_NPY_MAGIC = b"\x93NUMPY"
_EXR_MAGIC = b"\x76\x2f\x31\x01"


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


def add_mark(path: str | os.PathLike, data: bytes) -> bytes:
    """``data`` with bokehfit's mark added, where the format of ``path`` (by its suffix) has a stamp here.

    Formats without one (JSON, OpenEXR, Parquet) carry the mark their writer gives them.
    """
    stamp = _STAMPS.get(Path(path).suffix.lower())
    return stamp(bytes(data)) if stamp else bytes(data)
