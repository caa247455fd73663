"""Interleaved A/B of a speed change of the diagnosis: CPU per diagnosis, both sides in one process.

    .venv/bin/python -m benchmarks.diagnosis_speed_ab [--repeats 2]                  # round 4: the caches
    .venv/bin/python -m benchmarks.diagnosis_speed_ab --change projection --out diagnosis_speed_ab_fastdiag

``caches`` (round 4): seven cached ANDES windows (the four slowest of ``confirm3`` among them, noise on V and
θ) diagnosed with the filter-design and relay-V caches on (after) and off (before: the Butterworth design and
the switched-shunt candidate's low-passed V recomputed at every call); the reports must be identical.

``projection`` (round 6): the slowest windows of the seen sets' records (``docs/results/
diagnosis_independent_*.json``, CPU field; :data:`SLOW`) diagnosed with the compiled lower stage
(:mod:`aslm_core.diagnosis.projection`) and the static regressors kept between evaluations (after), and with
the NumPy lower stage it replaced (before: :func:`aslm_core.diagnosis.engine._train_residuals` per residual
evaluation, the static part recomputed at every call).  The two agree to rounding, not to
the last bit, so the upper stage's path can differ where it stops at its evaluation cap: the verdicts and
causes must be the same, every other number is compared and the largest difference reported.

The order of the two sides alternates per window and repeat; ``--out`` writes the raw times to docs/results/.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy import signal

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

CASES = (("oscillating_load", 9201, 2.0, 1, True), ("oscillating_load", 9203, 12.0, 3, True),
         ("thermostatic_cycling", 9203, 2.0, 2, True), ("noisy_load", 9203, 12.0, 2, True),
         ("second_motor", 9201, 2.0, 2, True), ("clean", 9205, 2.0, 3, False), ("double_cage", 9201, 12.0, 2, False))
#: The slowest windows of the seen sets' runs of record (kind, seed, window start [s], level, V/θ noise):
#: CPU 1.97–2.38 s there (confirm2–confirm5; the first diagnosis of a worker, start-up included, left out).
SLOW = (("noisy_load", 9203, 12.0, 2, True), ("noisy_load", 9103, 2.0, 3, True), ("noisy_load", 9101, 2.0, 3, True),
        ("oscillating_load", 9101, 2.0, 2, False), ("noisy_load", 9303, 2.0, 3, True),
        ("thermostatic_cycling", 9203, 2.0, 2, True), ("noisy_load", 9402, 12.0, 3, True),
        ("double_cage", 9401, 2.0, 1, False), ("oscillating_load", 9301, 2.0, 2, True),
        ("noisy_load", 9402, 12.0, 2, True))


def _caches():
    from aslm_core.diagnosis import locate, segment
    from aslm_core.diagnosis.candidates import switched_shunt

    cached_sos, cached_relay = segment.butter_sos, switched_shunt.SwitchedShunt._relay_v

    def uncached_sos(fc: float, fs: float) -> np.ndarray:
        return signal.butter(4, fc, fs=fs, output="sos")

    def uncached_relay(self, seg) -> np.ndarray:
        return segment._lowpass(seg.V, seg.fs, segment.FREQ_LOWPASS_HZ)

    def toggle(on: bool) -> None:
        segment.butter_sos = locate.butter_sos = cached_sos if on else uncached_sos
        switched_shunt.SwitchedShunt._relay_v = cached_relay if on else uncached_relay

    return toggle


def _projection():
    from aslm_core.diagnosis import engine
    from aslm_core.diagnosis.candidates import base, motor_stator_dynamics, switched_shunt

    compiled = engine.Projector
    kept = base.static_part
    users = (base, motor_stator_dynamics, switched_shunt)  # the modules that hold static_part by name

    def recomputed(seg, ctx, V=None):
        """static_part as before round 6: computed afresh at every call."""
        base._LAST_STATIC = None
        return kept(seg, ctx, V)

    class NumpyProjector:
        """The lower stage as before round 6: the NumPy path of :func:`engine._train_residuals` per call."""

        def __init__(self, seg, noise, fallback):
            self.seg, self.noise = seg, noise

        def residuals(self, pr) -> np.ndarray:
            rp, rq, *_ = engine._train_residuals(pr, self.seg, self.noise)
            return np.concatenate([rp, rq])

    def toggle(on: bool) -> None:
        engine.Projector = compiled if on else NumpyProjector
        for mod in users:
            mod.static_part = kept if on else recomputed

    return toggle


CHANGES = {"caches": (CASES, _caches, True), "projection": (SLOW, _projection, False)}


def _numbers(x, path: str = "") -> dict[str, float]:
    """Every number of a report, flattened (path → value)."""
    out: dict[str, float] = {}
    if isinstance(x, dict):
        for k, v in x.items():
            out.update(_numbers(v, f"{path}/{k}"))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            out.update(_numbers(v, f"{path}/{i}"))
    elif isinstance(x, (int, float)) and not isinstance(x, bool) and x is not None:
        out[path] = float(x)
    return out


def main(argv: list[str] | None = None) -> int:
    from aslm_core.diagnosis import diagnose
    from aslm_sim.andes.effects import recording
    from benchmarks.diagnosis_independent import TF, TSTEP, _window

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--change", choices=list(CHANGES), default="caches")
    p.add_argument("--out", default="", help="write docs/results/<out>.json")
    args = p.parse_args(argv)
    cases, make_toggle, exact = CHANGES[args.change]
    toggle = make_toggle()
    windows = [_window(recording(k, s, tf=TF, tstep=TSTEP), t0, t0 + 10.0, lvl, inp, f"{k}/{s}")[0]
               for k, s, t0, lvl, inp in cases]
    diagnose(windows[0])  # numba compilation outside the timing
    cpu: dict[str, list[float]] = {"before": [], "after": []}
    rows = []
    identical, same_verdicts, max_rel = True, True, 0.0
    for rep in range(args.repeats):
        for i, w in enumerate(windows):
            out, times = {}, {}
            for on in ((False, True) if (rep + i) % 2 == 0 else (True, False)):
                toggle(on)
                c0 = time.process_time()
                d = diagnose(w).to_dict()
                times[on] = time.process_time() - c0
                cpu["after" if on else "before"].append(times[on])
                d.pop("elapsed_s", None)
                out[on] = d
            identical &= json.dumps(out[True], sort_keys=True, default=str) == json.dumps(out[False], sort_keys=True,
                                                                                            default=str)
            same = (out[True]["verdict"], out[True]["cause"], out[True]["causes"]) == \
                (out[False]["verdict"], out[False]["cause"], out[False]["causes"])
            same_verdicts &= same
            a, b = _numbers(out[True]), _numbers(out[False])
            rel = max((abs(a[k] - b[k]) / max(abs(b[k]), 1e-12) for k in a.keys() & b.keys()), default=0.0)
            max_rel = max(max_rel, rel)
            rows.append({"case": list(cases[i]), "repeat": rep, "before_s": times[False], "after_s": times[True],
                         "verdict_before": [out[False]["verdict"], out[False]["cause"], out[False]["causes"]],
                         "verdict_after": [out[True]["verdict"], out[True]["cause"], out[True]["causes"]],
                         "max_rel_diff": rel})
            print(f"{cases[i]} before {times[False]:.2f} s after {times[True]:.2f} s  "
                  f"{out[False]['verdict']}/{out[False]['cause']} -> {out[True]['verdict']}/{out[True]['cause']}  "
                  f"max rel diff {rel:.1e}", flush=True)
    toggle(True)
    summary = {}
    for k, v in cpu.items():
        t = np.array(v)
        summary[k] = {"median": float(np.median(t)), "max": float(t.max()), "total": float(t.sum())}
        print(f"{k}: CPU per diagnosis median {np.median(t):.2f} s, max {t.max():.2f} s, total {t.sum():.1f} s")
    load = os.getloadavg()
    print(f"reports identical: {identical}; verdicts identical: {same_verdicts}; largest relative difference of a "
          f"number {max_rel:.1e}; load average {load}")
    if args.out:
        (ROOT / "docs" / "results" / f"{args.out}.json").write_text(json.dumps(
            {"change": args.change, "summary": summary, "identical": identical, "verdicts_identical": same_verdicts,
             "max_rel_diff": max_rel, "load_avg": load, "rows": rows,
             "command": "benchmarks/diagnosis_speed_ab.py " + " ".join(argv if argv is not None else sys.argv[1:])},
            indent=1))
    return 0 if (identical if exact else same_verdicts) else 1


if __name__ == "__main__":
    sys.exit(main())
