"""The switched capacitor's state read from noisy V against the one read from exact V (issue 12, stop 39).

    .venv/bin/python -m benchmarks.diagnosis_shunt_state --set confirm15

For every cached ``switched_capacitor`` scenario of an ANDES set (:mod:`benchmarks.diagnosis_independent`), each window
and noise level is diagnosed twice, as the benchmark does: noise on P and Q only (V exact) and noise on V and θ too.
In each, the ``switched_shunt`` candidate's fitted law (its scanned parameters) gives the bank's state path s(t) from
the window's inputs, as its held-out prediction uses it.  The share of the time-ordered fold's held-out samples on
which the two paths agree says how much of the bank's switching the noisy V still shows: the separability oracle fits
noise-free recordings, so a case it calls separable can be one whose state no input-only prediction reads from a
PMU's V.  Since stop 40 each path is also set against the bank's true state (read off the noise-free recording's Q
steps), and so is an oracle of the candidate's relay family: the law that best reproduces the true state on the
training samples from the V the candidate reads (exact, then noisy), judged on the held-out ones — how much of the
state the family can re-enact from a PMU's V when it is given the truth to aim at; and the same for the two-state form
(its V step, least dwell and breaker delay chosen by the held-out truth: an upper bound on what its scan could pick).  Raw rows to ``docs/results/diagnosis_shunt_state_<set>.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks import diagnosis_independent as di  # noqa: E402

RESULTS = ROOT / "docs" / "results"


def fitted_state(window):
    """The diagnosis of ``window``, its segment and the switched shunt's fitted state path s(t) ∈ {0, 1}."""
    from aslm_core.diagnosis import diagnose
    from aslm_core.diagnosis.candidates import LIBRARY
    from aslm_core.diagnosis.candidates.switched_shunt import _state
    from aslm_core.diagnosis.segment import make_segment

    cand = LIBRARY["switched_shunt"]
    rep = diagnose(window)
    entry = rep.candidate("switched_shunt")
    seg = make_segment(window)
    z = np.array([float(entry.parameters.get(k, 0.0)) for k in cand.nl_names])
    return rep, seg, _state(cand._relay_v(seg), z, seg.dt, cand._steps(seg), cand._two(seg))


def true_state(rec: dict, t0: float, t1: float) -> tuple[np.ndarray, int]:
    """The bank's true state on the window, read off the noise-free recording's Q: its steps of −b·V² at the
    switchings (detrended 20 ms steps of −Q beyond 0.3·b·V0², the bank's step with its own V lift partly offset by
    the load's response).  Returns the state and its switchings over the whole record (the bench's count to check
    against)."""
    from aslm_core.diagnosis.candidates.switched_shunt import STEP_SAMPLES, detrended_step, step_state

    relay = rec["meta"]["drawn"]["effect"]["relay"]
    full = step_state(detrended_step(-rec["Q"]), 0.3 * relay["b"] * float(rec["V"][0]) ** 2, STEP_SAMPLES)
    sl = (rec["t"] >= t0 - 1e-9) & (rec["t"] <= t1 + 1e-9)
    return full[sl], int(np.sum(np.diff(full) != 0))


def best_law_state(v: np.ndarray, target: np.ndarray, train: slice, dt: float) -> np.ndarray:
    """An oracle of the candidate's relay family: the law (Vc, dv, τ, t_op, s0) whose state on ``v`` (V low-passed
    as the candidate reads it) agrees with the true ``target`` state on the most training samples, on a fine grid;
    its state over the whole window.  What the family can re-enact from this V given the truth to aim at."""
    from aslm_core.diagnosis.candidates.switched_shunt import T_OP_MAX_S, delayed, relay_state

    sd = max(float(np.std(v)), 1e-9)
    best, arg = -1.0, None
    for vc in np.quantile(v, np.linspace(0.05, 0.95, 37)):
        for dv in sd * np.array([0.02, 0.05, 0.1, 0.2, 0.3, 0.45, 0.6, 0.8, 1.0, 1.3]):
            for tau in np.arange(0.0, 0.61, 0.02):
                for s0 in (0.0, 1.0):
                    r = relay_state(v, float(vc), float(dv), float(tau), dt, s0)
                    for k in range(int(T_OP_MAX_S / dt + 1e-9) + 1):
                        sh = delayed(r, k)
                        a = float(np.mean(sh[train] == target[train]))
                        if a > best:
                            best, arg = a, sh
    return arg


def best_two_state(window, target: np.ndarray, test: slice) -> tuple[np.ndarray, float]:
    """An oracle of the candidate's two-state form: its path on the window's measured V for the V step h (2–6 × V's
    white scale), least dwell (0–0.2 s) and breaker delay (0–0.1 s) that agree best with the true ``target`` state on
    the held-out samples ``test``; the path and h over V's white scale.  The form's best from this V, the truth
    choosing its settings."""
    from aslm_core.diagnosis.candidates.switched_shunt import T_OP_MAX_S, delayed, two_state, white_sigma
    from aslm_core.diagnosis.segment import make_segment

    seg = make_segment(window)
    vm = seg.v_measured
    sig = white_sigma(vm)
    best, arg = -1.0, (None, 0.0)
    for q in (2.0, 2.5, 3.0, 4.0, 5.0, 6.0):
        for dwell in (0.0, 0.05, 0.1, 0.2):
            path = two_state(vm, q * sig, int(round(dwell / seg.dt)), 1.0 / seg.dt)
            for k in range(int(T_OP_MAX_S / seg.dt + 1e-9) + 1):
                sh = delayed(path, k)
                a = float(np.mean(sh[test] == target[test]))
                if a > best:
                    best, arg = a, (sh, q)
    return arg


def cand_v(window) -> np.ndarray:
    """The V the candidate's relay law reads from ``window`` (low-passed at 5 Hz) [pu]."""
    from aslm_core.diagnosis.candidates import LIBRARY
    from aslm_core.diagnosis.segment import make_segment

    return LIBRARY["switched_shunt"]._relay_v(make_segment(window))


def rows_of(seed: int) -> list[dict]:
    """One row per window and level of a cached switched-capacitor scenario."""
    from aslm_sim.andes import effects

    rec = effects.recording("switched_capacitor", seed, tf=di.TF, tstep=di.TSTEP)
    out = []
    for t0, t1 in di.WINDOWS:
        for level in di.LEVELS:
            key = f"switched_capacitor/{seed}"
            exact, _ = di._window(rec, t0, t1, level, False, key)
            noisy, _ = di._window(rec, t0, t1, level, True, key)
            rep_e, seg, s_exact = fitted_state(exact)
            rep_n, _, s_noisy = fitted_state(noisy)
            truth, n_true = true_state(rec, t0, t1)
            te, tr = slice(seg.ks, seg.ke), seg.train
            law_exact = best_law_state(cand_v(exact), truth, tr, seg.dt)
            law_noisy = best_law_state(cand_v(noisy), truth, tr, seg.dt)
            two_noisy, two_q = best_two_state(noisy, truth, te)
            out.append({
                "seed": seed, "window": [t0, t1], "level": level,
                "answer_exact_v": rep_e.cause or rep_e.verdict, "answer_noisy_v": rep_n.cause or rep_n.verdict,
                "held_out_agreement": float(np.mean(s_exact[te] == s_noisy[te])),
                "switchings_exact_v": int(np.sum(np.diff(s_exact) != 0)),
                "switchings_noisy_v": int(np.sum(np.diff(s_noisy) != 0)),
                # Against the true state (``true_state``): the fits' states, and the relay family's best law given
                # the truth on the training samples (``best_law_state``) on the exact and on the noisy V.
                "true_switchings_record": n_true, "recorded_switchings": rec["meta"]["switchings"],
                "true_switchings_window": int(np.sum(np.diff(truth) != 0)),
                "agreement_fit_exact_v": float(np.mean(s_exact[te] == truth[te])),
                "agreement_fit_noisy_v": float(np.mean(s_noisy[te] == truth[te])),
                "agreement_best_law_exact_v": float(np.mean(law_exact[te] == truth[te])),
                "agreement_best_law_noisy_v": float(np.mean(law_noisy[te] == truth[te])),
                "agreement_best_two_state_noisy_v": float(np.mean(two_noisy[te] == truth[te])),
                "best_two_state_h_over_sigma": two_q,
            })
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--set", choices=list(di.SETS), required=True)
    p.add_argument("--no-write", action="store_true")
    args = p.parse_args(argv)
    from aslm_sim.andes.effects import cache_dir

    t0 = time.perf_counter()
    seeds = [s for k, s in di.jobs(args.set, ["switched_capacitor"])
             if any(cache_dir().glob(f"v*-switched_capacitor-{s}-*.npz"))]
    rows = [r for s in seeds for r in rows_of(s)]
    if not rows:
        print(f"no cached switched_capacitor scenario of {args.set}")
        return 1
    print("| seed | window | level | exact V | noisy V | held-out agreement | switchings exact / noisy |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['seed']} | {r['window'][0]:g}–{r['window'][1]:g} s | L{r['level']} | {r['answer_exact_v']} | "
              f"{r['answer_noisy_v']} | {r['held_out_agreement']:.3f} | {r['switchings_exact_v']} / {r['switchings_noisy_v']} |")
    agree = np.array([r["held_out_agreement"] for r in rows])
    named = np.array([r["answer_noisy_v"] == "switched_shunt" for r in rows])
    print("\n| seed | window | level | noisy V | switchings | fit on exact V | fit on noisy V | best law, exact V | best law, noisy V | best two-state, noisy V |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['seed']} | {r['window'][0]:g}–{r['window'][1]:g} s | L{r['level']} | {r['answer_noisy_v']} | "
              f"{r['true_switchings_window']} | {r['agreement_fit_exact_v']:.3f} | {r['agreement_fit_noisy_v']:.3f} | "
              f"{r['agreement_best_law_exact_v']:.3f} | {r['agreement_best_law_noisy_v']:.3f} | "
              f"{r['agreement_best_two_state_noisy_v']:.3f} |")
    versus = {k: {"named": float(np.median([r[k] for r, n in zip(rows, named, strict=True) if n])) if named.any() else None,
                  "not_named": float(np.median([r[k] for r, n in zip(rows, named, strict=True) if not n]))
                  if (~named).any() else None}
              for k in ("agreement_fit_exact_v", "agreement_fit_noisy_v", "agreement_best_law_exact_v",
                        "agreement_best_law_noisy_v", "agreement_best_two_state_noisy_v")}
    print("\nmedian held-out agreement with the true state (named / not named with noisy V): " + "; ".join(
        f"{k[len('agreement_'):]} {v['named'] if v['named'] is None else round(v['named'], 3)} / "
        f"{v['not_named'] if v['not_named'] is None else round(v['not_named'], 3)}" for k, v in versus.items()))
    summary = {"set": args.set, "cases": len(rows), "named_with_noisy_v": int(named.sum()),
               "agreement_median": float(np.median(agree)),
               "agreement_median_named": float(np.median(agree[named])) if named.any() else None,
               "agreement_median_not_named": float(np.median(agree[~named])) if (~named).any() else None,
               "versus_true_state": versus,
               "wall_s": time.perf_counter() - t0,
               "command": "benchmarks/diagnosis_shunt_state.py " + " ".join(argv if argv is not None else sys.argv[1:])}
    print(f"\n{summary['named_with_noisy_v']} of {len(rows)} named with noisy V; held-out state agreement median "
          f"{summary['agreement_median']:.2f} (named {summary['agreement_median_named']}, not named "
          f"{summary['agreement_median_not_named']}); {summary['wall_s']:.0f} s")
    if not args.no_write:
        (RESULTS / f"diagnosis_shunt_state_{args.set}.json").write_text(
            json.dumps({"summary": summary, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
