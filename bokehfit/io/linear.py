"""Decoded pixels to a :class:`Photo`: orientation, linear light, the display copy, progress.

The pixels a format reader decodes are oriented once (:func:`orient`) and linearised in blocks
of :data:`BLOCK_ROWS` rows (:func:`linearise_integer`; float and raw images through
:func:`display_from_linear` for their display), into arrays from :func:`photo_array`;
:func:`make_photo` freezes them into the :class:`Photo`.
"""

from __future__ import annotations

import math
import mmap
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bokehfit.io.colour import Encoding, srgb_decode, srgb_display_lut
from bokehfit.io.exif import Exif

__all__ = [
    "BLOCK_ROWS",
    "PLAIN_PAGES_BYTES",
    "PROGRESS_MIN_PIXELS",
    "Photo",
    "Progress",
    "display_from_linear",
    "displayed_size",
    "linearise_integer",
    "make_photo",
    "orient",
    "photo_array",
    "progress_for",
    "row_blocks",
]

#: ``progress=True`` shows a bar only for images larger than this (pixels).
PROGRESS_MIN_PIXELS = 8_000_000
#: Rows per block when linearising: keeps the float32 temporaries small.
BLOCK_ROWS = 64
#: Arrays from this size on are given ordinary pages, not transparent huge pages (:func:`photo_array`).
PLAIN_PAGES_BYTES = 8 << 20


@dataclass(frozen=True, eq=False)
class Photo:
    """A photo in linear light, as displayed (EXIF orientation applied).

    Attributes
    ----------
    path : Path
        The file read.
    width, height : int
        Size in pixels, as displayed.
    luminance : ndarray of shape (height, width), float32
        Linear light, 1.0 = the encoding's white (raw: the white level); the
        Y of the file's RGB space. Read-only.
    clipped : ndarray of shape (height, width), bool
        Pixels where a channel is at the encoding's maximum in the file
        (8-bit 255, 16-bit 65535; raw: a photosite at or above the white
        level, or next to one). Float TIFFs: the pixels with a NaN or
        ±Inf sample or one above :data:`~bokehfit.io.tiff.FLOAT_SAMPLE_MAX`.
        Read-only.
    display : ndarray of shape (height, width, 3), uint8
        RGB for overlays: the decoded 8-bit image; 16-bit files rounded to
        8 bits; float and raw files encoded with the sRGB curve (values
        above 1 clip). Read-only.
    raw : bool
        True for camera raw files.
    exif : Exif
        Camera and lens metadata.
    linearisation : str
        What was done to reach linear light, for people.
    colour_space : str
        ``"sRGB"``, ``"Adobe RGB (1998)"``, ``"Display P3"``, ``"ProPhoto RGB"``, ``"linear"``,
        ``"camera raw → sRGB primaries (linear)"``, ...
    notes : tuple of str
        One line each about what was done to read a file that was not clean: a damaged JPEG,
        a CMYK conversion, masked float samples, skipped metadata.
    display_decoding : ndarray of shape (256, 3), float32, or None
        Linear light of each 8-bit code of ``display``, per channel (the file's own curves, or
        sRGB's for the displays bokehfit encoded); None means sRGB. See :meth:`linear_rgb`.
    """

    path: Path
    width: int
    height: int
    luminance: np.ndarray = field(repr=False)
    clipped: np.ndarray = field(repr=False)
    display: np.ndarray = field(repr=False)
    raw: bool
    exif: Exif
    linearisation: str
    colour_space: str
    notes: tuple[str, ...] = ()
    display_decoding: np.ndarray | None = field(default=None, repr=False)

    def linear_rgb(self, rows: slice, cols: slice) -> np.ndarray:
        """Linear RGB (float32, (h, w, 3), 1.0 = white) of a window of the photo.

        Decoded from the 8-bit ``display`` on demand, a window at a time (the whole photo in
        float RGB would be 12 bytes a pixel): for measures in the colour channels of small
        regions, such as a disc's colours (:func:`bokehfit.fit.chromatic.measure_chromatic`).
        """
        table = self.display_decoding if self.display_decoding is not None else _srgb_decoding()
        codes = self.display[rows, cols]
        return np.stack([table[codes[..., c], c] for c in range(3)], axis=-1)

    def input_json(self) -> dict:
        """The ``input`` object of design.md §7 (plus ``colour_space``), in plain JSON types."""
        return {
            "path": str(self.path),
            "width": int(self.width),
            "height": int(self.height),
            "raw": bool(self.raw),
            "exif": self.exif.to_json(),
            "linearisation": self.linearisation,
            "colour_space": self.colour_space,
            "notes": list(self.notes),
        }


def _srgb_decoding() -> np.ndarray:
    """The linear value of every 8-bit sRGB code, per channel: (256, 3) float32."""
    return np.repeat(srgb_decode(np.arange(256) / 255.0).astype(np.float32)[:, None], 3, axis=1)


def make_photo(path, luminance, clipped, display, raw, exif, linearisation, colour_space, notes=(), decoding=None) -> Photo:
    height, width = luminance.shape
    return Photo(
        path=path,
        width=int(width),
        height=int(height),
        luminance=_frozen(luminance),
        clipped=_frozen(clipped),
        display=_frozen(display),
        raw=raw,
        exif=exif,
        linearisation=linearisation,
        colour_space=colour_space,
        notes=tuple(notes),
        display_decoding=decoding,
    )


def _frozen(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def photo_array(shape: tuple[int, ...], dtype) -> np.ndarray:
    """An empty array for the photo's full-size arrays (the decoded pixels, luminance, clipped mask).

    NumPy asks Linux for transparent huge pages for every large array; a process's first
    read of a large photo then waits while the kernel compacts memory into huge pages
    (a 24-MP JPEG read in 0.25–0.33 s, against 0.15 s on ordinary pages, measured in fresh
    processes on a 2-core machine). These arrays are written once, in order, and then read
    in windows, where huge pages save little: from ``PLAIN_PAGES_BYTES`` on they are mapped
    with ``MADV_NOHUGEPAGE`` (a private anonymous mapping that the array owns), where the
    system has it.
    """
    dtype = np.dtype(dtype)
    count = math.prod(shape)
    size = count * dtype.itemsize
    advisable = hasattr(mmap, "MADV_NOHUGEPAGE") and hasattr(mmap, "MAP_ANONYMOUS")
    if size < max(PLAIN_PAGES_BYTES, 1) or not advisable:
        return np.empty(shape, dtype=dtype)
    memory = mmap.mmap(-1, size, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    try:
        memory.madvise(mmap.MADV_NOHUGEPAGE)
    except OSError:
        pass  # the advice is only a hint
    return np.frombuffer(memory, dtype=dtype, count=count).reshape(shape)


# --------------------------------------------------------------------------------------
# Orientation
# --------------------------------------------------------------------------------------


def displayed_size(width: int, height: int, orientation: int) -> tuple[int, int]:
    return (height, width) if orientation in (5, 6, 7, 8) else (width, height)


def orient(image: np.ndarray, orientation: int) -> np.ndarray:
    """Apply an EXIF orientation (1..8) to an image of shape (H, W) or (H, W, C≤4)."""
    import cv2

    if orientation == 1:
        return image
    if image.dtype == np.bool_:
        return orient(image.view(np.uint8), orientation).view(np.bool_)
    if orientation == 2:
        return cv2.flip(image, 1)
    if orientation == 3:
        return cv2.rotate(image, cv2.ROTATE_180)
    if orientation == 4:
        return cv2.flip(image, 0)
    if orientation == 5:
        return cv2.transpose(image)
    if orientation == 6:
        return cv2.rotate(image, cv2.ROTATE_90_CLOCKWISE)
    if orientation == 7:
        return cv2.rotate(cv2.transpose(image), cv2.ROTATE_180)
    if orientation == 8:
        return cv2.rotate(image, cv2.ROTATE_90_COUNTERCLOCKWISE)
    return image


# --------------------------------------------------------------------------------------
# Progress
# --------------------------------------------------------------------------------------


class Progress:
    """A tqdm bar on stderr for big images, or nothing."""

    def __init__(self, name: str, pixels: int, steps: int, enabled: bool):
        self._bar = None
        if enabled and pixels > PROGRESS_MIN_PIXELS:
            from tqdm import tqdm

            self._bar = tqdm(total=steps, desc=f"loading {name}", unit="step", file=sys.stderr, leave=False)

    def step(self, what: str | None = None, n: int = 1) -> None:
        if self._bar is not None:
            if what:
                self._bar.set_postfix_str(what, refresh=False)
            self._bar.update(n)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None


def progress_for(name: str, width: int, height: int, orientation: int, enabled: bool) -> Progress:
    """A bar with a step for decoding, one per block of rows, and one for the display copy."""
    rows = displayed_size(width, height, orientation)[1]
    return Progress(name, width * height, 2 + len(row_blocks(rows)), enabled)


def row_blocks(height: int):
    return [(r0, min(r0 + BLOCK_ROWS, height)) for r0 in range(0, height, BLOCK_ROWS)]


# --------------------------------------------------------------------------------------
# Linearisation of decoded pixels
# --------------------------------------------------------------------------------------


def linearise_integer(pixels: np.ndarray, bits: int, order: str, encoding: Encoding, bar: Progress):
    """Luminance, clipped mask and 8-bit RGB display of an oriented uint8/uint16 image.

    ``pixels`` is (H, W) grey or (H, W, 3) in channel order ``order`` ("RGB" or "BGR"). An
    8-bit colour image becomes the display: its channels are put in RGB order in place.
    """
    import cv2

    height, width = pixels.shape[:2]
    top = 2**bits - 1
    luminance = photo_array((height, width), np.float32)
    clipped = photo_array((height, width), np.bool_)
    if pixels.ndim == 2:
        curve = np.ascontiguousarray(encoding.lut(bits)[:, 1])  # a grey image: the G curve, weight 1
        for r0, r1 in row_blocks(height):
            block = pixels[r0:r1]
            if bits == 8:
                luminance[r0:r1] = cv2.LUT(block, curve)
            else:
                np.take(curve, block, out=luminance[r0:r1])
            np.equal(block, top, out=clipped[r0:r1])
            bar.step("linearise")
        display8 = pixels if bits == 8 else cv2.convertScaleAbs(pixels, alpha=1.0 / 257.0)
        display = cv2.cvtColor(display8, cv2.COLOR_GRAY2RGB)
        bar.step("display")
        return luminance, clipped, display

    weighted = encoding.weighted_lut(bits)
    if order == "BGR":
        weighted = weighted[:, ::-1]
    weighted = np.ascontiguousarray(weighted, dtype=np.float32)
    lut3 = weighted.reshape(2**bits, 1, 3)
    ones = np.ones((1, 3), dtype=np.float32)
    columns = [np.ascontiguousarray(weighted[:, c]) for c in range(3)]
    for r0, r1 in row_blocks(height):
        block = pixels[r0:r1]
        out = luminance[r0:r1]
        if bits == 8:
            cv2.transform(cv2.LUT(block, lut3), ones, dst=out)
        else:
            np.take(columns[0], block[..., 0], out=out)
            out += np.take(columns[1], block[..., 1])
            out += np.take(columns[2], block[..., 2])
        # Clipped: some channel at the top code, i.e. not all three below it (one OpenCV pass).
        np.equal(cv2.inRange(block, (0, 0, 0), (top - 1,) * 3), 0, out=clipped[r0:r1])
        bar.step("linearise")
    # The display is the decoded image itself, not a copy of it: its channels are swapped in
    # place, a block at a time (OpenCV copies a whole source that is also the destination).
    display = np.ascontiguousarray(pixels if bits == 8 else cv2.convertScaleAbs(pixels, alpha=1.0 / 257.0))
    if order == "BGR":
        for r0, r1 in row_blocks(height):
            cv2.cvtColor(display[r0:r1], cv2.COLOR_BGR2RGB, dst=display[r0:r1])
    bar.step("display")
    return luminance, clipped, display


def display_from_linear(rgb: np.ndarray, scale: float, bar: Progress | None = None) -> np.ndarray:
    """sRGB-encoded uint8 RGB of a linear image (uint16 or float32; ``scale`` maps it to [0, 1])."""
    table = srgb_display_lut()
    height = rgb.shape[0]
    display = np.empty(rgb.shape[:2] + (3,), dtype=np.uint8)
    for r0, r1 in row_blocks(height):
        block = rgb[r0:r1]
        if block.dtype == np.uint16 and scale == 1.0 / 65535.0:
            index = block
        else:
            index = np.clip(block * np.float32(scale * 65535.0) + np.float32(0.5), 0.0, 65535.0).astype(np.uint16)
        if index.ndim == 2:
            index = index[..., None]
        display[r0:r1] = np.take(table, index)
    return display
