"""Large candidates measured at the scale their outline needs: on the photo area-averaged.

Notes
-----
A candidate's measurement (:func:`bokehfit.discs.measure.measure_candidate`) works on windows of
about 3.4 times its radius a side, grown while its outline runs into them: its work grows with the
square of its size. A disc's outline and levels need no more than a few hundred pixels of outline
to be drawn well: from ``2 · MEASURE_SIDE_PX`` on, a blob candidate of the search is measured on
the photo area-averaged by ``k = ⌊D / MEASURE_SIDE_PX⌋`` (``k × k`` pixels a pixel), where it is
``MEASURE_SIDE_PX`` to ``2 · MEASURE_SIDE_PX`` across, and its measurement is put back in the
photo's pixels (:meth:`bokehfit.discs.verdict.Measurement.enlarged`). The fit measures every disc
afresh on the photo's own pixels; a person's places (``compare --discs``) and the circles through
edges are measured at full resolution.

What the copy changes: the surround's noise is that of the averaged pixels (white noise falls k
times, texture at the disc's scale does not), so ``snr`` is the disc's at the scale it was measured;
a copy pixel is clipped where any of its pixels is; the last ``k − 1`` rows and columns of the photo
(the remainder of its size over ``k``) are not in the copy, so a disc that reaches that strip is
cut by the copy's frame there.

Measured on the 17 reference photos (``benchmarks/RESULTS.md``, 2026-11-29): the search 6–7 % less
CPU, recall of the labelled discs 135 → 136 of 268, the same answers but one (photo 11: a third disc
fitted, unsure → fitted, right); at ``MEASURE_SIDE_PX`` = 96 (k = 2 from 192 px) 13 % less, but the
fitted rims of photos 04 and 07 moved (+0.38 → +0.34 and +0.26): which discs the fit takes first, and
what their measurement says of them, starts it.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["PhotoScales", "MEASURE_SIDE_PX", "averaged"]

#: A candidate is measured on the photo area-averaged by ⌊D / MEASURE_SIDE_PX⌋ where that is 2 or more.
MEASURE_SIDE_PX = 128.0


class PhotoScales:
    """A photo's luminance and clipping with an area-averaged copy, made when asked for and kept until
    another is (one search's, dropped with it). The search measures its candidates largest first, so the
    factors it asks for only fall: each copy is made once, and one at a time is held (at most a quarter
    of the photo's pixels)."""

    def __init__(self, luminance: np.ndarray, clipped: np.ndarray | None):
        self.luminance = luminance
        self.clipped = clipped
        self._copy: tuple[int, np.ndarray, np.ndarray | None] | None = None

    @staticmethod
    def factor(diameter_px: float) -> int:
        """The averaging a candidate of ``diameter_px`` is measured at (1: the photo itself)."""
        return max(1, int(diameter_px // MEASURE_SIDE_PX))

    def at(self, factor: int) -> tuple[np.ndarray, np.ndarray | None]:
        """The luminance and clipping averaged ``factor`` × ``factor`` (the photo's own at 1)."""
        if factor <= 1:
            return self.luminance, self.clipped
        if self._copy is None or self._copy[0] != factor:
            self._copy = None  # the last copy goes before the next is made
            height, width = (side // factor for side in self.luminance.shape)
            copy = averaged(self.luminance, factor)
            clipped = None
            if self.clipped is not None:
                blocks = self.clipped[: height * factor, : width * factor].reshape(height, factor, width, factor)
                clipped = blocks.any(axis=(1, 3))
            self._copy = (factor, copy, clipped)
        return self._copy[1], self._copy[2]

    @staticmethod
    def to_copy(xy: tuple[float, float], factor: int) -> tuple[float, float]:
        """A point of the photo in the pixels of the copy averaged by ``factor``."""
        shift = 0.5 * (factor - 1)
        return ((xy[0] - shift) / factor, (xy[1] - shift) / factor)


def averaged(image: np.ndarray, factor: int) -> np.ndarray:
    """``image`` (rows and columns first; channels after, if any) area-averaged ``factor`` × ``factor``: its pixel
    (r, c) the mean of the image's block from (factor · r, factor · c), the rows and columns past the last whole block
    left out. A view is read (OpenCV reads its rows where they lie): no temporary the size of the image."""
    height, width = (side // factor for side in image.shape[:2])
    whole = image[: height * factor, : width * factor].astype(np.float32, copy=False)
    return cv2.resize(whole, (width, height), interpolation=cv2.INTER_AREA)
