"""First-order lags of a driving signal, shared by the candidates whose law acts on a filtered input.

A candidate whose extra term is K·x_f with T·dx_f/dt = x − x_f (a transducer, a controller or a frequency
estimator between the bus signal x and the load's response) fits T in the upper stage and K in the lower
one; :func:`lag_start` picks T's start from a scan with D held at the plain fit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy import signal

from aslm_core.diagnosis.segment import Segment


def lagged(x: np.ndarray, T: float, dt: float) -> np.ndarray:
    """First-order lag of x with time constant T [s], T·dx_f/dt = x − x_f, starting at rest at x[0].

    Exact for x linear between samples (y_{k+1} = α·y_k + c0·x_k + c1·x_{k+1}, α = e^{−dt/T}), so the lag holds
    at any dt/T (2 at 25 frames/s with T at its 0.02 s bound).  T ≤ 0 returns x itself (a copy): the lag's limit.
    """
    if T <= 0.0:
        return np.array(x, dtype=float)
    alpha = math.exp(-dt / T)
    c1 = 1.0 - (T / dt) * (1.0 - alpha)
    c0 = (1.0 - alpha) - c1
    zi = signal.lfiltic([c1, c0], [1.0, -alpha], y=[x[0]], x=[x[0]])
    return signal.lfilter([c1, c0], [1.0, -alpha], x, zi=zi)[0]


def lag_start(seg: Segment, ctx, x: np.ndarray, grid: Sequence[float], default: float) -> float:
    """The T of ``grid`` [s] whose lagged ``x``, as one extra column on P and on Q beside the static
    regressors, best fits the training residual of the plain model at ``ctx.d0`` (each channel's sum of
    squares relative to its variance); ``default`` when the plain motor has no trajectory.  ``ctx`` is the
    candidates' :class:`~aslm_core.diagnosis.candidates.base.Context`.
    """
    # Imported here: the candidates import this module, and the package's __init__ imports every candidate.
    from aslm_core.diagnosis.candidates.base import simulate_motor, static_part

    m = simulate_motor(seg, ctx.d0)
    if m is None:
        return default
    fp, fq, sx = static_part(seg, ctx)
    tr = seg.train
    yp, yq = (seg.P - m[0] - fp)[tr], (seg.Q - m[1] - fq)[tr]
    best, best_t = np.inf, default
    for T in grid:
        xs = np.hstack([sx, lagged(x, T, seg.dt)[:, None]])[tr]
        xs = xs / np.linalg.norm(xs, axis=0)
        ssr = 0.0
        for y in (yp, yq):
            beta, *_ = np.linalg.lstsq(xs, y, rcond=None)
            r = y - xs @ beta
            ssr += float(r @ r) / max(float(np.var(y)) * y.size, 1e-300)
        if ssr < best:
            best, best_t = ssr, float(T)
    return best_t
