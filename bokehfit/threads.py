"""The thread pools of numerical libraries: BLAS and OpenMP on one thread for bokehfit's own work.

The fit's matrices are small (a few dozen columns, a few thousand rows): a BLAS thread pool does
none of the work in parallel, and OpenBLAS's sums depend on its thread count in their last digits.
At one thread a photo's numbers do not depend on the machine's cores, ``--jobs`` or Dask, and no
idle BLAS thread spins beside the one that works. Measured on a 16-core machine
(``benchmarks/cli_threads.py``, ``benchmarks/RESULTS.md``): the 17 reference photos took 5 % less
CPU time this way than with OpenBLAS's default pool of a thread per core, the same wall time, and
the same answers.

Two ways in, one rule: a process started for bokehfit's work (a survey's worker) is given
:data:`SINGLE_THREAD_VARIABLES` at 1 before it loads NumPy (:mod:`bokehfit.surveys.work`); the
``bokehfit`` command, whose NumPy is loaded by then, limits the pools while it runs
(:func:`one_thread`, through threadpoolctl). A variable the user set stands in both.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Mapping

__all__ = ["SINGLE_THREAD_VARIABLES", "one_thread"]

#: The thread-pool sizes of OpenMP and of BLAS (OpenBLAS, as NumPy and SciPy ship it, and MKL),
#: read from the environment as each library loads.
SINGLE_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@contextlib.contextmanager
def one_thread(environ: Mapping[str, str] | None = None) -> Iterator[None]:
    """BLAS and OpenMP pools of one thread while the block runs (threadpoolctl), restored after it.

    Where ``environ`` (default ``os.environ``) sets any of :data:`SINGLE_THREAD_VARIABLES`, the
    pools are left as the user sized them.
    """
    environ = os.environ if environ is None else environ
    if any(environ.get(name) for name in SINGLE_THREAD_VARIABLES):
        yield
        return
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"), threadpool_limits(limits=1, user_api="openmp"):
        yield
