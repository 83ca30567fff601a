"""Choose the discs to fit: the clearest whose outlines an aperture explains, and why the others are set aside.

A defocused light is the aperture's image, so every disc shows the same outline: a blob is fitted
only where some aperture shape, or a shape stretched by what a lens does to discs (a squeeze, a
cat-eye at the frame's edge), explains its outline (:func:`choose_discs`).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from bokehfit.discs import MIN_FIT_SEEN, USABLE_EVIDENCE, Disc
from bokehfit.fit.agreement import ELONGATED_ANGLE_SPREAD_DEG, ELONGATED_ASPECT_SPREAD, MIN_ELONGATED_DISCS
from bokehfit.fit.families import Family
from bokehfit.fit.features import VIGNETTING_MIN_FIELD
from bokehfit.fit.crop import field_position
from bokehfit.fit.signature import Ellipse, Screen, fit_ellipse, screen
from bokehfit.metrics import angle_error

__all__ = ["choose_discs", "no_disc_reason", "slit_aspect", "REGULAR_OUTLINE_MISFIT", "CATEYE_AXIS_DEG", "CHOICE_POOL",
           "MIN_SHARP_DISCS"]

#: A disc's outline is regular when some aperture shape (not an elongated one) fits it this well:
#: median radial misfit in equal-area radii. Bokeh discs of a real lens show 0.01–0.05 (noise,
#: JPEG, a little bloom); out-of-focus petals, leaves, discs cut by a blade and merged glows 0.1
#: and more. Regular discs are fitted before irregular ones, and a sure fit needs its discs'
#: median misfit at most this (bokehfit.compare).
REGULAR_OUTLINE_MISFIT = 0.08
#: A disc whose outline only an ellipse explains (to REGULAR_OUTLINE_MISFIT) is fitted where a lens
#: feature accounts for the stretch: at least MIN_ELONGATED_DISCS such discs stretched alike (angles
#: within ELONGATED_ANGLE_SPREAD_DEG, aspects within ELONGATED_ASPECT_SPREAD: a squeeze, or a slit), or
#: the cat-eye's: a disc at least VIGNETTING_MIN_FIELD from the centre whose long axis lies within
#: CATEYE_AXIS_DEG of square to the line from the centre (the barrel cuts the side away from it).
CATEYE_AXIS_DEG = 20.0
#: The discs fitted are chosen from this many times the budget (max_discs) of the clearest ones; where none of
#: those is an aperture's image (a window of in-focus raindrops, a carpet of glints), from all of them: what
#: outshines a photo's discs need not be its discs, and the reason for no fit then speaks for every disc found.
CHOICE_POOL = 4
#: Soft-edged discs (:attr:`bokehfit.discs.Disc.soft_edge`: a glow's edge can be as soft) fill the budget
#: only where at least this many sharp discs are fitted: the shape, the consensus and the lens's features
#: then stand on discs whose edges are a disc's, and a soft blob that is not the aperture's image is
#: left out as a disagreeing disc is.
MIN_SHARP_DISCS = 3


def _order_for_fit(discs: list[Disc]) -> list[Disc]:
    """The usable discs, clearest first: those on their own before those beside or on other light (fitted
    with that light left out); within each, clean ones first, then edges, then outlines seen in part; the
    largest and clearest first."""
    usable = [d for d in discs if d.usable]
    usable.sort(key=lambda d: (d.overlaps, USABLE_EVIDENCE.index(d.evidence), -d.diameter_px * min(d.snr, 50.0)))
    return usable


def _outline_class(screens: list[Screen], ellipse: Ellipse | None) -> tuple[int, float]:
    """How an aperture explains the outline, and the best non-elongated shape's misfit: class 0
    where a shape that is not elongated fits it to REGULAR_OUTLINE_MISFIT, 1 where only an elongated
    one does (a slit at the disc's own aspect, or an ellipse: a squeeze, a cat-eye), 2 where none does."""
    round_misfit = min((s.rms for s in screens if not s.family.aperture.has_aspect), default=math.inf)
    if round_misfit <= REGULAR_OUTLINE_MISFIT:
        return 0, round_misfit
    stretched = min([s.rms for s in screens] + ([ellipse.misfit] if ellipse is not None else []))
    return (1 if stretched <= REGULAR_OUTLINE_MISFIT else 2), round_misfit


def _stretch_explained(disc: Disc, ellipse: Ellipse, others: list[Ellipse], shape: tuple[int, int]) -> bool:
    """Whether a lens feature accounts for an elongated disc (CATEYE_AXIS_DEG's note): others
    stretched alike, or the cat-eye's cut at its place in the frame."""
    alike = sum(angle_error(ellipse.axis_deg, e.axis_deg, 180.0) <= ELONGATED_ANGLE_SPREAD_DEG
                and abs(ellipse.aspect - e.aspect) <= ELONGATED_ASPECT_SPREAD for e in others)
    if alike + 1 >= MIN_ELONGATED_DISCS:
        return True
    qx, qy = field_position(disc.center_xy, shape)
    if math.hypot(qx, qy) < VIGNETTING_MIN_FIELD:
        return False
    radial = math.degrees(math.atan2(-qy, qx))  # the line from the centre, in the image (y down)
    return angle_error(ellipse.axis_deg, radial + 90.0, 180.0) <= CATEYE_AXIS_DEG


def choose_discs(discs: list[Disc], families: tuple[Family, ...], max_discs: int, models: dict,
                  shape: tuple[int, int]) -> tuple[list[Disc], dict[int, str]]:
    """The discs fitted, and those set aside with the reason: the sharp discs first
    (:func:`_chosen`), then, where at least MIN_SHARP_DISCS of them are fitted and the budget
    ``max_discs`` is not full, the soft-edged ones chosen the same way to fill it; where fewer are,
    the soft-edged discs are set aside, saying so."""
    sharp = [d for d in discs if not d.soft_edge]
    soft = [d for d in discs if d.soft_edge]
    fitted, set_aside = _chosen(sharp, families, max_discs, models, shape)
    if not soft or len(fitted) >= max_discs:
        return fitted, set_aside
    if len(fitted) < MIN_SHARP_DISCS:
        why = f"its edge is soft, as a glow's may be: fitted only beside {MIN_SHARP_DISCS} sharp discs ({len(fitted)} here)"
        return fitted, {**set_aside, **{d.index: why for d in soft if d.usable}}
    more, aside = _chosen(soft, families, max_discs - len(fitted), models, shape)
    return fitted + more, {**set_aside, **aside}


def _chosen(discs: list[Disc], families: tuple[Family, ...], max_discs: int, models: dict,
            shape: tuple[int, int]) -> tuple[list[Disc], dict[int, str]]:
    """The discs fitted of ``discs``, and those set aside with the reason.

    A defocused light is the aperture's image: every disc shows the same outline. So a disc is
    fitted only where an aperture explains its outline (its own points) to REGULAR_OUTLINE_MISFIT
    of its radius: some shape, or a shape stretched by what a lens does to every disc or to those
    at the frame's edge (:func:`_stretch_explained`). Lit leaves and petals, in-focus highlights,
    patches of sky between branches, discs cut by a blade and glows run together are not, and are
    set aside with the reason, whatever their clarity. They are chosen from the CHOICE_POOL ·
    ``max_discs`` clearest (:func:`_order_for_fit`), or from all where none of those is fitted (CHOICE_POOL's
    note): discs on their own before those beside other
    light, shapes that are not elongated before elongated ones, each group in that order. The
    straight families suffice (a rounded polygon lies between its straight one and the circle) and
    keep the screen cheap; all of them, whatever shapes the fit tries. ``models`` is the fit's memo of
    model signatures (:func:`~bokehfit.fit.signature.screen`); ``shape`` the photo's (rows, columns)."""
    pool = _order_for_fit(discs)
    groups: dict[tuple[bool, int], list[Disc]] = {(False, 0): [], (False, 1): [], (True, 0): [], (True, 1): []}
    set_aside: dict[int, str] = {}
    stretched: list[tuple[Disc, Ellipse]] = []
    for n, disc in enumerate(pool):  # discs on their own come first: once max_discs of them are regular, the rest can wait
        if len(groups[False, 0]) >= max_discs:
            break
        if n == CHOICE_POOL * max_discs and (any(groups.values()) or any(_explained(stretched, shape))):
            break  # the clearest give discs to fit: the rest can wait
        screens = screen(disc.outline_xy, families, slit_aspect(disc), disc.outline_reliable, models)
        kind, misfit = _outline_class(screens, None)
        ellipse = None
        if kind != 0:
            ellipse = fit_ellipse(disc.outline_xy, disc.outline_reliable)
            kind, _ = _outline_class(screens, ellipse)
        if kind == 1 and ellipse is not None:
            stretched.append((disc, ellipse))
        elif kind == 1:
            groups[disc.overlaps, 1].append(disc)
        elif kind == 0:
            groups[disc.overlaps, 0].append(disc)
        else:
            set_aside[disc.index] = (f"no aperture shape explains its outline (misfit {misfit:.2f} of its radius, "
                                     f"at most {REGULAR_OUTLINE_MISFIT} for a disc)")
    for (disc, ellipse), explained in zip(stretched, _explained(stretched, shape)):
        if explained:
            groups[disc.overlaps, 1].append(disc)
        else:
            set_aside[disc.index] = (f"stretched (aspect {ellipse.aspect:.2f} at {ellipse.axis_deg:.0f}°) as no other "
                                     "disc is and not as a cat-eye at its place: not the aperture's image")
    order = {disc.index: i for i, disc in enumerate(pool)}
    return [disc for group in groups.values() for disc in sorted(group, key=lambda d: order[d.index])][:max_discs], set_aside


def _explained(stretched: list[tuple[Disc, Ellipse]], shape: tuple[int, int]) -> list[bool]:
    """For each elongated disc (with its ellipse), whether a lens feature accounts for its stretch
    (:func:`_stretch_explained`, against the others)."""
    return [_stretch_explained(disc, ellipse, [e for d, e in stretched if d is not disc], shape)
            for disc, ellipse in stretched]


def slit_aspect(disc: Disc) -> float:
    (_, _), (a, b), _ = cv2.minAreaRect(disc.outline_xy.astype(np.float32))
    return float(np.clip(math.sqrt(min(a, b) / max(a, b, 1e-9)), 0.02, 1.0))


def no_disc_reason(discs: list[Disc], set_aside: dict[int, str]) -> str:
    """Why no disc could be fitted: how many of ``discs`` were found, and what kept each kind out."""
    soft = sum(d.soft_edge and d.index in set_aside for d in discs)  # none fitted: fewer than MIN_SHARP_DISCS sharp
    flagged = {
        "cut by the frame": sum(d.clipped for d in discs),
        "under 8 px": sum(not d.resolvable for d in discs),
        "seen only in part": sum(d.outline_seen < MIN_FIT_SEEN for d in discs),
        "with an outline no aperture shape explains": len(set_aside) - soft,
        f"soft-edged, beside fewer than {MIN_SHARP_DISCS} sharp discs": soft,
    }
    why = ", ".join(f"{n} {what}" for what, n in flagged.items() if n)
    found = f"{len(discs)} found: {why}" if discs else "none found"
    return f"no disc is clean enough to fit ({found})"
