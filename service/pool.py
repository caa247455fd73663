"""Executors of identification tasks: a local pool of spawned processes, or a Dask cluster.

Why not ``concurrent.futures.ProcessPoolExecutor``: one worker dying breaks that pool for every
pending task, and a hung task cannot be stopped.  Here each worker has its own pipe, a dispatcher
thread watches pipes, process sentinels and deadlines, and a crashed or timed-out task fails only its
bus; the dead or killed worker is replaced.
"""

from __future__ import annotations

import collections
import itertools
import logging
import multiprocessing as mp
import signal
import threading
import time
from concurrent.futures import Future
from multiprocessing.connection import Connection, wait
from typing import Protocol

from service import _worker_boot
from service.worker import TaskOutcome, WindowTask, resolve, run_task

log = logging.getLogger(__name__)


class Executor(Protocol):
    """What the scheduler needs: submit a task, get a future of its :class:`TaskOutcome`."""

    def submit(self, task: WindowTask) -> Future: ...

    def close(self) -> None: ...


def worker_loop(conn: Connection, fn_path: str) -> None:
    """Body of a worker process (started by :func:`service._worker_boot.main`): tasks until None or EOF."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    try:
        resolve(fn_path)  # import numerics once, before the first task
    except Exception as exc:  # noqa: BLE001 - reported per task below
        log.error("worker cannot import %s: %s", fn_path, exc)
    conn.send(("ready", None))
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return
        if msg is None:
            return
        task_id, task = msg
        conn.send((task_id, run_task(fn_path, task)))


class _Worker:
    __slots__ = ("process", "conn", "task_id", "future", "deadline", "bus", "ready")

    def __init__(self, process, conn: Connection) -> None:
        self.process = process
        self.conn = conn
        self.task_id: int | None = None
        self.future: Future | None = None
        self.deadline = 0.0
        self.bus = ""
        self.ready = False


class LocalPool:
    """Spawned worker processes with per-task timeouts and replacement of dead workers.

    Parameters
    ----------
    workers : int
        Processes (default setting 2: both cores of this machine).
    fn_path : str
        ``module:function`` run on each :class:`WindowTask`.
    timeout_s : float
        Per-task limit from the moment a worker receives it [s].
    """

    def __init__(self, workers: int, fn_path: str, timeout_s: float) -> None:
        self._ctx = mp.get_context("spawn")  # never fork a process holding a Zenoh session
        self.fn_path = fn_path
        self.timeout_s = timeout_s
        self._queue: collections.deque[tuple[int, WindowTask, Future]] = collections.deque()
        self._ids = itertools.count()
        self._lock = threading.Lock()
        self._wake_r, self._wake_w = self._ctx.Pipe(duplex=False)
        self._closed = False
        self.replaced = 0
        self._workers = [self._spawn() for _ in range(workers)]
        self._thread = threading.Thread(target=self._loop, name="aslm-pool", daemon=True)
        self._thread.start()

    # --- public -------------------------------------------------------------------------------------
    def submit(self, task: WindowTask) -> Future:
        """Queue a task; the future resolves to a :class:`TaskOutcome` (it never raises)."""
        fut: Future = Future()
        with self._lock:
            if self._closed:
                fut.set_result(TaskOutcome(ok=False, reason="shutdown", message="pool closed"))
                return fut
            self._queue.append((next(self._ids), task, fut))
        self._wake()
        return fut

    def busy(self) -> dict[int, str]:
        """pid → bus of the workers currently running a task."""
        return {w.process.pid: w.bus for w in list(self._workers) if w.future is not None}

    def pids(self) -> list[int]:
        """Process ids of the current workers."""
        return [w.process.pid for w in list(self._workers)]

    def wait_ready(self, timeout: float = 60.0) -> bool:
        """Block until every worker has imported its function (startup), False on timeout."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if all(w.ready for w in list(self._workers)):
                return True
            time.sleep(0.02)
        return False

    def close(self, timeout: float = 5.0) -> None:
        """Stop the workers; queued and running tasks resolve as ``shutdown``."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._wake()
        self._thread.join(timeout)
        for w in self._workers:
            try:
                w.conn.send(None)
            except (OSError, ValueError):
                pass
        end = time.monotonic() + timeout
        for w in self._workers:
            w.process.join(max(0.0, end - time.monotonic()))
            if w.process.is_alive():
                w.process.kill()
                w.process.join(1.0)
            self._fail(w, "shutdown", "pool closed")
            w.conn.close()
        with self._lock:
            while self._queue:
                _, _, fut = self._queue.popleft()
                fut.set_result(TaskOutcome(ok=False, reason="shutdown", message="pool closed"))

    # --- internals ----------------------------------------------------------------------------------
    def _wake(self) -> None:
        try:
            self._wake_w.send_bytes(b"x")
        except (OSError, ValueError):
            pass

    def _spawn(self) -> _Worker:
        parent, child = self._ctx.Pipe()
        proc = self._ctx.Process(target=_worker_boot.main, args=(child, self.fn_path), name="aslm-worker",
                                 daemon=True)
        proc.start()
        child.close()
        return _Worker(proc, parent)

    def _fail(self, w: _Worker, reason: str, message: str) -> None:
        if w.future is not None and not w.future.done():
            w.future.set_result(TaskOutcome(ok=False, reason=reason, message=message,
                                            elapsed_s=self.timeout_s if reason == "timeout" else 0.0))
        w.future, w.task_id, w.bus = None, None, ""

    def _replace(self, w: _Worker, reason: str, message: str) -> None:
        self.replaced += 1
        if w.process.is_alive():
            w.process.kill()
        w.process.join(2.0)
        w.conn.close()
        self._fail(w, reason, message)
        if not self._closed:
            i = self._workers.index(w)
            self._workers[i] = self._spawn()
            log.warning("worker %s replaced (%s)", w.process.pid, reason)

    def _dispatch(self) -> None:
        for w in self._workers:
            if w.future is not None or not w.ready:
                continue
            with self._lock:
                if not self._queue:
                    return
                task_id, task, fut = self._queue.popleft()
            if not fut.set_running_or_notify_cancel():
                continue
            w.task_id, w.future, w.bus = task_id, fut, task.bus
            w.deadline = time.monotonic() + self.timeout_s
            try:
                w.conn.send((task_id, task))
            except (OSError, ValueError) as exc:
                self._replace(w, "worker_crashed", f"send failed: {exc}")

    def _loop(self) -> None:
        while not self._closed:
            try:
                self._dispatch()
                busy = [w for w in self._workers if w.future is not None]
                now = time.monotonic()
                timeout = min([w.deadline - now for w in busy], default=1.0)
                handles: list = [self._wake_r]
                for w in self._workers:
                    handles += [w.conn, w.process.sentinel]
                ready = set(wait(handles, timeout=max(0.0, min(timeout, 1.0))))
                if self._wake_r in ready:
                    while self._wake_r.poll():
                        self._wake_r.recv_bytes()
                for w in list(self._workers):
                    if w.conn in ready:
                        try:
                            tag, outcome = w.conn.recv()
                        except (EOFError, OSError):
                            self._replace(w, "worker_crashed", f"worker {w.process.pid} died during the task")
                            continue
                        if tag == "ready":
                            w.ready = True
                        elif tag == w.task_id and w.future is not None:
                            w.future.set_result(outcome)
                            w.future, w.task_id, w.bus = None, None, ""
                    elif w.process.sentinel in ready:
                        code = w.process.exitcode
                        self._replace(w, "worker_crashed", f"worker {w.process.pid} exited ({code}) during the task")
                    elif w.future is not None and time.monotonic() > w.deadline:
                        self._replace(w, "timeout", f"no result within {self.timeout_s:g} s; worker killed")
            except Exception:  # noqa: BLE001 - the dispatcher must outlive any surprise
                log.exception("pool dispatcher error")
                time.sleep(0.1)


class DaskPool:
    """Tasks on a Dask distributed cluster (``pip install aslm[dask]``).

    Parameters
    ----------
    address : str
        Scheduler address, e.g. ``tcp://scheduler:8786``.
    fn_path : str
        ``module:function``; it must be importable on the Dask workers.
    timeout_s : float
        Per-task limit [s]; the Dask future is cancelled when it passes.
    """

    def __init__(self, address: str, fn_path: str, timeout_s: float) -> None:
        try:
            from distributed import Client
        except ImportError as exc:  # optional extra
            raise RuntimeError("executor is a Dask address but dask[distributed] is not installed: "
                               "pip install 'aslm[dask]'") from exc
        self.client = Client(address, timeout=30)
        self.fn_path = fn_path
        self.timeout_s = timeout_s

    def submit(self, task: WindowTask) -> Future:
        out: Future = Future()
        dfut = self.client.submit(run_task, self.fn_path, task, pure=False)

        def expire() -> None:
            if not out.done():
                dfut.cancel()
                out.set_result(TaskOutcome(ok=False, reason="timeout", message=f"no result within {self.timeout_s:g} s"))

        timer = threading.Timer(self.timeout_s, expire)
        timer.daemon = True
        timer.start()

        def done(f) -> None:
            timer.cancel()
            if out.done():
                return
            try:
                out.set_result(f.result())
            except Exception as exc:  # noqa: BLE001 - KilledWorker, CancelledError, ...
                reason = "worker_crashed" if type(exc).__name__ == "KilledWorker" else f"error:{type(exc).__name__}"
                out.set_result(TaskOutcome(ok=False, reason=reason, message=str(exc)[:500]))

        dfut.add_done_callback(done)
        return out

    def close(self) -> None:
        self.client.close()


def make_executor(executor: str, workers: int, fn_path: str, timeout_s: float) -> Executor:
    """``local`` → :class:`LocalPool`; a ``tcp://`` address → :class:`DaskPool`."""
    if executor == "local":
        return LocalPool(workers, fn_path, timeout_s)
    return DaskPool(executor, fn_path, timeout_s)
