"""Synthetic bokeh photos with known discs, drawn with bokehfit's exact kernels.

Each disc is the exact area coverage of its aperture (at a sub-pixel centre),
scaled to its plateau brightness and added in linear light over a background;
a Gaussian edge blur (sensor, demosaicing, lens), sensor noise and clipping at
1.0 follow. The ground truth comes back with the image, so tests and
benchmarks can score the disc finder and the fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bokehfit.apertures import Aperture, image_to_aperture, make_aperture
from bokehfit.kernels.exact import coverage

__all__ = ["SyntheticDisc", "render_discs", "encode_srgb8"]

#: The default aperture of a :class:`SyntheticDisc`: the plain circle (an
#: :class:`~bokehfit.apertures.Aperture` is frozen, so one instance is shared).
CIRCLE = make_aperture("circle", 0.0)


@dataclass(frozen=True)
class SyntheticDisc:
    """One disc of a synthetic photo: where, how big, which aperture, how bright.

    Parameters
    ----------
    center_xy : tuple of float
        (column, row) of the centre, pixel-centre coordinates.
    diameter_px : float
        Equal-area diameter, pixels.
    aperture : Aperture
        The aperture drawn (:func:`~bokehfit.apertures.make_aperture`); the
        plain circle by default. The exact coverage of its outline is drawn,
        so rounded blades and squeeze show; rim, chromatic and vignetting
        (no field position is given) do not.
    side : {"far", "near"}
        Which side of focus: ``near`` shows the aperture turned by 180°
        (:meth:`Aperture.near <bokehfit.apertures.Aperture.near>`).
    brightness : float
        Plateau above the background, linear (1.0 = white).

    Examples
    --------
    >>> SyntheticDisc((60.3, 40.7), 30.0, make_aperture("hexagon", 10.0), brightness=0.6).aperture.describe()
    'hexagon 10°'
    """

    center_xy: tuple[float, float]  #: (column, row), pixel-centre coordinates
    diameter_px: float  #: equal-area diameter
    aperture: Aperture = CIRCLE
    side: str = "far"
    brightness: float = 0.8  #: plateau above the background, linear (1.0 = white)


def _stamp(image: np.ndarray, disc: SyntheticDisc) -> None:
    aperture = disc.aperture
    scale = disc.diameter_px * math.sqrt(math.pi) / 2.0
    half = math.ceil(aperture.extent() * scale) + 2
    col0, row0 = round(disc.center_xy[0]), round(disc.center_xy[1])
    # Offset of the true centre from the stamp's centre pixel, in the aperture frame (y up).
    offset = image_to_aperture((disc.center_xy[1] - row0, disc.center_xy[0] - col0))
    stamp = coverage(aperture, scale, 2 * half + 1, flip=disc.side == "near", offset_xy=tuple(offset))
    height, width = image.shape
    top, left = row0 - half, col0 - half
    r0, c0 = max(top, 0), max(left, 0)
    r1, c1 = min(top + 2 * half + 1, height), min(left + 2 * half + 1, width)
    if r0 < r1 and c0 < c1:
        image[r0:r1, c0:c1] += disc.brightness * stamp[r0 - top : r1 - top, c0 - left : c1 - left].astype(np.float32)


def render_discs(
    width: int,
    height: int,
    discs: list[SyntheticDisc],
    *,
    background: float | np.ndarray = 0.02,
    edge_blur_px: float = 0.6,
    noise_sigma: float = 0.0,
    seed: int = 0,
) -> np.ndarray:
    """Linear-light float32 (height, width) image of the discs, clipped to [0, 1].

    Parameters
    ----------
    background : float or ndarray of shape (height, width)
        Linear level under the discs (a gradient, a texture).
    edge_blur_px : float
        Standard deviation of a Gaussian blur applied to the discs.
    noise_sigma : float
        Standard deviation of additive Gaussian noise, linear units.
    """
    import cv2

    image = np.zeros((height, width), dtype=np.float32)
    for disc in discs:
        _stamp(image, disc)
    if edge_blur_px > 0:
        image = cv2.GaussianBlur(image, (0, 0), edge_blur_px, borderType=cv2.BORDER_CONSTANT)
    image += np.asarray(background, dtype=np.float32)
    if noise_sigma > 0:
        image += np.random.default_rng(seed).normal(0.0, noise_sigma, image.shape).astype(np.float32)
    return np.clip(image, 0.0, 1.0)


def encode_srgb8(linear: np.ndarray) -> np.ndarray:
    """uint8 sRGB encoding of linear values in [0, 1] (for writing test JPEGs and PNGs)."""
    from bokehfit.io.colour import srgb_encode

    encoded = srgb_encode(np.clip(linear, 0.0, 1.0))
    return np.round(encoded * 255.0).astype(np.uint8)
