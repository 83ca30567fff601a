"""Degraded copies of the real reference photos: does ``compare`` keep its answer and its features?

Usage::

    BOKEHFIT_REFERENCE_DIR=path/to/reference_photos python benchmarks/real_degraded.py [--only 01 06] [--json out.json]
        [--variants jpeg60 noise half rot90 rot33 mirror]

Each photo of ``reference_photos/manifest.json`` that is present is compared as it is, then as
copies made here (8-bit, no metadata, so the f-stop is left out of the comparison):

- ``jpeg60``: re-encoded as JPEG at quality 60;
- ``noise``: Gaussian noise of σ 0.02 added to the encoded values (0–1), then 8-bit PNG; the draw is
  the copy's own (:func:`copy_rng`: seeded by the photo's name and the variant), the same whichever
  photos are run and in ``tests/test_reference_degraded.py``;
- ``half``: half the size (area averaging);
- ``rot90``: turned by 90°; ``rot33``: turned by 33° about the centre on a canvas that holds
  the whole photo (the corners black);
- ``mirror``: mirrored left to right.

Per copy it prints the status and the answer, and whether they agree with the original's:
the same kind of status (an answer, fitted or unsure, or none), the same shape family, and
the same lens features (rim's sign, vignetting, squeeze, chromatic) present or absent. A
feature that appears on a degraded copy of a photo whose original answer has none, and that the
person's label does not read in it either (:func:`unread`), is the failure the issue names (noise
or JPEG made into a lens feature); the summary counts those copies. It asserts nothing.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from real_photos import MANIFEST, answer, find_photo  # noqa: E402

from bokehfit.compare import compare_photo  # noqa: E402

VARIANTS = ("jpeg60", "noise", "half", "rot90", "rot33", "mirror")
NOISE_SIGMA = 0.02
SEED = 7


def copy_rng(name: str, variant: str) -> np.random.Generator:
    """The random draws of one copy: seeded by SEED, the photo's file name and the variant, so that a copy is the
    same whichever photos and variants are run (``--only``, ``--variants``) and in the tests."""
    digest = hashlib.sha256(f"{name}/{variant}".encode("utf-8")).digest()
    return np.random.default_rng([SEED, int.from_bytes(digest[:8], "little")])


def degrade(image: np.ndarray, variant: str, rng: np.random.Generator) -> tuple[np.ndarray, str]:
    """The degraded copy (8-bit BGR) and the file suffix to write it with."""
    if variant == "jpeg60":
        return image, ".jpg"
    if variant == "noise":
        noisy = image / 255.0 + rng.normal(0.0, NOISE_SIGMA, image.shape)
        return np.clip(np.round(noisy * 255.0), 0, 255).astype(np.uint8), ".png"
    if variant == "half":
        height, width = image.shape[:2]
        return cv2.resize(image, (width // 2, height // 2), interpolation=cv2.INTER_AREA), ".png"
    if variant == "rot90":
        return cv2.rotate(image, cv2.ROTATE_90_CLOCKWISE), ".png"
    if variant == "rot33":
        height, width = image.shape[:2]
        turn = cv2.getRotationMatrix2D(((width - 1) / 2, (height - 1) / 2), 33.0, 1.0)
        cos, sin = abs(turn[0, 0]), abs(turn[0, 1])
        size = (math.ceil(width * cos + height * sin), math.ceil(width * sin + height * cos))
        turn[:, 2] += ((size[0] - width) / 2, (size[1] - height) / 2)
        return cv2.warpAffine(image, turn, size, flags=cv2.INTER_LINEAR, borderValue=(0, 0, 0)), ".png"
    if variant == "mirror":
        return cv2.flip(image, 1), ".png"
    raise ValueError(f"variant must be one of {', '.join(VARIANTS)} (got {variant!r})")


def reading(comparison) -> dict:
    """What the comparison says, for comparing copies: status kind, shape family, features."""
    data = comparison.to_json("")
    aperture = data.get("aperture") or {}
    features = []
    if aperture.get("rim"):
        features.append("rim+" if aperture["rim"] > 0 else "rim-")
    for name in ("vignetting", "chromatic"):
        if aperture.get(name):
            features.append(name)
    if aperture.get("squeeze") not in (None, 1.0):
        features.append("squeeze")
    answered = comparison.status in ("fitted", "unsure")
    return {"status": comparison.status, "answered": answered, "answer": answer(aperture),
            "family": aperture.get("shape") if answered else None, "features": sorted(features)}


def person_reads(label: dict) -> set[str]:
    """The features (as :func:`reading` names them) that the person's label of a photo reads in its discs."""
    reads = set()
    if label.get("rim"):
        reads.add("rim+" if label["rim"] == "positive" else "rim-")
    if label.get("vignetting"):
        reads.add("vignetting")
    return reads


def unread(original: dict, copy: dict, label: dict) -> list[str]:
    """The features a copy's answer has that neither the original's answer nor the person's label has: what
    JPEG, noise or a turn of the frame made, the failure the issue names."""
    return sorted(set(copy["features"]) - set(original["features"]) - person_reads(label)) if copy["answered"] else []


def agreement(original: dict, copy: dict) -> str:
    """'same', or what changed."""
    changes = []
    if original["answered"] != copy["answered"]:
        changes.append(f"status {original['status']} -> {copy['status']}")
    elif original["family"] != copy["family"]:
        changes.append(f"shape {original['family']} -> {copy['family']}")
    added = sorted(set(copy["features"]) - set(original["features"]))
    lost = sorted(set(original["features"]) - set(copy["features"]))
    if copy["answered"] and added:
        changes.append("added " + ", ".join(added))
    if original["answered"] and copy["answered"] and lost:
        changes.append("lost " + ", ".join(lost))
    return "same" if not changes else "; ".join(changes)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", nargs="*", help="photos whose file names start with these")
    parser.add_argument("--variants", nargs="*", default=list(VARIANTS), choices=VARIANTS)
    parser.add_argument("--json", type=Path, help="write the table as JSON")
    args = parser.parse_args(argv)
    manifest = json.loads(MANIFEST.read_text(encoding="utf-8"))
    tally: Counter = Counter()
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for entry in manifest["photos"]:
            if args.only and not any(entry["file"].startswith(o) for o in args.only):
                continue
            path = find_photo(entry)
            if path is None:
                print(f"{entry['file']}: missing (set BOKEHFIT_REFERENCE_DIR)")
                continue
            start = time.perf_counter()
            original = reading(compare_photo(path))
            print(f"\n{entry['file']}  original: {original['answer']}  {original['status']}  "
                  f"[{time.perf_counter() - start:.1f} s]")
            image = cv2.imread(str(path), cv2.IMREAD_COLOR)
            row = {"file": entry["file"], "original": original, "copies": {}}
            for variant in args.variants:
                copy, suffix = degrade(image, variant, copy_rng(entry["file"], variant))
                out = Path(folder) / f"{Path(entry['file']).stem}_{variant}{suffix}"
                params = [cv2.IMWRITE_JPEG_QUALITY, 60] if suffix == ".jpg" else []
                cv2.imwrite(str(out), copy, params)
                start = time.perf_counter()
                seen = reading(compare_photo(out))
                verdict = agreement(original, seen)
                tally[variant, verdict == "same"] += 1
                tally["added", variant] += bool(unread(original, seen, entry.get("label") or {}))
                print(f"  {variant:7s} {seen['answer']:32s} {seen['status']:9s} {verdict}  "
                      f"[{time.perf_counter() - start:.1f} s]")
                row["copies"][variant] = {**seen, "agreement": verdict}
            rows.append(row)
    print("\nper variant: " + ", ".join(
        f"{v} {tally[v, True]}/{tally[v, True] + tally[v, False]} same, {tally['added', v]} with a feature added"
        " that neither the original nor the person reads"
        for v in args.variants))
    print("target: every copy the same; no feature added by JPEG 60 or noise")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
