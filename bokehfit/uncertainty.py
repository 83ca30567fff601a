"""A measured value and its uncertainty for people: whether it is a measurement, and how it is written.

``value ± uncertainty`` is written with the uncertainty to two significant digits and the value
to match (:func:`plus_minus`); a value whose uncertainty (one standard deviation) exceeds it is
"not measurable" (:func:`measurable`), and the reason says so with the numbers behind it
(:func:`unmeasurable_reason`). The f-stop (:mod:`bokehfit.optics`) and the words of a result
(:mod:`bokehfit.words`) both use these, so this module imports no other bokehfit module.
"""

from __future__ import annotations

import math

__all__ = ["measurable", "plus_minus", "unmeasurable_reason"]


def measurable(value: float | None, uncertainty: float | None) -> bool:
    """Whether a value is a measurement: its uncertainty (one standard deviation) does not exceed it."""
    return value is None or uncertainty is None or (math.isfinite(uncertainty) and uncertainty <= abs(value))


def unmeasurable_reason(shown: str, uncertainty: float, why: str) -> str:
    """The reason a value is "not measurable", in words, with the numbers behind it."""
    return f"not measurable: {shown} ± {_significant(uncertainty)}, an uncertainty larger than the value ({why})"


def _significant(uncertainty: float) -> str:
    return f"{uncertainty:.{_decimals(uncertainty)}f}"


def _decimals(uncertainty: float | None, least: int = 2) -> int:
    """Decimals for a value with this uncertainty: ``least``, more for an uncertainty under 0.01 (its first
    significant digit shows), fewer for one of 1 and more (two significant digits)."""
    if uncertainty is None or not uncertainty > 0 or not math.isfinite(uncertainty):
        return least
    if uncertainty >= 1.0:
        return max(0, min(least, 1 - math.floor(math.log10(uncertainty))))
    return max(least, min(6, -math.floor(math.log10(uncertainty))))


def plus_minus(value: float, uncertainty: float | None, digits: int = 2, unit: str = "") -> str:
    """``value ± uncertainty`` for people: the uncertainty to two significant digits and the value to match;
    the value alone where there is no uncertainty (never "± 0.00")."""
    if uncertainty is None or not uncertainty > 0:
        return f"{value:.{digits}f}{unit}"
    decimals = _decimals(uncertainty, digits)
    return f"{value:.{decimals}f} ± {uncertainty:.{decimals}f}{unit}"
