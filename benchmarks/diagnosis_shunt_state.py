"""The switched capacitor's state read from noisy V against the one read from exact V (issue 12, stop 39).

    .venv/bin/python -m benchmarks.diagnosis_shunt_state --set confirm15

For every cached ``switched_capacitor`` scenario of an ANDES set (:mod:`benchmarks.diagnosis_independent`), each window
and noise level is diagnosed twice, as the benchmark does: noise on P and Q only (V exact) and noise on V and θ too.
In each, the ``switched_shunt`` candidate's fitted law (its scanned parameters) gives the bank's state path s(t) from
the window's inputs, as its held-out prediction uses it.  The share of the time-ordered fold's held-out samples on
which the two paths agree says how much of the bank's switching the noisy V still shows: the separability oracle fits
noise-free recordings, so a case it calls separable can be one whose state no input-only prediction reads from a
PMU's V.  Raw rows to ``docs/results/diagnosis_shunt_state_<set>.json``.
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
            te = slice(seg.ks, seg.ke)
            out.append({
                "seed": seed, "window": [t0, t1], "level": level,
                "answer_exact_v": rep_e.cause or rep_e.verdict, "answer_noisy_v": rep_n.cause or rep_n.verdict,
                "held_out_agreement": float(np.mean(s_exact[te] == s_noisy[te])),
                "switchings_exact_v": int(np.sum(np.diff(s_exact) != 0)),
                "switchings_noisy_v": int(np.sum(np.diff(s_noisy) != 0)),
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
    summary = {"set": args.set, "cases": len(rows), "named_with_noisy_v": int(named.sum()),
               "agreement_median": float(np.median(agree)),
               "agreement_median_named": float(np.median(agree[named])) if named.any() else None,
               "agreement_median_not_named": float(np.median(agree[~named])) if (~named).any() else None,
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
