"""Stop 59's confirmation: P's and Q's noise in ``quality`` at every reporting rate, read under the band's own content.

``quality["noise_p"]`` and ``["noise_q"]`` were the median of the channel's periodogram above 5 Hz.  At 25–50 frames/s
that band still holds the motor's fast response: on development seed 41 the median read P at 1.37 × the injected std at
25 frames/s and DL 3 (the 90th percentile 2.5 ×), on ANDES's records (ambient seeds 21–24) at 3.3 × at 25 frames/s,
1.7 × at 50 and 1.3 × at 100.  Since stop 59 they are the white level fitted under that content where the band holds
some (:func:`aslm_core.noise.output_floors`, the fit the refinement's S has used since stop 57), for every window, and
the own-fluctuation indicators, the gate of ``disturbance="gated"`` and the pooled gate read them.  The level of an
unaliased record comes out at 0.98–1.01 × in the median on those development windows; ANDES's windows at 25 frames/s are
decimated without an anti-alias filter, and their clean P alone reads a white level of 1.1–1.3 × the noise there (the
motor's content above 12.5 Hz folded into the band), so no reading of the band can reach the noise at that rate.

The rule (:data:`RULE`) was fixed in this file before any run on its seeds.  It judges the change against the tree
before it (ee651b8) on the same windows and draws (the ``before`` tag is that tree's run of this module's ``--run``):

    .venv/bin/python -m benchmarks.output_floors --run --tag after
    (in a checkout of ee651b8 with this file copied in)  python -m benchmarks.output_floors --run --tag before
    .venv/bin/python -m benchmarks.output_floors --verdict

Per window (JSON ``docs/results/output_floors_TAG.json``): the injected std of P's and Q's noise, ``noise_p``,
``noise_q``, ``floor_p``, ``floor_q`` (where separated), ``own_ratio_p``, ``gated_ar_iv``, ``own_median_hz_p`` and D.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import math  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import IdentifyConfig, WindowError, identify  # noqa: E402
from aslm_sim.cases import make_cases  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.input_noise import INPUT_NOISE, with_input_noise  # noqa: E402

#: The generator's fresh seed, ANDES's fresh ambient seeds and the own-fluctuation windows' fresh seed.
SEED = 99
ANDES_SEEDS = (91, 92, 93, 94, 95)
OWN_SEED = 343
RATES = (25.0, 30.0, 50.0, 60.0, 100.0, 120.0)
OWN_RATES = (25.0, 50.0, 100.0)
#: Windows per generator cell (rate × DL × class) and per own-fluctuation cell (rate × ratio × shape × class).
N, N_OWN = 40, 30
RULE = ("Against the tree before (ee651b8), on the same windows and draws. "
        "(C1) the generator, fresh seed 99, 25/30/50/60/100/120 frames/s, DL 1-3, exact V/theta and the two PMU "
        "classes, 40 windows a cell: in every cell the median of noise_p and of noise_q over the injected std lies in "
        "[0.88, 1.12] and their 10th and 90th percentiles in [0.7, 1.4]. "
        "(C2) ANDES, fresh ambient seeds 91-95 (white PMU noise, P/Q at 22 dB, 7 windows x 2 draws x 3 classes): at 50 "
        "and 100 frames/s the medians of noise_p and noise_q over the injected std lie in [0.9, 1.1]; at 25 frames/s "
        "each is at most 2.0 and at most 0.7 x the band median's (the tree before's noise_p, noise_q). "
        "(C3) on C1's and C2's windows D differs from the tree before's (relative 1e-9) on at most 2 % of the windows "
        "of each rate, and only where the gate's decision (gated_ar_iv) differs. "
        "(C4) own-fluctuation windows, fresh seed 343 (own/total 0.5 and 0.9, lowpass and switching shapes, exact V/theta "
        "and the two PMU classes, DL 2, 25/50/100 frames/s, 30 windows a cell): the gate's decision is the tree before's "
        "on at least 99 % of them and own_median_hz_p is present on at least 97 %. "
        "(C5) C1's exact-input windows at 100 and 120 frames/s: own_median_hz_p absent on at least 90 %.")


def _row(r, **keys) -> dict:
    q = r.quality
    return {**keys, "noise_p": q["noise_p"], "noise_q": q["noise_q"], "floor_p": q.get("floor_p"),
            "floor_q": q.get("floor_q"), "own_ratio_p": q["own_ratio_p"], "gated": q.get("gated_ar_iv"),
            "own_median_hz_p": q.get("own_median_hz_p"), "d": r.d.tolist()}


def _answer(w, **keys) -> dict:
    try:
        return _row(identify(w, config=IdentifyConfig()), **keys)
    except WindowError as exc:
        return {**keys, "error": exc.reason}


def generator_rows(fs: float, level: int, seed: int = SEED, n: int = N) -> list[dict]:
    """C1's windows of one rate and DL: each case with exact V and θ and with each PMU class's white noise."""
    out = []
    rng = np.random.default_rng([seed, level, int(fs)])
    for i, c in enumerate(common.cases(n, level=level, seed=seed, fs=fs)):
        inj = {"inj_p": float(np.std(c.window.P - c.clean.P)), "inj_q": float(np.std(c.window.Q - c.clean.Q))}
        for k, (_, v_rel, th) in enumerate(INPUT_NOISE):
            out.append(_answer(with_input_noise(c.window, c.clean, v_rel, th, rng), set="generator", fs=fs,
                               level=level, cls=k, i=i, **inj))
    return out


def andes_rows(seed: int) -> list[dict]:
    """C2's windows of one ambient seed (as :mod:`benchmarks.andes_rates` draws its white-PMU windows)."""
    from benchmarks.andes_crosscheck import PMU_CLASSES, noisy_window, scenario_record
    from benchmarks.andes_history import TF
    from benchmarks.andes_rates import CLASSES, STEPS, decimated

    rec, _ = scenario_record("model", tf=TF, tstep=0.01, amp=0.15, seed=seed)
    out = []
    for j in range(7):
        span = (2.0 + 10.0 * j, 12.0 + 10.0 * j)
        base = noisy_window(rec, *span, None, None)
        for k in range(2):
            noisy_pq = noisy_window(rec, *span, 22.0, np.random.default_rng([seed, 220, j, k]))
            for ci, cls in enumerate(CLASSES):
                _, v_rel, th = PMU_CLASSES[cls]
                w = with_input_noise(noisy_pq, base, v_rel, th, np.random.default_rng([seed, j, k, ci]))
                for fs, step in STEPS.items():
                    wd, bd = decimated(w, step), decimated(base, step)
                    out.append(_answer(wd, set="andes", seed=seed, fs=fs, cls=ci, i=j, draw=k,
                                       inj_p=float(np.std(wd.P - bd.P)), inj_q=float(np.std(wd.Q - bd.Q))))
    return out


def own_rows(fs: float, ratio: float, shape: str, seed: int = OWN_SEED, n: int = N_OWN) -> list[dict]:
    """C4's windows of one rate, own ratio and shape (as :func:`benchmarks.own_fluctuation.own_cases` makes them)."""
    base = make_cases(n, level=2, seed=seed, input_noise=False, fs=fs)
    k = ratio / math.sqrt(1.0 - ratio * ratio)
    sig = [k * float(np.std(c.clean.P)) / c.truth.power(1.0)[0] for c in base]
    cs = make_cases(n, level=2, seed=seed, input_noise=False, own_sigma=sig, own_shape=shape, fs=fs)
    out = []
    for cls, (_, v_rel, th) in enumerate(INPUT_NOISE):
        rng = np.random.default_rng([seed, int(100 * ratio), cls, int(fs)])
        for i, c in enumerate(cs):
            out.append(_answer(with_input_noise(c.window, c.clean, v_rel, th, rng), set="own", fs=fs, ratio=ratio,
                               shape=shape, cls=cls, i=i))
    return out


def _job(job: tuple) -> list[dict]:
    kind, *args = job
    return {"generator": generator_rows, "andes": andes_rows, "own": own_rows}[kind](*args)


def run(workers: int = 2) -> list[dict]:
    """Every window of the rule, this tree's answers."""
    jobs = ([("andes", s) for s in ANDES_SEEDS] + [("generator", fs, lv) for fs in RATES for lv in (1, 2, 3)]
            + [("own", fs, r, s) for fs in OWN_RATES for r in (0.5, 0.9) for s in ("lowpass", "switching")])
    rows: list[dict] = []
    with ProcessPoolExecutor(workers) as ex:
        for out in ex.map(_job, jobs):
            rows.extend(out)
    return rows


def _key(r: dict) -> tuple:
    return tuple(r.get(k) for k in ("set", "seed", "fs", "level", "ratio", "shape", "cls", "i", "draw"))


def _pct(x: list[float]) -> tuple[float, float, float]:
    return float(np.percentile(x, 10)), float(np.median(x)), float(np.percentile(x, 90))


def verdict(after: list[dict], before: list[dict]) -> dict:
    """:data:`RULE` on the two trees' rows (matched by window)."""
    old = {_key(r): r for r in before}
    pairs = [(r, old[_key(r)]) for r in after if "error" not in r and "error" not in old.get(_key(r), {"error": 1})]
    out: dict = {"rule": RULE, "windows": len(pairs), "cells": []}
    met = {c: True for c in ("C1", "C2", "C3", "C4", "C5")}
    gen = [(a, b) for a, b in pairs if a["set"] == "generator"]
    for fs in RATES:
        for level in (1, 2, 3):
            for cls in range(len(INPUT_NOISE)):
                cell = [a for a, _ in gen if a["fs"] == fs and a["level"] == level and a["cls"] == cls]
                if not cell:
                    continue
                st = {c: _pct([a[f"noise_{c}"] / a[f"inj_{c}"] for a in cell]) for c in ("p", "q")}
                ok = all(0.88 <= m <= 1.12 and lo >= 0.7 and hi <= 1.4 for lo, m, hi in st.values())
                met["C1"] &= ok
                out["cells"].append({"set": "generator", "fs": fs, "level": level, "cls": cls, "n": len(cell),
                                     "p_10_50_90": st["p"], "q_10_50_90": st["q"], "met": ok})
    andes = [(a, b) for a, b in pairs if a["set"] == "andes"]
    for fs in (25.0, 50.0, 100.0):
        cell = [(a, b) for a, b in andes if a["fs"] == fs]
        if not cell:
            continue
        med = {c: float(np.median([a[f"noise_{c}"] / a[f"inj_{c}"] for a, _ in cell])) for c in ("p", "q")}
        band = {c: float(np.median([b[f"noise_{c}"] / b[f"inj_{c}"] for _, b in cell])) for c in ("p", "q")}
        ok = all(0.9 <= med[c] <= 1.1 for c in med) if fs != 25.0 else all(
            med[c] <= 2.0 and med[c] <= 0.7 * band[c] for c in med)
        met["C2"] &= ok
        out["cells"].append({"set": "andes", "fs": fs, "n": len(cell), "median": med, "band_median": band, "met": ok})
    out["changed"] = {}
    for fs in RATES:
        cell = [(a, b) for a, b in pairs if a["set"] in ("generator", "andes") and a["fs"] == fs]
        changed = [(a, b) for a, b in cell if not np.allclose(a["d"], b["d"], rtol=1e-9, atol=0.0)]
        unexplained = sum(a["gated"] == b["gated"] for a, b in changed)
        ok = len(changed) <= 0.02 * len(cell) and unexplained == 0
        met["C3"] &= ok
        out["changed"][str(fs)] = {"n": len(cell), "d_changed": len(changed), "without_a_gate_change": unexplained}
    own = [(a, b) for a, b in pairs if a["set"] == "own"]
    if own:
        same_gate = sum(a["gated"] == b["gated"] for a, b in own) / len(own)
        present = sum(a["own_median_hz_p"] is not None for a, _ in own) / len(own)
        met["C4"] = same_gate >= 0.99 and present >= 0.97
        out["own"] = {"n": len(own), "same_gate": same_gate, "own_median_present": present,
                      "own_median_present_before": sum(b["own_median_hz_p"] is not None for _, b in own) / len(own)}
    exact = [a for a, _ in gen if a["cls"] == 0 and a["fs"] >= 100.0]
    if exact:
        absent = sum(a["own_median_hz_p"] is None for a in exact) / len(exact)
        met["C5"] = absent >= 0.9
        out["exact_own_median_absent"] = {"n": len(exact), "absent": absent}
    out["criteria"] = met
    out["met"] = all(met.values())
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", action="store_true", help="identify every window of the rule with this tree")
    ap.add_argument("--tag", default="after", help="with --run: the JSON's tag (after, or before for ee651b8)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--verdict", action="store_true", help="judge the stored after and before runs by RULE")
    args = ap.parse_args(argv)
    out: dict = {}
    if args.run:
        out = {"machine": common.machine(), "rows": run(args.workers)}
        common.write_json(f"output_floors_{args.tag}", out)
    if args.verdict:
        out = verdict(common.read_json("output_floors_after")["rows"], common.read_json("output_floors_before")["rows"])
        for c in out["cells"]:
            if c["set"] == "generator":
                print(f"generator {c['fs']:g} frames/s DL {c['level']} class {c['cls']}: noise_p / injected "
                      + " / ".join(f"{x:.2f}" for x in c["p_10_50_90"]) + ", noise_q "
                      + " / ".join(f"{x:.2f}" for x in c["q_10_50_90"]) + ("" if c["met"] else "  NOT met"))
            else:
                print(f"ANDES {c['fs']:g} frames/s (n {c['n']}): median noise_p / injected {c['median']['p']:.2f} "
                      f"(band median {c['band_median']['p']:.2f}), noise_q {c['median']['q']:.2f} "
                      f"({c['band_median']['q']:.2f})" + ("" if c["met"] else "  NOT met"))
        print("D changed / without a gate change, per rate: " + ", ".join(
            f"{k}: {v['d_changed']} of {v['n']} / {v['without_a_gate_change']}" for k, v in out["changed"].items()))
        if "own" in out:
            print(f"own-fluctuation windows: same gate {100 * out['own']['same_gate']:.1f} %, own_median_hz_p present "
                  f"{100 * out['own']['own_median_present']:.1f} % (before {100 * out['own']['own_median_present_before']:.1f} %)")
        if "exact_own_median_absent" in out:
            print(f"exact inputs at 100-120 frames/s: own_median_hz_p absent on "
                  f"{100 * out['exact_own_median_absent']['absent']:.1f} %")
        print("criteria: " + ", ".join(f"{k} {'met' if v else 'NOT met'}" for k, v in out["criteria"].items()))
        print(f"verdict: {'met' if out['met'] else 'not met'}")
        common.write_json("output_floors_verdict", out)
    return out


if __name__ == "__main__":
    main()
