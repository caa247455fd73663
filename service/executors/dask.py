"""The Dask executor: tasks on a Dask distributed cluster (``executor = "tcp://scheduler:8786"``).

``distributed`` is imported only when this executor is created (the ``dask`` extra).

Why batches: Dask's scheduler costs about 1 ms per task (its documentation's figure), against
2.5–3.7 ms of work per warm-started window (docs/service.md), so one task per bus would spend a quarter
of the cluster on scheduling.  Windows go out in batches sized from the measured per-bus cost so that a
batch holds about :data:`BATCH_S` of work; each batch's outcomes come back together and resolve one
future per window.

A worker that dies mid-batch: the scheduler runs the batch again on another worker (the batch's
partial work is never reported, so no bus is duplicated); if that one dies too (the scheduler's
``distributed.scheduler.allowed-failures``, which the compose profile and the tests set to 1), the
batch's windows are run again one at a time, each alone on the cluster (no other batch of this pool
in flight), and a window whose lone run kills the workers again fails with ``worker_crashed``.  Why
alone: the scheduler counts a worker's death against every task that worker held, so a batch that
merely ran or queued beside a poisonous one on both workers fails too; only a window that kills
its workers while nothing else ran is certainly the cause.  No window is ever left without an
outcome.
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
from concurrent.futures import CancelledError, Future

from service.executors.base import TaskOutcome, WindowTask
from service.worker import resolve, run_task

try:  # the dask extra; DaskPool says how to install it when it is missing
    from distributed import WorkerPlugin
except ImportError:  # pragma: no cover - the extra is part of the test install
    WorkerPlugin = object

log = logging.getLogger(__name__)

#: Work per batch [s of a worker thread's CPU]: 1 ms of scheduling is then 0.5 % of it, and a batch
#: lost with its worker costs a fifth of a second to run again.
BATCH_S = 0.2
#: Per-bus cost assumed until the first outcomes are measured [s of CPU] (a warm-started window,
#: docs/service.md: 2.5–3.7 ms).
COST_S = 0.004
#: Batches in flight per worker thread: one running, one queued behind it so no thread idles for a
#: round trip; the rest wait here, so a batch's deadline starts close to when it runs.
INFLIGHT_PER_THREAD = 2
#: How long the cluster's thread count is reused [s]: asking the scheduler costs a round trip, which
#: each hand-over of a batch would otherwise pay.
THREADS_TTL_S = 1.0
#: Dask settings of the cluster's scheduler and workers: the compose profile's ``DASK_*`` variables
#: and the tests' and benchmarks' ``LocalCluster``.  A batch whose worker dies is
#: run once more, then fails.  The rest cuts Dask's background work, which by default costs an idle
#: 2-worker cluster about 0.11 core (docs/cluster.md, "Measured"): the statistical profiler samples the
#: task thread every 10 ms, every server's event loop ticks every 20 ms, memory is polled every 100 ms
#: and the system monitor runs every 0.5 s.  None of these serve the service (no dashboard).
CLUSTER_CONFIG: dict[str, object] = {
    "distributed.scheduler.allowed-failures": 1,
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "1s",
}


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
    """Windows handed to the scheduler as one Dask task, with their futures."""

    __slots__ = ("tasks", "futures", "dfut", "timer", "alone")

    def __init__(self, tasks: list[WindowTask], futures: list[Future], alone: bool = False) -> None:
        self.tasks = tasks
        self.futures = futures
        self.dfut = None
        self.timer: threading.Timer | None = None
        self.alone = alone  # one window of a killed batch, run with nothing else of this pool in flight


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
        Running estimate of the work per window [s of CPU] (mean of the latest outcomes' ``cpu_s``):
        batches are sized from it.  CPU rather than wall time because on a shared machine a window's
        wall time grows with the other jobs' load while Dask's per-task overhead, which batches
        amortise, is CPU too: sized from wall time, batches would shrink as the machine gets busier.
    wall_s : float
        Running estimate of the wall time per window [s] (``elapsed_s``), for the batches' deadlines.
    batches : int
        Batches handed to the scheduler so far.
    rerun_alone : int
        Windows of killed batches run again one at a time, each alone on the cluster.
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
        self.wall_s = COST_S
        self.batches = 0
        self.rerun_alone = 0
        self.replaced = 0  # the Executor attribute /health reports; Dask's nannies replace workers
        self._lock = threading.Lock()
        # Windows not yet handed over: cut into batches only when a batch can go, so windows submitted in
        # small groups (the period scheduler hands them over 64 at a time) still travel in full batches.
        self._waiting: collections.deque[tuple[WindowTask, Future]] = collections.deque()
        self._inflight = 0  # batches handed to the scheduler and not resolved
        self._suspects: collections.deque[tuple[WindowTask, Future]] = collections.deque()  # of killed batches
        self._inflight_windows = 0
        self._threads = (0, -math.inf)  # (count, monotonic time it was asked)
        self._closed = False
        self.client.register_plugin(WarmupPlugin(fn_path, cache_root), name=WarmupPlugin.name)

    # --- public -------------------------------------------------------------------------------------
    def threads(self) -> int:
        """Worker threads of the cluster (at least 1), as the scheduler said at most :data:`THREADS_TTL_S` ago."""
        count, asked = self._threads
        now = time.monotonic()
        if now - asked > THREADS_TTL_S:
            count = max(1, sum(self.client.nthreads().values()))
            self._threads = (count, now)
        return count

    def batch_size(self, n: int, threads: int | None = None) -> int:
        """Windows per batch when ``n`` windows are outstanding (waiting here or in flight): about
        ``batch_s`` of work, yet at least 4 batches per worker thread when ``n`` allows (so the load
        spreads at the end of a period and a lost batch is small)."""
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
        with self._lock:
            if self._closed:
                for fut in futs:
                    fut.set_result(TaskOutcome(ok=False, reason="shutdown", message="executor closed"))
                return futs
            self._waiting.extend(zip(tasks, futs, strict=True))
        self._pump()
        return futs

    def close(self) -> None:
        """Fail what has not finished as ``shutdown`` and disconnect from the scheduler."""
        with self._lock:
            self._closed = True
            waiting, self._waiting = list(self._waiting) + list(self._suspects), collections.deque()
            self._suspects = collections.deque()
        for _, fut in waiting:
            fut.set_result(TaskOutcome(ok=False, reason="shutdown", message="executor closed"))
        self.client.close()

    # --- internals ----------------------------------------------------------------------------------
    def _pump(self) -> None:
        """Cut waiting windows into batches (:meth:`batch_size` of all outstanding windows) and hand
        them to the scheduler, up to ``inflight_per_thread`` batches per worker thread."""
        threads = self.threads()
        limit = self.inflight_per_thread * threads
        while True:
            with self._lock:
                if self._suspects and not self._closed:
                    if self._inflight:  # a suspect runs alone: let what is in flight finish first
                        return
                    task, fut = self._suspects.popleft()
                    batch = _Batch([task], [fut], alone=True)
                    self._inflight += 1
                    self._inflight_windows += len(batch.tasks)
                    self.batches += 1
                    self.rerun_alone += 1
                else:
                    batch = None
            if batch is not None:
                self._launch(batch)
                return
            with self._lock:
                if self._closed or not self._waiting or self._inflight >= limit:
                    return
                size = self.batch_size(len(self._waiting) + self._inflight_windows, threads)
                items = [self._waiting.popleft() for _ in range(min(size, len(self._waiting)))]
                batch = _Batch([task for task, _ in items], [fut for _, fut in items])
                self._inflight += 1
                self._inflight_windows += len(items)
                self.batches += 1
            self._launch(batch)

    def _launch(self, batch: _Batch) -> None:
        """Hand one batch (already counted in flight) to the scheduler, with its deadline."""
        try:
            batch.dfut = self.client.submit(run_batch, self.fn_path, batch.tasks, pure=False)
        except Exception as exc:  # noqa: BLE001 - e.g. the scheduler is gone: fail this batch
            self._settle(batch, None, f"error:{type(exc).__name__}", str(exc)[:500])
            return
        limit_s = self.timeout_s + 2.0 * len(batch.tasks) * max(self.wall_s, self.cost_s)
        batch.timer = threading.Timer(limit_s, self._expire, args=(batch, limit_s))
        batch.timer.daemon = True
        batch.timer.start()
        batch.dfut.add_done_callback(lambda f, batch=batch: self._done(batch, f))

    def _suspect(self, batch: _Batch) -> bool:
        """Queue the windows of a batch killed beside others to run again alone (False: it ran alone,
        or it is already resolved)."""
        if batch.timer is not None:
            batch.timer.cancel()
        with self._lock:
            if batch.alone or not batch.futures or self._closed:
                return False
            futures, batch.futures = batch.futures, []
            self._suspects.extend(zip(batch.tasks, futures, strict=True))
            self._inflight -= 1
            self._inflight_windows -= len(batch.tasks)
        log.warning("a batch of %d windows was on workers that died: running them again one at a time",
                    len(futures))
        self._pump()
        return True

    def _expire(self, batch: _Batch, limit_s: float) -> None:
        # Resolve before cancelling: the cancellation calls _done on another thread, which must find
        # the batch resolved (else its windows could fail as the cancellation, not as the timeout).
        self._settle(batch, None, "timeout", f"batch of {len(batch.tasks)} not done within {limit_s:.3g} s")
        if batch.dfut is not None:
            batch.dfut.cancel()

    def _done(self, batch: _Batch, dfut) -> None:
        try:
            outcomes = dfut.result()
        except Exception as exc:  # noqa: BLE001 - KilledWorker, CancelledError, ...
            name = type(exc).__name__
            if isinstance(exc, CancelledError):  # distributed's FutureCancelledError is one too
                return  # cancelled by the timeout, which has resolved the batch
            if name == "KilledWorker" and self._suspect(batch):
                return
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
                self._inflight_windows -= len(batch.tasks)
            self._pump()

    def _resolve(self, batch: _Batch, outcomes: list[TaskOutcome] | None, reason: str | None, message: str) -> bool:
        """Set every future of ``batch`` (False if another path already did: a batch resolves once)."""
        with self._lock:
            if not batch.futures:
                return False
            futures, batch.futures = batch.futures, []
        if outcomes is not None:
            done = [o for o in outcomes if o.ok]
            if done:
                self.cost_s = 0.5 * self.cost_s + 0.5 * sum(o.cpu_s for o in done) / len(done)
                self.wall_s = 0.5 * self.wall_s + 0.5 * sum(o.elapsed_s for o in done) / len(done)
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
