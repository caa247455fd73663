"""Table II analogue: fitting degree (eq. 9) of identified vs true load under large disturbances.

For each level, the load identified from its ambient window (paper protocol, RK4 default) is played back
on the V/θ of two fault events of the TRUE load (``aslm_sim.faults.large_disturbance``: event A, 20 % sag for
100 ms; event B, 30 % sag for 150 ms; the network around the load differs between them), with
``motor.simulate`` + ``static.static_power``, and compared with the event's P and Q by FD (eq. 9, mean of P
and Q).  Reference rows: the true D with the static part regressed from the same ambient window (OS(D_real),
shows whether the static part limits FD), and the true D with the true static part (checks the playback).

    .venv/bin/python -m benchmarks.table2 [--quick]
"""

from __future__ import annotations

import math
import time

import numpy as np

from aslm_core import IdentifyConfig, WindowError, identify_many, motor, static
from aslm_core.preprocess import prepare
from aslm_sim.faults import large_disturbance
from benchmarks import common

SEED = 31
EVENTS = {"A": {"sag_depth": 0.2, "fault_duration_s": 0.1}, "B": {"sag_depth": 0.3, "fault_duration_s": 0.15}}


def fd(y1: np.ndarray, y2: np.ndarray) -> float:
    """Fitting degree, eq. 9: 1 − Σ(y2 − y1)² / Σ(y1 − mean y1)²."""
    return 1.0 - float(np.sum((y2 - y1) ** 2)) / float(np.sum((y1 - y1.mean()) ** 2))


def playback_fd(event, d, static_coef) -> float:
    """Mean of FD(P) and FD(Q) of a model (D + static coefficients) driven by the event's V, θ."""
    try:
        p_im, q_im, _ = motor.simulate(event.V, event.theta, np.asarray(d, float), event.dt,
                                       motor.omega0_of(event.f0))
    except Exception:  # no equilibrium: the model cannot even start
        return -math.inf
    if not np.all(np.isfinite(p_im)):
        return -math.inf
    p_st, q_st = static.static_power(event.V, static_coef)
    return 0.5 * (fd(event.P, p_im + p_st) + fd(event.Q, q_im + q_st))


def regressed_static(window, d, skip_s: float = IdentifyConfig().skip_s) -> dict:
    """OS(D): the lower-stage ZIP regression of the ambient window for a fixed D (RK4 playback)."""
    prep = prepare(window)
    p_im, q_im, _ = motor.simulate(prep.V, prep.theta, np.asarray(d, float), prep.dt, motor.omega0_of(window.f0))
    k0 = int(math.ceil(skip_s / prep.dt - 1e-9))
    phi = static.regressors(prep.V[k0:], "zip")
    bp = np.linalg.lstsq(phi, prep.P[k0:] - p_im[k0:], rcond=None)[0]
    bq = np.linalg.lstsq(phi, prep.Q[k0:] - q_im[k0:], rcond=None)[0]
    return static.coefficients(bp, bq, "zip")


def summary(fds) -> dict:
    f = np.asarray(fds, dtype=float)
    return {"n": int(f.size), "median": float(np.median(f)), "pct_gt_0.9": float(100 * np.mean(f > 0.9)),
            "pct_gt_0.95": float(100 * np.mean(f > 0.95)), "min": float(np.min(f))}


def main(argv=None) -> dict:
    args = common.parser(__doc__.splitlines()[0]).parse_args(argv)
    n = 30 if args.quick else 300
    t_all = time.perf_counter()
    out = {"machine": common.machine(), "n_per_level": n, "seed": SEED, "events": EVENTS, "quick": args.quick}
    levels = (1, 2, 3)
    res = {}
    events_cache = {}
    for level in (*levels, None):
        cs = common.cases(n, level=level, seed=SEED, input_noise=False)
        ids = identify_many([c.window for c in cs], config=IdentifyConfig(), workers=2)
        rows = {"identified": {e: [] for e in EVENTS}, "true_D_regressed_static": {e: [] for e in EVENTS},
                "true_D_true_static": {e: [] for e in EVENTS}}
        for i, (c, r) in enumerate(zip(cs, ids, strict=True)):
            st_true_d = regressed_static(c.window, c.truth.d)
            for e, kw in EVENTS.items():
                key = (i, e)
                if key not in events_cache:  # same clean records at every level: same truths, same events
                    events_cache[key] = large_disturbance(c.truth, seed=SEED * 100 + i, **kw)
                ev = events_cache[key]
                rows["identified"][e].append(-math.inf if isinstance(r, WindowError)
                                             else playback_fd(ev, r.d, r.static))
                rows["true_D_regressed_static"][e].append(playback_fd(ev, c.truth.d, st_true_d))
                rows["true_D_true_static"][e].append(playback_fd(ev, c.truth.d, c.truth.static_identifiable))
        res["noise-free" if level is None else level] = {k: {e: summary(v[e]) for e in EVENTS}
                                                         for k, v in rows.items()}
        print(f"level {level} done ({time.perf_counter() - t_all:.0f} s)", flush=True)
    out.update(results=res, total_s=time.perf_counter() - t_all)

    head = ["DL", "model", "M(FD) A", "%>0.9 A", "%>0.95 A", "min A", "M(FD) B", "%>0.9 B", "%>0.95 B", "min B"]
    rows = []
    names = {"identified": "identified (D_opt, OS(D_opt))", "true_D_regressed_static": "true D, OS(D_real)",
             "true_D_true_static": "true D, true static"}
    for lv, r in res.items():
        for k, label in names.items():
            cells = []
            for e in EVENTS:
                s = r[k][e]
                cells += [f"{s['median']:.4f}", f"{s['pct_gt_0.9']:.1f}", f"{s['pct_gt_0.95']:.1f}", f"{s['min']:.3f}"]
            rows.append([lv, label, *cells])
    for lv, (yc, xls) in common.PAPER_TABLE2.items():
        rows.append([lv, "paper (Fault YC / Fault XLS)", f"{yc[0]:.3f}", yc[1], yc[2], "–",
                     f"{xls[0]:.3f}", xls[1], xls[2], "–"])
    text = common.md_table(head, rows)
    print(text)
    if not args.no_write:
        common.write_json("table2" + ("_quick" if args.quick else ""), out)
        body = (f"Command: `{common.command('table2', args.quick)}` — {n} loads per level (seed {SEED}, paper "
                f"protocol: noise on P and Q only, RK4 identification), events A = "
                f"{EVENTS['A']['sag_depth']:.0%} sag for {EVENTS['A']['fault_duration_s'] * 1e3:.0f} ms and B = "
                f"{EVENTS['B']['sag_depth']:.0%} sag for {EVENTS['B']['fault_duration_s'] * 1e3:.0f} ms at the load bus "
                f"(5 s records at 100 Hz), total {out['total_s']:.0f} s. Raw numbers: "
                f"`docs/results/table2{'_quick' if args.quick else ''}.json`.\n\n" + text)
        common.write_section("table2" + ("-quick" if args.quick else ""), body)
    return out


if __name__ == "__main__":
    main()
