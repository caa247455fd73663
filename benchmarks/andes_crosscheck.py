"""Cross-check of the identifier against an independent simulator: ANDES (Motor3 + ZIP in IEEE 14-bus).

A third-order induction motor (ANDES ``Motor3``) and a ZIP static load share bus 9 of ANDES's
``ieee14/ieee14_full.xlsx`` (GENROU machines, exciters, governors).  Every *other* load's
constant-power part is driven by independent 2 Hz low-passed white noise (ambient excitation);
ANDES integrates the whole DAE (implicit trapezoid, fixed step), and bus 9's V, θ and total load
P, Q (motor + static), resampled to 100 Hz, go through :func:`aslm_core.identify` in 10 s windows.

Conversion of Motor3 (ANDES ``models/motor/motorbase.py``, ``motor3.py``; all on the system base
after ANDES's per-unit conversion of the device data, z-type parameters × (Sb/Sn)·(Vn/Vb)², Hm × Sn/Sb)::

    X   = x0  = xs + xm
    X'  = x1  = xs + xr1·xm/(xr1 + xm)
    Td0 = T10 = (xr1 + xm)/(ωb·rr1),   ωb = 2π·fn
    a = (X/X' − 1)/(Td0·X'),   b = X/(Td0·X'),   H2 = M = 2·Hm (system base),   Tm = τm at the power flow

ANDES writes ``M·dσ/dt = τm − τe`` with ``τm = (c1+c2+c3) + (−c2−2c3)·σ + c2·σ²`` (its source uses c2,
not c3, in the quadratic term) and the stator algebra ``v − e' = (rs + j·x')·i``; with rs = 0 and
c2 = c3 = 0 this is exactly the paper's eq. 1 (ANDES's vd + j·vq = j·V·e^{jθ} is a 90° rotation of the
paper's frame, to which the model is invariant).

The system and the simulation are :mod:`aslm_sim.andes.scenario`; this module checks the identifier on it.

Two scenarios: ``model`` (rs ≈ 0, constant torque: the identifier's assumptions) and
``andes_default`` (ANDES's default rs = 0.01 and torque coefficients c1 = 0.1, c2 = c3 = 0.02; the
other motor data are the same).  Run::

    .venv/bin/python -m benchmarks.andes_crosscheck [--quick]
    .venv/bin/python -m benchmarks.andes_crosscheck --input-noise exact,pmu003,pmu01 [--meas-snr-db 22 14 28]

``--input-noise``: white PMU noise on V and θ (issue 11's two classes) added to the exact ANDES record,
many P/Q noise draws per window over seeds 1–10 of both scenarios, the default identifier against
``input_smoother="none"`` (:func:`input_noise_study`; docs/andes_crosscheck.md, "Noise on V and θ");
with ``--weighting`` the default (``input_weighting="spectral"``) against ``input_weighting="none"`` instead (JSON
``andes_crosscheck_input_noise_weighting``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from functools import partial

import numpy as np

from aslm_core import IdentifyConfig, Window, WindowError, identify, input_weighting, motor
from aslm_core.identify import Problem
from aslm_core.preprocess import prepare
from aslm_sim.andes.effects import cache_dir

# The scenario lives in aslm_sim.andes; these names stay importable from here (other benchmarks use them).
from aslm_sim.andes.scenario import (  # noqa: F401
    BUS,
    CASE,
    F0,
    FS,
    MAIN_SCENARIOS,
    MOTOR,
    NAMES,
    PQ_AT_BUS,
    SCENARIOS,
    STATIC_PQ,
    ZIP_SHARES,
    lowpass_noise,
    resample,
    rotor_modes,
    simulate,
    solve_power_flow,
)
from benchmarks import common
from benchmarks.input_noise import INPUT_NOISE, with_input_noise

#: Facts of a run kept in the cache beside the resampled record.
FACTS = ("truth", "static_truth", "x1", "slip0", "rs_sys", "tm_slope", "tds_s", "andes_version")


def scenario_record(scenario: str, *, tf: float, tstep: float, amp: float, seed: int, tol: float = 1e-8,
                    cache: bool = True) -> tuple[dict, dict]:
    """A scenario's record resampled to :data:`FS` and its facts, simulated or read from the cache.

    The cache (:func:`aslm_sim.andes.effects.cache_dir`) is keyed by the scenario and every simulation
    setting: an ANDES run at a 5 ms step takes minutes here, the noise added to it afterwards milliseconds.

    Parameters
    ----------
    scenario : str
        A key of :data:`SCENARIOS`.
    tf, tstep : float
        Simulated time and ANDES's fixed step [s].
    amp : float
        Relative std of the ambient noise on the other loads [-].
    seed : int
        Seed of the ambient noise.
    tol : float
        ANDES's Newton tolerance.
    cache : bool
        Read and write the cache.

    Returns
    -------
    (dict, dict)
        The record (``t`` [s], ``V``, ``theta``, ``P``, ``Q``, ``p_motor``, ``q_motor``, as :func:`resample`)
        and the facts :data:`FACTS` (``truth`` as an array).
    """
    path = cache_dir() / f"crosscheck-v1-{scenario}-s{seed}-tf{tf:g}-h{tstep:g}-a{amp:g}-tol{tol:g}.npz"
    if cache and path.exists():
        with np.load(path) as z:
            rec = {k: z[k] for k in z.files if k != "facts"}
            facts = json.loads(str(z["facts"]))
    else:
        sim = simulate(scenario, tf=tf, tstep=tstep, amp=amp, seed=seed, tol=tol)
        rec = resample(sim)
        facts = json.loads(json.dumps({k: sim[k] for k in FACTS}, default=lambda o: np.asarray(o).tolist()))
        if cache:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(".tmp.npz")
            np.savez(tmp, **rec, facts=json.dumps(facts))
            tmp.replace(path)
    facts["truth"] = np.asarray(facts["truth"], dtype=float)
    return rec, facts


def noisy_window(rec: dict, t0: float, t1: float, snr_db: float | None, rng: np.random.Generator | None) -> Window:
    """The resampled record's [t0, t1] as a Window, white noise added to P and Q at ``snr_db`` (each channel's std).

    ``snr_db`` None: P and Q as simulated (``rng`` unused).
    """
    sl = (rec["t"] >= t0 - 1e-9) & (rec["t"] <= t1 + 1e-9)
    P, Q = rec["P"][sl].copy(), rec["Q"][sl].copy()
    if snr_db is not None:
        for x in (P, Q):
            x += rng.standard_normal(x.size) * np.std(x) * 10 ** (-snr_db / 20)
    return Window(rec["t"][sl], rec["V"][sl], rec["theta"][sl], P, Q, f0=F0, bus=f"andes-bus{BUS}")


def conversion_check(rec: dict, sim: dict) -> dict:
    """Drive the identifier's motor model (eq. 4–5, RK4) with truth D on ANDES's V, θ from t = 0 and compare
    with ANDES's Motor3 output: relative RMS error of the fluctuations of P and of Q − V²/X'."""
    p, q, _ = motor.simulate(rec["V"], rec["theta"], sim["truth"], 1.0 / FS, motor.omega0_of(F0))
    pa = rec["p_motor"]
    qa = rec["q_motor"] - rec["V"] ** 2 / sim["x1"]
    sl = slice(int(2 * FS), None)
    return {"p": float(np.std((p - pa)[sl]) / np.std(pa[sl])), "q": float(np.std((q - qa)[sl]) / np.std(qa[sl])),
            "p_offset": float(np.mean((p - pa)[sl]))}


def fd_at(window: Window, d: np.ndarray, config: IdentifyConfig) -> tuple[float, float, float]:
    """FD of P and Q and the eq. 7 objective of a given D on a window (truth reference)."""
    prob = Problem(prepare(window, max_gap_samples=config.max_gap_samples, min_duration_s=config.min_duration_s,
                          lowpass_hz=config.lowpass_hz), window.f0, config)
    out = prob.residuals(np.asarray(d, dtype=float), jacobian=False)
    if out is None:
        return float("nan"), float("nan"), float("nan")
    rp, rq, _, _ = out
    pc, qc = prob.p_meas - prob.p_meas.mean(), prob.q_meas - prob.q_meas.mean()
    return (1 - float(rp @ rp) / float(pc @ pc), 1 - float(rq @ rq) / float(qc @ qc),
            (math.sqrt(rp @ rp) + math.sqrt(rq @ rq)) / prob.l)


def run_scenario(scenario: str, *, tf: float, tstep: float, amp: float, seed: int, windows: list[tuple[float, float]],
                 meas_snr_db: float | None, config: IdentifyConfig) -> dict:
    sim = simulate(scenario, tf=tf, tstep=tstep, amp=amp, seed=seed)
    rec = resample(sim)
    conv = conversion_check(rec, sim)
    rng = np.random.default_rng(seed + 1)
    rows = []
    for t0, t1 in windows:
        w = noisy_window(rec, t0, t1, meas_snr_db, rng)
        res = identify(w, config=config)
        fdp_t, fdq_t, of_t = fd_at(w, sim["truth"], config)
        vbar, st, zt = float(np.mean(w.V)), res.static, sim["static_truth"]
        # The ZIP split is not identifiable from ±0.2 % voltage; the static power at the mean voltage is.
        static_ratio = [(st[z] * vbar**2 + st[i] * vbar + st[c]) / (zt[z] * vbar**2 + zt[i] * vbar + zt[c])
                        for z, i, c in (("Pz", "Pi", "Pp"), ("Qz", "Qi", "Qp"))]
        rows.append({
            "window": [t0, t1], "d": res.d.tolist(), "ratio": (res.d / sim["truth"]).tolist(),
            "stderr": [res.stderr[k] for k in NAMES], "fd_p": res.fit["fd_p"], "fd_q": res.fit["fd_q"],
            "objective": res.objective, "fd_p_truth": fdp_t, "fd_q_truth": fdq_t, "objective_truth": of_t,
            "static_ratio": static_ratio, "flags": res.flags, "v_std_rel": res.quality["v_std_rel"], "static": res.static, "elapsed_s": res.elapsed_s,
        })
    return {"scenario": scenario, "truth": sim["truth"].tolist(), "static_truth": sim["static_truth"],
            "slip0": sim["slip0"], "rs_sys": sim["rs_sys"], "tm_slope": sim["tm_slope"], "conversion": conv,
            "tds_s": sim["tds_s"], "andes_version": sim["andes_version"], "meas_snr_db": meas_snr_db, "rows": rows}


#: PMU classes of ``--input-noise`` (the same as benchmarks.input_noise's): key → (label, V noise std as a
#: fraction of the window's mean V [-], θ noise std [rad]).
PMU_CLASSES = dict(zip(("exact", "pmu003", "pmu01"), INPUT_NOISE, strict=True))
#: The identifier's default and the one before issue 11 (no input smoother, no low-pass; spectral SEs both).
#: "none": the identifier before issue 11 (no input smoother, no S-weighting).
VARIANTS = {"default": IdentifyConfig(), "none": IdentifyConfig(input_smoother="none", **common.OUTPUT_ERROR)}
#: ``--weighting``: the default (the S-weighted refinement, :mod:`aslm_core.input_weighting`) against
#: ``input_weighting="none"`` (the default until issue 11's follow-up).
WEIGHTING_VARIANTS = {"default": IdentifyConfig(), "weighting none": IdentifyConfig(**common.OUTPUT_ERROR)}
#: Flags that say a window's answer is not to be trusted as it stands.
WARNING_FLAGS = ("uncertain", "poor_fit", "at_bound", "restarts", "input_noise_too_large")


def identify_draw(base: Window, rec: dict, span: tuple[float, float], snr_db: float, classes: list[str],
                  key: list[int], variants: dict[str, IdentifyConfig] = VARIANTS) -> list[dict]:
    """One P/Q noise draw on a window, then each PMU class's input noise on it, every variant identified.

    Parameters
    ----------
    base : Window
        The window as simulated (exact V, θ, P, Q): the reference for the V noise's std.
    rec, span :
        The resampled record and the window's [t0, t1] [s].
    snr_db : float
        SNR of the white noise on P and Q [dB].
    classes : list of str
        Keys of :data:`PMU_CLASSES`.
    key : list of int
        Seed of the P/Q noise; a class's V/θ noise uses ``[*key, 1 + its index in PMU_CLASSES]``, so the
        draws do not depend on which classes are run, and P/Q noise is the same for every class.
    variants : dict
        Name → configuration identified on each draw (:data:`VARIANTS` or :data:`WEIGHTING_VARIANTS`).

    Returns
    -------
    list of dict
        Per class and variant: D, its standard errors, the flags, the noise estimates of V
        [pu] and θ [rad], ``input_ratio_v``, the low-pass applied [Hz], the time [s]; or the WindowError's reason.
    """
    w_pq = noisy_window(rec, *span, snr_db, np.random.default_rng(key))
    out = []
    for cls in classes:
        _, v_rel, th = PMU_CLASSES[cls]
        rng = np.random.default_rng([*key, 1 + list(PMU_CLASSES).index(cls)])
        w = with_input_noise(w_pq, base, v_rel, th, rng)
        for variant, cfg in variants.items():
            try:
                r = identify(w, config=cfg)
            except WindowError as exc:
                out.append({"class": cls, "variant": variant, "error": exc.reason})
                continue
            out.append({"class": cls, "variant": variant, "d": r.d.tolist(),
                        "stderr": [r.stderr[k] for k in NAMES], "flags": r.flags,
                        "noise_v": r.quality["noise_v"], "noise_theta": r.quality["noise_theta"],
                        "input_ratio_v": r.quality.get("input_ratio_v"), "lowpass_hz": r.quality["lowpass_hz"],
                        "elapsed_s": r.elapsed_s})
    return out


def input_noise_study(*, scenarios: list[str], seeds: list[int], windows: list[tuple[float, float]],
                      snrs: list[float], classes: list[str], draws: int, tf: float, tstep: float, amp: float,
                      workers: int = 1, variants: dict[str, IdentifyConfig] = VARIANTS) -> dict:
    """ANDES windows with white PMU noise on V and θ added to the exact record (``--input-noise``).

    Per scenario, seed and window: ``draws`` P/Q noise draws at each SNR [dB]; on each draw every class of
    :data:`PMU_CLASSES` in ``classes`` (its own V/θ noise) and every entry of ``variants``.  Also per window
    and variant the noise-free identification (exact inputs, no P/Q noise): the window's deterministic
    answer, the centre of the second coverage figure.

    Returns
    -------
    dict
        ``windows``: per scenario/seed/window the truth and the noise-free answers; ``cells``: the
        statistics of :func:`summarise_cells` pooled over windows, ``window_cells`` per window (the single
        identifications are not kept: 72,000 of them in the documented run).
    """
    per_window, rows = [], []
    for si, scenario in enumerate(scenarios):
        for seed in seeds:
            rec, facts = scenario_record(scenario, tf=tf, tstep=tstep, amp=amp, seed=seed)
            for wi, span in enumerate(windows):
                base = noisy_window(rec, *span, None, None)
                centre = {v: identify(base, config=cfg).d for v, cfg in variants.items()}
                per_window.append({"scenario": scenario, "seed": seed, "window_index": wi, "window": list(span),
                                   "truth": facts["truth"].tolist(), "tds_s": facts["tds_s"],
                                   "centre": {v: d.tolist() for v, d in centre.items()},
                                   "centre_ratio": {v: (d / facts["truth"]).tolist() for v, d in centre.items()}})
                for snr in snrs:
                    keys = [[si, seed, wi, int(round(snr * 10)), k] for k in range(draws)]
                    with ThreadPoolExecutor(max_workers=workers) as pool:
                        done = list(pool.map(partial(identify_draw, base, rec, span, snr, classes, variants=variants), keys))
                    for k, out in enumerate(done):
                        rows.extend({"scenario": scenario, "seed": seed, "window": wi, "snr_db": snr, "draw": k,
                                     "v_noise": PMU_CLASSES[o["class"]][1] * float(np.mean(base.V)),
                                     "theta_noise": PMU_CLASSES[o["class"]][2], **o} for o in out)
                    print(f"{scenario} seed {seed} window {span[0]:g}–{span[1]:g} s, {snr:g} dB: {draws} draws",
                          flush=True)
    return {"windows": per_window, "cells": summarise_cells(per_window, rows),
            "window_cells": summarise_cells(per_window, rows, by_window=True)}


def summarise_cells(per_window: list[dict], rows: list[dict], by_window: bool = False) -> list[dict]:
    """Statistics per scenario, SNR, PMU class and variant, pooled over seeds, windows and draws.

    Per parameter: bias (mean of estimate/truth − 1), σ (std of estimate/truth over every identification)
    and σ within windows (root mean of the per-window variances: the noise's share without the windows'
    deterministic differences), median and worst |error|, coverage of ±1.96 SE around the truth and around
    the window's noise-free answer; how many identifications carry each flag; the noise estimates of V and
    θ over the injected std.  ``by_window``: one cell per seed and window as well (not pooled).
    """
    centre = {(w["scenario"], w["seed"], w["window_index"]): w for w in per_window}
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        where = (r["seed"], r["window"]) if by_window else ()
        groups.setdefault((r["scenario"], r["snr_db"], r["class"], r["variant"], *where), []).append(r)
    cells = []
    for key, rs in groups.items():
        scenario, snr, cls, variant = key[:4]
        ok = [r for r in rs if "d" in r]
        ratio, cov_truth, cov_centre, windows = [], [], [], {}
        flags: dict[str, int] = {}
        for r in ok:
            w = centre[(scenario, r["seed"], r["window"])]
            d, se = np.array(r["d"]), np.array(r["stderr"])
            truth, c0 = np.array(w["truth"]), np.array(w["centre"][variant])
            ratio.append(d / truth)
            cov_truth.append(np.abs(d - truth) < 1.96 * se)
            cov_centre.append(np.abs(d - c0) < 1.96 * se)
            windows.setdefault((r["seed"], r["window"]), []).append(d / truth)
            for f in r["flags"]:
                flags[f] = flags.get(f, 0) + 1
        rr = np.array(ratio)
        err = np.abs(rr - 1.0)
        within = np.sqrt(np.mean([np.var(v, axis=0, ddof=1) for v in windows.values()], axis=0))
        warned = np.array([any(f.startswith(WARNING_FLAGS) for f in r["flags"]) for r in ok], dtype=bool)
        off = np.any(err > 0.2, axis=1)
        noisy = [r for r in ok if r["v_noise"] > 0]
        raised = np.array(["input_noise_too_large" in r["flags"] for r in ok], dtype=bool)
        cells.append({
            "scenario": scenario, "snr_db": snr, "class": cls, "label": PMU_CLASSES[cls][0], "variant": variant,
            **({"seed": key[4], "window": key[5]} if by_window else {}),
            "n": len(ok), "failed": len(rs) - len(ok), "windows": len(windows),
            **{name: dict(zip(NAMES, val.tolist(), strict=True)) for name, val in (
                ("bias", rr.mean(axis=0) - 1.0), ("sigma", rr.std(axis=0, ddof=1)), ("sigma_within", within),
                ("median_abs_err", np.median(err, axis=0)), ("worst_abs_err", err.max(axis=0)),
                ("coverage_truth", np.mean(cov_truth, axis=0)), ("coverage_centre", np.mean(cov_centre, axis=0)))},
            "flags": dict(sorted(flags.items())), "any_warning_flag": int(warned.sum()),
            "off_20pct": int(off.sum()), "off_20pct_unwarned": int(np.sum(off & ~warned)),
            # Does the input-noise flag pick out the poor answers?  The same statistics on either side of it.
            "input_flag": {side: _spread(rr[sel], off[sel])
                           for side, sel in (("raised", raised), ("not_raised", ~raised))},
            "noise_v_over_injected": float(np.median([r["noise_v"] / r["v_noise"] for r in noisy])) if noisy else None,
            "noise_theta_over_injected": (float(np.median([r["noise_theta"] / r["theta_noise"] for r in noisy]))
                                          if noisy else None),
            "median_lowpass_hz": float(np.median([r["lowpass_hz"] for r in ok])),
            "median_input_ratio_v": float(np.median([min(r["input_ratio_v"], 1e6) for r in ok])),
            "median_time_ms": float(np.median([r["elapsed_s"] for r in ok]) * 1e3),
        })
    return cells


def _spread(ratio: np.ndarray, off: np.ndarray) -> dict:
    """n, σ and median |error| per parameter of (n, 4) estimate/truth ratios, and how many are off by > 20 %."""
    if len(ratio) < 2:
        return {"n": len(ratio)}
    return {"n": len(ratio), "sigma": dict(zip(NAMES, ratio.std(axis=0, ddof=1).tolist(), strict=True)),
            "median_abs_err": dict(zip(NAMES, np.median(np.abs(ratio - 1.0), axis=0).tolist(), strict=True)),
            "off_20pct": int(off.sum())}


STUDY_HEAD = ["scenario", "P/Q SNR", "V/θ noise", "identifier", "n", "bias a / b / H2 / Tm [%]",
              "σ a / b / H2 / Tm [%]", "σ within windows [%]", "σ within / exact inputs' (oracle)",
              "median abs. error [%]", "worst abs. error [%]", "off > 20 % (no warning flag)",
              "±1.96 SE cover, truth [%]", "cover, noise-free answer [%]", "flags (identifications)"]
#: Raised on every ANDES window (the ZIP split from ±0.2 % voltage, docs/andes_crosscheck.md): not tabulated.
ALWAYS_FLAG = "static_split_unidentifiable"


def study_rows(cells: list[dict]) -> list[list]:
    """The study's table (docs/andes_crosscheck.md, "Noise on V and θ")."""
    def pct(st: dict, scale: float = 100.0, fmt: str = ".1f") -> str:
        return " / ".join(f"{scale * st[k]:{fmt}}" for k in NAMES)

    # The oracle floor: the same windows and P/Q draws identified with the exact V and θ.
    exact = {(c["scenario"], c["snr_db"]): c["sigma_within"] for c in cells
             if c["class"] == "exact" and c["variant"] == "default"}
    out = []
    for c in cells:
        flags = ", ".join(f"{k} {v}" for k, v in c["flags"].items() if k != ALWAYS_FLAG) or "–"
        floor = exact.get((c["scenario"], c["snr_db"]))
        oracle = ("–" if floor is None or c["class"] == "exact"
                  else " / ".join(f"{c['sigma_within'][k] / floor[k]:.1f}" for k in NAMES))
        out.append([c["scenario"], f"{c['snr_db']:g} dB", "exact" if c["class"] == "exact" else c["label"],
                    c["variant"], c["n"], pct(c["bias"]), pct(c["sigma"]), pct(c["sigma_within"]), oracle,
                    pct(c["median_abs_err"]), pct(c["worst_abs_err"], fmt=".0f"),
                    f"{c['off_20pct']} ({c['off_20pct_unwarned']})", pct(c["coverage_truth"], fmt=".0f"),
                    pct(c["coverage_centre"], fmt=".0f"), flags])
    return out


def print_report(results: list[dict], args) -> None:
    print(f"ANDES {results[0]['andes_version']}; case {CASE}, bus {BUS}; tstep {args.tstep} s, tf {args.tf} s, "
          f"ambient amplitude {args.amp} (relative, on the constant-power part), seed {args.seed}")
    for r in results:
        tr = r["truth"]
        c = r["conversion"]
        print(f"\n### {r['scenario']} (meas. SNR {r['meas_snr_db']} dB): truth D = "
              + ", ".join(f"{k}={v:.4g}" for k, v in zip(NAMES, tr, strict=True))
              + f"; slip0 {r['slip0']:.4f}, rs(sys) {r['rs_sys']:.3g}, dTm/dσ {r['tm_slope']:.3g}; ANDES TDS {r['tds_s']:.1f} s")
        print(f"conversion check (eq. 4–5 with truth D vs Motor3): rel. RMS error P {c['p']:.3%}, "
              f"Q−V²/X' {c['q']:.3%}, mean P offset {c['p_offset']:.2e} pu")
        print("| window [s] | a | b | H2 | Tm | a/a0 | b/b0 | H2/H20 | Tm/Tm0 | FD_P | FD_Q | FD_P,Q @truth "
              "| OF / OF@truth | Pst/Pst0, Qst/Qst0 at V̄ | V std | flags |")
        print("|---|" + "---|" * 15)
        for w in r["rows"]:
            d, q = w["d"], w["ratio"]
            print(f"| {w['window'][0]:g}–{w['window'][1]:g} | " + " | ".join(f"{x:.4g}" for x in d) + " | "
                  + " | ".join(f"{x:.3f}" for x in q)
                  + f" | {w['fd_p']:.4f} | {w['fd_q']:.4f} | {w['fd_p_truth']:.4f}, {w['fd_q_truth']:.4f} "
                  f"| {w['objective'] / w['objective_truth']:.3f} | {w['static_ratio'][0]:.3f}, {w['static_ratio'][1]:.3f} "
                  f"| {w['v_std_rel']:.2%} | "
                  f"{', '.join(w['flags']) or '–'} |")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="12.5 s at a 10 ms step per scenario, one window each")
    p.add_argument("--scenario", choices=[*SCENARIOS, "all"], default="all")
    p.add_argument("--tstep", type=float, default=None, help="ANDES fixed step [s] (default 0.005, quick 0.01)")
    p.add_argument("--tf", type=float, default=None,
                   help="simulated time [s] (default 16, with --input-noise 22; quick 12.5)")
    p.add_argument("--amp", type=float, default=0.15, help="relative std of the ambient load noise")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--meas-snr-db", type=float, nargs="+", default=None,
                   help="add white measurement noise to P, Q [dB] (one value; with --input-noise several, default 22)")
    p.add_argument("--json", type=str, default=None, help="write the results to this JSON file")
    p.add_argument("--input-noise", type=str, default=None, metavar="CLASSES",
                   help=f"study: white PMU noise on V and θ, comma-separated of {', '.join(PMU_CLASSES)}")
    p.add_argument("--seeds", type=int, nargs="+", default=list(range(1, 11)), help="study: ambient seeds")
    p.add_argument("--draws", type=int, default=100, help="study: P/Q noise draws per window and SNR")
    p.add_argument("--workers", type=int, default=1, help="study: identification threads")
    p.add_argument("--weighting", action="store_true",
                   help="study: the default against input_weighting='none' (instead of input_smoother='none')")
    p.add_argument("--band-at-cutoff", action="store_true",
                   help="stop 50's candidate: input_weighting.BAND_AT_CUTOFF on")
    args = p.parse_args(argv)
    input_weighting.BAND_AT_CUTOFF = args.band_at_cutoff
    scen = list(MAIN_SCENARIOS) if args.scenario == "all" else [args.scenario]
    if args.input_noise is not None:
        return study_main(args, scen)
    if args.meas_snr_db is not None and len(args.meas_snr_db) > 1:
        p.error("--meas-snr-db takes one value without --input-noise")
    args.tf = args.tf or (12.5 if args.quick else 16.0)
    args.tstep = args.tstep or (0.01 if args.quick else 0.005)
    windows = [(args.tf - 10.0, args.tf)] if args.quick else [(2.0, 12.0), (args.tf - 10.0, args.tf)]
    config = IdentifyConfig()
    snr = args.meas_snr_db[0] if args.meas_snr_db else None
    results = [run_scenario(s, tf=args.tf, tstep=args.tstep, amp=args.amp, seed=args.seed, windows=windows,
                            meas_snr_db=snr, config=config) for s in scen]
    print_report(results, args)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1, default=float)
    return 0


def study_main(args, scenarios: list[str]) -> int:
    """``--input-noise``: run :func:`input_noise_study`, print its table, write its JSON."""
    classes = args.input_noise.split(",")
    if unknown := set(classes) - set(PMU_CLASSES):
        raise SystemExit(f"unknown PMU class(es) {sorted(unknown)}; known: {', '.join(PMU_CLASSES)}")
    # Non-overlapping 10 s windows after a 2 s settling; --quick: the test's run (12.5 s at 10 ms, one window).
    tf = args.tf or (12.5 if args.quick else 22.0)
    tstep = args.tstep or (0.01 if args.quick else 0.005)
    windows = [(tf - 10.0, tf)] if args.quick else [(t0, t0 + 10.0) for t0 in np.arange(2.0, tf - 9.999, 10.0)]
    seeds = [args.seed] if args.quick else args.seeds
    snrs = args.meas_snr_db or [22.0]
    machine = common.machine()
    t_start = time.perf_counter()
    variants = WEIGHTING_VARIANTS if args.weighting else VARIANTS
    out = input_noise_study(scenarios=scenarios, seeds=seeds, windows=windows, snrs=snrs, classes=classes,
                            draws=args.draws, tf=tf, tstep=tstep, amp=args.amp, workers=args.workers,
                            variants=variants)
    out = {"settings": {"scenarios": scenarios, "seeds": seeds, "windows": windows, "snr_db": snrs,
                        "classes": {c: PMU_CLASSES[c] for c in classes}, "draws": args.draws, "tf": tf,
                        "tstep": tstep, "amp": args.amp, "variants": {k: v.to_dict() for k, v in variants.items()}},
           "machine": machine, "elapsed_s": time.perf_counter() - t_start,
           "load_avg_at_end": list(os.getloadavg()), **out}
    print(common.md_table(STUDY_HEAD, study_rows(out["cells"])))
    print(f"\n{time.perf_counter() - t_start:.0f} s; load at start {machine['load_avg_at_start']}, "
          f"at end {[round(x, 2) for x in os.getloadavg()]}")
    # --quick is a smoke run: it does not overwrite the documented results unless asked to.
    name = "andes_crosscheck_input_noise" + ("_weighting" if args.weighting else "")
    path = args.json or (None if args.quick else str(common.RESULTS / f"{name}.json"))
    if path is None:
        return 0
    with open(path, "w") as fh:
        json.dump(out, fh, indent=1, default=float)
        fh.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
