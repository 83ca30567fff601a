"""A person's disc labels, and how well found discs agree with them.

The format is the reference photos' ``discs/`` labels (one JSON file per photo)::

    {"file": "NAME.jpg", "sha256": "...", "width": W, "height": H,
     "discs": [{"center_xy": [x, y], "diameter_px": D, "kind": "clean", "usable": true, "note": ""}],
     "junk":  [{"center_xy": [x, y], "size_px": S, "what": "in-focus edge"}],
     "complete_within": [[x0, y0, x1, y1]], "notes": "..."}

Coordinates are full-resolution pixels, x to the right, y down, origin at the
top-left pixel; ``diameter_px`` is the equal-area diameter of the 50 % outline.
Only ``discs[].center_xy`` and ``discs[].diameter_px`` are required: a file that
lists places to fit (``bokehfit compare --discs``) needs nothing else. ``kind``
is one of :data:`DISC_KINDS`; ``usable`` (default true) says whether a person
can read the aperture's outline from the disc. ``junk`` lists bright blobs that
are not discs, and ``complete_within`` the boxes inside which every usable disc
and every junk blob is listed (none: the lists are partial).

:func:`score_discs` matches found discs to labelled ones (:func:`matches`: the
centre within :data:`MATCH_CENTRE_REL` of the labelled diameter and the
diameters within :data:`MATCH_DIAMETER_REL`) and returns a :class:`DiscScore`:
the recall of labelled usable discs, and what the discs a fit used are.
"""

from __future__ import annotations

import json
import math
import os
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bokehfit.errors import InputError

__all__ = [
    "DISC_KINDS",
    "MATCH_CENTRE_REL",
    "MATCH_DIAMETER_REL",
    "MAX_LABELLED_DISCS",
    "LabelledDisc",
    "Junk",
    "DiscLabels",
    "DiscScore",
    "read_labels",
    "at_place",
    "matches",
    "score_discs",
]

#: The kinds of labelled disc (the labels' README): one per disc, the most important.
DISC_KINDS = ("clean", "saturated", "overlapping", "occluded", "cut_by_frame", "ring", "faint")
#: A found disc is a labelled one when its centre lies within this share of the labelled diameter ...
MATCH_CENTRE_REL = 0.25
#: ... and the two diameters differ by at most this share of the labelled one.
MATCH_DIAMETER_REL = 0.25
#: Most discs read from one file: a photo's usable discs are tens, rarely hundreds.
MAX_LABELLED_DISCS = 5000
#: Largest labels file read (bytes): 5000 discs with notes fit in well under this.
MAX_LABELS_BYTES = 8 << 20


@dataclass(frozen=True)
class LabelledDisc:
    """One disc of a person's labels."""

    center_xy: tuple[float, float]
    diameter_px: float
    kind: str = "clean"
    usable: bool = True
    note: str = ""

    def to_json(self) -> dict:
        return {"center_xy": [round(self.center_xy[0], 2), round(self.center_xy[1], 2)],
                "diameter_px": round(self.diameter_px, 2), "kind": self.kind, "usable": self.usable,
                "note": self.note}


@dataclass(frozen=True)
class Junk:
    """A bright blob that is not a bokeh disc, and what it is."""

    center_xy: tuple[float, float]
    size_px: float
    what: str = "other"


@dataclass(frozen=True)
class DiscLabels:
    """A photo's disc labels (the module's format)."""

    discs: tuple[LabelledDisc, ...]
    junk: tuple[Junk, ...] = ()
    complete_within: tuple[tuple[float, float, float, float], ...] = ()
    file: str | None = None
    sha256: str | None = None
    width: int | None = None
    height: int | None = None
    notes: str = ""

    @property
    def usable(self) -> tuple[LabelledDisc, ...]:
        """The discs a person reads the aperture from."""
        return tuple(d for d in self.discs if d.usable)

    @property
    def repeated(self) -> tuple[LabelledDisc, ...]:
        """The usable discs labelled twice: each that is the same disc as one before it in the list (at its place and
        of its size, each as the other's, :func:`matches`). A disc is one disc however often it is listed."""
        kept: list[LabelledDisc] = []
        again: list[LabelledDisc] = []
        for d in self.usable:
            same = any(matches(d.center_xy, d.diameter_px, k) and matches(k.center_xy, k.diameter_px, d) for k in kept)
            (again if same else kept).append(d)
        return tuple(again)

    @property
    def distinct_usable(self) -> tuple[LabelledDisc, ...]:
        """The usable discs, each once (:attr:`repeated` left out): what recall is counted on."""
        again = {id(d) for d in self.repeated}
        return tuple(d for d in self.usable if id(d) not in again)

    def complete_at(self, xy) -> bool:
        """True where the lists are complete (inside one of ``complete_within``)."""
        x, y = xy
        return any(x0 <= x <= x1 and y0 <= y <= y1 for x0, y0, x1, y1 in self.complete_within)

    @classmethod
    def from_json(cls, data, where: str = "the discs file") -> DiscLabels:
        """Labels from parsed JSON; ``InputError`` naming the first thing that is wrong."""
        if not isinstance(data, dict):
            raise InputError(f"{where} must hold a JSON object with a 'discs' list (got {type(data).__name__})")
        entries = data.get("discs")
        if not isinstance(entries, list):
            raise InputError(f"{where} must have a 'discs' list of {{\"center_xy\": [x, y], \"diameter_px\": D}}")
        if len(entries) > MAX_LABELLED_DISCS:
            raise InputError(f"{where} lists {len(entries)} discs; at most {MAX_LABELLED_DISCS} are read")
        discs = tuple(_disc(entry, f"{where}: discs[{i}]") for i, entry in enumerate(entries))
        junk_entries = data.get("junk") or []
        if not isinstance(junk_entries, list) or len(junk_entries) > MAX_LABELLED_DISCS:
            raise InputError(f"{where}: 'junk' must be a list of at most {MAX_LABELLED_DISCS} blobs")
        junk = tuple(_junk(entry, f"{where}: junk[{i}]") for i, entry in enumerate(junk_entries))
        boxes = data.get("complete_within") or []
        if not isinstance(boxes, list) or len(boxes) > 100:
            raise InputError(f"{where}: 'complete_within' must be a list of [x0, y0, x1, y1] boxes")
        complete = tuple(tuple(_numbers(box, 4, f"{where}: complete_within[{i}]")) for i, box in enumerate(boxes))
        size = [data.get(k) for k in ("width", "height")]
        width, height = (int(v) if isinstance(v, int) and not isinstance(v, bool) and v > 0 else None for v in size)
        text = {k: data.get(k) if isinstance(data.get(k), str) else None for k in ("file", "sha256", "notes")}
        return cls(discs, junk, complete, text["file"], text["sha256"], width, height, text["notes"] or "")


def _numbers(value, count: int, where: str) -> list[float]:
    if not isinstance(value, (list, tuple)) or len(value) != count:
        raise InputError(f"{where} must be a list of {count} numbers (got {str(value)[:40]})")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InputError(f"{where} must be a list of {count} finite numbers (got {str(value)[:40]})")
        out.append(float(v))
    return out


def _disc(entry, where: str) -> LabelledDisc:
    if not isinstance(entry, dict):
        raise InputError(f"{where} must be an object with center_xy and diameter_px")
    x, y = _numbers(entry.get("center_xy"), 2, f"{where}.center_xy")
    (diameter,) = _numbers([entry.get("diameter_px")], 1, f"{where}.diameter_px")
    if diameter <= 0:
        raise InputError(f"{where}.diameter_px must be above 0 (got {diameter:g})")
    kind = entry.get("kind", "clean")
    if kind not in DISC_KINDS:
        raise InputError(f"{where}.kind must be one of {', '.join(DISC_KINDS)} (got {str(kind)[:40]!r})")
    usable = entry.get("usable", True)
    if not isinstance(usable, bool):
        raise InputError(f"{where}.usable must be true or false (got {str(usable)[:40]})")
    note = entry.get("note", "")
    return LabelledDisc((x, y), diameter, kind, usable, note if isinstance(note, str) else "")


def _junk(entry, where: str) -> Junk:
    if not isinstance(entry, dict):
        raise InputError(f"{where} must be an object with center_xy and size_px")
    x, y = _numbers(entry.get("center_xy"), 2, f"{where}.center_xy")
    (size,) = _numbers([entry.get("size_px", 0.0)], 1, f"{where}.size_px")
    what = entry.get("what", "other")
    return Junk((x, y), max(size, 0.0), what if isinstance(what, str) else "other")


def read_labels(path: str | os.PathLike) -> DiscLabels:
    """Read a discs file; ``InputError`` (one line) when it is missing, too large or malformed."""
    path = Path(path)
    try:
        if not path.is_file():
            raise InputError(f"discs file {path.name!r} is not a regular file")
        if path.stat().st_size > MAX_LABELS_BYTES:
            raise InputError(f"discs file {path.name!r} is over {MAX_LABELS_BYTES >> 20} MiB")
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise InputError(f"cannot read discs file {path.name!r}: {error.strerror or error}") from None
    except UnicodeDecodeError:
        raise InputError(f"discs file {path.name!r} is not UTF-8 text") from None
    try:
        data = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as error:
        raise InputError(f"discs file {path.name!r} is not valid JSON ({str(error)[:80]})") from None
    return DiscLabels.from_json(data, f"discs file {path.name!r}")


def at_place(found_xy, label: LabelledDisc) -> bool:
    """True when a found centre lies at the labelled disc's place (MATCH_CENTRE_REL of its diameter)."""
    return math.dist(found_xy, label.center_xy) <= MATCH_CENTRE_REL * label.diameter_px


def matches(found_xy, found_diameter: float, label: LabelledDisc) -> bool:
    """True when a found disc is the labelled one: at its place, and its size within MATCH_DIAMETER_REL."""
    return at_place(found_xy, label) and abs(found_diameter / label.diameter_px - 1.0) <= MATCH_DIAMETER_REL


def _pairs(found: list[tuple[tuple[float, float], float]], labels: tuple[LabelledDisc, ...]) -> dict[int, int]:
    """One-to-one matches {found index: label index}, closest (relative to the label's size) first."""
    candidates = []
    for i, (xy, diameter) in enumerate(found):
        for j, label in enumerate(labels):
            if matches(xy, diameter, label):
                distance = math.hypot(xy[0] - label.center_xy[0], xy[1] - label.center_xy[1]) / label.diameter_px
                candidates.append((distance + abs(diameter / label.diameter_px - 1.0), i, j))
    pairs: dict[int, int] = {}
    taken = set()
    for _, i, j in sorted(candidates):
        if i not in pairs and j not in taken:
            pairs[i] = j
            taken.add(j)
    return pairs


@dataclass
class DiscScore:
    """Found and used discs against a person's labels (:func:`score_discs`)."""

    usable_labelled: int  #: labelled usable discs
    usable_found: int  #: of those, found as usable discs
    used: int  #: discs the fit used
    #: What each used disc is: "disc" (a labelled disc), "junk" (a labelled non-disc),
    #: "mis-sized" (at a labelled disc's place, its size off by more than MATCH_DIAMETER_REL),
    #: "unlabelled" (inside a complete box, neither), "unknown" (outside the complete boxes).
    used_as: Counter = field(default_factory=Counter)
    #: Found size over labelled size − 1, per matched usable disc.
    diameter_errors: list[float] = field(default_factory=list)
    missed: list[LabelledDisc] = field(default_factory=list)  #: usable discs not found as usable
    junk_used: list[tuple[tuple[float, float], float, str]] = field(default_factory=list)  #: (centre, size, as what)
    labelled_kinds: Counter = field(default_factory=Counter)  #: the labelled usable discs by kind

    def recall_by_kind(self) -> dict[str, tuple[int, int]]:
        """Per kind of labelled usable disc (DISC_KINDS' order): (found usable, labelled)."""
        missed = Counter(d.kind for d in self.missed)
        return {kind: (self.labelled_kinds[kind] - missed[kind], self.labelled_kinds[kind])
                for kind in DISC_KINDS if self.labelled_kinds[kind]}

    @property
    def recall(self) -> float | None:
        return self.usable_found / self.usable_labelled if self.usable_labelled else None

    @property
    def junk(self) -> int:
        """Used discs that are not discs: labelled junk, mis-sized or unlabelled inside a complete box."""
        return self.used_as["junk"] + self.used_as["mis-sized"] + self.used_as["unlabelled"]

    @property
    def junk_share(self) -> float | None:
        """Junk over the used discs whose nature is known (inside a complete box, or labelled)."""
        known = self.used - self.used_as["unknown"]
        return self.junk / known if known else None

    def __iadd__(self, other: DiscScore) -> DiscScore:
        self.usable_labelled += other.usable_labelled
        self.usable_found += other.usable_found
        self.used += other.used
        self.used_as += other.used_as
        self.diameter_errors += other.diameter_errors
        self.missed += other.missed
        self.junk_used += other.junk_used
        self.labelled_kinds += other.labelled_kinds
        return self

    def to_json(self) -> dict:
        errors = np.abs(self.diameter_errors) if self.diameter_errors else None
        return {"usable_labelled": self.usable_labelled, "usable_found": self.usable_found,
                "recall": None if self.recall is None else round(self.recall, 4), "used": self.used,
                "used_as": dict(self.used_as), "junk": self.junk,
                "junk_share": None if self.junk_share is None else round(self.junk_share, 4),
                "median_abs_diameter_error": None if errors is None else round(float(np.median(errors)), 4),
                "recall_by_kind": {kind: list(pair) for kind, pair in self.recall_by_kind().items()}}


def score_discs(labels: DiscLabels, found, used) -> DiscScore:
    """Score discs against labels.

    Parameters
    ----------
    labels : DiscLabels
    found : list of ((x, y), diameter_px)
        The discs found usable (recall is counted on these).
    used : list of ((x, y), diameter_px)
        The discs a fit used (what each is, is counted on these).
    """
    found, used = list(found), list(used)
    usable = labels.distinct_usable
    pairs = _pairs(found, usable)
    score = DiscScore(len(usable), len(pairs), len(used), labelled_kinds=Counter(d.kind for d in usable))
    score.diameter_errors = [found[i][1] / usable[j].diameter_px - 1.0 for i, j in pairs.items()]
    hit = set(pairs.values())
    score.missed = [d for j, d in enumerate(usable) if j not in hit]
    on_disc = _pairs(used, labels.discs)
    for i, (xy, diameter) in enumerate(used):
        if i in on_disc:
            what = "disc"
        elif any(math.hypot(xy[0] - j.center_xy[0], xy[1] - j.center_xy[1]) <= max(0.5 * j.size_px, 0.25 * diameter)
                 for j in labels.junk):
            what = "junk"
        elif any(at_place(xy, d) for d in labels.discs):
            what = "mis-sized"
        elif labels.complete_at(xy):
            what = "unlabelled"
        else:
            what = "unknown"
        score.used_as[what] += 1
        if what not in ("disc", "unknown"):
            score.junk_used.append((xy, diameter, what))
    return score
