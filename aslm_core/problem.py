"""One window's identification problem (paper §III–V): the data, the static regressors' projection and
the simulation with sensitivities that the upper stage descends on.

Its own module so that the estimators built on it (:mod:`aslm_core.identify`, :mod:`aslm_core.input_weighting`)
import it without importing each other.
"""

from __future__ import annotations

import math

import numpy as np

from aslm_core import motor, optimize, static
from aslm_core.params import dynamic_bounds
from aslm_core.preprocess import Prepared
from aslm_core.result import IdentifyConfig

# Keep a·Vmin² − 2b·Tm at least this fraction of a·Vmin²: strictly inside the equilibrium set.
EQUILIBRIUM_MARGIN = 1e-3
# Longest RK4 step of the coarse grid random starts first descend on [s]; RK4 at 40 ms stays stable
# over the box almost everywhere (where it does not, that start descends on the full grid).
COARSE_MAX_STEP_S = 0.04


class Problem:
    """One window's identification problem: measured data, projection basis and work buffers.

    Parameters
    ----------
    prep : Prepared
        Conditioned window.
    f0 : float
        Nominal frequency [Hz].
    config : IdentifyConfig
    """

    def __init__(self, prep: Prepared, f0: float, config: IdentifyConfig) -> None:
        self.prep = prep
        self.config = config
        self.omega0 = motor.omega0_of(f0)
        self.dt = prep.dt
        self.rk4 = config.integrator == "rk4"
        self.substeps = motor.substeps(prep.dt) if self.rk4 else 1
        self.vd, self.vq, self.vdm, self.vqm = motor.dq_inputs(prep.V, prep.theta, self.substeps)
        n = prep.V.shape[0]
        self._set_samples(prep.V, prep.P, prep.Q, min(int(math.ceil(config.skip_s / prep.dt - 1e-9)), n - 10))
        self.v_min = float(prep.V.min())
        self.p_mean = float(prep.P.mean())
        self.lower, self.upper = dynamic_bounds(self.p_mean)
        self._coarse: Problem | None | bool = False

    def _set_samples(self, V: np.ndarray, P: np.ndarray, Q: np.ndarray, k0: int) -> None:
        """Regression samples from k0 on, their projection basis, and the simulation buffers."""
        n = V.shape[0]
        self.k0 = k0
        self.l = n - k0
        phi = static.regressors(V[k0:], self.config.static)
        self.basis, self.r_factor = optimize.thin_qr(np.ascontiguousarray(phi))
        # Non-constant orthonormal regressors (the constant column comes first), padded to two.
        self.basis2 = np.zeros((self.basis.shape[0], 2))
        self.basis2[:, : self.basis.shape[1] - 1] = self.basis[:, 1:]
        self.p_meas = np.ascontiguousarray(P[k0:])
        self.q_meas = np.ascontiguousarray(Q[k0:])
        self._p = np.empty(n)
        self._q = np.empty(n)
        self._dp = np.empty((n, 4))
        self._dq = np.empty((n, 4))
        self._x = np.empty((n, 3))
        self.evaluations = 0

    def coarse(self) -> Problem | None:
        """The same problem on every m-th sample (m even, m·dt ≤ COARSE_MAX_STEP_S), or None.

        RK4 over m samples takes its half-step inputs from the sample m/2 in between, so the coarse
        model is the same ODE driven by measured values, at 1/m of the cost.  Only for RK4.
        """
        if self._coarse is not False:
            return self._coarse
        m = 2 * int(COARSE_MAX_STEP_S / (2 * self.dt) + 1e-9)
        self._coarse = None
        if not self.rk4 or m < 2 or self.prep.V.size < 20 * m:
            return None
        c = object.__new__(Problem)
        c.__dict__.update(self.__dict__)
        c.vd, c.vq = np.ascontiguousarray(self.vd[::m]), np.ascontiguousarray(self.vq[::m])
        n = c.vd.size
        c.vdm = np.ascontiguousarray(self.vd[m // 2::m][: n - 1])
        c.vqm = np.ascontiguousarray(self.vq[m // 2::m][: n - 1])
        if c.vdm.size < n - 1:
            return None
        c.dt = self.dt * m
        p = self.prep
        c._set_samples(p.V[::m], p.P[::m], p.Q[::m], int(math.ceil(self.k0 / m)))
        c._coarse = None
        self._coarse = c
        return c

    def feasible(self, d: np.ndarray) -> bool:
        """Inside the box and strictly inside the equilibrium set."""
        return bool(optimize.feasible(np.asarray(d, dtype=np.float64), self.lower, self.upper, self.v_min,
                                      EQUILIBRIUM_MARGIN))

    def residuals(self, d: np.ndarray, jacobian: bool = True):
        """Projected residuals of P and Q over the regression samples, and their D-Jacobians.

        Returns None when the simulation fails (no equilibrium, divergence).
        """
        self.evaluations += 1
        l = self.l
        rp, rq, yp, yq = np.empty(l), np.empty(l), np.empty(l), np.empty(l)
        jp, jq = np.empty((l, 4)), np.empty((l, 4))
        ok = optimize.residuals_into(
            np.asarray(d, dtype=np.float64), self.vd, self.vq, self.vdm, self.vqm, self.dt, self.omega0,
            self.rk4, jacobian, self.basis, self.p_meas, self.q_meas, self.k0,
            self._p, self._q, self._dp, self._dq, self._x, yp, yq, rp, rq, jp, jq,
        )
        if not ok:
            return None
        return (rp, rq, jp, jq) if jacobian else (rp, rq, None, None)

    def cost(self, rp: np.ndarray, rq: np.ndarray) -> float:
        """The configured objective of projected residuals."""
        np_, nq_ = float(np.sqrt(rp @ rp)), float(np.sqrt(rq @ rq))
        obj = self.config.objective
        if obj == "paper":
            return (np_ + nq_) / self.l
        if obj == "ml":
            return 0.5 * self.l * (math.log(np_ * np_ + 1e-300) + math.log(nq_ * nq_ + 1e-300))
        return 0.5 * (np_ * np_ + nq_ * nq_)

    def random_start(self, rng: np.random.Generator) -> np.ndarray:
        """A point drawn uniformly in the box of a, b, H2 and then Tm inside the equilibrium set."""
        lo, hi = self.lower, self.upper
        while True:
            d = lo + (hi - lo) * rng.random(4)
            tm_max = min(hi[3], (1.0 - 2 * EQUILIBRIUM_MARGIN) * d[0] * self.v_min**2 / (2.0 * d[1]))
            d[3] = lo[3] + (tm_max - lo[3]) * rng.random()
            if self.feasible(d):
                return d

    def into_feasible(self, d: np.ndarray) -> np.ndarray:
        """Clip a (warm-start) point into the box and the equilibrium set."""
        d = np.minimum(np.maximum(np.asarray(d, dtype=np.float64), self.lower), self.upper)
        tm_max = (1.0 - 2 * EQUILIBRIUM_MARGIN) * d[0] * self.v_min**2 / (2.0 * d[1])
        d[3] = min(d[3], tm_max)
        return d
