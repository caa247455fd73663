"""What runs inside a worker process: one window in, one outcome out.

Kept free of Zenoh, FastAPI and SQLite imports so spawned workers start quickly and hold no sockets.
"""

from __future__ import annotations

import dataclasses
import importlib
import math
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from aslm_core.window import Window
from service.executors.base import TaskOutcome, WindowTask

if TYPE_CHECKING:
    from aslm_core.noise import InputSpectrum


def identify_window(task: WindowTask) -> dict:
    """Default worker function: :func:`aslm_core.identify` on the task's window, with the inputs' spectrum
    pooled from the bus's windows before it where the task carries them (:func:`history_spectrum`).

    Returns
    -------
    dict
        ``IdentificationResult.to_dict()``.
    """
    from aslm_core import IdentifyConfig, identify

    warm = np.asarray(task.warm_start, dtype=float) if task.warm_start is not None else None
    config = IdentifyConfig(**task.options)
    spectrum = history_spectrum(task.history, task.window, config.max_gap_samples) if task.history else None
    return result_dict(identify(task.window, warm_start=warm, config=config, input_spectrum=spectrum))


def history_spectrum(history: Sequence[Window], window: Window, max_gap_samples: int) -> InputSpectrum | None:
    """The inputs' spectrum pooled from the windows before ``window`` (:class:`aslm_core.input_history.InputHistory`
    of all of them), or None where one of them cannot give its periodogram (the window is then identified alone).

    Parameters
    ----------
    history : sequence of aslm_core.Window
        The bus's windows before ``window``, oldest first, not overlapping.
    window : aslm_core.Window
        The window to identify.
    max_gap_samples : int
        As :func:`aslm_core.preprocess.prepare`.

    Returns
    -------
    aslm_core.noise.InputSpectrum or None
    """
    from aslm_core import WindowError
    from aslm_core.input_history import InputHistory
    from aslm_core.preprocess import input_periodogram

    held = InputHistory(k=len(history), max_age_s=math.inf)
    for w in history:
        try:
            held.add(float(w.t[0]), float(w.t[-1]), input_periodogram(w, max_gap_samples=max_gap_samples))
        except (WindowError, ValueError):
            return None
    return held.spectrum(float(window.t[0]))


def result_dict(result) -> dict:
    """``result.to_dict()`` (an :class:`aslm_core.IdentificationResult`) without its deep copy.

    ``to_dict`` is ``dataclasses.asdict``, which deep-copies every nested dict and list: 0.23 ms per
    window, ~7 % of a warm-started identification.  The result is discarded after pickling, so its
    fields can be shared; a field that is itself a dataclass falls back to ``to_dict``.
    ``tests/service/test_service_worker.py`` checks that both give the same dict.
    """
    out = {f.name: getattr(result, f.name) for f in dataclasses.fields(result)}
    if any(dataclasses.is_dataclass(v) for v in out.values()):
        return result.to_dict()
    return out


def _warm_identify() -> None:
    """Compile (or load from numba's cache) the identifier's kernels: worker start-up, not the first period.

    Identifies a small synthetic window with the default configuration (RK4, input smoother): the
    service's path only (``aslm_core.warmup`` also compiles the Euler mode, which the service never uses).
    """
    from aslm_core import IdentifyConfig, Window, identify

    t = np.arange(500) / 50.0
    V = 1.0 + 0.003 * np.sin(2 * np.pi * 0.7 * t) + 0.002 * np.sin(2 * np.pi * 1.9 * t)
    theta = 0.005 * np.sin(2 * np.pi * 0.4 * t)
    identify(Window(t, V, theta, 0.8 * V * V + 0.05 * V, 0.3 * V * V), warm_start=[40.0, 15.0, 1.3, 0.5],
             config=IdentifyConfig(n_starts=1))


identify_window.warmup = _warm_identify


def diagnose_window(task: WindowTask) -> dict:
    """Worker function of the discrepancy diagnosis (DESIGN §3) of the task's window.

    Returns
    -------
    dict
        The JSON-ready report of :func:`aslm_core.diagnosis.diagnose_dict`, warm-started from the
        window's identification in ``task.previous``, with ``task.options``' ``input_noise`` (the service's).
    """
    from aslm_core.diagnosis import DiagnosisConfig, diagnose_dict

    window = task.window
    # The channels' noise as the bus's identification took it (a PMU's reporting filter: ``input_noise``).
    config = DiagnosisConfig(input_noise=(task.options or {}).get("input_noise", "auto"))
    return diagnose_dict(window, previous=task.previous, config=config)


def pooled_window(task: WindowTask) -> dict:
    """Worker function of the tracked model's joint pooled fit: one D from the windows of ``task.pool``.

    :func:`aslm_core.pooled.identify_pooled` on the pool's windows (back in float64), started from
    ``task.warm_start`` (the bus's previous joint D, or the tracker's mean), with ``task.options`` as
    :class:`aslm_core.IdentifyConfig` keyword arguments.

    Returns
    -------
    dict
        ``dynamic``, ``stderr`` (as D's), ``cov`` (4×4 in the order a, b, H2, Tm), ``n_windows``,
        ``iterations``, ``status``, ``flags``, ``objective``, ``disturbance`` (``none`` or ``ar_iv``: which of the
        gated pool's estimates answered) and ``own_ratio_p`` (what the gate read).
    """
    from aslm_core import IdentifyConfig
    from aslm_core.pooled import identify_pooled

    fit = identify_pooled([w.window() for w in task.pool or []], start=task.warm_start,
                          config=IdentifyConfig(**task.options))
    return {"dynamic": fit.dynamic, "stderr": fit.stderr, "cov": fit.cov, "n_windows": fit.n_windows,
            "iterations": fit.iterations, "status": fit.status, "flags": fit.flags, "objective": fit.objective,
            "disturbance": fit.disturbance, "own_ratio_p": fit.own_ratio_p}


_FN_CACHE: dict[str, Callable[[WindowTask], dict]] = {}


def resolve(fn_path: str) -> Callable[[WindowTask], dict]:
    """Import ``module:function``.

    A worker function may carry a ``warmup`` attribute: a callable without arguments that the worker
    runs once at start, before it reports ready (e.g. JIT compilation).
    """
    fn = _FN_CACHE.get(fn_path)
    if fn is None:
        module, _, name = fn_path.partition(":")
        fn = _FN_CACHE[fn_path] = getattr(importlib.import_module(module), name)
    return fn


def finite(obj):
    """Replace non-finite floats (not JSON) by None, recursively (in the worker: off the service's process)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite(v) for v in obj]
    return obj


def run_task(fn_path: str, task: WindowTask) -> TaskOutcome:
    """Run one task, turning every exception into a failed outcome with a reason.

    The value's non-finite floats become None (:func:`finite`).  The outcome carries the task's wall time
    and its thread's CPU time [s].
    """
    t0, c0 = time.perf_counter(), time.thread_time()
    try:
        value = resolve(task.fn or fn_path)(task)
        return TaskOutcome(ok=True, value=finite(value), elapsed_s=time.perf_counter() - t0,
                           cpu_s=time.thread_time() - c0)
    except Exception as exc:  # noqa: BLE001 - any failure fails this bus only
        reason = getattr(exc, "reason", None)
        reason = f"window:{reason}" if reason and type(exc).__name__ == "WindowError" else f"error:{type(exc).__name__}"
        return TaskOutcome(ok=False, reason=reason, message=str(exc)[:500], elapsed_s=time.perf_counter() - t0,
                           cpu_s=time.thread_time() - c0)
