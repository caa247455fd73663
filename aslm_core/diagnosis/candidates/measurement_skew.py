"""``measurement_skew``: a time offset τ between the voltage channels and the power channels.

Notes
-----
The recorded powers lag the recorded voltage by τ [s] (e.g. P, Q from another device, or a mis-aligned
time stamp)::

    P_meas(t) = P_model(t − τ),   Q_meas(t) = Q_model(t − τ)

The model output (motor power and every lower-stage regressor) is evaluated at t − τ by cubic-convolution
interpolation on the sample grid — the *model* is shifted, never the measurement, so the noise is not
smoothed and no candidate gains from interpolating noise.  One nonlinear parameter τ [s], bounded to
±0.1 s, fitted in the upper stage with D.

Signature: residual ≈ −τ·dP/dt, i.e. in quadrature with the power's own fluctuation; coherent with
dV/dt and Δf on both channels alike.
"""

from __future__ import annotations

import numpy as np

from aslm_core.diagnosis.candidates.base import Candidate, Context, Prediction
from aslm_core.diagnosis.segment import Segment

TAU_MAX_S = 0.1


def shift(t: np.ndarray, y: np.ndarray, tau: float) -> np.ndarray:
    """y evaluated at t − τ along axis 0 on a uniform grid (Keys cubic convolution, edges held).

    Four-tap interpolation with third-order accuracy: for ambient content (< 5 Hz at ≥ 50 frames/s) its
    error is below 1e-4 of the signal, far below any noise level.
    """
    if tau == 0.0:
        return y
    dt = float(t[1] - t[0])
    u = -tau / dt  # fractional sample offset: y(t_i − τ) = y at index i + u
    m = int(np.floor(u))
    f = u - m
    # Keys (a = −1/2) weights for the samples at offsets m−1, m, m+1, m+2.
    w = (
        ((-0.5 * f + 1.0) * f - 0.5) * f,
        (1.5 * f - 2.5) * f * f + 1.0,
        ((-1.5 * f + 2.0) * f + 0.5) * f,
        (0.5 * f - 0.5) * f * f,
    )
    n = y.shape[0]
    idx = np.arange(n)
    out = np.zeros_like(y, dtype=np.float64)
    for j, wj in zip(range(-1, 3), w, strict=True):
        k = np.clip(idx + m + j, 0, n - 1)
        out += wj * y[k]
    return out


class MeasurementSkew(Candidate):
    name = "measurement_skew"
    magnitude = ("tau",)
    nl_names = ("tau",)
    nl_units = ("s",)
    signature = "residual ≈ −τ·dP/dt on both channels (in quadrature with P and Q)"

    def starts(self, seg: Segment, ctx: Context) -> list[np.ndarray]:
        return [np.array([0.01]), np.array([-0.01])]

    def bounds(self, seg: Segment, ctx: Context):
        return np.array([-TAU_MAX_S]), np.array([TAU_MAX_S])

    def predict(self, seg: Segment, ctx: Context, d: np.ndarray, z: np.ndarray) -> Prediction | None:
        base = super().predict(seg, ctx, d, z)
        if base is None:
            return None
        tau = float(z[0])
        kp = base.xp.shape[1]
        stacked = np.column_stack([base.mp, base.mq, base.xp, base.xq])
        s = shift(seg.t, stacked, tau)
        return Prediction(s[:, 0], s[:, 1], s[:, 2:2 + kp], s[:, 2 + kp:])


#: The library entry (registered by module name in :mod:`aslm_core.diagnosis.candidates`).
CANDIDATE = MeasurementSkew()
