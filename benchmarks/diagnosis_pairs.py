"""How often the paired held-out test separates the diagnosis's look-alike pairs on ANDES data (issue 12).

    .venv/bin/python -m benchmarks.diagnosis_pairs --sets dev,confirm,confirm2,dev3 --workers 2

For each pair (A, B) and each window of the ANDES kinds where one of them is the truth (or, for a pair whose
look-alike data is outside the library, the kind that looks like it), both candidates are fitted on the
window's training samples, exactly as :func:`aslm_core.diagnosis.diagnose` fits them, and the paired held-out
statistic is computed both ways: z(A over B) (the statistic the verdict uses when A is the top candidate and
B a rival) and z(B over A).  A pair is *separated rightly* on a window when the true member beats the other
at the one-comparison critical value (one-sided 5 %), *wrongly* when the other beats the true one.  Rows are
kept only where at least one member explains the held-out data (score test above the verdict's Bonferroni
critical value and a positive penalised gain): only there does the pair decide a verdict.  Records and per-pair
shares go to ``docs/results/diagnosis_pairs.json``.  Recordings come from the cache of
:mod:`benchmarks.diagnosis_independent` (windows, levels and noise drawn identically).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.diagnosis import _init  # noqa: E402
from benchmarks.diagnosis_independent import LEVELS, SETS, TF, TSTEP, WINDOWS, _window  # noqa: E402

OUT = ROOT / "docs" / "results" / "diagnosis_pairs.json"
#: pair → {ANDES kind: the member that is the truth there (None: neither, an outside-library look-alike)}.
PAIRS: dict[tuple[str, str], dict[str, str | None]] = {
    ("second_motor", "double_cage_rotor"): {"second_motor": "second_motor", "double_cage": "double_cage_rotor"},
    ("frequency_dependence", "speed_dependent_torque"): {
        "frequency_dependence": "frequency_dependence", "speed_dependent_torque": "speed_dependent_torque"},
    ("inverter_der", "switched_shunt"): {"thermostatic_cycling": None},
    ("inverter_der", "second_motor"): {"thermostatic_cycling": None, "second_motor": "second_motor"},
}
Z_ONE = 1.6448536269514722  # one-sided 5 %, one comparison


def run_job(job: tuple) -> list[dict]:
    """Every window, level and noise mode of one scenario: the pairs' fits and paired statistics."""
    from aslm_core.diagnosis import pipeline
    from aslm_core.diagnosis.candidates import LIBRARY
    from aslm_core.diagnosis.engine import dm_critical
    from aslm_sim.andes.effects import recording

    kind, seed, pairs, modes = job
    rec = recording(kind, seed, tf=TF, tstep=TSTEP)
    members = tuple(dict.fromkeys(m for p in pairs for m in p))
    config = pipeline.DiagnosisConfig(candidates=members)
    zcrit = dm_critical(config.alpha, len(LIBRARY))  # the verdict's Bonferroni over the whole library
    out = []
    for input_noise in modes:
        for t0, t1 in WINDOWS:
            for level in LEVELS:
                w, snr = _window(rec, t0, t1, level, input_noise, f"{kind}/{seed}")
                try:
                    a = pipeline._analyse(w, None, None, config)
                except ValueError as exc:
                    out.append({"kind": kind, "seed": seed, "failed": repr(exc)})
                    continue
                ent = {m: pipeline._entry([a], m, zcrit) for m in members}
                for p in pairs:
                    sep = {f"{x}>{y}": pipeline._separation_z([a], x, y, config) for x, y in (p, p[::-1])}
                    out.append({
                        "pair": list(p), "kind": kind, "truth": PAIRS[p][kind], "seed": seed, "window": [t0, t1],
                        "level": level, "input_noise": input_noise, "snr_db": snr, "separation_z": sep,
                        "members": {m: {"z": ent[m].score_z, "gain": ent[m].penalised_gain,
                                        "magnitude_z": ent[m].magnitude_z, "significant": ent[m].significant,
                                        "fits": bool(ent[m].score_z > zcrit and ent[m].penalised_gain > 0),
                                        "parameters": ent[m].parameters} for m in p},
                    })
    return out


def summarise(recs: list[dict]) -> dict:
    """Per pair, kind, noise mode and level, over the windows where a member explains the held-out data: how the
    paired test comes out both ways — ``x-`` the true member (or, for an outside kind, the pair's first)
    beats the other and not in turn (separated rightly), ``-y`` the other beats it and not in turn
    (separated wrongly), ``xy`` each beats the other (not separated with the reverse comparison), ``--``
    neither (not separated)."""
    out: dict = {}
    for r in recs:
        if "failed" in r or not any(m["fits"] for m in r["members"].values()):
            continue
        a, b = r["pair"]
        x = r["truth"] or a
        y = b if x == a else a
        cls = ("x" if r["separation_z"][f"{x}>{y}"] > Z_ONE else "-") + ("y" if r["separation_z"][f"{y}>{x}"] > Z_ONE else "-")
        row = out.setdefault(f"{a} / {b}", {}).setdefault(r["kind"], {}).setdefault(
            "input" if r["input_noise"] else "pq", {}).setdefault(str(r["level"]), {"x-": 0, "-y": 0, "xy": 0, "--": 0})
        row[cls] += 1
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sets", default="dev,confirm,confirm2", help="comma-separated sets of the benchmark")
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    p.add_argument("--noise", choices=("pq", "input", "both"), default="both")
    p.add_argument("--out", default=str(OUT))
    args = p.parse_args(argv)
    sets = [s for s in args.sets.split(",") if s]
    if "confirm3" in sets:
        raise SystemExit("confirm3 is the third round's confirmation set: not for development")
    kinds: dict[str, list] = {}
    for pair, truth in PAIRS.items():
        for k in truth:
            kinds.setdefault(k, []).append(pair)
    from aslm_sim.andes.effects import cache_dir

    # Only scenarios already in the cache: this measurement never starts an ANDES simulation.
    modes = {"pq": (False,), "input": (True,), "both": (False, True)}[args.noise]
    todo = [(k, s, tuple(kinds[k]), modes) for name in sets for k in kinds for s in SETS[name]["effect"]
            if any(cache_dir().glob(f"v*-{k}-{s}-*.npz"))]
    t0 = time.perf_counter()
    recs: list[dict] = []
    with ProcessPoolExecutor(max_workers=args.workers, initializer=_init) as pool:
        futs = {pool.submit(run_job, j): j for j in todo}
        for f in as_completed(futs):
            try:
                rows = f.result()
            except (RuntimeError, FileNotFoundError) as exc:  # a scenario ANDES could not simulate
                rows = [{"kind": futs[f][0], "seed": futs[f][1], "failed": repr(exc)}]
            recs += rows
            print(f"{futs[f][0]}/{futs[f][1]}: {len(rows)} rows", flush=True)
    summary = summarise(recs)
    for key, per_kind in summary.items():
        for kind, per_mode in per_kind.items():
            for mode, per_level in per_mode.items():
                for level, row in per_level.items():
                    print(f"{key:45s} {kind:24s} {mode:5s} L{level} " + "  ".join(f"{c} {n:2d}" for c, n in row.items()))
    Path(args.out).write_text(json.dumps({
        "sets": sets, "wall_s": time.perf_counter() - t0, "load_avg": os.getloadavg(), "z_one": Z_ONE,
        "command": "benchmarks/diagnosis_pairs.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "summary": summary, "records": recs}, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
