"""No hidden state: the same call gives the same answer, whatever ran before it in the process.

The command line records the argv it was given, leaves the process's warning
handler as it found it, and is the only reader of the adapter's environment
variables; the library takes the adapter choice as an argument, and keeps one
device per choice. (The metrics' part is in ``test_metrics.py``.)
"""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
import tempfile
import warnings

import cv2
import numpy as np
import pytest

from bokehfit import cli
from bokehfit.apertures import make_aperture
from bokehfit.cli import adapter_from_environment, entry_point, main
from bokehfit.errors import GPUUnavailableError, InputError
from bokehfit.gpu import AdapterChoice, get_gpu
from bokehfit.synthetic import SyntheticDisc, encode_srgb8, render_discs

#: argv[0..] of the process while a test calls main() with other arguments.
UNRELATED_ARGV = ["pytest", "--not-a-bokehfit-option", "unrelated words"]
NO_SUCH_ADAPTER = "no-such-adapter-for-this-test"


# ---------------------------------------------------------------------------
# command_line is the argv given to main()


def test_similarity_json_records_the_argv_given_to_main(tmp_path, monkeypatch):
    monkeypatch.setattr(sys, "argv", UNRELATED_ARGV)
    out = tmp_path / "with space" / "s.json"
    out.parent.mkdir()
    argv = ["similarity", "hexagon", "circle", "--angle-a", "20", "--json", str(out)]
    main(argv)
    assert json.loads(out.read_text())["command_line"] == shlex.join(["bokehfit", *argv])


def test_discs_json_records_the_argv_given_to_main(tmp_path, monkeypatch):
    disc = SyntheticDisc((60.3, 58.6), 40, make_aperture("hexagon", 12))
    linear = render_discs(160, 120, [disc], background=0.03, seed=2)
    photo = tmp_path / "bokeh.png"
    cv2.imwrite(str(photo), np.repeat(encode_srgb8(linear)[..., None], 3, axis=2))
    monkeypatch.setattr(sys, "argv", UNRELATED_ARGV)
    argv = ["discs", str(photo), "--json", str(tmp_path / "d.json"), "--max-discs", "3"]
    main(argv)
    assert json.loads((tmp_path / "d.json").read_text())["command_line"] == shlex.join(["bokehfit", *argv])


# ---------------------------------------------------------------------------
# entry_point and the process's warning handler


def test_entry_point_leaves_showwarning_as_it_found_it(monkeypatch, capsys):
    before = warnings.showwarning

    def warn_once():
        warnings.simplefilter("always")  # the suite turns warnings into errors
        warnings.warn("kernel clipped: 3% of the light falls outside the frame", UserWarning)

    monkeypatch.setattr(cli, "main", warn_once)
    entry_point()
    assert warnings.showwarning is before
    assert capsys.readouterr().err == "bokehfit: warning: kernel clipped: 3% of the light falls outside the frame\n"


def test_entry_point_restores_showwarning_when_it_exits(monkeypatch, capsys):
    before = warnings.showwarning
    monkeypatch.setattr(sys, "argv", ["bokehfit", "similarity", "hexgon", "circle"])
    with pytest.raises(SystemExit) as exited:
        entry_point()
    assert exited.value.code == 2
    assert warnings.showwarning is before
    assert "hexgon" in capsys.readouterr().err


# ---------------------------------------------------------------------------
# The adapter: an argument; the environment is read by the command line only


def test_adapter_from_environment():
    choice = adapter_from_environment({"BOKEHFIT_ADAPTER": " LLVMpipe ", "BOKEHFIT_BACKEND": "Vulkan"})
    assert choice == AdapterChoice("llvmpipe", "vulkan")
    assert adapter_from_environment({}) == AdapterChoice()
    with pytest.raises(InputError, match=r"^BOKEHFIT_BACKEND must be one of vulkan, metal, d3d12, gl"):
        adapter_from_environment({"BOKEHFIT_BACKEND": "opengl"})


@pytest.mark.parametrize(
    "name,backend,parameter", [(3, "", "name"), ("", "cuda", "backend"), ("", None, "backend")]
)
def test_adapter_choice_names_the_bad_field(name, backend, parameter):
    with pytest.raises(InputError) as raised:
        AdapterChoice(name, backend)
    assert str(raised.value).startswith(f"{parameter} "), str(raised.value)


def test_get_gpu_rejects_what_is_not_a_choice():
    with pytest.raises(InputError, match=r"^adapter must be an AdapterChoice"):
        get_gpu("llvmpipe")


@pytest.mark.gpu
def test_get_gpu_ignores_the_environment(gpu):
    # A fresh process whose environment names no existing adapter: the library
    # takes the default choice, because only the command line reads the variables.
    code = "from bokehfit.gpu import get_gpu; print(get_gpu().adapter_name)"
    env = dict(os.environ, BOKEHFIT_ADAPTER=NO_SUCH_ADAPTER, BOKEHFIT_BACKEND="vulkan" if gpu.backend != "Vulkan" else "gl")
    done = subprocess.run([sys.executable, "-c", code], cwd=tempfile.gettempdir(), env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == get_gpu().adapter_name


@pytest.mark.gpu
def test_one_device_per_adapter_choice(gpu):
    word = gpu.adapter_name.split()[0]
    default = get_gpu()
    assert get_gpu(AdapterChoice()) is default
    named = get_gpu(AdapterChoice(word.upper()))
    assert named is get_gpu(AdapterChoice(f"  {word.lower()} "))  # equal choices share one device
    assert named.adapter_name == default.adapter_name
    assert named.device is not default.device  # a different choice never gets another's device
    with pytest.raises(GPUUnavailableError, match=NO_SUCH_ADAPTER):
        get_gpu(AdapterChoice(NO_SUCH_ADAPTER))


@pytest.mark.gpu
def test_kernel_command_honours_the_adapter_variables(gpu, tmp_path, capsys):
    argv = ["kernel", "--shape", "star", "--diameter-px", "12", "--size", "24", "--method", "mc",
            "--samples", "1000", "--out", str(tmp_path / "k.npy")]
    with pytest.raises(GPUUnavailableError, match=NO_SUCH_ADAPTER):
        main(argv, environ={"BOKEHFIT_ADAPTER": NO_SUCH_ADAPTER})
    kernel = main(argv, environ={"BOKEHFIT_ADAPTER": gpu.adapter_name.split()[0]})
    assert kernel.device == gpu.describe()
    assert f"on {gpu.describe()}" in capsys.readouterr().out


@pytest.mark.gpu
def test_render_command_honours_the_adapter_variables(gpu, tmp_path, capsys):
    argv = ["render", "--scene", "points", "--size", "16x12", "--spp", "1", "--out", str(tmp_path / "r.png")]
    with pytest.raises(GPUUnavailableError, match=NO_SUCH_ADAPTER):
        main(argv, environ={"BOKEHFIT_ADAPTER": NO_SUCH_ADAPTER})
    result = main(argv, environ={"BOKEHFIT_ADAPTER": gpu.adapter_name.split()[0]})
    assert result.adapter == gpu.adapter_name
    assert f"on {gpu.adapter_name} ({gpu.backend})" in capsys.readouterr().out


def test_bad_backend_variable_is_a_usage_error(tmp_path):
    with pytest.raises(InputError, match=r"^BOKEHFIT_BACKEND "):
        main(["similarity", "hexagon", "circle"], environ={"BOKEHFIT_BACKEND": "cuda"})
