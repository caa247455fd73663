"""Third-order motor variants the paper's transformed model leaves out: a stator resistance and a second
rotor circuit, in one RK4 kernel (used by the ``stator_resistance`` and ``double_cage_rotor`` candidates).

Complex phasors in the paper's frame (V = Vd + jVq, F = Fd + jFq = E'/X'), with the motor's power part
S_F = P_F + jQ_F = −j·V·F* (eq. 5: P_F = Fd·Vq − Fq·Vd, Q_F = −Vd·Fd − Vq·Fq).  Two rotor modes share
the slip s::

    dF1/dt = −(b1 − c + c·κ)·F1 + a1·κ·V − j·s·ω0·F1,     κ = 1/(1 − j·ρ)
    dF2/dt = −b2·F2 + a2·V − j·s·ω0·F2
    H2·ds/dt = Tm − Te,     Te = Re(κ*·(S_F* − j·X'·|F|²)),     F = F1 + F2
    P + jQ = κ*·S_F + (κ* − 1)·j·|V|²/X'

* ρ = Rs/X', c = a1·X' = b1 − 1/T0' (stator resistance, see
  :mod:`aslm_core.diagnosis.candidates.stator_resistance`); ρ = 0 is the paper's motor, whose static
  part j|V|²/X' the identifier books into Qz — the last term is what Rs adds to it.
* a2, b2: a second rotor mode (see :mod:`aslm_core.diagnosis.candidates.double_cage_rotor`); a2 = 0 is
  the paper's motor.

The initial state is the low-slip equilibrium at the first sample turning with the voltage phasor (as
:mod:`aslm_core.motor`): F_i = A_i(c)·V with c = s·ω0 + dθ/dt, c the smallest root of Te(c) = Tm.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from aslm_core.diagnosis.segment import Segment
from aslm_core.motor import _start_angular_speed, substep_inputs, substep_layout

#: Parameter vector of the kernel: a1, b1, H2, Tm, a2, b2, ρ, c, X' (see the module docstring).
N_PARAMS = 9


@nb.njit(cache=True, inline="always")
def _rates(f1, f2, s, v, p, w0):  # pragma: no cover - numba
    kap = 1.0 / (1.0 - 1j * p[6])
    ws = 1j * w0 * s
    d1 = -(p[1] - p[7] + p[7] * kap) * f1 + p[0] * kap * v - ws * f1
    d2 = -p[5] * f2 + p[4] * v - ws * f2
    f = f1 + f2
    sf = -1j * v * np.conj(f)
    te = (np.conj(kap) * (np.conj(sf) - 1j * p[8] * (f.real**2 + f.imag**2))).real
    return d1, d2, (p[3] - te) / p[2]


@nb.njit(cache=True)
def _torque_at(c, v0, p):  # pragma: no cover - numba
    """Steady-state F1, F2 and Te at the rotor-frame frequency c = s·ω0 + dθ/dt [rad/s]."""
    kap = 1.0 / (1.0 - 1j * p[6])
    f1 = p[0] * kap * v0 / (p[1] - p[7] + p[7] * kap + 1j * c)
    f2 = p[4] * v0 / (p[5] + 1j * c)
    f = f1 + f2
    sf = -1j * v0 * np.conj(f)
    te = (np.conj(kap) * (np.conj(sf) - 1j * p[8] * (f.real**2 + f.imag**2))).real
    return f1, f2, te


@nb.njit(cache=True)
def simulate_kernel(vd, vq, vdm, vqm, p, dt, w0, p_out, q_out):  # pragma: no cover - numba
    """P, Q of the variant (module docstring) from the low-slip equilibrium; False if none or diverged."""
    n = vd.shape[0]
    v0 = vd[0] + 1j * vq[0]
    # The low root: scan c upwards (log grid to 50× the fastest rotor rate), then bisect the crossing.
    cmax = 50.0 * max(p[1], p[5], 1e-3)
    lo = 0.0
    hi = -1.0
    _, _, te_prev = _torque_at(0.0, v0, p)
    if te_prev >= p[3]:
        return False
    for i in range(200):
        c = cmax * 10.0 ** (-6.0 + 6.0 * i / 199.0)
        _, _, te = _torque_at(c, v0, p)
        if te >= p[3]:
            hi = c
            break
        lo = c
    if hi < 0.0:
        return False
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        _, _, te = _torque_at(mid, v0, p)
        if te >= p[3]:
            hi = mid
        else:
            lo = mid
    c = 0.5 * (lo + hi)
    f1, f2, _ = _torque_at(c, v0, p)
    s = (c - _start_angular_speed(vd, vq, dt)) / w0
    kap_c = np.conj(1.0 / (1.0 - 1j * p[6]))
    per, m = substep_layout(n, vdm.shape[0])
    h = dt / m
    for k in range(n):
        v = vd[k] + 1j * vq[k]
        out = kap_c * (-1j * v * np.conj(f1 + f2))
        if p[6] != 0.0:
            out += (kap_c - 1.0) * 1j * (v.real**2 + v.imag**2) / p[8]
        p_out[k] = out.real
        q_out[k] = out.imag
        if k == n - 1:
            break
        for j in range(m):
            ud, uq, md, mq, nd, nq = substep_inputs(vd, vq, vdm, vqm, k, j, per, m)
            vs = ud + 1j * uq
            vm = md + 1j * mq
            vn = nd + 1j * nq
            k1 = _rates(f1, f2, s, vs, p, w0)
            k2 = _rates(f1 + 0.5 * h * k1[0], f2 + 0.5 * h * k1[1], s + 0.5 * h * k1[2], vm, p, w0)
            k3 = _rates(f1 + 0.5 * h * k2[0], f2 + 0.5 * h * k2[1], s + 0.5 * h * k2[2], vm, p, w0)
            k4 = _rates(f1 + h * k3[0], f2 + h * k3[1], s + h * k3[2], vn, p, w0)
            f1 += h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
            f2 += h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
            s += h / 6.0 * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
        if not (math.isfinite(s) and abs(f1) < 1e12 and abs(f2) < 1e12):
            return False
    return True


def variant_power(seg: Segment, d: np.ndarray, *, a2: float = 0.0, b2: float = 1.0, rs: float = 0.0,
                  xp: float = 1.0) -> tuple[np.ndarray, np.ndarray] | None:
    """Motor P, Q [pu] of a variant driven by the segment's voltage; None without equilibrium or on divergence.

    Parameters
    ----------
    seg : Segment
    d : ndarray
        D = [a, b, H2, Tm] of the first rotor mode [1/s, 1/s, s, pu].
    a2, b2 : float
        Second rotor mode [1/s, 1/s] (a2 = 0: none).
    rs : float
        Stator resistance [pu, system base] (0: none).
    xp : float
        Transient reactance X' [pu, system base], needed when rs > 0; 0 < X' < b/a.
    """
    a, b, h2, tm = (float(x) for x in d)
    if a <= 0 or b <= 0 or h2 <= 0 or tm <= 0:
        return None
    c = a * xp if rs != 0.0 else 0.0
    if rs != 0.0 and not 0.0 < c < b:
        return None
    p = np.array([a, b, h2, tm, a2, b2, rs / xp if rs != 0.0 else 0.0, c, xp])
    n = seg.n
    po, qo = np.empty(n), np.empty(n)
    if not simulate_kernel(seg.vd, seg.vq, seg.vdm, seg.vqm, p, seg.dt, seg.omega0, po, qo):
        return None
    return po, qo
