"""Table III analogue: time per identification of the paper's method (interpreted and compiled), DE (ref. [11]) and ours.

Same windows (DL=1, paper protocol: noise on P and Q).  Ours and both implementations of the paper's method
run from the same three start points on each window: the starts ``identify`` draws for a per-window seed,
the first one (from ``SEED`` + 1000·i on) at which OF with explicit Euler is finite at all three starts (an
SQP needs a defined objective at its start, and every method then spends its three restarts alike); those
points are passed to the baselines.  Every method is timed the same way: per window the minimum over
``REPS`` runs, the methods taking turns in a rotating order, medians and totals over windows.  One core:
BLAS/OpenMP limited to one thread, identifications one after another.  Also: ours on more windows with its
default starts, warm start + one random start, 1,000 windows through ``identify_many`` on 2 workers, and the
same-optimum checks (compiled vs interpreted baseline, and ours with the paper's Euler vs the baseline, per
start).

    .venv/bin/python -m benchmarks.speed [--quick]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import math  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Sequence  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import IdentifyConfig, identify, identify_many  # noqa: E402
from aslm_core.identify import Problem, levenberg_marquardt  # noqa: E402
from aslm_core.preprocess import prepare  # noqa: E402
from benchmarks import baselines, common  # noqa: E402

SEED = 21
REPS = 5
TARGETS = {"ours_ms": 5.0, "ratio": 100.0, "warm_ms": 2.0, "batch_s": 4.0, "same_opt": 1e-4}


def starts_of(window, config: IdentifyConfig) -> list[np.ndarray]:
    """The random starts ``identify(window, config=config)`` draws (same RNG, same Problem)."""
    problem = Problem(prepare(window), window.f0, config)
    rng = np.random.default_rng(config.seed)
    return [problem.random_start(rng) for _ in range(config.n_starts)]


def shared_starts(window, config: IdentifyConfig, seed0: int) -> tuple[int, list[np.ndarray]]:
    """The first seed from ``seed0`` on whose ``identify`` starts all have a finite explicit-Euler OF, and those starts."""
    paper = baselines.CompiledPaperProblem.from_window(window)
    seed = seed0
    while True:
        starts = starts_of(window, replace(config, seed=seed))
        if all(math.isfinite(paper.of(s)) for s in starts):
            return seed, starts
        seed += 1


def interleaved_min(n: int, calls: dict[str, Callable[[int], object]], reps: int = REPS) -> dict[str, list[float]]:
    """Per item i < n and method: the minimum wall time of ``calls[name](i)`` over ``reps`` runs [s].

    The methods take turns on each item, in an order rotated every round, so a slow phase of the shared
    machine (or the cache a method leaves behind) hits them alike; the minimum over repeats drops the
    one-sided delays of other jobs (the cost of the identification itself is what remains).
    """
    names = list(calls)
    out = {k: [] for k in names}
    for i in range(n):
        best = dict.fromkeys(names, math.inf)
        for r in range(reps):
            for k in names[r % len(names):] + names[: r % len(names)]:
                t0 = time.perf_counter()
                calls[k](i)
                best[k] = min(best[k], time.perf_counter() - t0)
        for k in names:
            out[k].append(best[k])
    return out


#: Below this (in each parameter's unit) two values count as equal: Tm ends at exactly 0 from some starts
#: and at 1e-17 from others, a relative difference of 1 between the same corner of the box.
ABS_FLOOR = 1e-9


def max_rel(a: np.ndarray, b: np.ndarray) -> float:
    """Largest relative difference of two D over the four parameters (relative to b, at least ``ABS_FLOOR``)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), ABS_FLOOR)))


def per_start_agreement(runs_a: Sequence[dict], runs_b: Sequence[dict]) -> list[float | None]:
    """Per start: max relative difference of the two methods' end points (None unless both end at a finite OF)."""
    return [max_rel(ra["d"], rb["d"]) if math.isfinite(ra["of"]) and math.isfinite(rb["of"]) else None
            for ra, rb in zip(runs_a, runs_b, strict=True)]


def summary(seconds: Sequence[float]) -> dict:
    """Median and total over windows [ms, s]."""
    return {"median_ms": float(np.median(seconds) * 1e3), "total_s": float(np.sum(seconds))}


def main(argv=None) -> dict:
    p = common.parser(__doc__.splitlines()[0])
    p.add_argument("--n-baseline", type=int, default=None)
    p.add_argument("--n-de", type=int, default=None)
    args = p.parse_args(argv)
    q = args.quick
    n_base = args.n_baseline or (3 if q else 60)
    n_de = args.n_de or (1 if q else 3)
    n_ours = 50 if q else 300
    n_batch = 200 if q else 1000
    out = {"machine": common.machine(), "quick": q, "seed": SEED, "reps": REPS}
    t_all = time.perf_counter()

    cs = common.cases(max(n_ours, n_batch), level=1, seed=SEED, input_noise=False)
    windows = [c.window for c in cs]
    cfg = IdentifyConfig()
    cfg_euler = IdentifyConfig(integrator="euler", skip_s=baselines.SKIP_S, transient_tau=0.0)  # baseline's OF
    # Compile / load every numba cache outside the timings.
    identify(windows[0], config=cfg)
    identify(windows[0], config=cfg_euler)
    baselines.compiled_identify(windows[0], starts=starts_of(windows[0], cfg)[:1])

    # (iii) ours on n_ours windows, its default starts: cold, 3 random starts, RK4 (default) and the paper's
    # Euler; warm: previous D (our cold answer) perturbed by U(±3 %) per parameter + 1 random start.
    rng = np.random.default_rng(SEED)
    cold = [identify(w, config=cfg) for w in windows[:n_ours]]
    warm_d = [r.d * (1.0 + rng.uniform(-0.03, 0.03, 4)) for r in cold]
    cfg_warm = IdentifyConfig(n_starts=1)
    t = interleaved_min(n_ours, {
        "rk4": lambda i: identify(windows[i], config=cfg),
        "euler": lambda i: identify(windows[i], config=cfg_euler),
        "warm": lambda i: identify(windows[i], config=cfg_warm, warm_start=warm_d[i]),
    })
    t_rk4, t_eul, t_warm = t["rk4"], t["euler"], t["warm"]
    warm_res = [identify(w, config=cfg_warm, warm_start=d) for w, d in zip(windows[:n_ours], warm_d, strict=True)]
    warm_dev = float(np.max([max_rel(a.d, b.d) for a, b in zip(warm_res, cold, strict=True)]))
    print(f"ours: {np.median(t_rk4) * 1e3:.2f} ms (rk4), {np.median(t_eul) * 1e3:.2f} ms (euler), "
          f"warm {np.median(t_warm) * 1e3:.2f} ms", flush=True)

    # (i), (i') and ours on the first n_base windows, all from the same three starts per window.
    seeds, starts = zip(*(shared_starts(w, cfg, SEED + 1000 * i) for i, w in enumerate(windows[:n_base])),
                        strict=True)
    last: dict[str, list] = {}  # the results of the last timed run per method and window

    def run(name: str, fn: Callable[[int], object]) -> Callable[[int], object]:
        last[name] = [None] * n_base

        def call(i: int) -> None:
            last[name][i] = fn(i)
        return call

    cmp = interleaved_min(n_base, {
        "ours_rk4": run("ours_rk4", lambda i: identify(windows[i], config=replace(cfg, seed=seeds[i]))),
        "ours_euler": run("ours_euler", lambda i: identify(windows[i], config=replace(cfg_euler, seed=seeds[i]))),
        "compiled": run("compiled", lambda i: baselines.compiled_identify(windows[i], starts=starts[i])),
        "compiled_scipy_fd": run("compiled_scipy_fd", lambda i: baselines.compiled_identify(
            windows[i], starts=starts[i], scipy_gradients=True)),
        "interpreted": run("interpreted", lambda i: baselines.faithful_identify(windows[i], starts=starts[i])),
    })
    same = {k: summary(v) for k, v in cmp.items()}
    print("same windows and starts: " + ", ".join(f"{k} {v['median_ms']:.2f} ms" for k, v in same.items()),
          flush=True)

    # Same optimum, per start: compiled vs interpreted baseline; ours (LM, paper's Euler) vs interpreted.
    comp_dev, lm_dev, runs_info = [], [], []
    best_comp, best_lm = [], []
    for i, w in enumerate(windows[:n_base]):
        interp, comp, ours_e = last["interpreted"][i], last["compiled"][i], last["ours_euler"][i]
        best_comp.append(max_rel(comp.d, interp.d))
        best_lm.append(max_rel(ours_e.d, interp.d))
        problem = Problem(prepare(w), w.f0, cfg_euler)
        lm = [levenberg_marquardt(problem, s, max_iter=cfg_euler.max_iter) for s in starts[i]]
        lm = [{**r, "of": r["cost"]} for r in lm]
        cd = per_start_agreement(comp.runs, interp.runs)
        ld = per_start_agreement(lm, interp.runs)
        comp_dev += cd
        lm_dev += ld
        for k, r in enumerate(interp.runs):
            runs_info.append({"window": i, "seed": seeds[i], "iterations": r["iterations"],
                              "evaluations": r["evaluations"], "of": r["of"], "compiled_of": comp.runs[k]["of"],
                              "compiled_evaluations": comp.runs[k]["evaluations"], "lm_cost": lm[k]["cost"],
                              "lm_status": lm[k]["status"], "message": r["message"], "compiled_dev": cd[k],
                              "lm_dev": ld[k], "d": r["d"], "compiled_d": comp.runs[k]["d"], "lm_d": lm[k]["d"]})

    def agreement(devs: list, best: list, higher_of: Callable[[dict], bool], key: str) -> dict:
        finite = [d for d in devs if d is not None]
        differ = [r for r in runs_info if r[key] is not None and r[key] > TARGETS["same_opt"]]
        return {"best_of_3_max_rel": float(np.max(best)), "per_start_max_rel": float(np.max(finite)),
                "per_start_median_rel": float(np.median(finite)), "starts_compared": len(finite),
                "starts_total": len(devs), "starts_differ": len(differ),
                "starts_differ_other_higher_of": sum(1 for r in differ if higher_of(r))}

    same_opt = {
        "compiled_vs_interpreted": agreement(comp_dev, best_comp, lambda r: r["compiled_of"] > r["of"],
                                             "compiled_dev"),
        "ours_euler_vs_interpreted": agreement(lm_dev, best_lm, lambda r: r["lm_cost"] > r["of"], "lm_dev"),
        "slsqp_ftol": baselines.SLSQP_FTOL, "runs": runs_info,
    }

    # (ii) DE on the first n_de windows
    de_t, de_err = [], []
    for c in cs[:n_de]:
        r = baselines.de_identify(c.window, seed=SEED)
        de_t.append(r.elapsed_s)
        de_err.append((r.d / c.truth.d - 1).tolist())
    print(f"DE: median {np.median(de_t):.1f} s over {n_de} windows", flush=True)

    # batch: n_batch windows on 2 workers (and 1 for reference)
    batch = {}
    for workers in (2, 1):
        t0 = time.perf_counter()
        identify_many(windows[:n_batch], config=cfg, workers=workers)
        batch[workers] = time.perf_counter() - t0

    def ratios(slow: str, fast: str) -> dict:
        """slow / fast: of the medians over windows, of the totals, and the median of per-window ratios."""
        per = np.asarray(cmp[slow]) / np.asarray(cmp[fast])
        return {"of_medians": same[slow]["median_ms"] / same[fast]["median_ms"],
                "of_totals": same[slow]["total_s"] / same[fast]["total_s"], "median_per_window": float(np.median(per))}

    rat = {f"{a}_over_{b}": ratios(a, b) for a, b in (("interpreted", "ours_rk4"), ("compiled", "ours_rk4"),
                                                      ("interpreted", "ours_euler"), ("compiled", "ours_euler"),
                                                      ("interpreted", "compiled"),
                                                      ("interpreted", "compiled_scipy_fd"))}
    med = {"ours_rk4_ms": float(np.median(t_rk4) * 1e3), "ours_euler_ms": float(np.median(t_eul) * 1e3),
           "warm_ms": float(np.median(t_warm) * 1e3), "de_s": float(np.median(de_t)), "batch_2w_s": batch[2],
           "batch_1w_s": batch[1]}
    out.update(
        counts={"ours": n_ours, "baseline": n_base, "de": n_de, "batch": n_batch},
        medians=med, same_windows_and_starts=same, ratios=rat,
        ratio_de_over_ours_rk4=med["de_s"] * 1e3 / med["ours_rk4_ms"],
        same_optimum=same_opt, warm_max_dev_from_cold=warm_dev, de_rel_err=de_err,
        start_seeds=list(seeds),
        times={"ours_rk4_s": t_rk4, "ours_euler_s": t_eul, "warm_s": t_warm, "de_s": de_t,
               **{f"same_starts_{k}_s": v for k, v in cmp.items()}},
        load_avg_at_end=[round(x, 2) for x in os.getloadavg()],
        total_s=time.perf_counter() - t_all,
    )

    def row(label: str, key: str, vs: str) -> list:
        v = same[key]
        return [label, n_base, f"{v['median_ms']:.2f} ms", f"{v['total_s']:.2f} s", vs]

    def faster(a: str, b: str, name: str) -> str:
        r = rat[f"{a}_over_{b}"]
        return f"{r['of_medians']:.0f}× ({r['of_totals']:.0f}× in total) faster than {name}"

    rows = [
        row("(i) paper's method, interpreted: SLSQP + scipy's FD gradients, plain-Python Euler", "interpreted", "1×"),
        row("(i') paper's method, compiled: the same with numba Euler + eq. 7, compiled FD gradients", "compiled",
            faster("interpreted", "compiled", "(i)")),
        row("(i') variant: only OF compiled, SLSQP's own finite differences", "compiled_scipy_fd",
            faster("interpreted", "compiled_scipy_fd", "(i)")),
        row("(iii) ours, RK4 (default)", "ours_rk4",
            faster("interpreted", "ours_rk4", "(i)") + "; " + faster("compiled", "ours_rk4", "(i')")),
        row("(iii) ours, the paper's Euler", "ours_euler",
            faster("interpreted", "ours_euler", "(i)") + "; " + faster("compiled", "ours_euler", "(i')")),
    ]
    text = ("Same windows, same three starts per window for every method, each timed as the minimum of "
            f"{REPS} interleaved runs:\n\n")
    text += common.md_table(["method", "windows", "median / identification", "total over the windows",
                             "ratio (of medians)"], rows)
    rows2 = [
        ["(ii) previous approach [11]: DE on Z+IM, plain-Python Euler (one run each)", n_de, f"{med['de_s']:.1f} s",
         f"{med['de_s'] * 1e3 / same['interpreted']['median_ms']:.0f}× slower than (i)", "paper: > 30 s"],
        ["(iii) ours, RK4, 3 starts (its default seed)", n_ours, f"{med['ours_rk4_ms']:.2f} ms",
         f"{out['ratio_de_over_ours_rk4']:.0f}× faster than (ii)", "≤ 5 ms"],
        ["(iii) ours, paper's Euler, 3 starts (its default seed)", n_ours, f"{med['ours_euler_ms']:.2f} ms", "–", "–"],
        ["(iii) ours, warm start (±3 %) + 1 random start", n_ours, f"{med['warm_ms']:.2f} ms", "–", "≤ 2 ms"],
        [f"{n_batch} windows, identify_many, 2 workers (total)", n_batch, f"{batch[2]:.2f} s",
         f"1 worker: {batch[1]:.2f} s", "≤ 4 s for 1,000" if n_batch == 1000 else "(1,000 in full run)"],
        ["paper (MATLAB, 1000 DL=1 LMCs, mean)", 1000, "1.82 s", "> 16× vs [11]", "–"],
    ]
    text += "\n\n" + common.md_table(["method", "windows", "median time / identification", "ratio", "target"], rows2)
    ci, oe = same_opt["compiled_vs_interpreted"], same_opt["ours_euler_vs_interpreted"]
    text += (
        f"\n\nSame optimum, from the same starts (SLSQP ftol {baselines.SLSQP_FTOL:g} on OF/OF(start)), "
        f"per start over the {ci['starts_compared']} of {ci['starts_total']} starts where both end at a finite "
        f"OF:\n\n"
        + common.md_table(
            ["pair", "best of 3: max rel. difference of D", "per start: median", "per start: max",
             "starts > 1e-4 apart", "of which the first ended at the higher OF"],
            [["(i') compiled vs (i) interpreted", f"{ci['best_of_3_max_rel']:.1e}", f"{ci['per_start_median_rel']:.1e}",
              f"{ci['per_start_max_rel']:.1e}", ci["starts_differ"], ci["starts_differ_other_higher_of"]],
             ["(iii) ours, paper's Euler (LM) vs (i) interpreted", f"{oe['best_of_3_max_rel']:.1e}",
              f"{oe['per_start_median_rel']:.1e}", f"{oe['per_start_max_rel']:.1e}", oe["starts_differ"],
              oe["starts_differ_other_higher_of"]]])
        + f"\n\nRelative differences of D: per parameter, relative to the second method's value (absolute below "
        f"{ABS_FLOOR:g}, for a parameter at zero).\n\nWarm-started answers differ from the cold ones by at most {warm_dev:.1e} (relative, any parameter)."
    )
    print(text)
    if not args.no_write:
        common.write_json("speed" + ("_quick" if q else ""), out)
        body = (f"Command: `{common.command('speed', q)}` — DL=1 windows (seed {SEED}), one core for single "
                f"identifications (BLAS/OpenMP 1 thread), total {out['total_s']:.0f} s; machine: "
                f"{out['machine']['cpus']} cores, shared (load average at start "
                f"{out['machine']['load_avg_at_start']}, at the end {out['load_avg_at_end']}), "
                f"{out['machine']['cpu']}, {out['machine']['date']}. "
                f"Every method: per window the minimum of {REPS} runs, the methods taking turns in a rotating "
                f"order; medians and totals over windows. Starts: per window the three that `identify` draws for "
                f"the first seed (from {SEED} + 1000·i on) where all three have a finite explicit-Euler OF, passed "
                f"to both baselines. The machine is shared and noisy. Raw numbers: "
                f"`docs/results/speed{'_quick' if q else ''}.json`.\n\n" + text)
        common.write_section("speed" + ("-quick" if q else ""), body)
    return out


if __name__ == "__main__":
    main()
