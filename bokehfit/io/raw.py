"""Camera raw (DNG, NEF, CR2, CR3, ARW, RAF, ...): developed by LibRaw into linear light.

:func:`load_raw` develops with gamma 1, no brightening, no lowered maximum and the camera's white
balance, into linear sRGB primaries (1.0 = the white level); the clipped mask comes from the
photosites at the white level; EXIF and XMP are read by exiv2, else sought in the file's bytes.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from bokehfit.errors import InputError
from bokehfit.io.colour import luminance_weights
from bokehfit.io.decoders import short
from bokehfit.io.exif import build_exif
from bokehfit.io.files import METADATA_MAX_BYTES, MIN_SIDE_PX, check_size
from bokehfit.io.linear import Photo, Progress, display_from_linear, displayed_size, make_photo, orient, row_blocks
from bokehfit.io.tags import ExifTags, read_exif_tags, read_file_tags
from bokehfit.io.xmp import XMP_MAX_BYTES

__all__ = ["load_raw"]

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


def load_raw(path: Path, max_pixels: int, progress: bool) -> Photo:
    import cv2
    import rawpy

    errors = (rawpy.LibRawError, rawpy.NotSupportedError, OSError, ValueError, RuntimeError)
    try:
        raw = rawpy.imread(str(path))
    except errors as error:
        raise InputError(
            f"{path.name} could not be read as camera raw ({short(error)}); convert it to DNG or TIFF"
        ) from None
    with raw:
        sizes = raw.sizes
        orientation = _LIBRAW_FLIP_TO_EXIF.get(int(sizes.flip), 1)
        width, height = int(sizes.width), int(sizes.height)
        out_w, out_h = displayed_size(width, height, orientation)
        check_size(path.name, out_w, out_h, max_pixels)
        bar = Progress(path.name, width * height, 2 + len(row_blocks(out_h)), progress)
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
                    f"{path.name} could not be developed as camera raw ({short(error)}); convert it to DNG or TIFF"
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
            rgb = orient(rgb, orientation)
            clipped = orient(clipped, orientation)
            h, w = rgb.shape[:2]
            luminance = np.empty((h, w), dtype=np.float32)
            weights = np.asarray([luminance_weights("sRGB")], dtype=np.float32) / np.float32(65535.0)
            for r0, r1 in row_blocks(h):
                cv2.transform(rgb[r0:r1].astype(np.float32), weights, dst=luminance[r0:r1])
                bar.step("linearise")
            display = display_from_linear(rgb, 1.0 / 65535.0)
            bar.step("display")
        finally:
            bar.close()
    text = f"raw sensor data, linear ({_RAW_PARAMETERS}; 1.0 = white level {white}); {clip_note}"
    return make_photo(path, luminance, clipped, display, True, exif, text, "camera raw → sRGB primaries (linear)")


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
