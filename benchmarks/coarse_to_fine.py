"""Coarse-to-fine descent against full-grid descent: the same answers, the time ratio, the evaluations.

Interleaved in one run on the same windows (DL 1–3 and noise-free, paper protocol, and DL 1–2 with
noise on V and θ too): ``identify`` with ``coarse_to_fine`` on (default) and off, 3 random starts, one
core.  Prints per set how many answers differ (D by > 1e-4 relative) and whose objective is lower, the median
time of each (minimum of 3 repeats per window) and their ratio.

    .venv/bin/python -m benchmarks.coarse_to_fine [--quick]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import time  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import IdentifyConfig, identify  # noqa: E402
from benchmarks import common  # noqa: E402

SEED = 23
CONFIGS = {"full": IdentifyConfig(coarse_to_fine=False), "c2f": IdentifyConfig()}


def _run(windows, reps: int) -> dict:
    """Both configurations on every window, interleaved; times are the minimum over ``reps``."""
    out = {k: {"t": [], "d": [], "cost": [], "ev": []} for k in CONFIGS}
    for w in windows:
        for k, cfg in CONFIGS.items():
            ts = []
            for _ in range(reps):
                t0 = time.perf_counter()
                r = identify(w, config=cfg)
                ts.append(time.perf_counter() - t0)
            out[k]["t"].append(min(ts))
            out[k]["d"].append(r.d)
            out[k]["cost"].append(r.objective)
            out[k]["ev"].append(r.evaluations)
    return out


def main(argv=None) -> dict:
    args = common.parser(__doc__.splitlines()[0]).parse_args(argv)
    n = 10 if args.quick else 60
    sets = [(f"DL {lv}", lv, False) for lv in (1, 2, 3)] + [("noise-free", None, False)]
    sets += [(f"DL {lv}, noise on V and θ too", lv, True) for lv in (1, 2)]
    w0 = common.cases(1, level=1, seed=SEED)[0].window
    for cfg in CONFIGS.values():
        identify(w0, config=cfg)  # compile / load the numba cache outside the timings
    rows, res = [], {}
    for name, lv, inn in sets:
        cs = common.cases(n, level=lv, seed=SEED, input_noise=inn)
        o = _run([c.window for c in cs], reps=3)
        dd = np.max(np.abs(np.array(o["c2f"]["d"]) / np.array(o["full"]["d"]) - 1), axis=1)
        rc = np.array(o["c2f"]["cost"]) / np.array(o["full"]["cost"]) - 1
        tf, tc = np.median(o["full"]["t"]) * 1e3, np.median(o["c2f"]["t"]) * 1e3
        res[name] = {"n": n, "d_differs_1e-4": int(np.sum(dd > 1e-4)), "c2f_higher_of": int(np.sum((dd > 1e-4) & (rc > 0))),
                     "c2f_lower_of": int(np.sum((dd > 1e-4) & (rc < 0))), "max_of_rel_diff": float(np.max(np.abs(rc[dd > 1e-4]), initial=0.0)),
                     "full_ms": float(tf), "c2f_ms": float(tc), "ratio": float(tc / tf),
                     "evals_full": float(np.median(o["full"]["ev"])), "evals_c2f": float(np.median(o["c2f"]["ev"]))}
        r = res[name]
        rows.append([name, n, r["d_differs_1e-4"], f"{r['c2f_higher_of']} / {r['c2f_lower_of']}",
                     f"{100 * r['max_of_rel_diff']:.2f} %",
                     f"{tf:.2f} ms", f"{tc:.2f} ms", f"{r['ratio']:.2f}",
                     f"{r['evals_full']:.0f} / {r['evals_c2f']:.0f}"])
        print(f"{name} done", flush=True)
    text = common.md_table(["windows", "n", "D differs > 1e-4", "of which OF higher / lower with coarse to fine", "largest OF difference",
                            "full grid", "coarse to fine", "time ratio", "evaluations full / c2f (median)"], rows)
    text += ("\n\nEvaluations with coarse to fine count coarse-grid ones too (each about a quarter of the cost "
             "at 100 frames/s). Times: median over the windows of the minimum of 3 repeats, one core.")
    print(text)
    if not args.no_write:
        out = {"machine": common.machine(), "seed": SEED, "quick": args.quick, "sets": res}
        stem = "coarse_to_fine" + ("_quick" if args.quick else "")
        common.write_json(stem, out)
        body = (f"Command: `{common.command('coarse_to_fine', args.quick)}` — seed {SEED}, machine: "
                f"{out['machine']['cpus']} cores, shared (load average at start "
                f"{out['machine']['load_avg_at_start']}), {out['machine']['date']}. Raw numbers: "
                f"`docs/results/{stem}.json`.\n\n" + text)
        common.write_section(stem.replace("_", "-"), body)
    return out


if __name__ == "__main__":
    main()
