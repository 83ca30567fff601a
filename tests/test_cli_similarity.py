"""``bokehfit similarity``: the table, the JSON and the exit codes, through the installed command."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from bokehfit.apertures import make_aperture
from bokehfit.cli import main
from bokehfit.errors import InputError
from bokehfit.metrics import METRICS, aperture_outline, compare_outlines

JSON_KEYS = {"schema_version", "bokehfit_version", "command_line", "a", "b", "metrics", "angle_error_deg", "best_rotation_deg"}


def bokehfit(*args, cwd):
    return subprocess.run([sys.executable, "-m", "bokehfit", *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def test_json_matches_the_api(tmp_path):
    done = bokehfit("similarity", "hexagon", "circle", "--angle-a", "20", "--json", "s.json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    for name in METRICS:
        assert name in done.stdout
    data = json.loads((tmp_path / "s.json").read_text())
    assert JSON_KEYS <= set(data)
    assert data["schema_version"] == 1
    assert data["command_line"].startswith("bokehfit similarity hexagon circle")
    assert data["a"] == {"shape": "hexagon", "angle_deg": 20.0, "blades": 6, "aspect": None, "symmetry_deg": 60.0}
    assert data["b"]["shape"] == "circle" and data["b"]["angle_deg"] is None
    expected = compare_outlines(aperture_outline(make_aperture("hexagon", 20.0)), aperture_outline(make_aperture("circle")))
    assert data["metrics"] == expected  # JSON floats round-trip exactly
    assert data["angle_error_deg"] is None  # different shapes
    assert data["best_rotation_deg"] is None  # a circle has no best rotation
    assert not list(tmp_path.glob(".s.json.*")), "temporary files left behind"


def test_same_shape_reports_angle_error_and_rotation(tmp_path, capsys):
    result = main(["similarity", "hexagon", "hexagon", "--angle-a", "59", "--angle-b", "1", "--json", str(tmp_path / "s.json")])
    assert result["angle_error_deg"] == pytest.approx(2.0)
    # b (at 1°) turned by −2° matches a (at 59° ≡ −1°)
    assert result["best_rotation_deg"] == pytest.approx(-2.0, abs=0.05)
    assert result["metrics"]["iou"] == pytest.approx(1.0, abs=1e-3)
    assert json.loads((tmp_path / "s.json").read_text())["metrics"] == result["metrics"]
    out = capsys.readouterr().out
    assert "angle_error" in out and "2.000°" in out and "best rotation of B: -2.00°" in out


def test_ngon_and_slit_options(capsys):
    result = main(["similarity", "ngon", "slit", "--blades-a", "9", "--aspect-b", "0.5", "--angle-b", "30"])
    assert result["a"]["blades"] == 9 and result["b"]["aspect"] == 0.5
    assert result["angle_error_deg"] is None
    assert 0.0 < result["metrics"]["iou"] < 1.0


def test_unknown_shape_exit_2_one_line(tmp_path):
    done = bokehfit("similarity", "hexgon", "circle", "--json", "s.json", cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.startswith("bokehfit: error: SHAPE_A must be one of")
    assert "'hexgon'" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "s.json").exists()


@pytest.mark.parametrize(
    "args,needle",
    [
        (["circle", "stra"], "SHAPE_B"),
        (["ngon", "circle"], "--blades-a"),
        (["hexagon", "circle", "--blades-a", "5"], "--blades-a"),
        (["square", "circle", "--aspect-a", "2"], "--aspect-a"),
        (["circle", "slit", "--aspect-b", "0"], "--aspect-b"),
        (["circle", "square", "--angle-b", "nan"], "--angle-b"),
        (["circle", "square", "--json", "s.txt"], "output file"),
    ],
)
def test_bad_options_name_the_option(args, needle):
    with pytest.raises(InputError, match=f"^{needle}"):
        main(["similarity", *args])
