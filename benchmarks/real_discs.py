"""The disc finder against a person's disc labels, on the real reference photos.

Usage::

    BOKEHFIT_REFERENCE_DIR=path/to/reference_photos python benchmarks/real_discs.py [--json out.json] [--only 04 09]
        [--no-person] [--finder-only] [--at-places] [--sheets DIR]

For every photo of ``reference_photos/manifest.json`` that has a person's
labels (``$BOKEHFIT_REFERENCE_DIR/discs/NAME.discs.json``, same sha256), it
runs ``compare`` in this process twice:

- **own discs**: as ``bokehfit compare PHOTO`` does, and scores what it found
  against the labels (:func:`bokehfit.discs.labels.score_discs`): the recall of
  labelled usable discs found as usable, what each disc the fit used is (a
  labelled disc, labelled junk, a labelled disc mis-sized by more than 25 %, an
  unlabelled blob inside a box where the labels are complete, or unknown outside
  one), and the median size error of the matched discs;
- **person's discs**: as ``bokehfit compare PHOTO --discs LABELS`` does, fitted
  on the labelled usable discs only,

and prints the whole-photo answer of each beside the label (the verdicts of
``benchmarks/real_photos.py``), so that a wrong answer is known to be the
finder's or the fit's, with each lens feature the fit tried and why it was kept
or not, and those the discs did not ask for (``aperture.feature_trials``,
``features_not_tried``). Pooled figures close the table. It asserts nothing.

``--finder-only`` runs the disc search alone (as ``compare`` runs it) and scores
every disc it finds usable, as if the fit used them all: the recall is the same
as ``compare``'s, and "used" then counts what the search offers the fit (its
junk before the fit's consensus sets any aside), with the search's CPU time.
It takes a fraction of the time of the whole run, for trying a change to the search.

``--sheets DIR`` also writes, per photo, a contact sheet (``DIR/NAME.sheet.png``) of what the table counts
against the finder: each disc the fit used that is not a labelled disc, and each labelled usable disc missed
with why, a tile each, with the search's outlines as the report draws them and the label's circle (yellow):
a miss is read in seconds where its numbers take minutes. The sheets show the photos: keep them out of the
repository (their licences, ``reference_photos/MANIFEST.md``).

``--at-places`` measures each labelled usable disc and each labelled non-disc at its own place and
size, as the search measures a place, and counts those that pass its tests of a disc: whether a miss
is the search not finding a place, or its tests not telling a disc from a bright blob there.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from real_photos import MANIFEST, answer, find_photo, judge  # noqa: E402

from bokehfit.compare import compare_photo  # noqa: E402
from bokehfit.discs.labels import DiscLabels, DiscScore, read_labels, score_discs  # noqa: E402
from bokehfit.words import feature_trial_lines  # noqa: E402


def labels_for(entry: dict) -> tuple[Path, DiscLabels] | None:
    """The labels file of a manifest entry and its labels, where they exist for this very photo."""
    folder = os.environ.get("BOKEHFIT_REFERENCE_DIR")
    if not folder:
        return None
    path = Path(folder) / "discs" / f"{entry['file']}.discs.json"
    if not path.is_file():
        return None
    labels = read_labels(path)
    return (path, labels) if labels.sha256 in (None, entry["sha256"]) else None


def places(discs) -> list:
    return [(tuple(d.center_xy), float(d.diameter_px)) for d in discs]


def score_comparison(comparison, labels: DiscLabels) -> DiscScore:
    return score_discs(labels, places(comparison.usable_discs), places(comparison.used_discs))


def recall_by_kind(score: DiscScore) -> str:
    """The recall of each kind of labelled disc (clean, saturated, overlapping, ...), in a line."""
    return "recall by kind: " + ", ".join(f"{kind} {found}/{labelled}" for kind, (found, labelled)
                                          in score.recall_by_kind().items())


def why_missed(comparison, score: DiscScore) -> Counter:
    """Why the labelled usable discs were not found usable, counted (:func:`why_each`)."""
    return Counter(why for _, why in why_each(comparison, score))


def why_each(comparison, score: DiscScore) -> list:
    """(label, why) for each labelled usable disc not found usable: found but not usable (the disc's
    problems), found at its place with another size, a candidate measured and rejected there (the
    reason), or no candidate at all."""
    from bokehfit.discs.labels import at_place, matches
    from bokehfit.words import disc_problems

    reasons = []
    for label in score.missed:
        found = [d for d in comparison.search.discs if matches(d.center_xy, d.diameter_px, label)]
        placed = [d for d in comparison.search.discs if at_place(d.center_xy, label)]
        rejected = [r for r in comparison.search.rejections if at_place(r.center_xy, label)]
        if found:
            why = "found, not usable: " + ", ".join(disc_problems(found[0])).split(" (")[0]
        elif placed:
            ratio = placed[0].diameter_px / label.diameter_px
            why = f"found {'larger' if ratio > 1 else 'smaller'} ({label.kind})"
        elif rejected:
            why = f"rejected: {rejected[0].rejected_because.split(' (')[0]} ({label.kind})"
        else:
            why = f"no candidate ({label.kind})"
        reasons.append((label, why))
    return reasons


#: A contact sheet's tiles: their side (px), how many a row, and the most a sheet shows; the labelled disc's
#: circle (BGR: the Okabe–Ito yellow, apart from the report's outline colours).
TILE_PX, TILES_A_ROW, MOST_TILES = 220, 6, 48
LABEL_BGR = (66, 228, 240)


def write_sheet(comparison, score: DiscScore, path: Path) -> int:
    """A contact sheet (PNG) of what to look at on one photo: each disc the fit used that is not a labelled
    disc (what the score calls it) and each labelled usable disc missed (why), a tile each, with every disc
    the search found drawn as the report draws it (:func:`bokehfit.report.overlay.draw_disc_overlay`: used,
    usable, rejected; soft-edged dashed) and the label's circle in yellow. Returns how many tiles it shows;
    writes nothing where there are none."""
    import cv2
    import numpy as np

    from bokehfit.outputs import write_png
    from bokehfit.report.overlay import draw_disc_overlay

    items = [((xy, size), f"used {what}") for xy, size, what in score.junk_used]
    items += [((label.center_xy, label.diameter_px), why) for label, why in why_each(comparison, score)]
    items = items[:MOST_TILES]
    if not items:
        return 0
    display = comparison.photo.display
    height, width = display.shape[:2]
    used = {d.index for d in comparison.used_discs}
    tiles = []
    for ((x, y), size), caption in items:
        half = max(24, int(math.ceil(1.2 * size)))
        x0, y0 = int(round(x)) - half, int(round(y)) - half  # the tile's corner in the photo
        crop = np.zeros((2 * half, 2 * half, 3), np.uint8)  # black beyond the frame
        r0, c0, r1, c1 = max(0, y0), max(0, x0), min(height, y0 + 2 * half), min(width, x0 + 2 * half)
        if r1 > r0 and c1 > c0:
            crop[r0 - y0 : r1 - y0, c0 - x0 : c1 - x0] = display[r0:r1, c0:c1]
        near = [replace(d, outline_xy=d.outline_xy - [x0, y0]) for d in comparison.search.discs
                if math.dist(d.center_xy, (x, y)) < 2.0 * half + d.diameter_px]
        tile = draw_disc_overlay(crop, near, used, max_side=TILE_PX)
        tile = cv2.resize(tile, (TILE_PX, TILE_PX), interpolation=cv2.INTER_AREA if 2 * half > TILE_PX else cv2.INTER_LINEAR)
        if not caption.startswith("used"):
            radius = int(round(0.5 * size * TILE_PX / (2 * half)))
            cv2.circle(tile, (TILE_PX // 2, TILE_PX // 2), radius, LABEL_BGR, 1, cv2.LINE_AA)
        for text, at in ((f"({x:.0f}, {y:.0f}) {size:.0f} px", 0), (caption[:44], TILE_PX - 16)):
            cv2.rectangle(tile, (0, at), (TILE_PX - 1, at + 15), (0, 0, 0), cv2.FILLED)
            cv2.putText(tile, text, (3, at + 11), cv2.FONT_HERSHEY_SIMPLEX, 0.36, (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(tile)
    tiles += [np.zeros_like(tiles[0])] * (-len(tiles) % TILES_A_ROW)
    write_png(path, np.vstack([np.hstack(tiles[i : i + TILES_A_ROW]) for i in range(0, len(tiles), TILES_A_ROW)]))
    return len(items)


def row(comparison, label: dict, seconds: float) -> dict:
    data = comparison.to_json("")
    return {"answer": answer(data.get("aperture")), "status": comparison.status,
            "verdict": judge(label, data), "reason": comparison.reason, "seconds": round(seconds, 1),
            "features": feature_trial_lines(data.get("aperture") or {})}


def labelled_photos(only: list[str] | None):
    """(manifest entry, photo path, (labels path, labels)) of every reference photo here with its
    labels, those whose file names start with ``only`` where given; the others are told and skipped."""
    manifest = json.loads(MANIFEST.read_text(encoding="utf-8"))
    for entry in manifest["photos"]:
        if only and not any(entry["file"].startswith(o) for o in only):
            continue
        photo, found = find_photo(entry), labels_for(entry)
        if photo is None or found is None:
            print(f"{entry['file']}: {'missing' if photo is None else 'no labels'} (set BOKEHFIT_REFERENCE_DIR)")
            continue
        yield entry, photo, found


def finder_only(args) -> int:
    """The search alone on every labelled photo: its usable discs scored against the labels (module notes)."""
    from types import SimpleNamespace

    from bokehfit.discs import COMPARE_MIN_DIAMETER_PX, find_discs
    from bokehfit.io import load_photo

    pooled, rows, seconds = DiscScore(0, 0, 0), [], 0.0
    missed = Counter()
    for entry, photo, found in labelled_photos(args.only):
        loaded = load_photo(photo)
        start = time.process_time()
        search = find_discs(loaded.luminance, loaded.clipped, min_diameter_px=COMPARE_MIN_DIAMETER_PX, rgb=loaded.linear_rgb)
        cpu = time.process_time() - start
        seconds += cpu
        usable = places([d for d in search.discs if d.usable])
        score = score_discs(found[1], usable, usable)
        pooled += score
        why = why_missed(SimpleNamespace(search=search), score)
        for reason, n in why.items():  # pooled by what happened, whatever the label's kind
            missed[reason.split(":")[0] if reason.startswith("found, not usable") else reason.split(" (")[0]] += n
        twice = f"  ({len(found[1].repeated)} labelled twice, counted once)" if found[1].repeated else ""
        print(f"{entry['file'][:2]}  recall {score.usable_found:3d}/{score.usable_labelled:<3d} usable found {score.used:4d}"
              f" (labelled junk {score.used_as['junk']}, not discs in complete boxes {score.junk})  {cpu:5.1f} s CPU"
              + twice)
        rows.append({"file": entry["file"], "score": score.to_json(), "cpu_s": round(cpu, 2), "missed": dict(why)})
    print(f"\npooled: recall {pooled.usable_found}/{pooled.usable_labelled}"
          f" ({'-' if pooled.recall is None else f'{pooled.recall:.1%}'}), usable found {pooled.used}"
          f" ({pooled.junk} not discs in complete boxes), search {seconds:.1f} s CPU")
    print(recall_by_kind(pooled))
    print("missed: " + ", ".join(f"{n} {why}" for why, n in missed.most_common()))
    if args.json:
        args.json.write_text(json.dumps({"photos": rows, "pooled": pooled.to_json(), "cpu_s": round(seconds, 2)},
                                        indent=1), encoding="utf-8")
    return 0


def at_places(args) -> int:
    """Each labelled usable disc and each labelled non-disc measured at its own place and size, as the
    search measures a place (its contour, and its own step along rays where that finds none): how many
    pass the search's tests of a disc, and the edge widths over the radius of all those outlined there
    (what the soft-edge test weighs; module notes)."""
    import numpy as np

    from bokehfit.discs.places import _measure_place
    from bokehfit.discs.reasons import NoDisc
    from bokehfit.io import load_photo

    passed, widths, counts = Counter(), {"disc": [], "not a disc": []}, Counter()
    for entry, photo, (_, labels) in labelled_photos(args.only):
        loaded = load_photo(photo)
        items = [("disc", d.center_xy, d.diameter_px) for d in labels.distinct_usable]
        items += [("not a disc", j.center_xy, j.size_px) for j in labels.junk]
        seen = Counter()
        for what, xy, size in items:
            counts[what] += 1
            m = _measure_place(loaded.luminance, loaded.clipped, tuple(map(float, xy)), float(size))
            if isinstance(m, NoDisc):
                continue
            widths[what].append(m.edge_width_px / max(0.5 * m.diameter_px, 1e-9))  # passing or not
            if m.reason is None:
                passed[what] += 1
                seen[what] += 1
        print(f"{entry['file'][:2]}  discs passing {seen['disc']}, non-discs passing {seen['not a disc']}")
    print()
    for what in ("disc", "not a disc"):
        w = np.array(widths[what])
        quartiles = ", ".join(f"{q:.2f}" for q in np.percentile(w, [25, 50, 75])) if len(w) else "-"
        between = int(((w >= 0.6) & (w < 1.2)).sum())
        print(f"{what}: {passed[what]}/{counts[what]} pass the search's tests at their places; of the {len(w)} "
              f"outlined there, edge width over radius quartiles {quartiles}, {between} between 0.6 and 1.2")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", type=Path, help="write the table as JSON")
    parser.add_argument("--only", nargs="*", help="photos whose file names start with these")
    parser.add_argument("--no-person", action="store_true", help="skip the fit on the person's discs")
    parser.add_argument("--finder-only", action="store_true",
                        help="run the disc search alone and score all the discs it finds usable")
    parser.add_argument("--sheets", type=Path, metavar="DIR",
                        help="write a contact sheet per photo into DIR: the used discs that are not labelled discs and"
                             " the labelled discs missed, each outlined (not for committing: the photos' licences)")
    parser.add_argument("--at-places", action="store_true",
                        help="measure each labelled disc and non-disc at its own place: how many pass as discs")
    args = parser.parse_args(argv)
    if args.finder_only:
        return finder_only(args)
    if args.at_places:
        return at_places(args)
    pooled = DiscScore(0, 0, 0)
    verdicts = {"own": Counter(), "person": Counter()}
    measured = [0, 0]  # the person's discs measured usable at their places, of all
    rows = []
    for entry, photo, found in labelled_photos(args.only):
        labels_path, labels = found
        start = time.perf_counter()
        comparison = compare_photo(photo)
        own = row(comparison, entry["label"], time.perf_counter() - start)
        score = score_comparison(comparison, labels)
        pooled += score
        verdicts["own"][own["verdict"].split(" (")[0]] += 1
        figures = score.to_json()
        print(f"\n{entry['file']}  [{own['seconds']:.1f} s]")
        recall = "-" if score.recall is None else f"{score.recall:.0%}"
        share = "-" if score.junk_share is None else f"{score.junk_share:.0%}"
        error = figures["median_abs_diameter_error"]
        print(f"  own discs:     recall {score.usable_found}/{score.usable_labelled} ({recall}), used {score.used}: "
              + ", ".join(f"{n} {what}" for what, n in score.used_as.most_common())
              + f"; junk {share}; size error {'-' if error is None else f'{error:.1%}'}")
        print(f"                 {own['answer']}  {own['status']} -> {own['verdict']}")
        for line in own["features"]:
            print(f"                 {line}")
        for why, n in why_missed(comparison, score).most_common(6):
            print(f"                 missed {n} × {why}")
        for xy, size, what in score.junk_used[:6]:
            print(f"                 used {what}: ({xy[0]:.0f}, {xy[1]:.0f}) {size:.0f} px")
        if args.sheets is not None:
            args.sheets.mkdir(parents=True, exist_ok=True)
            sheet = args.sheets / f"{Path(entry['file']).stem}.sheet.png"
            if write_sheet(comparison, score, sheet):
                print(f"                 sheet: {sheet}")
        result = {"file": entry["file"], "label": entry["label"], "own": own, "score": figures}
        for d in labels.repeated:
            print(f"                 labelled twice, counted once: ({d.center_xy[0]:.0f}, {d.center_xy[1]:.0f})"
                  f" {d.diameter_px:.0f} px")
        if not args.no_person and labels.usable:
            start = time.perf_counter()
            person = compare_photo(photo, discs=labels_path)
            mine = row(person, entry["label"], time.perf_counter() - start)
            verdicts["person"][mine["verdict"].split(" (")[0]] += 1
            # How many of the person's discs the measurement draws a usable outline for, at their places.
            mine["measured_usable"] = score_discs(labels, places(person.usable_discs), []).usable_found
            measured[0] += mine["measured_usable"]
            measured[1] += len(labels.distinct_usable)
            print(f"  person's discs ({len(labels.distinct_usable)}, {mine['measured_usable']} measured usable): "
                  f"{mine['answer']}  {mine['status']} -> {mine['verdict']}  [{mine['seconds']:.1f} s]")
            for line in mine["features"]:
                print(f"                 {line}")
            result["person"] = mine
        rows.append(result)
    figures = pooled.to_json()
    print("\npooled: recall {}/{} ({}), used {}: {}; junk share {}; median size error {}".format(
        pooled.usable_found, pooled.usable_labelled, "-" if pooled.recall is None else f"{pooled.recall:.1%}",
        pooled.used, ", ".join(f"{n} {w}" for w, n in pooled.used_as.most_common()),
        "-" if pooled.junk_share is None else f"{pooled.junk_share:.1%}",
        "-" if figures["median_abs_diameter_error"] is None else f"{figures['median_abs_diameter_error']:.1%}"))
    print(recall_by_kind(pooled))
    if measured[1]:
        print(f"the person's discs measured usable at their places: {measured[0]}/{measured[1]}")
    for who, counted in verdicts.items():
        if counted:
            print(f"verdicts ({who} discs): " + ", ".join(f"{n} {v}" for v, n in counted.most_common()))
    print("targets: recall ≥ 90 %, junk ≤ 3 % of used discs, no WRONG; with the person's discs every photo right")
    if args.json:
        args.json.write_text(json.dumps({"photos": rows, "pooled": figures}, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
