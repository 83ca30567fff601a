"""Longitudinal chromatic aberration from the discs' colours (design.md §3b ``chromatic``).

Notes
-----
A lens that brings red, green and blue to focus at different distances gives
each colour its own defocus disc: the red and blue discs are larger or smaller
than the green one, and the discs show coloured rims (magenta where red and blue
are the larger, green or cyan the other way). ``chromatic`` is those diameters
over green's, minus 1.

Each fitted disc that is a clean plateau (not saturated: a clipped channel's
half level is not its disc's, nor a ring or a bright centre, whose profiles
differ between channels as much as their sizes, nor soft-edged: its half level
lies on a slope as wide as its radius, where a channel's profile moves its
outline more than a lens's colour error does) is measured in the red, green
and blue channels of the photo in linear light, as the detection measures the
luminance (:func:`bokehfit.discs.measure.outline_diameter`: background, plateau
and the equal-area diameter of the 50 % outline), and gives d_R/d_G − 1 and
d_B/d_G − 1. The photo's value is the median over the discs, its uncertainty
the median's robust standard error (1.4826 · MAD · √(π/2) / √n), and no less
than what the discs can tell: each channel's outline is read to no better than
``CHANNEL_EDGE_PX`` of its radius, so a disc of diameter d gives a ratio to
about √2 · 2 · ``CHANNEL_EDGE_PX`` / d (three or four discs can agree by chance
far more closely: a JPEG-60 copy of a photo without colour error gave blue
+0.6 % ± 0.1 % from three discs of 29–84 px). It is
reported only where at least ``MIN_DISCS`` discs measure it and one channel's
median lies ``MIN_SIGNIFICANCE`` standard errors and ``MIN_CHROMATIC`` from 0:
a lens whose colours agree to a fraction of a percent has no chromatic model.
Where the error is the discs' own spread, that spread is estimated from the n
discs themselves, and a few discs agree closely by chance far more often than a
normal distribution allows: the bar is then the same tail (that of
``MIN_SIGNIFICANCE`` normal standard deviations) of Student's t with n − 1
degrees of freedom, 9.2 errors for four discs, 4.3 for nine (a noisy copy of
reference photo 04 gave red −2.3 % ± 0.4 % from four discs; its original −2.6 %
± 1.2 % from three, and other noise −1.2 % to −2.8 %, never significant). Where
the error is what the discs' size lets a channel's edge tell (known, not
estimated), the bar is ``MIN_SIGNIFICANCE`` errors.

The discs are measured in the frame they show (the seen side); the fit turns
the sign with the rest of the aperture for a ``near`` focus side.

Limits: the channels are read from the 8-bit display (the file's own curves
undo its encoding). A JPEG with 4:2:0 chroma (most cameras' and editors')
stores colour at half resolution, so the red and blue edges follow the
luminance's in part and the values come out smaller by up to about a third
(``tests/test_chromatic.py``). Discs whose channels differ in profile as well
as size (spherochromatism: a green rim around a magenta centre) give the sizes
of their 50 % outlines, which is what their coloured rims show.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr, stdtrit

from bokehfit.apertures import Chromatic
from bokehfit.discs import Disc
from bokehfit.discs.measure import outline_diameter

__all__ = ["ChromaticMeasure", "measure_chromatic", "median_and_bar", "MIN_DISCS", "MIN_SIGNIFICANCE", "MIN_CHROMATIC",
           "CHANNEL_EDGE_PX"]

#: Fewest discs measured in all three channels for a value: four. Of three, the median absolute deviation is the
#: median disc's nearer neighbour's distance (the median disc's own is zero), so that two discs agreeing by chance
#: make the spread nil and leave the floor (CHANNEL_EDGE_PX) as the error: a noisy copy of reference photo 04 gave red
#: −1.5 %, −2.9 % and −2.85 % (the last a faint ring on a twig that noise made a plateau), "significant" against
#: the floor alone. Of four, the deviation is the mean of two discs' and reads their spread.
MIN_DISCS = 4
#: A channel's median must lie this many robust standard errors from 0 ...
MIN_SIGNIFICANCE = 3.0
#: ... and at least this far (0.5 % of the diameter: a tenth of a pixel on a 20-px disc).
MIN_CHROMATIC = 0.005
#: Least error of a channel's 50 % outline radius (px): its edge, a few pixels wide and quantised to
#: 8 bits, is located to about a tenth of a pixel.
CHANNEL_EDGE_PX = 0.1
#: The window read around a disc: this share of its diameter beyond the detection's annulus.
_WINDOW_REL = 1.0


@dataclass(frozen=True)
class ChromaticMeasure:
    """What the discs' colours say: the value, its uncertainty, and how many discs gave it."""

    chromatic: Chromatic  #: median red and blue diameter ratios, minus 1
    uncertainty: Chromatic  #: one robust standard error of each
    discs: int  #: discs measured in all three channels
    significant: bool  #: the module's criteria are met: the photo shows chromatic aberration
    #: The least distance of each from 0 that the discs make significant (:func:`median_and_bar`; MIN_CHROMATIC aside).
    bar: Chromatic

    def describe(self) -> str:
        return (f"red {100 * self.chromatic.red:+.1f} % ± {100 * self.uncertainty.red:.1f}, blue "
                f"{100 * self.chromatic.blue:+.1f} % ± {100 * self.uncertainty.blue:.1f} from {self.discs} discs")

    @property
    def reason(self) -> str:
        """Why the aperture has the chromatic aberration measured, or has none, in words."""
        if self.significant:
            return f"kept: {self.describe()}"
        return (f"not kept: {self.describe()}, within what {self.discs} discs can differ by chance (|red| ≥ "
                f"{100 * max(self.bar.red, MIN_CHROMATIC):.1f} % or |blue| ≥ {100 * max(self.bar.blue, MIN_CHROMATIC):.1f} %"
                " needed)")

    def to_json(self) -> dict:
        """The measure as a trial of the ``chromatic`` feature (beside :class:`bokehfit.fit.features.FeatureTrial`'s)."""
        return {"feature": "chromatic", "kept": self.significant, "discs": self.discs,
                "value": {"red": round(self.chromatic.red, 4), "blue": round(self.chromatic.blue, 4)},
                "uncertainty": {"red": round(self.uncertainty.red, 4), "blue": round(self.uncertainty.blue, 4)},
                "reason": self.reason, "asked_because": f"{self.discs} clean discs measured in red, green and blue"}


def measure_chromatic(rgb: Callable[[slice, slice], np.ndarray], discs: Sequence[Disc],
                      shape: tuple[int, int]) -> ChromaticMeasure | None:
    """Measure the chromatic aberration of ``discs`` in the linear RGB of the photo.

    ``rgb(rows, cols)`` returns a window of the photo as linear RGB, float (h, w, 3)
    (:meth:`bokehfit.io.Photo.linear_rgb`); ``shape`` is the photo's (height, width).
    None where fewer than :data:`MIN_DISCS` discs can be measured in every channel.
    """
    height, width = shape
    ratios, readable = [], []
    for disc in discs:
        if disc.evidence != "plateau" or disc.saturated or disc.profiled or disc.soft_edge:
            continue
        half = int(math.ceil((1.7 + _WINDOW_REL) * 0.5 * disc.diameter_px + 6.0))
        col, row = int(round(disc.center_xy[0])), int(round(disc.center_xy[1]))
        r0, c0 = max(0, row - half), max(0, col - half)
        r1, c1 = min(height, row + half + 1), min(width, col + half + 1)
        window = np.asarray(rgb(slice(r0, r1), slice(c0, c1)), dtype=np.float32)
        centre = (disc.center_xy[0] - c0, disc.center_xy[1] - r0)
        sizes = _channel_diameters(window, centre, disc.diameter_px)
        if any(size is None for size in sizes):
            continue
        red, green, blue = sizes
        ratios.append((red / green - 1.0, blue / green - 1.0))
        readable.append(math.sqrt(2.0) * 2.0 * CHANNEL_EDGE_PX / green)
    if len(ratios) < MIN_DISCS:
        return None
    median, error, bar = median_and_bar(np.asarray(ratios), readable)
    significant = bool(np.any((np.abs(median) >= bar) & (np.abs(median) >= MIN_CHROMATIC)))
    return ChromaticMeasure(Chromatic(float(median[0]), float(median[1])), Chromatic(float(error[0]), float(error[1])),
                            len(ratios), significant, Chromatic(float(bar[0]), float(bar[1])))


def _channel_diameters(window: np.ndarray, centre: tuple[float, float], diameter_px: float) -> list[float | None]:
    """The disc's 50 % outline diameter in each of the window's three channels; a channel the same as
    one before it (a grey photo's) is that one's number, not measured again."""
    channels = [np.ascontiguousarray(window[..., c]) for c in range(3)]
    sizes: list[float | None] = []
    for c, channel in enumerate(channels):
        same = next((k for k in range(c) if np.array_equal(channels[k], channel)), None)
        sizes.append(sizes[same] if same is not None else outline_diameter(channel, centre, diameter_px))
    return sizes


def median_and_bar(values: np.ndarray, readable: Sequence[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The discs' median ratios (``values``: one row per disc, red and blue), the median's standard error, and the
    least distance from 0 that is significant (module Notes): MIN_SIGNIFICANCE errors where the error is what the
    discs' sizes let a channel tell (``readable``: each disc's, known), the same tail of Student's t with n − 1
    degrees of freedom where it is the spread of the n discs, estimated from them."""
    count = len(values)
    median = np.median(values, axis=0)
    spread = 1.4826 * np.median(np.abs(values - median), axis=0)
    floor = math.sqrt(float(np.mean(np.square(readable))))  # each disc's ratio errs by at least this (module Notes)
    to_error = math.sqrt(math.pi / 2.0) / math.sqrt(count)  # the median's standard error: √(π/2) that of a mean
    error = np.maximum(spread, floor) * to_error
    # Student's t quantile at the normal tail beyond MIN_SIGNIFICANCE (scipy.special: scipy.stats costs a second to load)
    estimated = float(stdtrit(count - 1, ndtr(MIN_SIGNIFICANCE))) if count > 1 else math.inf
    bar = np.maximum(estimated * spread * to_error, MIN_SIGNIFICANCE * floor * to_error)
    return median, error, bar
