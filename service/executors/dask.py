"""The Dask executor: tasks on a Dask distributed cluster (``executor = "tcp://scheduler:8786"``).

``distributed`` is imported only when this executor is created (the ``dask`` extra).

Why batches: Dask's scheduler costs about 1 ms per task (its documentation's figure), against
2.5–3.7 ms of work per warm-started window (docs/service.md), so one task per bus would spend a quarter
of the cluster on scheduling.  Windows go out in batches sized from the measured per-bus cost so that a
batch holds about :data:`BATCH_S` of work; each batch's outcomes come back together and resolve one
future per window.

A worker that dies mid-batch: the scheduler runs the batch again on another worker (the batch's
partial work is never reported, so no bus is duplicated); if that one dies too (the scheduler's
``distributed.scheduler.allowed-failures``, which the compose profile and the tests set to 1), every
window of the batch fails with ``worker_crashed``.  No window is ever left without an outcome.
"""

from __future__ import annotations

import collections
import logging
import math
import os
import re
import sys
import tempfile
import threading
import time
from concurrent.futures import Future

from service.executors.base import TaskOutcome, WindowTask
from service.worker import resolve, run_task

try:  # the dask extra; DaskPool says how to install it when it is missing
    from distributed import WorkerPlugin
except ImportError:  # pragma: no cover - the extra is part of the test install
    WorkerPlugin = object

log = logging.getLogger(__name__)

#: Work per batch [s]: 1 ms of scheduling is then 0.5 % of it, and a batch lost with its worker
#: costs a fifth of a second to run again.
BATCH_S = 0.2
#: Per-bus cost assumed until the first outcomes are measured [s] (a warm-started window,
#: docs/service.md: 2.5–3.7 ms).
COST_S = 0.004
#: Batches in flight per worker thread: one running, one queued behind it so no thread idles for a
#: round trip; the rest wait here, so a batch's deadline starts close to when it runs.
INFLIGHT_PER_THREAD = 2


def run_batch(fn_path: str, tasks: list[WindowTask]) -> list[TaskOutcome]:
    """Run each task of a batch on a Dask worker (:func:`service.worker.run_task`: never raises)."""
    return [run_task(fn_path, task) for task in tasks]


def _cache_dir(root: str, worker_name: object) -> str:
    """The numba cache directory of one worker: ``root/<worker name, made a file name>``."""
    return os.path.join(root, re.sub(r"[^A-Za-z0-9_.-]", "_", str(worker_name)) or "worker")


class WarmupPlugin(WorkerPlugin):
    """Dask worker plugin: a per-worker numba cache directory, then the worker function's warm-up.

    Registered by :class:`DaskPool` on every current and future worker (a restarted one too), so
    numba compiles (or loads from this worker's cache) once per worker process, before its first
    batch rather than inside it.

    Parameters
    ----------
    fn_path : str
        ``module:function`` whose ``warmup`` attribute (if any) is run.
    cache_root : str or None
        Parent of the per-worker cache directories on the workers' file system; None reads
        ``ASLM_NUMBA_CACHE_ROOT`` on the worker, else ``<tmp>/aslm-numba``.

    Notes
    -----
    Why one cache directory per worker: numba writes its cache next to the sources by default, which
    a container may mount read-only and which every worker on a host would write at once; a
    directory named after the worker is kept across its restarts (same name), so a replaced worker
    loads rather than compiles.
    """

    name = "aslm-warmup"

    def __init__(self, fn_path: str, cache_root: str | None = None) -> None:
        self.fn_path = fn_path
        self.cache_root = cache_root
        self.cache_dir: str | None = None
        self.warmed = False

    def setup(self, worker) -> None:
        """Point numba at this worker's cache (if numba is not loaded yet), then warm up."""
        root = self.cache_root or os.environ.get("ASLM_NUMBA_CACHE_ROOT") or os.path.join(
            tempfile.gettempdir(), "aslm-numba")
        self.cache_dir = _cache_dir(root, worker.name)
        if "numba" in sys.modules:  # numba reads its cache directory once, at import
            log.warning("numba already imported on worker %s: its cache stays where it is", worker.name)
        else:
            os.makedirs(self.cache_dir, exist_ok=True)
            os.environ["NUMBA_CACHE_DIR"] = self.cache_dir
        try:
            fn = resolve(self.fn_path)
            if callable(getattr(fn, "warmup", None)):
                fn.warmup()
            self.warmed = True
        except Exception as exc:  # noqa: BLE001 - the batches report it per window
            log.error("worker %s cannot import or warm up %s: %s", worker.name, self.fn_path, exc)


def worker_state(dask_worker=None) -> dict:
    """What the warm-up plugin did on this worker (for tests and ``aslm`` diagnostics)."""
    plugin = dask_worker.plugins.get(WarmupPlugin.name) if dask_worker is not None else None
    return {"pid": os.getpid(), "cache_dir": getattr(plugin, "cache_dir", None),
            "warmed": getattr(plugin, "warmed", False), "numba_cache_dir": os.environ.get("NUMBA_CACHE_DIR")}


class _Batch:
    __slots__ = ("tasks", "futures", "dfut", "timer")

    def __init__(self, tasks: list[WindowTask], futures: list[Future]) -> None:
        self.tasks = tasks
        self.futures = futures
        self.dfut = None
        self.timer: threading.Timer | None = None


class DaskPool:
    """Batches of tasks on a Dask distributed cluster (``pip install 'aslm[dask]'``).

    Parameters
    ----------
    address : str
        Scheduler address, e.g. ``tcp://scheduler:8786``.
    fn_path : str
        ``module:function``; it must be importable on the Dask workers.
    timeout_s : float
        Per-task limit [s].  A batch fails as ``timeout`` (each of its windows) when it has not
        finished within ``timeout_s`` plus twice its expected duration after it was handed to the
        scheduler; its Dask future is cancelled (a task already running on a worker thread cannot be
        stopped: the thread stays busy until it returns).
    batch_s : float
        Target work per batch [s] (:data:`BATCH_S`).
    cache_root : str, optional
        Root of the per-worker numba cache directories (:class:`WarmupPlugin`).
    inflight_per_thread : int
        Batches handed to the scheduler per worker thread (:data:`INFLIGHT_PER_THREAD`).

    Attributes
    ----------
    cost_s : float
        Running estimate of the work per window [s] (mean of the latest outcomes' ``elapsed_s``).
    """

    def __init__(self, address: str, fn_path: str, timeout_s: float, *, batch_s: float = BATCH_S,
                 cache_root: str | None = None, inflight_per_thread: int = INFLIGHT_PER_THREAD) -> None:
        try:
            from distributed import Client
        except ImportError as exc:  # optional extra
            raise RuntimeError("executor is a Dask address but dask[distributed] is not installed: "
                               "pip install 'aslm[dask]'") from exc
        self.client = Client(address, timeout=30)
        self.fn_path = fn_path
        self.timeout_s = timeout_s
        self.batch_s = batch_s
        self.inflight_per_thread = max(1, int(inflight_per_thread))
        self.cost_s = COST_S
        self.replaced = 0  # the Executor attribute /health reports; Dask's nannies replace workers
        self._lock = threading.Lock()
        self._waiting: collections.deque[_Batch] = collections.deque()
        self._inflight = 0
        self._closed = False
        self.client.register_plugin(WarmupPlugin(fn_path, cache_root), name=WarmupPlugin.name)

    # --- public -------------------------------------------------------------------------------------
    def threads(self) -> int:
        """Worker threads of the cluster now (at least 1)."""
        return max(1, sum(self.client.nthreads().values()))

    def batch_size(self, n: int, threads: int | None = None) -> int:
        """Windows per batch for ``n`` windows: about ``batch_s`` of work, yet at least 4 batches per
        worker thread when ``n`` allows (so the load spreads and a lost batch is small)."""
        threads = self.threads() if threads is None else threads
        by_cost = max(1, int(self.batch_s / max(self.cost_s, 1e-5)))
        return max(1, min(by_cost, math.ceil(n / (4 * threads))))

    def submit(self, task: WindowTask) -> Future:
        """Queue one task (a batch of one); the future resolves to a :class:`TaskOutcome`."""
        return self.submit_many([task])[0]

    def submit_many(self, tasks: list[WindowTask]) -> list[Future]:
        """Queue tasks in batches; one future per task, resolving to its :class:`TaskOutcome` (never raises)."""
        futs = [Future() for _ in tasks]
        if not tasks:
            return futs
        size = self.batch_size(len(tasks))
        with self._lock:
            if self._closed:
                for fut in futs:
                    fut.set_result(TaskOutcome(ok=False, reason="shutdown", message="executor closed"))
                return futs
            for i in range(0, len(tasks), size):
                self._waiting.append(_Batch(tasks[i:i + size], futs[i:i + size]))
        self._pump()
        return futs

    def close(self) -> None:
        """Fail what has not finished as ``shutdown`` and disconnect from the scheduler."""
        with self._lock:
            self._closed = True
            waiting, self._waiting = list(self._waiting), collections.deque()
        for batch in waiting:
            self._resolve(batch, None, "shutdown", "executor closed")
        self.client.close()

    # --- internals ----------------------------------------------------------------------------------
    def _pump(self) -> None:
        """Hand waiting batches to the scheduler, up to ``inflight_per_thread`` per worker thread."""
        limit = self.inflight_per_thread * self.threads()
        while True:
            with self._lock:
                if self._closed or not self._waiting or self._inflight >= limit:
                    return
                batch = self._waiting.popleft()
                self._inflight += 1
            try:
                batch.dfut = self.client.submit(run_batch, self.fn_path, batch.tasks, pure=False)
            except Exception as exc:  # noqa: BLE001 - e.g. the scheduler is gone: fail this batch
                self._settle(batch, None, f"error:{type(exc).__name__}", str(exc)[:500])
                continue
            limit_s = self.timeout_s + 2.0 * len(batch.tasks) * self.cost_s
            batch.timer = threading.Timer(limit_s, self._expire, args=(batch, limit_s))
            batch.timer.daemon = True
            batch.timer.start()
            batch.dfut.add_done_callback(lambda f, batch=batch: self._done(batch, f))

    def _expire(self, batch: _Batch, limit_s: float) -> None:
        if batch.dfut is not None:
            batch.dfut.cancel()
        self._settle(batch, None, "timeout", f"batch of {len(batch.tasks)} not done within {limit_s:.3g} s")

    def _done(self, batch: _Batch, dfut) -> None:
        try:
            outcomes = dfut.result()
        except Exception as exc:  # noqa: BLE001 - KilledWorker, CancelledError, ...
            name = type(exc).__name__
            if name == "CancelledError":
                return  # cancelled by the timeout, which has resolved the batch
            reason = "worker_crashed" if name == "KilledWorker" else f"error:{name}"
            self._settle(batch, None, reason, str(exc)[:500])
            return
        self._settle(batch, outcomes, None, "")

    def _settle(self, batch: _Batch, outcomes: list[TaskOutcome] | None, reason: str | None, message: str) -> None:
        """Resolve a batch that was handed to the scheduler (once), then hand over the next ones."""
        if batch.timer is not None:
            batch.timer.cancel()
        if self._resolve(batch, outcomes, reason, message):
            with self._lock:
                self._inflight -= 1
            self._pump()

    def _resolve(self, batch: _Batch, outcomes: list[TaskOutcome] | None, reason: str | None, message: str) -> bool:
        """Set every future of ``batch`` (False if another path already did: a batch resolves once)."""
        with self._lock:
            if not batch.futures:
                return False
            futures, batch.futures = batch.futures, []
        if outcomes is not None:
            elapsed = [o.elapsed_s for o in outcomes if o.ok]
            if elapsed:
                self.cost_s = 0.5 * self.cost_s + 0.5 * (sum(elapsed) / len(elapsed))
            for fut, outcome in zip(futures, outcomes, strict=True):
                fut.set_result(outcome)
        else:
            for fut in futures:
                fut.set_result(TaskOutcome(ok=False, reason=reason, message=message))
        return True


def create(address: str, workers: int, fn_path: str, timeout_s: float) -> DaskPool:
    """A :class:`DaskPool` on the scheduler at ``address`` (``workers`` is the cluster's business)."""
    return DaskPool(address, fn_path, timeout_s)


def wait_workers(pool: DaskPool, n: int, timeout: float = 60.0) -> bool:
    """Block until ``n`` workers are connected and warmed up (startup of tests and benchmarks)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        states = pool.client.run(worker_state)
        if len(states) >= n and all(s["warmed"] for s in states.values()):
            return True
        time.sleep(0.1)
    return False
