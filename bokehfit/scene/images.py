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


def tone_map_srgb8(image: np.ndarray, exposure_ev: float = 0.0) -> np.ndarray:
    """uint8 sRGB of a linear (H, W, 3) image: scaled by 2^exposure_ev, clipped to [0, 1], sRGB-encoded."""
    from bokehfit.io.colour import srgb_display_lut

    exposure_ev = check("exposure_ev", exposure_ev)
    scaled = np.nan_to_num(np.asarray(image, dtype=np.float64) * 2.0**exposure_ev, nan=0.0, posinf=1.0, neginf=0.0)
    index = np.rint(np.clip(scaled, 0.0, 1.0) * 65535.0).astype(np.int64)
    return srgb_display_lut()[index]


def write_render(path: Path, image: np.ndarray, exposure_ev: float = 0.0) -> None:
    """Write ``image`` (linear RGB, (H, W, 3)) atomically; the suffix picks the format.

    ``.png``: 8-bit sRGB after :func:`tone_map_srgb8`. ``.exr``: linear float32 R, G, B
    (ZIP compression), the exposure left out.
    """
    exposure_ev = check("exposure_ev", exposure_ev)
    suffix = path.suffix.lower()
    if suffix == ".png":
        rgb = tone_map_srgb8(image, exposure_ev)
        write_png(path, np.ascontiguousarray(rgb[..., ::-1]))  # OpenCV writes BGR
    elif suffix == ".exr":
        write_exr(path, {name: image[..., i] for i, name in enumerate("RGB")})
    else:
        raise InputError(f"image file must end in {', '.join(RENDER_FORMATS)} (got {str(path)!r})")
