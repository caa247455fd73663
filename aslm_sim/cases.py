"""Ambient cases with known truth: a random load in a random network, simulated, sampled as a PMU would.

Each case draws a :class:`~aslm_sim.truth.LoadTruth`, a network around it (:mod:`aslm_sim.network`), the
ambient excitation at bus N, and measurement noise per the paper's eq. 10 (:mod:`aslm_sim.noise`); all
cases of a call run in one numba kernel (parallel over cases).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from aslm_core.window import Window
from aslm_sim.network import (
    MAX_FORCING_STEP_S,
    MAX_STEP_S,
    NPAR,
    NX,
    WARMUP_S,
    bus_frequency,
    draw_network,
    forcing_filter,
    motor_and_static,
    simulate,
    steady_state,
    step_grid,
)
from aslm_sim.noise import ambient, channel_snr_db, noise_sigma, target_snr
from aslm_sim.own import OWN_Q_PER_P, OWN_SHAPES, own_process
from aslm_sim.truth import LoadTruth, random_truth

__all__ = ["SyntheticCase", "make_case", "make_cases"]

#: Cases simulated together in make_cases (bounds the memory of the forcing arrays).
_CHUNK = 64
#: make_cases runs its cases in threads from this many on.
_PARALLEL_MIN_CASES = 8


def _plain(net: dict) -> dict:
    """JSON-friendly copy of a network draw: complex impedances as [re, im]."""
    return {k: ([v.real, v.imag] if isinstance(v, complex) else float(v)) for k, v in net.items()}


@dataclass(frozen=True)
class SyntheticCase:
    """One synthetic load-modelling case.

    Attributes
    ----------
    window : Window
        What a PMU gives: V [pu], θ [rad], P, Q [pu], f [Hz] with measurement noise (== clean when
        noise-free).
    clean : Window
        The same without noise.  ``clean.meta`` holds the network draw and the case's SNR target.
    truth : LoadTruth
        The load that produced the record.
    snr_db : float
        Achieved SNR of the case (mean of the SNR of P and of Q, eq. 10) [dB]; inf when noise-free.
    level : int or None
        Disturbance level of NOISE_LEVELS, if the case was made by level.
    states : dict
        Noise-free internals at the samples: ``Ed``, ``Eq`` [pu], ``s`` [-] (eq. 1 states),
        ``P_motor``, ``Q_motor`` (eq. 3), ``P_static``, ``Q_static`` (eq. 6) [pu], with an own fluctuation
        ``P_own``, ``Q_own`` (added to the static part's constant-power term) [pu], and ``snr``:
        the achieved SNR per channel [dB].
    """

    window: Window
    clean: Window
    truth: LoadTruth
    snr_db: float
    level: int | None
    states: dict = field(default_factory=dict, compare=False, repr=False)


def make_cases(
    n: int,
    *,
    level: int | None = None,
    snr_db: float | None = None,
    seed: int = 0,
    duration_s: float = 10.0,
    fs: float = 100.0,
    f0: float = 50.0,
    input_noise: bool = True,
    own_sigma: float | Sequence[float] = 0.0,
    own_shape: str = "lowpass",
    own_q_coherence: float = 1.0,
    truths: Sequence[LoadTruth] | None = None,
    networks: Sequence[dict] | None = None,
) -> list[SyntheticCase]:
    """Simulate n ambient cases with known truth.

    Parameters
    ----------
    n : int
        Number of cases.
    level : int, optional
        Disturbance level (key of NOISE_LEVELS): per-case SNR target ~ U[mean ± 2 dB].
    snr_db : float, optional
        Fixed SNR target [dB] for every case (instead of level).  Neither: noise-free.
    seed : int
        Case i depends only on (seed, i): the truth, the network and the ambient excitation come from
        streams independent of the noise, so the same seed at different levels gives the same clean
        records.
    duration_s : float
        Length of the record after the warm-up [s]; n_samples = round(duration_s·fs).
    fs : float
        Sample rate [Hz].
    f0 : float
        Nominal frequency [Hz] (ω0 = 2π·f0).
    input_noise : bool
        Add noise to V, θ and f too (same SNR rule per channel); False: noise on P and Q only.
    own_sigma : float or sequence of float
        The load's own fluctuation (:mod:`aslm_sim.own`): std of its constant-power part's ΔP, as a
        fraction of the load's P at 1 pu (one value, or one per case); ΔQ = 0.33·ΔP.  It moves V and θ
        through the network (closed loop).  0 (default): none, and the cases are those of earlier
        versions for the same seed.
    own_shape : str
        Shape of the own process, one of :data:`aslm_sim.own.OWN_SHAPES`.
    own_q_coherence : float
        Correlation ρ of the own ΔQ with the own ΔP [-]: ΔQ = 0.33·(ρ·x + √(1 − ρ²)·x₂)·σ·P with x₂ a second,
        independent process of the same shape (a load whose small loads switch at different power factors).
        1 (default): ΔQ = 0.33·ΔP, the same cases as before.
    truths : sequence of LoadTruth, optional
        The load of each case instead of a random draw (e.g. one bus over successive windows, or a load
        that changes between them); the excitation and noise still come from (seed, i).
    networks : sequence of dict, optional
        The network of each case (as :func:`aslm_sim.network.draw_network` returns) instead of a draw.

    Returns
    -------
    list of SyntheticCase
        Windows start at t = 0 [s].

    Notes
    -----
    SNR per eq. 10 with y the ambient part (minus the mean; θ also minus a linear trend) of the
    noise-free channel; the noise std of each channel is set so that the expected SNR equals the
    target, so the achieved value scatters by ~±0.3 dB around it.
    """
    sig_own = np.broadcast_to(np.asarray(own_sigma, dtype=np.float64), (n,))
    if own_shape not in OWN_SHAPES:
        raise ValueError(f"unknown own-fluctuation shape {own_shape!r} (use one of {OWN_SHAPES})")
    n_samp = int(round(duration_s * fs))
    n_skip = int(round(WARMUP_S * fs))
    m, k, h = step_grid(fs, MAX_STEP_S, MAX_FORCING_STEP_S)
    sos, gain = forcing_filter(fs * m)
    n_int = (n_skip + n_samp) * m

    cases: list[SyntheticCase] = []
    children = np.random.SeedSequence(seed).spawn(n)
    for c0 in range(0, n, _CHUNK):
        fixed = (truths[c0:c0 + _CHUNK] if truths is not None else None,
                 networks[c0:c0 + _CHUNK] if networks is not None else None)
        cases.extend(_make_chunk(children[c0:c0 + _CHUNK], c0, sos, gain, m, k, h, n_skip, n_samp, n_int,
                                 level, snr_db, seed, fs, f0, input_noise, sig_own[c0:c0 + _CHUNK], own_shape,
                                 fixed, own_q_coherence))
    return cases


def _make_chunk(children: list, c0: int, sos: np.ndarray, gain: float, m: int, k: int, h: float,
                n_skip: int, n_samp: int, n_int: int, level: int | None, snr_db: float | None, seed: int,
                fs: float, f0: float, input_noise: bool, sig_own: np.ndarray,
                own_shape: str, fixed: tuple = (None, None), own_q_coherence: float = 1.0) -> list[SyntheticCase]:
    """Simulate and post-process one chunk of :func:`make_cases` (cases c0, c0 + 1, ...).

    ``fixed``: the chunk's truths and networks, each a sequence or None (drawn).
    """
    n = len(children)
    truths, nets, rows, x0s, vl0s, noise_rngs = [], [], [], [], [], []
    with_own = bool(np.any(sig_own > 0.0))
    forcing = np.zeros((n, 4 if with_own else 2, n_int + 1))
    for i, ss in enumerate(children):
        # A fourth child for the own process: the first three are the same as ss.spawn(3)'s.
        s_truth, s_net, s_noise, s_own = ss.spawn(4)
        tr = fixed[0][i] if fixed[0] is not None else random_truth(np.random.default_rng(s_truth))
        rng_net = np.random.default_rng(s_net)
        net = fixed[1][i] if fixed[1] is not None else draw_network(rng_net, tr, f0)
        p, x0, vl0 = steady_state(tr, net)
        w = rng_net.standard_normal((2, n_int))
        # Zero first value: the system starts at its steady state with no fluctuation.
        forcing[i, 0, 1:] = net["sigma_P"] * net["P_N"] * gain * signal.sosfilt(sos, w[0])
        forcing[i, 1, 1:] = net["sigma_Q"] * net["P_N"] * gain * signal.sosfilt(sos, w[1])
        if sig_own[i] > 0.0:
            scale = sig_own[i] * tr.power(1.0)[0]
            x = own_process(np.random.default_rng(s_own), own_shape, n_int, fs * m, sos, gain)
            forcing[i, 2, 1:] = scale * x
            if own_q_coherence < 1.0:
                # A child of the own seed: the ΔP process (and every case with ρ = 1) stays as it was.
                x2 = own_process(np.random.default_rng(s_own.spawn(1)[0]), own_shape, n_int, fs * m, sos, gain)
                x = own_q_coherence * x + math.sqrt(1.0 - own_q_coherence**2) * x2
            forcing[i, 3, 1:] = OWN_Q_PER_P * scale * x
        truths.append(tr)
        nets.append(net)
        rows.append(p)
        x0s.append(x0)
        vl0s.append(vl0)
        noise_rngs.append(np.random.default_rng(s_noise))
    par = np.array(rows).reshape(n, NPAR)
    faults = -np.ones((n, 2), dtype=np.int64)
    # Threads only pay off for a batch (and the parallel kernel costs its own compilation).
    out_v, out_s, out_x, _, _ = simulate(
        par, np.array(x0s).reshape(n, NX), np.array(vl0s, dtype=complex), forcing,
        h, k, m, n_skip, n_samp, faults, parallel=n >= _PARALLEL_MIN_CASES,
    )
    # The own ΔP, ΔQ at the samples (sample r is forcing-grid point (n_skip + r)·m), before the arrays go.
    own_at_samples = forcing[:, 2:, (n_skip + np.arange(n_samp)) * m].copy() if with_own else None
    del forcing
    t = np.arange(n_samp) / fs
    cases = []
    for i in range(n):
        tr, net = truths[i], nets[i]
        v = np.abs(out_v[i])
        th = np.unwrap(np.angle(out_v[i]))
        fr = bus_frequency(th, fs, f0)
        pc, qc = out_s[i].real, out_s[i].imag
        rng = noise_rngs[i]
        target = target_snr(rng, level, snr_db)
        meta = {
            "source": "synthetic", "seed": seed, "case": c0 + i, "snr_target_db": target,
            "network": _plain(net),
            "step_s": h,
        }
        if with_own:
            meta.update({"own_sigma": float(sig_own[i]), "own_shape": own_shape})
        clean = Window(t=t, V=v, theta=th, P=pc, Q=qc, f=fr, f0=f0, bus=f"syn{c0 + i:04d}", meta=meta)
        states = motor_and_static(tr, out_v[i], out_x[i])
        if own_at_samples is not None:
            states["P_own"], states["Q_own"] = own_at_samples[i]
        if target is None:
            noisy, achieved, per = clean, float("inf"), {}
        else:
            chans = {"P": (pc, False), "Q": (qc, False)}
            if input_noise:
                chans.update({"V": (v, False), "theta": (th, True), "f": (fr, False)})
            noisy_ch = {"V": v, "theta": th, "P": pc, "Q": qc, "f": fr}
            per = {}
            for name in ("P", "Q", "V", "theta", "f"):  # fixed order: deterministic draws
                if name not in chans:
                    continue
                y, detr = chans[name]
                amb = ambient(y, detr)
                sig = noise_sigma(float(np.sqrt(np.mean(amb * amb))), target)
                noisy_ch[name] = y + sig * rng.standard_normal(y.shape)
                per[name] = channel_snr_db(y, noisy_ch[name], detrend=detr)
            achieved = 0.5 * (per["P"] + per["Q"])
            noisy = Window(
                t=t, V=noisy_ch["V"], theta=noisy_ch["theta"], P=noisy_ch["P"], Q=noisy_ch["Q"],
                f=noisy_ch["f"], f0=f0, bus=clean.bus, meta=meta,
            )
        states["snr"] = per
        cases.append(SyntheticCase(window=noisy, clean=clean, truth=tr, snr_db=achieved, level=level,
                                   states=states))
    return cases


def make_case(seed: int, **kw) -> SyntheticCase:
    """One case: ``make_cases(1, seed=seed, **kw)[0]``.

    Parameters
    ----------
    seed : int
        Seed of the case (see :func:`make_cases`).
    kw : dict
        Any other keyword of :func:`make_cases` (level, snr_db, duration_s, fs, f0, input_noise).
    """
    return make_cases(1, seed=seed, **kw)[0]


