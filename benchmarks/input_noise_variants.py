"""The refinement's input spectrum, three ways tried at stop 44 and not adopted (issue 11): kept so the figures rerun.

On the supplement's windows and draws of ``benchmarks.input_noise_bound --weighting`` (seed ``--seed``, ``--n`` windows
per level, both PMU classes), every noisy window is identified by the default (``IdentifyConfig()``) and by each variant:

* ``pq``: the S-weighted refinement's smoother given the inputs' signal spectrum read through P and Q,
  S_x = H⁻¹·(S_PQ − N_PQ)·H⁻ᴴ — H the model's input response at the output-error D (as the refinement forms it), S_PQ the
  smoothed periodogram matrix of the measured P and Q on the regression samples, N_PQ their white floors — negative
  eigenvalues clipped, zero from 5 Hz (:func:`pq_spectrum`);
* ``avg``: the mean of that and the window's own estimate (:func:`aslm_core.noise.pooled_spectrum` of the one window,
  without the cut-off rule);
* ``ptail``: the window's own estimate on its grid with today's tail rebuilt here (the power law over [cut-off / 2,
  cut-off)), the control of the next one;
* ``wpl``: the tail's power law fitted instead by the Whittle likelihood of the raw periodogram over [cut-off / 2, 5 Hz)
  with the white floor known (:func:`whittle_power_law`);
* ``floor_outside``, ``no_floor`` (stop 45): the refinement's S with the residual periodogram's floor on its diagonal
  kept only in the bins where the model's S has no input-error content (H·P_x·Hᴴ ≤ 1e-3 of the white floor: above the
  smoother's spectrum), or not at all (:func:`residual_floor`); ``floor_sig2``, ``floor_sig1.5`` (stop 46): kept only
  where it raises the diagonal above 2 or 1.5 × the model's (a significant excess);
* ``em`` (stop 45): the spectrum by the joint likelihood of the measured V, θ, P and Q with the inputs latent, H at the
  output-error D (:func:`em_spectrum`);
* ``hist6``, ``hist6_fine_td`` (stop 46): end to end through :func:`aslm_core.identify`'s ``input_spectrum``, the
  default given a minute of the bus's history (six noisy 10 s windows of another realisation of the same load and
  network, :func:`benchmarks.input_noise_bound.history_periodograms`, pooled by :func:`~benchmarks.input_noise_bound.pooled_history` as the service's
  worker pools them), each in its own form (:func:`history_measure`): ``hist6`` stop 41's (smoothed over 0.5 Hz, the
  window's own refinement); ``hist6_fine_td`` pooled unsmoothed, the refinement whitened in the time domain below 5 Hz
  without the residual floor (stop 46's lead, which failed its confirmation on seed 54 at stop 47);
  ``hist6_guard1.3``, ``hist6_guard1.5`` (stop 47): that form redone with the floor where its whitened residual's χ²
  exceeds 1.3 or 1.5 (``input_weighting.HISTORY_CHI2_MAX``; the JSON's ``guard_fired`` counts the windows per row),
  ``hist6_guard1.5`` the core's form from its confirmation on seed 55 until stop 48; ``hist6_checked`` (stop 48) that
  with the staleness check, the core's form since (the others run without the check, as they first ran); any of these
  with the suffix ``_of1``: given the next case's history instead, another load and network (a stale history, as
  ``input_noise_bound --history-of 1``);
* ``own_td``, ``own_td_guard1.5``, ``own_td_fallback1.5`` (stop 48): the history's form on the window alone, with the
  window's own spectrum and its tail (:func:`own_history_form`): no guard, the guard's refit, or the default's fit where
  χ² exceeds 1.5; ``own_td_guard1.5`` failed its confirmation on seed 57 (:data:`OWN_RULE`);
* ``band5``, ``band3`` (stop 45): the refinement's band (``input_weighting.BAND_FRACTION``) at a twentieth or a
  thirty-third of the rate instead of a tenth (5 or 3 Hz at 100 frames/s);
* ``cap3.5``, ``cap4``, ``capinf`` (stop 49): the window's own refinement's band at most 3.5 or 4 Hz, or uncapped
  (``input_weighting.MAX_BAND_HZ``; 4 Hz the default since stop 49, so ``capinf`` is the default before it; the runs of
  record tagged ``cap`` and ``confirm49cap`` were made before, their ``default`` uncapped);
* ``gain49``, ``own_bin_out``, ``band4`` (stop 49): the smoother's gain from each bin's neighbours' periodogram without
  its own and the refinement's band at least 4 Hz (4 Hz at 25 and 30 frames/s), or either alone (:data:`GAIN49_VARIANTS`).
  ``gain49`` was the default from 2a38811 until its confirmation failed (``benchmarks.input_noise_gain``): the runs of
  record made then (tags ``dev49``, ``confirm49``) hold it as ``default`` and today's default as ``before49``, the
  decomposition as ``band_tenth`` (``own_bin_out`` today) and ``own_bin_in`` (``band4``);
* ``band_cut`` (stop 50): the window's own refinement's band past 4 Hz up to V's own signal cut-off, at most a tenth
  of the rate (``input_weighting.BAND_AT_CUTOFF``);
* ``lagrange`` (stop 50): the inputs inside a sample step from 4-point Lagrange cubics (``motor.SPLINE_INPUTS`` off),
  as before stop 50, instead of the not-a-knot spline;
* ``multitaper`` (stop 55): the Wiener smoother's gain and cut-off read from Thomson's multitaper estimate of the
  window's (V, θ) cross-spectrum (Slepian tapers of half-bandwidth 0.25 Hz, the same resolution as today's 0.5 Hz
  average of the padded periodogram) instead (``noise.GAIN_SPECTRUM``);
* ``widths``: the default run with the Wiener smoother's averaging width at 0.5 (today's), 0.25 and 1 Hz — every call of
  the smoother, the output-error stage's prefilter too — and each parameter's median of the three (``widths_median``) or
  the run nearest that median (``widths_medoid``, distance in units of each parameter's spread over the cell's windows).

The spectrum variants reach the refinement through ``identify(..., input_spectrum=)``'s seam (the one the service's
history uses) by standing in for :func:`aslm_core.input_weighting.weighted_fit` within this process; ``widths`` stands in
for :func:`aslm_core.noise.wiener_smooth`, the floor variants for the refinement's spectrum and whitening functions;
the history variants set the core's history knobs (:data:`HISTORY_FORMS`).  Each is restored after the call.  Printed
per variant: σ of D/D_real over the default's per cell (median and range over the noisy cells × parameters, Tm at
0.1 % / 1e-3 rad per DL), the windows off by more than 20 % per class, the coverage of ±1.96 SE and the median ms per
identification of the default and the history variants; JSON
``docs/results/input_noise_variants_seed<seed>[_<tag>][_fs<rate>].json`` (per window D/D_real and SE).  ``--against ROW`` takes the
ratios and far-off counts against another row; ``--report NAME...`` prints the same from stored runs without running
(their rows merged: runs of one seed and size).

    .venv/bin/python -m benchmarks.input_noise_variants --seed 41 [--n 300] [--variants pq,avg,ptail,wpl,widths]
    .venv/bin/python -m benchmarks.input_noise_variants --seed 41 --variants floor_outside,no_floor --tag floor
    .venv/bin/python -m benchmarks.input_noise_variants --seed 41 --variants em --tag em
    .venv/bin/python -m benchmarks.input_noise_variants --seed 41 --variants band5,band3 --tag band
    .venv/bin/python -m benchmarks.input_noise_variants --seed 41 --variants floor_sig2,floor_sig1.5 --tag floorsig
    .venv/bin/python -m benchmarks.input_noise_variants --seed 41 --variants hist6,hist6_fine_td --tag hist
    .venv/bin/python -m benchmarks.input_noise_variants --seed 41 --variants hist6_guard1.3,hist6_guard1.5 --tag guard
    .venv/bin/python -m benchmarks.input_noise_variants --seed 55 --variants hist6,hist6_guard1.5 --tag confirm
    .venv/bin/python -m benchmarks.input_noise_variants --seed 41 --n 150 --fs 120 --variants hist6,hist6_guard1.5 --tag hist
    .venv/bin/python -m benchmarks.input_noise_variants --seed 54 --variants hist6_of1,hist6_guard1.5_of1 --tag stale
    .venv/bin/python -m benchmarks.input_noise_variants --report input_noise_variants_seed55_confirm --against hist6
    .venv/bin/python -m benchmarks.input_noise_variants --seed 45 --variants own_td_guard1.5,own_td_fallback1.5 --tag own
    .venv/bin/python -m benchmarks.input_noise_variants --seed 57 --variants own_td_guard1.5 --tag confirm [--n 150 --fs 25]

Measurements: docs/numerics.md, "Stop 44: the inputs' spectrum read through P and Q (tried, dropped)"; the floor
variants, ``em`` and the bands "Stop 45: the bound with the inputs' spectrum learnt from the window"; ``floor_sig*`` and
the history variants "Stop 46: the learnt bound is within reach of maximum likelihood; where the default leaves it"
and "Stop 47: the history's spectrum unsmoothed, the refinement in the time domain"; the ``own_td`` variants "Stop 48:
the history's form on a window alone (tried, not adopted); the history on ANDES, its staleness check; the whitener by
Levinson" (the ``own_td_switch`` variants and the staleness statistic there too).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import contextlib  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402
from scipy import optimize  # noqa: E402

from aslm_core import WindowError, identify, input_history, input_weighting, motor, noise, preprocess  # noqa: E402
from aslm_core.identify import IV_SE_MAX  # noqa: E402
from aslm_core.problem import Problem  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.input_noise_bound import (  # noqa: E402
    INPUT_NOISE,
    LEVELS,
    TAIL,
    history_periodograms,
    pooled_history,
    with_input_noise,
)

VARIANTS = ("pq", "avg", "ptail", "wpl", "widths", "floor_outside", "no_floor", "em", "band5", "band3", "floor_sig2",
            "floor_sig1.5", "hist6", "hist6_fine_td", "hist6_guard1.3", "hist6_guard1.5", "own_td", "own_td_guard1.5",
            "own_td_fallback1.5", "hist6_checked", "gain49", "own_bin_out", "band4", "cap3.5", "cap4", "capinf",
            "lagrange", "band_cut", "multitaper")
#: ``hist6``, ``hist6_fine_td`` (stop 46): end to end, the default given a minute of the bus's history (module docstring).
#: Each history variant's form, set whatever the core's defaults: (``input_history.HISTORY_SMOOTH_HZ``,
#: ``input_weighting.HISTORY_BAND_HZ``, ``input_weighting.HISTORY_CHI2_MAX``, ``input_history.HISTORY_STALE_MAX``).
#: The forms of stops 46–47 ran before the staleness check (stop 48) and keep running without it, so that their stored
#: runs reproduce and ``--stale-report`` composes unchecked rows; ``hist6_checked`` is the core's form since stop 48.
HISTORY_FORMS = {"hist6": (noise.WIENER_SMOOTH_HZ, None, None, math.inf),  # stop 41's form
                 "hist6_fine_td": (0.0, noise.FLOOR_FROM_HZ, None, math.inf),
                 "hist6_guard1.3": (0.0, noise.FLOOR_FROM_HZ, 1.3, math.inf),
                 "hist6_guard1.5": (0.0, noise.FLOOR_FROM_HZ, 1.5, math.inf),
                 "hist6_checked": (0.0, noise.FLOOR_FROM_HZ, 1.5, 3.0)}
HISTORY_VARIANTS = tuple(HISTORY_FORMS)
#: Suffix of a history variant given the next case's history (another load and network: a stale history).
STALE = "_of1"
#: Per history variant, the windows on which the guard refitted with the floor (counted by :func:`history_measure`).
GUARD_FIRED: dict[str, int] = {}
HISTORY_K = 6
#: ``own_td``, ``own_td_guard1.5`` (stop 48): the history's form (time domain below 5 Hz, no residual floor; the guard
#: at χ² 1.5 or none) on the window alone, its smoother's own spectrum with the tail standing in for the history's.
#: The variant's guard (``input_weighting.HISTORY_CHI2_MAX``).
#: ``own_td_fallback1.5``: where that form's χ² exceeds 1.5, the default's fit (spectral, to a tenth of the rate, the
#: floor) instead of the guard's refit in the same form.
OWN_FORMS = {"own_td": None, "own_td_guard1.5": 1.5, "own_td_fallback1.5": 1.5}
#: Seed of ``own_td_guard1.5``'s confirmation (stop 48, fixed with :data:`OWN_RULE` before any run on it).  Development:
#: seeds 41 and 45 at 100 frames/s, seed 41 at 25 and 120 frames/s.
OWN_CONFIRM_SEED = 57
#: The rule ``own_td_guard1.5`` must meet on :data:`OWN_CONFIRM_SEED` against the default (σ of D/D_real per noisy cell ×
#: parameter, both PMU classes, DL 1–3) to become the default's form for a window alone (committed before the run):
#: at 100 frames/s, 300 windows per level (``--seed 57 --variants own_td_guard1.5 --tag confirm``):
#: (1) median σ ratio ≤ 0.99; (2) largest ≤ 1.10; (3) at DL 3 / 0.1 % / 1e-3 rad ≤ 0.95 for at least three of the four
#: parameters; (4) windows off by more than 20 % at 0.1 % over DL 1–3 at most the default's; (5) coverage of ±1.96 SE
#: inside 90–97 % in at least the default's count less two of the 24, none below 87 %;
#: at 25 and at 120 frames/s, 150 windows per level (``--n 150 --fs 25``, ``--fs 120``, the same seed and tag):
#: (6) median σ ratio ≤ 1.00 and largest ≤ 1.15; (7) windows off by more than 20 % at 0.1 % at most the default's + 3.
OWN_RULE = "stop 48"
#: ``own_td_switch<x>`` (stop 48, development): that form only where the window's input-error share ρ (:func:`input_share`,
#: the larger of P's and Q's) exceeds x, else the default's; x = −1 takes it everywhere and records ρ.  Per cell the
#: windows' (ρ_P, ρ_Q), in the order of ``per_window``'s rows (JSON ``rho``).
SWITCH = "own_td_switch"
RHO: dict[str, list] = {}
#: Per cell and history row, each window's staleness statistic (:func:`staleness`; JSON ``staleness``), stop 48.
STALENESS: dict[str, list] = {}
#: The staleness check's threshold, chosen on development seeds 41 and 54 (``--stale-report``: the bus's own history
#: gave at most 2.6 at its 99th percentile and above 3 in one window of 1,800 on each seed; a stale one a median of
#: 4.8–4.9).  Its confirmation
#: (stop 48, fixed before any run on seed 58: ``--seed 58 --variants hist6_guard1.5,hist6_guard1.5_of1 --tag
#: stalecheck``, read with ``--stale-report … --thresholds=3``): the check goes into the core if (1) with the bus's own
#: history it keeps at least 97 % of the windows and σ's median over the default's is within 0.005 of the unchecked
#: row's; (2) with a stale history σ's median over the default's is at most 1.00 and the windows off by more than 20 %
#: at 0.1 % at most the default's; (3) there that median is at least 0.02 below the unchecked stale row's.
STALE_THRESHOLD = 3.0
STALE_CONFIRM_SEED = 58
#: Seed 58's verdict: (1) and (2) met, (3) missed by 2e-5 (the stale row's median 1.0066, checked 0.9866: 0.01998 below
#: where 0.02 was asked).  (3) asked for a gain that depends on how much worse than none the seed's stale history is
#: (1.016–1.050 on development, 1.007 on seed 58), not on the check.  A second confirmation, fixed before any run on seed
#: 59 (``--seed 59 --variants hist6_guard1.5,hist6_guard1.5_of1 --tag stalecheck``, threshold 3 as before): (1) and (2)
#: as above; (3') with a stale history the checked row's σ median over the default's and its windows off by more than
#: 20 % at 0.1 % are at most the unchecked stale row's.
STALE_SECOND_SEED = 59
_CELL: list[str] = [""]
#: ``band5``, ``band3``: the refinement's band at 5 or 3 Hz at 100 frames/s (a twentieth, a thirty-third of the rate).
BAND_VARIANTS = {"band5": 0.05, "band3": 0.03}
#: ``gain49``, ``own_bin_out``, ``band4`` (stop 49): the smoother's gain without each bin's own periodogram in its
#: average (``noise.GAIN_WITHOUT_OWN_BIN``), the refinement's band at least 4 Hz (``input_weighting.MIN_BAND_HZ``), or
#: both (the candidate, not adopted): (GAIN_WITHOUT_OWN_BIN, MIN_BAND_HZ), None where the core's is kept.
#: Stop 50's rows (and stop 55's ``multitaper``): a core module's switch set to a value within the row
#: (:func:`core_switch`).
CORE_SWITCHES = {"band_cut": (input_weighting, "BAND_AT_CUTOFF", True), "lagrange": (motor, "SPLINE_INPUTS", False),
                 "multitaper": (noise, "GAIN_SPECTRUM", "multitaper")}
GAIN49_VARIANTS = {"gain49": (True, 4.0), "own_bin_out": (True, None), "band4": (None, 4.0)}
FLOOR_VARIANTS = {"floor_outside": "outside", "no_floor": "none", "floor_sig2": "significant_2",
                  "floor_sig1.5": "significant_1.5"}
#: ``floor_outside``: the model's S counts as having input-error content above this fraction of the white floor [-].
FLOOR_CONTENT_REL = 1e-3
WIDTHS_HZ = (0.5, 0.25, 1.0)  # today's first
_WEIGHTED_FIT = input_weighting.weighted_fit
_WIENER_SMOOTH = noise.wiener_smooth
_DISTURBANCE_SPECTRUM = input_weighting.disturbance_spectrum
_REFINE = input_weighting.refine
_BUILD_WEIGHTING = input_weighting.build_weighting
_WHITENING = input_weighting.whitening


def response_at(window, config, d0: np.ndarray, skip_s: float):
    """The window prepared as the S-weighted refinement prepares it, its :class:`Problem` simulated at d0, and the
    model's impulse response there with the plain fit's static coefficients (as the refinement forms H); None when the
    model cannot be simulated or H formed."""
    prep = preprocess.prepare(window, max_gap_samples=config.max_gap_samples, min_duration_s=config.min_duration_s,
                              floors=True, input_smoother="wiener", input_tail=config.input_spectrum_tail)
    at = _response(prep, window.f0, config, d0, skip_s)
    return None if at is None else (prep, *at)


def _response(prep, f0: float, config, d0: np.ndarray, skip_s: float):
    """(the :class:`Problem` of ``prep`` simulated at d0, the model's impulse response there with the plain fit's static
    coefficients), or None (:func:`response_at`)."""
    pb = Problem(prep, f0, replace(config, skip_s=skip_s))
    if not input_weighting._simulate(pb, d0):
        return None
    resid = np.column_stack([pb.p_meas - pb._p[pb.k0:], pb.q_meas - pb._q[pb.k0:]])
    beta = np.linalg.solve(pb.r_factor, pb.basis.T @ resid)
    h = input_weighting.impulse_response(pb, d0, beta[:, 0], beta[:, 1])
    return None if h is None else (pb, h)


def pq_spectrum(window, config, d0: np.ndarray, skip_s: float) -> noise.InputSpectrum | None:
    """The inputs' signal spectrum read through the measured P and Q at the output-error D (module docstring)."""
    at = response_at(window, config, d0, skip_s)
    if at is None:
        return None
    _, pb, h = at
    sy = noise.pooled_spectrum([noise.input_periodogram(np.vstack([pb.p_meas, pb.q_meas]), 1.0 / pb.dt)])
    hm = np.fft.rfft(h, axis=0)[:sy.freqs.size]
    try:
        hinv = np.linalg.inv(hm)
    except np.linalg.LinAlgError:
        return None
    sx = hinv @ sy.s @ hinv.conj().transpose(0, 2, 1)
    lam, vec = np.linalg.eigh(0.5 * (sx + sx.conj().transpose(0, 2, 1)))
    sx = (vec * np.maximum(lam, 0.0)[:, None, :]) @ vec.conj().transpose(0, 2, 1)
    sx[sy.freqs >= noise.FLOOR_FROM_HZ] = 0.0
    return noise.InputSpectrum(sy.freqs, sx, 1)


def whittle_power_law(f: np.ndarray, p: np.ndarray, floor: float) -> tuple[float, float]:
    """(ln A, β) of the mean A·f^−β + floor fitted to periodogram ordinates p at f by the Whittle likelihood, β ≥ 1."""
    lf = np.log(f)

    def nll(x):
        m = np.exp(x[0] - x[1] * lf) + floor
        return float(np.sum(np.log(m) + p / m))

    la0 = np.log(max(float(np.mean(p[:3])) - floor, 1e-3 * floor)) + 2.0 * lf[0]
    best = min((optimize.minimize(nll, [la0 + (b0 - 2.0) * lf[0], b0], method="Nelder-Mead",
                                  options={"xatol": 1e-4, "fatol": 1e-6, "maxiter": 400}) for b0 in (1.5, 3.0, 5.0)),
               key=lambda r: r.fun)
    return float(best.x[0]), max(float(best.x[1]), 1.0)


def own_spectrum(window, config, whittle: bool) -> noise.InputSpectrum:
    """The window's own estimate on its grid, zero above each input's cut-off, continued to 5 Hz by a power law
    (``ptail``, or ``wpl`` with ``whittle``), the cross-spectrum there at the coherence of [cut-off / 2, cut-off)."""
    pm = preprocess.prepare(window, max_gap_samples=config.max_gap_samples, min_duration_s=0.0)
    x, fs = np.stack([pm.V, pm.theta]), 1.0 / pm.dt
    per = noise.input_periodogram(x, fs)
    own = noise.pooled_spectrum([per])
    f, s = own.freqs, own.s.copy()
    _, cuts = _WIENER_SMOOTH(x, fs, np.sqrt(per.floor), return_cutoffs=True)
    k_top = int(np.searchsorted(f, noise.FLOOR_FROM_HZ))
    ends = [int(np.searchsorted(f, c)) for c in cuts]
    for i, e in enumerate(ends):
        s[e:, i, :] = 0.0
        s[e:, :, i] = 0.0
    for i, e in enumerate(ends):
        if e >= k_top:
            continue
        lo, k = max(1, e // 2), np.arange(e, k_top)
        if whittle:
            la, b = whittle_power_law(f[lo:k_top], per.p[lo:k_top, i, i].real, float(per.floor[i]))
            s[k, i, i] = np.exp(la - b * np.log(f[k]))
        else:
            band = np.arange(lo, e)
            band = band[s[band, i, i].real > 0]
            if band.size >= 3:
                slope, level = np.polyfit(np.log(f[band]), np.log(s[band, i, i].real), 1)
                s[k, i, i] = np.exp(level + min(slope, -1.0) * np.log(f[k]))
    first = min(ends)
    if first < k_top:
        band = np.arange(max(1, first // 2), first)
        sa, sd, sb = s[band, 0, 0].real.sum(), s[band, 1, 1].real.sum(), s[band, 0, 1].sum()
        if sa > 0 and sd > 0:
            coh = sb / np.sqrt(sa * sd)
            coh *= min(1.0, 0.999 / max(abs(coh), 1e-12))
            k = np.arange(first, k_top)
            s[k, 0, 1] = coh * np.sqrt(s[k, 0, 0].real * s[k, 1, 1].real)
            s[k, 1, 0] = s[k, 0, 1].conj()
    s[k_top:] = 0.0
    return noise.InputSpectrum(f, s, 1)


def em_spectrum(window, config, d0: np.ndarray, skip_s: float, iters: int = 30) -> noise.InputSpectrum | None:
    """The inputs' signal spectrum by the joint likelihood of the measured V, θ, P and Q with the inputs latent (``em``):
    per rfft bin of the regression samples u = x + n, y = H·x + v (H the model's response at the output-error D, as
    the refinement forms it; n, v white at the window's floors), x ~ CN(0, S_x); EM over x, its M-step averaged over
    the smoother's width (0.5 Hz) as the window's own estimate is, from that estimate plus a tenth of the floor; zero
    from 5 Hz."""
    at = response_at(window, config, d0, skip_s)
    if at is None:
        return None
    prep, pb, h = at
    k0, l = pb.k0, pb.l
    raw = preprocess.prepare(window, max_gap_samples=config.max_gap_samples, min_duration_s=0.0)
    x = np.stack([raw.V[k0:], raw.theta[k0:], pb.p_meas, pb.q_meas])
    taper, ww = noise._taper(l)
    z = np.fft.rfft(noise._detrend(x) * taper, axis=1) / math.sqrt(ww)  # E|z|² = the per-sample spectrum
    freqs = np.fft.rfftfreq(l, pb.dt)
    m = freqs.size
    # h[k] is the response k − 2 samples after the impulse: undo that delay for y = H·x bin by bin.
    hf = np.fft.rfft(h, axis=0) * np.exp(2j * np.pi * 2.0 * np.arange(m) / l)[:, None, None]
    ru = np.array([prep.noise["noise_v"] ** 2, prep.noise["noise_theta"] ** 2])
    ry = np.array([prep.noise["noise_p"] ** 2, prep.noise["noise_q"] ** 2])
    if np.any(ru <= 0.0) or np.any(ry <= 0.0):
        return None
    top = int(np.searchsorted(freqs, noise.FLOOR_FROM_HZ))
    k = np.arange(1, top)
    u, y, hk = z[:2, k].T, z[2:, k].T, hf[k]
    own = noise.spectrum_at(noise.pooled_spectrum([noise.input_periodogram(x[:2], 1.0 / pb.dt)]), freqs[k])
    s = own + 0.1 * np.diag(ru)
    hr = hk.conj().transpose(0, 2, 1) / ry[None, None, :]  # Hᴴ·R_y⁻¹
    prec = np.diag(1.0 / ru)[None] + hr @ hk
    b = u / ru[None, :] + (hr @ y[:, :, None])[:, :, 0]
    width = max(1, int(round(noise.WIENER_SMOOTH_HZ * l * pb.dt)))
    for _ in range(iters):
        cov = np.linalg.inv(np.linalg.inv(s) + prec)
        mu = (cov @ b[:, :, None])[:, :, 0]
        e = np.einsum("ki,kj->kij", mu, mu.conj()) + cov
        s = np.empty_like(e)
        for i in range(2):
            for j in range(2):
                s[:, i, j] = noise._moving_average(e[:, i, j], width)
        s = 0.5 * (s + s.conj().transpose(0, 2, 1)) + 1e-12 * np.diag(ru)[None]
    out = np.zeros((m, 2, 2), dtype=complex)
    out[k] = s
    return noise.InputSpectrum(freqs, out, 1)


def _spectrum(variant: str, window, config, d0, skip_s) -> noise.InputSpectrum | None:
    if variant == "em":
        return em_spectrum(window, config, d0, skip_s)
    if variant in ("ptail", "wpl"):
        return own_spectrum(window, config, whittle=variant == "wpl")
    pq = pq_spectrum(window, config, d0, skip_s)
    if pq is None or variant == "pq":
        return pq
    own = noise.spectrum_at(noise.pooled_spectrum([preprocess.input_periodogram(window, config.max_gap_samples)]),
                                pq.freqs)
    return noise.InputSpectrum(pq.freqs, 0.5 * (pq.s + own), 1)


@contextlib.contextmanager
def spectrum_variant(variant: str):
    """Within the block, the S-weighted refinement's smoother is given the variant's spectrum (module docstring)."""
    def fit(window, config, d0, skip_s, floors, margin, input_spectrum=None):
        if input_spectrum is None and input_weighting.noisy_inputs(floors):
            spec = _spectrum(variant, window, config, d0, skip_s)
            if spec is not None:
                return _WEIGHTED_FIT(window, config, d0, skip_s, floors, margin, input_spectrum=spec)
        return _WEIGHTED_FIT(window, config, d0, skip_s, floors, margin, input_spectrum=input_spectrum)

    input_weighting.weighted_fit = fit
    try:
        yield
    finally:
        input_weighting.weighted_fit = _WEIGHTED_FIT


def staleness(window, spectrum: noise.InputSpectrum) -> float:
    """The core's staleness of a window's inputs against a history's spectrum
    (:func:`aslm_core.input_history.staleness`)."""
    fs = 1.0 / float(np.median(np.diff(window.t)))
    return input_history.staleness(noise.input_periodogram(np.stack([window.V, window.theta]), fs), spectrum)


@contextlib.contextmanager
def _refits_counted(label: str, count: bool = True):
    """Within the block, :func:`aslm_core.input_weighting.build_weighting`'s calls are watched: the history's form asks
    for S without the floor first, and a later call with it is the guard's refit (or a fallback, which appends True to
    the yielded list itself); with ``count``, whether one happened is added to :data:`GUARD_FIRED` under ``label``."""
    old = input_weighting.build_weighting
    floors: list[bool] = []

    def counted(*args, **kwargs):
        floors.append(args[6] if len(args) > 6 else kwargs.get("residual_floor", True))
        return old(*args, **kwargs)

    input_weighting.build_weighting = counted
    try:
        yield floors
    finally:
        input_weighting.build_weighting = old
        if count:
            fired = False in floors and any(floors[floors.index(False) + 1:])
            GUARD_FIRED[label] = GUARD_FIRED.get(label, 0) + int(fired)


def _number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def input_share(prep, f0: float, config, d0: np.ndarray, skip_s: float) -> tuple[float, float]:
    """(ρ_P, ρ_Q): below 5 Hz (or a tenth of the rate), the mean over the bins of the input error's part of the
    refinement's S over the white floor, (S_ii − σ_i²)/σ_i², at the output-error D; NaN where it cannot be formed."""
    at = _response(prep, f0, config, np.asarray(d0, float), skip_s)
    if at is None:
        return math.nan, math.nan
    pb, h = at
    freqs = np.fft.rfftfreq(pb.l, pb.dt)
    white = (prep.noise["noise_p"] ** 2, prep.noise["noise_q"] ** 2)
    s = input_weighting.disturbance_spectrum(h, freqs, *prep.input_error, white)
    sel = (freqs > 0) & (freqs < min(noise.FLOOR_FROM_HZ, input_weighting.BAND_FRACTION / pb.dt))
    return tuple(float(np.mean(s[sel, c, c].real - white[c]) / white[c]) for c in (0, 1))


@contextlib.contextmanager
def own_history_form(variant: str):
    """Within the block, the refinement takes the history's form (:func:`aslm_core.input_weighting.refine`'s
    ``history``) on every noisy window, with the window's own spectrum, the guard :data:`OWN_FORMS`'s; refits with the
    floor counted in :data:`GUARD_FIRED`."""
    old = (input_weighting.refine, input_weighting.HISTORY_BAND_HZ, input_weighting.HISTORY_CHI2_MAX)
    input_weighting.HISTORY_BAND_HZ = noise.FLOOR_FROM_HZ
    input_weighting.HISTORY_CHI2_MAX = (None if variant.startswith("own_td_fallback")
                                        else 1.5 if variant.startswith(SWITCH) else OWN_FORMS[variant])
    try:
        with _refits_counted(variant) as floors:

            def refine(prep, f0, config, d0, skip_s, margin, history=False):
                if variant.startswith(SWITCH):
                    rho = input_share(prep, f0, config, d0, skip_s)
                    RHO.setdefault(_CELL[0], []).append(rho)
                    return old[0](prep, f0, config, d0, skip_s, margin,
                                  history=max(rho) > float(variant[len(SWITCH):]))
                out = old[0](prep, f0, config, d0, skip_s, margin, history=True)
                if not variant.startswith("own_td_fallback") or (out is not None
                                                                 and out["chi2"] <= OWN_FORMS[variant]):
                    return out
                floors.append(True)  # the fallback, counted as the guard's refit
                return old[0](prep, f0, config, d0, skip_s, margin, history=False)

            input_weighting.refine = refine
            yield
    finally:
        input_weighting.refine, input_weighting.HISTORY_BAND_HZ, input_weighting.HISTORY_CHI2_MAX = old


@contextlib.contextmanager
def smoother_width(hz: float):
    """Within the block, every call of the Wiener smoother averages its cross-spectrum over ``hz`` [Hz]."""
    def smooth(*args, **kwargs):
        kwargs["smooth_hz"] = hz
        return _WIENER_SMOOTH(*args, **kwargs)

    noise.wiener_smooth = smooth
    try:
        yield
    finally:
        noise.wiener_smooth = _WIENER_SMOOTH


@contextlib.contextmanager
def core_switch(module, name: str, value):
    """Within the block, ``module.name`` is ``value``; restored afterwards."""
    old = getattr(module, name)
    setattr(module, name, value)
    try:
        yield
    finally:
        setattr(module, name, old)


@contextlib.contextmanager
def smoother_gain(own_bin_out: bool | None, min_band_hz: float | None):
    """Within the block, the smoother's gain with or without each bin's own periodogram and the refinement's lowest band
    as given (None: as the core has it)."""
    old = noise.GAIN_WITHOUT_OWN_BIN, input_weighting.MIN_BAND_HZ
    noise.GAIN_WITHOUT_OWN_BIN = old[0] if own_bin_out is None else own_bin_out
    input_weighting.MIN_BAND_HZ = old[1] if min_band_hz is None else min_band_hz
    try:
        yield
    finally:
        noise.GAIN_WITHOUT_OWN_BIN, input_weighting.MIN_BAND_HZ = old


@contextlib.contextmanager
def residual_floor(mode: str):
    """Within the block, the refinement's S keeps the residual periodogram's floor on its diagonal only where the
    model's S has no input-error content (``outside``), only where the floored diagonal exceeds c times the model's
    (``significant_<c>``: the residual's excess over S is significant; its periodogram averaged over 1 Hz of a 10 s
    window has about 20 degrees of freedom, so c = 2 is about its 99.5 % quantile under the model, c = 1.5 its 93 %), or
    drops it (``none``)."""
    model: dict = {}

    def spectrum(h, freqs, px_freqs, px, white_var):
        s = _DISTURBANCE_SPECTRUM(h, freqs, px_freqs, px, white_var)
        model["s"], model["white"] = s.copy(), white_var
        return s

    def whitening(s):
        if "s" in model:
            for c in range(2):
                if mode.startswith("significant_"):
                    keep = s[:, c, c].real < float(mode.split("_", 1)[1]) * model["s"][:, c, c].real
                else:
                    keep = model["s"][:, c, c].real - model["white"][c] > FLOOR_CONTENT_REL * model["white"][c]
                s[keep, c, c] = model["s"][keep, c, c]
        return _WHITENING(s)

    old = input_weighting.RESIDUAL_SMOOTH_HZ
    if mode == "none":
        input_weighting.RESIDUAL_SMOOTH_HZ = 0.0
    else:
        input_weighting.disturbance_spectrum, input_weighting.whitening = spectrum, whitening
    try:
        yield
    finally:
        input_weighting.RESIDUAL_SMOOTH_HZ = old
        input_weighting.disturbance_spectrum, input_weighting.whitening = _DISTURBANCE_SPECTRUM, _WHITENING


def _measure(window, truth, config=TAIL, input_spectrum=None) -> tuple[list[float], list[float]]:
    """D/D_real and the standard errors over D_real of the identifier (default: the default) on the window (NaN where it
    refuses)."""
    try:
        r = identify(window, config=config, input_spectrum=input_spectrum)
    except WindowError:
        return [math.nan] * 4, [math.nan] * 4
    return (r.d / truth).tolist(), (np.array([r.stderr[p] for p in common.PARAMS]) / truth).tolist()


def history_measure(variant: str, periodograms: list, window, truth,
                    label: str | None = None) -> tuple[list[float], list[float]]:
    """The default given the spectrum of an :class:`~aslm_core.input_history.InputHistory` holding the periodograms
    (consecutive windows ending before the identified one), in the variant's form (:data:`HISTORY_FORMS`): ``hist6``
    stop 41's (smoothed over 0.5 Hz, the window's own refinement form); ``hist6_fine_td`` unsmoothed, the refinement in
    the time domain below 5 Hz without the residual floor; ``hist6_guard*`` that, redone with the floor above the χ².
    Counts in :data:`GUARD_FIRED` (under ``label``, the variant by default) whether the fit was redone with the floor."""
    old = (input_history.HISTORY_SMOOTH_HZ, input_weighting.HISTORY_BAND_HZ, input_weighting.HISTORY_CHI2_MAX,
           input_history.HISTORY_STALE_MAX)
    (input_history.HISTORY_SMOOTH_HZ, input_weighting.HISTORY_BAND_HZ, input_weighting.HISTORY_CHI2_MAX,
     input_history.HISTORY_STALE_MAX) = HISTORY_FORMS[variant]
    try:
        spectrum = pooled_history(periodograms)
        STALENESS.setdefault(_CELL[0], []).append(staleness(window, spectrum))
        with _refits_counted(label or variant, count=HISTORY_FORMS[variant][2] is not None):
            return _measure(window, truth, input_spectrum=spectrum)
    finally:
        (input_history.HISTORY_SMOOTH_HZ, input_weighting.HISTORY_BAND_HZ, input_weighting.HISTORY_CHI2_MAX,
         input_history.HISTORY_STALE_MAX) = old


def run(n: int, seed: int, variants: list[str], fs: float = 100.0) -> tuple[dict, dict, dict]:
    """Per level, noisy class and row (``default`` and the variants' rows): the per-window D/D_real, and their
    standard errors over D_real (the median of the widths takes the 0.5 Hz run's, the run nearest it its own); and
    the median ms per identification of the default and the history variants (each window's rows run in turn, one
    thread)."""
    cases = {level: common.cases(n, level=level, seed=seed, fs=fs) for level in LEVELS}
    rngs = {(level, k): np.random.default_rng([seed, level, k]) for level in LEVELS for k in range(len(INPUT_NOISE))}
    per: dict[str, list] = {}
    per_se: dict[str, list] = {}
    times: dict[str, list] = {}  # row -> seconds per identification (history variants and the default)
    history: dict = {}
    t0 = time.perf_counter()
    for i in range(n):
        for level in LEVELS:
            c = cases[level][i]
            for k, (cls, v_rel, th) in enumerate(INPUT_NOISE):
                w = with_input_noise(c.window, c.clean, v_rel, th, rngs[level, k])  # drawn for every class, as there
                if cls == "none":
                    continue
                t1 = time.perf_counter()
                rows = {"default": _measure(w, c.truth.d)}
                times.setdefault("default", []).append(time.perf_counter() - t1)
                for variant in variants:
                    if variant in HISTORY_VARIANTS or variant.removesuffix(STALE) in HISTORY_VARIANTS:
                        # A stale history (suffix _of1) is the next case's own: another load and network.
                        j = (i + 1) % n if variant.endswith(STALE) else i
                        if (j, k) not in history:
                            history[j, k] = history_periodograms(cases[LEVELS[0]][j], HISTORY_K, v_rel, th,
                                                                 np.random.default_rng([seed, 7, j, k]))
                        _CELL[0] = f"{level}|{cls}|{variant}"
                        t1 = time.perf_counter()
                        rows[variant] = history_measure(variant.removesuffix(STALE), history[j, k], w, c.truth.d, variant)
                        times.setdefault(variant, []).append(time.perf_counter() - t1)
                    elif variant == "widths":
                        runs = [rows["default"]]
                        for hz in WIDTHS_HZ[1:]:
                            with smoother_width(hz):
                                runs.append(_measure(w, c.truth.d))
                        rows["widths_runs"] = ([r for r, _ in runs], [e for _, e in runs])
                    elif variant in BAND_VARIANTS:  # a fraction of the rate, without stop 49's 4 Hz cap (as they ran)
                        old = input_weighting.BAND_FRACTION, input_weighting.MAX_BAND_HZ
                        input_weighting.BAND_FRACTION, input_weighting.MAX_BAND_HZ = BAND_VARIANTS[variant], math.inf
                        try:
                            rows[variant] = _measure(w, c.truth.d)
                        finally:
                            input_weighting.BAND_FRACTION, input_weighting.MAX_BAND_HZ = old
                    elif variant.startswith("cap"):
                        old = input_weighting.MAX_BAND_HZ
                        input_weighting.MAX_BAND_HZ = float(variant[3:])
                        try:
                            rows[variant] = _measure(w, c.truth.d)
                        finally:
                            input_weighting.MAX_BAND_HZ = old
                    elif variant in CORE_SWITCHES:
                        with core_switch(*CORE_SWITCHES[variant]):
                            rows[variant] = _measure(w, c.truth.d)
                    elif variant in GAIN49_VARIANTS:
                        with smoother_gain(*GAIN49_VARIANTS[variant]):
                            rows[variant] = _measure(w, c.truth.d)
                    elif variant in OWN_FORMS or variant.startswith(SWITCH):
                        _CELL[0] = f"{level}|{cls}|{variant}"
                        t1 = time.perf_counter()
                        with own_history_form(variant):
                            rows[variant] = _measure(w, c.truth.d)
                        times.setdefault(variant, []).append(time.perf_counter() - t1)
                    elif variant in FLOOR_VARIANTS:
                        with residual_floor(FLOOR_VARIANTS[variant]):
                            rows[variant] = _measure(w, c.truth.d)
                    else:
                        with spectrum_variant(variant):
                            rows[variant] = _measure(w, c.truth.d)
                for name, (r, e) in rows.items():
                    per.setdefault(f"{level}|{cls}|{name}", []).append(r)
                    per_se.setdefault(f"{level}|{cls}|{name}", []).append(e)
        if (i + 1) % 50 == 0:
            print(f"{i + 1} windows ({time.perf_counter() - t0:.0f} s)", flush=True)
    for key in [k for k in per if k.endswith("|widths_runs")]:
        base = key.rsplit("|", 1)[0]
        runs, ses = np.array(per.pop(key)), np.array(per_se.pop(key))
        med, mdo, pick = combine_widths(runs)
        rows_ = np.arange(runs.shape[0])
        per[f"{base}|widths_median"], per_se[f"{base}|widths_median"] = med.tolist(), ses[:, 0].tolist()
        per[f"{base}|widths_medoid"], per_se[f"{base}|widths_medoid"] = mdo.tolist(), ses[rows_, pick].tolist()
    ms = {k: 1e3 * float(np.median(v)) for k, v in times.items()}
    return per, per_se, ms


def combine_widths(runs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """From runs (windows, widths, 4) of D/D_real, each window's per-parameter median, the run nearest it (L1
    distance in units of each parameter's spread over the windows of the first width's run) and that run's index."""
    med = np.nanmedian(runs, axis=1)
    scale = np.nanstd(runs[:, 0], axis=0, ddof=1)
    dist = np.nansum(np.abs(runs - med[:, None, :]) / scale, axis=2)
    pick = np.argmin(np.where(np.isfinite(dist), dist, np.inf), axis=1)
    return med, runs[np.arange(runs.shape[0]), pick], pick


def coverage(per: dict, per_se: dict) -> dict[str, list[float]]:
    """Per row, the share of windows with |D/D_real − 1| < 1.96·SE in each noisy cell × parameter (24 per row)."""
    out: dict[str, list[float]] = {}
    for key, r in per.items():
        r, e = np.array(r), np.array(per_se[key])
        ok = np.all(np.isfinite(r), axis=1) & np.all(np.isfinite(e), axis=1)
        out.setdefault(key.rsplit("|", 1)[1], []).extend(np.mean(np.abs(r[ok] - 1.0) < 1.96 * e[ok], axis=0).tolist())
    return out


def summary(per: dict, base: str = "default") -> dict:
    """Per row other than ``base``: σ over the base row's per (level, class, parameter) (median, range and where the
    largest is), and the windows off by more than 20 % per class for both (base, row)."""
    names = sorted({k.rsplit("|", 1)[1] for k in per} - {base})
    out = {}
    for name in names:
        ratios, cells, off, tm = [], [], {}, []
        for key in (k for k in per if k.endswith("|" + name)):
            level, cls, _ = key.split("|")
            d, m = np.array(per[f"{level}|{cls}|{base}"]), np.array(per[key])
            ok = np.all(np.isfinite(d), axis=1) & np.all(np.isfinite(m), axis=1)
            r = m[ok].std(axis=0, ddof=1) / d[ok].std(axis=0, ddof=1)
            ratios.append(r)
            cells.extend(f"{p} at DL {level} / {cls}" for p in common.PARAMS)
            if cls.startswith("0.1"):
                tm.append((int(level), float(r[3])))
            o = off.setdefault(cls, [0, 0])
            o[0] += int(np.sum(np.any(np.abs(d[ok] - 1.0) > 0.2, axis=1)))
            o[1] += int(np.sum(np.any(np.abs(m[ok] - 1.0) > 0.2, axis=1)))
        r = np.array(ratios)
        out[name] = {"base": base, "sigma_ratio_median": float(np.median(r)), "sigma_ratio_min": float(r.min()),
                     "sigma_ratio_max": float(r.max()), "sigma_ratio_max_at": cells[int(np.argmax(r))],
                     "tm_ratio_01pct": [x for _, x in sorted(tm)], "off_20pct_base_variant": off}
    return out


def bound_ratios(per: dict, bounds_path, drop: int = 0) -> dict[str, np.ndarray] | None:
    """Per key of ``per`` (level|class|row), σ of D/D_real over the RMS structural bound per parameter, from
    ``input_noise_bound --n N``'s per-window bounds (seed 43's windows: the same windows and draws); None when that
    file is absent or holds fewer windows.  ``drop``: σ without the ``drop`` windows farthest from the parameter's
    median (how much of it a few windows make; the bound over all windows)."""
    if not bounds_path.exists():
        return None
    bounds = json.loads(bounds_path.read_text())["per_window_relative_variance"]
    n = len(next(iter(per.values())))
    if len(bounds) < n:
        return None
    out: dict[str, np.ndarray] = {}
    for key, r in per.items():
        level, cls, _ = key.split("|")
        r = np.array(r)
        ok = np.all(np.isfinite(r), axis=1)
        var = np.array([w[level][f"{cls}|structural"] for w in bounds[:n]])[ok]
        r = r[ok]
        far = np.argsort(-np.abs(r - np.median(r, axis=0)), axis=0)[:drop]  # per parameter
        keep = np.ones(r.shape, dtype=bool)
        keep[far, np.arange(4)] = False
        sd = np.array([r[keep[:, j], j].std(ddof=1) for j in range(4)])
        out[key] = sd / np.sqrt(var.mean(axis=0))
    return out


def honest_counts(per: dict, bounds_path, drop: int = 0) -> dict[str, int] | None:
    """Per row, issue 11's honest version on these windows: the noisy cells × parameters whose σ of D/D_real is at most
    1.3 × the RMS structural bound (:func:`bound_ratios`, with its ``drop``); None where those are."""
    ratios = bound_ratios(per, bounds_path, drop)
    if ratios is None:
        return None
    out: dict[str, int] = {}
    for key, r in ratios.items():
        name = key.rsplit("|", 1)[1]
        out[name] = out.get(name, 0) + int(np.sum(r <= 1.3))
    return out


#: Stored per-window structural bounds by seed: the file and the key of the bound (seed 43: ``input_noise_bound --n 300``'s
#: time-domain structural bound; seed 53: ``input_noise_bound_spectrum``'s bound with the inputs' spectrum known).
BOUNDS_BY_SEED = {43: ("input_noise_bound_n300", "structural"), 53: ("input_noise_bound_spectrum_seed53", "known")}


def vouched_ratios(run: dict, row: str = "default", se_max: float = IV_SE_MAX) -> dict[str, dict]:
    """Issue 11's honest version read on the answers the identifier vouches for: per noisy cell, σ of D/D_real over the
    windows whose every standard error is at most ``se_max`` of its parameter (those without ``error_may_exceed_20pct``,
    :data:`aslm_core.identify.IV_SE_MAX`) against the RMS structural bound over the same windows, beside the same over all
    windows.  A selection by the estimator's own output, so a user can make it; not the target (σ over every window)."""
    path, key = BOUNDS_BY_SEED[run["seed"]]
    bounds = common.read_json(path)["per_window_relative_variance"]
    out = {}
    for cell, r in run["per_window"].items():
        level, cls, name = cell.split("|")
        if name != row:
            continue
        r, se = np.array(r), np.array(run["per_window_se"][cell])
        var = np.array([w[level][f"{cls}|{key}"] for w in bounds[:len(r)]])
        ok = np.all(np.isfinite(r), axis=1) & np.all(np.isfinite(se), axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            kept = ok & np.all(se <= se_max * np.abs(r), axis=1)
        out[f"{level}|{cls}"] = {
            "n": int(ok.sum()), "kept": int(kept.sum()),
            "all": (r[ok].std(axis=0, ddof=1) / np.sqrt(var[ok].mean(axis=0))).tolist(),
            "vouched": (r[kept].std(axis=0, ddof=1) / np.sqrt(var[kept].mean(axis=0))).tolist(),
            "off_20pct_kept": int(np.sum(np.any(np.abs(r[kept] - 1) > 0.2, axis=1))),
            "off_20pct_dropped": int(np.sum(np.any(np.abs(r[ok & ~kept] - 1) > 0.2, axis=1)))}
    return out


def vouched_report(name: str, row: str = "default") -> dict:
    """``--vouched-report``: :func:`vouched_ratios` of a stored run, printed."""
    res = vouched_ratios(common.read_json(name), row)
    rows = [[cell.split("|")[0], cell.split("|")[1], f"{c['kept']} of {c['n']}",
             " / ".join(f"{x:.2f}" for x in c["all"]), " / ".join(f"{x:.2f}" for x in c["vouched"]),
             f"{c['off_20pct_kept']} / {c['off_20pct_dropped']}"] for cell, c in res.items()]
    print(common.md_table(["DL", "input noise", "vouched for", "σ / bound, all windows", "σ / bound, vouched for",
                           "off > 20 %: vouched / not"], rows))
    met_all = sum(int(np.sum(np.array(c["all"]) <= 1.3)) for c in res.values())
    met_kept = sum(int(np.sum(np.array(c["vouched"]) <= 1.3)) for c in res.values())
    print(f"σ ≤ 1.3 × the bound, cells × parameters of {4 * len(res)}: all windows {met_all}, vouched for {met_kept}")
    return {"cells": res, "met_all": met_all, "met_vouched": met_kept}


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=None, help="windows per level (default 300; --quick 3)")
    ap.add_argument("--seed", type=int, default=41, help="seed of the windows and draws (41, 43, 45: development)")
    ap.add_argument("--variants", default=",".join(VARIANTS[:5]),
                    help=f"comma-separated, of {', '.join(VARIANTS)} (default: stop 44's five)")
    ap.add_argument("--tag", default="", help="suffix of the JSON's name (e.g. floor), so runs of other variants sit beside")
    ap.add_argument("--fs", type=float, default=100.0, help="reporting rate [frames/s] (JSON name suffix _fs<rate> if not 100)")
    ap.add_argument("--against", default="default", help="the row σ ratios and far-off counts are taken against")
    ap.add_argument("--switch-report", nargs="+", metavar="NAME", default=None,
                    help="no run: stored runs with own_td_switch-1 rows composed at each --thresholds (stop 48)")
    ap.add_argument("--stale-report", nargs="+", metavar="NAME", default=None,
                    help="no run: stored runs with hist6_guard1.5 and its _of1 row composed with the staleness check "
                         "at each --thresholds (stop 48)")
    ap.add_argument("--thresholds", default="0,1,3,10,30,100",
                    help="--switch-report: the input-error shares tried; --stale-report: the staleness thresholds")
    ap.add_argument("--report", nargs="+", metavar="NAME", default=None,
                    help="no run: the summary of stored runs (docs/results/NAME.json, their rows merged; the same seed "
                         "and windows), e.g. input_noise_variants_seed55_confirm --against hist6")
    ap.add_argument("--vouched-report", metavar="NAME", default=None,
                    help="no run: issue 11's honest version on the answers without error_may_exceed_20pct, from a stored "
                         "run on seed 43 or 53 (stop 51)")
    args = ap.parse_args(argv)
    if args.vouched_report:
        return vouched_report(args.vouched_report)
    if args.stale_report:
        return stale_report(args.stale_report, [float(x) for x in args.thresholds.split(",")])
    if args.switch_report:
        return switch_report(args.switch_report, [float(x) for x in args.thresholds.split(",")])
    if args.report:
        return report(args.report, args.against)
    variants = [v for v in args.variants.split(",") if v]
    unknown = sorted(set(variants) - set(VARIANTS) - {h + STALE for h in HISTORY_VARIANTS}
                     - {v for v in variants if v.startswith(SWITCH) and _number(v[len(SWITCH):])})
    if unknown:
        raise SystemExit(f"unknown variants {unknown}; known: {', '.join(VARIANTS)}")
    n = args.n or (3 if args.quick else 300)
    t0 = time.perf_counter()
    GUARD_FIRED.clear()
    RHO.clear()
    STALENESS.clear()
    per, per_se, ms = run(n, args.seed, variants, args.fs)
    if GUARD_FIRED:
        print("history form refitted with the floor by its χ² guard, windows: "
              + ", ".join(f"{k} {v}" for k, v in GUARD_FIRED.items()))
    summ, cover, honest = print_summary(per, per_se, args.seed, args.against)
    print("ms per identification, median: " + ", ".join(f"{k} {v:.1f}" for k, v in ms.items()))
    out = {"machine": common.machine(), "n": n, "seed": args.seed, "fs": args.fs, "variants": variants, "summary": summ,
           "honest_version_met": honest, "coverage_95": cover, "per_window_se": per_se,
           "ms_median": ms, "guard_fired": dict(GUARD_FIRED), "rho": dict(RHO), "staleness": dict(STALENESS), "per_window": per, "total_s": time.perf_counter() - t0, "load_avg_at_end": os.getloadavg()}
    if not args.no_write:
        common.write_json(f"input_noise_variants_seed{args.seed}" + (f"_{args.tag}" if args.tag else "")
                          + (f"_fs{args.fs:g}" if args.fs != 100.0 else "")
                          + ("_quick" if args.quick else ""), out)
    return out


def print_summary(per: dict, per_se: dict, seed: int, against: str = "default") -> tuple[dict, dict, dict | None]:
    """Print (and return) the rows' coverage, their :func:`summary` against ``against`` and, on seed 43's windows,
    issue 11's honest version with each row's σ over the structural bound per cell."""
    summ = summary(per, against)
    cover = coverage(per, per_se)
    print("coverage of ±1.96 SE over the noisy cells × parameters, min–max (inside 90–97 % of 24): "
          + "; ".join(f"{k} {100 * min(v):.0f}–{100 * max(v):.0f} % ({sum(0.90 <= x <= 0.97 for x in v)})"
                      for k, v in sorted(cover.items())))
    for name, s in summ.items():
        print(f"{name:14s} σ / {against} median {s['sigma_ratio_median']:.3f} ({s['sigma_ratio_min']:.2f}–"
              f"{s['sigma_ratio_max']:.3f}, largest {s['sigma_ratio_max_at']}); Tm at 0.1 %, DL 1/2/3: "
              + " / ".join(f"{x:.2f}" for x in s["tm_ratio_01pct"])
              + f"; off > 20 % {against} → variant: "
              + ", ".join(f"{cls}: {a} → {b}" for cls, (a, b) in s["off_20pct_base_variant"].items()))
    path = common.RESULTS / "input_noise_bound_n300.json"
    honest = honest_counts(per, path) if seed == 43 else None
    if honest:
        print("issue 11's honest version (σ ≤ 1.3 × the structural bound), noisy cells × parameters met of 24: "
              + ", ".join(f"{k} {v}" for k, v in sorted(honest.items())))
        for key, r in bound_ratios(per, path).items():
            print(f"  σ / bound {key}: " + " / ".join(f"{x:.2f}" for x in r))
        # How much of the miss one window per cell and parameter makes (stop 49): not the target, a diagnosis.
        print("  the same without each cell's one window farthest from the median, per parameter: "
              + ", ".join(f"{k} {v}" for k, v in sorted(honest_counts(per, path, drop=1).items())))
    return summ, cover, honest


def report(names: list[str], against: str = "default") -> dict:
    """``--report``: :func:`print_summary` of stored runs, their rows merged (they must share seed and windows)."""
    runs = [json.loads((common.RESULTS / f"{name}.json").read_text()) for name in names]
    if len({r["seed"] for r in runs}) != 1 or len({r["n"] for r in runs}) != 1:
        raise SystemExit(f"--report: runs of different seeds or sizes: {[(r['seed'], r['n']) for r in runs]}")
    per = {k: v for r in runs for k, v in r["per_window"].items()}
    per_se = {k: v for r in runs for k, v in r["per_window_se"].items()}
    summ, cover, honest = print_summary(per, per_se, runs[0]["seed"], against)
    return {"summary": summ, "coverage_95": cover, "honest_version_met": honest}


def switched(run: dict, threshold: float) -> tuple[dict, dict, float]:
    """A stored run's ``default`` and ``own_td_switch-1`` rows composed window by window as ``own_td_switch<threshold>``
    would answer (the history's form where the window's larger input-error share ρ exceeds the threshold, the default's
    answer elsewhere), with its standard errors; and the share of noisy windows switched."""
    per, per_se = {}, {}
    on = total = 0
    for key, rho in run["rho"].items():
        level, cls, row = key.split("|")
        base = f"{level}|{cls}|default"
        use = [max(r) > threshold if np.all(np.isfinite(r)) else False for r in rho]
        name = f"{level}|{cls}|switch{threshold:g}"
        per[base], per_se[base] = run["per_window"][base], run["per_window_se"][base]
        per[name] = [t if u else d for u, t, d in zip(use, run["per_window"][key], per[base], strict=True)]
        per_se[name] = [t if u else d for u, t, d in zip(use, run["per_window_se"][key], per_se[base], strict=True)]
        on += sum(use)
        total += len(use)
    return per, per_se, on / max(total, 1)


def switch_report(names: list[str], thresholds: list[float]) -> dict:
    """``--switch-report``: per stored run with ``own_td_switch-1`` rows and each threshold, the composed row's σ ratios
    against the default (median, largest, DL 3 / 0.1 %), far-off windows at 0.1 % and coverage inside 90–97 %."""
    out = {}
    for name in names:
        run = json.loads((common.RESULTS / f"{name}.json").read_text())
        for x in thresholds:
            per, per_se, share = switched(run, x)
            s = summary(per)[f"switch{x:g}"]
            cover = coverage(per, per_se)
            inside = {k: int(np.sum((np.array(v) >= 0.9) & (np.array(v) <= 0.97))) for k, v in cover.items()}
            d3 = f"3|{INPUT_NOISE[2][0]}|"
            dl3 = (np.array(per[d3 + f"switch{x:g}"]).std(axis=0, ddof=1)
                   / np.array(per[d3 + "default"]).std(axis=0, ddof=1)) if d3 + "default" in per else None
            off = s["off_20pct_base_variant"][INPUT_NOISE[2][0]]
            out[f"{name}|{x:g}"] = {"switched": share, "median": s["sigma_ratio_median"], "max": s["sigma_ratio_max"],
                                    "max_at": s["sigma_ratio_max_at"], "off_01": off, "inside": inside,
                                    "dl3_01": None if dl3 is None else dl3.tolist()}
            print(f"{name} x={x:g}: switched {100 * share:.0f} %, median {s['sigma_ratio_median']:.3f}, largest "
                  f"{s['sigma_ratio_max']:.3f} ({s['sigma_ratio_max_at']}), DL 3 / 0.1 % "
                  + ("–" if dl3 is None else " / ".join(f"{v:.2f}" for v in dl3))
                  + f", far-off at 0.1 % {off[0]} → {off[1]}, coverage inside default {inside['default']} → "
                  f"{inside[f'switch{x:g}']}")
    return out


def checked(run: dict, row: str, threshold: float) -> tuple[dict, float]:
    """A stored run's history row ``row`` composed window by window with a staleness check: the history's answer where
    the window's statistic (:func:`staleness`) is at most ``threshold``, the default's elsewhere; and the share kept."""
    per = {}
    kept = total = 0
    for key, stat in run["staleness"].items():
        level, cls, name = key.split("|")
        if name != row:
            continue
        base = f"{level}|{cls}|default"
        use = [x <= threshold for x in stat]
        per[base] = run["per_window"][base]
        per[f"{level}|{cls}|checked"] = [t if u else d for u, t, d in zip(use, run["per_window"][key], per[base],
                                                                         strict=True)]
        kept += sum(use)
        total += len(use)
    return per, kept / max(total, 1)


def stale_report(names: list[str], thresholds: list[float]) -> dict:
    """``--stale-report``: per stored run and threshold, the bus's own history (``hist6_guard1.5``) and a stale one
    (``…_of1``) composed with the staleness check: the share of windows that keep the history, σ over the default's
    (median, largest), windows off by more than 20 % at 0.1 %; and the statistic's quantiles per row."""
    out = {}
    for name in names:
        run = json.loads((common.RESULTS / f"{name}.json").read_text())
        for row in ("hist6_guard1.5", "hist6_guard1.5" + STALE):
            stats = np.concatenate([v for k, v in run["staleness"].items() if k.endswith("|" + row)])
            q = np.percentile(stats, [50, 90, 95, 99])
            print(f"{name} {row}: staleness median / 90 / 95 / 99 % {' / '.join(f'{v:.2f}' for v in q)}")
            for x in thresholds:
                per, kept = checked(run, row, x)
                s = summary(per)["checked"]
                off = s["off_20pct_base_variant"][INPUT_NOISE[2][0]]
                out[f"{name}|{row}|{x:g}"] = {"kept": kept, "median": s["sigma_ratio_median"],
                                              "max": s["sigma_ratio_max"], "off_01": off}
                print(f"  threshold {x:g}: kept {100 * kept:.0f} %, σ / default median {s['sigma_ratio_median']:.3f} "
                      f"(largest {s['sigma_ratio_max']:.3f}, {s['sigma_ratio_max_at']}), far-off at 0.1 % "
                      f"{off[0]} → {off[1]}")
    return out


if __name__ == "__main__":
    main()
