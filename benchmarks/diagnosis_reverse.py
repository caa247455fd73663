"""The reverse paired comparisons on the self-test's `ambiguous` cases whose truth is listed (issue 12, sixth round).

    .venv/bin/python -m benchmarks.diagnosis_reverse                 # the cases of docs/results/diagnosis.json
    .venv/bin/python -m benchmarks.diagnosis_reverse --from FILE --out diagnosis_reverse_cases_after

For each such case the truth T is taken as the top candidate and compared with every other cause listed:
z(T over R) and z(R over T) (the paired held-out statistics of the verdict, Stouffer over windows), the held-out
log-likelihood gain of R added to T (what the rival holds that the truth lacks) and of T over the plain model
[nats], and the share of T's improvement the rival holds: by the gains, and by the squared score statistics,
(z(R over T) / z(T over plain))², the estimate the margin test of ``DiagnosisConfig.reverse_margin`` uses.
Records go to ``docs/results/<out>.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.diagnosis import _init, case  # noqa: E402


def reverse_record(job: tuple, listed: list[str]) -> dict:
    """The truth's forward and reverse comparisons with the other listed causes of one self-test case."""
    from aslm_core.diagnosis import pipeline
    from aslm_core.diagnosis.engine import dm_critical

    effect, level, i = job[:3]
    _, ec, model, user = case(job)
    config = pipeline.DiagnosisConfig()
    analyses = [pipeline._analyse(ec.window, model, None, config)]
    tested = [n for n in config.candidates if n in analyses[0].comps]
    zcrit = dm_critical(config.alpha, len(tested))
    truth = pipeline._entry(analyses, effect, zcrit)
    fwd_gain = float(sum(a.comps[effect].gain for a in analyses))
    rows = []
    for rival in listed:
        if rival == effect:
            continue
        back = pipeline.paired_comparisons(analyses, rival, effect, config)
        ahead = pipeline.paired_comparisons(analyses, effect, rival, config)
        if back is None or ahead is None:
            rows.append({"rival": rival, "failed": True})
            continue
        z_rev = float(sum(c.score_z for c in back) / math.sqrt(len(back)))
        g_rev = float(sum(c.gain for c in back))
        rows.append({
            "rival": rival, "z_forward": float(sum(c.score_z for c in ahead) / math.sqrt(len(ahead))),
            "z_reverse": z_rev, "gain_reverse": g_rev,
            "share_gain": g_rev / fwd_gain if fwd_gain > 0 else None,
            "share_z": (max(z_rev, 0.0) / truth.score_z) ** 2 if truth.score_z > 0 else None,
        })
    return {"effect": effect, "level": level, "case": i, "mode": "user" if user else "identified",
            "truth_z": truth.score_z, "truth_gain": fwd_gain, "rivals": rows}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--from", dest="src", default=str(ROOT / "docs" / "results" / "diagnosis.json"),
                   help="self-test records whose `ambiguous` cases with the truth listed are analysed")
    p.add_argument("--out", default="diagnosis_reverse_cases", help="written as docs/results/<out>.json")
    args = p.parse_args(argv)
    recs = json.loads(Path(args.src).read_text())["records"]
    todo = [r for r in recs if r["verdict"] == "ambiguous" and r["effect"] in r["causes"]]
    _init()
    out = []
    for r in todo:
        rec = reverse_record((r["effect"], r["level"], r["case"], r["input_noise"]), r["causes"])
        out.append(rec)
        for x in rec["rivals"]:
            if x.get("failed"):
                continue
            print(f"{rec['effect']:24s} L{rec['level']} #{rec['case']:2d} {rec['mode']:10s} z_T {rec['truth_z']:7.1f} "
                  f"gain_T {rec['truth_gain']:8.1f} | {x['rival']:22s} z_fwd {x['z_forward']:6.2f} "
                  f"z_rev {x['z_reverse']:6.2f} gain_rev {x['gain_reverse']:6.2f} share_gain {x['share_gain']:.4f} "
                  f"share_z {x['share_z']:.4f}", flush=True)
    (ROOT / "docs" / "results" / f"{args.out}.json").write_text(json.dumps({"source": args.src, "records": out},
                                                                           indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
