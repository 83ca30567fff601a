"""The physical ranges of bokehfit's numeric parameters, and the one check that enforces them.

Every public entry point (``render_kernel``, ``bokehfit.scene.render``,
``make_lens``, the ``bokehfit.optics`` functions) and every command-line
option of the same quantity goes through :func:`check` with an entry of
``RANGES`` (the options through the argparse types of
:mod:`bokehfit.cli.arg_types`), so the Python API and the command line accept
the same values and refuse the rest with the same message, naming the
parameter (the keyword, or the option on the command line) and the range::

    --focal-length-mm must be a finite number in [1, 10000] mm (got 1e-300)

Each range carries its reason: a physical bound where one exists (no lens is
shorter than 1 mm), otherwise the bound of the arithmetic behind it (float32
rays on the GPU, u32 sample indices, the double-precision exponent).

Examples
--------
>>> check("fstop", 2.8)
2.8
>>> check("spp", 0, name="--spp")
Traceback (most recent call last):
...
bokehfit.errors.InputError: --spp must be an integer in [1, 65536] (got 0)
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from bokehfit.errors import InputError

__all__ = ["Range", "RANGES", "check"]


@dataclass(frozen=True)
class Range:
    """An accepted interval of one quantity, with its unit and the reason for its bounds."""

    low: float
    high: float
    unit: str = ""
    reason: str = ""
    low_open: bool = False  #: the low bound itself is refused
    integer: bool = False
    allow_inf: bool = False  #: +inf is accepted as well (a light at infinity)

    def describe(self) -> str:
        """What is expected, e.g. ``a finite number in (0, 1e+06] m or inf``."""
        left = "(" if self.low_open else "["
        low, high = (f"{int(self.low)}", f"{int(self.high)}") if self.integer else (f"{self.low:g}", f"{self.high:g}")
        interval = f"{left}{low}, {high}]" + (f" {self.unit}" if self.unit else "")
        if self.integer:
            return f"an integer in {interval}"
        return f"a number in {interval} or inf" if self.allow_inf else f"a finite number in {interval}"

    def contains(self, number: float) -> bool:
        if self.allow_inf and number == math.inf:
            return True
        if not math.isfinite(number) or number > self.high:
            return False
        return number > self.low if self.low_open else number >= self.low


#: The one table of accepted ranges (keys are the Python parameter names).
RANGES: dict[str, Range] = {
    "focal_length_mm": Range(1.0, 10000.0, "mm", "phone lenses (about 2 mm) to the longest telescope lenses used as camera lenses"),
    "sensor_width_mm": Range(1.0, 300.0, "mm", "the smallest phone sensors to 8×10-inch film (254 mm)"),
    "fstop": Range(0.1, 10000.0, "", "below f/0.1 the aperture is wider than any scene; above f/10000 the lens is a pinhole"),
    "fitted_fstop": Range(0.5, 1000.0, "", "the fastest camera lenses are about f/0.7; pinhole cameras reach f/500: a fit outside is wrong geometry"),
    "focus_distance_m": Range(1e-3, 1e6, "m", "1 mm (macro) to 1000 km; beyond, float32 rays lose the focus plane"),
    "light_distance_m": Range(
        0.0, 1e20, "m", "anywhere in front of the lens (a star is 1e16 m away); inf for a light at infinity", low_open=True, allow_inf=True
    ),
    "coc_mm": Range(0.0, 1000.0, "mm", "a blur disc larger than 1 m on the sensor is no lens's", low_open=True),
    "exposure_ev": Range(-30.0, 30.0, "EV", "±30 stops spans moonlight to sunlight on snow; 2^EV stays a normal float32"),
    "angle_deg": Range(-1e9, 1e9, "°", "any rotation; beyond ±1e9° a double keeps less than 1e-7° of the angle"),
    "diameter_px": Range(0.0, 20000.0, "px", "the largest disc of a 100-megapixel frame", low_open=True),
    "tolerance": Range(0.0, 2.0, "", "L1 between two images that sum to 1 is at most 2", low_open=True),
    "kernel_size": Range(1, 8192, "px", "8192² float32 is 256 MiB; the GPU methods check their adapter's own limits", integer=True),
    "kernel_samples": Range(
        1, 46340**2, "", "46340² is the largest square grid of samples whose index stays below 2³¹ (u32 with a stride)", integer=True
    ),
    "spp": Range(1, 2**16, "", "at 65536 spp the noise is 0.4 % of one sample's; more is a day's render on a CPU adapter", integer=True),
    "image_side_px": Range(1, 16384, "px", "pixel indices, the RNG stream and float32 pixel positions stay exact", integer=True),
    "seed": Range(0, 2**32 - 1, "", "the RNG hashes a u32 seed", integer=True),
    "blades": Range(3, 64, "", "beyond 64 blades an ngon is a circle for every purpose", integer=True),
    "aspect": Range(1e-3, 1e3, "", "a slit thinner than 1:1000 is a line"),
    "roundness": Range(0.0, 1.0, "", "R/ρ of the blade arcs (design.md §3b): 0 straight edges, 1 the circle"),
    "squeeze": Range(1e-3, 1e3, "", "anamorphic lenses squeeze 1.33 to 2; beyond 1:1000 the disc is a line"),
    "rim": Range(-1.0, 1.0, "", "the profile 1 + rim·(2ρ² − 1) stays non-negative only for |rim| ≤ 1"),
    "vignetting_radius": Range(
        1.0, 1e3, "", "in units of the unit-area disc's radius: below 1 the barrel would cut the disc at the image centre; 1000 cuts nothing"
    ),
    "vignetting_shift": Range(-1e3, 1e3, "", "barrel offset per unit field position; real lenses are within ±3, ±1000 leaves the float32 rays room"),
    "chromatic": Range(-0.5, 0.5, "", "longitudinal colour changes a channel's disc by a few per cent; ±50 % is no lens's"),
    "field_position": Range(-10.0, 10.0, "", "the frame's corners are at |q| = 1 (half-diagonal units); a margin for discs centred off the frame"),
    "min_diameter_px": Range(1.0, 20000.0, "px", "a disc smaller than a pixel has no shape"),
    "max_diameter_px": Range(1.0, 20000.0, "px", "the largest disc of a 100-megapixel frame"),
    "max_time_s": Range(0.0, 1e7, "s", "a bound on the estimated time of one render (about 4 months); inf: no bound", low_open=True, allow_inf=True),
}


def _refused(rule: Range, name: str, value) -> InputError:
    """The error that names what ``name`` must be and what it got (made only when a value is refused)."""
    return InputError(f"{name} must be {rule.describe()} (got {value!r})")


def check(quantity: str, value, *, name: str | None = None, high: float | None = None):
    """``value`` as a float (or int) inside ``RANGES[quantity]``, or ``InputError`` naming ``name``.

    Parameters
    ----------
    quantity : str
        Key of ``RANGES``.
    value : object
        What the caller gave: a real number (bools and text are refused), or
        for integer quantities an ``int`` or NumPy integer.
    name : str, optional
        The parameter's name in the message (default ``quantity``): a keyword
        in Python, an option such as ``--spp`` on the command line.
    high : float, optional
        A tighter upper bound than the table's, e.g. an adapter's limit.

    Returns
    -------
    float or int
    """
    rule = RANGES[quantity]
    if high is not None and high < rule.high:
        rule = Range(rule.low, high, rule.unit, rule.reason, rule.low_open, rule.integer, rule.allow_inf)
    name = name or quantity
    if isinstance(value, (bool, np.bool_)):
        raise _refused(rule, name, value)
    if rule.integer:
        if not isinstance(value, (int, np.integer)) or not rule.contains(float(value)):
            raise _refused(rule, name, value)
        return int(value)
    if not isinstance(value, numbers.Real):  # int, float, NumPy scalars; not text (bokehfit.cli.arg_types parses that)
        raise _refused(rule, name, value)
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        raise _refused(rule, name, value) from None
    if not rule.contains(number):
        raise _refused(rule, name, value)
    return number
