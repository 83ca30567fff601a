"""Draw found discs on the photo: each outline, coloured by use, with its index."""

from __future__ import annotations

import cv2
import numpy as np

from bokehfit.discs import Disc

__all__ = ["draw_disc_overlay", "USED_BGR", "FLAGGED_BGR"]

#: Outline colours (BGR): discs clean enough to fit, and discs left out (saturated,
#: clipped by the frame, overlapping, or too small to show a shape).
USED_BGR = (80, 220, 60)
FLAGGED_BGR = (40, 90, 255)
#: Sub-pixel precision of the drawn outlines (OpenCV fixed-point shift).
_SHIFT = 4


def draw_disc_overlay(display_rgb: np.ndarray, discs: list[Disc]) -> np.ndarray:
    """BGR image (for cv2.imencode) of the photo with every disc's outline and index.

    Line widths and labels scale with the image, so they stay visible on a
    24-megapixel photo viewed whole.
    """
    canvas = cv2.cvtColor(np.ascontiguousarray(display_rgb), cv2.COLOR_RGB2BGR)
    height, width = canvas.shape[:2]
    thickness = max(1, round(max(height, width) / 1500))
    font_scale = max(0.4, max(height, width) / 3000)
    for disc in discs:
        colour = USED_BGR if disc.usable else FLAGGED_BGR
        points = np.round((disc.outline_xy + 0.5) * (1 << _SHIFT)).astype(np.int32)
        cv2.polylines(canvas, [points], True, colour, thickness, cv2.LINE_AA, shift=_SHIFT)
        x = int(disc.outline_xy[:, 0].max()) + 2 * thickness
        y = int(disc.outline_xy[:, 1].min()) + int(12 * font_scale)
        cv2.putText(canvas, str(disc.index), (x, y), cv2.FONT_HERSHEY_SIMPLEX, font_scale, (0, 0, 0), 3 * thickness, cv2.LINE_AA)
        cv2.putText(canvas, str(disc.index), (x, y), cv2.FONT_HERSHEY_SIMPLEX, font_scale, colour, thickness, cv2.LINE_AA)
    return canvas
