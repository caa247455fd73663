"""ANDES as an independent bench for the load's own fluctuation (closed loop through the network).

The system is the ANDES cross-check's (IEEE 14-bus, GENROU machines, Motor3 + ZIP at bus 9, the other loads'
constant-power parts driven by 2 Hz low-passed noise: :mod:`aslm_sim.andes.scenario`), and in addition the
constant-power part of bus 9's own load moves by an own process ΔP(t) (ΔQ = 0.33·ΔP) through ANDES's
time-domain perturbation hook, at every step, so that ANDES carries its effect on V and θ.  The recorded
P and Q are the whole bus load: Motor3 + ZIP + the own ΔP, ΔQ.

Recordings are long runs cut into windows.  To give every window its requested ratio of own to grid-driven
fluctuation without one ANDES run per ratio and shape, the grid-driven run and the response to the own
process are made separately and superposed: for an ambient operating point the response is linear in the
small perturbations, so x = x_grid + k·x_own with a per-window k, and x_own is the own ΔP's increments
convolved with bus 9's step response from one ANDES run (:func:`step_response`).
:func:`superposition_error` measures what that costs against one ANDES run with both (docs/numerics.md).

ANDES is an optional dependency: importing this module does not import it.
"""

from __future__ import annotations

import logging
import math
import os
import time
from pathlib import Path

import numpy as np
from scipy import signal

from aslm_sim.network import forcing_filter
from aslm_sim.own import OWN_Q_PER_P, own_process

__all__ = ["CACHE_DIR", "cut_windows", "grid_recording", "own_input", "own_recording", "respond", "run",
           "step_response", "superposition_error"]

#: Recordings are cached here (ANDES runs at 2–6 s of wall time per simulated second).
CACHE_DIR = Path(os.environ.get("ASLM_ANDES_OWN_CACHE", Path.home() / ".cache" / "aslm" / "andes_own"))
#: Std of the own ΔP in the run with the own process alone [pu, 100 MVA]: small (linear), far above ANDES's
#: Newton tolerance.
OWN_RUN_STD = 0.003
#: Relative std of the grid-side ambient noise on the other loads' constant-power parts (as the cross-check).
GRID_AMP = 0.15
_CHANNELS = ("V", "theta", "P", "Q", "dp_own", "dq_own")
#: Length of the step-response run [s]: the governors settle the frequency within it.
STEP_RUN_S = 60.0


def run(*, tf: float, tstep: float, grid_amp: float, own: np.ndarray | None, seed: int, tol: float = 1e-8,
        own_q: np.ndarray | None = None) -> dict:
    """One ANDES time-domain run of the 14-bus case with grid-side ambient and/or bus 9's own fluctuation.

    Parameters
    ----------
    tf, tstep : float
        Simulated time and ANDES's fixed step [s].
    grid_amp : float
        Relative std of the other loads' constant-power noise (0: no grid-side excitation) [-].
    own : ndarray or None
        Bus 9's own ΔP at every step (at least round(tf/tstep) + 2 values) [pu, system base]; None for none.
        ΔQ = 0.33·ΔP unless ``own_q`` is given.
    seed : int
        The grid noise is drawn from ``default_rng(seed)`` (as the cross-check).
    tol : float
        ANDES's Newton tolerance.
    own_q : ndarray or None
        Bus 9's own ΔQ at every step [pu, system base], instead of 0.33·ΔP.

    Returns
    -------
    dict with ``t`` [s] (ANDES's step grid), ``V`` [pu], ``theta`` [rad], ``P``, ``Q`` (bus 9's whole load)
    and ``dp_own``, ``dq_own`` (the injected own part) [pu], ``truth`` (D of the motor), ``tds_s``.
    """
    import andes

    from aslm_sim.andes import scenario as ac

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
    dp = np.zeros(n) if own is None else np.asarray(own, dtype=np.float64)[:n]
    dq = OWN_Q_PER_P * dp if own_q is None else np.asarray(own_q, dtype=np.float64)[:n]
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


def own_input(shape: str, n: int, tstep: float, seed: int, stream: int = 7) -> np.ndarray:
    """Bus 9's own ΔP on ANDES's step grid: the unit own process (from ``default_rng([seed, stream])``) × OWN_RUN_STD
    [pu].  ``stream`` 8 draws the second, independent process of a partly coherent ΔQ (:func:`own_recording`)."""
    sos, gain = forcing_filter(1.0 / tstep)
    return OWN_RUN_STD * own_process(np.random.default_rng([seed, stream]), shape, n, 1.0 / tstep, sos, gain)


def _cached(name: str, make) -> dict:
    """The arrays cached under ``name`` in :data:`CACHE_DIR`, made by ``make()`` the first time."""
    path = CACHE_DIR / f"{name}.npz"
    if path.exists():
        with np.load(path) as z:
            return {k: z[k] for k in z.files}
    rec = make()
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **rec)
    return rec


def _on_grid(sim: dict, fs: float) -> dict:
    """An ANDES run on a uniform grid at fs from t = 0 (linear interpolation), with its truth and TDS time."""
    grid = np.arange(0.0, sim["t"][-1] + 1e-9, 1.0 / fs)
    rec = {k: np.interp(grid, sim["t"], sim[k]) for k in _CHANNELS}
    rec.update(t=grid, truth=sim["truth"], tds_s=np.float64(sim["tds_s"]))
    return rec


def grid_recording(*, tf: float, tstep: float, seed: int, fs: float = 100.0) -> dict:
    """The cached ANDES recording with the grid-side ambient only (keys as :func:`run`, on a uniform grid)."""
    return _cached(f"grid_tf{tf:g}_dt{tstep:g}_s{seed}_fs{fs:g}",
                   lambda: _on_grid(run(tf=tf, tstep=tstep, grid_amp=GRID_AMP, own=None, seed=seed), fs))


def step_response(*, tstep: float, tf: float = STEP_RUN_S) -> dict:
    """Bus 9's response to a step of its own ΔP (ΔQ = 0.33·ΔP), per pu of ΔP, from ANDES (cached).

    Returns
    -------
    dict of ``V``, ``theta``, ``P``, ``Q``: s[j] = (y[k_s + j] − y[k_s − 1]) / ΔP on ANDES's step grid, and
    ``t`` (j·tstep) [s].
    """
    def make() -> dict:
        n = int(round(tf / tstep)) + 2
        k_s = int(round(1.0 / tstep))
        own = np.where(np.arange(n) >= k_s, OWN_RUN_STD, 0.0)
        sim = run(tf=tf, tstep=tstep, grid_amp=0.0, own=own, seed=0)
        rec = _on_grid(sim, 1.0 / tstep)
        out = {c: (rec[c][k_s:] - rec[c][k_s - 1]) / OWN_RUN_STD for c in ("V", "theta", "P", "Q")}
        return {**out, "t": rec["t"][k_s:] - rec["t"][k_s], "tds_s": rec["tds_s"]}

    return _cached(f"step_tf{tf:g}_dt{tstep:g}", make)


def step_response_q(*, tstep: float, tf: float = STEP_RUN_S) -> dict:
    """Bus 9's response to a step of its own ΔQ alone (ΔP = 0), per pu of ΔQ, from ANDES (cached); keys as
    :func:`step_response`.  With it a ΔQ that only partly follows ΔP is superposed (:func:`own_recording`)."""
    def make() -> dict:
        n = int(round(tf / tstep)) + 2
        k_s = int(round(1.0 / tstep))
        step = np.where(np.arange(n) >= k_s, OWN_RUN_STD, 0.0)
        sim = run(tf=tf, tstep=tstep, grid_amp=0.0, own=np.zeros(n), own_q=step, seed=0)
        rec = _on_grid(sim, 1.0 / tstep)
        out = {c: (rec[c][k_s:] - rec[c][k_s - 1]) / OWN_RUN_STD for c in ("V", "theta", "P", "Q")}
        return {**out, "t": rec["t"][k_s:] - rec["t"][k_s], "tds_s": rec["tds_s"]}

    return _cached(f"stepq_tf{tf:g}_dt{tstep:g}", make)


def respond(step: dict, own: np.ndarray) -> dict:
    """Bus 9's V, θ, P, Q deviations caused by an own ΔP sequence on the step grid (linear superposition).

    y[j] = Σ_i Δu[i]·s[j − i] with Δu the increments of ``own`` and s the :func:`step_response`, continued past
    its end along its slope over its last 10 s, or last half (the angle keeps turning at the settled frequency offset).
    """
    n = own.size
    du = np.diff(own, prepend=0.0)
    out = {}
    for c in ("V", "theta", "P", "Q"):
        s = step[c]
        if s.size < n:
            tail = min(int(10.0 / float(step["t"][1] - step["t"][0])), s.size // 2)
            slope = (s[-1] - s[-tail]) / (tail - 1)
            s = np.concatenate([s, s[-1] + slope * np.arange(1, n - s.size + 1)])
        out[c] = signal.fftconvolve(du, s[:n])[:n]
    return out


def own_recording(shape: str, *, tf: float, tstep: float, seed: int, step_tf: float = STEP_RUN_S,
                  coherence: float = 1.0) -> dict:
    """Bus 9 driven by its own process alone (at :data:`OWN_RUN_STD`), on ANDES's step grid from t = 0.

    Made from ANDES's :func:`step_response` by superposition (one ANDES run serves every shape and length);
    :func:`superposition_error` measures it against a direct ANDES run.  ``step_tf``: length of the step run
    [s].  ``coherence`` ρ < 1: ΔQ = 0.33·(ρ·x + √(1 − ρ²)·x₂), x₂ a second own process of the shape (stream 8), its
    part beyond 0.33·ΔP superposed with :func:`step_response_q`.  Keys as :func:`run`.
    """
    n = int(round(tf / tstep)) + 1
    own = own_input(shape, n + 1, tstep, seed)[:n]
    rec = respond(step_response(tstep=tstep, tf=step_tf), own)
    dq = OWN_Q_PER_P * own
    if coherence < 1.0:
        x2 = own_input(shape, n + 1, tstep, seed, stream=8)[:n]
        dq = OWN_Q_PER_P * (coherence * own + math.sqrt(1.0 - coherence**2) * x2)
        extra = respond(step_response_q(tstep=tstep, tf=step_tf), dq - OWN_Q_PER_P * own)
        rec = {c: rec[c] + extra[c] for c in rec}
    return {**rec, "t": np.arange(n) * tstep, "dp_own": own, "dq_own": dq}


def local_response(own: dict, a: int, end: int, h: int, tstep: float) -> dict:
    """Bus 9's V, θ, P, Q response on samples a … end − 1 to the own increments from sample a − h on only.

    The own process's level at a − h is taken as the operating point: its earlier history, and the level it had
    accumulated by then, are left out (:func:`cut_windows` with ``horizon_s``).
    """
    lo = max(0, a - h)
    dp = own["dp_own"][lo:end] - own["dp_own"][lo]
    rec = respond(step_response(tstep=tstep), dp)
    extra = (own["dq_own"][lo:end] - own["dq_own"][lo]) - OWN_Q_PER_P * dp
    if np.any(extra):
        more = respond(step_response_q(tstep=tstep), extra)
        rec = {c: rec[c] + more[c] for c in rec}
    return {c: rec[c][a - lo:] for c in ("V", "theta", "P", "Q")}


def cut_windows(grid: dict, own: dict | None, ratio: float, *, length_s: float, start_s: float, stride_s: float,
                n: int, snr_db: float, rng: np.random.Generator, loop: bool = True,
                horizon_s: float | None = None) -> list[dict]:
    """Windows of the superposed recording with std(own ΔP) / std(grid-driven P) at k = r/√(1 − r²) each.

    ``loop`` False cuts the loop through the network: only the own ΔP and ΔQ themselves are added to P and Q,
    so V and θ (and the load's response to them) carry none of the own process.

    Parameters
    ----------
    grid, own : dict
        :func:`grid_recording` and :func:`own_recording` of a shape (None when ``ratio`` is 0).
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
    horizon_s : float, optional
        With the loop closed, superpose only the response to the own increments of the ``horizon_s`` before each
        window and in it (:func:`local_response`) [s]; None: to the whole own run from t = 0, so that a window
        also carries k times the level the own run has reached by then (for a slow ramp scaled by a large k,
        a shift of the bus's operating point far beyond what the step response describes).

    Returns
    -------
    list of dict with t, V, theta, P, Q (the window), ``own_ratio`` (the achieved std(own ΔP)/std(grid P)),
    ``k`` (the scale of the own run), ``dp_own`` (the window's own ΔP) [pu] and ``noise_std_p``, ``_q`` (the
    white noise added) [pu].
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
            if loop and horizon_s is not None:
                tstep = float(own["t"][1] - own["t"][0])
                local = local_response(own, a, a + m, int(round(horizon_s / tstep)), tstep)
                for c in ("V", "theta", "P", "Q"):
                    w[c] += scale * local[c]
            elif loop:
                for c in ("V", "theta", "P", "Q"):
                    w[c] += scale * (own[c][sl] - own[c][0])
            else:
                w["P"] += scale * own["dp_own"][sl]
                w["Q"] += scale * own["dq_own"][sl]
        dp = scale * own["dp_own"][sl] if own is not None else np.zeros(m)
        for c in ("P", "Q"):
            w[f"noise_std_{c.lower()}"] = float(np.std(w[c])) * 10 ** (-snr_db / 20)
            w[c] += rng.standard_normal(m) * w[f"noise_std_{c.lower()}"]
        w.update(own_ratio=float(np.std(dp)) / float(np.std(grid["P"][sl])), k=scale, dp_own=dp)
        out.append(w)
    return out


def superposition_error(*, tf: float, tstep: float, shape: str, seed: int, scale: float) -> dict:
    """Relative error of the superposed recording against one ANDES run with both excitations.

    The joint run has the grid-side ambient and the own process at ``scale``·:data:`OWN_RUN_STD`; the
    superposition is the grid-only run plus ``scale``·:func:`own_recording` (same seeds, same length).
    Returns, per channel V, theta, P, Q, the std of the difference over the std of the joint run after 1 s
    [-] (constant offsets do not matter to the identifier), and the same for the own part alone
    (``own_V``, ...: the difference over the std of the own-driven part).
    """
    n = int(round(tf / tstep)) + 2
    own = own_input(shape, n, tstep, seed)
    # On the uniform step grid: ANDES inserts points where it shortens a step, so raw indices do not align.
    joint = _on_grid(run(tf=tf, tstep=tstep, grid_amp=GRID_AMP, own=scale * own, seed=seed), 1.0 / tstep)
    grid = _on_grid(run(tf=tf, tstep=tstep, grid_amp=GRID_AMP, own=None, seed=seed), 1.0 / tstep)
    m = min(joint["t"].size, grid["t"].size)
    resp = respond(step_response(tstep=tstep), scale * own[:m])
    k0 = int(round(1.0 / tstep))
    err = {}
    for c in ("V", "theta", "P", "Q"):
        diff = (grid[c][:m] + resp[c] - joint[c][:m])[k0:]
        err[c] = float(np.std(diff) / np.std(joint[c][k0:m]))
        err[f"own_{c}"] = float(np.std(diff) / np.std((joint[c][:m] - grid[c][:m])[k0:]))
    return err
