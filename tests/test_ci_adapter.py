"""The adapter check that keeps CI from passing by skipping the GPU path.

Under ``CI=true`` the GPU tests must run on Mesa's lavapipe (the reference
adapter of design.md §1); anywhere else any adapter will do, but it must
describe itself.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile

import pytest

@pytest.mark.gpu
def test_adapter_is_lavapipe_under_ci(gpu):
    found = f"{gpu.adapter_name!r} ({gpu.backend})"
    if os.environ.get("CI") == "true":
        assert gpu.is_lavapipe, f"CI=true expects Mesa lavapipe (llvmpipe on Vulkan), found {found}"
        assert "llvmpipe" in gpu.adapter_name.lower(), f"expected an llvmpipe adapter, found {found}"
        assert gpu.backend == "Vulkan", f"expected the Vulkan backend, found {found}"
    else:
        assert isinstance(gpu.adapter_name, str) and gpu.adapter_name.strip(), f"empty adapter name: {found}"
        assert isinstance(gpu.backend, str) and gpu.backend.strip(), f"empty backend: {found}"


@pytest.mark.gpu
def test_is_lavapipe_matches_name_and_backend(gpu):
    # is_lavapipe must be exactly "llvmpipe in the name and Vulkan backend".
    expected = "llvmpipe" in gpu.adapter_name.lower() and gpu.backend == "Vulkan"
    assert gpu.is_lavapipe == expected


def _run_adapter_test_without_adapter(ci: str | None) -> subprocess.CompletedProcess:
    """Run the adapter test in a fresh process where no adapter matches."""
    env = dict(os.environ, BOKEHFIT_ADAPTER="no-such-adapter-for-this-test")
    env.pop("CI", None)
    if ci is not None:
        env["CI"] = ci
    return subprocess.run(
        [sys.executable, "-m", "pytest", __file__, "-q", "-p", "no:cacheprovider", "-rsE",
         "-k", "test_adapter_is_lavapipe_under_ci"],
        cwd=tempfile.gettempdir(), env=env, capture_output=True, text=True, timeout=120,
    )


def test_no_adapter_skips_outside_ci():
    result = _run_adapter_test_without_adapter(ci=None)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "1 skipped" in result.stdout and "no-such-adapter" in result.stdout, result.stdout


def test_no_adapter_fails_under_ci():
    result = _run_adapter_test_without_adapter(ci="true")
    assert result.returncode != 0, result.stdout + result.stderr
    assert "1 error" in result.stdout and "CI=true" in result.stdout, result.stdout
