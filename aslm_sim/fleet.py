"""A live synthetic PMU fleet: independent load buses simulated continuously, frame batch by frame batch.

The replay and demo commands stream it onto Zenoh; the service's end-to-end tests identify it.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from aslm_sim.network import (
    NPAR,
    NX,
    WARMUP_S,
    draw_network,
    forcing_filter,
    simulate,
    steady_state,
    step_grid,
)
from aslm_sim.noise import ambient_rows, target_snr
from aslm_sim.truth import LoadTruth, random_truth

__all__ = ["SyntheticFleet"]


class SyntheticFleet:
    """A live synthetic PMU fleet: n independent load buses, continuous in time.

    Parameters
    ----------
    n_buses : int
        Number of buses.
    fs : float
        Frame rate [Hz].
    f0 : float
        Nominal frequency [Hz].
    level : int or None
        Disturbance level (NOISE_LEVELS) of the measurement noise; None: noise-free.
    seed : int
        Everything (truths, networks, excitation, noise) is deterministic for a seed.
    t0 : float or None
        Time of the first sample [s] (e.g. seconds since epoch, given by the caller); None: 0.0.
    step_s : float
        Longest internal RK4 step [s] (default 10 ms, see Notes).

    Attributes
    ----------
    truths : list of LoadTruth
    bus_names : list of str
        ``bus0001``, ``bus0002``, …
    snr_db : ndarray
        SNR target per bus [dB] (nan when noise-free).

    Notes
    -----
    Same model as :func:`aslm_sim.cases.make_cases` (one independent small network per bus) but
    integrated with a coarser step, 10 ms instead of 1 ms, with the forcing on the same 10 ms grid
    (piecewise linear), in the calling thread (no thread pool: the fleet must leave the cores to the
    identification workers).  With the fastest motor pole at b ≤ 28 1/s and the electromechanical mode
    near 1 Hz, RK4 at 10 ms differs from 1 ms by < 1e-7 pu in V and < 5e-7
    pu in P, ~1e-4 of the ambient fluctuation and far below the noise of any level.  The construction
    runs a 5 s warm-up and a 20 s calibration (not emitted) whose ambient rms per channel fixes each
    bus's noise std (eq. 10), so the SNR of a live 10 s window scatters around the bus's target
    (within ~±3 dB).  Noise is on V, θ, P, Q and f.  Random draws are time-major, so the stream
    does not depend on how it is chunked into :meth:`advance` calls.
    """

    _CAL_S = 20.0

    def __init__(
        self,
        n_buses: int,
        *,
        fs: float = 50.0,
        f0: float = 50.0,
        level: int | None = 2,
        seed: int = 0,
        t0: float | None = None,
        step_s: float = 1e-2,
    ) -> None:
        self.n_buses = int(n_buses)
        self.fs = float(fs)
        self.f0 = float(f0)
        self.level = level
        self.t0 = 0.0 if t0 is None else float(t0)
        self._k = 0  # index of the next sample
        root = np.random.SeedSequence([seed, 0xF1EE7])
        children = root.spawn(self.n_buses + 1)
        self._rng_stream = np.random.default_rng(children[-1])
        self.truths: list[LoadTruth] = []
        self.bus_names = [f"bus{i + 1:04d}" for i in range(self.n_buses)]
        rows, x0s, vl0s, sp, sq, tgt = [], [], [], [], [], []
        for ss in children[:-1]:
            s_truth, s_net, s_noise = ss.spawn(3)
            tr = random_truth(np.random.default_rng(s_truth))
            rng_net = np.random.default_rng(s_net)
            net = draw_network(rng_net, tr, self.f0)
            p, x0, vl0 = steady_state(tr, net)
            self.truths.append(tr)
            rows.append(p)
            x0s.append(x0)
            vl0s.append(vl0)
            sp.append(net["sigma_P"] * net["P_N"])
            sq.append(net["sigma_Q"] * net["P_N"])
            t_ = target_snr(np.random.default_rng(s_noise), level, None)
            tgt.append(np.nan if t_ is None else t_)
        self._par = np.array(rows).reshape(self.n_buses, NPAR)
        self._x = np.array(x0s).reshape(self.n_buses, NX)
        self._vl = np.array(vl0s, dtype=complex)
        self._amp = np.stack([np.array(sp), np.array(sq)], axis=1)  # (n, 2)
        self.snr_db = np.array(tgt)
        self._m, self._ksub, self._h = step_grid(self.fs, step_s, step_s)
        self._sos, self._gain = forcing_filter(self.fs * self._m)
        self._zi = np.zeros((self._sos.shape[0], self.n_buses, 2, 2))
        self._f_last = np.zeros((self.n_buses, 2))
        self._theta_last: np.ndarray | None = None
        self._sigma = np.zeros((self.n_buses, 5))
        # Warm-up + calibration, not emitted: continue the stream from where they end.
        self._run(int(round(WARMUP_S * self.fs)))
        cal = self._run(int(round(self._CAL_S * self.fs)) + 1)
        if level is not None:
            for ci, name in enumerate(("V", "theta", "P", "Q", "f")):
                amb = ambient_rows(cal[name], detrend=(name == "theta"))
                rms = np.sqrt(np.mean(amb * amb, axis=1))
                self._sigma[:, ci] = rms * 10.0 ** (-self.snr_db / 20.0)
        self._noise_rng = np.random.default_rng(root.spawn(1)[0])

    def _run(self, n: int) -> dict[str, np.ndarray]:
        """Simulate n samples (noise-free), carrying the state and the forcing filter over."""
        m = self._m
        # Time-major draws: the stream does not depend on how it is chunked into advance() calls.
        w = self._rng_stream.standard_normal((n * m, self.n_buses, 2)).transpose(1, 2, 0)
        y, self._zi = signal.sosfilt(self._sos, w, axis=-1, zi=self._zi)
        new = y * self._gain * self._amp[:, :, None]
        forcing = np.concatenate([self._f_last[:, :, None], new], axis=-1)
        self._f_last = new[:, :, -1].copy()
        out_v, out_s, _, self._x, self._vl = simulate(
            self._par, self._x, self._vl, forcing, self._h, self._ksub, m, 0, n,
            -np.ones((self.n_buses, 2), dtype=np.int64), parallel=False,
        )
        th = np.angle(out_v)
        # Unwrap continuously across calls.
        if self._theta_last is not None:
            th = np.concatenate([self._theta_last[:, None], th], axis=1)
            th = np.unwrap(th, axis=1)[:, 1:]
        else:
            th = np.unwrap(th, axis=1)
        prev = self._theta_last
        self._theta_last = th[:, -1].copy()
        # Frequency by backward differences so a sample never depends on the future.
        if prev is None:
            prev = th[:, 0]
        dth = np.diff(np.concatenate([prev[:, None], th], axis=1), axis=1)
        fr = self.f0 + dth * self.fs / (2.0 * math.pi)
        return {"V": np.abs(out_v), "theta": th, "P": out_s.real, "Q": out_s.imag, "f": fr}

    def advance(self, n_samples: int) -> dict[str, np.ndarray]:
        """Next n_samples frames of every bus.

        Returns
        -------
        dict
            ``t`` (n,) [s]; ``V`` [pu], ``theta`` [rad], ``P``, ``Q`` [pu], ``f`` [Hz], each
            (n_buses, n); noisy at the fleet's level; continuous with the previous call.
        """
        n = int(n_samples)
        t = self.t0 + (self._k + np.arange(n)) / self.fs
        self._k += n
        if n == 0:
            z = np.zeros((self.n_buses, 0))
            return {"t": t, "V": z, "theta": z.copy(), "P": z.copy(), "Q": z.copy(), "f": z.copy()}
        out = self._run(n)
        if self.level is not None:
            e = self._noise_rng.standard_normal((n, 5, self.n_buses))  # time-major, as above
            for ci, name in enumerate(("V", "theta", "P", "Q", "f")):
                out[name] = out[name] + self._sigma[:, ci, None] * e[:, ci, :].T
        out["t"] = t
        return out
