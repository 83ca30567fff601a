"""The disc finder on the real CC0 photos: what reference_photos/manifest.json states, as ranges.

The manifest's sizes were read off by eye (±15 %) and its counts are rough, so
these tests assert ranges and places, not exact numbers.
"""

from __future__ import annotations

import numpy as np
import pytest

from bokehfit.discs import find_discs
from bokehfit.io import load_photo


@pytest.fixture(scope="module")
def found(reference_photo):
    cache = {}

    def search(name):
        if name not in cache:
            photo = load_photo(reference_photo(name))
            cache[name] = (photo, find_discs(photo.luminance, photo.clipped))
        return cache[name]

    return search


def in_box(discs, x0, x1, y0, y1):
    return [d for d in discs if x0 <= d.center_xy[0] <= x1 and y0 <= d.center_xy[1] <= y1]


def test_01_water_glints_round_discs_of_16_to_20_px(found):
    photo, search = found("01_water-glints_canon6d_ef85.jpg")
    resolvable = [d for d in search.discs if d.resolvable]
    sharp = [d for d in resolvable if not d.soft_edge]  # the soft-edged ones are the second tier
    assert 15 <= len(sharp) <= 60
    assert len(resolvable) - len(sharp) <= len(sharp)
    assert 12.0 <= np.median([d.diameter_px for d in resolvable]) <= 24.0
    assert len(in_box(resolvable, 1000, 1550, 520, 750)) >= 5  # the densest cluster
    assert sum(d.usable for d in search.discs) >= 5


def test_02_dew_discs_from_small_to_large(found):
    photo, search = found("02_dew-glints_aaron-burden.jpg")
    assert len(search.discs) >= 15
    assert sum(d.diameter_px >= 60 for d in search.discs) >= 3  # most are 80–200 px
    assert max(d.diameter_px for d in search.discs) <= 400


def test_03_frost_finds_many_small_discs(found):
    photo, search = found("03_frosted-grass_pixabay-1358926.jpg")
    assert len(search.discs) >= 50
    assert 4.0 <= np.median([d.diameter_px for d in search.discs]) <= 25.0


@pytest.mark.xfail(
    strict=True,
    reason="known limit: the faint discs in the hazy band are small (6–25 px) with contrast under 15 % of the "
    "haze: the lower contrast floor holds from LARGE_DISC_PX only, where JPEG blocks average out; and in-focus "
    "frost glints in the foreground pass as small discs",
)
def test_03_frost_many_small_discs_in_a_band(found):
    photo, search = found("03_frosted-grass_pixabay-1358926.jpg")
    assert len(search.discs) >= 50
    in_band = [d for d in search.discs if 300 <= d.center_xy[1] <= 800]
    assert len(in_band) >= 0.6 * len(search.discs)
    assert 5.0 <= np.median([d.diameter_px for d in in_band]) <= 25.0
    assert not any(d.saturated for d in search.discs)  # "none clipped"


def test_04_juniper_ring_discs_on_the_sprig(found):
    """Soap-bubble rings of 25–60 px over the lit sprig of a 22-MP photo. The blob search finds none of
    them (each ring's light is one low-threshold blob with the sprig, cut at the sprig's brightest); they
    are found by their edges, the band of 32–64 px searched on the photo halved, tile by tile. Before
    the tiles that band was left out of a photo this large (the transform took 31 s on one copy): 1 of
    the person's 18 rings found usable, now 5."""
    from photo_factory import reference_labels

    from bokehfit.discs.labels import matches

    photo, search = found("04_juniper-droplet-rings_pablo-garcia-saldana.jpg")
    rings = [d for d in in_box(search.discs, 1800, 2250, 850, 1350) if 20 <= d.diameter_px <= 55]
    assert len(rings) >= 3
    _, labels = reference_labels("04_juniper-droplet-rings_pablo-garcia-saldana.jpg")
    usable = [d for d in search.discs if d.usable]
    labelled = [label for label in labels.usable if label.kind == "ring"]
    assert sum(any(matches(d.center_xy, d.diameter_px, label) for d in usable) for label in labelled) >= 5


def test_05_backlit_grass_is_a_weak_case(found):
    photo, search = found("05_backlit-grass_unsplash-522b53fb137bb.jpg")
    # Clipped sun and in-focus glints: almost nothing here is a clean plateau. 9 before blobs were also
    # measured by their step along rays, 11 since: the two more are faint blobs of the background's
    # bokeh, outside the boxes where the person's labels are complete.
    assert sum(d.usable and d.evidence == "plateau" for d in search.discs) <= 12


def test_06_saturated_string_lights_are_kept_as_outline_evidence(found):
    photo, search = found("06_christmas-lights_nikon-d5300.jpg")
    saturated = [d for d in search.discs if d.saturated]
    assert len(saturated) >= 30  # "a dense band of overlapping, mostly saturated discs"
    assert all(d.evidence in ("edge", "partial") and d.clipped_share > 0 for d in saturated)
    assert sum(d.shape_usable for d in saturated) >= 30
    clean = [d for d in in_box(search.discs, 0, 2560, 450, 750) if 35 <= d.diameter_px <= 60]
    assert len(clean) >= 10  # "clean isolated round discs of 40–50 px around y 450–750"


def test_07_large_low_contrast_discs_on_a_bright_background(found):
    photo, search = found("07_touch-the-light_canon-50d-ef100.jpg")
    large = [d for d in search.discs if 150 <= d.diameter_px <= 250]
    assert len(large) >= 4  # "about 20 large (170–210 px), low-contrast, heavily overlapping discs"
    assert search.time_s < 60.0
