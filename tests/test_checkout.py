"""A fresh clone works: its tracked files alone, copied to a temporary folder.

These check, in seconds and without running the whole CI, what a fresh clone
needs (bokehfit issue 10): the shaders load when Python imports the checkout
itself (started in the repository root), the reference-photo tests skip with
a reason that says where to get the photos, processes started by the tests
get SIGINT back when the run began with it ignored (a background job), and
every folder of the package is in the wheel's package list.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

#: Appended to the copy's rng.wgsl to show which shaders/ folder was read.
MARKER = "// checkout marker: read from the copy\n"


def _tracked_files() -> list[str]:
    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip(f"{REPO} is not a git checkout: the tracked files are unknown")
    listed = subprocess.run(["git", "-C", str(REPO), "ls-files", "-z"], capture_output=True, check=True).stdout
    return [name for name in listed.decode().split("\0") if name]


@pytest.fixture(scope="module")
def checkout(tmp_path_factory) -> Path:
    """A copy of the tracked files (as they are in the working tree), like a fresh clone."""
    root = tmp_path_factory.mktemp("checkout") / "bokehfit"
    for name in _tracked_files():
        source = REPO / name
        if source.is_file():  # tracked but deleted in the working tree: not in the clone
            target = root / name
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target)
    return root


def _env(**extra: str) -> dict[str, str]:
    """The environment of a child run, without the reference-photo settings of this run."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("BOKEHFIT_RE")}
    env.update(extra)
    return env


def _pytest(checkout: Path, args: list[str], env: dict[str, str], ignore_sigint: bool = False):
    """pytest on the copy's tests, started in the copy (SIGINT ignored from the start if asked)."""
    command = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", "-rs", *args]
    if ignore_sigint:  # as in a job that a non-interactive shell put in the background
        command = [
            sys.executable, "-c",
            "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_IGN); os.execv(sys.executable, sys.argv[1:])",
            *command,
        ]
    return subprocess.run(command, cwd=checkout, env=env, capture_output=True, text=True, timeout=300, check=False)


def test_shaders_load_from_a_source_checkout(checkout):
    with (checkout / "shaders" / "rng.wgsl").open("a", encoding="utf-8") as wgsl:
        wgsl.write(MARKER)
    code = (
        "import bokehfit\n"
        "from pathlib import Path\n"
        "from bokehfit.gpu.shaders import load_shader, shader_source\n"
        "print(Path(bokehfit.__file__).resolve().parent)\n"
        "print('marker' if shader_source('rng.wgsl').endswith(" + repr(MARKER) + ") else 'no marker')\n"
        "print(len(load_shader('apertures.wgsl')) > 0)\n"
    )
    # Started in the copy, as `python -m bokehfit ...` from the repository root: the copy's
    # bokehfit/ comes first on sys.path, ahead of any installed bokehfit.
    done = subprocess.run([sys.executable, "-c", code], cwd=checkout, env=_env(PYTHONPATH=str(checkout)),
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    package, marker, loaded = done.stdout.split("\n")[:3]
    assert Path(package) == (checkout / "bokehfit").resolve()
    assert marker == "marker", "the shaders did not come from the checkout that bokehfit was imported from"
    assert loaded == "True"


def test_reference_photo_tests_skip_and_say_where_to_get_the_photos(checkout, tmp_path):
    empty = tmp_path / "no_photos"
    empty.mkdir()
    wrong = tmp_path / "wrong_photos"
    wrong.mkdir()
    (wrong / "03_frosted-grass_pixabay-1358926.jpg").write_bytes(b"not the manifest's photo")
    for folder, why in [(empty, "is not in"), (tmp_path / "missing", "no folder"), (wrong, "has sha256")]:
        done = _pytest(checkout, ["tests/test_reference_discs.py", "-k", "test_03"], _env(BOKEHFIT_REFERENCE_DIR=str(folder)))
        counts = done.stdout.strip().splitlines()[-1].split(" in ")[0]
        # The plain test and the strict xfail both skip: neither fails, nor "xfails" for want of a photo.
        assert done.returncode == 0 and counts.startswith("2 skipped"), done.stdout + done.stderr
        assert not any(word in counts for word in ("passed", "failed", "xfailed", "xpassed", "error")), counts
        assert why in done.stdout and "reference_photos/manifest.json" in done.stdout
        assert "point BOKEHFIT_REFERENCE_DIR at their folder" in done.stdout


def test_reference_photos_can_be_required(checkout, tmp_path):
    env = _env(BOKEHFIT_REFERENCE_DIR=str(tmp_path), BOKEHFIT_REQUIRE_REFERENCE_PHOTOS="1")
    done = _pytest(checkout, ["tests/test_reference_discs.py", "-k", "test_03_frost_finds"], env)
    assert done.returncode == 1 and "1 failed" in done.stdout, done.stdout + done.stderr
    assert "BOKEHFIT_REQUIRE_REFERENCE_PHOTOS=1 but" in done.stdout


def test_processes_started_by_tests_get_sigint_back(checkout):
    probe = checkout / "tests" / "test_sigint_probe.py"
    probe.write_text(
        "import subprocess, sys\n\n\n"
        "def test_child_has_the_default_sigint_handler():\n"
        "    code = 'import signal; print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)'\n"
        "    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True).stdout\n"
        "    assert out.strip() == 'True'\n",
        encoding="utf-8",
    )
    try:
        done = _pytest(checkout, [str(probe.relative_to(checkout))], _env(), ignore_sigint=True)
    finally:
        probe.unlink()
    assert done.returncode == 0 and "1 passed" in done.stdout, done.stdout + done.stderr


def test_every_package_folder_is_in_the_wheel(checkout):
    tomllib = pytest.importorskip("tomllib", reason="tomllib is Python 3.11+")
    setuptools = tomllib.loads((checkout / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    folders = {
        ".".join(path.relative_to(checkout).parts)
        for path in (checkout / "bokehfit").rglob("*")
        if path.is_dir() and any(child.is_file() for child in path.iterdir())
    }
    folders.add("bokehfit")
    shipped = set(setuptools["packages"])
    assert folders <= shipped, f"folders of bokehfit/ missing from pyproject.toml's packages: {sorted(folders - shipped)}"
    assert setuptools["package-dir"]["bokehfit.shaders"] == "shaders" and (checkout / "shaders" / "__init__.py").is_file()
