"""The one conversion between the image's frame and the aperture's (design.md §2).

Images are indexed (row, col), row downward; the aperture plane is (x, y), y
up. :func:`image_to_aperture` and :func:`aperture_to_image` convert offsets,
:func:`aperture_rows_to_image` the row order of a grid; nothing else flips axes.
"""

from __future__ import annotations

import numpy as np

__all__ = ["aperture_rows_to_image", "aperture_to_image", "image_to_aperture"]


def image_to_aperture(offsets_rc) -> np.ndarray:
    """Image offsets (row, col) from a centre → aperture-frame (x, y): x = col, y = −row (design.md §2).

    The one conversion from the image's row-down frame to the aperture's y-up frame.

    Examples
    --------
    >>> image_to_aperture([[2.0, 3.0]])
    array([[ 3., -2.]])
    """
    offsets = np.asarray(offsets_rc, dtype=np.float64)
    return np.stack([offsets[..., 1], -offsets[..., 0]], axis=-1)


def aperture_to_image(points_xy) -> np.ndarray:
    """Inverse of :func:`image_to_aperture`: aperture (x, y) → image offsets (row, col) = (−y, x)."""
    points = np.asarray(points_xy, dtype=np.float64)
    return np.stack([-points[..., 1], points[..., 0]], axis=-1)


def aperture_rows_to_image(grid) -> np.ndarray:
    """A grid whose rows run up in aperture y (first row lowest) → image row order (row downward).

    The row-order face of :func:`aperture_to_image` (image row = −y): for
    kernels computed or rasterised on the aperture frame's y-up grid.

    Examples
    --------
    >>> aperture_rows_to_image([[0, 1], [2, 3]])
    array([[2, 3],
           [0, 1]])
    """
    return np.ascontiguousarray(np.flip(np.asarray(grid), axis=0))
