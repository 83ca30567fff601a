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
  :data:`~bokehfit.io.exif.XMP_MAX_BYTES`), stored or after decompression,
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
"""

from __future__ import annotations

import contextlib
import logging
import math
import mmap
import os
import struct
import sys
import tempfile
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from bokehfit.errors import InputError
from bokehfit.io.colour import (
    Encoding,
    detect_encoding,
    icc_description,
    linear_encoding,
    luminance_weights,
    named_encoding,
    srgb_decode,
    srgb_display_lut,
)
from bokehfit.io.exif import (
    XMP_MAX_BYTES,
    Exif,
    ExifTags,
    build_exif,
    read_exif_tags,
    read_file_tags,
    xmp_property,
)

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

#: Smallest accepted side of an image, in pixels.
MIN_SIDE_PX = 16
#: Largest accepted image, in pixels (width × height), unless ``max_pixels`` says otherwise.
MAX_PIXELS = 250_000_000
#: Largest photo file read, bytes: MAX_PIXELS of uncompressed RGBA float32 (16 bytes a pixel, the
#: largest sample layout read) and 64 MiB of metadata. A larger file is no photo bokehfit could use.
MAX_FILE_BYTES = MAX_PIXELS * 16 + (64 << 20)
#: ``progress=True`` shows a bar only for images larger than this (pixels).
PROGRESS_MIN_PIXELS = 8_000_000
#: File suffixes read as camera raw through LibRaw (lower case, with the dot).
RAW_SUFFIXES = frozenset(
    ".dng .nef .nrw .cr2 .cr3 .crw .arw .srf .sr2 .raf .orf .rw2 .pef .srw .x3f .3fr .iiq .erf .mef .mos .mrw"
    " .kdc .dcr .rwl .raw".split()
)
#: Rows per block when linearising: keeps the float32 temporaries small.
_BLOCK_ROWS = 64
#: Largest metadata block read (bytes, after decompression): an ICC profile or an EXIF block.
#: Real ones are a few kB to a few hundred kB; larger ones are skipped with a note.
METADATA_MAX_BYTES = 4 << 20
#: Most bytes inflated from all the metadata chunks of one file together (ICC profile, XMP): a file of
#: ten thousand compressed chunks costs no more than a few legitimate ones; past it, the rest is skipped.
METADATA_INFLATE_BUDGET_BYTES = 4 * METADATA_MAX_BYTES
#: Most pixels a Huffman-coded JPEG may claim per byte of the file. Every 8×8 block of the luminance
#: is coded in the first (DC) scan with at least one bit (Huffman codes are 1 to 16 bits long, ITU T.81
#: Annex C), so a file of B bytes holds at most 8·B blocks, 512·B pixels, whatever the image; lossless
#: JPEG spends a bit a pixel at least. Arithmetic coding (SOF9–SOF15, rare: no camera writes it) can
#: code a flat block in less than a bit, so for it the bound is not a theorem but a photo's: a 24-MP
#: frame would have to fit in 47 kB, which only a nearly all-black frame does, and a refused file is
#: told to re-encode with Huffman coding. Without the bound, a 143 kB file claiming 15811² pixels
#: decoded for 40–117 s at 2.4 GB.
JPEG_MAX_PIXELS_PER_BYTE = 512
#: Start-of-frame markers of arithmetic-coded JPEGs (ITU T.81 Table B.1).
_ARITHMETIC_SOF = frozenset({0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF})
#: Largest ratio of deflate: one length code (≥ 1 bit) and one distance code (≥ 1 bit) repeat at
#: most 258 bytes, so 2 bits give at most 258 bytes (RFC 1951 §3.2.5): 1032 bytes per byte.
DEFLATE_MAX_RATIO = 1032
#: Float TIFFs whose robust white point (99.9th percentile of the luminance) is above this are
#: taken to be in other units and scaled so that it is 1 (linear float files put white at 1.0;
#: HDR merges reach a few hundred).
FLOAT_WHITE_MAX = 1e4
#: Float samples above this, after any scaling, are clamped to it and marked clipped: beyond
#: it, squares of the values overflow float32 (bokehfit.discs.MAX_LUMINANCE is the same bound).
FLOAT_SAMPLE_MAX = 1e6
#: Most text kept from a decoder's messages in a note.
_MESSAGE_MAX_CHARS = 120

_XMP_JPEG = b"http://ns.adobe.com/xap/1.0/\x00"
_ICC_JPEG = b"ICC_PROFILE\x00"
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
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
        ±Inf sample or one above :data:`FLOAT_SAMPLE_MAX`. Read-only.
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


# --------------------------------------------------------------------------------------
# Entry point
# --------------------------------------------------------------------------------------


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
    _check_file(path)
    if path.suffix.lower() in RAW_SUFFIXES:
        return _quietly(path, _load_raw, path, int(max_pixels), progress)
    data = _read(path)
    head = data[:16]
    if head.startswith(b"\xff\xd8\xff"):
        return _load_jpeg(path, data, int(max_pixels), progress)
    if head.startswith(_PNG_SIGNATURE):
        return _load_png(path, data, int(max_pixels), progress)
    if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return _quietly(path, _load_tiff, path, data, int(max_pixels), progress)
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


def _check_file(path: Path) -> None:
    try:
        if not path.exists():
            raise InputError(f"{path} does not exist; check the file name")
        if path.is_dir():
            raise InputError(f"{path} is a folder, not a photo; name a file in it")
        if not path.is_file():
            raise InputError(f"{path} is not a regular file; name a photo file")
        size = path.stat().st_size
        if size == 0:
            raise InputError(f"{path} is empty (0 bytes); check the file")
        if size > MAX_FILE_BYTES:
            raise InputError(f"{path} holds {size / 2**30:.3g} GiB, more than a photo of {MAX_PIXELS / 1e6:g} megapixels"
                             f" can (at most {MAX_FILE_BYTES / 2**30:.3g} GiB); check the file")
    except OSError as error:
        raise InputError(f"cannot read {path}: {error.strerror or error}") from None


def _read(path: Path) -> bytes:
    """The file's bytes; only a regular file is opened (non-blocking, so a FIFO put there since the check can't stall)."""
    from bokehfit.outputs import open_regular

    try:
        with open_regular(path) as file:
            data = file.read(MAX_FILE_BYTES + 1)
    except OSError as error:
        raise InputError(f"cannot read {path}: {error.strerror or error}") from None
    if len(data) > MAX_FILE_BYTES:
        raise InputError(f"{path} is larger than a photo can be ({MAX_FILE_BYTES / 2**30:.3g} GiB); check the file")
    return data


def _check_size(name: str, width: int, height: int, max_pixels: int) -> None:
    if width < MIN_SIDE_PX or height < MIN_SIDE_PX:
        raise InputError(f"{name}: image is {width}×{height} px; bokehfit needs at least {MIN_SIDE_PX} px a side")
    if width * height > max_pixels:
        raise InputError(
            f"{name}: image is {width}×{height} px ({width * height / 1e6:.0f} megapixels), more than the limit of"
            f" {max_pixels / 1e6:g} megapixels; downscale it or raise max_pixels"
        )


# --------------------------------------------------------------------------------------
# Progress
# --------------------------------------------------------------------------------------


class _Progress:
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


def _progress_for(name: str, width: int, height: int, orientation: int, enabled: bool) -> _Progress:
    """A bar with a step for decoding, one per block of rows, and one for the display copy."""
    rows = _displayed_size(width, height, orientation)[1]
    return _Progress(name, width * height, 2 + len(_blocks(rows)), enabled)


def _blocks(height: int):
    return [(r0, min(r0 + _BLOCK_ROWS, height)) for r0 in range(0, height, _BLOCK_ROWS)]


# --------------------------------------------------------------------------------------
# Orientation
# --------------------------------------------------------------------------------------


def _orient(image: np.ndarray, orientation: int) -> np.ndarray:
    """Apply an EXIF orientation (1..8) to an image of shape (H, W) or (H, W, C≤4)."""
    import cv2

    if orientation == 1:
        return image
    if image.dtype == np.bool_:
        return _orient(image.view(np.uint8), orientation).view(np.bool_)
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


@contextlib.contextmanager
def _library_messages():
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


def _quietly(path: Path, load, *args) -> Photo:
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
        with _library_messages() as printed:
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


def _imdecode(data: bytes, path: Path | None = None, shape: tuple[int, ...] | None = None):
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
            with _library_messages() as messages:
                try:
                    pixels = cv2.imread(name, _photo_array(shape, np.uint8), flags)
                except cv2.error:
                    pixels = None
            if pixels is not None and pixels.size:
                return pixels, messages
        with _library_messages() as messages:
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
    for r1 in range(height, 0, -_BLOCK_ROWS):
        r0 = max(0, r1 - _BLOCK_ROWS)
        block = pixels[r0:r1].reshape(r1 - r0, -1, *pixels.shape[2:3])
        flat = np.all(block == fill, axis=tuple(range(1, block.ndim)))
        if not flat.all():
            return r0 + int(len(flat) - np.argmin(flat[::-1]))
    return 0


def _damage_note(name: str, kind: str, pixels: np.ndarray, messages: list[str]) -> str:
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


def _displayed_size(width: int, height: int, orientation: int) -> tuple[int, int]:
    return (height, width) if orientation in (5, 6, 7, 8) else (width, height)


# --------------------------------------------------------------------------------------
# Linearisation of decoded pixels
# --------------------------------------------------------------------------------------


def _frozen(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


#: Arrays from this size on are given ordinary pages, not transparent huge pages (:func:`_photo_array`).
PLAIN_PAGES_BYTES = 8 << 20


def _photo_array(shape: tuple[int, ...], dtype) -> np.ndarray:
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


def _linearise_integer(pixels: np.ndarray, bits: int, order: str, encoding: Encoding, bar: _Progress):
    """Luminance, clipped mask and 8-bit RGB display of an oriented uint8/uint16 image.

    ``pixels`` is (H, W) grey or (H, W, 3) in channel order ``order`` ("RGB" or "BGR"). An
    8-bit colour image becomes the display: its channels are put in RGB order in place.
    """
    import cv2

    height, width = pixels.shape[:2]
    top = 2**bits - 1
    luminance = _photo_array((height, width), np.float32)
    clipped = _photo_array((height, width), np.bool_)
    if pixels.ndim == 2:
        curve = np.ascontiguousarray(encoding.lut(bits)[:, 1])  # a grey image: the G curve, weight 1
        for r0, r1 in _blocks(height):
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
    for r0, r1 in _blocks(height):
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
        for r0, r1 in _blocks(height):
            cv2.cvtColor(display[r0:r1], cv2.COLOR_BGR2RGB, dst=display[r0:r1])
    bar.step("display")
    return luminance, clipped, display


def _display_from_linear(rgb: np.ndarray, scale: float, bar: _Progress | None = None) -> np.ndarray:
    """sRGB-encoded uint8 RGB of a linear image (uint16 or float32; ``scale`` maps it to [0, 1])."""
    table = srgb_display_lut()
    height = rgb.shape[0]
    display = np.empty(rgb.shape[:2] + (3,), dtype=np.uint8)
    for r0, r1 in _blocks(height):
        block = rgb[r0:r1]
        if block.dtype == np.uint16 and scale == 1.0 / 65535.0:
            index = block
        else:
            index = np.clip(block * np.float32(scale * 65535.0) + np.float32(0.5), 0.0, 65535.0).astype(np.uint16)
        if index.ndim == 2:
            index = index[..., None]
        display[r0:r1] = np.take(table, index)
    return display


# --------------------------------------------------------------------------------------
# JPEG
# --------------------------------------------------------------------------------------

# Start-of-frame markers (baseline, extended, progressive, lossless; Huffman and arithmetic).
_SOF_MARKERS = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


@dataclass
class _Meta:
    """What a file's headers say."""

    width: int = 0
    height: int = 0
    exif: ExifTags = field(default_factory=ExifTags)
    xmp: bytes | None = None
    icc: bytes | None = None
    png_srgb: bool = False
    png_gamma: float | None = None
    notes: list[str] = field(default_factory=list)
    bits_per_pixel: int = 24  #: PNG: bit depth × channels
    arithmetic: bool = False  #: JPEG: arithmetic-coded
    image_data_bytes: int = 0  #: PNG: the IDAT chunks' total length


def _jpeg_header(name: str, data: bytes) -> tuple[_Meta, int]:
    """Parse a JPEG up to its first scan: size, EXIF, XMP, ICC profile; and the number of components."""
    meta = _Meta()
    icc_chunks: dict[int, bytes] = {}
    exif_blob = None
    components = None
    i, n = 2, len(data)
    damaged = f"{name} is a damaged JPEG file (its header is corrupt); re-export it"
    truncated = f"{name} is a truncated JPEG file (it ends before the image data does); copy or export it again"
    while True:
        if i + 4 > n:
            raise InputError(truncated)
        if data[i] != 0xFF:
            raise InputError(damaged)
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker == 0x01 or 0xD0 <= marker <= 0xD8:  # markers without a length
            i += 2
            continue
        if marker == 0xD9:
            raise InputError(f"{name} is a JPEG file without image data; re-export it")
        (length,) = struct.unpack(">H", data[i + 2 : i + 4])
        if length < 2:
            raise InputError(damaged)
        if i + 2 + length > n:
            raise InputError(truncated)
        payload = data[i + 4 : i + 2 + length]
        if marker == 0xE1 and payload.startswith(b"Exif\x00\x00") and exif_blob is None:
            exif_blob = payload
        elif marker == 0xE1 and payload.startswith(_XMP_JPEG) and meta.xmp is None:
            meta.xmp = payload[len(_XMP_JPEG) :]
        elif marker == 0xE2 and payload.startswith(_ICC_JPEG) and len(payload) > 14:
            icc_chunks[payload[12]] = payload[14:]
        elif marker in _SOF_MARKERS and components is None:
            if len(payload) < 6:
                raise InputError(damaged)
            meta.height, meta.width = struct.unpack(">HH", payload[1:5])
            meta.arithmetic = marker in _ARITHMETIC_SOF
            components = payload[5]
        elif marker == 0xDA:
            break
        i += 2 + length
    if components is None:
        raise InputError(damaged)
    # Entropy-coded data stuffs every 0xFF with 0x00, so 0xFFD9 after the first scan is the end-of-image marker.
    if data.rfind(b"\xff\xd9", i) < 0:
        raise InputError(truncated)
    icc_size = sum(len(chunk) for chunk in icc_chunks.values())
    if icc_size > METADATA_MAX_BYTES:
        meta.notes.append(f"{name}: its ICC profile holds {icc_size} bytes, more than the {METADATA_MAX_BYTES} read; skipped")
    elif icc_chunks:
        meta.icc = b"".join(icc_chunks[k] for k in sorted(icc_chunks))
    meta.exif = read_exif_tags(exif_blob)
    return meta, components


def _load_jpeg(path: Path, data: bytes, max_pixels: int, progress: bool) -> Photo:
    meta, components = _jpeg_header(path.name, data)
    if meta.width == 0 or meta.height == 0:
        raise InputError(f"{path.name} is a JPEG file that gives no image size; re-export it")
    _check_size(path.name, meta.width, meta.height, max_pixels)
    blocks = math.ceil(meta.width / 8) * math.ceil(meta.height / 8)
    if blocks > 8 * len(data):  # a bit per 8×8 block of the luminance at least (JPEG_MAX_PIXELS_PER_BYTE)
        fix = "re-encode it with Huffman coding" if meta.arithmetic else "copy or export it again"
        raise InputError(
            f"{path.name}: its header claims {meta.width}×{meta.height} px, which {len(data)} bytes of JPEG can't hold "
            f"(at most {JPEG_MAX_PIXELS_PER_BYTE} px a byte); the file is truncated or crafted: {fix}"
        )
    if components not in (1, 3, 4):
        raise InputError(f"{path.name} is a {components}-channel JPEG; convert it to RGB")
    exif = build_exif(meta.exif, meta.xmp, width_px=meta.width, height_px=meta.height)
    notes = list(meta.notes)
    bar = _progress_for(path.name, meta.width, meta.height, exif.orientation, progress)
    try:
        if components == 4:
            pixels, order, messages, encoding, note = _decode_cmyk_jpeg(path.name, data, meta.icc)
            notes.append(note)
        else:
            encoding = _encoding_for(meta)
            shape = (meta.height, meta.width) if components == 1 else (meta.height, meta.width, 3)
            (pixels, messages), order = _imdecode(data, path, shape), "BGR"
        if pixels is None or pixels.shape[:2] != (meta.height, meta.width):
            raise InputError(f"{path.name} could not be decoded as a JPEG; re-export it")
        if pixels.ndim == 3 and pixels.shape[2] != 3:
            raise InputError(f"{path.name} is a {pixels.shape[2]}-channel JPEG; convert it to RGB")
        if messages:
            notes.append(_damage_note(path.name, "JPEG", pixels, messages))
        pixels = _orient(pixels, exif.orientation)
        bar.step("decode")
        luminance, clipped, display = _linearise_integer(pixels, 8, order, encoding, bar)
    finally:
        bar.close()
    return _photo(
        path, luminance, clipped, display, False, exif, encoding.describe(), encoding.colour_space, notes,
        decoding=encoding.lut(8),
    )


def _decode_cmyk_jpeg(name: str, data: bytes, icc: bytes | None):
    """A CMYK or YCCK JPEG as 8-bit sRGB: ``(pixels, "RGB", messages, encoding, note)``.

    Pillow decodes it (libjpeg turns YCCK into CMYK; Pillow undoes Adobe's inverted
    CMYK). With a usable embedded CMYK profile, littleCMS converts to sRGB (perceptual
    intent); otherwise Pillow's naive conversion ``R = (1 − C)(1 − K)``,
    ``G = (1 − M)(1 − K)``, ``B = (1 − Y)(1 − K)``, which ignores ink and paper.
    """
    import io
    import warnings

    from PIL import Image, ImageCms

    with _library_messages() as messages, warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)  # max_pixels was checked
        try:
            image = Image.open(io.BytesIO(data))
            image.load()
        except (OSError, ValueError, SyntaxError, Image.DecompressionBombError) as error:
            raise InputError(f"{name} could not be decoded as a CMYK JPEG ({_short(error)}); re-export it") from None
    if image.mode != "CMYK":
        raise InputError(f"{name} is a 4-channel JPEG that decodes as {image.mode}; convert it to RGB")
    how = None
    if icc and icc[16:20] == b"CMYK":
        label = icc_description(icc) or "no description"
        try:
            source = ImageCms.ImageCmsProfile(io.BytesIO(icc))
            rgb = ImageCms.profileToProfile(image, source, ImageCms.createProfile("sRGB"), outputMode="RGB")
            how = f"with its embedded ICC profile '{label}' (littleCMS, perceptual intent)"
        except (ImageCms.PyCMSError, OSError, ValueError) as error:
            why = f"its embedded ICC profile '{label}' is not usable ({_short(error)})"
    else:
        why = "no CMYK ICC profile in the file"
    if how is None:
        rgb = image.convert("RGB")
        how = f"naively, R = (1 − C)(1 − K) and so on ({why}; colours are approximate)"
    pixels = np.asarray(rgb, dtype=np.uint8)
    encoding = named_encoding("sRGB", "the conversion from CMYK")
    return pixels, "RGB", list(messages), encoding, f"{name} is a CMYK JPEG: converted to sRGB {how}"


def _encoding_for(meta: _Meta) -> Encoding:
    colour_space = meta.exif.get(0xA001)
    interop = meta.exif.interop.get(0x0001)
    return detect_encoding(
        icc=meta.icc,
        png_srgb=meta.png_srgb,
        png_gamma=meta.png_gamma,
        exif_colour_space=colour_space if isinstance(colour_space, int) else None,
        interop_index=interop if isinstance(interop, str) else None,
        xmp_icc_name=xmp_property(meta.xmp, "photoshop:ICCProfile"),
    )


def _srgb_decoding() -> np.ndarray:
    """The linear value of every 8-bit sRGB code, per channel: (256, 3) float32."""
    return np.repeat(srgb_decode(np.arange(256) / 255.0).astype(np.float32)[:, None], 3, axis=1)


def _photo(path, luminance, clipped, display, raw, exif, linearisation, colour_space, notes=(), decoding=None) -> Photo:
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


# --------------------------------------------------------------------------------------
# PNG
# --------------------------------------------------------------------------------------


def _png_header(name: str, data: bytes) -> _Meta:
    """Parse a PNG's chunks: size, ICC profile, sRGB, gAMA, eXIf, XMP."""
    meta = _Meta()
    exif_blob = None
    truncated = f"{name} is a truncated PNG file (it ends before its IEND chunk); copy or export it again"
    i, n = 8, len(data)
    first = True
    budget = _InflateBudget(METADATA_INFLATE_BUDGET_BYTES)
    icc_seen = False
    while True:
        if i + 8 > n:
            raise InputError(truncated)
        length, kind = struct.unpack(">I4s", data[i : i + 8])
        if i + 12 + length > n:  # checked before anything is read
            raise InputError(truncated)
        wanted = kind in (b"IHDR", b"iCCP", b"sRGB", b"gAMA", b"eXIf", b"iTXt")
        cap = XMP_MAX_BYTES if kind == b"iTXt" else METADATA_MAX_BYTES
        if wanted and length > cap:
            meta.notes.append(
                f"{name}: its {kind.decode('latin-1')} chunk holds {length} bytes, more than the {cap} read; skipped"
            )
            wanted = False
        body = data[i + 8 : i + 8 + length] if wanted else b""
        if first:
            if kind != b"IHDR" or length < 13:
                raise InputError(f"{name} is a damaged PNG file (no IHDR chunk); re-export it")
            meta.width, meta.height = struct.unpack(">II", body[:8])
            meta.bits_per_pixel = body[8] * _PNG_CHANNELS.get(body[9], 4)
            first = False
        elif kind == b"IDAT":
            meta.image_data_bytes += length
        elif kind == b"iCCP" and wanted and icc_seen:
            budget.skipped += 1  # the PNG standard allows one; the first counts
        elif kind == b"iCCP" and wanted:
            icc_seen = True
            try:
                separator = body.index(b"\x00")
                meta.icc = budget.inflate(body[separator + 2 :], METADATA_MAX_BYTES)
            except (ValueError, zlib.error):
                meta.icc = None
            if meta.icc is None and length:
                meta.notes.append(f"{name}: its ICC profile is damaged or inflates past {METADATA_MAX_BYTES} bytes; ignored")
        elif kind == b"sRGB":
            meta.png_srgb = True
        elif kind == b"gAMA" and length == 4:
            meta.png_gamma = struct.unpack(">I", body)[0] / 100000.0 or None
        elif kind == b"eXIf" and wanted:
            exif_blob = body
        elif kind == b"iTXt" and body.startswith(b"XML:com.adobe.xmp\x00") and meta.xmp is not None:
            budget.skipped += 1
        elif kind == b"iTXt" and body.startswith(b"XML:com.adobe.xmp\x00"):
            meta.xmp = _itxt_text(body, XMP_MAX_BYTES, budget)
            if meta.xmp is None:
                meta.notes.append(f"{name}: its XMP packet is damaged or inflates past {XMP_MAX_BYTES} bytes; ignored")
        elif kind == b"IEND":
            break
        i += 12 + length
    if budget.skipped:
        meta.notes.append(f"{name}: {budget.skipped} more ICC or XMP chunks than the one of each a PNG may hold, or past the"
                          f" {METADATA_INFLATE_BUDGET_BYTES} bytes inflated per file; skipped")
    meta.exif = read_exif_tags(exif_blob)
    return meta


#: Channels of each PNG colour type (grey, RGB, palette, grey + alpha, RGBA).
_PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}


class _InflateBudget:
    """The bytes that one file's metadata chunks may inflate to, all together."""

    def __init__(self, total: int):
        self.left, self.skipped = total, 0

    def inflate(self, data: bytes, cap: int) -> bytes | None:
        """:func:`_inflate` within what is left; a chunk past the budget is skipped (None) and counted."""
        if self.left <= 0:
            self.skipped += 1
            return None
        out = _inflate(data, min(cap, self.left))
        self.left -= min(cap, self.left) if out is None else len(out)
        return out


def _check_png_data_size(name: str, meta: "_Meta") -> None:
    """``InputError`` if the image data claimed by the header can't come out of the file's IDAT bytes.

    Unfiltered rows are ``height × (1 + ⌈width × bits per pixel / 8⌉)`` bytes, and deflate gives at most
    :data:`DEFLATE_MAX_RATIO` bytes per byte; the zlib header and Adam7's extra filter bytes get a margin.
    """
    raw = meta.height * (1 + math.ceil(meta.width * meta.bits_per_pixel / 8))
    if raw > DEFLATE_MAX_RATIO * (meta.image_data_bytes + 64) + 16 * meta.height:
        raise InputError(
            f"{name}: its header claims {meta.width}×{meta.height} px, which {meta.image_data_bytes} bytes of PNG image"
            f" data can't hold (deflate packs at most {DEFLATE_MAX_RATIO} bytes a byte); the file is truncated or crafted:"
            " copy or export it again"
        )


def _inflate(data: bytes, cap: int) -> bytes | None:
    """zlib-decompressed ``data``, or None when it would be longer than ``cap`` bytes.

    At most ``cap + 1`` bytes are ever produced: a small chunk that inflates to
    gigabytes costs no more than a legitimate one.
    """
    inflater = zlib.decompressobj()
    out = inflater.decompress(data, cap + 1)
    return None if len(out) > cap else out


def _itxt_text(body: bytes, cap: int, budget: "_InflateBudget | None" = None) -> bytes | None:
    """The text of an iTXt chunk (decompressed up to ``cap`` bytes), or None."""
    try:
        keyword_end = body.index(b"\x00")
        compressed = body[keyword_end + 1]
        rest = body[keyword_end + 3 :]
        rest = rest[rest.index(b"\x00") + 1 :]  # language tag
        rest = rest[rest.index(b"\x00") + 1 :]  # translated keyword
        if not compressed:
            return rest
        return budget.inflate(rest, cap) if budget is not None else _inflate(rest, cap)
    except (ValueError, IndexError, zlib.error):
        return None


def _load_png(path: Path, data: bytes, max_pixels: int, progress: bool) -> Photo:
    meta = _png_header(path.name, data)
    _check_size(path.name, meta.width, meta.height, max_pixels)
    _check_png_data_size(path.name, meta)
    exif = build_exif(meta.exif, meta.xmp, width_px=meta.width, height_px=meta.height)
    encoding = _encoding_for(meta)
    bar = _progress_for(path.name, meta.width, meta.height, exif.orientation, progress)
    try:
        pixels, messages = _imdecode(data)
        if pixels is None or pixels.shape[:2] != (meta.height, meta.width):
            said = f": {_short(Exception(messages[0]))}" if messages else ""
            raise InputError(f"{path.name} could not be decoded as a PNG (damaged image data{said}); re-export it")
        if messages:  # libpng stops at errors in the image data: these are warnings about other chunks
            said = _short(Exception(" ".join(messages[0].split()).removeprefix("libpng warning: ")))
            more = f" (+{len(messages) - 1} more)" if len(messages) > 1 else ""
            meta.notes.append(f"{path.name}: the PNG decoder warned ({said}{more}); the image data decoded in full")
        bits = 16 if pixels.dtype == np.uint16 else 8
        if pixels.ndim == 3:
            pixels = pixels[..., :3] if pixels.shape[2] >= 3 else pixels[..., 0]  # drop alpha
        pixels = _orient(np.ascontiguousarray(pixels), exif.orientation)
        bar.step("decode")
        luminance, clipped, display = _linearise_integer(pixels, bits, "BGR", encoding, bar)
    finally:
        bar.close()
    return _photo(
        path, luminance, clipped, display, False, exif, encoding.describe(), encoding.colour_space, meta.notes,
        decoding=encoding.lut(8),
    )


# --------------------------------------------------------------------------------------
# TIFF
# --------------------------------------------------------------------------------------


def _load_tiff(path: Path, data: bytes, max_pixels: int, progress: bool) -> Photo:
    import io

    import tifffile

    try:
        tif = tifffile.TiffFile(io.BytesIO(data))
    except Exception as error:  # noqa: BLE001 - tifffile raises many kinds for damaged files
        raise InputError(f"{path.name} is a damaged TIFF file ({_short(error)}); re-export it") from None
    with tif:
        if not tif.pages:
            raise InputError(f"{path.name} is a TIFF file without images; re-export it")
        page = tif.pages.first
        tags = read_exif_tags(data)
        if 50706 in tags.ifd0 or page.tags.get(50706) is not None:  # DNGVersion: a DNG named .tif
            return _load_raw(path, max_pixels, progress)
        width, height = int(page.imagewidth), int(page.imagelength)
        _check_size(path.name, width, height, max_pixels)
        depth = int(getattr(page, "imagedepth", 1) or 1)
        if depth != 1:
            raise InputError(f"{path.name} is a volume TIFF (ImageDepth {depth}), not a photo; save one image as TIFF")
        _check_tiff_data_size(path.name, page, width, height)
        photometric = int(page.photometric)
        if photometric in (3, 5, 8, 32803, 34892) or page.bitspersample == 1:
            kind = {3: "palette", 5: "CMYK", 8: "CIELab", 32803: "raw CFA", 34892: "linear raw"}.get(
                photometric, "bilevel"
            )
            raise InputError(f"{path.name} is a {kind} TIFF; save it as an RGB or grey TIFF (8/16-bit or float)")
        icc = tags.ifd0.get(34675)
        xmp = tags.ifd0.get(700)
        meta = _Meta(
            width, height, tags, xmp if isinstance(xmp, bytes) else None, icc if isinstance(icc, bytes) else None
        )
        for what, attribute, cap in (("XMP packet", "xmp", XMP_MAX_BYTES), ("ICC profile", "icc", METADATA_MAX_BYTES)):
            if getattr(meta, attribute) is not None and len(getattr(meta, attribute)) > cap:
                meta.notes.append(f"{path.name}: its {what} holds {len(getattr(meta, attribute))} bytes, more than"
                                  f" the {cap} read; skipped")
                setattr(meta, attribute, None)
        exif = build_exif(tags, meta.xmp, width_px=width, height_px=height)
        bar = _progress_for(path.name, width, height, exif.orientation, progress)
        try:
            pixels, order = _decode_tiff(path.name, page, data)
            bar.step("decode")
            if pixels.shape[:2] != (height, width):
                raise InputError(f"{path.name} could not be decoded as a TIFF (damaged image data); re-export it")
            if pixels.ndim == 3:
                pixels = pixels[..., :3] if pixels.shape[2] >= 3 else pixels[..., 0]  # drop alpha
            if photometric == 0 and pixels.dtype.kind == "u":  # MINISWHITE
                pixels = np.iinfo(pixels.dtype).max - pixels
            if pixels.dtype.kind == "f":
                return _finish_float_tiff(path, pixels, order, exif, bar, meta.notes)
            if pixels.dtype not in (np.uint8, np.uint16):
                raise InputError(f"{path.name} has {pixels.dtype} samples; save it as an 8/16-bit or float32 TIFF")
            pixels = _orient(np.ascontiguousarray(pixels), exif.orientation)
            encoding = _encoding_for(meta)
            bits = 8 if pixels.dtype == np.uint8 else 16
            luminance, clipped, display = _linearise_integer(pixels, bits, order, encoding, bar)
        finally:
            bar.close()
    return _photo(
        path, luminance, clipped, display, False, exif, encoding.describe(), encoding.colour_space, meta.notes,
        decoding=encoding.lut(8),
    )


#: Most bytes each TIFF compression can give per byte of its data: deflate 1032 (DEFLATE_MAX_RATIO);
#: LZW 4096 bytes per code of at least 9 bits, 3641; PackBits 128 bytes per 2, 64; JPEG 512 pixels a byte
#: (JPEG_MAX_PIXELS_PER_BYTE) of at most 3 bytes each. Other compressions are not bounded here.
_TIFF_MAX_RATIO = {5: 3641, 7: 3 * JPEG_MAX_PIXELS_PER_BYTE, 8: DEFLATE_MAX_RATIO, 32946: DEFLATE_MAX_RATIO, 32773: 64}


def _check_tiff_data_size(name: str, page, width: int, height: int) -> None:
    """``InputError`` if the image a TIFF's header claims can't come out of its strips' or tiles' bytes."""
    try:
        compression = int(page.compression)
        stored = sum(int(n) for n in page.databytecounts)
        bits = int(page.bitspersample) * int(page.samplesperpixel)
        pieces = len(page.databytecounts)
    except (TypeError, ValueError, AttributeError):
        return
    ratio = 1 if compression == 1 else _TIFF_MAX_RATIO.get(compression)
    if ratio is None:
        return
    raw = height * math.ceil(width * bits / 8)
    if raw > ratio * (stored + 64 * pieces) + 4096:
        raise InputError(
            f"{name}: its header claims {width}×{height} px, which {stored} bytes of image data"
            f" (compression {compression}) can't hold; the file is truncated or crafted: copy or export it again"
        )


def _short(error: Exception) -> str:
    text = " ".join(str(error).split()) or type(error).__name__
    return text if len(text) <= 120 else text[:117] + "..."


def _decode_tiff(name: str, page, data: bytes) -> tuple[np.ndarray, str]:
    """The first page's pixels as (H, W) or (H, W, S), and their channel order."""
    try:
        array = page.asarray()
    except Exception as error:  # noqa: BLE001 - tifffile raises many kinds for damaged files
        if "imagecodecs" not in str(error):
            raise InputError(f"{name} could not be decoded as a TIFF ({_short(error)}); re-export it") from None
        array = None  # LZW or JPEG compression without imagecodecs: OpenCV's libtiff decodes those
    if array is not None:
        axes = page.axes
        array = np.asarray(array)
        if "S" in axes and axes.index("S") < axes.index("Y"):
            array = np.moveaxis(array, axes.index("S"), -1)
        array = array.reshape(array.shape[-3:] if array.ndim >= 3 and "S" in axes else array.shape[-2:])
        return array, "RGB"
    pixels, _ = _imdecode(data)
    if pixels is None:
        raise InputError(f"{name} could not be decoded as a TIFF (damaged or unsupported compression); re-export it")
    return pixels, "BGR"


def _robust_white(pixels: np.ndarray) -> float:
    """The 99.9th percentile of the finite, positive luminance of a float image (0 if none).

    Taken on a sample of at most about a million pixels, in float64 (float32 overflows
    for samples near its limit).
    """
    step = max(1, round(float(np.sqrt(pixels.shape[0] * pixels.shape[1] / 1e6))))
    sample = np.asarray(pixels[::step, ::step], dtype=np.float64)
    if sample.ndim == 3:
        with np.errstate(invalid="ignore", over="ignore"):
            sample = sample[..., :3] @ np.asarray(luminance_weights("sRGB"))
    sample = sample[np.isfinite(sample) & (sample > 0)]
    return float(np.percentile(sample, 99.9)) if sample.size else 0.0


def _finish_float_tiff(path: Path, pixels: np.ndarray, order: str, exif: Exif, bar: _Progress, notes: list[str]) -> Photo:
    """Luminance, mask and display of a float TIFF (module docstring: masking, scaling, clamping)."""
    import cv2

    notes = list(notes)
    if pixels.ndim == 3 and order == "BGR":
        pixels = pixels[..., ::-1]
    white = _robust_white(pixels)
    scale = 1.0 / white if white > FLOAT_WHITE_MAX else 1.0
    out = np.empty(pixels.shape, dtype=np.float32)  # our own copy: masked, scaled and clamped in place
    nonfinite = np.zeros(pixels.shape[:2], dtype=np.bool_)
    unusable = np.zeros(pixels.shape[:2], dtype=np.bool_)
    masked = negatives = clamped = 0
    for r0, r1 in _blocks(pixels.shape[0]):
        block = np.array(pixels[r0:r1], dtype=np.float64)
        bad = ~np.isfinite(block)
        if bad.any():
            block[bad] = 0.0
            bad_pixels = bad if bad.ndim == 2 else bad.any(axis=-1)
            masked += int(np.count_nonzero(bad_pixels))
            nonfinite[r0:r1] = bad_pixels
            unusable[r0:r1] |= bad_pixels
        if scale != 1.0:
            block *= scale
        below = block < 0
        negatives += int(np.count_nonzero(below))
        block[below] = 0.0
        above = block > FLOAT_SAMPLE_MAX
        if above.any():
            above_pixels = above if above.ndim == 2 else above.any(axis=-1)
            clamped += int(np.count_nonzero(above_pixels))
            unusable[r0:r1] |= above_pixels
            block[above] = FLOAT_SAMPLE_MAX
        out[r0:r1] = block
    if masked == unusable.size:
        raise InputError(f"{path.name} has no finite sample (all are NaN or Inf); check the file")
    pixels = _orient(out, exif.orientation)
    unusable = _orient(unusable, exif.orientation)
    nonfinite = _orient(nonfinite, exif.orientation)
    height, width = pixels.shape[:2]
    encoding = linear_encoding("float TIFF")
    luminance = np.empty((height, width), dtype=np.float32)
    if pixels.ndim == 2:
        luminance[...] = pixels
    else:
        weights = np.asarray([luminance_weights("sRGB")], dtype=np.float32)
        for r0, r1 in _blocks(height):
            cv2.transform(pixels[r0:r1], weights, dst=luminance[r0:r1])
            bar.step("linearise")
    if masked:
        # Fill the masked pixels from their neighbours, so that they make no edges of their own.
        luminance = cv2.inpaint(luminance, nonfinite.view(np.uint8), 3, cv2.INPAINT_TELEA)
        notes.append(
            f"{path.name}: {masked} pixels with NaN or Inf samples masked (filled from their neighbours,"
            " flagged like clipped pixels, so that no disc containing them is used)"
        )
    display = _display_from_linear(pixels, 1.0)
    bar.step("display")
    text = "linear float TIFF (sRGB primaries assumed, 1.0 = white)"
    if scale != 1.0:
        text += f"; scaled by {scale:.3g} so that the robust white point (99.9th percentile, {white:.3g}) is 1"
        notes.append(
            f"{path.name}: values up to {white:.3g} at the 99.9th percentile, far above 1.0 = white: scaled by"
            f" {scale:.3g}"
        )
    if negatives:
        text += f"; {negatives} negative values clamped to 0"
    if clamped:
        notes.append(f"{path.name}: {clamped} pixels above {FLOAT_SAMPLE_MAX:g} clamped there and flagged like clipped pixels")
    return _photo(path, luminance, unusable, display, False, exif, text, encoding.colour_space, notes)


# --------------------------------------------------------------------------------------
# Camera raw
# --------------------------------------------------------------------------------------

#: LibRaw's ``flip`` (dcraw bits: 1 mirror x, 2 mirror y, 4 transpose) as an EXIF orientation.
_LIBRAW_FLIP_TO_EXIF = {0: 1, 1: 2, 2: 4, 3: 3, 4: 5, 5: 8, 6: 6, 7: 7}

_RAW_PARAMETERS = "rawpy: gamma 1, no auto-brightening, adjust_maximum_thr=0, camera white balance"


def _raw_metadata(path: Path) -> tuple[ExifTags, bytes | None]:
    """EXIF tags (maker notes included) and XMP of a raw file.

    exiv2 reads every common raw format (TIFF-based raws, CR3, RAF, ORF, RW2, ...); for a
    file it does not know, the EXIF block of an embedded JPEG preview and an XMP packet
    are sought in the file's bytes, best effort.
    """
    tags, xmp = read_file_tags(path)
    if tags.ifd0 or tags.exif:
        return tags, xmp
    try:
        data = path.read_bytes()
    except OSError:
        return ExifTags(), None
    start = data.find(b"Exif\x00\x00", 0, 4 << 20)
    if start >= 0:
        tags = read_exif_tags(data[start : start + METADATA_MAX_BYTES])
    if xmp is None:
        start = data.find(b"<x:xmpmeta")
        end = data.find(b"</x:xmpmeta>", start, start + XMP_MAX_BYTES) if start >= 0 else -1
        xmp = data[start : end + 12] if end >= 0 else None
    return tags, xmp


def _load_raw(path: Path, max_pixels: int, progress: bool) -> Photo:
    import cv2
    import rawpy

    errors = (rawpy.LibRawError, rawpy.NotSupportedError, OSError, ValueError, RuntimeError)
    try:
        raw = rawpy.imread(str(path))
    except errors as error:
        raise InputError(
            f"{path.name} could not be read as camera raw ({_short(error)}); convert it to DNG or TIFF"
        ) from None
    with raw:
        sizes = raw.sizes
        orientation = _LIBRAW_FLIP_TO_EXIF.get(int(sizes.flip), 1)
        width, height = int(sizes.width), int(sizes.height)
        out_w, out_h = _displayed_size(width, height, orientation)
        _check_size(path.name, out_w, out_h, max_pixels)
        bar = _Progress(path.name, width * height, 2 + len(_blocks(out_h)), progress)
        try:
            try:
                rgb = raw.postprocess(
                    gamma=(1, 1),
                    no_auto_bright=True,
                    output_bps=16,
                    use_camera_wb=True,
                    adjust_maximum_thr=0,
                    user_flip=0,
                    output_color=rawpy.ColorSpace.sRGB,
                )
            except errors as error:
                raise InputError(
                    f"{path.name} could not be developed as camera raw ({_short(error)}); convert it to DNG or TIFF"
                ) from None
            if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint16 or min(rgb.shape[:2]) < MIN_SIDE_PX:
                shape = "×".join(map(str, rgb.shape))
                raise InputError(
                    f"{path.name} could not be developed as camera raw (LibRaw gave a {shape} {rgb.dtype} image, not"
                    " RGB: its colour filter (CFA) tags are damaged); convert it to DNG or TIFF with a raw converter"
                )
            bar.step("develop")
            white = int(raw.white_level)
            clipped, clip_note = _raw_clipped(raw, rgb.shape[:2], white)
            lens = raw.lens.model if raw.lens is not None else None
            other = raw.other
            fallback = {
                "lens": lens.decode("latin-1") if isinstance(lens, bytes) else lens,
                "fnumber": getattr(other, "aperture", None),
                "focal_length_mm": getattr(other, "focal_length", None),
            }
            tags, xmp = _raw_metadata(path)
            exif = build_exif(tags, xmp, width_px=width, height_px=height, fallback=fallback)
            exif = replace(exif, orientation=orientation)
            rgb = _orient(rgb, orientation)
            clipped = _orient(clipped, orientation)
            h, w = rgb.shape[:2]
            luminance = np.empty((h, w), dtype=np.float32)
            weights = np.asarray([luminance_weights("sRGB")], dtype=np.float32) / np.float32(65535.0)
            for r0, r1 in _blocks(h):
                cv2.transform(rgb[r0:r1].astype(np.float32), weights, dst=luminance[r0:r1])
                bar.step("linearise")
            display = _display_from_linear(rgb, 1.0 / 65535.0)
            bar.step("display")
        finally:
            bar.close()
    text = f"raw sensor data, linear ({_RAW_PARAMETERS}; 1.0 = white level {white}); {clip_note}"
    return _photo(path, luminance, clipped, display, True, exif, text, "camera raw → sRGB primaries (linear)")


def _raw_clipped(raw, shape: tuple[int, int], white: int) -> tuple[np.ndarray, str]:
    """Pixels of the developed image that a photosite at or above the white level touches."""
    import cv2

    try:
        photosites = raw.raw_image_visible
        if photosites is None or photosites.ndim != 2:
            raise ValueError("no CFA image")
        levels = raw.camera_white_level_per_channel
        if levels and len(set(levels)) > 1 and all(level > 0 for level in levels):
            at_white = photosites >= np.asarray(levels, dtype=photosites.dtype)[raw.raw_colors_visible]
        else:
            at_white = photosites >= white
    except Exception:  # noqa: BLE001 - linear DNGs and Foveon have no CFA image
        return np.zeros(shape, dtype=np.bool_), "clipped mask unavailable (no CFA photosites)"
    mask = at_white.view(np.uint8)
    if mask.shape != shape:
        mask = cv2.resize(mask, (shape[1], shape[0]), interpolation=cv2.INTER_NEAREST)
    # Demosaicing fills each pixel's two missing colours from its 3×3 neighbours.
    mask = cv2.dilate(mask, np.ones((3, 3), np.uint8))
    return mask.astype(np.bool_), "clipped: photosites >= white level, dilated 3×3 for demosaicing"
