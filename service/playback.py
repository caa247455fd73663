"""Worker side of the dashboard's "measured vs model": a bus's model played back on its newest frames.

Runs in a worker process (``WindowTask.fn = "service.playback:playback_window"``), because the model
is simulated by the numba kernels the service's main process never loads.  Like :mod:`service.worker`
it imports no Zenoh, FastAPI or SQLite.
"""

from __future__ import annotations

import math

import numpy as np

from service.executors.base import WindowTask

#: Most points per channel sent back (the page draws a few hundred pixels wide).
MAX_POINTS = 600


def fit_degree(measured: np.ndarray, model: np.ndarray) -> float:
    """Fit degree 1 − Σ(y − ŷ)² / Σ(y − ȳ)² [-] (the paper's eq. 9 form, over the whole window).

    The identifier's own figure skips the motor's start-up transient, so this one can be slightly lower.
    """
    ss = float(np.sum((measured - measured.mean()) ** 2))
    return 1.0 - float(np.sum((measured - model) ** 2)) / ss if ss > 0.0 else math.nan


def playback_window(task: WindowTask) -> dict:
    """P and Q of the model in ``task.previous`` driven by the window's measured V and θ.

    Parameters
    ----------
    task : WindowTask
        ``window``: the bus's newest frames; ``previous``: an identification (``dynamic`` D = {a [1/s],
        b [1/s], H2 [s], Tm [pu]} and ``static``); ``options["lowpass_hz"]``: the fixed low-pass the identifier
        applies [Hz] (None: the identifier's default conditioning), and ``options["input_noise"]`` the service's
        (``auto`` when absent), so that the model is compared with what it was fitted to.

    Returns
    -------
    dict
        ``t`` [s], ``P``, ``Q``, ``P_model``, ``Q_model`` [pu] (decimated to at most :data:`MAX_POINTS`
        points), ``fd_p``, ``fd_q`` [-] on the full grid, ``n`` (samples before decimation).

    Raises
    ------
    WindowError
        The frames do not form a usable window (gaps, too short); the worker reports it as
        ``window:<reason>``.
    """
    from aslm_core import IdentifyConfig
    from aslm_core.diagnosis.playback import model_power
    from aslm_core.preprocess import prepare

    smoother = IdentifyConfig.input_smoother  # the identifier's default input conditioning
    prep = prepare(task.window, lowpass_hz=task.options.get("lowpass_hz"), input_smoother=smoother,
                   input_noise=task.options.get("input_noise", "auto"))
    p_model, q_model = model_power(prep.V, prep.theta, task.previous, prep.dt, task.window.f0)
    step = max(1, math.ceil(prep.t.size / MAX_POINTS))
    return {
        "t": prep.t[::step].tolist(), "P": prep.P[::step].tolist(), "Q": prep.Q[::step].tolist(),
        "P_model": p_model[::step].tolist(), "Q_model": q_model[::step].tolist(),
        "fd_p": fit_degree(prep.P, p_model), "fd_q": fit_degree(prep.Q, q_model), "n": int(prep.t.size),
    }
