"""A minute of the bus's history on an independent simulator: ANDES records, PMU noise on every channel.

Stop 47 made the history's form (``identify(..., input_spectrum=)``, the service's ``input_history_windows``) on the
project's own generator only.  Here the records are ANDES's (:mod:`benchmarks.andes_crosscheck`: IEEE 14-bus, bus 9's
ZIP load and Motor3, the other loads' ambient fluctuation; scenario ``model`` unless ``--scenario``), simulated for
:data:`TF` s, and on each the last 10 s window is identified alone (the default) and given the six 10 s windows before
it, each with its own noise draw, pooled as the service's worker pools them
(:func:`benchmarks.input_noise_bound.pooled_history`).  Per ambient seed, P/Q SNR and PMU class, ``--draws`` draws of
white noise on all seven windows (P, Q at the SNR; V, θ at the class).  Per cell over the draws and seeds: bias and σ
of D/D_true for both, σ with over without, the windows off by more than 20 %, coverage of ±1.96 SE, and σ within
windows (the root mean of the per-seed variances over the draws: the noise's spread without the seeds' deterministic
differences).  JSON ``docs/results/andes_history[_<tag>].json`` (per identification D and SE).

    .venv/bin/python -m benchmarks.andes_history [--seeds 1 2 ... 10] [--draws 20] [--snr 22 28] [--tstep 0.01]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import WindowError, identify, noise  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.andes_crosscheck import PMU_CLASSES, noisy_window, scenario_record  # noqa: E402
from benchmarks.input_noise import with_input_noise  # noqa: E402
from benchmarks.input_noise_bound import pooled_history  # noqa: E402

#: Simulated time [s]: 2 s of settling, six windows of history, the window identified.
TF = 72.0
#: The history's windows and the identified one [s].
HISTORY = [(2.0 + 10.0 * k, 12.0 + 10.0 * k) for k in range(6)]
TARGET = (62.0, 72.0)
NOISY = ("pmu003", "pmu01")


def draw(rec: dict, snr_db: float, cls: str, key: list[int]) -> tuple[object, list]:
    """The target window and the history's, each with its own P/Q and V/θ noise ([key, window index] seeds)."""
    _, v_rel, th = PMU_CLASSES[cls]
    out = []
    for j, span in enumerate([*HISTORY, TARGET]):
        base = noisy_window(rec, *span, None, None)
        rng = np.random.default_rng([*key, j])
        out.append(with_input_noise(noisy_window(rec, *span, snr_db, rng), base, v_rel, th, rng))
    return out[-1], out[:-1]


def _answer(w, spectrum=None) -> dict:
    try:
        r = identify(w, input_spectrum=spectrum)
    except WindowError as exc:
        return {"error": exc.reason}
    return {"d": r.d.tolist(), "stderr": [r.stderr[k] for k in common.PARAMS], "flags": r.flags,
            "windows": int(r.quality.get("input_spectrum_windows", 0)), "elapsed_s": r.elapsed_s}


def run(scenario: str, seeds: list[int], snrs: list[float], draws: int, tstep: float, amp: float) -> dict:
    """Per seed, SNR, class and draw the answers alone and with the history; the seeds' truths."""
    rows, truths = [], {}
    for seed in seeds:
        t0 = time.perf_counter()
        rec, facts = scenario_record(scenario, tf=TF, tstep=tstep, amp=amp, seed=seed)
        truths[seed] = facts["truth"].tolist()
        print(f"seed {seed}: record ({time.perf_counter() - t0:.0f} s)", flush=True)
        for snr in snrs:
            for ci, cls in enumerate(NOISY):
                for k in range(draws):
                    w, hist = draw(rec, snr, cls, [seed, int(round(snr * 10)), ci, k])
                    spec = pooled_history([noise.input_periodogram(np.stack([h.V, h.theta]), 1.0 / float(
                        np.median(np.diff(h.t)))) for h in hist])
                    rows.append({"seed": seed, "snr_db": snr, "class": cls, "draw": k,
                                 "alone": _answer(w), "history": _answer(w, spec)})
        print(f"seed {seed}: done ({time.perf_counter() - t0:.0f} s)", flush=True)
    return {"rows": rows, "truths": truths}


def cells(out: dict) -> list[dict]:
    """Per (SNR, class): the statistics of the module docstring for ``alone`` and ``history``."""
    res = []
    keys = sorted({(r["snr_db"], r["class"]) for r in out["rows"]})
    for snr, cls in keys:
        sel = [r for r in out["rows"] if r["snr_db"] == snr and r["class"] == cls
               and "d" in r["alone"] and "d" in r["history"]]
        cell = {"snr_db": snr, "class": cls, "n": len(sel)}
        for name in ("alone", "history"):
            truth = np.array([out["truths"][r["seed"]] if r["seed"] in out["truths"] else out["truths"][str(r["seed"])]
                              for r in sel])
            d = np.array([r[name]["d"] for r in sel])
            se = np.array([r[name]["stderr"] for r in sel])
            ratio = d / truth
            seeds = np.array([r["seed"] for r in sel])
            within = np.sqrt(np.mean([ratio[seeds == s].var(axis=0, ddof=1) for s in np.unique(seeds)], axis=0))
            cell[name] = {"bias": (ratio.mean(axis=0) - 1).tolist(), "sigma": ratio.std(axis=0, ddof=1).tolist(),
                          "sigma_within": within.tolist(),
                          "off_20pct": int(np.sum(np.any(np.abs(ratio - 1) > 0.2, axis=1))),
                          "cover": np.mean(np.abs(d - truth) < 1.96 * se, axis=0).tolist(),
                          "ms_median": 1e3 * float(np.median([r[name]["elapsed_s"] for r in sel])),
                          "history_used": int(sum(r[name]["windows"] > 0 for r in sel))}
        cell["sigma_ratio"] = (np.array(cell["history"]["sigma"]) / np.array(cell["alone"]["sigma"])).tolist()
        cell["sigma_within_ratio"] = (np.array(cell["history"]["sigma_within"])
                                      / np.array(cell["alone"]["sigma_within"])).tolist()
        res.append(cell)
    return res


def table(res: list[dict]) -> str:
    def f(v, scale=100.0, fmt="{:.1f}"):
        return " / ".join(fmt.format(scale * x) for x in v)

    rows = []
    for c in res:
        for name in ("alone", "history"):
            s = c[name]
            rows.append([f"{c['snr_db']:g} dB", c["class"], name, c["n"], f(s["bias"]), f(s["sigma"]),
                         f(s["sigma_within"]), s["off_20pct"], f(s["cover"], fmt="{:.0f}"),
                         f(c["sigma_ratio"], 1.0, "{:.2f}") if name == "history" else "",
                         f(c["sigma_within_ratio"], 1.0, "{:.2f}") if name == "history" else "",
                         f"{s['ms_median']:.0f}"])
    head = ["P/Q SNR", "V/θ noise", "identifier", "n", "bias a / b / H2 / Tm [%]", "σ [%]", "σ within seeds [%]",
            "off > 20 %", "±1.96 SE cover [%]", "σ ratio", "σ within ratio", "ms"]
    return common.md_table(head, rows)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="model")
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(1, 11)))
    ap.add_argument("--snr", type=float, nargs="+", default=[22.0, 28.0], help="P/Q SNR [dB]")
    ap.add_argument("--draws", type=int, default=20)
    ap.add_argument("--tstep", type=float, default=0.01, help="ANDES's fixed step [s]")
    ap.add_argument("--amp", type=float, default=0.15)
    ap.add_argument("--tag", default=None)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    out = run(args.scenario, args.seeds, args.snr, args.draws, args.tstep, args.amp)
    res = cells(out)
    print(table(res))
    doc = {"machine": common.machine(), "scenario": args.scenario, "seeds": args.seeds, "snr_db": args.snr,
           "draws": args.draws, "tf": TF, "tstep": args.tstep, "amp": args.amp, "cells": res, **out,
           "total_s": time.perf_counter() - t0, "load_avg_at_end": list(os.getloadavg())}
    if not args.no_write:
        common.write_json("andes_history" + (f"_{args.tag}" if args.tag else ""), doc)
    return doc


if __name__ == "__main__":
    main()
