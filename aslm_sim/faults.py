"""Large disturbances: the noise-free response of a true load to a temporary fault (paper §VI.B.1.b).

The same network as the ambient cases (:mod:`aslm_sim.network`) without the ambient fluctuation, with a
shunt fault at the hub H that sags the voltage at L by a chosen depth.
"""

from __future__ import annotations

import numpy as np

from aslm_core.window import Window
from aslm_sim.network import (
    MAX_STEP_S,
    Par,
    bus_frequency,
    draw_network,
    motor_and_static,
    simulate,
    solve_at,
    steady_state,
    step_grid,
)
from aslm_sim.truth import LoadTruth

__all__ = ["disturbance_inputs", "large_disturbance"]


def _fault_admittance(p: np.ndarray, x0: np.ndarray, vl0: complex, sag_depth: float) -> complex:
    """Shunt admittance at H that makes |V_L| drop to (1 − sag_depth)·|V_L0| at fault inception."""
    zs, zg, zn = _cplx_py(p, Par.ZS), _cplx_py(p, Par.ZG), _cplx_py(p, Par.ZN)
    yn = p[Par.PN] - 1j * p[Par.QN]
    z_th = 1.0 / (1.0 / zs + 1.0 / zg + 1.0 / (zn + 1.0 / yn))
    y_unit = 1.0 / z_th  # same angle as the Thevenin admittance: a real voltage ratio on no load
    target = (1.0 - sag_depth) * abs(vl0)

    def v_at(kappa: float) -> float:
        q = p.copy()
        yf = kappa * y_unit
        q[Par.YF], q[Par.YF + 1] = yf.real, yf.imag
        v, _, _, _ = solve_at(q, x0, 0.0, 0.0, True, vl0)
        return abs(v)

    k_lo, k_hi = 0.0, sag_depth / (1.0 - sag_depth)
    while v_at(k_hi) > target:
        k_hi *= 2.0
    for _ in range(60):  # bisection: |V_L| decreases monotonically with the fault admittance
        k_mid = 0.5 * (k_lo + k_hi)
        if v_at(k_mid) > target:
            k_lo = k_mid
        else:
            k_hi = k_mid
    return complex(0.5 * (k_lo + k_hi) * y_unit)


def _cplx_py(p: np.ndarray, i: int) -> complex:
    return complex(p[i], p[i + 1])


def large_disturbance(
    truth: LoadTruth,
    *,
    seed: int = 0,
    fs: float = 100.0,
    f0: float = 50.0,
    sag_depth: float = 0.2,
    duration_s: float = 5.0,
    fault_start_s: float = 1.0,
    fault_duration_s: float = 0.1,
) -> Window:
    """Noise-free response of the TRUE load to a temporary fault (paper §VI.B.1.b, Table II).

    Parameters
    ----------
    truth : LoadTruth
        The load at bus L.
    seed : int
        Seed of the network draw around the load.
    fs : float
        Sample rate [Hz].
    f0 : float
        Nominal frequency [Hz].
    sag_depth : float
        Voltage drop at L at fault inception, as a fraction of the pre-fault |V_L| [-].
    duration_s : float
        Record length [s], starting from the pre-fault steady state.
    fault_start_s, fault_duration_s : float
        Fault application time and duration [s] (rounded to the fine step).

    Returns
    -------
    Window
        V [pu], θ [rad], P, Q [pu] (from the feeder current), f [Hz] at L; ``meta`` has the fault
        admittance, the times and the states (``Ed``, ``Eq``, ``s``, ``P_motor``...).

    Notes
    -----
    The fault is a shunt admittance at the hub H with the angle of the hub's Thevenin admittance,
    scaled by bisection so |V_L| drops by sag_depth at inception (the motor's E' is frozen then).
    No ambient fluctuation is applied.  Play an identified model back on (V, θ) and compare P, Q by
    the fitting degree FD, eq. 9.
    """
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x1D]))
    net = draw_network(rng, truth, f0)
    p, x0, vl0 = steady_state(truth, net)
    yf = _fault_admittance(p, x0, vl0, sag_depth)
    p[Par.YF], p[Par.YF + 1] = yf.real, yf.imag
    n_samp = int(round(duration_s * fs))
    m, k, h = step_grid(fs, MAX_STEP_S, MAX_STEP_S)
    on = int(round(fault_start_s / h))
    off = on + max(1, int(round(fault_duration_s / h)))
    forcing = np.zeros((1, 2, n_samp * m + 1))
    out_v, out_s, out_x, _, _ = simulate(
        p[None, :], x0[None, :], np.array([vl0]), forcing, h, k, m, 0, n_samp,
        np.array([[on, off]], dtype=np.int64), parallel=False,
    )
    vl = out_v[0]
    th = np.unwrap(np.angle(vl))
    states = motor_and_static(truth, vl, out_x[0])
    meta = {
        "source": "synthetic-fault", "seed": seed, "sag_depth": sag_depth,
        "fault_admittance": [yf.real, yf.imag], "fault_start_s": on * h, "fault_end_s": off * h, "states": states,
    }
    return Window(
        t=np.arange(n_samp) / fs, V=np.abs(vl), theta=th, P=out_s[0].real, Q=out_s[0].imag,
        f=bus_frequency(th, fs, f0), f0=f0, bus="fault", meta=meta,
    )


def disturbance_inputs(truth: LoadTruth, **kw) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t [s], V [pu], θ [rad]) of :func:`large_disturbance` — the inputs for a model playback.

    Parameters
    ----------
    truth : LoadTruth
        The load at bus L.
    kw : dict
        Any other keyword of :func:`large_disturbance`.
    """
    w = large_disturbance(truth, **kw)
    return w.t, w.V, w.theta


