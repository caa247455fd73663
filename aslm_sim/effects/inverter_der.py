"""A DER/inverter load: Q–V droop and a P–V response through a first-order voltage transducer lag T.

The lag (T ~ U[0.3, 2] s) is integrated by RK4 at 1 ms on the spline-interpolated voltage magnitude.
Magnitude: the droop Kq/P0 [pu/pu]; Kp is up to 0.3 of it, either sign.  Load convention (P, Q consumed): a
Q–V droop (volt-var) injects Q when V drops and absorbs it when V rises, so the consumed Q rises with V,
Kq > 0.  Until stop 31 this effect had the opposite sign (Q injected as V rises), which no droop does.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from aslm_sim.cases import SyntheticCase
from aslm_sim.effects.base import Effect, EffectOutput
from aslm_sim.motors import fine_inputs


@nb.njit(cache=True)
def _lag(vf, stride, h, T, n):  # pragma: no cover - numba
    """First-order lag dVf/dt = (V − Vf)/T by RK4 on the fine half-step grid, sampled at the samples."""
    out = np.empty(n)
    x = vf[0]
    for i in range(n):
        out[i] = x
        if i == n - 1:
            break
        for m in range(stride):
            j = 2 * (i * stride + m)
            k1 = (vf[j] - x) / T
            k2 = (vf[j + 1] - (x + 0.5 * h * k1)) / T
            k3 = (vf[j + 1] - (x + 0.5 * h * k2)) / T
            k4 = (vf[j + 2] - (x + h * k3)) / T
            x += h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return out


def generate(case: SyntheticCase, magnitude: float, rng: np.random.Generator) -> EffectOutput:
    """ΔP, ΔQ [pu] and {T [s], Kp, Kq [pu/pu]} (see :class:`~aslm_sim.effects.base.Effect`)."""
    w = case.clean
    p0 = float(np.mean(w.P))
    T = rng.uniform(0.3, 2.0)
    vdf, _, stride, h = fine_inputs(w.t, w.V, np.zeros_like(w.V))
    vf = _lag(vdf, stride, h, T, w.V.size)
    kq = magnitude * p0  # Q–V droop [pu/pu], consumed: Q_der = Kq·(Vf − V0)
    kp = 0.3 * magnitude * p0 * rng.uniform(-1.0, 1.0)
    dv = vf - vf[0]
    return -kp * dv, kq * dv, {"T": T, "Kp": -kp, "Kq": kq}


EFFECT = Effect(name="inverter_der", generate=generate, magnitude=(1.0, 4.0), channels="Q", in_library=True,
                label="DER", main_parameter="T")
