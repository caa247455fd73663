"""Entry point of a spawned worker process, importable without numpy.

Why a separate module: the spawned child imports the target's module before running it; setting the
thread limits here, before numpy/numba/BLAS load, keeps each worker on one core (BLAS threads that
spin-wait would otherwise starve the service's ingest and REST threads), and ``nice`` gives those
latency-sensitive threads priority over identification, which is batch work.
"""

from __future__ import annotations

import os

WORKER_NICE = 5
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS",
                "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


def main(conn, fn_path: str) -> None:
    """Limit threads, lower priority, then run :func:`service.pool.worker_loop`."""
    for var in _THREAD_VARS:
        os.environ[var] = "1"
    try:
        os.nice(WORKER_NICE)
    except OSError:
        pass
    from service.pool import worker_loop

    worker_loop(conn, fn_path)
