"""What a fit returns: its options, its parameters with uncertainties, and the failure object.

A fit returns one object (lmfit ``ModelResult``, scipy ``OptimizeResult``): the
parameters, each with its value and uncertainty, and the evidence. When nothing
could be fitted it returns a :class:`FailedFit` instead (scikit-image's
``FailedEstimation``): falsy, it carries the reason, converts to JSON with its
status, and raises :class:`FitFailedError` naming that reason when a fitted
field is read, rather than an ``IndexError`` or ``AttributeError`` far from the cause.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from bokehfit.errors import InputError, NoResultError

__all__ = ["FitOptions", "Parameter", "FailedFit", "FitFailedError", "STATUSES"]

#: The outcomes of ``compare`` (design.md §7b), best first.
STATUSES = ("fitted", "unsure", "no_fit", "no_discs")


class FitFailedError(NoResultError):
    """A field of a failed fit was read; the message says why the fit failed."""


@dataclass(frozen=True)
class FitOptions:
    """The fit's budget and thresholds, passed explicitly to :func:`bokehfit.fit.fit_aperture`.

    Parameters
    ----------
    max_discs : int
        Most discs fitted, the largest and clearest first (the time budget: the
        fit's time grows about linearly with it).
    shortlist : int
        Families fitted to pixels after the outline screen (the circle always is too).
    model_discs : int
        Discs on which the shortlisted families compete; the winner is then fitted to all.
    sure_delta_bic_per_disc : float
        Below this BIC margin per disc between the best and the runner-up the choice is unsure.
    """

    max_discs: int = 12
    shortlist: int = 3
    model_discs: int = 4
    sure_delta_bic_per_disc: float = 10.0

    def __post_init__(self):
        for name in ("max_discs", "shortlist", "model_discs"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise InputError(f"{name} must be an integer of at least 1 (got {value!r})")
        value = self.sure_delta_bic_per_disc
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
            raise InputError(f"sure_delta_bic_per_disc must be a finite number of at least 0 (got {value!r})")


@dataclass(frozen=True)
class Parameter:
    """One fitted quantity: its value and its standard uncertainty (None where not estimated).

    A feature with members (``vignetting``) has a dict of values and a dict of uncertainties.
    """

    name: str
    value: float | dict | None
    uncertainty: float | dict | None = None

    def to_json(self, digits: int = 3) -> dict:
        return {"value": _round(self.value, digits), "uncertainty": _round(self.uncertainty, digits)}


def _round(value, digits: int):
    if isinstance(value, dict):  # a feature with members (vignetting: radius and shift)
        return {key: _round(member, digits) for key, member in value.items()}
    if value is None or not math.isfinite(value):
        return None
    return round(float(value), digits)


@dataclass(frozen=True)
class FailedFit:
    """A fit that found nothing to fit: falsy, with ``status`` and ``reason``.

    Reading a fitted field (``aperture``, ``family``, ``diameter_px``, ...) raises
    :class:`FitFailedError` with the reason.

    Examples
    --------
    >>> fit = FailedFit("no_discs", "no disc is clean enough to fit (none found)")
    >>> bool(fit)
    False
    >>> fit.to_json()["status"]
    'no_discs'
    """

    status: str
    reason: str
    candidates: list = field(default_factory=list)  #: the models tried (none)
    disc_fits: list = field(default_factory=list)
    time_s: float = 0.0
    #: Seconds by step of the fit (``ApertureFit.timing_s``'s keys, those reached).
    timing_s: dict = field(default_factory=dict)
    success = False
    sure = False

    def __post_init__(self):
        if self.status not in STATUSES[2:]:
            raise InputError(f"status of a failed fit must be one of {', '.join(STATUSES[2:])} (got {self.status!r})")

    def __bool__(self) -> bool:
        return False

    @property
    def message(self) -> str:
        return self.reason

    def __getattr__(self, name: str):
        # Only reached for names the failure does not have: the fitted fields.
        if name.startswith("_"):
            raise AttributeError(name)
        raise FitFailedError(f"no aperture was fitted, so it has no {name}: {self.reason}")

    def disc_fit(self, disc):
        """No disc was fitted."""
        return None

    def disc_item(self, disc):
        """No disc was fitted."""
        return None

    rejected: dict = field(default_factory=dict)  #: discs set aside (index → reason): outlines no aperture explains

    def to_json(self) -> dict:
        return {"status": self.status, "reason": self.reason, "candidates": []}
