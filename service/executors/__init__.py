"""Executors of identification tasks, chosen by the ``executor`` setting.

An executor takes :class:`~service.executors.base.WindowTask` s and returns futures of
:class:`~service.executors.base.TaskOutcome` s (the :class:`~service.executors.base.Executor`
protocol).  Each lives in its own module with a factory ``create(address, workers, fn_path,
timeout_s)``; adding one is that module plus one line in :data:`EXECUTORS`.

This package's own import stays free of numpy: a spawned worker imports it on its way to
:mod:`service.executors.boot`, before the thread limits are set.
"""

from __future__ import annotations

import importlib
import re
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from service.executors.base import Executor

#: Executor module → the values of the ``executor`` setting it serves: a name, or ``scheme://`` for
#: an address ``scheme://host:port``.
EXECUTORS: dict[str, tuple[str, ...]] = {
    "service.executors.local": ("local",),
    "service.executors.dask": ("tcp://", "tls://", "ucx://", "inproc://"),
}


def executor_module(executor: str) -> str | None:
    """The module that serves an ``executor`` setting, or None if no executor does.

    Parameters
    ----------
    executor : str
        ``local`` or an address such as ``tcp://scheduler:8786``.
    """
    for module, forms in EXECUTORS.items():
        for form in forms:
            if executor == form if not form.endswith("://") else re.fullmatch(re.escape(form) + r"\S+", executor):
                return module
    return None


def make_executor(executor: str, workers: int, fn_path: str, timeout_s: float) -> Executor:
    """Create the executor an ``executor`` setting names.

    Parameters
    ----------
    executor : str
        ``local`` (a pool of spawned processes) or a Dask scheduler address ``tcp://host:port``.
    workers : int
        Worker processes of the local pool.
    fn_path : str
        ``module:function`` run on each task.
    timeout_s : float
        Per-task limit [s].

    Raises
    ------
    ValueError
        No registered executor serves ``executor``.
    """
    module = executor_module(executor)
    if module is None:
        raise ValueError(f"no executor for {executor!r}")
    return importlib.import_module(module).create(executor, workers, fn_path, timeout_s)
