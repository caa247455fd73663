"""The loop a spawned worker process runs (started by :func:`service.executors.boot.main`).

It imports the worker functions (and with them numpy), never the pool: the parent's side lives in
:mod:`service.executors.local`.
"""

from __future__ import annotations

import logging
import os
import queue
import signal
import threading
from multiprocessing.connection import Connection
from multiprocessing.reduction import ForkingPickler

from service.executors.base import TaskOutcome
from service.worker import resolve, run_task

log = logging.getLogger(__name__)

#: Tag of a worker's first message: its function is imported and warmed up.
READY = "ready"


def worker_loop(conn: Connection, fn_path: str) -> None:
    """Body of a worker process.

    Parameters
    ----------
    conn : Connection
        The worker's end of its pipe to the pool.
    fn_path : str
        ``module:function`` run on each task (unless the task names its own ``fn``).

    Notes
    -----
    Messages in are lists of ``(task_id, task)`` (or None: stop); each task's outcome goes back as
    ``(task_id, outcome)`` as soon as it is done, in order.  A reader thread takes messages off the
    pipe while a task runs, so the parent can queue the next tasks without waiting for this one and
    its sends never wait for the computation.  When the pipe closes without a stop message (the parent
    was killed), the reader ends the process at once, whatever task is running.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    try:
        fn = resolve(fn_path)  # import numerics once, before the first task
        if callable(getattr(fn, "warmup", None)):
            fn.warmup()  # e.g. JIT compilation, before the worker reports ready
    except Exception as exc:  # noqa: BLE001 - reported per task below
        log.error("worker cannot import or warm up %s: %s", fn_path, exc)
    inbox: queue.SimpleQueue = queue.SimpleQueue()
    stop = threading.Event()

    def read() -> None:
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):
                # The parent has gone (a graceful stop sends None first): nobody is left to take this worker's
                # results, so it ends now, not after its running task, which may be one that hangs.
                os._exit(0)
            if msg is None:
                stop.set()
                inbox.put(None)
                return
            inbox.put(msg)

    threading.Thread(target=read, name="aslm-worker-recv", daemon=True).start()
    conn.send((READY, None))
    while True:
        msg = inbox.get()
        if msg is None:
            return
        for task_id, task in msg:
            if stop.is_set():
                return
            outcome = run_task(fn_path, task)
            try:
                data = ForkingPickler.dumps((task_id, outcome))
            except Exception as exc:  # noqa: BLE001 - a result that cannot be pickled fails its task only
                data = ForkingPickler.dumps((task_id, TaskOutcome(
                    ok=False, reason=f"error:{type(exc).__name__}", message=f"result not transferable: {exc}"[:500],
                    elapsed_s=outcome.elapsed_s)))
            try:
                conn.send_bytes(data)
            except (OSError, ValueError):
                return  # the parent has gone
