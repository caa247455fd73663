"""Tracking a bus's load model over time: a pool of windows since the last change, and a change detector.

Numpy only (no numba), so the service's main process can run it on the per-window results.

Every period gives an estimate D_t with standard errors s_t.  The tracked model is the information-weighted
mean of the pool, the last ``pool_windows`` estimates since the last change (per parameter, weights 1/s²),
with standard error (Σ 1/s²)^-½.  A new estimate's standardised innovation against the pool before it is
z_t = (D_t − D̂_pool)/√(s_t² + ŝ_pool²).  The detector declares a change when two consecutive windows
both stand more than h from the pool on the same parameter with the same sign: the first such window is
held out of the pool (a suspect), the second confirms it, and the pool restarts from the two.  Requiring
two windows keeps a single outlying window (a local optimum, a disturbance) from restarting the pool, and a
real step is still confirmed at the second period after it; a suspect that the next window does not confirm
joins the pool winsorised (its innovations clipped at ±h).  Under the null (independent Gaussian z) the
false-alarm probability per period is ≤ 4·2·P(Z1 > h, Z2 > h) (four parameters, two signs; the two
innovations correlate with ρ = 1/(n + 1) through the pool of n windows they share), so h follows from a
false-alarm rate per bus and day at period T: α = rate·T/86 400 = 8·P(Z1 > h, Z2 > h; ρ).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from statistics import NormalDist

import numpy as np

from aslm_core.params import DYNAMIC_NAMES

#: Four parameters, two signs: the union bound of the two-window test.
_CELLS = 2 * len(DYNAMIC_NAMES)


def _pair_tail(h: float, rho: float) -> float:
    """P(Z1 > h, Z2 > h) for standard normals with correlation rho (one-dimensional quadrature)."""
    nd = NormalDist()
    x = np.linspace(h, h + 8.0, 401)  # the integrand is below 1e-16 of its value at h beyond h + 8
    pdf = np.exp(-0.5 * x * x) / math.sqrt(2.0 * math.pi)
    cond = np.array([1.0 - nd.cdf((h - rho * xi) / math.sqrt(1.0 - rho * rho)) for xi in x])
    y = pdf * cond
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(x)))


@lru_cache(maxsize=256)
def threshold(false_alarms_per_day: float, period_s: float, pool_n: int = 0) -> float:
    """Threshold h on |z| for a false-alarm rate per bus and day at one estimate per period.

    Parameters
    ----------
    false_alarms_per_day : float
        Accepted false alarms per bus and day under a stationary load [1/day], > 0.
    period_s : float
        Identification period T [s].
    pool_n : int
        Windows in the pool both innovations are taken against: they share its error, so they correlate
        with ρ = 1/(n + 1) (equal standard errors); 0: independent.

    Returns
    -------
    float
        h [-] with 8·P(Z1 > h, Z2 > h; ρ) = rate·T/86 400 (see the module docstring).
    """
    alpha = min(false_alarms_per_day * period_s / 86400.0, 0.5)
    h = -NormalDist().inv_cdf(math.sqrt(alpha / _CELLS))
    rho = 1.0 / (pool_n + 1.0) if pool_n > 0 else 0.0
    if rho == 0.0:
        return float(h)
    lo, hi = h, h + 4.0
    for _ in range(30):  # bisection to 4·2^-30: the pair tail falls with h
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _CELLS * _pair_tail(mid, rho) > alpha else (lo, mid)
    return float(hi)


@dataclass(frozen=True)
class TrackerConfig:
    """Options of :class:`Tracker`.

    Attributes
    ----------
    pool_windows : int
        Longest pool k [windows]: the tracked model combines at most the last k estimates since the last
        change.
    false_alarms_per_day : float
        Detector false-alarm rate per bus and day under a stationary load [1/day].
    period_s : float
        Period between estimates T [s] (sets the threshold with the rate).
    se_scale : float
        Factor on the per-window standard errors in the innovations [-]: the windows' spread beyond
        what their standard errors say (set on development seeds, docs/tracking.md).
    pool_scatter : bool
        Scale each parameter's innovations by √ of the pool's own reduced χ² (its estimates' scatter about their mean
        over their standard errors, at least 1) once the pool holds :data:`MIN_SCATTER_POOL` estimates: a bus whose
        standard errors are too small for its estimates' spread (Tm under PMU noise on V and θ) stops raising
        alarms on it, one whose are right is left nearly as it is (docs/tracking.md, "False alarms").
    """

    pool_windows: int = 16
    false_alarms_per_day: float = 0.05
    period_s: float = 900.0
    se_scale: float = 1.0
    pool_scatter: bool = True

    @property
    def threshold(self) -> float:
        """Detector threshold h on |z| against a full pool [-]."""
        return threshold(self.false_alarms_per_day, self.period_s, self.pool_windows)


@dataclass
class Estimate:
    """One window's estimate: time t [s since epoch or any origin], D and its standard errors."""

    t: float
    d: list[float]
    se: list[float]


@dataclass
class ChangeEvent:
    """A detected change.

    Attributes
    ----------
    t : float
        Time of the first window after the change (the suspect) [s].
    detected_t : float
        Time of the confirming window [s].
    before, after : dict
        The tracked model before the change and the pool of the two windows after it: ``dynamic``,
        ``stderr``, ``n_windows``.
    evidence : dict
        ``param`` (the parameter that moved), ``z`` (the two windows' standardised innovations on it),
        ``threshold`` h, ``z_all`` (both windows' innovations on every parameter).
    """

    t: float
    detected_t: float
    before: dict
    after: dict
    evidence: dict

    def to_dict(self) -> dict:
        """Plain JSON-serialisable dict."""
        return asdict(self)


def combine(pool: list[Estimate]) -> tuple[np.ndarray, np.ndarray]:
    """Information-weighted mean of estimates and its standard error, per parameter.

    Windows without a finite positive standard error get no weight; when none has one, the plain mean
    with an infinite standard error.
    """
    d = np.array([e.d for e in pool], dtype=np.float64)
    se = np.array([e.se for e in pool], dtype=np.float64)
    with np.errstate(divide="ignore"):
        w = 1.0 / (se * se)
    w[~np.isfinite(w)] = 0.0  # SE 0 or non-finite: no weight
    sw = w.sum(axis=0)
    if sw.all():
        return (w * d).sum(axis=0) / sw, 1.0 / np.sqrt(sw)
    none = sw == 0.0
    sw[none] = 1.0
    mean = (w * d).sum(axis=0) / sw
    mean[none] = d[:, none].mean(axis=0)
    se_out = 1.0 / np.sqrt(sw)
    se_out[none] = np.inf
    return mean, se_out


#: Estimates a pool needs before its scatter scales the innovations (``TrackerConfig.pool_scatter``).
MIN_SCATTER_POOL = 4


def pool_scatter(pool: list[Estimate], mean: np.ndarray) -> np.ndarray:
    """Per parameter, max(1, √ of the pool's reduced χ²): Σ_i (d_i − mean)² / se_i² / (n − 1) [-].

    Windows without a finite positive standard error are left out (none left: 1).
    """
    d = np.array([e.d for e in pool], dtype=np.float64)
    se = np.array([e.se for e in pool], dtype=np.float64)
    ok = np.isfinite(se) & (se > 0.0)
    z2 = np.where(ok, (d - mean) ** 2 / np.where(ok, se * se, 1.0), 0.0)
    n = ok.sum(axis=0)
    chi2 = np.where(n > 1, z2.sum(axis=0) / np.maximum(n - 1, 1), 1.0)
    return np.sqrt(np.maximum(chi2, 1.0))


def _plain(est: Estimate) -> dict:
    return {"t": est.t, "d": est.d, "se": est.se}


def _summary(pool: list[Estimate]) -> dict:
    mean, se = combine(pool)
    return {"dynamic": dict(zip(DYNAMIC_NAMES, mean.tolist(), strict=True)),
            "stderr": dict(zip(DYNAMIC_NAMES, se.tolist(), strict=True)), "n_windows": len(pool)}


@dataclass
class Tracker:
    """The tracked model of one bus: pool since the last change and the two-window change detector.

    Attributes
    ----------
    config : TrackerConfig
    pool : list of Estimate
        Estimates since the last change, oldest first (at most ``pool_windows``).
    suspect : Estimate or None
        A window that stood out, held out of the pool until the next window confirms or clears it.
    suspect_z : list of float or None
        Its standardised innovations.
    last_change : float or None
        Time of the last detected change [s].
    """

    config: TrackerConfig = field(default_factory=TrackerConfig)
    pool: list[Estimate] = field(default_factory=list)
    suspect: Estimate | None = None
    suspect_z: list[float] | None = None
    last_change: float | None = None

    def innovation(self, est: Estimate) -> np.ndarray | None:
        """Standardised innovation of ``est`` against the pool (None while the pool is empty)."""
        if not self.pool:
            return None
        mean, se_pool = combine(self.pool)
        d, se = np.asarray(est.d, dtype=np.float64), np.asarray(est.se, dtype=np.float64)
        scale = self.config.se_scale * np.sqrt(np.where(np.isfinite(se), se, np.inf) ** 2 + se_pool**2)
        if self.config.pool_scatter and len(self.pool) >= MIN_SCATTER_POOL:
            scale = scale * pool_scatter(self.pool, mean)
        return np.where(np.isfinite(scale) & (scale > 0.0), (d - mean) / np.where(scale > 0, scale, 1.0), 0.0)

    def update(self, t: float, d, se) -> ChangeEvent | None:
        """Take one window's estimate; returns the change it confirms, if any.

        Parameters
        ----------
        t : float
            Window time [s].
        d : array_like
            D = [a, b, H2, Tm].
        se : array_like
            Its standard errors (non-finite: the window carries no weight and cannot raise an alarm).
        """
        est = Estimate(float(t), [float(x) for x in d], [float(x) for x in se])
        if not all(math.isfinite(x) for x in est.d):
            return None
        # The suspect was tested against the same pool (it is held out of it until now).
        h = threshold(self.config.false_alarms_per_day, self.config.period_s, len(self.pool))
        z = self.innovation(est)
        if self.suspect is not None:
            zs = np.asarray(self.suspect_z)
            both = (np.abs(zs) > h) & (np.abs(z) > h) & (np.sign(zs) == np.sign(z)) if z is not None else None
            if both is not None and both.any():
                j = int(np.argmax(np.where(both, np.minimum(np.abs(zs), np.abs(z)), -1.0)))
                event = ChangeEvent(
                    t=self.suspect.t, detected_t=est.t, before=_summary(self.pool),
                    after=_summary([self.suspect, est]),
                    evidence={"param": DYNAMIC_NAMES[j], "z": [float(zs[j]), float(z[j])], "threshold": h,
                              "z_all": [zs.tolist(), z.tolist()]})
                self.pool = [self.suspect, est]
                self.suspect = self.suspect_z = None
                self.last_change = event.t
                return event
            # Not confirmed: an outlier of the stationary load.  It joins the pool winsorised (each
            # innovation clipped at ±h), so that it neither biases the pool nor makes the next windows
            # stand out against a pool it has pulled.
            self._append(self._winsorised(self.suspect, np.asarray(self.suspect_z), h))
            self.suspect = self.suspect_z = None
            z = self.innovation(est)
            h = threshold(self.config.false_alarms_per_day, self.config.period_s, len(self.pool))
        if z is not None and bool(np.any(np.abs(z) > h)):
            self.suspect, self.suspect_z = est, z.tolist()
        else:
            self._append(est)
        return None

    def _winsorised(self, est: Estimate, z: np.ndarray, h: float) -> Estimate:
        """``est`` with each parameter moved to the pool's mean + clip(z, ±h)·(its innovation's scale)."""
        if not self.pool:
            return est
        mean = combine(self.pool)[0]
        d = np.asarray(est.d)
        clipped = np.where(np.abs(z) > h, mean + (d - mean) * h / np.where(np.abs(z) > h, np.abs(z), 1.0), d)
        return Estimate(est.t, clipped.tolist(), est.se)

    def _append(self, est: Estimate) -> None:
        self.pool.append(est)
        del self.pool[: max(len(self.pool) - self.config.pool_windows, 0)]

    def model(self) -> dict | None:
        """The tracked model: ``dynamic``, ``stderr``, ``n_windows``, ``since`` (oldest pooled window [s]),
        ``t`` (newest pooled window [s]), ``last_change`` [s or None], ``suspect`` (a window is held out);
        None before the first estimate."""
        if not self.pool:
            return None
        return {**_summary(self.pool), "since": self.pool[0].t, "t": self.pool[-1].t,
                "last_change": self.last_change, "suspect": self.suspect is not None}

    def to_state(self) -> dict:
        """The tracker's state as a plain dict (the configuration excluded), for persistence."""
        # Plain dicts by hand: dataclasses.asdict deep-copies, ~10x slower per bus and period.
        return {"pool": [_plain(e) for e in self.pool], "suspect": _plain(self.suspect) if self.suspect else None,
                "suspect_z": self.suspect_z, "last_change": self.last_change}

    @classmethod
    def from_state(cls, state: dict, config: TrackerConfig) -> Tracker:
        """A tracker from :meth:`to_state`'s dict and the current configuration."""
        pool = [Estimate(**e) for e in state.get("pool", [])][-config.pool_windows:]
        suspect = Estimate(**state["suspect"]) if state.get("suspect") else None
        return cls(config=config, pool=pool, suspect=suspect, suspect_z=state.get("suspect_z"),
                   last_change=state.get("last_change"))
