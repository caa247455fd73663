"""What the plain fit's bound as a rival costs: the windows it concerns diagnosed with and without it, in one process.

    .venv/bin/python -m benchmarks.diagnosis_bound_cost --repeats 2 --out diagnosis_bound_cost

Issue 12, seventh round (``DiagnosisConfig.bound_rule``: the plain model refitted with its box opened where it is
pinned is a rival of the cause).  The windows: the self-test's seven cases whose right names the sixth round's veto
withheld, the four ANDES cases of ``confirm5``/``confirm6`` it withheld, and the out-of-box clean windows that
were named or ``ambiguous`` without any rule (the old draws of clean 9004, 9205, 9303, 9305; recordings from the
cache, nothing simulated).  Each is diagnosed with the rule and without it (order alternating per window and
repeat), CPU by ``time.process_time``; the rival's own build (its fits, input-noise draws and comparison with the
plain model, :func:`aslm_core.diagnosis.pipeline._outside_box`) is timed apart.  The paired comparisons with it
run inside the verdict and are in the difference of the two sides only.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

SELFTEST = (("second_motor", 1, 10), ("second_motor", 2, 0), ("second_motor", 3, 5), ("switched_shunt", 1, 5),
            ("switched_shunt", 2, 11), ("switched_shunt", 3, 10), ("switched_shunt", 3, 11))
#: (kind, seed, window start [s], level, V/θ noise, the bench's old out-of-box draw)
ANDES = (("switched_capacitor", 9501, 2.0, 3, True, False), ("switched_capacitor", 9502, 2.0, 2, True, False),
         ("speed_dependent_torque", 9402, 12.0, 1, False, False), ("stator_resistance", 9404, 2.0, 2, True, False),
         ("clean", 9004, 12.0, 3, False, True), ("clean", 9205, 2.0, 3, False, True),
         ("clean", 9205, 12.0, 3, False, True), ("clean", 9303, 2.0, 3, False, True),
         ("clean", 9303, 12.0, 3, False, True), ("clean", 9305, 2.0, 2, False, True),
         ("clean", 9305, 2.0, 3, False, True))


def windows() -> list[tuple[str, object]]:
    """(label, window) of every concerned case."""
    from aslm_sim.andes.effects import recording
    from benchmarks.diagnosis import case
    from benchmarks.diagnosis_independent import TF, TSTEP, WINDOWS, _window

    out = [(f"selftest {e}/{lvl}/{i}", case((e, lvl, i))[1].window) for e, lvl, i in SELFTEST]
    for kind, seed, t0, lvl, inp, old in ANDES:
        rec = recording(kind, seed, tf=TF, tstep=TSTEP, paper_box=not old)
        t1 = next(b for a, b in WINDOWS if a == t0)
        out.append((f"andes {kind}/{seed} {t0:g} s L{lvl} {'V/θ' if inp else 'P/Q'}",
                    _window(rec, t0, t1, lvl, inp, f"{kind}/{seed}")[0]))
    return out


def main(argv: list[str] | None = None) -> int:
    from aslm_core.diagnosis import pipeline

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--out", default="")
    args = p.parse_args(argv)
    build = pipeline._outside_box
    spent: list[float] = []

    def timed(analyses, config):
        c = time.process_time()
        out = build(analyses, config)
        spent.append(time.process_time() - c)
        return out

    pipeline._outside_box = timed
    rows = []
    for j, (label, w) in enumerate(windows()):
        for r in range(args.repeats):
            row: dict = {"window": label, "repeat": r}
            for rule in ((True, False) if (j + r) % 2 == 0 else (False, True)):
                spent.clear()
                c = time.process_time()
                rep = pipeline.diagnose(w, config=pipeline.DiagnosisConfig(bound_rule=rule))
                side = "with" if rule else "without"
                row[f"cpu_{side}"] = time.process_time() - c
                row[f"answer_{side}"] = rep.cause if rep.verdict == "explained" else rep.verdict
                if rule:
                    row["rival_build_s"] = sum(spent)
            rows.append(row)
            print(f"{label}: {row['answer_without']} -> {row['answer_with']}  CPU {row['cpu_without']:.2f} -> "
                  f"{row['cpu_with']:.2f} s (rival built in {row['rival_build_s']:.3f} s)", flush=True)
    pipeline._outside_box = build
    d = np.array([r["cpu_with"] - r["cpu_without"] for r in rows])
    summary = {"extra_cpu_median": float(np.median(d)), "extra_cpu_max": float(d.max()),
               "rival_build_median": float(np.median([r["rival_build_s"] for r in rows])),
               "rival_build_max": float(max(r["rival_build_s"] for r in rows)),
               "cpu_with_max": float(max(r["cpu_with"] for r in rows)), "load_avg": os.getloadavg(),
               "command": "benchmarks/diagnosis_bound_cost.py " + " ".join(argv if argv is not None else sys.argv[1:])}
    print(json.dumps(summary, indent=1))
    if args.out:
        (ROOT / "docs" / "results" / f"{args.out}.json").write_text(json.dumps({"summary": summary, "rows": rows},
                                                                               indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
