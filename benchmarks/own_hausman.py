"""Choosing per window between the prediction-error fit and the IV: a Hausman-type comparison of their D.

Under own fluctuation the gated default answers with the IV (consistent through the loop, at the price of weak
instruments); the prediction-error fit with the same coupled AR model (``disturbance="ar"``) is more efficient where
the loop does not bias it (:mod:`benchmarks.own_loop`: on 2 Hz own processes) and far off where it does (step-like
switching).  The textbook rule: if the efficient estimate is consistent, the two differ only by the IV's extra
scatter, Var(D_IV − D_PEM) = Var(D_IV) − Var(D_PEM); so answer with the PEM unless some parameter's difference
exceeds ``Z_MAX`` of √(SE_IV² − SE_PEM²) (2.5: two-sided 5 % over the four parameters, Bonferroni; fixed, not tuned).

A second rule looks at the loop itself (stop 36): the loop biases the prediction-error fit where the load's own
innovations move V in the same sample, so at the PEM's D the whitened P residual is then correlated at lag 0 with V's
one-step innovation (from V's own AR model).  ``loop test``: the PEM unless that correlation, as z = r·√n, has
|z| > ``Z_LOOP`` (3; set after seeing the statistic's spread on the development windows, closed ≈ −13 to −16 on switching
and |median| ≤ 1.6 elsewhere, not tuned on the choice's errors), else the IV.

Per row (own shape, own/clean ratio, P–Q coherence; exact V and θ; the same windows as the own bench's seed):
median |error| and bias of the IV, the PEM and the two choices, and how often each took the PEM.

    .venv/bin/python -m benchmarks.own_hausman [--seed 243] [--n 30] [--coherence 1 0.7] [--andes --own-seed 1]

Results: ``docs/results/own_hausman_seed<seed>.json`` or ``own_hausman_andes_own<seed>.json``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

from aslm_core import IdentifyConfig, WindowError, disturbance, identify  # noqa: E402
from aslm_core.preprocess import prepare  # noqa: E402
from aslm_core.problem import Problem  # noqa: E402
from aslm_sim.cases import make_cases  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.own_fluctuation import LEVEL, own_cases  # noqa: E402
from benchmarks.own_loop import innovations  # noqa: E402

PEM = IdentifyConfig(disturbance="ar", input_weighting="none")
IV = IdentifyConfig(disturbance="ar_iv", input_weighting="none")
Z_MAX = 2.5
Z_LOOP = 3.0


def loop_z(window, d: np.ndarray) -> float:
    """z = r·√n of the lag-0 correlation of the whitened P residual at D with V's one-step innovation [-]."""
    prep = prepare(window, floors=True)
    pb = Problem(prep, window.f0, PEM)
    r = pb.residuals(np.asarray(d, dtype=np.float64), jacobian=False)
    if r is None:
        return float("nan")
    skip = disturbance.AR_MAX_ORDER  # both filters' start-up
    e, ev = innovations(r[0])[skip:], innovations(prep.V[pb.k0:])[skip:]
    return float(np.corrcoef(e, ev)[0, 1] * np.sqrt(e.size))


def choice(iv, pem) -> tuple[np.ndarray, bool, float]:
    """(D of the choice, whether it is the PEM's, the largest |z| of the comparison)."""
    se_iv = np.array([iv.stderr[k] for k in common.PARAMS])
    se_pem = np.array([pem.stderr[k] for k in common.PARAMS])
    diff = np.sqrt(np.maximum(se_iv**2 - se_pem**2, 1e-12 * se_iv**2))
    z = float(np.max(np.abs(iv.d - pem.d) / diff))
    return (pem.d, True, z) if z <= Z_MAX else (iv.d, False, z)


def row(windows: list, truths: list) -> dict:
    errs = {"IV": [], "PEM": [], "choice": [], "loop test": []}
    took, zs, took_loop, zl = [], [], [], []
    for w, t in zip(windows, truths, strict=True):
        try:
            iv, pem = identify(w, config=IV), identify(w, config=PEM)
        except WindowError:
            continue
        d, is_pem, z = choice(iv, pem)
        z_loop = loop_z(w, pem.d)
        d_loop = pem.d if abs(z_loop) <= Z_LOOP else iv.d
        for k, v in (("IV", iv.d), ("PEM", pem.d), ("choice", d), ("loop test", d_loop)):
            errs[k].append(100.0 * (v / t - 1.0))
        took.append(is_pem)
        zs.append(z)
        took_loop.append(abs(z_loop) <= Z_LOOP)
        zl.append(z_loop)
    out = {k: {"median_abs_pct": np.median(np.abs(v), axis=0).tolist(), "bias_pct": np.mean(v, axis=0).tolist(),
               "off_20": int(np.sum(np.max(np.abs(v), axis=1) > 20.0)), "errors_pct": np.array(v).tolist()}
           for k, v in errs.items()}
    out["took_pem"] = int(sum(took))
    out["took_pem_loop_test"] = int(sum(took_loop))
    out["n"] = len(took)
    out["z"] = zs
    out["z_loop"] = zl
    return out


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=243, help="synthetic own bench seed (243: development)")
    ap.add_argument("--n", type=int, default=30)
    ap.add_argument("--shapes", nargs="+", default=["lowpass", "switching", "pink"])
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.5, 0.9])
    ap.add_argument("--coherence", nargs="+", type=float, default=[1.0, 0.7])
    ap.add_argument("--andes", action="store_true", help="the ANDES own bench instead")
    ap.add_argument("--own-seed", type=int, default=1, help="with --andes: own seed (1: development)")
    args = ap.parse_args(argv)
    out = {"machine": common.machine(), "z_max": Z_MAX, "z_loop": Z_LOOP, "n": args.n, "rows": []}
    table = []
    if args.andes:
        from aslm_sim.andes import own_fluctuation as andes_own
        from benchmarks import own_fluctuation_andes as bench

        grid = andes_own.grid_recording(tf=bench.TF, tstep=bench.TSTEP, seed=bench.SEED, fs=bench.FS)
        truth = np.asarray(grid["truth"], dtype=np.float64)
    else:
        base = make_cases(args.n, level=LEVEL, seed=args.seed, input_noise=False)
    for coh in args.coherence:
        for shape in args.shapes:
            if args.andes:
                own = andes_own.own_recording(shape, tf=bench.TF, tstep=bench.TSTEP, seed=args.own_seed, coherence=coh)
            for ratio in args.ratios:
                if args.andes:
                    windows = [bench.as_window(w) for w in bench.row_windows(grid, own, ratio, shape, args.n,
                                                                              args.own_seed)]
                    truths = [truth] * len(windows)
                else:
                    cs = own_cases(args.n, ratio, shape, base, args.seed, coh)
                    windows, truths = [c.window for c in cs], [c.truth.d for c in cs]
                r = row(windows, truths)
                r.update(shape=shape, ratio=ratio, coherence=coh)
                out["rows"].append(r)
                table.append([f"{coh:g}", shape, f"{ratio:g}",
                              *(" / ".join(f"{x:.1f}" for x in r[k]["median_abs_pct"]) + f" ({r[k]['bias_pct'][0]:+.1f})"
                                for k in ("IV", "PEM", "choice", "loop test")), f"{r['took_pem']}/{r['n']}",
                              f"{r['took_pem_loop_test']}/{r['n']}"])
                print(f"ρ {coh:g} {shape} {ratio:g}: done", flush=True)
    print(common.md_table(["ρ", "shape", "own", "IV median a / b / H2 / Tm (bias a)", "PEM", "choice", "loop test",
                           "choice took PEM", "loop test took PEM"], table))
    if not args.no_write:
        common.write_json(f"own_hausman_andes_own{args.own_seed}" if args.andes else f"own_hausman_seed{args.seed}", out)
    return out


if __name__ == "__main__":
    main()
