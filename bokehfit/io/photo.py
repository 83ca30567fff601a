"""Read a photo into float32 linear light, with its EXIF.

:func:`load_photo` reads JPEG, PNG, TIFF (8/16-bit and float) and camera raw
files (through LibRaw) and returns a :class:`Photo`: the luminance in linear
light, a mask of clipped pixels, an 8-bit RGB copy for overlays, and what the
metadata says about camera and lens. Everything is as displayed: the EXIF
orientation is applied once, to the decoded pixels, so that luminance,
clipped mask and display always agree.

The file's header is read first: an image that is too small, too large
(``max_pixels``), truncated or not an image at all is refused with an
:class:`~bokehfit.errors.InputError` before anything is decoded. The input
file is only ever read.

Hostile and damaged files
-------------------------
- Only a regular file is read, of at most :data:`MAX_FILE_BYTES` (a FIFO, a
  device or a link to one is refused unopened).
- Every chunk and segment length is checked against the file's size before
  it is read; metadata larger than :data:`METADATA_MAX_BYTES` (XMP:
  :data:`~bokehfit.io.xmp.XMP_MAX_BYTES`), stored or after decompression,
  is skipped with a note, never inflated in full; all of a PNG's metadata
  chunks together inflate to at most :data:`METADATA_INFLATE_BUDGET_BYTES`
  (one ICC profile and one XMP packet are read; more are skipped, counted).
- The size a header claims is weighed against the bytes that must hold it,
  before decoding: at most :data:`JPEG_MAX_PIXELS_PER_BYTE` pixels a byte of
  JPEG, :data:`DEFLATE_MAX_RATIO` bytes a byte of PNG image data, and each TIFF
  compression's largest ratio; a file that claims more is truncated or crafted.
- What LibRaw and tifffile print about a damaged file (on file descriptor 2,
  through logging) is captured: a note where the file is read, nothing where
  it is refused with its one-line error.
- A JPEG whose image data is corrupt (libjpeg's "Corrupt JPEG data" warnings)
  is read, not refused: the decoder's messages are kept off the terminal and
  ``Photo.notes`` says in one line that the file is damaged and which rows
  were decoded (libjpeg fills what it could not decode with flat grey).
  Damaged PNG image data is refused (libpng stops at the first error); libpng's
  warnings about other chunks become a note.
- CMYK and YCCK JPEGs are converted to sRGB by Pillow (Adobe's inverted CMYK
  included): through littleCMS with the embedded ICC profile when there is a
  usable one, else naively, ``R = (1 − C)(1 − K)`` and so on; a note says which.
- Float TIFFs: NaN and ±Inf samples are masked (their pixels are filled from
  their neighbours and marked in ``clipped``, so that no disc containing them
  is used); a file whose robust white point (99.9th percentile of the
  luminance) exceeds :data:`FLOAT_WHITE_MAX` is taken to be in other units and
  scaled so that it is 1; samples still above :data:`FLOAT_SAMPLE_MAX` are
  clamped there and marked in ``clipped``. Each of these is counted in a note.

Speed and memory: 8-bit files decode with OpenCV (libjpeg-turbo, libpng) and
are linearised with a 256-entry table per channel (``cv2.LUT``) and one weighted
channel sum (``cv2.transform``), in blocks of rows, all in float32. A JPEG is
decoded straight into the array that then becomes the display (its channels put
in RGB order in place, block by block), so a photo holds 8 bytes a pixel
(luminance 4, display 3, clipped mask 1) and loading one peaks little above
that: a 24-megapixel JPEG takes about 1.5 times a bare ``cv2.imread`` of it.

Where the code is: this module dispatches by format (:func:`load_photo`); :mod:`~bokehfit.io.jpeg`,
:mod:`~bokehfit.io.png`, :mod:`~bokehfit.io.tiff` and :mod:`~bokehfit.io.raw` read one format each;
:mod:`~bokehfit.io.files` checks the file and the size its header claims,
:mod:`~bokehfit.io.decoders` keeps the decoders' messages off the terminal, and
:mod:`~bokehfit.io.linear` turns decoded pixels into the :class:`Photo`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from bokehfit.errors import InputError
from bokehfit.io.decoders import quietly
from bokehfit.io.files import (
    MAX_FILE_BYTES,
    MAX_PIXELS,
    METADATA_MAX_BYTES,
    MIN_SIDE_PX,
    RAW_SUFFIXES,
    check_file,
    read_file,
)
from bokehfit.io.jpeg import JPEG_MAX_PIXELS_PER_BYTE, load_jpeg
from bokehfit.io.linear import PROGRESS_MIN_PIXELS, Photo
from bokehfit.io.png import DEFLATE_MAX_RATIO, METADATA_INFLATE_BUDGET_BYTES, PNG_SIGNATURE, load_png
from bokehfit.io.raw import load_raw
from bokehfit.io.tiff import FLOAT_SAMPLE_MAX, FLOAT_WHITE_MAX, load_tiff

__all__ = [
    "Photo",
    "load_photo",
    "FLOAT_SAMPLE_MAX",
    "FLOAT_WHITE_MAX",
    "METADATA_MAX_BYTES",
    "METADATA_INFLATE_BUDGET_BYTES",
    "JPEG_MAX_PIXELS_PER_BYTE",
    "DEFLATE_MAX_RATIO",
    "MIN_SIDE_PX",
    "MAX_PIXELS",
    "MAX_FILE_BYTES",
    "PROGRESS_MIN_PIXELS",
    "RAW_SUFFIXES",
]

# Magic numbers of formats people may try, for a helpful refusal.
_OTHER_FORMATS = (
    (b"GIF87a", "GIF"),
    (b"GIF89a", "GIF"),
    (b"BM", "BMP"),
    (b"\x76\x2f\x31\x01", "OpenEXR"),
    (b"8BPS", "Photoshop PSD"),
    (b"%PDF", "PDF"),
    (b"\x00\x00\x00\x0cjP  ", "JPEG 2000"),
    (b"\xff\x0a", "JPEG XL"),
    (b"\x00\x00\x00\x0cJXL ", "JPEG XL"),
)


def load_photo(path: str | os.PathLike, *, max_pixels: int = MAX_PIXELS, progress: bool = False) -> Photo:
    """Read a JPEG, PNG, TIFF or camera raw file into linear light.

    Parameters
    ----------
    path : str or path-like
        The photo. Its format is taken from its first bytes (raw files: from
        the suffix, see :data:`RAW_SUFFIXES`, or a TIFF's DNGVersion tag).
    max_pixels : int, optional
        Refuse images with more pixels than this, before decoding.
    progress : bool, optional
        Show a progress bar on stderr for images over
        :data:`PROGRESS_MIN_PIXELS`.

    Returns
    -------
    Photo

    Raises
    ------
    InputError
        The file is missing, unreadable, not a supported image, damaged,
        smaller than :data:`MIN_SIDE_PX` a side or larger than ``max_pixels``.

    Notes
    -----
    8/16-bit files: each channel is decoded with the transfer curve of the
    colour space found by :func:`bokehfit.io.colour.detect_encoding`, and
    ``Y = w · (R, G, B)`` with that space's weights. Float TIFFs are taken as
    linear with sRGB primaries (negative values clamped to 0; NaN, Inf and
    absurdly large values handled as the module docstring says). CMYK JPEGs are
    converted to sRGB first. What was done to a file that was not clean (a
    damaged JPEG read as far as it goes, skipped metadata) is in
    ``Photo.notes``, one line each. Raw files are
    developed by LibRaw without gamma, brightening or a lowered maximum, with
    the camera's white balance, into linear sRGB primaries; 1.0 is the white
    level.

    Examples
    --------
    >>> photo = load_photo("glints.jpg")  # doctest: +SKIP
    >>> photo.luminance.dtype, photo.colour_space  # doctest: +SKIP
    (dtype('float32'), 'sRGB')
    """
    try:
        path = Path(path)
    except TypeError:
        raise InputError(f"photo path must be a file name (got {path!r})") from None
    if isinstance(max_pixels, bool) or not isinstance(max_pixels, (int, np.integer)) or max_pixels < 1:
        raise InputError(f"max_pixels must be a positive whole number (got {max_pixels!r})")
    check_file(path)
    if path.suffix.lower() in RAW_SUFFIXES:
        return quietly(path, load_raw, path, int(max_pixels), progress)
    data = read_file(path)
    head = data[:16]
    if head.startswith(b"\xff\xd8\xff"):
        return load_jpeg(path, data, int(max_pixels), progress)
    if head.startswith(PNG_SIGNATURE):
        return load_png(path, data, int(max_pixels), progress)
    if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return quietly(path, load_tiff, path, data, int(max_pixels), progress)
    for magic, name in _OTHER_FORMATS:
        if head.startswith(magic):
            raise InputError(f"{path.name} is a {name} file; bokehfit reads JPEG, PNG, TIFF and camera raw: convert it")
    if head[4:8] == b"ftyp":
        raise InputError(
            f"{path.name} is a HEIF/AVIF/MP4-family file; bokehfit reads JPEG, PNG, TIFF and camera raw: convert it"
        )
    if head[:4] == b"RIFF" and data[8:12] == b"WEBP":
        raise InputError(f"{path.name} is a WebP file; bokehfit reads JPEG, PNG, TIFF and camera raw: convert it")
    raise InputError(
        f"{path.name} is not a JPEG, PNG, TIFF or camera raw file (it starts with {bytes(head[:8])!r}); check the file"
    )
