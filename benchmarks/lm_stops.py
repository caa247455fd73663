"""Where the upper stage's LM stops: every start's end point checked against the KKT conditions.

DL 1 windows (paper protocol), many random starts each, full-grid LM (no coarse grid, no duplicate
stopping). A start that ends above its window's best objective is either at another KKT point (another
local minimum) or stopped where a feasible direction still descends (non-KKT: an optimiser defect).
Run it on an older commit to see the counts the constrained step removed.

    .venv/bin/python -m benchmarks.lm_stops [--quick]
"""

from __future__ import annotations

import time

import numpy as np
from scipy.optimize import nnls

from aslm_core import IdentifyConfig
from aslm_core.identify import EQUILIBRIUM_MARGIN, Problem, levenberg_marquardt
from aslm_core.preprocess import prepare
from benchmarks import common

SEED = 41


def kkt_residual(problem: Problem, d: np.ndarray) -> float:
    """Relative norm of the part of the eq. 7 gradient that no active constraint's multiplier (≥ 0) takes.

    Per relative change of each parameter, divided by the objective: 0 at a KKT point.
    """
    rp, rq, jp, jq = problem.residuals(d, jacobian=True)
    g = (jp.T @ rp / np.linalg.norm(rp) + jq.T @ rq / np.linalg.norm(rq)) / problem.l
    active = []
    for u in range(4):
        if d[u] <= problem.lower[u] * (1 + 1e-9):
            active.append(np.eye(4)[u])
        if d[u] >= problem.upper[u] * (1 - 1e-9):
            active.append(-np.eye(4)[u])
    v2 = problem.v_min**2
    if (d[0] * v2 * (1 - EQUILIBRIUM_MARGIN) - 2 * d[1] * d[3]) / (d[0] * v2) < 1e-6:
        active.append(np.array([v2 * (1 - EQUILIBRIUM_MARGIN), -2 * d[3], 0.0, -2 * d[1]]))
    gs = g * d
    if not active:
        return float(np.linalg.norm(gs) / problem.cost(rp, rq))
    _, res = nnls(np.array(active).T * d[:, None], gs)
    return float(res / problem.cost(rp, rq))


def count(integrator: str, n_windows: int, n_starts: int) -> dict:
    """Counts over all starts of ``n_windows`` DL 1 windows."""
    cs = common.cases(n_windows, level=1, seed=SEED, input_noise=False)
    config = IdentifyConfig(integrator=integrator)
    out = {"starts": 0, "finite": 0, "above_best": 0, "above_best_non_kkt": 0, "above_best_on_constraint": 0,
           "above_best_max_iter": 0, "evaluations": 0}
    for c in cs:
        problem = Problem(prepare(c.window), c.window.f0, config)
        rng = np.random.default_rng(5)
        runs = [levenberg_marquardt(problem, problem.random_start(rng)) for _ in range(n_starts)]
        best = min(r["cost"] for r in runs)
        out["starts"] += len(runs)
        out["evaluations"] += sum(r["evaluations"] for r in runs)
        for r in runs:
            if not np.isfinite(r["cost"]):
                continue
            out["finite"] += 1
            if r["cost"] <= best * (1 + 1e-3):
                continue
            d = r["d"]
            out["above_best"] += 1
            out["above_best_max_iter"] += r["status"] == "max_iter"
            av = d[0] * problem.v_min**2
            out["above_best_on_constraint"] += (av * (1 - EQUILIBRIUM_MARGIN) - 2 * d[1] * d[3]) / av < 1e-4
            out["above_best_non_kkt"] += r["status"] == "converged" and kkt_residual(problem, d) > 1e-2
    return out


def main(argv=None) -> dict:
    args = common.parser(__doc__.splitlines()[0]).parse_args(argv)
    n_windows, n_starts = (20, 10) if args.quick else (200, 20)
    t0 = time.perf_counter()
    res = {k: count(k, n_windows, n_starts) for k in ("rk4", "euler")}
    rows = [[k, r["starts"], r["finite"], r["above_best"], r["above_best_non_kkt"], r["above_best_on_constraint"],
             r["above_best_max_iter"], f"{r['evaluations'] / r['starts']:.1f}"] for k, r in res.items()]
    text = (f"{n_windows} DL 1 windows (seed {SEED}) × {n_starts} random starts, full-grid LM:\n\n"
            + common.md_table(["integrator", "starts", "finite OF", "end above the window's best (> 0.1 %)",
                               "of those converged at a non-KKT point", "of those on the equilibrium constraint",
                               "of those at max_iter", "evaluations / start"], rows))
    print(text)
    if not args.no_write:
        common.write_json("lm_stops" + ("_quick" if args.quick else ""),
                          {"machine": common.machine(), "windows": n_windows, "starts": n_starts, "counts": res,
                           "total_s": time.perf_counter() - t0})
    return res


if __name__ == "__main__":
    main()
