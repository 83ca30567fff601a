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
    assert data["a"] == {"shape": "hexagon", "angle_deg": 20.0, "blades": 6, "aspect": None, "symmetry_deg": 60.0,
                         "roundness": 0.0, "squeeze": 1.0, "vignetting": None, "field_position": None}
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


def test_ngon_n_spelling_as_in_compare_shapes(capsys):
    """``ngon(9)`` names the same aperture as ``ngon --blades 9``, as in ``compare --shapes``."""
    result = main(["similarity", "ngon(9)", "ngon", "--blades-b", "9"])
    assert result["a"] == result["b"] and result["a"]["blades"] == 9
    assert result["metrics"]["iou"] == pytest.approx(1.0, abs=1e-6)
    assert result["angle_error_deg"] == pytest.approx(0.0, abs=1e-9)


def test_aperture_features_per_side(capsys):
    """--roundness-a, --squeeze-b, --vignetting-a with --field-position-a change the compared outline."""
    result = main(["similarity", "ngon(9)", "ngon(9)", "--roundness-a", "0.5", "--squeeze-b", "1.4"])
    a = make_aperture("ngon", 0.0, blades=9, roundness=0.5)
    b = make_aperture("ngon", 0.0, blades=9, squeeze=1.4)
    assert result["a"]["roundness"] == 0.5 and result["b"]["squeeze"] == 1.4
    assert result["metrics"] == compare_outlines(aperture_outline(a), aperture_outline(b))
    assert result["metrics"]["iou"] < 0.95
    # Rounded blades at roundness 1 are the circle.
    assert main(["similarity", "ngon(9)", "circle", "--roundness-a", "1"])["metrics"]["iou"] == pytest.approx(1.0, abs=1e-4)
    clipped = main(["similarity", "pentagon", "pentagon", "--vignetting-a", "1.2,1.5", "--field-position-a", "0.7,0.3"])
    assert clipped["a"]["vignetting"] == {"radius": 1.2, "shift": 1.5} and clipped["a"]["field_position"] == [0.7, 0.3]
    assert clipped["metrics"]["iou"] < 0.9
    # At the centre a barrel of 1.2·R0 clears the pentagon's corners (circumradius 0.6485 < 0.677): nothing is cut.
    centred = main(["similarity", "pentagon", "pentagon", "--vignetting-a", "1.2,1.5"])
    assert centred["metrics"]["iou"] == pytest.approx(1.0, abs=1e-4)


@pytest.mark.parametrize(
    "args,needle",
    [
        (["star", "circle", "--roundness-a", "0.3"], "--roundness-a"),
        (["hexagon", "circle", "--field-position-b", "0.1,0.1"], "--field-position-b"),
    ],
)
def test_feature_options_name_the_option(args, needle):
    with pytest.raises(InputError, match=f"^{needle}"):
        main(["similarity", *args])


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--roundness-a", "2"], "argument --roundness-a: must be"),
        (["--squeeze-b", "0"], "argument --squeeze-b: must be"),
        (["--vignetting-a", "0.5,0"], "argument --vignetting-a: must be"),
        (["--vignetting-b", "1.2"], "argument --vignetting-b: must be RADIUS,SHIFT"),
        (["--field-position-a", "x,1"], "argument --field-position-a: must be"),
    ],
)
def test_bad_feature_values_one_line_exit_2(tmp_path, args, needle):
    done = bokehfit("similarity", "hexagon", "hexagon", *args, cwd=tmp_path)
    assert done.returncode == 2 and needle in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
