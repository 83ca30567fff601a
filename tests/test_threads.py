"""BLAS and OpenMP on one thread for the ``bokehfit`` command (bokehfit.threads), the user's sizes standing."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from threadpoolctl import threadpool_info

from bokehfit.threads import SINGLE_THREAD_VARIABLES, one_thread


def _blas_threads() -> list[int]:
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


@pytest.fixture
def blas():
    """NumPy's BLAS, loaded (threadpoolctl sees only loaded libraries)."""
    import numpy  # noqa: F401

    pools = _blas_threads()
    if not pools:
        pytest.fail("threadpoolctl finds no BLAS behind NumPy: the limits would do nothing")
    return pools


def test_one_thread_limits_blas_while_it_runs_and_restores_it(blas):
    with one_thread(environ={}):
        assert set(_blas_threads()) == {1}
    assert _blas_threads() == blas


@pytest.mark.parametrize("name", SINGLE_THREAD_VARIABLES)
def test_a_size_the_user_set_stands(blas, name):
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=2, user_api="blas"):
        with one_thread(environ={name: "2"}):
            assert set(_blas_threads()) == {2}


def test_the_command_runs_its_work_on_one_blas_thread(tmp_path):
    """The console entry point (as the installed ``bokehfit`` runs it) limits BLAS around the command,
    in a fresh process whose OpenBLAS would otherwise start a thread per core."""
    script = textwrap.dedent(
        """
        import sys
        from threadpoolctl import threadpool_info, threadpool_limits
        import numpy
        import bokehfit.cli as cli

        seen = []
        def main(argv=None, environ=None):
            seen.append(sorted({p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"}))
            return 0
        cli.main = main
        with threadpool_limits(limits=2, user_api="blas"):  # as on a machine of two cores or more
            try:
                cli.entry_point()
            except SystemExit:
                pass
            after = sorted({p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"})
        print(seen, after)
        """
    )
    import bokehfit

    env = {k: v for k, v in os.environ.items() if k not in SINGLE_THREAD_VARIABLES}
    # The subprocess imports the bokehfit under test, wherever it lies.
    env["PYTHONPATH"] = os.pathsep.join([str(Path(bokehfit.__file__).resolve().parents[1]), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", script, "compare", "x.jpg"], capture_output=True, text=True, env=env,
                         cwd=tmp_path, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["[[1]]", "[2]"]
