"""What the scheduler and every executor share: the task, its outcome and the executor protocol."""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from aslm_core.window import Window

if TYPE_CHECKING:
    from service.window_ring import CompactWindow


@dataclass
class WindowTask:
    """One bus's window to identify (pickled to the worker).

    Attributes
    ----------
    window : aslm_core.Window or CompactWindow
        The bus's samples (t [s], V [pu], θ [rad], P, Q [pu], optional f [Hz]), nominal frequency f0
        [Hz] and bus name.  Its ``meta`` stays empty: it would be pickled with every task.  In the joint
        pooled fit's task, the newest of ``pool``.
    warm_start : list of float or None
        Previous period's D = [a, b, H2, Tm] of the bus.
    options : dict
        Keyword arguments of :class:`aslm_core.IdentifyConfig` (e.g. ``n_starts``); the diagnosis's task carries only
        ``input_noise``.
    fn : str or None
        ``module:function`` to run instead of the executor's (e.g. the diagnosis).
    previous : dict or None
        The bus's identification of this window (``IdentificationResult.to_dict()``), for the diagnosis.
    background : bool
        Runs only when no identification waits (the diagnosis): an executor that can order its tasks
        gives such a task only to an idle worker and nothing else to that worker while it runs.
    pool : list of CompactWindow or None
        The windows of the joint pooled fit of the tracked model (``service.worker:pooled_window``),
        oldest first, in float32 (:mod:`service.window_ring`).
    history : tuple of aslm_core.Window
        The bus's windows just before ``window``, oldest first, non-overlapping, from its buffer (the service's
        ``input_history_windows``): the worker pools their V and θ periodograms into the inputs' spectrum of the
        identifier's noisy-input refinement (:class:`aslm_core.input_history.InputHistory`).  Empty: the window
        alone.
    """

    window: Window | CompactWindow
    warm_start: list[float] | None = None
    options: dict[str, Any] = field(default_factory=dict)
    fn: str | None = None
    previous: dict | None = None
    background: bool = False
    pool: list[CompactWindow] | None = None
    history: tuple[Window, ...] = ()

    @property
    def bus(self) -> str:
        """The window's bus."""
        return self.window.bus


@dataclass
class TaskOutcome:
    """Result of one task: ``value`` (the identification dict) or a failure ``reason``.

    Reasons: ``window:<WindowError.reason>``, ``error:<ExceptionType>``, ``timeout``,
    ``worker_crashed``, ``shutdown``.

    ``elapsed_s`` is the task's wall time in the worker [s], ``cpu_s`` the CPU time of the worker's
    thread meanwhile [s]: on a shared machine the wall time also counts the time the worker waited
    for a core, so what a task costs is ``cpu_s``.
    """

    ok: bool
    value: dict | None = None
    reason: str | None = None
    message: str = ""
    elapsed_s: float = 0.0
    cpu_s: float = 0.0


class Executor(Protocol):
    """What the scheduler needs: submit a task, get a future of its :class:`TaskOutcome`.

    The futures never raise: every failure (the task's own, a crash, a timeout, shutdown) resolves
    as a :class:`TaskOutcome` with ``ok=False`` and a reason.
    """

    def submit(self, task: WindowTask) -> Future: ...

    def submit_many(self, tasks: list[WindowTask]) -> list[Future]: ...

    def close(self) -> None: ...
