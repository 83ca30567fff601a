"""The photo file before it is decoded: which files are read, their size bounds, what their headers say.

Only a regular file of at most :data:`MAX_FILE_BYTES` is read (:func:`check_file`,
:func:`read_file`); the size a header claims is checked against :data:`MIN_SIDE_PX` and
``max_pixels`` before anything is decoded (:func:`check_size`). The format readers fill a
:class:`Meta` from their headers, and :func:`encoding_for` names its colour encoding.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from bokehfit.errors import InputError
from bokehfit.io.colour import Encoding, detect_encoding
from bokehfit.io.tags import ExifTags
from bokehfit.io.xmp import xmp_property

__all__ = [
    "MAX_FILE_BYTES",
    "MAX_PIXELS",
    "METADATA_MAX_BYTES",
    "MIN_SIDE_PX",
    "RAW_SUFFIXES",
    "Meta",
    "check_file",
    "check_size",
    "encoding_for",
    "read_file",
]

#: Smallest accepted side of an image, in pixels.
MIN_SIDE_PX = 16
#: Largest accepted image, in pixels (width × height), unless ``max_pixels`` says otherwise.
MAX_PIXELS = 250_000_000
#: Largest photo file read, bytes: MAX_PIXELS of uncompressed RGBA float32 (16 bytes a pixel, the
#: largest sample layout read) and 64 MiB of metadata. A larger file is no photo bokehfit could use.
MAX_FILE_BYTES = MAX_PIXELS * 16 + (64 << 20)
#: File suffixes read as camera raw through LibRaw (lower case, with the dot).
RAW_SUFFIXES = frozenset(
    ".dng .nef .nrw .cr2 .cr3 .crw .arw .srf .sr2 .raf .orf .rw2 .pef .srw .x3f .3fr .iiq .erf .mef .mos .mrw"
    " .kdc .dcr .rwl .raw".split()
)
#: Largest metadata block read (bytes, after decompression): an ICC profile or an EXIF block.
#: Real ones are a few kB to a few hundred kB; larger ones are skipped with a note.
METADATA_MAX_BYTES = 4 << 20


def check_file(path: Path) -> None:
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


def read_file(path: Path) -> bytes:
    """The file's bytes; only a regular file is opened (non-blocking, so a FIFO put there since the check can't stall)."""
    from bokehfit.regular_files import open_regular

    try:
        with open_regular(path) as file:
            data = file.read(MAX_FILE_BYTES + 1)
    except OSError as error:
        raise InputError(f"cannot read {path}: {error.strerror or error}") from None
    if len(data) > MAX_FILE_BYTES:
        raise InputError(f"{path} is larger than a photo can be ({MAX_FILE_BYTES / 2**30:.3g} GiB); check the file")
    return data


def check_size(name: str, width: int, height: int, max_pixels: int) -> None:
    if width < MIN_SIDE_PX or height < MIN_SIDE_PX:
        raise InputError(f"{name}: image is {width}×{height} px; bokehfit needs at least {MIN_SIDE_PX} px a side")
    if width * height > max_pixels:
        raise InputError(
            f"{name}: image is {width}×{height} px ({width * height / 1e6:.0f} megapixels), more than the limit of"
            f" {max_pixels / 1e6:g} megapixels; downscale it or raise max_pixels"
        )


@dataclass
class Meta:
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


def encoding_for(meta: Meta) -> Encoding:
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
