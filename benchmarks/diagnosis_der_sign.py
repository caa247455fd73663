"""The lagged droop's fitted sign on stored diagnosis runs: outside-library loads against a real DER (stop 31).

    .venv/bin/python -m benchmarks.diagnosis_der_sign --independent confirm5 confirm6_keptbound \
        confirm7_keptbound confirm8 --selftest diagnosis_only_genfix_before diagnosis_input_noise_only_genfix_before \
        --out diagnosis_der_sign

Reads records only (no diagnosis): ``docs/results/diagnosis_independent_<run>.json`` (ANDES; each record lists
every candidate's z, penalised gain, explained fraction and parameters) and self-test runs
``docs/results/<run>.json`` (the top candidate's parameters and the effect's truth).  Per ANDES case with the
outside-library kinds, and per case of any kind where ``inverter_der`` is significant or named: the best
(first significant) candidate, its z, gain and explained fraction, the located channels, and ``inverter_der``'s
Kp, Kq, T with standard errors.  Summary: the sign of Kq where the droop is significant, per kind and noise
mode.  Load convention (P, Q consumed): a Q–V droop has Kq > 0.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "docs" / "results"
OUTSIDE = ("thermostatic_cycling", "oscillating_load", "noisy_load")


def _der_row(run: str, r: dict) -> dict | None:
    cands = {c["name"]: c for c in r["candidates"]}
    der = cands.get("inverter_der")
    causes = r.get("report_extra", {}).get("causes") or []
    named = r["verdict"] == "explained" and r["cause"] == "inverter_der"
    listed = r["verdict"] == "ambiguous" and "inverter_der" in causes
    if der is None or not der.get("tested", True):
        return None
    if r["kind"] not in OUTSIDE and not (der["significant"] or named or listed):
        return None
    best = next((c for c in r["candidates"] if c["significant"]), None)
    p, s = der["parameters"], der["stderr"]
    return {
        "run": run, "kind": r["kind"], "seed": r["seed"], "window": r["window"][0], "level": r["level"],
        "mode": "VT" if r["input_noise"] else "PQ", "verdict": r["verdict"], "cause": r["cause"], "causes": causes,
        "located": r.get("located"),
        "best": None if best is None else {"name": best["name"], "z": round(best["z"], 2),
                                           "gain": round(best["gain"], 2), "ef": best["explained_fraction"]},
        "der": {"significant": der["significant"], "z": round(der["z"], 2), "gain": round(der["gain"], 2),
                "ef": der["explained_fraction"], "named": named, "listed": listed,
                **{k: round(p[k], 4) for k in ("Kp", "Kq", "T")}, **{f"se_{k}": round(s[k], 4) for k in ("Kp", "Kq")}},
    }


def independent(runs: list[str]) -> tuple[list[dict], dict]:
    rows = []
    for run in runs:
        recs = json.loads((RESULTS / f"diagnosis_independent_{run}.json").read_text())["records"]
        rows += [row for r in recs if (row := _der_row(run, r)) is not None]
    tally: dict = defaultdict(lambda: {"n": 0, "der_sig": 0, "der_sig_kq_neg": 0, "der_best": 0,
                                       "der_best_kq_neg": 0, "der_named_or_listed": 0, "der_named_or_listed_kq_neg": 0})
    for row in rows:
        d = row["der"]
        key = f"{'outside' if row['kind'] in OUTSIDE else row['kind']}/{row['mode']}"
        t = tally[key]
        t["n"] += row["kind"] in OUTSIDE
        neg = d["Kq"] < 0
        if d["significant"]:
            t["der_sig"] += 1
            t["der_sig_kq_neg"] += neg
        if row["best"] is not None and row["best"]["name"] == "inverter_der":
            t["der_best"] += 1
            t["der_best_kq_neg"] += neg
        if d["named"] or d["listed"]:
            t["der_named_or_listed"] += 1
            t["der_named_or_listed_kq_neg"] += neg
    return rows, dict(sorted(tally.items()))


def selftest(runs: list[str]) -> dict:
    out = {}
    for run in runs:
        recs = json.loads((RESULTS / f"{run}.json").read_text())["records"]
        der = [r for r in recs if r["effect"] == "inverter_der" and r.get("mode", "identified") == "identified"]
        named = [r for r in der if r["verdict"] == "explained" and r["cause"] == "inverter_der"]
        out[run] = {"n": len(der), "named": len(named),
                    "truth_kq_neg": sum(r["truth"]["Kq"] < 0 for r in der),
                    "named_fit_kq_neg": sum(r["parameters"]["Kq"] < 0 for r in named),
                    "other_effects_named_der": sum(r["effect"] != "inverter_der" and r["verdict"] == "explained"
                                                   and r["cause"] == "inverter_der" for r in recs)}
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--independent", nargs="*", default=[])
    p.add_argument("--selftest", nargs="*", default=[])
    p.add_argument("--out", default="")
    args = p.parse_args(argv)
    rows, tally = independent(args.independent)
    for row in rows:
        d, b = row["der"], row["best"]
        if d["significant"] or d["named"] or d["listed"]:
            print(f"{row['run'][:8]:8s} {row['kind'][:14]:14s} {row['seed']} {row['window']:4.0f} L{row['level']} "
                  f"{row['mode']} {row['verdict'][:5]:5s} best={b['name'] if b else None} "
                  f"der z={d['z']:.1f} g={d['gain']:.1f} ef={d['ef']} Kp={d['Kp']:+.3f}±{d['se_Kp']:.3f} "
                  f"Kq={d['Kq']:+.3f}±{d['se_Kq']:.3f} T={d['T']:.2f} located={row['located']}")
    print(json.dumps(tally, indent=1))
    st = selftest(args.selftest)
    print(json.dumps(st, indent=1))
    if args.out:
        (RESULTS / f"{args.out}.json").write_text(json.dumps(
            {"independent_runs": args.independent, "selftest_runs": args.selftest, "tally": tally,
             "selftest": st, "rows": [r for r in rows if r["der"]["significant"] or r["der"]["named"]
                                      or r["der"]["listed"]]}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
