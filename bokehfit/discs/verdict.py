"""Judge a closed outline: the disc's size, centre and shape, which of its outline is its own,
its flags, and whether it is a disc (a :class:`Measurement`).

Notes
-----
A candidate is kept as a disc when all of these hold (the rejection reasons, each a
:class:`bokehfit.discs.reasons.Reason`; those of a candidate that has no outline are
:mod:`bokehfit.discs.outlines`'s):

``too small``       equal-area diameter below the minimum (default 4 px);
``faint``           plateau contrast ``p − b`` below ``MIN_SNR`` local noise levels,
                    below ``MIN_CONTRAST_ABS`` (linear) or below
                    ``MIN_CONTRAST_REL`` of the background;
``soft edge``       the edge is wide for the size: the edge width, contrast over
                    the median gradient along the outline (its squared magnitude
                    less the share the crop's white pixel noise adds to it: noise
                    steepens a soft edge's slope, and made faint glows read
                    sharp), exceeds
                    ``max(EDGE_WIDTH_MIN_PX, EDGE_WIDTH_MAX_REL · r)``. A flat disc
                    blurred by b px has 2.5 b; an in-focus glint or a smooth
                    blob (Gaussian: 1.44 r) much more. Measured on the outline,
                    it is not fooled by neighbouring discs. One at most
                    ``SOFT_EDGE_WIDTH_MAX_REL · r`` wide that passes the tests
                    below is a soft-edged disc (:func:`soft_edged`), which the
                    search keeps as second-tier evidence;
``not compact``     solidity (area over convex-hull area) below ``MIN_SOLIDITY``
                    (the star has 0.68): edges, branches, texture;
``in a clipped region``  saturated, and the clipping goes on past its outline
                    (more than ``MAX_CLIPPED_RING_SHARE`` of a 2-px ring);
``elongated``       the minimum-area rectangle's sides differ by more than
                    ``MAX_ELONGATION`` (a slit of aspect 0.26 still passes);
``line-like``       the widest circle inside the blob has a radius below
                    ``MIN_THICKNESS_REL`` of the equal-area radius: a thin streak,
                    straight or curved (a glint on water, a lit stem), which a
                    minimum-area rectangle does not call elongated when it bends.

What a kept disc offers (for the fit that comes later):

- **Saturated discs** keep their outline: the 50 % level lies between the
  background and the clipped plateau, where the disc meets the background,
  so the clipping moves it little. ``clipped_share`` is the share of the disc's
  area clipped in the source. Outline points whose outside (2 px out) is
  clipped too are not reliable: bloom joins the disc to other clipped light.
- **Its own outline**: the points beyond the frame, on a cutting circle or within
  ``UNSEEN_MARGIN_PX`` of bridged pixels (:mod:`bokehfit.discs.gaps`) are marked not
  seen (``outline_reliable``).
- **Ring discs**: a disc is flagged ``ring`` when the
  median of its centre (within ``RING_CENTRE_REL`` of the radius) lies below the
  plateau by more than ``RING_DIP`` of the contrast.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy import ndimage

from bokehfit.discs.contours import _deep_concavities, _edge_gradient, polygon_area_centroid
from bokehfit.discs.levels import Window, _contrast_ok, _median, pixel_noise
from bokehfit.discs.outlines import EDGE_WIDTH_MIN_PX, Outlined
from bokehfit.discs.reasons import Reason

__all__ = ["Measurement", "describe", "ring_all_round", "rim_above_centre", "soft_edged", "light_ends", "MIN_SOLIDITY",
           "MAX_ELONGATION", "MIN_THICKNESS_REL", "RING_DIP", "EDGE_WIDTH_MAX_REL", "SOFT_EDGE_WIDTH_MAX_REL"]

#: The star, the least compact aperture, has solidity 0.68.
MIN_SOLIDITY = 0.6
#: A concavity deeper than this share of the equal-area radius (and than
#: OVERLAP_DEFECT_MIN_PX) marks overlapping discs when there are 2 to 4 of them:
#: two discs make two; the star's five are its own; outline noise stays below 0.2 px.
OVERLAP_DEFECT_DEPTH = 0.04
OVERLAP_DEFECT_MIN_PX = 1.0
#: A disc whose surrounding ring has its median above its 10th percentile by
#: more than this share of the disc's contrast sits on other light (most of its
#: surround is another disc) and is flagged ``overlaps``.
MAX_RING_LIFT = 0.5
MAX_ELONGATION = 15.0
EDGE_WIDTH_MAX_REL = 0.6
#: A blob whose edge is wider than EDGE_WIDTH_MAX_REL of its radius but at most this, and that passes
#: every other test of a disc, is a soft-edged disc (:func:`soft_edged`): a Gaussian blur of 0.24–0.40 of
#: the radius, the edge of a disc whose light falls from a bright centre (spherical aberration) or of an
#: extended light's; a glow or an in-focus blob's smooth fall (a Gaussian: 1.44) lies beyond it. Glows of
#: 0.6–1.0 r exist too, so such a disc is second-tier evidence (:attr:`bokehfit.discs.Disc.soft_edge`).
SOFT_EDGE_WIDTH_MAX_REL = 1.0
#: A soft-edged disc ends (:func:`light_ends`): a disc is the aperture's image blurred, so its light is down to the
#: ground within a blur width or so of its edge (a disc blurred by 0.4 of its radius keeps 2 % of its contrast at
#: 1.8 radii), where a glow's tail goes on (a Gaussian's outline measured at its half level has 15 % there). The
#: light over SOFT_TAIL_RING (radii), its quieter quarter of RING_SECTORS sectors (a neighbour lights a side, not
#: the whole ring), above the ground (the 10th percentile over SOFT_GROUND_RING), may be at most SOFT_MAX_TAIL of
#: the disc's contrast over that ground (the 90th percentile inside half its radius).
SOFT_TAIL_RING = (1.6, 2.0)
SOFT_GROUND_RING = (2.5, 3.5)
SOFT_MAX_TAIL = 0.1
#: Share of a disc's pixels that may be clipped in the source before it counts as saturated.
SATURATED_SHARE = 0.002
#: A saturated "disc" whose surrounding ring is clipped beyond this share is a
#: piece of a larger clipped region (the sun, a window), not a disc.
MAX_CLIPPED_RING_SHARE = 0.3
#: Line-like: the largest inscribed circle's radius over the equal-area radius. A disc has
#: about 1, the slit of aspect 0.3 (the thinnest aperture) 0.27, a rectangle of sides 1:a
#: 0.886/√a, so 0.2 refuses streaks longer than about 20 times their width.
MIN_THICKNESS_REL = 0.2
#: Outline points within this distance (px) of bridged or cut-off pixels are not seen.
UNSEEN_MARGIN_PX = 1.5
#: A disc is a ring when its centre lies below the rim by this share of the contrast.
RING_DIP = 0.25
#: The centre of a disc, for the ring test: this share of its equal-area radius; its rim, this
#: band (the blurred edge beyond it would make every disc look darker at the rim, not brighter).
RING_CENTRE_REL = 0.5
RING_RIM_REL = (0.7, 0.95)
#: A ring all round (:func:`ring_all_round`): its rim, cut into this many sectors, stands above its
#: centre by RING_DIP of the contrast in more than half of them. A lens's rim is the whole edge of
#: every disc; a drop's crescent of light or a glint on one side is not.
RING_SECTORS = 8


@dataclass(frozen=True)
class Measurement:
    """A measured blob; ``reason`` is None for a disc, else the test of a disc it fails (the module's Notes)."""

    center_xy: tuple[float, float]
    diameter_px: float
    area_px: float
    outline_xy: np.ndarray  #: (N, 2) closed sub-pixel outline, (x, y) = (column, row)
    plateau: float
    background: float
    snr: float
    solidity: float
    elongation: float
    edge_width_px: float
    saturated: bool
    clipped: bool
    overlaps: bool  #: cut out of a larger bright region, or shaped like two to four merged discs
    reason: Reason | None
    #: Per outline point: True where the outline is the disc's own edge and reliable (not the
    #: frame, a cutting circle, an occluder or clipped bloom).
    outline_reliable: np.ndarray | None = None
    clipped_share: float = 0.0  #: share of the disc's area clipped in the source
    ring: bool = False  #: rim brighter than the centre (soap-bubble disc)
    bright_centre: bool = False  #: centre brighter than the rim, edge a step below it (rim < 0)
    occluded: bool = False  #: a thin occluder bridged across the disc
    thickness: float = 1.0  #: largest inscribed radius over the equal-area radius
    #: The outline was traced along rays as the disc's own step down (:mod:`bokehfit.discs.rays`): light
    #: adds, so its seen points are the disc's edge inside other discs' light too.
    own_step: bool = False

    def enlarged(self, factor: int) -> Measurement:
        """This measurement, made on the photo area-averaged ``factor`` × ``factor``
        (:mod:`bokehfit.discs.scales`), in the photo's pixels: a copy pixel's centre c is the photo's
        factor · c + (factor − 1) / 2."""
        shift = 0.5 * (factor - 1)
        return replace(self, center_xy=(factor * self.center_xy[0] + shift, factor * self.center_xy[1] + shift),
                       diameter_px=factor * self.diameter_px, area_px=factor * factor * self.area_px,
                       outline_xy=factor * self.outline_xy + shift, edge_width_px=factor * self.edge_width_px)


def describe(luminance, clipped_mask, found: Outlined, min_noise, min_diameter_px) -> Measurement:
    """The :class:`Measurement` of a closed outline: size, shape, flags, what is seen, and the verdict."""
    window, crop, outline, levels = found.window, found.crop, found.outline, found.levels
    background, plateau, noise = levels.background, levels.plateau, levels.noise
    contrast = plateau - background
    area, cx, cy = polygon_area_centroid(outline)
    diameter = 2.0 * math.sqrt(area / math.pi)
    solidity, elongation = _solidity(outline, area), _elongation(outline)
    inside = np.zeros(crop.shape, dtype=np.uint8)
    cv2.fillPoly(inside, [np.round(outline).astype(np.int32)], 1)
    # The edge is measured where it is seen: not along a cutting circle or a filled-in arc.
    edge_points = outline[~found.on_cut] if (~found.on_cut).sum() >= 4 else outline
    # The edge's slope less the noise's share of it: noise steepens the slope a faint or soft edge shows.
    noise_px = found.pixel_noise if found.pixel_noise is not None else pixel_noise(crop)
    edge_width = contrast / max(_edge_gradient(crop, edge_points, None, noise_px, found.smoothing_px), 1e-12)
    outline_xy = outline + np.array([window.c0, window.r0], dtype=np.float64)
    off_frame = _off_frame(outline_xy, luminance.shape)
    unseen = off_frame | found.on_cut | _near(found.bridged, outline, UNSEEN_MARGIN_PX)
    clipping = _Clipping.of(clipped_mask, window, inside, area, outline)
    if clipping.bloom is not None:
        unseen |= clipping.bloom
    thickness = _thickness(inside.astype(bool), 0.5 * diameter)

    reason = None
    if diameter < min_diameter_px:
        reason = Reason.TOO_SMALL
    elif clipping.beyond:
        reason = Reason.IN_CLIPPED_REGION
    elif not _contrast_ok(contrast, noise, background, diameter):
        reason = Reason.FAINT
    elif edge_width > max(EDGE_WIDTH_MIN_PX, EDGE_WIDTH_MAX_REL * 0.5 * diameter) and not clipping.saturated:
        reason = Reason.SOFT_EDGE
    else:
        reason = _shape_reason(elongation, thickness, solidity)
    return Measurement(
        center_xy=(cx + window.c0, cy + window.r0),
        diameter_px=diameter,
        area_px=area,
        outline_xy=outline_xy,
        plateau=plateau,
        background=background,
        snr=contrast / max(noise, min_noise),
        solidity=solidity,
        elongation=elongation,
        edge_width_px=edge_width,
        saturated=clipping.saturated,
        clipped=bool(off_frame.any()),
        overlaps=_overlaps(found, diameter, contrast),
        reason=reason,
        outline_reliable=~unseen,
        clipped_share=clipping.share,
        ring=_is_ring(crop, cx, cy, diameter, contrast),
        occluded=found.bridged is not None,
        thickness=thickness,
    )


def _shape_reason(elongation: float, thickness: float, solidity: float) -> Reason | None:
    """The tests of a disc's shape, the last :func:`describe` makes: the first failed, or None."""
    if elongation > MAX_ELONGATION:
        return Reason.ELONGATED
    if thickness < MIN_THICKNESS_REL:
        return Reason.LINE_LIKE
    if solidity < MIN_SOLIDITY:
        return Reason.NOT_COMPACT
    return None


def soft_edged(m: Measurement) -> bool:
    """Whether ``m``, refused only for its soft edge, is a soft-edged disc: its edge at most
    SOFT_EDGE_WIDTH_MAX_REL of its radius wide, and the tests of its shape that :func:`describe` makes after
    the edge's passed (:func:`_shape_reason`). The tests before it (size, clipping, contrast) passed, or
    the edge would not have been the reason."""
    return (m.reason is Reason.SOFT_EDGE
            and m.edge_width_px <= max(EDGE_WIDTH_MIN_PX, SOFT_EDGE_WIDTH_MAX_REL * 0.5 * m.diameter_px)
            and _shape_reason(m.elongation, m.thickness, m.solidity) is None)


def light_ends(luminance: np.ndarray, m: Measurement) -> bool:
    """Whether the light of the disc ``m`` ends near its edge, as a defocused light's does (SOFT_MAX_TAIL's note);
    False where the frame leaves too little of the rings to tell."""
    radius = 0.5 * m.diameter_px
    window = Window.around(luminance.shape, m.center_xy, int(math.ceil(SOFT_GROUND_RING[1] * radius)) + 1)
    crop = window.of(luminance)
    cx, cy = m.center_xy[0] - window.c0, m.center_xy[1] - window.r0
    rho = _window_distance(crop.shape, cx, cy) / max(radius, 1e-9)
    ground, core = crop[(rho > SOFT_GROUND_RING[0]) & (rho < SOFT_GROUND_RING[1])], crop[rho < 0.5]
    rows, cols = np.nonzero((rho > SOFT_TAIL_RING[0]) & (rho < SOFT_TAIL_RING[1]))
    tail = _sector_medians(crop, rows, cols, cx, cy, least=3)
    if ground.size < 4 * RING_SECTORS or not core.size or len(tail) < RING_SECTORS - 2:
        return False
    base = float(np.percentile(ground, 10))
    contrast = float(np.percentile(core, 90)) - base
    return contrast > 0 and float(np.percentile(tail, 25)) - base <= SOFT_MAX_TAIL * contrast


def _solidity(outline: np.ndarray, area: float) -> float:
    """The outline's area over its convex hull's."""
    hull_area = float(cv2.contourArea(cv2.convexHull(outline.astype(np.float32))))
    return area / hull_area if hull_area > 0 else 0.0


def _elongation(outline: np.ndarray) -> float:
    """The longer side of the outline's minimum-area rectangle over the shorter."""
    (_, _), (side_a, side_b), _ = cv2.minAreaRect(outline.astype(np.float32))
    return max(side_a, side_b) / max(min(side_a, side_b), 1e-6)


def _off_frame(outline_xy: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Per outline point (photo coordinates): beyond the frame. The padded contour runs outside
    [0, size − 1] only where the frame cuts the disc."""
    height, width = shape
    off_frame = (outline_xy[:, 0] < 0.0) | (outline_xy[:, 1] < 0.0)
    off_frame |= (outline_xy[:, 0] > width - 1) | (outline_xy[:, 1] > height - 1)
    return off_frame


@dataclass(frozen=True)
class _Clipping:
    """What the source's clipping says of a disc."""

    share: float = 0.0  #: share of the disc's area clipped
    saturated: bool = False  #: more than SATURATED_SHARE of it clipped
    beyond: bool = False  #: saturated, and the clipping goes on past the outline (a larger clipped region)
    #: Per outline point of a saturated disc: where the clipping runs on past it (bloom), or None.
    bloom: np.ndarray | None = None

    @classmethod
    def of(cls, clipped_mask, window: Window, inside: np.ndarray, area: float, outline: np.ndarray) -> _Clipping:
        """The clipping of the disc ``inside`` (a mask of the window) in ``clipped_mask`` (None: none)."""
        if clipped_mask is None:
            return cls()
        blob = inside.astype(bool)
        clipped_crop = window.of(clipped_mask)
        share = float(clipped_crop[blob].sum()) / max(float(blob.sum()), 1.0)
        saturated = int(clipped_crop[blob].sum()) > max(1.0, SATURATED_SHARE * area)
        if not saturated:
            return cls(share, saturated)
        # A saturated disc's edge is where the clipping stops.
        ring = cv2.dilate(inside, np.ones((5, 5), np.uint8)).astype(bool) & ~blob
        beyond = bool(ring.any()) and clipped_crop[ring].mean() > MAX_CLIPPED_RING_SHARE
        # Bloom: where the clipping runs on past the outline, that stretch is not the disc's edge.
        return cls(share, saturated, beyond, _near(ring & clipped_crop, outline, UNSEEN_MARGIN_PX))


def _centre_and_rim(crop: np.ndarray, cx: float, cy: float, diameter: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The light of a disc's centre (within RING_CENTRE_REL of its radius) in ``crop``, and the rows and
    columns of its rim's pixels (the band RING_RIM_REL), the disc's centre at (cx, cy) in the crop."""
    from_centre = _window_distance(crop.shape, cx, cy) / max(0.5 * diameter, 1e-6)
    rows, cols = np.nonzero((from_centre >= RING_RIM_REL[0]) & (from_centre <= RING_RIM_REL[1]))
    return crop[from_centre <= RING_CENTRE_REL], rows, cols


def _is_ring(crop: np.ndarray, cx: float, cy: float, diameter: float, contrast: float) -> bool:
    """The disc's rim lies above its centre by more than RING_DIP of its contrast."""
    centre, rows, cols = _centre_and_rim(crop, cx, cy, diameter)
    return bool(centre.size and rows.size) and float(_median(crop[rows, cols]) - _median(centre)) > RING_DIP * contrast


def ring_all_round(luminance: np.ndarray, m: Measurement) -> bool:
    """The measured disc's rim stands above its centre (by RING_DIP of its contrast) in more than half
    of RING_SECTORS sectors of its circle, as :func:`_is_ring` measures the whole rim."""
    return rim_above_centre(luminance, m.center_xy, m.diameter_px, RING_DIP * (m.plateau - m.background))


def rim_above_centre(luminance: np.ndarray, center_xy, diameter: float, lift: float = 0.0) -> bool:
    """The rim of the circle (``center_xy``, ``diameter``) stands above its centre by more than ``lift`` in more
    than half of RING_SECTORS sectors (each sector's median against the centre's): :func:`ring_all_round` of a
    measured disc, or, with no lift, of a place before it is measured (what a ring all round there needs)."""
    window = Window.around(luminance.shape, center_xy, int(math.ceil(0.5 * diameter)) + 1)
    crop = window.of(luminance)
    cx, cy = center_xy[0] - window.c0, center_xy[1] - window.r0
    centre, rows, cols = _centre_and_rim(crop, cx, cy, diameter)
    if not centre.size or not rows.size:
        return False
    above = lift + float(_median(centre))
    return sum(level > above for level in _sector_medians(crop, rows, cols, cx, cy)) > RING_SECTORS / 2


def _sector_medians(crop: np.ndarray, rows: np.ndarray, cols: np.ndarray, cx: float, cy: float,
                    least: int = 1) -> list[float]:
    """The median of the pixels (``rows``, ``cols``) of ``crop`` in each of RING_SECTORS sectors around (cx, cy)
    that holds at least ``least`` of them."""
    turn = (np.arctan2(rows - cy, cols - cx) + math.pi) / (2.0 * math.pi)
    sector = np.floor(turn * RING_SECTORS).astype(int) % RING_SECTORS
    values = crop[rows, cols]
    return [float(_median(values[sector == k])) for k in range(RING_SECTORS) if (sector == k).sum() >= least]


def _overlaps(found: Outlined, diameter: float, contrast: float) -> bool:
    """Cut out of other light, shaped like two to four merged discs, or on other light."""
    depth = max(OVERLAP_DEFECT_MIN_PX, OVERLAP_DEFECT_DEPTH * 0.5 * diameter)
    # Most of its surround lifted above the rest by other light: the bright lens
    # where two discs overlap, or a disc sitting on another one.
    return (found.merged or 2 <= _deep_concavities(found.outline, depth) <= 4
            or found.levels.ring_lift > MAX_RING_LIFT * contrast)


def _window_distance(shape: tuple[int, int], cx: float, cy: float) -> np.ndarray:
    """Distance of every pixel of a crop of ``shape`` from (cx, cy)."""
    rows, cols = np.ogrid[: shape[0], : shape[1]]
    return np.hypot(cols - cx, rows - cy)


def _near(mask: np.ndarray | None, outline: np.ndarray, margin_px: float) -> np.ndarray:
    """Per outline point (crop coordinates): True within ``margin_px`` of a pixel of ``mask``.

    The distances are interpolated between the four pixels around each point, which lie within
    √2 of one another: only distances up to ``margin_px`` + 2√2 decide it, and those of pixels
    ``pad`` or more inside a box are the same as over the whole crop. So the distance
    transform is taken over the outline's box and that margin, not the crop."""
    if mask is None or not mask.any():
        return np.zeros(len(outline), dtype=bool)
    height, width = mask.shape
    rows, cols = np.clip(outline[:, 1], 0, height - 1), np.clip(outline[:, 0], 0, width - 1)
    pad = math.ceil(margin_px + 2.0 * math.sqrt(2.0)) + 2
    r0, c0 = max(0, int(rows.min()) - pad), max(0, int(cols.min()) - pad)
    r1, c1 = min(height, int(rows.max()) + pad + 1), min(width, int(cols.max()) + pad + 1)
    box = mask[r0:r1, c0:c1]
    if not box.any():  # none within pad of the outline
        return np.zeros(len(outline), dtype=bool)
    distance = ndimage.distance_transform_edt(~box)
    return ndimage.map_coordinates(distance, [rows - r0, cols - c0], order=1, mode="nearest") <= margin_px


def _thickness(blob: np.ndarray, radius: float) -> float:
    """Radius of the largest circle inside ``blob`` over the equal-area radius ``radius``."""
    if not blob.any():
        return 0.0
    inscribed = float(cv2.distanceTransform(np.pad(blob, 1).view(np.uint8), cv2.DIST_L2, 5).max())
    return inscribed / max(radius, 1e-6)
