"""The Dask executor: tasks on a Dask distributed cluster (``executor = "tcp://scheduler:8786"``).

``distributed`` is imported only when this executor is created (an optional extra).
"""

from __future__ import annotations

import threading
from concurrent.futures import Future

from service.executors.base import TaskOutcome, WindowTask
from service.worker import run_task


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

    def submit_many(self, tasks: list[WindowTask]) -> list[Future]:
        """:meth:`submit` of each task."""
        return [self.submit(task) for task in tasks]

    def close(self) -> None:
        self.client.close()


def create(address: str, workers: int, fn_path: str, timeout_s: float) -> DaskPool:
    """A :class:`DaskPool` on the scheduler at ``address`` (``workers`` is the cluster's business)."""
    return DaskPool(address, fn_path, timeout_s)
