"""``measurement_skew``: a time offset τ between the voltage channels and the power channels.

Notes
-----
The recorded powers lag the recorded voltage by τ [s] (e.g. P, Q from another device, or a mis-aligned
time stamp)::

    P_meas(t) = P_model(t − τ),   Q_meas(t) = Q_model(t − τ)

The model output (motor power and every lower-stage regressor) is evaluated at t − τ by cubic-spline
interpolation on the sample grid — the *model* is shifted, never the measurement, so the noise is not
smoothed and no candidate gains from interpolating noise.  One nonlinear parameter τ [s], bounded to
±0.1 s, fitted in the upper stage with D.

Signature: residual ≈ −τ·dP/dt, i.e. in quadrature with the power's own fluctuation; coherent with
dV/dt and Δf on both channels alike.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from aslm_core.diagnosis.candidates.base import Candidate, Context, Prediction
from aslm_core.diagnosis.segment import Segment

TAU_MAX_S = 0.1


def shift(t: np.ndarray, y: np.ndarray, tau: float) -> np.ndarray:
    """y evaluated at t − τ by a cubic spline along axis 0 (constant extrapolation at the ends)."""
    if tau == 0.0:
        return y
    ts = np.clip(t - tau, t[0], t[-1])
    return CubicSpline(t, y, axis=0)(ts)


class MeasurementSkew(Candidate):
    name = "measurement_skew"
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
