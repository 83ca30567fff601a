"""Degraded copies of the reference photos (JPEG at quality 60, noise of σ 0.02): ``compare`` adds no
lens feature that neither the original's answer nor the person's label shows, and keeps its answer
(issue: features on real photos only where the discs show them, none made of JPEG or sensor noise on
a photo that had none).

The copies and the reading of an answer are ``benchmarks/real_degraded.py``'s (one definition of
each), which prints the full table over every photo and more kinds of copy.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import cv2
import pytest

BENCHMARK = Path(__file__).resolve().parents[1] / "benchmarks" / "real_degraded.py"


def _benchmark():
    spec = importlib.util.spec_from_file_location("real_degraded", BENCHMARK)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _copy_read(bench, reference_photo, tmp_path, name: str, variant: str) -> dict:
    """The reading of ``compare`` on the ``variant`` copy of a reference photo (the benchmark's very copy)."""
    from bokehfit.compare import compare_photo

    image = cv2.imread(str(reference_photo(name)), cv2.IMREAD_COLOR)
    copy, suffix = bench.degrade(image, variant, bench.copy_rng(name, variant))
    out = tmp_path / f"copy{suffix}"
    assert cv2.imwrite(str(out), copy, [cv2.IMWRITE_JPEG_QUALITY, 60] if suffix == ".jpg" else [])
    return bench.reading(compare_photo(out))


def _label(bench, name: str) -> dict:
    return next(e for e in json.loads(bench.MANIFEST.read_text(encoding="utf-8"))["photos"] if e["file"] == name)["label"]


@pytest.mark.parametrize("variant", ["jpeg60", "noise"])
@pytest.mark.parametrize("name", ["01_water-glints_canon6d_ef85.jpg", "04_juniper-droplet-rings_pablo-garcia-saldana.jpg",
                                  "06_christmas-lights_nikon-d5300.jpg"])
def test_a_degraded_copy_adds_no_lens_feature(compared, reference_photo, tmp_path, name, variant):
    bench = _benchmark()
    original = bench.reading(compared(name))
    seen = _copy_read(bench, reference_photo, tmp_path, name, variant)
    assert seen["answered"] == original["answered"] and seen["family"] == original["family"], (original, seen)
    added = bench.unread(original, seen, _label(bench, name))
    assert not added, f"{variant} made {added} of a photo that shows none: {original} -> {seen}"
    if name.startswith("04"):  # the soap-bubble rims the person reads are kept
        assert "rim+" in seen["features"], seen


WEAK_05, WEAK_15 = "05_backlit-grass_unsplash-522b53fb137bb.jpg", "15_water-web_tom-kijas.jpg"
#: Photo 05's discs stand 5-7 % above the grass. Its benchmark copy with noise of σ 0.02 gained a vignetting (ΔBIC
#: 132) until the edge's slope was read with the noise's share taken out, and again (ΔBIC 136) on another machine's
#: arithmetic until small and faint discs asked for no feature read from their outlines (bokehfit.fit.features.
#: small_and_faint). Other draws of that noise (seeds 0-5) then give it no vignetting but a rim in 3 of 6: a rim is
#: read from the light's spread, not the outline, and is left open in issue 21 (benchmarks/RESULTS.md).
@pytest.mark.parametrize("name, variant", [(WEAK_05, "jpeg60"), (WEAK_05, "noise"),
                                           (WEAK_15, "jpeg60"), (WEAK_15, "noise")])
def test_a_weak_photo_s_copy_is_no_surer_and_adds_no_feature(compared, reference_photo, tmp_path, name, variant):
    """Photos whose labels call them weak (faint, soft discs): a copy's answer may waver, but it is not sure of
    another shape, and JPEG or noise adds no feature the label does not read. Before the discs of a sure angle
    had to show it the same way round, 15's JPEG-60 copy was a sure rounded triangle; before a feature had to
    hold with any one disc left out, 05's gained a rim and a vignetting, each one disc's."""
    bench = _benchmark()
    original = bench.reading(compared(name))
    seen = _copy_read(bench, reference_photo, tmp_path, name, variant)
    assert seen["status"] != "fitted" or seen["family"] == original["family"], (original, seen)
    added = bench.unread(original, seen, _label(bench, name))
    assert not added, f"{variant} made {added} of a photo that shows none: {original} -> {seen}"
