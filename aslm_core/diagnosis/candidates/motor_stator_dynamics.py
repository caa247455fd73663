"""``motor_stator_dynamics``: the stator flux transients of a fifth-order motor, missing from eq. 4–5.

Notes
-----
The fifth-order motor keeps the stator flux ψ as a state: V = Rs·I + (1/ω0)·dψ/dt + jψ (synchronous frame,
complex phasors V = Vd + jVq [pu]); the third-order model sets dψ/dt = 0.  Written as
V − (1/ω0)·dψ/dt = Rs·I + jψ, the fifth-order motor is the third-order one driven by the effective voltage
V_eff = V − (1/ω0)·dψ/dt.  To first order in 1/ω0 (ψ ≈ −jV, Rs ≪ X'), with V = |V|·e^{jθ}::

    V_eff = V + j·(dV/dt)/ω0,   i.e.  |V_eff| = |V|·(1 − (dθ/dt)/ω0),   θ_eff = θ + (d ln|V|/dt)/ω0

The measured power is V·I*, not V_eff·I*.  In the transformed model (§II.B.2) the current splits into the
rotor-flux part −jF (eq. 4–5, driven here by V_eff, its power taken with the true V) and V/(jX'), which
the identifier books as static Qz; the latter's power at V_eff differs from its static value by::

    ΔP = (1/X')·|V|·(d|V|/dt)/ω0,     ΔQ = −(1/X')·|V|²·(dθ/dt)/ω0 = −(1/X')·|V|²·Δf/f0

One extra parameter, 1/X' [1/pu] (the motor's transient susceptance on the system base, > a/b), shared by
P and Q and so fitted in the upper stage with D.  dθ/dt = 2π·Δf and d|V|/dt come from the segment
(low-passed at 5 Hz).

Signature: a Q residual coherent with Δf and a P residual coherent with dV/dt, in a ratio fixed by the
motor; the Q part alone looks like ``frequency_dependence``.  The effect scales with 1/(ω0·X'): small,
detectable mainly at the higher SNR levels.
"""

from __future__ import annotations

import math

import numpy as np

from aslm_core import motor
from aslm_core.diagnosis.candidates.base import Candidate, Context, Prediction, static_part
from aslm_core.diagnosis.segment import Segment


class MotorStatorDynamics(Candidate):
    name = "motor_stator_dynamics"
    motor_form = True
    magnitude = ("inv_Xp",)
    nl_names = ("inv_Xp",)
    nl_units = ("1/pu",)
    signature = "Q residual ∝ Δf and P residual ∝ dV/dt in the ratio a fifth-order motor fixes (one 1/X')"
    _cache: dict = {}

    def starts(self, seg: Segment, ctx: Context) -> list[np.ndarray]:
        return [np.array([2.0 * ctx.d0[0] / ctx.d0[1]])]

    def bounds(self, seg: Segment, ctx: Context):
        return np.array([0.0]), np.array([1e3])

    def _inputs(self, seg: Segment):
        key = id(seg)
        hit = self._cache.get("key")
        if hit is not None and hit[0] == key and hit[1] is seg:
            return hit[2]
        w0 = seg.omega0
        veff = seg.V * (1.0 - 2.0 * math.pi * seg.dfreq / w0)
        theff = seg.theta + seg.dvdt / (seg.V * w0)
        inputs = motor.dq_inputs(veff, theff, motor.substeps(seg.dt))
        self._cache["key"] = (key, seg, inputs)
        return inputs

    def motor_power(self, seg: Segment, d: np.ndarray, z: np.ndarray):
        vd_e, vq_e, vdm_e, vqm_e = self._inputs(seg)
        d = np.ascontiguousarray(d, dtype=np.float64)
        if d[0] * (vd_e[0] ** 2 + vq_e[0] ** 2) <= 2.0 * d[1] * d[3] or d[1] <= 0 or d[2] <= 0:
            return None
        n = seg.n
        p, q, x = np.empty(n), np.empty(n), np.empty((n, 3))
        dummy = np.empty((1, 4))
        ok = motor.simulate_kernel(vd_e, vq_e, vdm_e, vqm_e, d, seg.dt, seg.omega0, True, False, p, q, dummy, dummy,
                                   x, True, 0, p, q, dummy)
        if not ok:
            return None
        fd, fq = x[:, 0], x[:, 1]
        return fd * seg.vq - fq * seg.vd, -seg.vd * fd - seg.vq * fq  # power at the true voltage

    def predict(self, seg: Segment, ctx: Context, d: np.ndarray, z: np.ndarray) -> Prediction | None:
        m = self.motor_power(seg, d, z)
        if m is None:
            return None
        fp, fq, sx = static_part(seg, ctx)
        c = float(z[0])
        dp = c * seg.V * seg.dvdt / seg.omega0
        dq = -c * seg.V**2 * (2.0 * math.pi * seg.dfreq) / seg.omega0
        return Prediction(m[0] + fp + dp, m[1] + fq + dq, sx, sx)

    def describe(self, params: dict[str, float], seg: Segment, ctx: Context) -> dict[str, float]:
        c = params.get("inv_Xp", 0.0)
        return {"Xp": 1.0 / c} if c > 0 else {}


#: The library entry (registered by module name in :mod:`aslm_core.diagnosis.candidates`).
CANDIDATE = MotorStatorDynamics()
