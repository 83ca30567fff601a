"""A disc's edge in its own colours: lenses whose colours come to focus apart spread a disc's edge in luminance.

Notes
-----
A lens with longitudinal colour error (design.md §3b ``chromatic``) makes a red, a green and a blue disc of
different sizes for each light: each is the aperture's image, with an edge one blur wide, but their sum, the
luminance, steps down once for each over the gap between their radii (reference photo 06: red, green and blue
discs of 20, 28 and 38 px, their edges 0.2–0.5 of their radii wide, make a luminance edge as wide as its radius).
The luminance's soft-edge test (:mod:`bokehfit.discs.verdict`) takes such a disc for a glow. A glow is soft in
every colour, and its colours' outlines lie together. So a disc whose luminance edge is soft is measured again in
each colour channel of the photo by its contour (below), at the scale it was measured at
(:mod:`bokehfit.discs.scales`), and kept where

- one channel shows a disc there that passes every test of one (at its place and of about its size,
  :func:`bokehfit.discs.places._near_place`), and
- the channels' discs lie apart by at least ``MIN_COLOUR_GAP_REL`` of its radius (the largest radius less
  the smallest): a gap that spreads the luminance's edge past what a sharp disc's is (``EDGE_WIDTH_MAX_REL``
  of the radius, where a sharp disc's edge is about half that or less).

Its luminance measurement is kept: the 50 % outline of concentric images of one aperture is that aperture's
shape, and the fit reads the luminance. A channel is measured by its contour alone (its levels and 50 %
outline, :func:`bokehfit.discs.outlines._two_passes`, and the tests of a disc): the question is whether its
edge is sharp there, not what a ring or a bright centre would make of it. Discs under ``MIN_DIAMETER_PX`` are
not measured again: the gap sought is then under 1.6 px, as wide as the blur that a JPEG's colour, stored at half
resolution (4:2:0), gives the channels' edges, and the soft-edged blobs of that size on the reference photos were
glints and texture (the 225 of them measured in their colours cost 1 s of the 17 photos' search and added no
labelled disc).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from bokehfit.discs.candidates import MIN_NOISE
from bokehfit.discs.levels import Window
from bokehfit.discs.measure import Measurement, describe
from bokehfit.discs.outlines import _two_passes
from bokehfit.discs.places import _near_place
from bokehfit.discs.reasons import NoDisc
from bokehfit.discs.scales import PhotoScales, averaged
from bokehfit.errors import InputError

__all__ = ["sharp_in_a_colour", "COLOUR_WINDOW_REL", "MIN_COLOUR_GAP_REL", "MIN_DIAMETER_PX"]

#: The window read around the disc (its half side, in radii, and 8 px): the measurement's window and its
#: first growth (:data:`bokehfit.discs.outlines.WINDOW_GROWTH`) for a disc that touches its neighbours.
COLOUR_WINDOW_REL = 3.4
#: Least gap between the largest and the smallest of the channels' discs (radius less radius), over the disc's
#: radius, for its colours to account for a soft edge in luminance (module Notes).
MIN_COLOUR_GAP_REL = 0.2
#: Smallest disc (px, equal-area diameter) measured in its colours (module Notes).
MIN_DIAMETER_PX = 16.0


def sharp_in_a_colour(rgb: Callable[[slice, slice], np.ndarray], shape: tuple[int, int], m: Measurement,
                      min_diameter_px: float, factor: int = 1) -> bool:
    """Whether the disc ``m`` (measured in luminance, its edge soft) is a disc in its colours (module Notes):
    ``rgb(rows, cols)`` gives a window of the photo in linear RGB, (h, w, 3); ``shape`` is the photo's
    (height, width); ``factor`` the averaging the disc was measured at (:class:`bokehfit.discs.scales.PhotoScales`)."""
    if m.diameter_px < MIN_DIAMETER_PX:
        return False
    radius = 0.5 * m.diameter_px
    half = int(math.ceil(COLOUR_WINDOW_REL * radius + 8.0 * factor))
    window = Window.around(shape, m.center_xy, half)
    # A window of whole blocks of the copy, so that its pixels are the copy's.
    r0, c0 = -(-window.r0 // factor) * factor, -(-window.c0 // factor) * factor
    rows, cols = (window.r1 - r0) // factor, (window.c1 - c0) // factor
    if min(rows, cols) < 3:
        return False
    pixels = np.asarray(rgb(slice(r0, r0 + rows * factor), slice(c0, c0 + cols * factor)), dtype=np.float32)
    if pixels.shape != (rows * factor, cols * factor, 3):
        raise InputError(f"rgb(rows, cols) must give the window's linear RGB, {(rows * factor, cols * factor, 3)} here "
                         f"(got {pixels.shape})")
    if factor > 1:
        pixels = averaged(pixels, factor)
    centre = PhotoScales.to_copy((m.center_xy[0] - c0, m.center_xy[1] - r0), factor)
    diameter = m.diameter_px / factor
    sizes, sharp = [], False
    for channel in range(3):
        light = np.ascontiguousarray(pixels[..., channel])
        found = _two_passes(light, centre, 0.5 * diameter, 0.5 * diameter, 0.8)
        if isinstance(found, NoDisc):
            continue
        seen = describe(light, None, found, MIN_NOISE, min_diameter_px / factor)
        if _near_place(seen, centre, diameter):
            sizes.append(seen.diameter_px)
            sharp |= seen.reason is None
    return sharp and 0.5 * (max(sizes) - min(sizes)) >= MIN_COLOUR_GAP_REL * 0.5 * diameter
