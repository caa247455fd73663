"""``speed_dependent_torque``: mechanical load torque that varies with speed (fans, pumps, compressors).

Notes
-----
The slip equation of eq. 4 with a speed-dependent load torque::

    ds/dt = (Tm·((1 − s)/(1 − s0))^k − Te)/H2,     Te = Vq·Fd − Vd·Fq

normalised at the initial (steady-state) slip s0 so that Tm keeps its meaning (the torque, and the motor's
active power, at the operating point) and the equilibrium is that of the plain model.  k [-] is the
torque–speed exponent: 0 constant torque (the plain model), 1 linear, 2 fan/centrifugal pump.  Near the
operating point it adds a damping k·Tm/(1 − s0) to the slip dynamics, small beside the electrical torque's
slope a·V²·ω0/b², so k is only weakly identifiable from ambient data — reported with its uncertainty.
One nonlinear parameter fitted in the upper stage with D; the motor is integrated by RK4 as :mod:`aslm_core.motor`
integrates it (at the sample step, split into sub-steps below ~99 frames/s, the inputs inside a step from cubics).

Signature: the single-motor residual is coherent with V and dV/dt around the motor's electromechanical
(slip) mode; P and Q alike.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from aslm_core import motor
from aslm_core.diagnosis.candidates.base import Candidate, Context
from aslm_core.diagnosis.segment import Segment
from aslm_core.errors import NoEquilibriumError


@nb.njit(cache=True, inline="always")
def _rhs(fd, fq, s, vd, vq, a, b, h2, tm, s0, k, w0):  # pragma: no cover - numba
    ws = w0 * s
    torque = tm * ((1.0 - s) / (1.0 - s0)) ** k
    return -b * fd + ws * fq + a * vd, -b * fq - ws * fd + a * vq, (torque - (vq * fd - vd * fq)) / h2


@nb.njit(cache=True)
def simulate_k(vd, vq, vdm, vqm, a, b, h2, tm, k, w0, dt, fd, fq, s):  # pragma: no cover - numba
    """RK4 of eq. 4 with Tm(s) from the steady state (fd, fq, s), sub-stepped as :func:`motor.simulate_kernel`;
    returns P_im, Q_im (eq. 5)."""
    n = vd.shape[0]
    p = np.empty(n)
    q = np.empty(n)
    s0 = s
    per, m = motor.substep_layout(n, vdm.shape[0])
    h = dt / m
    for i in range(n):
        p[i] = fd * vq[i] - fq * vd[i]
        q[i] = -vd[i] * fd - vq[i] * fq
        if i == n - 1:
            break
        for j in range(m):
            ud, uq, md, mq, nd, nq = motor.substep_inputs(vd, vq, vdm, vqm, i, j, per, m)
            k1 = _rhs(fd, fq, s, ud, uq, a, b, h2, tm, s0, k, w0)
            k2 = _rhs(fd + 0.5 * h * k1[0], fq + 0.5 * h * k1[1], s + 0.5 * h * k1[2], md, mq, a, b, h2, tm, s0, k, w0)
            k3 = _rhs(fd + 0.5 * h * k2[0], fq + 0.5 * h * k2[1], s + 0.5 * h * k2[2], md, mq, a, b, h2, tm, s0, k, w0)
            k4 = _rhs(fd + h * k3[0], fq + h * k3[1], s + h * k3[2], nd, nq, a, b, h2, tm, s0, k, w0)
            fd += h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
            fq += h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
            s += h / 6.0 * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
        if not (np.isfinite(s) and abs(fd) < 1e12):
            p[:] = np.nan
            q[:] = np.nan
            break
    return p, q


class SpeedDependentTorque(Candidate):
    name = "speed_dependent_torque"
    motor_form = True
    magnitude = ("k",)
    nl_names = ("k",)
    nl_units = ("-",)
    signature = "single-motor residual around the slip mode (extra mechanical damping), P and Q alike"
    # The frequency term with its lag is a look-alike (see frequency_dependence.confusable): on ANDES FLoad data
    # with V/θ noise the lagged term fitted as well (score z 6.6 against 6.6) but its three parameters' penalty
    # left it out of the rivals, and the torque law was named.
    confusable = ("frequency_dependence",)

    def starts(self, seg: Segment, ctx: Context) -> list[np.ndarray]:
        return [np.array([1.0])]

    def bounds(self, seg: Segment, ctx: Context):
        return np.array([-2.0]), np.array([10.0])

    def motor_power(self, seg: Segment, d: np.ndarray, z: np.ndarray):
        try:
            x0 = motor.steady_state(float(np.hypot(seg.vd[0], seg.vq[0])), float(seg.theta[0]), d, seg.omega0)
        except NoEquilibriumError:
            return None
        if d[1] <= 0 or d[2] <= 0:
            return None
        p, q = simulate_k(seg.vd, seg.vq, seg.vdm, seg.vqm, float(d[0]), float(d[1]), float(d[2]), float(d[3]),
                          float(z[0]), seg.omega0, seg.dt, x0[0], x0[1], x0[2])
        if not np.isfinite(p[-1]):
            return None
        return p, q


#: The library entry (registered by module name in :mod:`aslm_core.diagnosis.candidates`).
CANDIDATE = SpeedDependentTorque()
