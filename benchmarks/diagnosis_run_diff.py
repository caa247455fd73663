"""Two runs of the ANDES benchmark compared case by case: every answer that changed, and the at-bound rule's share.

    .venv/bin/python -m benchmarks.diagnosis_run_diff confirm5 confirm5_fastdiag

Reads ``docs/results/diagnosis_independent_<run>.json`` for both runs and matches their records by kind, seed,
window, level and noise mode.  Prints each case whose answer (the named cause for ``explained``, else the
verdict; ``ambiguous`` with its causes) differs, marks those the plain fit's bound made ``unexplained``
(``DiagnosisConfig.bound_rule``: a veto in the sixth round, the motor outside the box as a rival since the
seventh; the message says so either way), counts the
right names each run has and the rule took, the cases whose plain fit sits on a bound (``plain_at_bound``,
recorded by runs since the sixth round), and CPU per diagnosis of both runs.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "docs" / "results"
#: The start of the message of a verdict the at-bound rule withheld (pipeline.diagnose).
RULE_MESSAGE = "the plain model sits on its box's bound"


def _key(r: dict) -> tuple:
    return r["kind"], r["seed"], r["window"][0], r["level"], r["input_noise"]


def answer(r: dict) -> str:
    """The case's answer: the cause when explained, the causes when ambiguous, else the verdict."""
    if r["verdict"] == "explained":
        return r["cause"]
    if r["verdict"] == "ambiguous":
        return "ambiguous(" + ",".join(r.get("report_extra", {}).get("causes", [])) + ")"
    return r["verdict"]


def diff(before: list[dict], after: list[dict]) -> dict:
    """Changed answers, right names per run, the rule's effect and CPU of two runs' records."""
    b = {_key(r): r for r in before}
    a = {_key(r): r for r in after}
    common = sorted(b.keys() & a.keys())
    changed = []
    for k in common:
        if answer(b[k]) != answer(a[k]):
            changed.append({"case": list(k), "before": answer(b[k]), "after": answer(a[k]),
                            "rule": a[k].get("message", "").startswith(RULE_MESSAGE),
                            "plain_at_bound": a[k].get("plain_at_bound")})
    right = {name: sum(r["verdict"] == "explained" and r["cause"] == r["expected"] for r in (x[k] for k in common))
             for name, x in (("before", b), ("after", a))}
    rule = [a[k] for k in common if a[k].get("message", "").startswith(RULE_MESSAGE)]
    at_bound = [a[k] for k in common if a[k].get("plain_at_bound")]
    cpu = {name: np.array([x[k]["cpu_s"] for k in common]) for name, x in (("before", b), ("after", a))}
    return {
        "n_common": len(common), "changed": changed, "right_named": right,
        "rule_fired": [[*_key(r), r["expected"]] for r in rule],
        "right_names_lost_to_rule": sum(c["rule"] and c["before"] == b[tuple(c["case"])]["expected"] for c in changed),
        "plain_at_bound": {"n": len(at_bound), "by_kind": dict(Counter(r["kind"] for r in at_bound)),
                           "bounds": dict(Counter(k for r in at_bound for k in r["plain_at_bound"]))},
        "cpu_s": {n: {"median": float(np.median(c)), "p95": float(np.percentile(c, 95)), "max": float(c.max())}
                  for n, c in cpu.items()},
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("before")
    p.add_argument("after")
    p.add_argument("--out", default="", help="write docs/results/<out>.json")
    args = p.parse_args(argv)
    runs = [json.loads((RESULTS / f"diagnosis_independent_{r}.json").read_text())["records"]
            for r in (args.before, args.after)]
    d = diff(*runs)
    for c in d["changed"]:
        print(f"{c['case']}: {c['before']} -> {c['after']}{'  (at-bound rule)' if c['rule'] else ''}"
              f"{'  plain at ' + str(c['plain_at_bound']) if c['plain_at_bound'] else ''}")
    print(f"{len(d['changed'])} of {d['n_common']} answers changed; right names {d['right_named']}; "
          f"the rule fired in {len(d['rule_fired'])} cases and took {d['right_names_lost_to_rule']} right names")
    print(f"plain fit on a bound: {d['plain_at_bound']}")
    print(f"CPU per diagnosis: {d['cpu_s']}")
    if args.out:
        (RESULTS / f"{args.out}.json").write_text(json.dumps({"before": args.before, "after": args.after, **d},
                                                             indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
