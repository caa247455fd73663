"""Why clean ANDES scenarios 9303/9305 (and 9004, 9205) were not clean: their motor lies outside the paper's box.

    ASLM_ANDES_CACHE=/tmp/clean93cache .venv/bin/python -m benchmarks.clean_box      # all four parts

Issue 12, fifth round.  The noise-free plain ZIP + IM fit of these clean recordings left a held-out residual
(oracle z 8.7–25.8 at L2–L3) that no other clean scenario had.  Four parts, each a table in
docs/diagnosis.md ("Why clean 9303 and 9305 were not clean"):

``census``
    Every scenario of every set as the bench drew it before the fix (:func:`aslm_sim.andes.effects.build`
    with ``paper_box=False``): its base motor's D from the transform and whether a, b, H2 lie inside the
    identifier's box (:data:`aslm_core.params.DYNAMIC_PARAMS`); for the clean ones the unit-SNR oracle z of
    the earlier runs (``docs/results/diagnosis_detectability*.json``).  Draws only: nothing is simulated.
``box``
    The oracle z of the old recordings (read from the cache) with the identifier's box and with a box
    widened past the drawn D: if the box is the cause, the residual goes with it.
``andes``
    ANDES re-simulations with one datum changed (the scenario's own ambient noise), so that D crosses the
    bound one way or the other: the cause shown in the simulator, not only in the fit.
``fixed``
    The scenarios as the bench draws them now (base motor redrawn inside the box).
``verdicts``
    The diagnosis of the old (out-of-box) clean recordings at the three noise levels, noise on P and Q and on
    V and θ too (sixth round): the plain fit's bounds (``model.at_bound``) and the verdict with and without the
    plain fit's bound in the verdict (``DiagnosisConfig.bound_rule``: a veto in the sixth round, a rival in the
    seventh).

The oracle z here is the unit-SNR one (:func:`benchmarks.diagnosis_detectability.recording_oracle`); a
case's is z_unit·10^(SNR/20), against the critical value 3.06: at L3's highest SNR (30 dB) z_unit < 0.097 is
undetectable.  New recordings go to :func:`aslm_sim.andes.effects.cache_dir` (set ``ASLM_ANDES_CACHE`` to
keep the shared cache unchanged).  Raw output: ``docs/results/clean_box.json``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.diagnosis_detectability import RESULTS, critical_z, recording_oracle  # noqa: E402
from benchmarks.diagnosis_independent import SETS, TF, TSTEP, jobs  # noqa: E402

#: The clean scenarios whose first draw lies outside the box and that were simulated and diagnosed.
OUTSIDE = (9004, 9205, 9303, 9305)
#: In-box controls: the largest in-box oracle z of the seen sets (9104) and a typical one (9304).
CONTROLS = (9104, 9304)
#: A box wide enough for every drawn motor: a ≥ 5, b ≤ 60 /s, H2 ≥ 0.2 s (the others as the identifier's).
WIDE = {"a": (5.0, 80.0), "b": (3.0, 60.0), "H2": (0.2, 3.0)}
#: One datum changed per re-simulation: (seed, datum, target) moves D to the target across the bound.
ONE_DATUM = ((9305, "Hm", ("H2", 0.55)), (9303, "Hm", ("H2", 0.55)), (9004, "Hm", ("H2", 0.55)),
             (9205, "rr1", ("b", 28.0)), (9304, "Hm", ("H2", 0.45)))
#: The highest SNR of L3 (28 ± 2 dB) [dB].
TOP_SNR_DB = 30.0


@contextlib.contextmanager
def wide_box():
    """The identifier's box widened to :data:`WIDE` while inside (the module global dynamic_bounds reads)."""
    import aslm_core.params as params

    saved = params.DYNAMIC_PARAMS
    params.DYNAMIC_PARAMS = tuple(replace(p, lower=WIDE[p.name][0], upper=WIDE[p.name][1]) if p.name in WIDE else p
                                  for p in saved)
    try:
        yield
    finally:
        params.DYNAMIC_PARAMS = saved


def _earlier_oracle() -> dict[int, float]:
    """The largest unit-SNR oracle z per clean seed in the earlier detectability runs."""
    out: dict[int, float] = {}
    for p in sorted(RESULTS.glob("diagnosis_detectability*.json")):
        for w in json.loads(p.read_text())["windows"]:
            if w["kind"] == "clean":
                out[w["seed"]] = max(out.get(w["seed"], 0.0), w["z_unit"])
    return out


def census() -> dict:
    """Every set's scenarios as first drawn: base motor D, inside the box or not; clean ones' earlier z."""
    from aslm_sim.andes.effects import base_d, build, in_paper_box

    z = _earlier_oracle()
    out = {}
    for st in SETS:
        rows = []
        for kind, seed in jobs(st):
            d = base_d(build(kind, seed, paper_box=False)[1]["motor"])
            rows.append({"kind": kind, "seed": seed, "d": d.tolist(), "in_box": in_paper_box(d),
                         "z_unit_earlier": z.get(seed) if kind == "clean" else None})
        out[st] = rows
    return out


def _oracle(rec: dict, seed: int, label: str, **extra) -> list[dict]:
    rows = recording_oracle(rec, "clean", seed)
    for r in rows:
        r.update(label=label, truth_d=rec["meta"]["motors"][0]["d"], z_top_snr=r["z_unit"] * 10 ** (TOP_SNR_DB / 20),
                 **extra)
        print(f"{label:>10} {seed} {r['window'][0]:4.0f} z_unit {r['z_unit']:.3f}  plain D "
              f"{np.round(r['plain_d'], 3).tolist()}  true D {np.round(r['truth_d'], 3).tolist()}", flush=True)
    return rows


def box_part() -> list[dict]:
    """Old recordings (first draw) fitted in the identifier's box and in :data:`WIDE`."""
    from aslm_sim.andes.effects import recording

    rows = []
    for seed in OUTSIDE + CONTROLS:
        rec = recording("clean", seed, tf=TF, tstep=TSTEP, paper_box=False)
        rows += _oracle(rec, seed, "paper box")
        with wide_box():
            rows += _oracle(rec, seed, "wide box")
    return rows


def andes_part() -> list[dict]:
    """Re-simulations of the old scenarios with one datum moved so that D crosses the box's bound."""
    from aslm_sim.andes.effects import base_d, build, recording

    rows = []
    for seed, datum, (name, target) in ONE_DATUM:
        motor = build("clean", seed, paper_box=False)[1]["motor"]
        d = base_d(motor)
        # H2 ∝ Hm and b ∝ rr1 (T'0 ∝ 1/rr1) with the other data fixed: the datum scales with the target.
        value = motor[datum] * target / d[{"H2": 2, "b": 1}[name]]
        rec = recording("clean", seed, tf=TF, tstep=TSTEP, paper_box=False, motor_overrides={datum: value})
        rows += _oracle(rec, seed, f"{datum}→{name}={target:g}", datum=datum, value=value)
    return rows


def fixed_part() -> list[dict]:
    """The changed clean scenarios as the bench draws them now (inside the box)."""
    from aslm_sim.andes.effects import recording

    rows = []
    for seed in OUTSIDE:
        rows += _oracle(recording("clean", seed, tf=TF, tstep=TSTEP), seed, "redrawn")
    return rows


def verdicts_part() -> list[dict]:
    """The old out-of-box clean recordings diagnosed with and without the plain fit's bound in the verdict
    (``DiagnosisConfig.bound_rule``; since the seventh round the plain motor refitted outside the box as a rival)."""
    from aslm_core.diagnosis import pipeline
    from aslm_sim.andes.effects import recording

    rival = pipeline._outside_box
    seen: list = []

    def timed(analyses, config):  # the rival's cost and, after the verdict, its paired statistic
        c = time.process_time()
        out = rival(analyses, config)
        seen.append((out, time.process_time() - c))
        return out

    pipeline._outside_box = timed
    rows = []
    try:
        rows = _verdict_rows(pipeline, recording, seen)
    finally:
        pipeline._outside_box = rival
    return rows


def _verdict_rows(pipeline, recording, seen: list) -> list[dict]:
    from benchmarks.diagnosis_independent import LEVELS, WINDOWS, _window

    rows = []
    for seed in OUTSIDE:
        rec = recording("clean", seed, tf=TF, tstep=TSTEP, paper_box=False)
        for inp in (False, True):
            for t0, t1 in WINDOWS:
                for lvl in LEVELS:
                    w, snr = _window(rec, t0, t1, lvl, inp, f"clean/{seed}")
                    seen.clear()
                    c0 = time.process_time()
                    before = pipeline.diagnose(w, config=pipeline.DiagnosisConfig(bound_rule=False))
                    c1 = time.process_time()
                    rep = pipeline.diagnose(w)
                    cpu, cpu0 = time.process_time() - c1, c1 - c0
                    causes = ([before.cause] if before.verdict == "explained" else
                              list(before.causes) if before.verdict == "ambiguous" else [])
                    row = {"seed": seed, "window": [t0, t1], "level": lvl, "input_noise": inp, "snr_db": snr,
                           "verdict": rep.verdict, "cause": rep.cause, "causes_before_rule": causes,
                           "verdict_without_rule": before.verdict, "plain_at_bound": rep.model.at_bound,
                           "plain_d": rep.model.dynamic, "message": rep.message, "cpu_s": cpu,
                           "cpu_s_without_rule": cpu0, **_rival_fields(seen)}
                    rows.append(row)
                    print(f"clean {seed} {t0:4.0f} L{lvl} {'V/θ' if inp else 'P/Q'}: at_bound "
                          f"{rep.model.at_bound}  without the rule {causes or before.verdict}  now {rep.verdict}"
                          f"{'/' + rep.cause if rep.cause else ''}  {cpu:.2f} s CPU", flush=True)
    return rows


def _rival_fields(seen: list) -> dict:
    """The motor-outside-the-box rival of one diagnosis: its fit's cost and the cause's paired statistic against it
    (None where no bound opened or no cause reached the paired tests)."""
    if not seen:
        return {"rival_cpu_s": None, "rival_separation_z": None, "rival_separated": None, "rival_d": None}
    out, cpu = seen[-1]
    entry = out[0] if out is not None else None
    return {"rival_cpu_s": cpu, "rival_separation_z": getattr(entry, "separation_z", None),
            "rival_separated": getattr(entry, "separated", None),
            "rival_d": {k: v for k, v in entry.parameters.items()} if entry is not None else None}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--parts", default="census,box,andes,fixed")
    p.add_argument("--out", default="clean_box")
    args = p.parse_args(argv)
    parts = {"census": census, "box": box_part, "andes": andes_part, "fixed": fixed_part, "verdicts": verdicts_part}
    t0 = time.perf_counter()
    out: dict = {"critical_z": critical_z(), "top_snr_db": TOP_SNR_DB, "wide_box": WIDE}
    path = RESULTS / f"{args.out}.json"
    if path.exists():  # parts run separately accumulate
        out = {**json.loads(path.read_text()), **out}
    for name in args.parts.split(","):
        out[name] = parts[name]()
    if "census" in out:
        for st, rows in out["census"].items():
            bad = [(r["kind"], r["seed"]) for r in rows if not r["in_box"]]
            print(f"{st}: {len(bad)} of {len(rows)} first draws outside the box {bad}")
    # one entry per run: parts run separately keep their own wall time, load and command
    run = {"parts": args.parts, "wall_s": time.perf_counter() - t0, "load_avg": os.getloadavg(),
           "command": "benchmarks/clean_box.py " + " ".join(argv if argv is not None else sys.argv[1:])}
    out["runs"] = [r for r in out.get("runs", []) if r["parts"] != args.parts] + [run]
    RESULTS.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
