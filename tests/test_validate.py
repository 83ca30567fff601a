"""Numeric parameters at the public boundary: one table of ranges, the same check for the API and the CLI.

Each test names the issue it guards: absurd geometry accepted silently, argparse's
"invalid _distance value", overflow from a huge exposure, an uncapped sample count.
"""

from __future__ import annotations

import argparse
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bokehfit.apertures import make_aperture, parse_shape
from bokehfit.cli import build_parser
from bokehfit.cli.arg_types import arg_type
from bokehfit.errors import InputError
from bokehfit.kernels import render_kernel
from bokehfit.optics import coc_mm, fstop_from_coc, pixel_pitch_mm
from bokehfit.scene import make_lens, make_settings, parse_depths, tone_map_srgb8
from bokehfit.validate import RANGES, check

REPO = Path(__file__).resolve().parents[1]


def bokehfit(*args, cwd):
    return subprocess.run([sys.executable, "-m", "bokehfit", *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def parse(argv):
    """Parse a command line as ``bokehfit`` would; usage errors come back as (exit code, message)."""
    try:
        return build_parser().parse_args(argv)
    except SystemExit as exit:
        return exit.code


# --- the table ---------------------------------------------------------------------------------


def test_every_range_is_an_interval_with_a_reason():
    for name, rule in RANGES.items():
        assert rule.low < rule.high, name
        assert len(rule.reason) > 10, f"{name}: say why the range is what it is"


@pytest.mark.parametrize("quantity", sorted(RANGES))
def test_check_accepts_the_bounds_it_states_and_refuses_just_beyond(quantity):
    rule = RANGES[quantity]
    if not rule.low_open:
        assert check(quantity, int(rule.low) if rule.integer else rule.low) == rule.low
    assert check(quantity, int(rule.high) if rule.integer else rule.high) == rule.high
    beyond = int(rule.high) + 1 if rule.integer else rule.high * (1 + 1e-9) + 1e-12
    with pytest.raises(InputError, match=rf"^{quantity} must be .* \(got "):
        check(quantity, beyond)
    for bad in (float("nan"), True, "3"):
        with pytest.raises(InputError, match=quantity):
            check(quantity, bad)


# --- absurd geometry, API and command line alike ------------------------------------------------


@pytest.mark.parametrize(
    "call,needle",
    [
        (lambda: coc_mm(2.0, 1e-300, 2.0, 10.0), r"focal_length_mm must be a finite number in \[1, 10000\] mm \(got 1e-300\)"),
        (lambda: coc_mm(2.0, 50.0, 2.0, -3.0), r"light_distance_m must be a number in \(0, .*\] m or inf \(got -3.0\)"),
        (lambda: fstop_from_coc(0.5, 50.0, 1e300, 10.0), r"focus_distance_m must be a finite number in \[0.001, 1e\+06\] m"),
        (lambda: pixel_pitch_mm(1e308, 6000, 4000), r"sensor_width_mm must be a finite number in \[1, 300\] mm"),
        (lambda: make_lens(make_aperture("circle"), fstop=2.0, focus_distance_m=0.7, focal_length_mm=1e-300), "focal_length_mm"),
        (lambda: make_lens(make_aperture("circle"), fstop=2.0, focus_distance_m=0.7, sensor_width_mm=1e308), "sensor_width_mm"),
        (lambda: make_lens(make_aperture("circle"), fstop=2.0, focus_distance_m=0.04, focal_length_mm=50.0),
         "focus_distance_m must be longer than the focal length"),
        (lambda: make_settings(64, 64, 2**24), r"spp must be an integer in \[1, 65536\] \(got 16777216\)"),
        (lambda: tone_map_srgb8(np.zeros((2, 2, 3)), 1e308), r"exposure_ev must be a finite number in \[-30, 30\] EV"),
        (lambda: parse_depths("1,-3"), r"light depths must be a number in \(0, .*\] m or inf \(got -3.0\)"),
    ],
    ids=["focal-tiny", "light-negative", "focus-huge", "sensor-huge", "lens-focal", "lens-sensor", "lens-focus-inside",
         "spp-huge", "exposure-huge", "light-depth-negative"],
)
def test_python_api_refuses_absurd_numbers_naming_the_parameter_and_range(call, needle):
    with pytest.raises(InputError, match=needle):
        call()


@pytest.mark.parametrize(
    "argv,option,expected",
    [
        (["compare", "p.jpg", "--focal-length-mm", "1e-300"], "--focal-length-mm", "[1, 10000] mm (got 1e-300)"),
        (["compare", "p.jpg", "--sensor-width-mm", "1e308"], "--sensor-width-mm", "[1, 300] mm (got 1e+308)"),
        (["compare", "p.jpg", "--light-distance-m", "-3"], "--light-distance-m", "m or inf (got -3.0)"),
        (["render", "--out", "x.png", "--spp", "16777216"], "--spp", "[1, 65536] (got 16777216)"),
        (["render", "--out", "x.png", "--exposure", "1e308"], "--exposure", "[-30, 30] EV (got 1e+308)"),
        (["render", "--out", "x.png", "--fstop", "0"], "--fstop", "[0.1, 10000] (got 0.0)"),
        (["kernel", "--out", "k.npy", "--samples", "2147483648"], "--samples", "[1, 2147395600] (got 2147483648)"),
        (["kernel", "--out", "k.npy", "--size", "9000"], "--size", "[1, 8192] px (got 9000)"),
        (["kernel", "--out", "k.npy", "--diameter-px", "abc"], "--diameter-px", "(0, 20000] px (got 'abc')"),
    ],
)
def test_command_line_refuses_them_with_the_same_range(argv, option, expected, capsys):
    assert parse(argv) == 2
    message = capsys.readouterr().err
    assert f"argument {option}: must be " in message and expected in message, message
    assert "invalid" not in message


def test_light_distance_minus_three_says_what_is_expected(tmp_path):
    """The issue's case, through the installed command: exit 2, one line, the range, no 'invalid _distance value'."""
    done = bokehfit("compare", "photo.jpg", "--light-distance-m", "-3", cwd=tmp_path)
    assert done.returncode == 2
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "--light-distance-m: must be a number in (0, " in done.stderr and "or inf (got -3.0)" in done.stderr


def test_light_distance_accepts_inf_on_the_command_line():
    assert math.isinf(parse(["compare", "p.jpg", "--light-distance-m", "inf"]).light_distance_m)


def test_argparse_type_and_api_share_one_message():
    with pytest.raises(InputError) as api:
        check("focal_length_mm", 0.5, name="--focal-length-mm")
    with pytest.raises(argparse.ArgumentTypeError) as cli:
        arg_type("focal_length_mm", "--focal-length-mm")("0.5")
    assert str(api.value) == f"--focal-length-mm {cli.value}"


# --- shape names: one parser --------------------------------------------------------------------


def test_one_shape_parser_for_every_entry_point():
    assert parse_shape("ngon(9)") == parse_shape(" NGON( 9 ) ") == ("ngon", 9)
    assert parse_shape("hexagon") == ("hexagon", None)
    assert make_aperture("ngon(9)", 10.0) == make_aperture("ngon", 10.0, blades=9)
    np.testing.assert_array_equal(
        render_kernel(make_aperture("ngon(9)", 5.0), 20.0, 32), render_kernel(make_aperture("ngon", 5.0, blades=9), 20.0, 32)
    )
    with pytest.raises(InputError, match="blades must be 9 or omitted"):
        make_aperture("ngon(9)", blades=8)
    with pytest.raises(InputError, match=r"blades must be an integer from 3 to 64 .*ngon\(99\)"):
        parse_shape("ngon(99)")


# --- --help cites only sections that exist (help text and defaults: tests/test_cli_help.py) ------


def _subparser(name):
    action = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices[name]


def test_render_help_cites_only_sections_that_exist():
    description = _subparser("render").description
    cited = re.findall(r"([\w/.-]+\.md)(?:, section (\d+))?", description)
    assert cited, description
    for path, section in cited:
        document = REPO / path
        assert document.is_file(), f"render --help cites {path}, which is not in the repository"
        if section:
            assert re.search(rf"^## {section}\. ", document.read_text(), flags=re.M), f"{path} has no section {section}"


# --- the adapter's limits, checked before a dispatch ----------------------------------------------


def test_bind_and_dispatch_check_the_adapter_limits_first():
    """Work beyond the adapter's limits gives a message naming the limit, not a GPUValidationError."""
    from types import SimpleNamespace

    import wgpu

    from bokehfit.gpu.compute import bind_buffers, dispatch

    limits = {
        "max-storage-buffer-binding-size": 2**27,
        "max-uniform-buffer-binding-size": 2**16,
        "max-compute-workgroups-per-dimension": 65535,
    }
    device = SimpleNamespace(limits=limits)
    too_big = SimpleNamespace(size=2**28, usage=wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.COPY_SRC)
    with pytest.raises(InputError, match=r"268435456 bytes is larger than the adapter's max-storage-buffer-binding-size \(134217728"):
        bind_buffers(device, None, too_big)
    with pytest.raises(InputError, match=r"65536 × 1 workgroups exceeds the adapter's max-compute-workgroups-per-dimension \(65535\)"):
        dispatch(device, None, None, 65536)
