"""Many windows in one call: :func:`identify_many` over a pool of forked processes or of threads.

Why processes: about half of a window's time is Python and numpy under the GIL (preprocessing, standard
errors, the result), so two threads gave only ×1.17 (docs/numerics.md, "Batch").  Forked children inherit the
parent's loaded numba kernels and the windows (nothing compiled or pickled on the way in; only the results
come back pickled), and run without a shared GIL.
"""

from __future__ import annotations

import gc
import math
import multiprocessing as mp
import os
import threading
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from typing import Literal

import numpy as np

from aslm_core.errors import WindowError
from aslm_core.identify import identify
from aslm_core.result import IdentificationResult, IdentifyConfig
from aslm_core.window import Window

Pool = Literal["auto", "process", "thread"]
#: Pool kinds of :func:`identify_many`.
POOLS: tuple[str, ...] = ("auto", "process", "thread")
#: ``auto`` forks processes from this many windows per worker on; below, threads.  Starting and ending two
#: forked workers cost 27–79 ms at load 7–9 (docs/numerics.md, "Batch"): two workers save half of 4–5 ms per
#: window, so they pay from ~11 windows each on.
PROCESS_MIN_WINDOWS_PER_WORKER = 16
#: Chunks per worker a forked batch is cut into: few enough that each carries many windows per message, enough
#: that a worker slowed by the shared machine's other jobs does not hold up the end.
CHUNKS_PER_WORKER = 8

Outcome = IdentificationResult | WindowError

# The batch a forked worker serves: set in the child by the pool's initializer (inherited memory, not pickled).
_job: tuple[Sequence[Window], list, IdentifyConfig] | None = None


def _one(window: Window, warm: np.ndarray | None, config: IdentifyConfig) -> Outcome:
    """One window's result, or the WindowError that rejected it."""
    try:
        return identify(window, warm_start=warm, config=config)
    except WindowError as exc:
        return exc


def _set_job(windows: Sequence[Window], warm: list, config: IdentifyConfig) -> None:
    """A forked worker's initializer: the batch it serves."""
    global _job
    _job = (windows, warm, config)


def _chunk(bounds: tuple[int, int]) -> list[Outcome]:
    """A forked worker's outcomes for windows ``bounds[0]`` to ``bounds[1] - 1`` of its inherited batch."""
    windows, warm, config = _job
    return [_one(windows[i], warm[i], config) for i in range(*bounds)]


def _forked(windows: Sequence[Window], warm: list, config: IdentifyConfig, n_workers: int) -> list[Outcome]:
    """The batch on ``n_workers`` forked processes, in contiguous chunks handed out as workers free up.

    The first window is identified here first: that loads (or compiles) the kernels it needs once, in the
    parent, for every child to inherit instead of each loading them from numba's cache.
    """
    first = _one(windows[0], warm[0], config)
    n = len(windows)
    size = max(1, math.ceil((n - 1) / (n_workers * CHUNKS_PER_WORKER)))
    bounds = [(lo, min(lo + size, n)) for lo in range(1, n, size)]
    ctx = mp.get_context("fork")
    # The children's garbage collector would otherwise walk (write to) every object inherited from here and copy
    # its memory pages: it cut the children's extra CPU over one worker from 12 % to 2 % (docs/numerics.md, "Batch").
    thawed = gc.get_freeze_count() == 0
    gc.freeze()
    try:
        # concurrent.futures rather than multiprocessing.Pool: a worker that dies (a crash in compiled code) fails
        # the call with BrokenProcessPool, where Pool waits for its lost chunk for ever.  With fork it starts every
        # worker before its manager thread, so no fork happens from a threaded parent.
        with ProcessPoolExecutor(min(n_workers, len(bounds)), mp_context=ctx, initializer=_set_job,
                                 initargs=(windows, warm, config)) as pool:
            parts = list(pool.map(_chunk, bounds))
    finally:
        if thawed:
            gc.unfreeze()
    return [first, *(r for part in parts for r in part)]


def pool_kind(pool: Pool, n_workers: int, n_windows: int) -> str:
    """The pool :func:`identify_many` runs: ``serial``, ``process`` or ``thread``.

    ``auto`` forks only where that is safe and pays: the platform forks, the calling process has no other
    thread (a fork copies locks other threads may hold), and each worker gets at least
    :data:`PROCESS_MIN_WINDOWS_PER_WORKER` windows.
    """
    if pool not in POOLS:
        raise ValueError(f"pool must be one of {POOLS}, got {pool!r}")
    if n_workers == 1 or n_windows < 2:
        return "serial"
    if pool != "auto":
        return pool
    forks = "fork" in mp.get_all_start_methods() and threading.active_count() == 1
    return "process" if forks and n_windows >= PROCESS_MIN_WINDOWS_PER_WORKER * n_workers else "thread"


def identify_many(windows: Sequence[Window], *, warm_starts: Sequence[np.ndarray | None] | None = None,
                  config: IdentifyConfig | None = None, workers: int | None = None,
                  pool: Pool = "auto") -> list[Outcome]:
    """Identify many bus windows in one call, on all cores.

    Parameters
    ----------
    windows : sequence of Window
    warm_starts : sequence of (array or None), optional
        One previous D per window.
    config : IdentifyConfig, optional
    workers : int, optional
        Processes or threads (default: the number of CPUs).
    pool : {"auto", "process", "thread"}
        ``process``: forked worker processes (POSIX; the results are the same bit for bit).  ``thread``: a
        thread pool in this process (only the compiled kernels run in parallel).  ``auto`` (default):
        processes where :func:`pool_kind` finds forking safe and worth its start-up, else threads.

    Returns
    -------
    list
        Per window, in order: its IdentificationResult, or the WindowError that rejected it (a bad
        window never stops the others).
    """
    config = config or IdentifyConfig()
    warm = list(warm_starts) if warm_starts is not None else [None] * len(windows)
    if len(warm) != len(windows):
        raise ValueError(f"{len(warm)} warm starts for {len(windows)} windows")
    if config.n_starts == 0 and any(w is None for w in warm):
        raise ValueError("no start to descend from: n_starts is 0 and some windows have no warm start")
    n_workers = workers or os.cpu_count() or 1
    kind = pool_kind(pool, n_workers, len(windows))
    if kind == "serial":
        return [_one(w, s, config) for w, s in zip(windows, warm, strict=True)]
    if kind == "process":
        return _forked(windows, warm, config, n_workers)
    with ThreadPoolExecutor(max_workers=n_workers) as ex:
        return list(ex.map(_one, windows, warm, [config] * len(windows)))
