"""The local executor: a pool of spawned worker processes on this machine.

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
import queue
import threading
import time
from concurrent.futures import Future
from multiprocessing.connection import Connection, wait

from service.executors import boot
from service.executors.base import TaskOutcome, WindowTask
from service.executors.child import READY

log = logging.getLogger(__name__)


_STOP = object()  # sender: send None (the worker's stop message), then end
_QUIT = object()  # sender: end without sending (the worker is being killed)


def _sender(conn: Connection, outbox: queue.SimpleQueue) -> None:
    """Send the messages of one worker's outbox (its own thread: a send to a worker that reads slowly
    or hangs blocks only this thread, never the dispatcher that enforces the deadlines)."""
    while True:
        msg = outbox.get()
        if msg is _QUIT:
            return
        try:
            conn.send(None if msg is _STOP else msg)
        except (OSError, ValueError):
            return  # the worker died: the dispatcher sees its sentinel and replaces it
        if msg is _STOP:
            return


class _Worker:
    __slots__ = ("process", "conn", "inflight", "deadline", "ready", "outbox")

    def __init__(self, process, conn: Connection) -> None:
        self.process = process
        self.conn = conn
        # Tasks sent and not yet answered, in the order the worker runs them: inflight[0] is running.
        self.inflight: collections.deque[tuple[int, WindowTask, Future]] = collections.deque()
        self.deadline = 0.0  # for inflight[0]
        self.ready = False
        self.outbox: queue.SimpleQueue = queue.SimpleQueue()
        threading.Thread(target=_sender, args=(conn, self.outbox), name="aslm-pool-send", daemon=True).start()


class LocalPool:
    """Spawned worker processes with per-task timeouts and replacement of dead workers.

    Parameters
    ----------
    workers : int
        Processes (default setting 2: both cores of this machine).
    fn_path : str
        ``module:function`` run on each :class:`WindowTask`.
    timeout_s : float
        Per-task limit [s], from the moment the task becomes the one its worker runs (the worker's
        previous result arrived, or it was idle when the task was sent).
    depth : int
        Tasks in flight per worker (default 8).  A worker is topped up to ``depth`` tasks, in one
        message, once it has ``depth // 2`` or fewer left, so it never idles waiting for the parent
        (a round trip costs ~0.5–5 ms when the parent is busy: comparable to one identification);
        results still come back one by one.  ``depth = 1`` is one task per worker at a time.

    Notes
    -----
    Failure isolation is per task, as with one task in flight: a worker runs its tasks in order and
    answers each, so the first unanswered one is the one running.  If the worker dies, that task fails
    (``worker_crashed``); if it passes its deadline, it fails (``timeout``) and the worker is killed.
    In both cases the worker's other unanswered tasks go back to the front of the queue, unchanged,
    and the worker is replaced.
    """

    def __init__(self, workers: int, fn_path: str, timeout_s: float, depth: int = 8) -> None:
        self._ctx = mp.get_context("spawn")  # never fork a process holding a Zenoh session
        self.fn_path = fn_path
        self.timeout_s = timeout_s
        self.depth = max(1, int(depth))
        self._queue: collections.deque[tuple[int, WindowTask, Future]] = collections.deque()
        # Background tasks (diagnoses) wait here: one goes only to an idle worker when no foreground task
        # waits, and a worker running one gets nothing else, so no identification waits behind it.
        self._background: collections.deque[tuple[int, WindowTask, Future]] = collections.deque()
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
        return self.submit_many([task])[0]

    def submit_many(self, tasks: list[WindowTask]) -> list[Future]:
        """Queue tasks (one lock, one wake-up of the dispatcher); futures as with :meth:`submit`."""
        futs = [Future() for _ in tasks]
        with self._lock:
            if self._closed:
                for fut in futs:
                    fut.set_result(TaskOutcome(ok=False, reason="shutdown", message="pool closed"))
                return futs
            for task, fut in zip(tasks, futs, strict=True):
                (self._background if task.background else self._queue).append((next(self._ids), task, fut))
        self._wake()
        return futs

    def busy(self) -> dict[int, str]:
        """pid → bus of the task each busy worker is running."""
        out = {}
        for w in list(self._workers):
            try:
                out[w.process.pid] = w.inflight[0][1].bus
            except IndexError:
                pass
        return out

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

    def problem(self) -> str | None:
        """Why the pool is not doing its job (dispatcher thread dead, no worker ready), or None."""
        if self._closed:
            return None
        if not self._thread.is_alive():
            return "pool dispatcher thread dead"
        workers = list(self._workers)
        if not any(w.ready and w.process.is_alive() for w in workers):
            return f"no worker ready (of {len(workers)}; {self.replaced} replaced since start)"
        return None

    def close(self, timeout: float = 5.0) -> None:
        """Stop the workers; queued and running tasks resolve as ``shutdown``."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._wake()
        self._thread.join(timeout)
        for w in self._workers:
            w.outbox.put(_STOP)
        end = time.monotonic() + timeout
        for w in self._workers:
            w.process.join(max(0.0, end - time.monotonic()))
            if w.process.is_alive():
                w.process.kill()
                w.process.join(1.0)
            w.outbox.put(_QUIT)
            self._fail_all(w, "shutdown", "pool closed")
            w.conn.close()
        with self._lock:
            for waiting in (self._queue, self._background):
                while waiting:
                    _, _, fut = waiting.popleft()
                    fut.set_result(TaskOutcome(ok=False, reason="shutdown", message="pool closed"))

    # --- internals ----------------------------------------------------------------------------------
    def _wake(self) -> None:
        try:
            self._wake_w.send_bytes(b"x")
        except (OSError, ValueError):
            pass

    def _spawn(self) -> _Worker:
        parent, child = self._ctx.Pipe()
        proc = self._ctx.Process(target=boot.main, args=(child, self.fn_path), name="aslm-worker",
                                 daemon=True)
        proc.start()
        child.close()
        return _Worker(proc, parent)

    def _fail_all(self, w: _Worker, reason: str, message: str) -> None:
        while w.inflight:
            _, _, fut = w.inflight.popleft()
            if not fut.done():
                fut.set_result(TaskOutcome(ok=False, reason=reason, message=message))

    def _replace(self, w: _Worker, reason: str, message: str) -> None:
        """Kill ``w``; its running task fails with ``reason``, its other tasks are queued again."""
        self.replaced += 1
        if w.process.is_alive():
            w.process.kill()
        w.process.join(2.0)
        w.outbox.put(_QUIT)
        w.conn.close()
        if w.inflight:
            _, _, fut = w.inflight.popleft()
            if not fut.done():
                fut.set_result(TaskOutcome(ok=False, reason=reason, message=message,
                                           elapsed_s=self.timeout_s if reason == "timeout" else 0.0))
        with self._lock:
            for item in reversed(w.inflight):  # not started: they run elsewhere, in order
                (self._background if item[1].background else self._queue).appendleft(item)
        w.inflight.clear()
        if not self._closed:
            i = self._workers.index(w)
            self._workers[i] = self._spawn()
            log.warning("worker %s replaced (%s)", w.process.pid, reason)

    def _dispatch(self) -> None:
        """Top up every ready worker with ``depth // 2`` or fewer tasks to ``depth``, least loaded first."""
        low = self.depth // 2
        open_ = [w for w in self._workers
                 if w.ready and len(w.inflight) <= low and not any(item[1].background for item in w.inflight)]
        if not open_:
            return
        batches: dict[int, list] = {id(w): [] for w in open_}
        now = time.monotonic()
        with self._lock:
            while self._queue:
                w = min(open_, key=lambda w: len(w.inflight))
                if len(w.inflight) >= self.depth:
                    break
                self._hand(w, self._queue.popleft(), now, batches)
            idle = [w for w in open_ if not w.inflight]
            while idle and self._background and not self._queue:
                w = idle[-1]
                if self._hand(w, self._background.popleft(), now, batches):
                    idle.pop()
        for w in open_:
            if batches[id(w)]:
                w.outbox.put(batches[id(w)])

    def _hand(self, w: _Worker, item: tuple[int, WindowTask, Future], now: float, batches: dict[int, list]) -> bool:
        """Give ``item`` to ``w`` in this round's batch; False if its future was cancelled."""
        fut = item[2]
        # A task queued again after its worker died is already running (for its future).
        if not fut.running() and not fut.set_running_or_notify_cancel():
            return False
        if not w.inflight:
            w.deadline = now + self.timeout_s
        w.inflight.append(item)
        batches[id(w)].append((item[0], item[1]))
        return True

    def _receive(self, w: _Worker) -> None:
        """Take every message ``w`` has sent so far."""
        while True:
            try:
                tag, outcome = w.conn.recv()
            except (EOFError, OSError):
                self._replace(w, "worker_crashed", f"worker {w.process.pid} died during the task")
                return
            if tag == READY:
                w.ready = True
            elif w.inflight and w.inflight[0][0] == tag:
                _, _, fut = w.inflight.popleft()
                w.deadline = time.monotonic() + self.timeout_s  # the next task starts now
                fut.set_result(outcome)
            else:
                log.error("worker %s answered unknown task %s", w.process.pid, tag)
            try:
                if not w.conn.poll():
                    return
            except (EOFError, OSError):
                return  # seen as dead on the next pass

    def _loop(self) -> None:
        while not self._closed:
            try:
                self._dispatch()
                now = time.monotonic()
                timeout = min([w.deadline - now for w in self._workers if w.inflight], default=1.0)
                handles: list = [self._wake_r]
                for w in self._workers:
                    handles += [w.conn, w.process.sentinel]
                ready = set(wait(handles, timeout=max(0.0, min(timeout, 1.0))))
                if self._wake_r in ready:
                    while self._wake_r.poll():
                        self._wake_r.recv_bytes()
                for w in list(self._workers):
                    if w.conn in ready:
                        self._receive(w)
                    elif w.process.sentinel in ready:
                        code = w.process.exitcode
                        self._replace(w, "worker_crashed", f"worker {w.process.pid} exited ({code}) during the task")
                    elif w.inflight and time.monotonic() > w.deadline:
                        self._replace(w, "timeout", f"no result within {self.timeout_s:g} s; worker killed")
            except Exception:  # noqa: BLE001 - the dispatcher must outlive any surprise
                log.exception("pool dispatcher error")
                time.sleep(0.1)


def create(address: str, workers: int, fn_path: str, timeout_s: float) -> LocalPool:
    """The ``local`` executor: a :class:`LocalPool` of ``workers`` processes (``address`` is ``local``)."""
    return LocalPool(workers, fn_path, timeout_s)
