"""Entry point of a spawned worker process, importable without numpy.

Why a separate module: the spawned child imports the target's module before running it; setting the
thread limits here, before numpy/numba/BLAS load, keeps each worker on one core (BLAS threads that
spin-wait would otherwise starve the service's ingest and REST threads), and ``nice`` gives those
latency-sensitive threads priority over identification, which is batch work.  The packages above it
(``service``, ``service.executors``) import nothing heavy either.
"""

from __future__ import annotations

import os

WORKER_NICE = 5
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS",
                "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


def main(conn, fn_path: str) -> None:
    """Limit threads, lower priority, then run :func:`service.executors.child.worker_loop`.

    Parameters
    ----------
    conn : multiprocessing.connection.Connection
        The worker's end of its pipe to the pool.
    fn_path : str
        ``module:function`` run on each task.
    """
    for var in _THREAD_VARS:
        os.environ[var] = "1"
    try:
        os.nice(WORKER_NICE)
    except OSError:
        pass
    from service.executors.child import worker_loop  # only now: it loads numpy

    worker_loop(conn, fn_path)
