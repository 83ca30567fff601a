"""A person's disc labels: reading them, scoring found discs against them, and fitting exactly them
(``measure_discs_at``, ``compare --discs``)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bokehfit.apertures import make_aperture
from bokehfit.discs import find_discs, measure_discs_at
from bokehfit.discs.labels import (
    MATCH_CENTRE_REL,
    MATCH_DIAMETER_REL,
    DiscLabels,
    LabelledDisc,
    read_labels,
    score_discs,
)
from bokehfit.errors import InputError
from bokehfit.synthetic import SyntheticDisc, encode_srgb8, render_discs

HEXAGON = make_aperture("hexagon", 10.0)
#: Five hexagons of 40 px on a dark ground, one faint light and one small glint.
DISCS = [SyntheticDisc((x, y), 40.0, HEXAGON, brightness=0.6) for x, y in
         ((60, 60), (160, 60), (260, 60), (60, 170), (160, 170))]
WIDTH, HEIGHT = 320, 240


def _image(noise=0.004):
    return render_discs(WIDTH, HEIGHT, DISCS, noise_sigma=noise, seed=3)


def _labels(**extra) -> dict:
    data = {"discs": [{"center_xy": list(d.center_xy), "diameter_px": d.diameter_px} for d in DISCS]}
    data.update(extra)
    return data


# --- reading --------------------------------------------------------------------------------------

def test_minimal_file_is_centres_and_diameters(tmp_path):
    path = tmp_path / "d.json"
    path.write_text(json.dumps(_labels()), encoding="utf-8")
    labels = read_labels(path)
    assert len(labels.usable) == 5 and labels.discs[0].kind == "clean" and labels.junk == ()
    assert not labels.complete_at((10, 10)), "no complete box: the lists are partial"


@pytest.mark.parametrize("text, words", [
    ("not json", "not valid JSON"),
    ("[1, 2]", "JSON object"),
    ('{"discs": 3}', "'discs' list"),
    ('{"discs": [{"center_xy": [1], "diameter_px": 3}]}', "discs[0].center_xy"),
    ('{"discs": [{"center_xy": [1, 2], "diameter_px": -3}]}', "above 0"),
    ('{"discs": [{"center_xy": [1, 2], "diameter_px": NaN}]}', "finite"),
    ('{"discs": [{"center_xy": [1, 2], "diameter_px": 3, "kind": "blob"}]}', "kind must be one of"),
    ('{"discs": [{"center_xy": [1, 2], "diameter_px": 3, "usable": "yes"}]}', "true or false"),
    ('{"discs": []' + ', "complete_within": [[1, 2]]}', "complete_within[0]"),
])
def test_malformed_files_are_one_line_errors(tmp_path, text, words):
    path = tmp_path / "d.json"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(InputError) as error:
        read_labels(path)
    assert words in str(error.value) and "\n" not in str(error.value)


def test_not_a_regular_file_is_refused(tmp_path):
    with pytest.raises(InputError, match="not a regular file"):
        read_labels(tmp_path)


# --- scoring --------------------------------------------------------------------------------------

def test_match_needs_the_centre_and_the_size():
    labels = DiscLabels((LabelledDisc((100.0, 100.0), 40.0),))
    inside = 100.0 + 0.99 * MATCH_CENTRE_REL * 40.0
    outside = 100.0 + 1.01 * MATCH_CENTRE_REL * 40.0
    assert score_discs(labels, [((inside, 100.0), 40.0)], []).usable_found == 1
    assert score_discs(labels, [((outside, 100.0), 40.0)], []).usable_found == 0
    assert score_discs(labels, [((100.0, 100.0), 40.0 * (1 + 0.99 * MATCH_DIAMETER_REL))], []).usable_found == 1
    assert score_discs(labels, [((100.0, 100.0), 40.0 * (1 + 1.01 * MATCH_DIAMETER_REL))], []).usable_found == 0


def test_one_found_disc_matches_one_label():
    # Two discs 11 px apart (each beyond the other's place: two discs, not one labelled twice); a disc found between
    # them is at the place of either, and is one of them.
    labels = DiscLabels((LabelledDisc((100.0, 100.0), 40.0), LabelledDisc((111.0, 100.0), 40.0)))
    assert not labels.repeated
    score = score_discs(labels, [((105.5, 100.0), 40.0)], [])
    assert score.usable_found == 1 and len(score.missed) == 1 and score.recall == 0.5


def test_a_disc_labelled_twice_is_counted_once():
    """Two labels of one disc (each at the other's place and of its size) are one disc: found once, it is found."""
    labels = DiscLabels((LabelledDisc((100.0, 100.0), 40.0), LabelledDisc((103.0, 101.0), 41.0),
                         LabelledDisc((112.0, 100.0), 40.0)))  # 12 px off: another disc
    assert [d.center_xy for d in labels.repeated] == [(103.0, 101.0)]
    assert len(labels.distinct_usable) == 2 and len(labels.usable) == 3
    score = score_discs(labels, [((101.0, 100.0), 40.0)], [])
    assert score.usable_labelled == 2 and score.usable_found == 1 and [d.center_xy for d in score.missed] == [(112.0, 100.0)]


def test_recall_is_counted_by_the_label_s_kind():
    labels = DiscLabels((LabelledDisc((100.0, 100.0), 40.0, "clean"), LabelledDisc((300.0, 100.0), 40.0, "faint"),
                         LabelledDisc((500.0, 100.0), 40.0, "faint"), LabelledDisc((700.0, 100.0), 40.0, "ring", False)))
    score = score_discs(labels, [((100.0, 100.0), 40.0), ((500.0, 100.0), 40.0)], [])
    assert score.recall_by_kind() == {"clean": (1, 1), "faint": (1, 2)}  # the unusable ring is not counted
    score += score_discs(labels, [], [])
    assert score.recall_by_kind() == {"clean": (1, 2), "faint": (1, 4)}
    assert score.to_json()["recall_by_kind"] == {"clean": [1, 2], "faint": [1, 4]}


def test_used_discs_are_told_apart():
    labels = DiscLabels.from_json({
        "discs": [{"center_xy": [100, 100], "diameter_px": 40},
                  {"center_xy": [300, 100], "diameter_px": 40, "usable": False}],
        "junk": [{"center_xy": [200, 200], "size_px": 30, "what": "lit leaf"}],
        "complete_within": [[0, 0, 400, 400]]})
    used = [((101, 99), 41.0),   # the usable disc
            ((300, 100), 39.0),  # a real disc a person would not read: not junk
            ((205, 195), 20.0),  # the lit leaf
            ((100, 100), 80.0),  # at the disc, twice its size: a merged glow
            ((350, 350), 20.0),  # nothing a person labelled, inside the complete box
            ((900, 900), 20.0)]  # outside it: unknown
    score = score_discs(labels, [], used)
    assert dict(score.used_as) == {"disc": 2, "junk": 1, "mis-sized": 1, "unlabelled": 1, "unknown": 1}
    assert score.junk == 3 and score.junk_share == pytest.approx(3 / 5)


# --- measuring a person's discs ---------------------------------------------------------------------

def test_measure_discs_at_measures_each_place_afresh():
    image = _image()
    # The places are rough (a person's click): 3 px off and 10 % small; the outline is measured.
    places = [((d.center_xy[0] + 3, d.center_xy[1] - 2), 0.9 * d.diameter_px) for d in DISCS]
    search = measure_discs_at(image, None, places)
    assert len(search.discs) == len(DISCS)
    for disc in search.discs:
        true = min(DISCS, key=lambda d: np.hypot(*np.subtract(d.center_xy, disc.center_xy)))
        assert np.hypot(*np.subtract(true.center_xy, disc.center_xy)) < 0.5
        assert disc.diameter_px == pytest.approx(true.diameter_px, rel=0.03)
        assert disc.usable


def test_a_person_s_soap_bubbles_are_measured_at_about_the_size_they_read(reference_photo):
    """Photo 09: at two of the person's soap-bubble discs (180 and 170 px) the contour outlines the light
    inside the rim (112 and 110 px). Measured again by their own step, each is the disc the person read (the
    labels' match: its centre within a quarter of the diameter, its size within 25 %) and usable; the discs
    whose contour matched already keep it."""
    from photo_factory import reference_labels

    from bokehfit.discs.labels import matches
    from bokehfit.io import load_photo

    name = "09_soap-bubbles_cat-eye.jpg"
    _, labels = reference_labels(name)
    picks = [d for d in labels.usable if tuple(d.center_xy) in ((247.0, 100.0), (132.0, 312.0), (2414.0, 504.0))]
    assert len(picks) == 3
    photo = load_photo(reference_photo(name))
    search = measure_discs_at(photo.luminance, photo.clipped, [(d.center_xy, d.diameter_px) for d in picks])
    for label in picks:
        found = [d for d in search.discs if matches(d.center_xy, d.diameter_px, label)]
        assert found and found[0].usable, (label.center_xy, [(d.center_xy, d.diameter_px) for d in search.discs])


def test_measure_discs_at_says_why_a_place_holds_no_disc():
    image = _image()
    search = measure_discs_at(image, None, [((230.0, 190.0), 40.0), ((-5.0, 10.0), 20.0), ((60.0, 60.0), 40.0)])
    assert len(search.discs) == 1
    reasons = [r.rejected_because for r in search.rejections]
    assert len(reasons) == 2 and "outside the photo" in reasons
    assert all(reason for reason in reasons)
    assert search.given and not find_discs(image, min_diameter_px=8).given
    nothing = measure_discs_at(image, None, [((230.0, 190.0), 40.0), ((-5.0, 10.0), 20.0)])
    assert not nothing and nothing.reason.startswith("no disc at the 2 places given (")
    assert "outside the photo" in nothing.reason


def test_measure_discs_at_matches_the_finder_on_clear_discs():
    image = _image()
    found = find_discs(image, min_diameter_px=8)
    given = measure_discs_at(image, None, [(d.center_xy, d.diameter_px) for d in found.discs])
    assert len(given.discs) == len(found.discs) == len(DISCS)
    for a, b in zip(sorted(found.discs, key=lambda d: d.center_xy), sorted(given.discs, key=lambda d: d.center_xy)):
        assert np.allclose(a.center_xy, b.center_xy, atol=0.05) and a.diameter_px == pytest.approx(b.diameter_px, rel=0.01)


# --- compare --discs --------------------------------------------------------------------------------

def _photo(tmp_path) -> Path:
    import cv2

    path = tmp_path / "hexagons.png"
    cv2.imwrite(str(path), encode_srgb8(_image()))
    return path


def _compare(*args, cwd):
    return subprocess.run([sys.executable, "-m", "bokehfit", "compare", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, stdin=subprocess.DEVNULL)


def test_compare_discs_fits_exactly_the_given_discs(tmp_path, gpu):
    photo = _photo(tmp_path)
    labels = _labels(junk=[{"center_xy": [260, 170], "size_px": 40, "what": "other"}])
    labels["discs"][4]["usable"] = False  # left out
    labels["discs"].append({"center_xy": [40, 220], "diameter_px": 20})  # nothing there: said why
    (tmp_path / "d.json").write_text(json.dumps(labels), encoding="utf-8")
    done = _compare(photo, "--discs", "d.json", "--json", "out.json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    result = json.loads((tmp_path / "out.json").read_text(encoding="utf-8"))
    used = [d for d in result["discs"] if d["used"]]
    assert len(used) == 4, [d["center_xy"] for d in result["discs"]]
    assert all(min(np.hypot(*np.subtract(d["center_xy"], g.center_xy)) for g in DISCS[:4]) < 0.5 for d in used)
    assert result["aperture"]["shape"] == "hexagon"
    # The place with nothing there is accounted for, with its reason: in the JSON, the summary and the report.
    detection = result["detection"]
    assert detection["places_given"] is True
    assert [(r["center_xy"], r["diameter_px"]) for r in detection["rejections"]] == [([40, 220], 20)]
    why = detection["rejections"][0]["rejected_because"]
    assert why and f"not a disc at (40, 220), 20 px given: {why}" in done.stdout
    report = (tmp_path / "out.html").read_text(encoding="utf-8")
    assert "Places given that are no disc" in report and "<td>(40, 220), 20 px</td>" in report


def test_compare_discs_refuses_a_file_for_another_photo(tmp_path):
    photo = _photo(tmp_path)
    (tmp_path / "d.json").write_text(json.dumps(_labels(sha256="0" * 64)), encoding="utf-8")
    done = _compare(photo, "--discs", "d.json", "--json", "out.json", cwd=tmp_path)
    assert done.returncode == 2 and "another photo" in done.stderr and "Traceback" not in done.stderr
    assert not (tmp_path / "out.json").exists()
    (tmp_path / "e.json").write_text("{", encoding="utf-8")
    done = _compare(photo, "--discs", "e.json", cwd=tmp_path)
    assert done.returncode == 2 and "not valid JSON" in done.stderr and len(done.stderr.strip().splitlines()) == 1
