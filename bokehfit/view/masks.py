"""The masks uploaded to the viewer (``POST /mask``): their PNG's pixels read, their tables kept by digest.

A mask is the custom ``mask`` aperture of design.md §3b, sent as an image file
(PNG) of transmission. The upload keeps only the PNG's pixel chunks
(:func:`png_pixels_only`), the table is built by the command line's code
(:func:`~bokehfit.apertures.mask.decode_mask`, the same code as ``--mask``),
and the server keeps the last ``MAX_MASKS`` by digest (:class:`MaskStore`),
whose CDF tables the page fetches from ``/mask_table`` and uploads as they are.
"""

from __future__ import annotations

import struct
import threading
import zlib

from bokehfit.apertures import MaskTable
from bokehfit.apertures.mask import decode_mask
from bokehfit.errors import InputError
from bokehfit.view.bodies import brief

__all__ = ["MAX_MASKS", "MAX_PNG_CHUNKS", "MaskStore", "mask_upload", "png_pixels_only"]

#: Uploaded masks the server keeps (the most recently used); an older one must be uploaded again.
MAX_MASKS = 8


class MaskStore:
    """The masks uploaded to one server (``POST /mask``), by digest: the last ``capacity`` used, thread-safe."""

    def __init__(self, capacity: int = MAX_MASKS):
        self.capacity = capacity
        self._tables: dict[str, MaskTable] = {}
        self._bytes: dict[str, bytes] = {}
        self._lock = threading.Lock()

    def add(self, table: MaskTable) -> str:
        """Keep ``table`` (dropping the least recently used beyond capacity); returns its digest."""
        with self._lock:
            self._tables.pop(table.digest, None)
            self._tables[table.digest] = table
            while len(self._tables) > self.capacity:
                self._bytes.pop(self._tables.pop(next(iter(self._tables))).digest, None)
        return table.digest

    def gpu_bytes(self, digest) -> bytes:
        """``GET /mask_table``: the table of ``digest`` as little-endian float32, made once and shared by every answer."""
        table = self.get(digest)
        with self._lock:
            data = self._bytes.get(table.digest)
        if data is None:
            data = table.gpu_table().astype("<f4").tobytes()
            with self._lock:
                if table.digest in self._tables:
                    self._bytes[table.digest] = data
        return data

    def get(self, digest) -> MaskTable:
        """The table of ``digest``; ``InputError`` where none was uploaded (or it was dropped)."""
        with self._lock:
            table = self._tables.pop(digest, None) if isinstance(digest, str) else None
            if table is None:
                raise InputError(f"mask must name an uploaded mask (got {brief(digest)}): upload the PNG again (POST /mask)")
            self._tables[digest] = table  # most recently used
            return table


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: The PNG chunks that make a mask's pixels (PNG 3rd edition §5.6; tRNS for palette
#: images); the others (profiles, texts, animation) are dropped unread.
_PNG_PIXEL_CHUNKS = (b"IHDR", b"PLTE", b"tRNS", b"IDAT", b"IEND")
#: Most chunks in an uploaded PNG (an encoder writes a few dozen).
MAX_PNG_CHUNKS = 100_000


def png_pixels_only(data: bytes | bytearray, name: str = "mask", source: str = "the uploaded file") -> bytes:
    """The PNG ``data`` with only the chunks that make its pixels: one pass over the chunk list.

    A PNG's compressed ancillary chunks (iCCP, zTXt, iTXt) are inflated one by
    one when it is opened; thousands of them in a few MiB cost seconds each
    time. A mask needs none of them, so they go before the image is decoded.
    """
    unreadable = f"{name} must be a readable image file (PNG) (got {source}: "
    if bytes(data[:8]) != _PNG_SIGNATURE:
        raise InputError(unreadable + "not a PNG)")
    view = memoryview(data)
    kept, offset, chunks = [view[:8]], 8, 0
    while offset + 12 <= len(data):
        length = int.from_bytes(view[offset : offset + 4], "big")
        kind = bytes(view[offset + 4 : offset + 8])
        end = offset + 12 + length
        if end > len(data):
            raise InputError(unreadable + f"chunk {kind!r} runs past the end of the file)")
        chunks += 1
        if chunks > MAX_PNG_CHUNKS:
            raise InputError(unreadable + f"more than {MAX_PNG_CHUNKS} chunks)")
        if kind in _PNG_PIXEL_CHUNKS:
            kept.append(view[offset:end])
        offset = end
        if kind == b"IEND":
            break
    return b"".join(kept)


def mask_upload(body: bytes | bytearray, store: MaskStore) -> dict:
    """``POST /mask``: the table of the uploaded PNG, kept in ``store``; its digest, size and tables' URL.

    The image is read by the command line's code (:func:`~bokehfit.apertures.mask.decode_mask`)
    from its pixel chunks (:func:`png_pixels_only`); a decoder's failure on a damaged file is one line.
    """
    pixels = png_pixels_only(body)
    try:
        table = decode_mask(pixels, source="the uploaded file")
    except InputError:
        raise
    except (ValueError, SyntaxError, EOFError, MemoryError, struct.error, zlib.error) as error:  # Pillow on damaged data
        raise InputError(f"mask must be a readable image file (PNG) (got the uploaded file: {brief(str(error), 120)})") from None
    store.add(table)
    height, width = table.shape
    return {
        "mask": table.digest,
        "width": width,
        "height": height,
        "describe": table.describe(),
        "table_url": f"/mask_table?mask={table.digest}",
        "table_floats": int(table.gpu_table().size),
    }

