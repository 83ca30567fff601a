"""Write rendered images: tone-mapped 8-bit sRGB PNG, or linear float32 OpenEXR."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bokehfit.errors import InputError
from bokehfit.outputs import write_exr, write_png
from bokehfit.validate import check

__all__ = ["RENDER_FORMATS", "tone_map_srgb8", "write_render"]

#: Image formats of ``bokehfit render --out``, by suffix.
RENDER_FORMATS = (".png", ".exr")


#: Rows tone-mapped at a time: the float temporaries stay a few MB whatever the image's size.
_BLOCK_ROWS = 64


def tone_map_srgb8(image: np.ndarray, exposure_ev: float = 0.0, *, bgr: bool = False) -> np.ndarray:
    """uint8 sRGB of a linear (H, W, 3) image: scaled by 2^exposure_ev, clipped to [0, 1], sRGB-encoded.

    NumPy twin of WGSL ``tone_map_srgb8`` (``shaders/tonemap.wgsl``), through which the
    viewer's page shows its frames: the clipped value is rounded to a 16-bit level (the
    index of :func:`~bokehfit.io.colour.srgb_display_lut`), encoded and rounded to 8 bits.
    NaN counts as 0 and +inf as 1 (the WGSL twin leaves non-finite input to the adapter).

    Done in blocks of rows into the one uint8 result (3 bytes a pixel), so that a
    16384² render needs no float64 copies of itself; ``bgr`` orders the channels as
    OpenCV writes them.
    """
    from bokehfit.io.colour import srgb_display_lut

    exposure_ev = check("exposure_ev", exposure_ev)
    image = np.asarray(image)
    lut = srgb_display_lut()
    scale = 2.0**exposure_ev
    out = np.empty(image.shape, dtype=np.uint8)
    for r0 in range(0, image.shape[0], _BLOCK_ROWS):
        block = image[r0 : r0 + _BLOCK_ROWS]
        if bgr:
            block = block[..., ::-1]
        scaled = np.nan_to_num(np.asarray(block, dtype=np.float64) * scale, nan=0.0, posinf=1.0, neginf=0.0)
        out[r0 : r0 + _BLOCK_ROWS] = lut[np.rint(np.clip(scaled, 0.0, 1.0) * 65535.0).astype(np.int64)]
    return out


def write_render(path: Path, image: np.ndarray, exposure_ev: float = 0.0) -> None:
    """Write ``image`` (linear RGB, (H, W, 3)) atomically; the suffix picks the format.

    ``.png``: 8-bit sRGB after :func:`tone_map_srgb8`. ``.exr``: linear float32 R, G, B
    (ZIP compression), the exposure left out.
    """
    exposure_ev = check("exposure_ev", exposure_ev)
    suffix = path.suffix.lower()
    if suffix == ".png":
        write_png(path, tone_map_srgb8(image, exposure_ev, bgr=True))  # OpenCV writes BGR
    elif suffix == ".exr":
        write_exr(path, {name: image[..., i] for i, name in enumerate("RGB")})
    else:
        raise InputError(f"image file must end in {', '.join(RENDER_FORMATS)} (got {str(path)!r})")
