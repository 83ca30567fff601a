"""A disc's crop for the pixel fit: the square of pixels around it, and which of its light is the disc's.

Notes
-----
**Other light is not the disc's.** A disc that overlaps others, or was cut
out of a larger bright region (``Disc.overlaps``), shares its crop with their
light. The pixels that are not its own are left out of its fit
(``DiscCrop.ignored``): inside its
outline, those inside another disc's outline (the overlap, where the lights
add up); outside it, beyond ``OWN_MARGIN_PX`` of the outline, those brighter
than ``FOREIGN_LEVEL`` of the disc's contrast over its background (a
neighbour, a bright region; the disc's own edge has fallen below that there).
A disc crossed by an occluder (``Disc.occluded``: a branch, a grass blade in
focus in front of it) also loses the pixels the occluder darkens: inside its
outline those below half its contrast, outside those below its background by
that much. What is left is fitted as usual: the disc's own edge and plateau fix its
shape. A disc on its own keeps its whole crop (the little light of a neighbour
that reaches it is fitted as background, as it always was).

Crops wider than ``MAX_FIT_SIDE`` px are reduced by an integer factor first
(area averaging), which keeps the cost per disc bounded and loses nothing the
shape needs. Pixels clipped in the source are marked (``DiscCrop.censored``): the
fit takes them as lower bounds (:mod:`bokehfit.fit.pixels`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np

from bokehfit.discs import Disc

if TYPE_CHECKING:
    from bokehfit.fit.pixels import PixelFit

__all__ = [
    "MAX_FIT_SIDE",
    "DiscCrop",
    "FullDisc",
    "crop_disc",
    "field_position",
]

#: Largest crop side fitted at full resolution; larger discs are reduced first.
MAX_FIT_SIDE = 36
#: A disc's own light reaches this far (px) beyond its 50 % outline (its blurred edge) ...
OWN_MARGIN_PX = 3.0
#: ... and beyond that, light brighter than this share of its contrast is another light's.
FOREIGN_LEVEL = 0.25
#: An occluder's pixels: inside the outline below this share of the contrast, outside below the
#: background by this share of it.
OCCLUDER_LEVEL = 0.5


@dataclass(frozen=True)
class FullDisc:
    """A disc's fitted place, size and edge blur at full resolution (:meth:`DiscCrop.to_full`)."""

    center_xy: tuple[float, float]  #: full-resolution (column, row)
    diameter_px: float
    blur_px: float


@dataclass(frozen=True)
class DiscCrop:
    """The pixels of one disc that the fit sees: a square crop, maybe reduced, with its censored pixels."""

    disc: Disc
    data: np.ndarray  #: flattened crop, float64
    censored: np.ndarray | None  #: flattened: True where the source is clipped (a lower bound); None if none is
    size: int
    factor: int
    corner: tuple[int, int]  #: full-resolution (left, top) of the crop
    field_position: tuple[float, float]  #: the disc's centre from the image centre, half-diagonals, y up
    turned: bool = False  #: the disc shows the aperture turned by 180° (:meth:`Aperture.near`) from the others
    #: flattened: True where the light is not the disc's (the module's Notes); None if there is none.
    ignored: np.ndarray | None = None

    @property
    def pixels(self) -> int:
        """The pixels fitted: the crop's, less those ignored."""
        return self.data.size - (0 if self.ignored is None else int(self.ignored.sum()))

    @property
    def start(self) -> dict[str, float]:
        """The disc's :data:`~bokehfit.fit.vector.DISC_NAMES` in crop units from its outline, a one-pixel blur."""
        left, top = self.corner
        return {
            "cx": (self.disc.center_xy[0] - left + 0.5) / self.factor - 0.5,
            "cy": (self.disc.center_xy[1] - top + 0.5) / self.factor - 0.5,
            "diameter_px": self.disc.diameter_px / self.factor,
            "blur_px": 0.7,
        }

    @property
    def clip_level(self) -> float | None:
        """The largest recorded value among the censored pixels (None when none is censored)."""
        return None if self.censored is None else float(np.max(self.data[self.censored]))

    def values_of(self, fit: PixelFit) -> dict[str, float]:
        """A fit's disc values in this crop's units (a start for another fit of the same disc)."""
        left, top = self.corner
        f = self.factor
        values = {
            "cx": (fit.center_xy[0] - left + 0.5) / f - 0.5,
            "cy": (fit.center_xy[1] - top + 0.5) / f - 0.5,
            "diameter_px": fit.diameter_px / f,
            "blur_px": math.sqrt(fit.blur_px**2 + (f * f - 1) / 12.0) / f,
        }
        if self.censored is not None:
            values["plateau"] = fit.plateau
        return values

    def to_full(self, values: Mapping[str, float]) -> FullDisc:
        """Crop-unit disc values → the full-resolution centre (x, y), diameter and blur."""
        left, top = self.corner
        f = self.factor
        centre = (left + (values["cx"] + 0.5) * f - 0.5, top + (values["cy"] + 0.5) * f - 0.5)
        # The area-averaging reduction adds a box blur of variance (f² − 1)/12 px².
        blur = math.sqrt(max((values["blur_px"] * f) ** 2 - (f * f - 1) / 12.0, 0.0))
        return FullDisc(center_xy=centre, diameter_px=values["diameter_px"] * f, blur_px=blur)


def field_position(center_xy: Sequence[float], shape: tuple[int, int]) -> tuple[float, float]:
    """A point's field position q (design.md §3b): from the image centre, in half-diagonals, y up."""
    height, width = shape
    half_diagonal = 0.5 * math.hypot(width, height)
    x = (center_xy[0] - (width - 1) / 2.0) / half_diagonal
    y = -(center_xy[1] - (height - 1) / 2.0) / half_diagonal
    return (x, y)


def crop_disc(luminance: np.ndarray, disc: Disc, clipped: np.ndarray | None = None,
              others: Sequence[Disc] = ()) -> DiscCrop:
    """Square crop around the disc (reduced if wide), with the clipped pixels of ``clipped`` censored
    and the light that is not the disc's ignored (``others``: the photo's other discs; module Notes)."""
    reach = float(np.max(np.hypot(*(disc.outline_xy - disc.center_xy).T)))
    half = int(math.ceil(reach * 1.25 + 3))
    factor = max(1, int(math.ceil((2 * half + 1) / MAX_FIT_SIDE)))
    half = int(math.ceil((half + 1) / factor)) * factor  # a whole number of reduced pixels
    col, row = int(round(disc.center_xy[0])), int(round(disc.center_xy[1]))
    height, width = luminance.shape
    top, left = row - half, col - half
    side = 2 * half

    def window(image: np.ndarray) -> np.ndarray:
        if top < 0 or left < 0 or top + side > height or left + side > width:
            pad = ((max(0, -top), max(0, top + side - height)), (max(0, -left), max(0, left + side - width)))
            return np.pad(image[max(0, top) : top + side, max(0, left) : left + side], pad, mode="edge")
        return image[top : top + side, left : left + side]

    crop = window(luminance).astype(np.float32)
    censored = None
    if clipped is not None:
        mask = window(clipped).astype(np.float32)
        if factor > 1:
            mask = cv2.resize(mask, (side // factor, side // factor), interpolation=cv2.INTER_AREA)
        # A reduced pixel with any clipped source pixel in it is a lower bound too.
        censored = mask.ravel() > 0.0
        if not censored.any():
            censored = None
    ignored = _foreign(crop, disc, others, (left, top)) if disc.overlaps or disc.occluded else None
    if factor > 1:
        crop = cv2.resize(crop, (side // factor, side // factor), interpolation=cv2.INTER_AREA)
        if ignored is not None:  # a reduced pixel with any foreign light in it is not the disc's
            ignored = cv2.resize(ignored.astype(np.float32), (side // factor, side // factor),
                                 interpolation=cv2.INTER_AREA) > 0.0
    return DiscCrop(
        disc=disc,
        data=crop.ravel().astype(np.float64),
        censored=censored,
        size=side // factor,
        factor=factor,
        corner=(left, top),
        field_position=field_position(disc.center_xy, luminance.shape),
        ignored=None if ignored is None or not ignored.any() else ignored.ravel(),
    )


def _foreign(crop: np.ndarray, disc: Disc, others: Sequence[Disc], corner: tuple[int, int]) -> np.ndarray | None:
    """Pixels of a full-resolution crop whose light is not the disc's (the module's Notes), or None."""
    side = crop.shape[0]
    origin = np.array(corner, dtype=np.float64)
    own = np.zeros(crop.shape, np.uint8)
    cv2.fillPoly(own, [np.round(disc.outline_xy - origin).astype(np.int32)], 1)
    margin = 2 * int(math.ceil(OWN_MARGIN_PX)) + 1
    near = cv2.dilate(own, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (margin, margin))).astype(bool)
    contrast = disc.plateau - disc.background
    foreign = ~near & (crop > disc.background + FOREIGN_LEVEL * contrast)
    if disc.occluded:  # what the occluder darkens, inside the disc and across its surround
        inside = own.astype(bool)
        foreign |= inside & (crop < disc.background + OCCLUDER_LEVEL * contrast)
        foreign |= ~near & (crop < disc.background - OCCLUDER_LEVEL * contrast)
    low, high = origin - 1.0, origin + side
    for other in others:
        if other is disc or np.any(other.outline_xy.max(axis=0) < low) or np.any(other.outline_xy.min(axis=0) > high):
            continue
        theirs = np.zeros(crop.shape, np.uint8)
        cv2.fillPoly(theirs, [np.round(other.outline_xy - origin).astype(np.int32)], 1)
        foreign |= near & cv2.dilate(theirs, np.ones((3, 3), np.uint8)).astype(bool)
    return foreign if foreign.any() else None
