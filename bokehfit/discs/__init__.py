"""Find bokeh discs in a linear-light luminance image.

:func:`find_discs` finds bright blobs above the local background
(:mod:`bokehfit.discs.candidates`), measures each with a sub-pixel 50 %
outline and keeps those that look like discs (:mod:`bokehfit.discs.measure`
states the criteria). The result is a :class:`DiscSearch`, falsy with a
``reason`` when no disc was found.

Work per photo is bounded: at most :data:`MAX_CANDIDATES` candidates are
measured (the clearest first: highest peak over the local noise), and the
result's ``notes`` say how many were found and how many were measured. The
look-ups between measured discs go through a grid of cells, so a photo with
tens of thousands of small highlights costs a few seconds, not hours.

Every disc says what it offers as evidence of the aperture's shape
(``evidence``): ``"plateau"`` a clean disc (outline and interior), ``"edge"``
its outline only (saturated, a ring with a bright rim, or a bright centre), ``"partial"`` part of
its outline (cut by the frame, crossed by an occluder, overlapping other discs,
or joined to other clipped light), with ``outline_seen``, the share of its
outline that is its own and reliable, and ``outline_reliable`` per outline
point. Discs whose outlines overlap share a ``cluster`` id; the part of each
outline that runs inside another disc is not its own. Every measured candidate
that was not kept is listed in ``rejections`` with the reason
(``rejected_because``, the words of a :class:`Reason`), and counted in ``rejected``.

The package is in rooms of one job: :mod:`bokehfit.discs.search` (:func:`find_discs` in named
steps, its limits), :mod:`bokehfit.discs.places` (:func:`measure_discs_at`, a person's places, and
the measurement at a place with its fallback along rays), :mod:`bokehfit.discs.disc` (the types
of the result, the checks of the inputs, and the making of discs from measurements); the
measurement of one candidate is :mod:`bokehfit.discs.measure`'s. This module imports and names
the public API. The constants are read at call time from the modules that hold them, not from
this one: a test that sets one sets it there (``bokehfit.discs.search.BLOB_RAYS_MIN_DIAMETER_PX``).
"""

from bokehfit.discs.disc import (
    FULL_OUTLINE_SEEN,
    MAX_LUMINANCE,
    MIN_FIT_SEEN,
    MIN_IMAGE_SIDE_PX,
    MIN_OUTLINE_SEEN,
    USABLE_EVIDENCE,
    Disc,
    DiscSearch,
    Rejection,
)
from bokehfit.discs.places import measure_discs_at
from bokehfit.discs.reasons import Reason
from bokehfit.discs.search import (
    COMPARE_MIN_DIAMETER_PX,
    DEFAULT_MAX_DIAMETER_PX,
    DEFAULT_MIN_DIAMETER_PX,
    MAX_CANDIDATES,
    MAX_CLUSTER_CANDIDATES,
    MAX_LARGE_CANDIDATES,
    find_discs,
)

__all__ = [
    "Disc",
    "DiscSearch",
    "Rejection",
    "Reason",
    "find_discs",
    "measure_discs_at",
    "DEFAULT_MIN_DIAMETER_PX",
    "COMPARE_MIN_DIAMETER_PX",
    "DEFAULT_MAX_DIAMETER_PX",
    "MAX_CANDIDATES",
    "MAX_LUMINANCE",
    "MIN_IMAGE_SIDE_PX",
    "MAX_LARGE_CANDIDATES",
    "MAX_CLUSTER_CANDIDATES",
    "FULL_OUTLINE_SEEN",
    "MIN_OUTLINE_SEEN",
    "MIN_FIT_SEEN",
    "USABLE_EVIDENCE",
]
