"""Draw found discs on the photo: each outline, coloured by use, with its index.

One vocabulary for ``discs`` and ``compare``: a disc is *usable* when it is clean
enough to fit (resolvable, within the frame, and most of its outline its own),
*used* when the fit actually used it (``compare`` only), and *rejected* otherwise. A soft-edged disc
(:attr:`bokehfit.discs.Disc.soft_edge`, the search's second tier) is outlined in dashes.
"""

from __future__ import annotations

import cv2
import numpy as np

from bokehfit.discs import Disc

__all__ = ["draw_disc_overlay", "disc_role", "ROLE_BGR", "USED_BGR", "USABLE_BGR", "FLAGGED_BGR", "LABEL_HEIGHT_REL"]

#: Outline colours (BGR), distinct for colour-blind readers too (Okabe–Ito palette):
#: discs used in the fit (bluish green), usable but not used (sky blue), and
#: rejected (vermilion: cut by the frame, too little of the outline its own, or too small).
USED_BGR = (115, 158, 0)
USABLE_BGR = (233, 180, 86)
FLAGGED_BGR = (0, 94, 213)
ROLE_BGR = {"used": USED_BGR, "usable": USABLE_BGR, "rejected": FLAGGED_BGR}
#: Label height as a fraction of the drawn image's longer side (about 14 px on a 1600-px overview).
LABEL_HEIGHT_REL = 0.009
#: Sub-pixel precision of the drawn outlines (OpenCV fixed-point shift).
_SHIFT = 4
#: A soft-edged disc's outline: dashes and gaps of this many line widths each.
DASH_WIDTHS = 4


def disc_role(disc: Disc, used: set[int] | None = None) -> str:
    """``used``, ``usable`` or ``rejected`` (``used`` only when the fitted indices are given)."""
    if used is not None and disc.index in used:
        return "used"
    return "usable" if disc.usable else "rejected"


def draw_disc_overlay(
    display_rgb: np.ndarray,
    discs: list[Disc],
    used: set[int] | None = None,
    max_side: int | None = None,
    labels: dict[int, str] | None = None,
    not_discs: list[tuple[tuple[float, float], float]] | None = None,
) -> np.ndarray:
    """BGR image (for cv2.imencode) of the photo with every disc's outline and index.

    Parameters
    ----------
    display_rgb : ndarray of shape (M, N, 3), uint8
        The photo as displayed.
    discs : list of Disc
        Outlines in the photo's pixel coordinates.
    used : set of int, optional
        Indices of the discs the fit used; without it discs are usable or rejected.
    max_side : int, optional
        Shrink the photo to this longer side first, so that lines and labels are
        sized for the picture as shown, not for the full-size photo.
    labels : dict of int to str, optional
        Text after a disc's index (``compare``: the light's distance, ``"3: 1.92 m"``).
    not_discs : list of ((x, y), diameter_px), optional
        Places asked about that are no disc (``compare --discs``): each a circle of its size with a cross at its
        centre, in the rejected colour.
    """
    canvas = cv2.cvtColor(np.ascontiguousarray(display_rgb), cv2.COLOR_RGB2BGR)
    scale = 1.0
    if max_side is not None and max(canvas.shape[:2]) > max_side:
        scale = max_side / max(canvas.shape[:2])
        # each side at least a pixel: a 16 × 100000 photo shrinks to 1 × 6144, not to nothing
        size = (max(1, round(canvas.shape[1] * scale)), max(1, round(canvas.shape[0] * scale)))
        canvas = cv2.resize(canvas, size, interpolation=cv2.INTER_AREA)
    height, width = canvas.shape[:2]
    thickness = max(1, round(max(height, width) / 1000))
    # FONT_HERSHEY_SIMPLEX is about 22 px tall at scale 1.
    font_scale = max(0.35, LABEL_HEIGHT_REL * max(height, width) / 22.0)
    labels = labels or {}
    placed: list[tuple[int, int, int, int]] = []  # the labels drawn so far, (x0, y0, x1, y1)
    for (x, y), diameter in not_discs or ():
        centre = tuple(int(round((v + 0.5) * scale * (1 << _SHIFT))) for v in (x, y))
        radius = int(round(0.5 * diameter * scale * (1 << _SHIFT)))
        arm = max(radius // 4, 3 << _SHIFT)
        cv2.circle(canvas, centre, radius, FLAGGED_BGR, thickness, cv2.LINE_AA, shift=_SHIFT)
        for dx, dy in ((arm, arm), (arm, -arm)):
            cv2.line(canvas, (centre[0] - dx, centre[1] - dy), (centre[0] + dx, centre[1] + dy), FLAGGED_BGR, thickness,
                     cv2.LINE_AA, shift=_SHIFT)
    for disc in discs:
        colour = ROLE_BGR[disc_role(disc, used)]
        outline = (disc.outline_xy + 0.5) * scale - 0.5
        points = np.round((outline + 0.5) * (1 << _SHIFT)).astype(np.int32)
        if disc.soft_edge:
            cv2.polylines(canvas, _dashes(outline, DASH_WIDTHS * thickness), False, colour, thickness, cv2.LINE_AA,
                          shift=_SHIFT)
        else:
            cv2.polylines(canvas, [points], True, colour, thickness, cv2.LINE_AA, shift=_SHIFT)
        # Hershey fonts are ASCII; the longer label where it overlaps no other, else the index alone
        texts = [f"{disc.index}: {labels[disc.index]}", str(disc.index)] if disc.index in labels else [str(disc.index)]
        for k, text in enumerate(texts):
            spot = _label_spot(text, outline, font_scale, thickness, placed, width, height, last=k == len(texts) - 1)
            if spot is not None:
                break
        (x, y), box = spot
        placed.append(box)
        cv2.putText(canvas, text, (x, y), cv2.FONT_HERSHEY_SIMPLEX, font_scale, (0, 0, 0), 3 * thickness, cv2.LINE_AA)
        cv2.putText(canvas, text, (x, y), cv2.FONT_HERSHEY_SIMPLEX, font_scale, colour, thickness, cv2.LINE_AA)
    return canvas


def _dashes(outline: np.ndarray, dash_px: float) -> list[np.ndarray]:
    """The closed ``outline`` (canvas pixels) cut into pieces ``dash_px`` long with gaps as long between them,
    as OpenCV's fixed-point polylines."""
    closed = np.vstack([outline, outline[:1]])
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(closed, axis=0).T))])
    dash = np.floor(along / max(dash_px, 1.0)).astype(int)
    fixed = np.round((closed + 0.5) * (1 << _SHIFT)).astype(np.int32)
    pieces = [fixed[dash == k] for k in np.unique(dash) if k % 2 == 0]
    return [piece for piece in pieces if len(piece) >= 2] or [fixed]


def _label_spot(text, outline, font_scale, thickness, placed, width, height, *, last):
    """Where a disc's label goes: beside the disc (right, then left, below, above) where it overlaps
    no label drawn before; ((x, y) baseline origin, box), or None (the first spot when ``last``)."""
    (w, h), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, font_scale, 3 * thickness)
    x0, x1 = int(outline[:, 0].min()), int(outline[:, 0].max())
    y0, y1 = int(outline[:, 1].min()), int(outline[:, 1].max())
    gap = 2 * thickness
    spots = [(x1 + gap, y0 + h), (x1 + gap, y1), (x0 - gap - w, y0 + h), (x0, y1 + gap + h), (x0, y0 - gap - base)]
    boxes = [(x, y - h, x + w, y + base) for x, y in spots]
    for spot, box in zip(spots, boxes):
        inside = box[0] >= 0 and box[1] >= 0 and box[2] <= width and box[3] <= height
        if inside and not any(box[0] < b[2] and b[0] < box[2] and box[1] < b[3] and b[1] < box[3] for b in placed):
            return spot, box
    return (spots[0], boxes[0]) if last else None
