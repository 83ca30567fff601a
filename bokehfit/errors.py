"""Errors that bokehfit reports to people, and the checks that raise them.

``InputError`` (a ``ValueError``) is bad input or usage: the command line maps it
to exit code 2. ``NoResultError`` means the input was fine but gave no
acceptable result: exit code 1. Messages are one line and name the fix.
"""

from __future__ import annotations

import math

__all__ = ["BokehfitError", "InputError", "NoResultError", "GPUUnavailableError", "check_finite", "check_positive"]


class BokehfitError(Exception):
    """Base class of errors that carry a one-line message for people."""

    exit_code = 2


class InputError(BokehfitError, ValueError):
    """The input or a parameter is unusable (exit code 2)."""


class NoResultError(BokehfitError):
    """The input was read but gave no acceptable result (exit code 1)."""

    exit_code = 1


class GPUUnavailableError(BokehfitError, RuntimeError):
    """No GPU or software adapter could be opened (exit code 2)."""


def check_finite(name: str, value) -> float:
    """``value`` as a float, or ``InputError`` naming ``name`` if it is not a finite number."""
    if isinstance(value, bool):
        raise InputError(f"{name} must be a finite number (got {value!r})")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a finite number (got {value!r})") from None
    if not math.isfinite(number):
        raise InputError(f"{name} must be a finite number (got {value!r})")
    return number


def check_positive(name: str, value) -> float:
    """``value`` as a float, or ``InputError`` if it is not finite and > 0."""
    number = check_finite(name, value)
    if number <= 0.0:
        raise InputError(f"{name} must be greater than 0 (got {value!r})")
    return number
