"""The true composite load of a synthetic bus: ZIP + third-order induction motor, drawn at random.

The motor is held in its ORIGINAL form (paper eq. 1–3: X, X', Td0, H2, Tm) besides the transformed
D = [a, b, H2, Tm] the identifier sees (eq. 4–5).  Units: powers in per unit on the 100 MVA system base,
voltages in pu, times in s.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numba as nb
import numpy as np

__all__ = ["SYSTEM_BASE_MVA", "LoadTruth", "low_slip_root", "random_truth"]

#: System base [MVA].
SYSTEM_BASE_MVA: float = 100.0

# Truth sampling ranges: the identification box of params.py with a margin.
_A_RANGE = (15.0, 75.0)
_B_RANGE = (4.0, 28.0)
_H2_RANGE = (0.6, 2.8)
_TM_FRACTION = (0.3, 0.55)  # Tm / breakdown torque a·V²/(2b) at V = 1: < 0.64 keeps one at 0.8 pu
_MOTOR_SHARE = (0.3, 0.7)  # motor share of the total P at V = 1
_XRATIO = (4.0, 12.0)  # X/X' of the motor
_POWER_FACTOR = (0.9, 0.98)
# Sag every truth must ride through (motor alone, rigid voltage, f0 = 60 Hz as the harsher case).
_CHECK_SAG_V = 0.75
_CHECK_SAG_S = 0.15


@dataclass(frozen=True)
class LoadTruth:
    """True composite load of one synthetic bus.

    Attributes
    ----------
    a, b : float
        Transformed motor parameters [1/s] (paper eq. 4): a = (X/X' − 1)/(Td0·X'), b = X/(Td0·X').
    H2 : float
        Inertia constant 2H of the slip equation [s] (on the system base).
    Tm : float
        Mechanical torque [pu on the system base]; equals the motor P in steady state.
    X, Xp, Td0 : float
        Original motor parameters (eq. 1): open-circuit reactance X [pu], transient reactance X' [pu],
        rotor open-circuit time constant Td0 [s].
    Pz, Pi, Pp, Qz, Qi, Qp : float
        True ZIP coefficients of the static part (eq. 6) [pu]; P = Pz·V² + Pi·V + Pp.

    Notes
    -----
    a/b = 1/X' − 1/X and Td0 = (X/X')/b.  The identifier sees the motor through eq. 4–5, which moves
    V²/X' from the motor's Q into the static part (§II.B.2): see :attr:`static_identifiable`.
    """

    a: float
    b: float
    H2: float
    Tm: float
    X: float
    Xp: float
    Td0: float
    Pz: float
    Pi: float
    Pp: float
    Qz: float
    Qi: float
    Qp: float

    @property
    def d(self) -> np.ndarray:
        """D = [a, b, H2, Tm] as identified (paper §V.A)."""
        return np.array([self.a, self.b, self.H2, self.Tm])

    @property
    def dynamic(self) -> dict[str, float]:
        """Motor parameters {a, b, H2, Tm}."""
        return {"a": self.a, "b": self.b, "H2": self.H2, "Tm": self.Tm}

    @property
    def static(self) -> dict[str, float]:
        """True ZIP coefficients {Pz, Pi, Pp, Qz, Qi, Qp} [pu]."""
        return {"Pz": self.Pz, "Pi": self.Pi, "Pp": self.Pp, "Qz": self.Qz, "Qi": self.Qi, "Qp": self.Qp}

    @property
    def static_identifiable(self) -> dict[str, float]:
        """ZIP coefficients an identifier using eq. 4–5 should find: Qz + 1/X' [pu]."""
        st = self.static
        st["Qz"] = self.Qz + 1.0 / self.Xp
        return st

    def slip0(self, V: float = 1.0, f0: float = 50.0) -> float:
        """Steady-state (low) slip at voltage V [pu] and nominal frequency f0 [Hz]."""
        x = low_slip_root(self.a, self.b, self.Tm, V)
        return float(x / (2.0 * math.pi * f0))

    def power(self, V: float = 1.0) -> tuple[float, float]:
        """Steady-state total P, Q [pu] at voltage V [pu] (motor eq. 3 plus ZIP)."""
        x = low_slip_root(self.a, self.b, self.Tm, V)
        qm = V * V / self.Xp - self.a * self.b * V * V / (self.b * self.b + x * x)
        p = self.Pz * V * V + self.Pi * V + self.Pp + self.Tm
        q = self.Qz * V * V + self.Qi * V + self.Qp + qm
        return float(p), float(q)

    def scaled_motor(self, factor: float) -> LoadTruth:
        """The same bus with ``factor`` times as many of its motors in parallel; the static part unchanged.

        On the system base a, H2 and Tm scale with the motor count, b = X/(Td0·X') does not (X and X'
        divide by it, Td0 stays), so Tm/(a/2b), the loading of each motor, and its ride-through are the
        same.  E.g. 1.2: a 20 % step in motor share (the evening motors switching on).

        Parameters
        ----------
        factor : float
            Motor count relative to this truth's [-], > 0.
        """
        return replace(self, a=self.a * factor, H2=self.H2 * factor, Tm=self.Tm * factor, X=self.X / factor,
                       Xp=self.Xp / factor)

    def to_dict(self) -> dict:
        """Plain dict (JSON-able): physical parameters plus the dynamic/static groupings."""
        out = {k: float(v) for k, v in asdict(self).items()}
        out["dynamic"] = self.dynamic
        out["static"] = self.static
        out["static_identifiable"] = self.static_identifiable
        return out


def low_slip_root(a: float, b: float, tm: float, v: float) -> float:
    """Low-slip equilibrium x = s·ω0 [rad/s] of eq. 4 at |V| = v, where Te(x) = a·V²·x/(b² + x²) = Tm.

    Parameters
    ----------
    a, b : float
        Transformed motor parameters [1/s] (eq. 4).
    tm : float
        Mechanical torque [pu].
    v : float
        Voltage magnitude [pu].

    Returns
    -------
    float
        x = s·ω0 [rad/s]; raises ValueError when there is no equilibrium (a·V² ≤ 2b·Tm).
    """
    av2 = a * v * v
    disc = av2 * av2 - 4.0 * tm * tm * b * b
    if disc < 0.0:
        raise ValueError("no motor equilibrium: a·V² <= 2b·Tm")
    return 2.0 * tm * b * b / (av2 + math.sqrt(disc))  # stable form of (aV² − √disc)/(2Tm)


@nb.njit(cache=True, error_model="numpy")
def _motor_sag_rhs(a, b, h2, tm, w0, v, fd, fq, s):  # pragma: no cover - numba
    """Eq. 4 on a rigid bus V = v∠0 (Vd = v, Vq = 0): Te = −v·Fq."""
    return -b * fd + s * w0 * fq + a * v, -b * fq - s * w0 * fd, (tm + v * fq) / h2


@nb.njit(cache=True, error_model="numpy")
def _motor_sag_response(a, b, h2, tm, w0, v_sag, t_sag, t_end, h):  # pragma: no cover - numba
    """Motor alone (eq. 4) on a rigid bus: 1 pu, sag to v_sag from 0.1 s for t_sag, back to 1 pu.

    Returns (max slip, slip at t_end, steady slip).
    """
    disc = a * a - 4.0 * tm * tm * b * b
    x0 = 2.0 * tm * b * b / (a + math.sqrt(disc))
    fd = a * b / (b * b + x0 * x0)
    fq = -a * x0 / (b * b + x0 * x0)
    s = x0 / w0
    s0 = s
    smax = s
    n = int(t_end / h + 0.5)
    i_on = int(0.1 / h + 0.5)
    i_off = i_on + int(t_sag / h + 0.5)
    for i in range(n):
        v = v_sag if (i >= i_on and i < i_off) else 1.0  # constant over the step
        k1d, k1q, k1s = _motor_sag_rhs(a, b, h2, tm, w0, v, fd, fq, s)
        k2d, k2q, k2s = _motor_sag_rhs(a, b, h2, tm, w0, v, fd + 0.5 * h * k1d, fq + 0.5 * h * k1q,
                                       s + 0.5 * h * k1s)
        k3d, k3q, k3s = _motor_sag_rhs(a, b, h2, tm, w0, v, fd + 0.5 * h * k2d, fq + 0.5 * h * k2q,
                                       s + 0.5 * h * k2s)
        k4d, k4q, k4s = _motor_sag_rhs(a, b, h2, tm, w0, v, fd + h * k3d, fq + h * k3q, s + h * k3s)
        fd += h / 6.0 * (k1d + 2.0 * k2d + 2.0 * k3d + k4d)
        fq += h / 6.0 * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)
        s += h / 6.0 * (k1s + 2.0 * k2s + 2.0 * k3s + k4s)
        smax = max(smax, s)
        if s > 1.0:
            break
    return smax, s, s0


def random_truth(rng: np.random.Generator) -> LoadTruth:
    """Draw a stable composite load inside the identification box (with a margin).

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of randomness (the result is a deterministic function of its state).

    Returns
    -------
    LoadTruth

    Notes
    -----
    a ~ U[15, 75], b ~ U[4, 28], H2 ~ U[0.6, 2.8] [s]; Tm = k·a/(2b) with k ~ U[0.3, 0.55], i.e. a
    fraction of the breakdown torque a·V²/(2b) at 1 pu that still leaves an equilibrium at 0.8 pu
    (k < 0.64).  A draw is rejected unless the motor, alone on a rigid bus, rides through a sag to
    0.75 pu for 150 ms at 60 Hz (slip back to its steady value, max slip < 0.15).  This guard
    against a stalling truth practically never fires with these ranges (the steep torque–slip
    curve below breakdown recovers the motor: max slip ~0.04), so a, b, H2, k are in effect
    independent uniforms.  X/X' ~ U[4, 12] then gives X = (X/X' − 1)·b/a, X' = X/(X/X'), Td0 = (X/X')/b.
    The static P at 1 pu makes the motor share of P ~ U[0.3, 0.7]; the total Q at 1 pu gives a
    power factor ~ U[0.9, 0.98] (lagging), so the static Q is often capacitive (negative).
    ZIP shares are uniform on the simplex.  Because Tm ≤ 0.55·a/(2b) [pu] (physics of eq. 4:
    the breakdown torque is a·V²/(2b)), Tm spans ~0.1–3.6 pu and the total P at 1 pu ~0.2–10 pu
    (median ~1.2 pu); the paper's printed examples (e.g. Tm = 7.33 with a/b = 2.25) are not on
    this scale and would violate a·V² > 2b·Tm.
    """
    w0_check = 2.0 * math.pi * 60.0
    for _ in range(1000):
        a = rng.uniform(*_A_RANGE)
        b = rng.uniform(*_B_RANGE)
        h2 = rng.uniform(*_H2_RANGE)
        k = rng.uniform(*_TM_FRACTION)
        tm = k * a / (2.0 * b)
        smax, s_end, s0 = _motor_sag_response(a, b, h2, tm, w0_check, _CHECK_SAG_V, _CHECK_SAG_S, 2.5, 1e-3)
        if smax < 0.15 and abs(s_end - s0) < 0.05 * s0 + 1e-4:
            break
    else:  # pragma: no cover - practically unreachable
        raise RuntimeError("random_truth: no stable draw in 1000 tries")
    r = rng.uniform(*_XRATIO)
    x = (r - 1.0) * b / a
    xp = x / r
    td0 = r / b
    share = rng.uniform(*_MOTOR_SHARE)
    p_static = tm * (1.0 - share) / share
    zp = rng.dirichlet(np.ones(3))
    pf = rng.uniform(*_POWER_FACTOR)
    p_tot = p_static + tm
    x0 = low_slip_root(a, b, tm, 1.0)
    q_motor = 1.0 / xp - a * b / (b * b + x0 * x0)
    q_static = p_tot * math.tan(math.acos(pf)) - q_motor
    zq = rng.dirichlet(np.ones(3))
    return LoadTruth(
        a=float(a), b=float(b), H2=float(h2), Tm=float(tm), X=float(x), Xp=float(xp), Td0=float(td0),
        Pz=float(p_static * zp[0]), Pi=float(p_static * zp[1]), Pp=float(p_static * zp[2]),
        Qz=float(q_static * zq[0]), Qi=float(q_static * zq[1]), Qp=float(q_static * zq[2]),
    )


