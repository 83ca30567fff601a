"""One result, one number: the summary, the JSON and the HTML report of ``compare`` agree.

Runs ``bokehfit compare`` (a fresh process each) on the default photo
(``examples/hexagon_85mm_f2.jpg``, a hexagon at 15°), on small rendered photos
and on reference photo 05 (no acceptable fit), and checks that every outcome
writes its JSON and a report named after it, that the kernel drawn is the
aperture reported, and that ``discs`` and ``compare`` share discs and words.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from test_cli_compare import PHOTO, bokehfit_cli, strict_json, write_jpeg, written

from bokehfit.apertures import make_aperture
from bokehfit.discs import find_discs
from bokehfit.report.overlay import ROLE_BGR, draw_disc_overlay
from bokehfit.synthetic import SyntheticDisc, render_discs
from bokehfit.words import diameter_text


@pytest.fixture(scope="module")
def hexagon_run(tmp_path_factory, gpu):
    """``compare`` and ``discs`` on the default photo: (stdout, document, html text, discs document)."""
    folder = tmp_path_factory.mktemp("report")
    done, _ = bokehfit_cli("compare", PHOTO, "--out-dir", "out", cwd=folder)
    assert done.returncode == 0, done.stderr
    stem = PHOTO.stem
    found, _ = bokehfit_cli("discs", PHOTO, "--json", "discs.json", cwd=folder)
    assert found.returncode == 0, found.stderr
    return (done.stdout, strict_json(folder / "out" / f"{stem}.json"),
            (folder / "out" / f"{stem}.html").read_text(encoding="utf-8"), strict_json(folder / "discs.json"))


def test_kernel_drawn_is_the_aperture_reported(hexagon_run):
    _, document, page, _ = hexagon_run
    aperture, kernel = document["aperture"], document["kernel"]
    assert (kernel["shape"], kernel["blades"]) == (aperture["shape"], aperture["blades"])
    assert kernel["angle_deg"] == aperture["angle_deg"]
    assert kernel["diameter_px"] == aperture["diameter_px"]
    assert f"The fitted aperture at {aperture['angle_deg']:.2f}°" in page


def test_disc_tiles_are_stored_at_the_windows_own_pixels_and_shown_at_the_tiles_size(hexagon_run):
    """Each disc's photo, model and residual tiles are shown at DISC_TILE_PX, enlarged by the browser as
    pixels (image-rendering: pixelated) from the window's own pixels where the window is smaller: the
    default photo's discs are 55 px, their windows under the tile's 120."""
    import base64

    import cv2

    from bokehfit.report.html import DISC_TILE_PX

    _, _, page, _ = hexagon_run
    assert ".tile img { image-rendering: pixelated; }" in page
    tiles = re.findall(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)" width="(\d+)" height="(\d+)" alt="(photo|model|residual)"', page)
    assert tiles
    for data, width, height, _ in tiles:
        image = cv2.imdecode(np.frombuffer(base64.b64decode(data), np.uint8), cv2.IMREAD_UNCHANGED)
        assert int(width) == int(height) == DISC_TILE_PX
        assert image.shape[0] == image.shape[1] < DISC_TILE_PX


def test_one_angle_and_one_diameter_everywhere(hexagon_run):
    stdout, document, page, _ = hexagon_run
    aperture = document["aperture"]
    winner = aperture["candidates"][0]
    assert (winner["angle_deg"], winner["diameter_px"]) == (aperture["angle_deg"], aperture["diameter_px"])
    angle, diameter = f"{aperture['angle_deg']:.2f}°", f"{aperture['diameter_px']:.2f}"
    verdict = stdout.splitlines()[0]
    assert verdict == document["verdict"] and angle in verdict
    shown = diameter_text(aperture)  # to the uncertainty's digits
    assert shown.startswith(f"{aperture['diameter_px']:.2f}") and " ± " in shown
    assert f"disc {shown}" in stdout
    assert shown in page and f"{angle} counter-clockwise from x" in page
    # The candidate table's winner row shows the same diameter.
    assert re.search(rf"<td>hexagon</td><td>{aperture['angle_deg']:.2f}</td>.*?<td>{diameter}</td>", page)
    # Each fitted disc's tile shows the JSON's fitted diameter, and nothing else claims to.
    fitted = [d for d in document["discs"] if d["used"]]
    assert fitted
    tiles = dict(re.findall(r"#(\d+): fitted ([0-9.]+) px", page))
    assert tiles, "the report shows the fitted discs"
    for disc in fitted:
        if str(disc["index"]) in tiles:
            assert tiles[str(disc["index"])] == f"{disc['fit_diameter_px']:.2f}"


def test_report_reads_for_a_photographer(hexagon_run):
    _, document, page, _ = hexagon_run
    first = re.search(r'<p class="verdict (\w+)">([^<]*)</p>', page)
    assert first and first.group(1) == "fitted" and first.group(2).startswith("Sure: hexagon")
    assert len(first.group(2)) <= 120, "one short sentence first"
    details = re.search(r'<p class="details">([^<]*)</p>', page)
    assert details and "very strong evidence" in details.group(1), "the numbers after it"
    assert page.index('class="verdict') < page.index("<svg"), "the verdict comes first"
    assert 'aria-label="aperture diagram"' in page
    assert page.count('class="bar"') >= 2, "colour scales on the residuals and on the kernel"
    for words in ("used in the fit", "usable, not needed", "rejected"):
        assert words in page
    assert "0.799657" not in page and not re.search(r"aspect \d\.\d{3,}", page)


def test_discs_and_compare_share_discs_and_words(hexagon_run):
    _, document, _, discs_document = hexagon_run
    compare_discs, found = document["discs"], discs_document["discs"]
    assert [d["diameter_px"] for d in compare_discs] == [d["diameter_px"] for d in found]
    assert [d["usable"] for d in compare_discs] == [d["usable"] for d in found]
    assert "used" not in found[0], "discs fits nothing: it says usable, never used"
    for disc in compare_discs:
        assert not disc["used"] or disc["usable"]
        assert bool(disc["rejected_because"]) == (not disc["usable"])
    assert any(d["usable"] and not d["used"] for d in compare_discs), "the photo has more clean discs than the budget"


def test_reports_of_two_photos_do_not_overwrite_each_other(tmp_path, gpu):
    discs = [SyntheticDisc((40 + 60 * i, 50), 36, make_aperture("hexagon", 10), brightness=0.6) for i in range(4)]
    for name in ("a.jpg", "b.jpg"):
        write_jpeg(tmp_path / name, discs, width=280, height=100)
        done, _ = bokehfit_cli("compare", name, "--out-dir", "out", "--shapes", "circle,hexagon", cwd=tmp_path)
        assert done.returncode == 0, done.stderr
    assert {"out/a.json", "out/a.html", "out/b.json", "out/b.html"} <= written(tmp_path)
    assert "a.jpg" in (tmp_path / "out" / "a.html").read_text() and "b.jpg" in (tmp_path / "out" / "b.html").read_text()


def test_without_outputs_nothing_is_written_and_it_says_so(tmp_path, gpu):
    write_jpeg(tmp_path / "a.jpg", [SyntheticDisc((60, 60), 40, make_aperture("hexagon", 10), brightness=0.6)])
    done, _ = bokehfit_cli("compare", "a.jpg", "--shapes", "hexagon", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "no files written" in done.stdout
    assert written(tmp_path) == {"a.jpg"}


def test_unusable_discs_write_json_and_report_with_the_reason(tmp_path):
    hexagon = make_aperture("hexagon", 10)
    write_jpeg(tmp_path / "sat.jpg", [SyntheticDisc((5, 60), 50, hexagon), SyntheticDisc((215, 60), 40, hexagon)])
    done, _ = bokehfit_cli("compare", "sat.jpg", "--json", "res/sat.json", cwd=tmp_path)
    assert done.returncode == 1
    document = strict_json(tmp_path / "res" / "sat.json")
    assert document["status"] == "no_discs" and "cut by the frame" in document["reason"]
    assert all(d["rejected_because"][0] == "cut by the frame" for d in document["discs"])
    for key in ("roundness", "squeeze", "vignetting", "rim", "chromatic"):
        assert document["aperture"][key] is None and document["aperture"][f"{key}_uncertainty"] is None
    page = (tmp_path / "res" / "sat.html").read_text(encoding="utf-8")
    assert '<p class="verdict no_discs">No usable disc: no disc is clean enough' in page


def test_no_acceptable_fit_writes_json_and_report(tmp_path, gpu):
    # Slit-shaped discs (one slit aperture: all alike), with the circle the only shape allowed: no
    # model tried explains them (the circle overlaps a slit of aspect 0.3 by about 0.2 of their union).
    discs = [SyntheticDisc((50 + 90 * i, 60), 40, make_aperture("slit", 25.0, aspect=0.3), brightness=0.6)
             for i in range(5)]
    write_jpeg(tmp_path / "slits.jpg", discs, width=470, height=120)
    done, _ = bokehfit_cli("compare", "slits.jpg", "--shapes", "circle", "--json", "weak.json", cwd=tmp_path)
    assert done.returncode == 1, done.stdout + done.stderr
    document = strict_json(tmp_path / "weak.json")
    assert document["status"] == "no_fit" and document["reason"]
    assert document["aperture"]["candidates"], "the candidates tried are reported"
    assert "No fit:" in (tmp_path / "weak.html").read_text(encoding="utf-8")


def test_overlay_colours_roles_and_sizes_labels_to_the_picture():
    assert len(set(ROLE_BGR.values())) == 3
    discs = [SyntheticDisc((100 + 200 * i, 150), 80, make_aperture("circle", 0), brightness=0.5) for i in range(3)]
    luminance = render_discs(700, 300, discs, noise_sigma=0.002, seed=2)
    found = find_discs(luminance).discs
    rgb = np.repeat(np.round(np.sqrt(np.clip(luminance, 0, 1)) * 255).astype(np.uint8)[..., None], 3, axis=-1)
    full = draw_disc_overlay(rgb, found, used={found[0].index})
    small = draw_disc_overlay(rgb, found, used={found[0].index}, max_side=350)
    assert small.shape[:2] == (150, 350)
    for canvas in (full, small):
        colours = {tuple(int(v) for v in px) for px in canvas.reshape(-1, 3)}
        assert ROLE_BGR["used"] in colours and ROLE_BGR["usable"] in colours
