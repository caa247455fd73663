"""ANDES as an independent bench for the load's own fluctuation (closed loop through the network).

The system is the ANDES cross-check's (IEEE 14-bus, GENROU machines, Motor3 + ZIP at bus 9, the other loads'
constant-power parts driven by 2 Hz low-passed noise: :mod:`benchmarks.andes_crosscheck`), and in addition the
constant-power part of bus 9's own load moves by an own process ΔP(t) (ΔQ = 0.33·ΔP) through ANDES's
time-domain perturbation hook, at every step, so that ANDES carries its effect on V and θ.  The recorded
P and Q are the whole bus load: Motor3 + ZIP + the own ΔP, ΔQ.

Recordings are long runs cut into windows.  To give every window its requested ratio of own to grid-driven
fluctuation without one ANDES run per ratio, the grid-driven run and a run with the own process alone are
made separately and superposed: for an ambient operating point the response is linear in the small
perturbations, so x = x_grid + k·(x_own − x_eq) with a per-window k.  :func:`superposition_error` measures
what that approximation costs against one ANDES run with both (docs/numerics.md gives the figure).

ANDES is an optional dependency: importing this module does not import it.
"""

from __future__ import annotations

import logging
import math
import os
import time
from pathlib import Path

import numpy as np

from aslm_sim.network import forcing_filter
from aslm_sim.own import OWN_Q_PER_P, own_process

__all__ = ["CACHE_DIR", "cut_windows", "recording", "run", "superposition_error"]

#: Recordings are cached here (ANDES runs at 2–6 s of wall time per simulated second).
CACHE_DIR = Path(os.environ.get("ASLM_ANDES_OWN_CACHE", Path.home() / ".cache" / "aslm" / "andes_own"))
#: Std of the own ΔP in the run with the own process alone [pu, 100 MVA]: small (linear), far above ANDES's
#: Newton tolerance.
OWN_RUN_STD = 0.003
#: Relative std of the grid-side ambient noise on the other loads' constant-power parts (as the cross-check).
GRID_AMP = 0.15
_CHANNELS = ("V", "theta", "P", "Q", "dp_own", "dq_own")


def run(*, tf: float, tstep: float, grid_amp: float, own_shape: str | None, own_std: float, seed: int,
        tol: float = 1e-8) -> dict:
    """One ANDES time-domain run of the 14-bus case with grid-side ambient and/or bus 9's own fluctuation.

    Parameters
    ----------
    tf, tstep : float
        Simulated time and ANDES's fixed step [s].
    grid_amp : float
        Relative std of the other loads' constant-power noise (0: no grid-side excitation) [-].
    own_shape : str or None
        Shape of bus 9's own process (:data:`aslm_sim.own.OWN_SHAPES`), None for none.
    own_std : float
        Std of the own ΔP [pu, system base].
    seed : int
        The grid noise is drawn from ``default_rng(seed)`` (as the cross-check), the own process from
        ``default_rng([seed, 7])``: a run with both equals the sum of the two runs with one each.
    tol : float
        ANDES's Newton tolerance.

    Returns
    -------
    dict with ``t`` [s] (ANDES's step grid), ``V`` [pu], ``theta`` [rad], ``P``, ``Q`` (bus 9's whole load)
    and ``dp_own``, ``dq_own`` (the injected own part) [pu], ``truth`` (D of the motor), ``tds_s``.
    """
    import andes

    from benchmarks import andes_crosscheck as ac

    andes.config_logger(stream_level=logging.ERROR)
    ss = andes.load(andes.get_case(ac.CASE), setup=False, no_output=True, default_config=True)
    ss.add("Motor3", {"idx": "M1", "name": "M1", "bus": ac.BUS, **ac.MOTOR, **ac.SCENARIOS["model"]})
    ss.setup()
    ss.PQ.set("p0", ac.PQ_AT_BUS, ac.STATIC_PQ[0], base="device")
    ss.PQ.set("q0", ac.PQ_AT_BUS, ac.STATIC_PQ[1], base="device")
    for k, v in ac.ZIP_SHARES.items():
        setattr(ss.PQ.config, k, v)
    ac.solve_power_flow(ss)
    m, pq = ss.Motor3, ss.PQ
    x0, x1, t10 = float(m.x0.v[0]), float(m.x1.v[0]), float(m.T10.v[0])
    truth = np.array([(x0 / x1 - 1) / (t10 * x1), x0 / (t10 * x1), float(m.M.v[0]), float(m.tm.v[0])])
    ss.TDS.config.tf, ss.TDS.config.tstep, ss.TDS.config.tol, ss.TDS.config.no_tqdm = tf, tstep, tol, 1
    ss.TDS.init()
    u9 = pq.idx2uid(ac.PQ_AT_BUS)
    others = np.array([i for i in range(pq.n) if i != u9])
    ppf0, qpf0 = pq.Ppf.v.copy(), pq.Qpf.v.copy()
    n = int(round(tf / tstep)) + 2
    rng = np.random.default_rng(seed)
    grid_p = np.stack([ac.lowpass_noise(n, tstep, 2.0, rng) for _ in others], axis=1)
    grid_q = np.stack([ac.lowpass_noise(n, tstep, 2.0, rng) for _ in others], axis=1)
    dp = np.zeros(n)
    if own_shape is not None and own_std > 0.0:
        sos, gain = forcing_filter(1.0 / tstep)
        dp = own_std * own_process(np.random.default_rng([seed, 7]), own_shape, n, 1.0 / tstep, sos, gain)
    dq = OWN_Q_PER_P * dp
    # ANDES's PQ in TDS is p2p·Ppf + p2i·Ipeq·v + p2z·Req·v²: the own ΔP enters through Ppf / p2p.
    p2p, q2q = ac.ZIP_SHARES["p2p"], ac.ZIP_SHARES["q2q"]

    def pert(t, system):
        k = min(int(round(float(t) / tstep)), n - 1)
        pq.Ppf.v[others] = ppf0[others] * (1.0 + grid_amp * grid_p[k])
        pq.Qpf.v[others] = qpf0[others] * (1.0 + grid_amp * grid_q[k])
        pq.Ppf.v[u9] = ppf0[u9] + dp[k] / p2p
        pq.Qpf.v[u9] = qpf0[u9] + dq[k] / q2q

    ss.TDS.callpert = pert
    t_run = time.perf_counter()
    ss.TDS.run()
    t_run = time.perf_counter() - t_run
    if ss.TDS.busted or ss.dae.t < tf - 1e-6:
        raise RuntimeError(f"ANDES TDS stopped at t = {float(ss.dae.t):.3f} s")
    t = np.asarray(ss.dae.ts.t, dtype=float)
    y = np.asarray(ss.dae.ts.y, dtype=float)
    ub = ss.Bus.idx2uid(ac.BUS)
    V, th = y[:, ss.Bus.v.a[ub]], y[:, ss.Bus.a.a[ub]]
    sh = ac.ZIP_SHARES
    ps = sh["p2z"] * pq.Req.v[u9] * V**2 + sh["p2i"] * pq.Ipeq.v[u9] * V + sh["p2p"] * ppf0[u9]
    qs = sh["q2z"] * pq.Xeq.v[u9] * V**2 + sh["q2i"] * pq.Iqeq.v[u9] * V + sh["q2q"] * qpf0[u9]
    k = np.minimum(np.round(t / tstep).astype(int), n - 1)
    keep = np.concatenate(([True], np.diff(t) > 1e-9))
    out = {"t": t, "V": V, "theta": th, "P": y[:, m.p.a[0]] + ps + dp[k], "Q": y[:, m.q.a[0]] + qs + dq[k],
           "dp_own": dp[k], "dq_own": dq[k]}
    out = {key: v[keep] for key, v in out.items()}
    return {**out, "truth": truth, "tds_s": t_run, "andes_version": andes.__version__}


def recording(kind: str, *, tf: float, tstep: float, seed: int, fs: float = 100.0) -> dict:
    """A cached ANDES recording on a uniform grid at fs [Hz]: ``grid`` (grid-side ambient only) or an own shape.

    The own recordings carry the own process alone at :data:`OWN_RUN_STD`.  Keys as :func:`run` (on the
    uniform grid), ``truth``, ``tds_s``.
    """
    path = CACHE_DIR / f"{kind}_tf{tf:g}_dt{tstep:g}_s{seed}_fs{fs:g}.npz"
    if path.exists():
        with np.load(path) as z:
            return {k: z[k] for k in z.files}
    if kind == "grid":
        sim = run(tf=tf, tstep=tstep, grid_amp=GRID_AMP, own_shape=None, own_std=0.0, seed=seed)
    else:
        sim = run(tf=tf, tstep=tstep, grid_amp=0.0, own_shape=kind, own_std=OWN_RUN_STD, seed=seed)
    grid = np.arange(0.0, sim["t"][-1] + 1e-9, 1.0 / fs)
    rec = {k: np.interp(grid, sim["t"], sim[k]) for k in _CHANNELS}
    rec.update(t=grid, truth=sim["truth"], tds_s=np.float64(sim["tds_s"]))
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **rec)
    return rec


def cut_windows(grid: dict, own: dict | None, ratio: float, *, length_s: float, start_s: float, stride_s: float,
                n: int, snr_db: float, rng: np.random.Generator) -> list[dict]:
    """Windows of the superposed recording with std(own ΔP) / std(grid-driven P) at k = r/√(1 − r²) each.

    Parameters
    ----------
    grid, own : dict
        :func:`recording` of ``grid`` and of an own shape (None when ``ratio`` is 0).
    ratio : float
        Target own/total std ratio r of P [-] (own and grid-driven parts uncorrelated: k gives r).
    length_s, start_s, stride_s : float
        Window length, the first window's start and the step between window starts [s].
    n : int
        Number of windows.
    snr_db : float
        White measurement noise on P and Q [dB, to each window's std].
    rng : numpy.random.Generator
        Source of the measurement noise.

    Returns
    -------
    list of dict with t, V, theta, P, Q (the window), ``own_ratio`` (the achieved std(own ΔP)/std(grid P))
    and ``k`` (the scale of the own run).
    """
    fs = 1.0 / float(grid["t"][1] - grid["t"][0])
    m = int(round(length_s * fs)) + 1
    k_target = ratio / math.sqrt(1.0 - ratio * ratio)
    out = []
    for i in range(n):
        a = int(round((start_s + i * stride_s) * fs))
        sl = slice(a, a + m)
        if grid["t"][sl].size < m:
            raise ValueError(f"the recording ends before window {i} ({n} windows of {length_s} s from {start_s} s)")
        w = {c: grid[c][sl].copy() for c in ("t", "V", "theta", "P", "Q")}
        scale = 0.0
        if own is not None and ratio > 0.0:
            scale = k_target * float(np.std(grid["P"][sl])) / float(np.std(own["dp_own"][sl]))
            for c in ("V", "theta", "P", "Q"):
                w[c] += scale * (own[c][sl] - own[c][0])
        dp = scale * own["dp_own"][sl] if own is not None else np.zeros(m)
        for c in ("P", "Q"):
            w[c] += rng.standard_normal(m) * float(np.std(w[c])) * 10 ** (-snr_db / 20)
        w["own_ratio"] = float(np.std(dp)) / float(np.std(grid["P"][sl]))
        w["k"] = scale
        out.append(w)
    return out


def superposition_error(*, tf: float, tstep: float, shape: str, seed: int, scale: float) -> dict:
    """Relative RMS error of the superposed recording against one ANDES run with both excitations.

    The joint run has the grid-side ambient and the own process at ``scale``·:data:`OWN_RUN_STD`; the
    superposition is ``grid + scale·own`` of the two separate runs (same seeds, same length) up to a constant.
    Returns, per channel V, theta, P, Q, the std of the difference over the std of the joint run (after 1 s) [-].
    """
    joint = run(tf=tf, tstep=tstep, grid_amp=GRID_AMP, own_shape=shape, own_std=scale * OWN_RUN_STD, seed=seed)
    grid = run(tf=tf, tstep=tstep, grid_amp=GRID_AMP, own_shape=None, own_std=0.0, seed=seed)
    own = run(tf=tf, tstep=tstep, grid_amp=0.0, own_shape=shape, own_std=OWN_RUN_STD, seed=seed)
    k0 = int(round(1.0 / tstep))
    err = {}
    for c in ("V", "theta", "P", "Q"):
        # Constant offsets (the own run's first sample is not the equilibrium) do not matter to the identifier.
        diff = (grid[c] + scale * own[c] - joint[c])[k0:]
        fl = joint[c][k0:]
        err[c] = float(np.std(diff) / np.std(fl))
    return err
