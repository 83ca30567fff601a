"""The pixel model of a disc: its blurred unit-contrast profile, and its crop with the levels that fit the data.

Notes
-----
The model of a disc's crop is

    I(x) = b + (p − b) · (G_σ ⊗ K)(x),

with K the light of the aperture on each pixel (``bokehfit.kernels.exact``:
exact coverage, weighted by the ``rim`` profile where the aperture has one,
clipped by the ``vignetting`` at the disc's place in the frame) at centre c
and equal-area diameter d, and G_σ a Gaussian edge blur (sensor,
demosaicing, JPEG). For a profile, the background b and plateau p that fit
the data best are solved for (they enter linearly: :func:`render_disc_model`);
the fit of c, d, σ and the aperture is :mod:`bokehfit.fit.pixels`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, NamedTuple

import cv2
import numpy as np

from bokehfit.apertures import Aperture, image_to_aperture
from bokehfit.kernels.exact import coverage, coverage_slopes
from bokehfit.kernels.rim import rim_coverage, rim_coverage_slopes

if TYPE_CHECKING:
    from bokehfit.fit.pixels import PixelFit

__all__ = [
    "BLUR_RANGE",
    "RIM",
    "DiscModel",
    "disc_profile",
    "level_pixels",
    "model_window",
    "profile_slopes",
    "render_disc_model",
]

#: Edge-blur bounds, crop pixels.
BLUR_RANGE = (0.05, 6.0)
#: Sub-pixels a side for the rim profile in the fit (the edge blur hides finer detail).
RIM_FIT_SUPERSAMPLE = 3
#: Bytes of coverages a fit keeps for its next steps (:func:`disc_profile`'s ``covers``): a
#: Jacobian's blur column comes a few steps after the point it is taken at.
COVERS_BYTES = 32 << 20


class DiscModel(NamedTuple):
    """A disc's model crop with its levels (:func:`render_disc_model`)."""

    model: np.ndarray  #: flattened, the crop's size
    background: float
    plateau: float
    profile: np.ndarray  #: the blurred unit-contrast disc it is made of (:func:`disc_profile`), flattened


def disc_profile(
    aperture: Aperture,
    disc: Mapping[str, float],
    size: int,
    field_position: Sequence[float] | None = None,
    covers: dict | None = None,
) -> np.ndarray:
    """The blurred unit-contrast disc (size × size) of ``aperture``; ``disc`` holds the
    :data:`~bokehfit.fit.vector.DISC_NAMES` in crop units, the centre in crop pixel coordinates.
    ``field_position`` places a vignetted aperture.

    ``covers``, where given, is the caller's memo of the unblurred coverages by their geometry
    (aperture, size, centre, diameter, field position): a fit's steps that change only the blur
    or the levels (a Jacobian's blur column, a plateau's) reuse the coverage instead of
    integrating it again. It keeps the latest, about ``COVERS_BYTES`` in all."""
    where = None if aperture.vignetting is None else field_position
    key = (aperture, size, disc["cx"], disc["cy"], disc["diameter_px"], None if where is None else tuple(where))
    cover = None if covers is None else covers.get(key)
    if cover is None:
        scale, offset_xy = _placement(disc, size)
        if aperture.rim != 0.0:
            cover, _ = rim_coverage(aperture, scale, size, field_position=where, supersample=RIM_FIT_SUPERSAMPLE,
                                    max_chord_error=1e-4, offset_xy=offset_xy)
        else:
            cover = coverage(_outline(aperture, where, covers), scale, size, offset_xy=offset_xy)
        cover = cover.astype(np.float32)
        if covers is not None:
            covers[key] = cover
            while (len(covers) - (_OUTLINES in covers)) * cover.nbytes > COVERS_BYTES and len(covers) > 2:
                del covers[next(k for k in covers if k != _OUTLINES)]  # the oldest
    return cv2.GaussianBlur(cover, (0, 0), max(disc["blur_px"], BLUR_RANGE[0]), borderType=cv2.BORDER_REPLICATE)


def _placement(disc: Mapping[str, float], size: int) -> tuple[float, tuple[float, float]]:
    """The aperture's scale (px a unit-area unit) and its centre's offset (x, y) from the crop's centre."""
    centre = (size - 1) / 2.0
    (offset_xy,) = image_to_aperture([[disc["cy"] - centre, disc["cx"] - centre]])
    return max(disc["diameter_px"], 1e-3) * SCALE_PER_DIAMETER, (float(offset_xy[0]), float(offset_xy[1]))


#: A unit-area shape's scale per px of equal-area diameter: area (d·√π/2)² = π d²/4.
SCALE_PER_DIAMETER = math.sqrt(math.pi) / 2.0
#: The disc's parameters whose slopes :func:`profile_slopes` gives ...
SLOPED = ("cx", "cy", "diameter_px")
#: ... and the aperture's, where its outline turns whole with it (no vignetting cut).
TURN = "angle_deg"
#: ... and the aperture's parameter that a ``rim`` profile's light is linear in (its slope is the profile's shape).
RIM = "rim"
#: A quarter turn: the velocity of a point p turning about the centre is J·p per radian.
_QUARTER_TURN = np.array([[0.0, -1.0], [1.0, 0.0]])


def profile_slopes(
    aperture: Aperture,
    disc: Mapping[str, float],
    size: int,
    field_position: Sequence[float] | None = None,
    covers: dict | None = None,
) -> dict[str, np.ndarray] | None:
    """∂/∂cx, ∂/∂cy and ∂/∂diameter_px of :func:`disc_profile` (flattened, by name), ∂/∂angle_deg
    where the aperture has an angle and no vignetting cut, and ∂/∂rim where it has a ``rim``; None
    where the aperture has a ``mask``.

    The coverage's exact slopes (:func:`bokehfit.kernels.exact.coverage_slopes`; with a ``rim``, those
    of its tabulated light, :func:`bokehfit.kernels.rim.rim_coverage_slopes`) blurred as the profile
    is: the blur is linear. The outline is S·R(θ)·p₀ (the squeeze S after the turn), so
    a degree of the angle moves its points by S·J·S⁻¹·p·π/180, J a quarter turn: a flow.
    ``covers`` lends its outlines (:func:`disc_profile`)."""
    if aperture.mask is not None:
        return None
    where = None if aperture.vignetting is None else field_position
    scale, offset_xy = _placement(disc, size)
    turns = aperture.has_angle and aperture.vignetting is None
    squeeze = aperture.squeeze_matrix()
    flow = squeeze @ _QUARTER_TURN @ np.linalg.inv(squeeze) * (math.pi / 180.0) if turns else None
    outline = _outline(aperture, where, covers)
    if aperture.rim != 0.0:
        slopes = rim_coverage_slopes(aperture, scale, size, offset_xy, where, flow, RIM_FIT_SUPERSAMPLE, outline)
    else:
        slopes = coverage_slopes(outline, scale, size, offset_xy, flow=flow)
    # The offset is image_to_aperture of (cy − centre, cx − centre): linear, so its columns are the chain rule's.
    (by_cx,), (by_cy,) = image_to_aperture([[0.0, 1.0]]), image_to_aperture([[1.0, 0.0]])
    sigma = max(disc["blur_px"], BLUR_RANGE[0])
    sized = SCALE_PER_DIAMETER if disc["diameter_px"] > 1e-3 else 0.0
    raw = dict(zip(SLOPED, (by_cx[0] * slopes.by_offset_x + by_cx[1] * slopes.by_offset_y,
                            by_cy[0] * slopes.by_offset_x + by_cy[1] * slopes.by_offset_y,
                            sized * slopes.by_scale)))
    if turns:
        raw[TURN] = slopes.by_flow
    if slopes.by_rim is not None:
        raw[RIM] = slopes.by_rim
    return {name: cv2.GaussianBlur(slope, (0, 0), sigma, borderType=cv2.BORDER_REPLICATE).ravel()
            for name, slope in raw.items()}


#: Key of :func:`disc_profile`'s ``covers`` under which the outlines of the latest apertures are kept.
_OUTLINES = "outlines"
#: Outlines kept there: a fit's steps that move only a disc (its centre, size or blur) reuse the
#: aperture's outline, which for a vignetted one (the shape clipped by the barrel) costs more
#: than the coverage.
OUTLINES_KEPT = 32


def _outline(aperture: Aperture, where: tuple[float, float] | None, covers: dict | None):
    """``aperture.outline(where)``, from the memo in ``covers`` where there is one."""
    if covers is None:
        return aperture.outline(where)
    outlines = covers.setdefault(_OUTLINES, {})
    key = (aperture, None if where is None else tuple(where))
    outline = outlines.get(key)
    if outline is None:
        outline = outlines[key] = aperture.outline(where)
        if len(outlines) > OUTLINES_KEPT:
            del outlines[next(iter(outlines))]  # the oldest
    return outline

def _levels(profile: np.ndarray, data: np.ndarray) -> tuple[float, float]:
    """Background and plateau that fit ``data`` best for this profile (2×2 linear least squares)."""
    ones = 1.0 - profile
    a11, a12, a22 = float(ones @ ones), float(ones @ profile), float(profile @ profile)
    r1, r2 = float(ones @ data), float(profile @ data)
    det = a11 * a22 - a12 * a12
    if abs(det) < 1e-12:
        return float(data.mean()), float(data.mean())
    return (a22 * r1 - a12 * r2) / det, (a11 * r2 - a12 * r1) / det


def _background(profile: np.ndarray, data: np.ndarray, plateau: float) -> float:
    """The background that fits ``data`` best for this profile and a given plateau."""
    ones = 1.0 - profile
    weight = float(ones @ ones)
    return float(ones @ (data - plateau * profile)) / weight if weight > 1e-12 else float(data.min())


def render_disc_model(
    aperture: Aperture,
    disc: Mapping[str, float],
    size: int,
    data: np.ndarray,
    field_position: Sequence[float] | None = None,
    censored: np.ndarray | None = None,
    ignored: np.ndarray | None = None,
    covers: dict | None = None,
) -> DiscModel:
    """Model crop (flattened) with its levels for ``data``: a :class:`DiscModel` (model, background, plateau).

    The levels are solved for (least squares over the pixels neither censored nor ignored);
    a ``disc`` that holds ``"plateau"`` (a saturated disc) fixes the plateau
    and only the background is solved for. ``covers``: see :func:`disc_profile`.
    """
    profile = disc_profile(aperture, disc, size, field_position, covers).ravel().astype(np.float64)
    seen = level_pixels(censored, ignored)
    if "plateau" in disc:
        plateau = disc["plateau"]
        background = _background(profile[seen], data[seen], plateau)
    else:
        background, plateau = _levels(profile[seen], data[seen])
    return DiscModel(model=background + (plateau - background) * profile, background=background, plateau=plateau,
                     profile=profile)


def level_pixels(censored: np.ndarray | None, ignored: np.ndarray | None) -> np.ndarray | slice:
    """The pixels a crop's levels are solved over: neither censored nor ignored (all of them where
    neither mask is given)."""
    if censored is None and ignored is None:
        return slice(None)
    return ~(ignored if censored is None else censored if ignored is None else censored | ignored)


def model_window(fit: PixelFit, left: int, top: int, size: int) -> np.ndarray:
    """The fitted model of a disc on a full-resolution window (size × size, top-left at (left, top))."""
    disc = {"cx": fit.center_xy[0] - left, "cy": fit.center_xy[1] - top, "diameter_px": fit.diameter_px,
            "blur_px": fit.blur_px}
    profile = disc_profile(fit.aperture, disc, size, fit.field_position)
    return (fit.background + (fit.plateau - fit.background) * profile).astype(np.float32)
