"""The words a person reads: a ``compare`` result's numbers said for people.

Each function takes the numbers of a ``compare --json`` document (or the disc and
fit behind them) and says them in words: the f-stop and the geometry behind it,
the disc's size, a light's distance, the aperture's shape and features, the
strength of the evidence, why a disc was not used, how the kernel was drawn. The
summary, the verdict (:class:`bokehfit.comparison.Comparison`) and the HTML
report (:mod:`bokehfit.report.html`) all say them this way. A value with its
uncertainty is written by :mod:`bokehfit.uncertainty`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from bokehfit.apertures import Aperture
from bokehfit.discs import MIN_FIT_SEEN, Disc
from bokehfit.discs.measure import RESOLVABLE_PX
from bokehfit.optics import FAR_AS_INFINITY
from bokehfit.uncertainty import measurable, plus_minus

if TYPE_CHECKING:
    from bokehfit.fit import ApertureFit

__all__ = [
    "EVIDENCE_WORDS",
    "HEADLINE_CHARS",
    "angle_note",
    "article",
    "clip_headline",
    "counted",
    "describe",
    "diameter_text",
    "disc_problems",
    "distance_text",
    "evidence_words",
    "feature_trial_lines",
    "fstop_text",
    "geometry_lines",
    "kernel_words",
    "place_text",
    "rejection_counts",
    "rejection_lines",
    "shape_words",
    "table_candidates",
    "used_as",
]

#: Evidence in words for a BIC margin (Kass & Raftery 1995, "Bayes factors",
#: J. Am. Stat. Assoc. 90:773, section 3.2, on the scale 2·ln B ≈ ΔBIC).
EVIDENCE_WORDS = ((2.0, "barely any"), (6.0, "positive"), (10.0, "strong"), (math.inf, "very strong"))
#: The verdict's first sentence aims at most this many characters (what the aperture is, how sure, why).
HEADLINE_CHARS = 120
#: The first sentence names the angle only where its uncertainty is at most this share of the shape's symmetry:
#: beyond it, the angle's ±2σ span covers the whole symmetry, every angle the shape can have (reference photo 15:
#: a rounded triangle at 47.89° ± 100° from two discs).
ANGLE_FIXED_SHARE = 0.25
#: A search's places that are no disc are counted by reason in the summary, this many reasons named (each place with
#: its reason is in the JSON); a person's places (``compare --discs``) that are no disc are named one by one.
REJECTION_REASONS_NAMED = 4


def fstop_text(aperture: dict) -> str:
    """The f-stop for people from the JSON's aperture: a value, a bound (said as one), or why it is unknown."""
    if aperture["fstop"] is None:
        return f"unknown: {aperture['fstop_reason']}"
    value = "f/" + plus_minus(aperture["fstop"], aperture["fstop_uncertainty"])
    how = f"{aperture['size_convention']}, {aperture['lens_model']} lens"
    if aperture.get("fstop_bound") == "upper":
        return f"at most {value} ({how}; {aperture['fstop_meaning']})"
    return f"{value} ({how})"


def geometry_lines(data: dict) -> list[str]:
    """The geometry behind the f-stop, each value with its source, from the JSON."""
    geometry = data["geometry"]
    sources = geometry["sources"]
    parts = []
    for key, label, unit in (("focal_length_mm", "focal length", "mm"), ("sensor_width_mm", "sensor width", "mm"),
                             ("focus_distance_m", "focus distance", "m"), ("light_distance_m", "lights' distance", "m")):
        value = geometry[key]
        shown = "unknown" if value is None else f"{value:g} {unit}"
        if key == "light_distance_m" and value is None:
            shown = "unknown"
        parts.append(f"{label} {shown} [{sources.get(key, 'unknown')}]")
    lines = ["geometry: " + "; ".join(parts)]
    if geometry.get("frame"):
        lines.append(f"frame: {geometry['frame']}")
    for ignored in data["input"]["exif"].get("ignored", []):
        lines.append(f"EXIF value ignored: {ignored}")
    return lines


def diameter_text(aperture: dict) -> str:
    """The disc diameter of the JSON's aperture for people, or why it is not measurable."""
    if aperture["diameter_px"] is None:
        return aperture.get("diameter_reason") or "unknown"
    return plus_minus(aperture["diameter_px"], aperture["diameter_uncertainty_px"], unit=" px")


def distance_text(distance_m: float | None, focus_distance_m: float | None = None) -> str:
    """A light's distance for people: "≈ ∞" at :data:`FAR_AS_INFINITY` focus distances or farther."""
    if distance_m is None:
        return "—"
    if not math.isfinite(distance_m) or (focus_distance_m and distance_m >= FAR_AS_INFINITY * focus_distance_m):
        return "≈ ∞"
    return f"{distance_m:.3g} m"


def table_candidates(aperture: dict) -> list[dict]:
    """The JSON's candidates as the runners-up tables list them: the chosen model, the runner-up the
    verdict names, then the rest by ΔBIC (``aperture.runners_up`` names them in this order)."""
    candidates = aperture["candidates"]
    if not candidates:
        return []
    first = [c for c in candidates if c.get("role") == "runner_up"]
    rest = sorted((c for c in candidates[1:] if c.get("role") != "runner_up"), key=lambda c: c["delta_bic"])
    return [candidates[0], *first, *rest]


def counted(count: int, noun: str) -> str:
    """``count`` and the noun, plural but for one: "1 disc", "2 discs"."""
    return f"{count} {noun}" + ("" if count == 1 else "s")


def feature_trial_lines(aperture: dict) -> list[str]:
    """The summary's lines on the lens's features (the JSON's ``feature_trials``): each one tried, what the discs
    showed that asked for it, what it gained and why it joined the model or did not; then each the discs did not
    ask for, and what they showed instead."""
    return ([f"feature tried: {trial['feature']}"
             + (f" ({trial['asked_because']})" if trial.get("asked_because") else "") + f", {trial['reason']}"
             for trial in aperture.get("feature_trials") or []]
            + [f"feature not tried: {skipped['feature']}: {skipped['reason']}"
               for skipped in aperture.get("features_not_tried") or []])


def runners_up_line(candidates: list[dict]) -> str:
    """The summary's runners-up line: each model's ΔBIC above the model that explains the pixels best (as the
    JSON's ``delta_bic`` and the report's table give it); where the answer is not that model (the consensus
    or the outlines set it aside), the line says so and gives the answer's own ΔBIC, so that the verdict's
    margin over the runner-up reads as the difference of the two."""
    same = {"same_answer": ", the same answer"}
    ranked = ", ".join(f"{c['display_name']} (ΔBIC {c['delta_bic']:.0f}{same.get(c['role'], '')})" for c in candidates[1:])
    if not candidates or round(candidates[0]["delta_bic"]) <= 0:
        return f"runners-up: {ranked or 'none'}"
    best = min(candidates, key=lambda c: c["delta_bic"])
    return (f"runners-up (ΔBIC above the {best['display_name']} the pixels favour; the answer's own "
            f"{candidates[0]['delta_bic']:.0f}): {ranked}")


def clip_headline(sentence: str) -> str:
    """A headline kept near :data:`HEADLINE_CHARS`: cut at a clause boundary before it when longer."""
    if len(sentence) <= HEADLINE_CHARS:
        return sentence
    for mark in (" (", "; ", ": ", ", "):
        cuts = [i for i in range(len(sentence)) if sentence.startswith(mark, i) and i < HEADLINE_CHARS - 1
                and sentence.count("(", 0, i) == sentence.count(")", 0, i) and i > len(sentence.split(":")[0]) + 2]
        if cuts:
            return sentence[:max(cuts)].rstrip(" ,;:") + "."
    return sentence[: HEADLINE_CHARS - 1].rstrip() + "…"


def shape_words(aperture: dict) -> str:
    """The aperture's shape and angle for the verdict's first sentence (its features come after, with numbers); the
    angle only where the discs fix it (ANGLE_FIXED_SHARE of the symmetry)."""
    name = Aperture.from_json(aperture).display_name
    angle, sigma, symmetry = aperture["angle_deg"], aperture.get("angle_uncertainty_deg"), aperture.get("symmetry_deg")
    if angle is None:
        return name
    if sigma is not None and symmetry and sigma > ANGLE_FIXED_SHARE * symmetry:
        return name + " (its angle not fixed by the discs)"
    return name + f" at {angle:.2f}°"


def article(words: str) -> str:
    """'a circle', 'an 8-blade polygon'."""
    vowel = words[:1].lower() in "aeiou" or words.split("-")[0] in ("8", "11", "18")
    return ("an " if vowel else "a ") + words


def describe(aperture: dict) -> str:
    """'hexagon at 15.02° ± 0.05°' from the JSON's aperture (its numbers, rounded for people).

    A feature whose uncertainty exceeds its departure from the plain aperture is not shown: the
    discs do not support it.
    """
    name = Aperture.from_json(aperture).display_name
    if aperture["aspect"] is not None:
        name += f" (aspect {aperture['aspect']:.2f})"
    if aperture["angle_deg"] is not None:
        name += " at " + plus_minus(aperture["angle_deg"], aperture["angle_uncertainty_deg"], unit="°")

    def supported(key, neutral=0.0, part=None):
        value, sigma = aperture.get(key), aperture.get(f"{key}_uncertainty")
        if part is not None:
            value = None if value is None else value.get(part)
            sigma = None if sigma is None else sigma.get(part)
        return value is not None and value != neutral and measurable(value - neutral, sigma)

    features = []
    if supported("roundness"):
        features.append("roundness " + plus_minus(aperture["roundness"], aperture.get("roundness_uncertainty")))
    if supported("squeeze", 1.0):
        tall = "taller than wide" if aperture["squeeze"] > 1 else "wider than tall"
        features.append(f"anamorphic squeeze {plus_minus(aperture['squeeze'], aperture.get('squeeze_uncertainty'), 3)} "
                        f"(discs {tall})")
    if supported("rim"):
        side = "bright rim" if aperture["rim"] > 0 else "bright centre"
        features.append(f"rim {plus_minus(aperture['rim'], aperture.get('rim_uncertainty'))} ({side})")
    if aperture.get("vignetting"):
        cut = aperture["vignetting"]
        features.append(f"cat-eye vignetting (barrel radius {cut['radius']:.2f}, shift {cut['shift']:+.2f})")
    if aperture.get("chromatic") and (supported("chromatic", part="red") or supported("chromatic", part="blue")):
        colour = aperture["chromatic"]
        features.append(f"chromatic (red disc {100 * colour['red']:+.1f} %, blue {100 * colour['blue']:+.1f} % of green's)")
    return name + "".join(f", {feature}" for feature in features)


def evidence_words(delta_bic: float) -> str:
    """How strongly a BIC margin favours the winner, in words (Kass & Raftery 1995)."""
    return next(words for limit, words in EVIDENCE_WORDS if delta_bic < limit)


def disc_problems(disc: Disc) -> list[str]:
    """Why a disc is not usable, in words shared by ``discs`` and ``compare`` (empty when usable)."""
    if disc.usable:
        return []
    problems = ["cut by the frame"] if disc.clipped else []
    if not disc.resolvable:
        problems.append(f"under {RESOLVABLE_PX:g} px")
    if disc.outline_seen < MIN_FIT_SEEN:
        problems.append(f"only {disc.outline_seen:.0%} of its outline is its own")
    return problems


def used_as(disc: Disc, fitted) -> str:
    """What a used disc gave the fit, in words."""
    if disc.evidence == "plateau" and not fitted.censored:
        return "plateau and outline"
    if fitted.censored:
        return f"outline (saturated: {fitted.censored} clipped pixels fitted as lower bounds)"
    if disc.profiled:
        return f"outline and profile ({'a ring: bright rim' if disc.ring else 'bright centre'})"
    if disc.evidence == "partial" or disc.overlaps:
        left_out = "the occluder" if disc.occluded else "the other light"
        return f"its own part ({disc.outline_seen:.0%} of the outline; {left_out} left out)"
    return "outline"


def angle_note(fit: ApertureFit) -> str | None:
    """An odd-symmetry aperture's angle both ways, where the focus side is unknown (None otherwise)."""
    aperture = fit.aperture
    if not aperture.odd_symmetry or fit.focus_side != "unknown":
        return None
    other = aperture.near().canonical_angle_deg
    return (
        f"odd symmetry: lights behind the focus plane give {aperture.canonical_angle_deg:.2f}°, "
        f"lights in front of it {other:.2f}° (pass --focus-side to choose)"
    )


def kernel_words(data: dict) -> str:
    """How the matched kernel of a ``compare`` JSON document was drawn, in words (method, samples, device)."""
    kernel, device = data["kernel"], data["device"]
    if kernel is None:
        return "none drawn"
    words = kernel["method"] if kernel["samples"] is None else f"{kernel['method']}, {kernel['samples']} samples"
    adapter = device.get("adapter")
    return f"{words} on {adapter}" if adapter else f"{words} on the CPU"


def rejection_counts(detection: dict) -> list[tuple[str, int]]:
    """A search's places that are no disc (a ``detection`` of ``compare --json``), counted by reason (the words before
    a reason's numbers), the most first."""
    return reason_counts(detection["rejected"].items())


def reason_counts(reasons) -> list[tuple[str, int]]:
    """``(reason, count)`` pairs counted by the words before each reason's numbers (its head, up to " ("), the most
    first."""
    counts: dict[str, int] = {}
    for reason, n in reasons:
        head = reason.split(" (")[0]
        counts[head] = counts.get(head, 0) + n
    return sorted(counts.items(), key=lambda item: (-item[1], item[0]))


def place_text(rejection: dict) -> str:
    """A place measured (an entry of ``detection.rejections``) as a person reads it: "(x, y), D px"."""
    return f"({rejection['center_xy'][0]:.0f}, {rejection['center_xy'][1]:.0f}), {rejection['diameter_px']:.0f} px"


def unfitted_lines(discs: list[dict], max_discs: int) -> list[str]:
    """The usable discs the fit did not use, for the summary (``discs`` of ``compare --json``): those it set
    aside, counted by reason (:func:`reason_counts`; each disc's whole reason is in the JSON), and those it did not
    need (it takes at most ``max_discs``, the clearest first, and screens no more once it has them)."""
    unused = [d for d in discs if d["usable"] and not d["used"]]
    set_aside = reason_counts((d["rejected_because"][0], 1) for d in unused if d["rejected_because"])
    spare = len(unused) - sum(n for _, n in set_aside)
    parts = ([", ".join(f"{n} {why}" for why, n in set_aside) + " (each disc's reason: --json's discs[].rejected_because)"]
             if set_aside else []) + \
        ([f"{spare} not needed (the fit takes at most {max_discs}, the clearest first)"] if spare else [])
    return [f"usable, not fitted: {'; '.join(parts)}"] if parts else []


def rejection_lines(detection: dict) -> list[str]:
    """The places measured that are no disc, for the summary: a ``detection`` of ``compare --json``. Each place a
    person gave (``places_given``) on a line of its own; a search's counted by reason (:func:`rejection_counts`),
    REJECTION_REASONS_NAMED reasons named, the rest counted together."""
    if detection["places_given"]:
        return [f"not a disc at {place_text(r)} given: {r['rejected_because']}" for r in detection["rejections"]]
    counts = rejection_counts(detection)
    if not counts:
        return []
    named = counts[:REJECTION_REASONS_NAMED]
    rest = sum(n for _, n in counts[REJECTION_REASONS_NAMED:])
    words = ", ".join(f"{n} {why}" for why, n in named) + (f", {rest} for other reasons" if rest else "")
    return [f"not discs: {words} (each with its place and reason: --json's detection.rejections)"]
