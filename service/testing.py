"""In-memory stand-ins for fast tests of the service: a source, a sink and an inline executor.

With a :class:`~service.clock.ManualClock` they run periods of the real
:class:`~service.scheduler.Scheduler` in milliseconds: push frames with :class:`MemorySource`, advance
the clock, read what came out of :class:`MemorySink`.  :class:`InlineExecutor` runs
:func:`service.worker.run_task` in the calling thread, so the worker function is the one the service
would run (the real identifier, or a cheap stand-in named ``module:function``).
"""

from __future__ import annotations

import json
from concurrent.futures import Future

import numpy as np

from service.frames import FrameBatch
from service.models import BusResult, PeriodSummary
from service.sources.base import Inlet
from service.worker import WindowTask, run_task


class MemorySource:
    """A source fed by the test: frames, windows or raw messages pushed for a bus.

    Parameters
    ----------
    name : str
    """

    def __init__(self, name: str = "memory") -> None:
        self.name = name
        self._inlet: Inlet | None = None

    def start(self, inlet: Inlet) -> None:
        """Deliver what is pushed from now on to ``inlet``."""
        self._inlet = inlet

    def _started(self) -> Inlet:
        if self._inlet is None:
            raise RuntimeError(f"source {self.name!r} is not started (or closed)")
        return self._inlet

    def push(self, bus: str, batch: FrameBatch) -> None:
        """Validate and buffer a batch of frames of ``bus``."""
        self._started().frames(bus, batch)

    def push_window(self, bus: str, t: np.ndarray, V: np.ndarray, theta: np.ndarray, P: np.ndarray,
                    Q: np.ndarray, f: np.ndarray | None = None) -> None:
        """Validate and buffer frames of ``bus`` given as columns.

        Parameters
        ----------
        bus : str
        t : ndarray
            Frame times, UTC [s].
        V, theta, P, Q : ndarray
            Voltage [pu], angle [rad], active and reactive power [pu].
        f : ndarray, optional
            Bus frequency [Hz].
        """
        cols = [np.asarray(c, dtype=np.float64) for c in (t, V, theta, P, Q)]
        self.push(bus, FrameBatch(*cols, f=None if f is None else np.asarray(f, dtype=np.float64)))

    def push_message(self, bus: str, payload: bytes, encoding: str) -> None:
        """Decode, validate and buffer one raw message of ``bus`` (as a network source would)."""
        self._started().message(bus, payload, encoding)

    def close(self) -> None:
        """Stop delivering."""
        self._inlet = None


class MemorySink:
    """A sink that keeps what it is given, optionally failing, optionally persisting.

    Parameters
    ----------
    name : str
    persists : bool
        Ordered with the persisting sinks (before those that publish).
    fail : bool
        Every write raises ``RuntimeError`` (a broken sink).
    journal : list, optional
        Shared with other sinks: each write appends ``(name, kind, key)``, so a test sees the order
        across sinks (``kind`` is ``results``, ``diagnosis`` or ``period``; ``key`` the buses or period).
    """

    def __init__(self, name: str = "memory", *, persists: bool = False, fail: bool = False,
                 journal: list | None = None) -> None:
        self.name = name
        self.persists = persists
        self.fail = fail
        self.journal = journal if journal is not None else []
        self.results: list[BusResult] = []
        self.payloads: list[str] = []
        self.diagnoses: list[dict] = []
        self.periods: list[PeriodSummary] = []
        self.closed = False

    def _note(self, kind: str, key) -> None:
        self.journal.append((self.name, kind, key))
        if self.fail:
            raise RuntimeError(f"sink {self.name} is broken")

    def write_results(self, batch: list[BusResult], payloads: list[str]) -> None:
        """Keep the results and their JSON."""
        self._note("results", tuple(r.bus for r in batch))
        self.results.extend(batch)
        self.payloads.extend(payloads)

    def write_diagnosis(self, bus: str, period: float, payload: str) -> None:
        """Keep the report, decoded."""
        self._note("diagnosis", (bus, period))
        self.diagnoses.append(json.loads(payload))

    def write_period(self, summary: PeriodSummary) -> None:
        """Keep the summary."""
        self._note("period", summary.period)
        self.periods.append(summary)

    def close(self) -> None:
        """Mark closed."""
        self.closed = True

    def by_period(self) -> dict[float, dict[str, BusResult]]:
        """period → bus → result, from what was written."""
        out: dict[float, dict[str, BusResult]] = {}
        for res in self.results:
            out.setdefault(res.period, {})[res.bus] = res
        return out


class InlineExecutor:
    """Runs each task at submission, in the calling thread; returns futures that are already done.

    Parameters
    ----------
    fn_path : str
        ``module:function`` of the worker function (as the ``identify_fn`` setting), e.g.
        ``service.worker:identify_window``.
    """

    def __init__(self, fn_path: str) -> None:
        self.fn_path = fn_path
        self.tasks: list[WindowTask] = []

    def submit(self, task: WindowTask) -> Future:
        """Run ``task`` now; its :class:`~service.worker.TaskOutcome` is the future's result."""
        self.tasks.append(task)
        fut: Future = Future()
        fut.set_result(run_task(self.fn_path, task))
        return fut

    def submit_many(self, tasks: list[WindowTask]) -> list[Future]:
        """:meth:`submit` of each task."""
        return [self.submit(task) for task in tasks]

    def close(self) -> None:
        """Nothing runs in the background."""
