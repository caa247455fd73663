"""§VI.C: quasi-convexity test of OF(D) and reliability test of the gradient-based upper stage.

Quasi-convexity (paper: 1000 DL=1 cases × 10,000 pairs): for pairs of random feasible points D1, D2 of a
case, success if OF((D1 + D2)/2) < max(OF(D1), OF(D2)); the success percentage (SP) per case.  Points
are drawn as ``identify`` draws its starts (a, b, H2 uniform in the box, then Tm uniform below the
equilibrium limit).  A midpoint outside the equilibrium set (the set is not convex) counts as a failure
and is reported.  OF is eq. 7 on the RK4 model (our default); the paper's explicit Euler is also tested,
where pairs with an end at which Euler diverges (OF = ∞) are excluded and counted.

Reliability (paper: 1000 cases × 1000 SQP runs): per case, many runs of our Levenberg–Marquardt from
random feasible starts; D_opt = the argmin of OF over the runs; a run succeeds if
Σ_j |D_ij/D_opt,j − 1| < 0.1 (the paper writes the sum without absolute values, which lets errors of
opposite signs cancel; we use the absolute value).  A small run of the faithful SLSQP baseline is added.

    .venv/bin/python -m benchmarks.convexity [--quick]
"""

from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from aslm_core import IdentifyConfig
from aslm_core.identify import Problem, levenberg_marquardt
from aslm_core.preprocess import prepare
from benchmarks import baselines, common

SEED = 41


def of(problem: Problem, d: np.ndarray) -> float:
    if not problem.feasible(d):
        return math.nan  # outside the equilibrium set (only midpoints can be)
    r = problem.residuals(d, jacobian=False)
    if r is None:
        return math.inf
    return problem.cost(r[0], r[1])


def quasi_convexity(window, n_pairs: int, integrator: str, seed: int) -> dict:
    problem = Problem(prepare(window), window.f0, IdentifyConfig(integrator=integrator))
    rng = np.random.default_rng(seed)
    ok = fail = mid_infeasible = excluded = 0
    for _ in range(n_pairs):
        d1, d2 = problem.random_start(rng), problem.random_start(rng)
        f1, f2 = of(problem, d1), of(problem, d2)
        if not (math.isfinite(f1) and math.isfinite(f2)):
            excluded += 1
            continue
        fm = of(problem, 0.5 * (d1 + d2))
        if math.isnan(fm):
            mid_infeasible += 1
            fail += 1
        elif fm < max(f1, f2):
            ok += 1
        else:
            fail += 1
    n = ok + fail
    return {"sp": 100.0 * ok / n if n else math.nan, "n": n, "mid_infeasible": mid_infeasible,
            "excluded": excluded}


def reliability(window, n_starts: int, seed: int) -> dict:
    problem = Problem(prepare(window), window.f0, IdentifyConfig())
    rng = np.random.default_rng(seed)
    runs = [levenberg_marquardt(problem, problem.random_start(rng)) for _ in range(n_starts)]
    out = _reliability_of([r["d"] for r in runs], [r["cost"] for r in runs])
    # Failed runs that stopped within 2 iterations with status "converged" (a premature stop at the start).
    out["fail_early_stop"] = int(sum(1 for r, ok in zip(runs, out.pop("_ok"), strict=True)
                                     if not ok and r["status"] == "converged" and r["iterations"] <= 2))
    out["fail_status"] = {}
    for r, ok in zip(runs, out.pop("_ok2"), strict=True):
        if not ok:
            out["fail_status"][r["status"]] = out["fail_status"].get(r["status"], 0) + 1
    return out


def _reliability_of(ds, costs) -> dict:
    costs = np.asarray(costs, dtype=float)
    ds = np.asarray(ds, dtype=float)
    best = ds[int(np.argmin(costs))]
    dev = np.abs(ds / best - 1.0).sum(axis=1)
    signed = (ds / best - 1.0).sum(axis=1)
    ok = np.isfinite(costs) & (dev < 0.1)
    ok_paper = np.isfinite(costs) & (signed < 0.1)
    return {"sp": float(100 * ok.mean()), "sp_paper_signed": float(100 * ok_paper.mean()), "n": int(len(costs)),
            "failed_runs": int(np.sum(~np.isfinite(costs))), "_ok": ok.tolist(), "_ok2": ok.tolist()}


def hist_line(sps: np.ndarray) -> str:
    edges = [0, 80, 88, 90, 92, 94, 96, 98, 99, 100.0001]
    counts, _ = np.histogram(sps, bins=edges)
    return ", ".join(f"[{edges[i]:g}, {min(edges[i + 1], 100):g}{']' if i == len(counts) - 1 else ')'}: {c}"
                     for i, c in enumerate(counts))


def main(argv=None) -> dict:
    args = common.parser(__doc__.splitlines()[0]).parse_args(argv)
    q = args.quick
    n_cases, n_pairs = (10, 200) if q else (100, 2000)
    n_cases_euler, n_pairs_euler = (5, 100) if q else (50, 1000)
    n_rel_cases, n_rel_starts = (10, 20) if q else (100, 100)
    n_sq_cases, n_sq_starts = (1, 4) if q else (5, 20)
    t_all = time.perf_counter()
    out = {"machine": common.machine(), "seed": SEED, "quick": q}
    cs = common.cases(max(n_cases, n_rel_cases), level=1, seed=SEED, input_noise=False)

    with ThreadPoolExecutor(max_workers=2) as pool:  # the numba kernels release the GIL
        qc = list(pool.map(lambda i: quasi_convexity(cs[i].window, n_pairs, "rk4", SEED + i), range(n_cases)))
        print(f"quasi-convexity rk4 done ({time.perf_counter() - t_all:.0f} s)", flush=True)
        qe = list(pool.map(lambda i: quasi_convexity(cs[i].window, n_pairs_euler, "euler", SEED + i),
                           range(n_cases_euler)))
        print(f"quasi-convexity euler done ({time.perf_counter() - t_all:.0f} s)", flush=True)
        rel = list(pool.map(lambda i: reliability(cs[i].window, n_rel_starts, SEED + i), range(n_rel_cases)))
        print(f"reliability done ({time.perf_counter() - t_all:.0f} s)", flush=True)
    sq = []
    for i in range(n_sq_cases):
        w = cs[i].window
        pp = baselines.PaperProblem.from_window(w)
        rng = np.random.default_rng(SEED + i)
        runs = [baselines.slsqp_from(pp, pp.random_start(rng, finite=True)) for _ in range(n_sq_starts)]
        r = _reliability_of([r["d"] for r in runs], [r["of"] for r in runs])
        r.pop("_ok"), r.pop("_ok2")
        sq.append(r)
    print(f"SLSQP reliability done ({time.perf_counter() - t_all:.0f} s)", flush=True)

    def qsum(res):
        sp = np.array([r["sp"] for r in res])
        return {"cases": len(res), "pairs_per_case": None, "median_sp": float(np.median(sp)),
                "min_sp": float(np.min(sp)), "pct_cases_sp_gt_96": float(100 * np.mean(sp > 96)),
                "mid_infeasible": int(sum(r["mid_infeasible"] for r in res)),
                "excluded": int(sum(r["excluded"] for r in res)), "pairs_tested": int(sum(r["n"] for r in res)),
                "histogram": hist_line(sp), "per_case": res}

    def rsum(res):
        sp = np.array([r["sp"] for r in res])
        sps = np.array([r["sp_paper_signed"] for r in res])
        return {"cases": len(res), "n_100": int(np.sum(sp == 100)), "n_ge_99_9": int(np.sum(sp >= 99.9)),
                "min_sp": float(sp.min()), "median_sp": float(np.median(sp)), "min_sp_paper_signed": float(sps.min()),
                "failed_runs": int(sum(r["failed_runs"] for r in res)),
                "runs_failed": int(sum(round(r["n"] * (100 - r["sp"]) / 100) for r in res)),
                "fail_early_stop": int(sum(r.get("fail_early_stop", 0) for r in res)), "per_case": res}

    out.update(
        quasi_convexity_rk4={**qsum(qc), "pairs_per_case": n_pairs},
        quasi_convexity_euler={**qsum(qe), "pairs_per_case": n_pairs_euler},
        reliability_lm={**rsum(rel), "starts_per_case": n_rel_starts},
        reliability_slsqp={**rsum(sq), "starts_per_case": n_sq_starts},
        total_s=time.perf_counter() - t_all,
    )
    a, e = out["quasi_convexity_rk4"], out["quasi_convexity_euler"]
    rows = [
        ["OF on RK4 (ours)", f"{n_cases} × {n_pairs}", f"{a['median_sp']:.2f}", f"{a['min_sp']:.2f}",
         f"{a['pct_cases_sp_gt_96']:.1f}", f"{a['mid_infeasible']} of {a['pairs_tested']}", a["excluded"]],
        ["OF on explicit Euler (paper)", f"{n_cases_euler} × {n_pairs_euler}", f"{e['median_sp']:.2f}",
         f"{e['min_sp']:.2f}", f"{e['pct_cases_sp_gt_96']:.1f}", f"{e['mid_infeasible']} of {e['pairs_tested']}",
         e["excluded"]],
        ["paper", "1000 × 10,000", "98.69", "88.28", "95.3", "–", "–"],
    ]
    text = "**Quasi-convexity test** (DL=1, paper protocol):\n\n" + common.md_table(
        ["objective", "cases × pairs", "median SP %", "min SP %", "% cases SP > 96", "midpoint infeasible (failures)",
         "pairs excluded (an end diverges)"], rows)
    text += f"\n\nHistogram of SP (RK4): {a['histogram']}.\n\nHistogram of SP (Euler): {e['histogram']}."
    rl, rs = out["reliability_lm"], out["reliability_slsqp"]
    rows = [
        ["ours: LM, exact gradients, RK4", f"{n_rel_cases} × {n_rel_starts}", rl["n_100"], rl["n_ge_99_9"],
         f"{rl['median_sp']:.1f}", f"{rl['min_sp']:.1f}", f"{rl['min_sp_paper_signed']:.1f}", rl["failed_runs"]],
        ["faithful baseline: SLSQP, FD gradients, Euler (finite-OF starts)", f"{n_sq_cases} × {n_sq_starts}",
         rs["n_100"], rs["n_ge_99_9"], f"{rs['median_sp']:.1f}", f"{rs['min_sp']:.1f}",
         f"{rs['min_sp_paper_signed']:.1f}", rs["failed_runs"]],
        ["paper: SQP", "1000 × 1000", 961, 996, "100", "95.7", "–", "–"],
    ]
    text += ("\n\n**Reliability test** (success: Σ_j |D_ij/D_opt,j − 1| < 0.1; the last-but-one column uses the "
             "paper's signed sum):\n\n" + common.md_table(
                 ["method", "cases × starts", "cases SP = 100 %", "cases SP ≥ 99.9 %", "median SP %", "min SP %",
                  "min SP % (signed)", "runs with OF = ∞"], rows))
    text += (f"\n\nOf the {rl['runs_failed']} unsuccessful LM runs, {rl['fail_early_stop']} stopped with status "
             f"`converged` within 2 iterations, i.e. at (or next to) their start: see the discussion.")
    print(text)
    if not args.no_write:
        common.write_json("convexity" + ("_quick" if q else ""), out)
        body = (f"Command: `{common.command('convexity', q)}` — DL=1 cases (seed {SEED}), counts as in the tables "
                f"(scaled down from the paper's), total {out['total_s']:.0f} s. Raw numbers: "
                f"`docs/results/convexity{'_quick' if q else ''}.json`.\n\n" + text)
        common.write_section("convexity" + ("-quick" if q else ""), body)
    return out


if __name__ == "__main__":
    main()
