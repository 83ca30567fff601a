"""Why there is no disc: the :class:`Reason` a measurement, a place or a candidate is not one, and
:class:`NoDisc`, what a measurement returns instead of a :class:`bokehfit.discs.verdict.Measurement`.

A measurement answers ``Measurement | NoDisc``; callers tell them apart with
``isinstance(m, NoDisc)`` and compare reasons by member (``m.reason is Reason.FAINT``), never by
their words. The words are what leaves the package: a :class:`bokehfit.discs.Rejection`'s
``rejected_because`` and the keys of a search's ``rejected`` counts are ``str(why)``, the
member's value (the words before there were members) or, for a :class:`NoDisc` with numbers, its
``detail``. The tests of a disc are in :mod:`bokehfit.discs.verdict`'s Notes, the outline's in
:mod:`bokehfit.discs.outlines`'; ``docs/discs.md`` lists them all.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

__all__ = ["Reason", "NoDisc"]


class Reason(str, Enum):
    """Why a candidate, a place or a circle is no disc. Each member is its words (``str``, JSON and
    f-strings give the value, as :class:`enum.StrEnum` does from Python 3.11)."""

    # The outline (bokehfit.discs.outlines; the rays' trace, bokehfit.discs.rays).
    #: No background around it in the frame (it fills the frame).
    NO_SURROUND = "no surround"
    #: No closed 50 % contour around the centre (along rays: no step seen around it).
    NO_OUTLINE = "no outline"
    #: Cut out of a bright region, its outline mostly the cutting circle.
    PART_OF_LARGER_REGION = "part of a larger region"

    # The tests of a disc (bokehfit.discs.verdict).
    #: Equal-area diameter below the minimum sought.
    TOO_SMALL = "too small"
    #: Saturated, and the clipping goes on past its outline.
    IN_CLIPPED_REGION = "in a clipped region"
    #: The plateau does not stand out of the surround's noise and contrast floors.
    FAINT = "faint"
    #: The edge is wide for the size (a glint, a smooth blob, a glow: no step).
    SOFT_EDGE = "soft edge"
    #: Its minimum-area rectangle's sides differ too much.
    ELONGATED = "elongated"
    #: The widest circle inside it is thin for its area: a streak.
    LINE_LIKE = "line-like"
    #: Its area over its convex hull's is low: edges, branches, texture.
    NOT_COMPACT = "not compact"

    # A place (bokehfit.discs.places).
    #: The place lies outside the frame.
    OUTSIDE_PHOTO = "outside the photo"
    #: The outline there is of another size or place (its detail says which).
    NOT_THE_DISC_ASKED = "not the disc asked for"

    # The search (bokehfit.discs.search).
    #: Equal-area diameter above the maximum sought.
    TOO_LARGE = "too large"
    #: The candidate lies inside a larger disc's outline: its light.
    INSIDE_LARGER_DISC = "inside a larger disc"
    #: A cluster candidate that splits into no discs (one disc and its glow).
    NOT_A_CLUSTER = "not a cluster"
    #: A cluster candidate past MAX_CLUSTER_CANDIDATES, not measured.
    BEYOND_CLUSTER_LIMIT = "beyond the cluster limit"
    #: A candidate past MAX_CANDIDATES, not measured.
    BEYOND_CANDIDATE_LIMIT = "beyond the candidate limit"

    __str__ = str.__str__
    __format__ = str.__format__


@dataclass(frozen=True)
class NoDisc:
    """No disc here, and why: falsy, as a failed estimate is.

    ``detail`` is the reason in words with the numbers measured, where there are some; ``str()`` gives
    it, else the reason's words.
    """

    reason: Reason
    detail: str | None = None

    def __bool__(self) -> bool:
        return False

    def __str__(self) -> str:
        return self.reason.value if self.detail is None else self.detail
