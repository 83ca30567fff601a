"""Numbers a person can trust and verdicts a photographer can read (issue 26, points 2 and 3).

One small rendered photo of circular discs (the survey's library photo at f/2: four 40 px discs whose
size says the lights are at infinity) is compared once; the tests read its summary, JSON and HTML
report, and variants of its fit made with :func:`dataclasses.replace` for the cases a real photo
shows: a size whose uncertainty exceeds it, a close runner-up, a chosen model that is not the one
with the lowest ΔBIC.
"""

from __future__ import annotations

import dataclasses
import html
import json
import math
import re

import pytest
from test_survey import API_OPTIONS, write_render

from bokehfit.judging import judge
from bokehfit.optics import estimate_fstop
from bokehfit.report.html import build_html

#: The verdict's first sentence, at most (characters).
HEADLINE_CHARS = 120
#: "± 0.00", "± 0", "± 0.000": an uncertainty that is none.
ZERO_UNCERTAINTY = re.compile(r"± 0(\.0+)?(?![0-9.]*[1-9])")


@pytest.fixture(scope="module")
def circle(tmp_path_factory, gpu):
    from bokehfit.compare import compare_photo

    path = tmp_path_factory.mktemp("readable") / "circle_f2.jpg"
    write_render(path, 2.0, "circle", 1)
    from bokehfit.fit.result import FitOptions

    options = {k: v for k, v in API_OPTIONS.items() if k != "shapes"}  # every shape: the runners-up are many,
    # and every shortlisted one fitted (clean round discs put the polygons out of the race by their outlines)
    return compare_photo(path, **options, fit_options=FitOptions(out_of_race_screen=math.inf))


def variant(comparison, **changes):
    """The comparison with its fit changed, the f-stop and the doubts worked out again from it."""
    fit = dataclasses.replace(comparison.fit, **changes)
    fstop = estimate_fstop(fit, comparison.photo, comparison.geometry, "thin", "equal-area")
    doubts, rejection = judge(fit, comparison.metrics)
    return dataclasses.replace(comparison, fit=fit, fstop=fstop, doubts=doubts, rejection=rejection)


def page_text(comparison) -> str:
    return html.unescape(re.sub(r"<[^>]+>", " ", re.sub(r'src="data:[^"]*"', "", build_html(comparison, ""))))


def everything(comparison) -> dict[str, str]:
    return {"summary": comparison.summary(), "json": json.dumps(comparison.to_json(""), ensure_ascii=False),
            "html": page_text(comparison)}


# --------------------------------------------------------------------------------------
# Point 2: numbers a person can trust
# --------------------------------------------------------------------------------------


def test_a_value_whose_uncertainty_exceeds_it_is_not_measurable(circle):
    loose = variant(circle, diameter_uncertainty_px=2.0 * circle.fit.diameter_px)
    aperture = loose.to_json("")["aperture"]
    assert aperture["diameter_px"] is None and aperture["diameter_reason"].startswith("not measurable")
    assert aperture["fstop"] is None and aperture["fstop_reason"].startswith("not measurable")
    assert "uncertainty larger than the value" in aperture["fstop_reason"]
    for where, text in everything(loose).items():
        assert "not measurable" in text, where
    summary = loose.summary()
    assert "disc not measurable" in summary and "f-stop: unknown: not measurable" in summary
    shown = re.sub(r"not measurable: [^,]*,", "", summary + page_text(loose))  # the reason quotes the numbers
    for value, uncertainty in re.findall(r"(\d+\.?\d*) ± (\d+\.?\d*)", shown):
        assert float(uncertainty) <= float(value), f"{value} ± {uncertainty} shown as a result"

    from bokehfit.surveys.store import row_from_record

    row = row_from_record({"sha256": "x", "path": "p.jpg", "status": loose.status, "document": loose.to_json("")},
                          size_bytes=None, json_path=None, html_path=None)
    assert row["diameter_px"] is None and row["fstop"] is None and row["fstop_bound"] is None


def test_no_plus_minus_zero_where_there_is_no_uncertainty(circle):
    # four identical renders: the size's spread is about nothing, the f-stop's rounds to 0.000
    for where, text in everything(circle).items():
        assert not ZERO_UNCERTAINTY.search(text), f"{where}: {ZERO_UNCERTAINTY.search(text).group(0)!r}"
    assert "f-stop: at most f/2.00 (" in circle.summary()


def test_lights_at_infinity_read_as_infinity(circle):
    depths = [d["depth_m"] for d in circle.to_json("")["discs"] if d["depth_m"] is not None]
    assert depths and min(depths) > 1e3, "EXIF's f/2 makes these discs only from lights very far away"
    line = next(line for line in circle.summary().splitlines() if line.startswith("lights' distance"))
    assert "≈ ∞" in line and "e+" not in line, line
    text = page_text(circle)
    assert "≈ ∞" in text and not re.search(r"\de\+\d", text)


def test_overlay_labels_do_not_overlap(circle, monkeypatch):
    import cv2

    from bokehfit.report import overlay

    drawn = []
    real = cv2.putText

    def record(canvas, text, origin, font, scale, colour, thickness, line):
        (w, h), base = cv2.getTextSize(text, font, scale, thickness)
        drawn.append((origin[0], origin[1] - h, origin[0] + w, origin[1] + base))
        return real(canvas, text, origin, font, scale, colour, thickness, line)

    monkeypatch.setattr(overlay.cv2, "putText", record)
    discs = circle.search.discs
    labels = {disc.index: "1.77e+04 m to 9.45e+05 m" for disc in discs}  # labels longer than the discs are apart
    overlay.draw_disc_overlay(circle.photo.display, discs, labels=labels)
    boxes = drawn[1::2]  # each label is drawn twice (outline, then colour)
    assert len(boxes) == len(discs)
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            assert not (a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]), f"labels overlap: {a} {b}"


# --------------------------------------------------------------------------------------
# Point 3: verdicts a photographer can read
# --------------------------------------------------------------------------------------


def test_verdict_is_one_short_sentence_then_the_numbers(circle):
    document = circle.to_json("")
    verdict, details = document["verdict"], document["verdict_details"]
    assert verdict.startswith("Sure: circle") and len(verdict) <= HEADLINE_CHARS, verdict
    assert verdict.count(". ") == 0 and verdict.endswith(".")
    assert "ΔBIC" not in verdict and "IoU" not in verdict, "the numbers come after the sentence"
    assert "ΔBIC" in details and "4 discs fitted" in details
    assert circle.summary().splitlines()[:2] == [verdict, details]


def test_an_unsure_verdict_says_why_in_one_short_sentence(circle):
    close = variant(circle, close_runner_up=True)
    assert close.status == "unsure"
    verdict = close.verdict
    runner_up = close.fit.runner_up.family.aperture.display_name
    assert verdict == f"Unsure: probably a circle, but a {runner_up} fits almost as well.", verdict
    assert len(verdict) <= HEADLINE_CHARS
    assert "evidence" not in close.verdict_details, "no 'strong evidence' beside 'fits almost as well'"


def test_an_unsure_verdict_does_not_headline_unsupported_features(circle):
    from bokehfit.apertures import Chromatic

    weak = Chromatic(0.01, -0.01)  # 1 % ± 3 %: the discs do not support it
    seen = circle.fit.seen_aperture.replace(chromatic=weak)
    close = variant(circle, close_runner_up=True, aperture=circle.fit.aperture.replace(chromatic=weak), seen_aperture=seen,
                    feature_uncertainty={"chromatic_red": 0.03, "chromatic_blue": 0.03})
    assert close.to_json("")["aperture"]["chromatic"] is not None
    assert "chromatic" not in close.verdict
    # The summary names it only as a feature tried and not kept (the discs' colours measured within chance).
    mentions = [line for line in close.summary().splitlines() if "chromatic" in line]
    assert all(line.startswith("feature tried: chromatic (") and "), not kept: " in line for line in mentions), mentions


def test_one_runner_up_everywhere(circle):
    # The best model after the circle a polygon whose blades are rounded until round: the same answer
    # (round discs), not a runner-up. Round discs get no rounded trial of their own (an outline the
    # circle fits as well shows no blades to round: bokehfit.fit.stages._looks_rounder), so the
    # case is made: the first polygon among the candidates, rounded to the circle, just behind it.
    from bokehfit.fit.result import ROUND_ENOUGH

    found = circle.fit
    polygon = next(c for c in found.candidates[1:] if c.family.rounded is not None)
    delta = 0.5 * found.candidates[1].delta_bic
    rounded = dataclasses.replace(polygon, family=polygon.family.rounded, roundness=max(ROUND_ENOUGH, 0.99),
                                  delta_bic=delta, bic=found.candidates[0].bic + delta)
    circle = variant(circle, candidates=[found.candidates[0], rounded, *found.candidates[1:]])
    fit = circle.fit
    assert fit.candidates[0].same_answer(fit.candidates[1]) and delta > 0
    runner_up = fit.runner_up.family
    document = circle.to_json("")
    aperture = document["aperture"]
    assert aperture["runner_up"]["name"] == runner_up.name and aperture["runners_up"][0] == runner_up.name
    roles = {c["name"]: c["role"] for c in aperture["candidates"]}  # the candidates stay best first
    assert roles[runner_up.name] == "runner_up" and roles[fit.candidates[1].family.name] == "same_answer"
    assert f"over a {runner_up.aperture.display_name} (" in document["verdict_details"]
    ranked = next(line for line in circle.summary().splitlines() if line.startswith("runners-up:"))
    assert ranked.startswith(f"runners-up: {runner_up.aperture.display_name} (")
    table = build_html(circle, "").split("<h2>Candidate apertures</h2>")[1].split("</table>")[0]
    rows = re.findall(r"<tr><td>([^<]*)</td>", table)
    assert rows[:2] == [fit.family.name, runner_up.name]


def test_the_row_marked_best_is_the_best(circle):
    fit = circle.fit
    # the chosen model set aside a model the pixels favour (as the consensus or the outlines do)
    shifted = [dataclasses.replace(fit.candidates[0], delta_bic=fit.candidates[1].delta_bic + 10.0)] + list(fit.candidates[1:])
    changed = variant(circle, candidates=shifted)
    table = build_html(changed, "").split("<h2>Candidate apertures</h2>")[1].split("</table>")[0]
    cells = [re.findall(r"<td>([^<]*)</td>", row) for row in table.split("<tr>")[2:]]
    best = [row for row in cells if row[3] == "best"]
    lowest = min(float(row[2]) for row in cells)
    assert all(float(row[2]) == lowest for row in best), cells
    assert cells[0][3].startswith("chosen"), cells[0]
    assert abs(min(c.delta_bic for c in shifted) - lowest) <= 0.5  # the table rounds to whole ΔBIC


@pytest.mark.parametrize("sigma, named", [(2.0, True), (29.0, True), (31.0, False), (100.0, False), (None, True)])
def test_the_headline_names_an_angle_only_where_the_discs_fix_it(sigma, named):
    """A rounded triangle at 47.89° ± 100° (reference photo 15, two discs): every angle of its 120° symmetry lies
    within that; the first sentence says so instead of naming one."""
    from bokehfit.words import ANGLE_FIXED_SHARE, shape_words

    aperture = {"shape": "triangle", "blades": 3, "roundness": 0.88, "angle_deg": 47.887, "angle_uncertainty_deg": sigma,
                "symmetry_deg": 120.0}
    words = shape_words(aperture)
    assert words.startswith("rounded triangle")
    assert ("at 47.89°" in words) == named and ("not fixed" in words) == (not named), words
    assert (sigma is None or sigma <= ANGLE_FIXED_SHARE * 120.0) == named


def test_places_that_are_no_disc_are_said():
    """A person's places that are no disc are named one by one; a search's are counted by reason (the words before a
    reason's numbers counted together), the fifth reason on counted as the rest; none, nothing said."""
    from bokehfit.words import REJECTION_REASONS_NAMED, rejection_counts, rejection_lines

    given = {"places_given": True, "rejected": {"faint": 1},
             "rejections": [{"center_xy": [2750.4, 775.0], "diameter_px": 310.2, "rejected_because": "faint"}]}
    assert rejection_lines(given) == ["not a disc at (2750, 775), 310 px given: faint"]
    rejected = {"faint": 9, "soft edge": 4, "the disc measured there (40 px at 3, 4)": 2,
                "the disc measured there (12 px at 5, 6)": 3, "no outline": 1, "not compact": 1, "elongated": 1}
    search = {"places_given": False, "rejected": rejected, "rejections": []}
    counts = rejection_counts(search)
    assert counts[:3] == [("faint", 9), ("the disc measured there", 5), ("soft edge", 4)]
    assert sum(n for _, n in counts) == sum(rejected.values())
    (line,) = rejection_lines(search)
    assert REJECTION_REASONS_NAMED == 4
    assert line.startswith("not discs: 9 faint, 5 the disc measured there, 4 soft edge, 1 elongated, 2 for other reasons")
    assert rejection_lines({"places_given": False, "rejected": {}, "rejections": []}) == []


def test_usable_discs_the_fit_did_not_use_are_said():
    """The usable discs left unfitted: those set aside counted by their reasons' words, those not needed counted
    with the fit's limit; discs not usable (the header counts them as rejected) and discs used are not."""
    from bokehfit.words import unfitted_lines

    def disc(usable, used, *why):
        return {"usable": usable, "used": used, "rejected_because": list(why)}

    shape = "no aperture shape explains its outline"
    discs = [disc(True, True), disc(False, False, "only 40% of its outline is its own"),
             disc(True, False, f"{shape} (misfit 0.13 of its radius, at most 0.08 for a disc)"),
             disc(True, False, f"{shape} (misfit 0.29 of its radius, at most 0.08 for a disc)"),
             disc(True, False, "its angle is not the other discs' (+9.0° from their 12.0°, tolerance 3.0°)"),
             disc(True, False), disc(True, False)]
    (line,) = unfitted_lines(discs, 12)
    assert line == ("usable, not fitted: 2 no aperture shape explains its outline, 1 its angle is not the other discs' "
                    "(each disc's reason: --json's discs[].rejected_because); 2 not needed (the fit takes at most 12, "
                    "the clearest first)")
    assert unfitted_lines(discs[:2], 12) == []
    assert unfitted_lines(discs[:3], 5) == ["usable, not fitted: 1 no aperture shape explains its outline (each disc's "
                                            "reason: --json's discs[].rejected_because)"]


def test_the_runners_up_line_reads_beside_the_verdicts_margin(circle):
    # The answer set aside a model the pixels favour: the line's ΔBICs are above that model's, and it
    # gives the answer's own, so the verdict's margin over the runner-up is the difference of the two.
    fit = circle.fit
    favoured = dataclasses.replace(fit.candidates[1], delta_bic=0.0)
    chosen = dataclasses.replace(fit.candidates[0], delta_bic=40.0)
    rest = [dataclasses.replace(c, delta_bic=c.delta_bic + 40.0) for c in fit.candidates[2:]]
    changed = variant(circle, candidates=[chosen, favoured, *rest])
    line = next(line for line in changed.summary().splitlines() if line.startswith("runners-up"))
    name = favoured.family.aperture.display_name
    assert line.startswith(f"runners-up (ΔBIC above the {name} the pixels favour; the answer's own 40): ")
    plain = next(line for line in circle.summary().splitlines() if line.startswith("runners-up"))
    assert plain.startswith("runners-up: ") and "the answer's own" not in plain


def test_each_lens_feature_tried_says_why_it_was_kept_or_not(circle):
    """A feature tried and set aside is named with its gain and the test it failed, in the summary, the JSON
    and the report; so are the colours measured and found within chance."""
    from bokehfit.apertures import Chromatic
    from bokehfit.fit.chromatic import ChromaticMeasure
    from bokehfit.fit.features import FeatureTrial

    used = next(d["index"] for d in circle.to_json("")["discs"] if d["used"])
    rim = FeatureTrial("rim", 122.0, -113.0, True, False, 0.23, used, "disc 3 is a ring or has a bright centre")
    colours = ChromaticMeasure(Chromatic(-0.086, -0.138), Chromatic(0.026, 0.038), 6, False, Chromatic(0.15, 0.2))
    skipped = ("squeeze", "2 discs fitted jointly (3 needed to share a stretch)")
    tried = variant(circle, feature_trials=(rim,), chromatic_measure=colours, features_not_tried=(skipped,))
    rim_says = (f"rim (disc 3 is a ring or has a bright centre), not kept: ΔBIC 122, but -113 without disc {used}: "
                "one disc's, not the lens's")
    colours_says = ("chromatic (6 clean discs measured in red, green and blue), not kept: red -8.6 % ± 2.6, blue -13.8 % "
                    "± 3.8 from 6 discs, within what 6 discs can")
    summary = tried.summary()
    assert f"feature tried: {rim_says}" in summary and f"feature tried: {colours_says}" in summary, summary
    assert "feature not tried: squeeze: 2 discs fitted jointly (3 needed to share a stretch)" in summary, summary
    trials = tried.to_json("")["aperture"]["feature_trials"]
    assert [t["feature"] for t in trials] == ["rim", "chromatic"] and not any(t["kept"] for t in trials), trials
    assert trials[0]["delta_bic_one_disc_out"] == {"least": -113.0, "disc": used}, trials
    page = page_text(tried)
    assert "Lens features tried" in page and rim_says.split("), ", 1)[1] in page, page
    assert "squeeze 2 discs fitted jointly (3 needed to share a stretch) not tried" in " ".join(page.split()), page
    assert "chromatic 6 clean discs measured in red, green and blue no not kept: red -8.6 %" in " ".join(page.split())
    bare = variant(circle, feature_trials=(), chromatic_measure=None, features_not_tried=())
    assert "Lens features tried" not in page_text(bare)
