"""How wide the diagnosis's held-out score statistics are on model-true windows (stop 56).

With nothing missing, each candidate's held-out score statistic is N(0, 1) (:func:`aslm_core.diagnosis.engine.compare`),
so E[z²] over windows and candidates is 1 when the noise model is right; above 1 the noise model reads the residual's
noise low and false findings follow.  Per window of the project's generator (``benchmarks.diagnosis_rates``' windows
and PMU noise, ``--pmu SHAPE:CLASS``), diagnosed with ``--config`` overrides: the verdicts, and E[z²] of the six
candidates that test the motor's and the measurement's form (:data:`CANDIDATES`).  JSON
``docs/results/diagnosis_score_width_<tag>.json``.

    .venv/bin/python -m benchmarks.diagnosis_score_width --seed 88 --pmu white:1e-3 --tag seed88_white_1e-3
    .venv/bin/python -m benchmarks.diagnosis_score_width --seed 88 --pmu fs5:1e-3 --config input_noise=measured \\
        --tag seed88_fs5_measured_1e-3
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
from collections import Counter  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402

import numpy as np  # noqa: E402

from benchmarks import common  # noqa: E402

#: The candidates whose statistics are averaged (those tested on every window).
CANDIDATES = ("double_cage_rotor", "inverter_der", "measurement_skew", "second_motor", "stator_resistance",
              "frequency_dependence")


def scored(job: tuple) -> dict:
    """One window: (rate, level, index, seed, (shape, class), DiagnosisConfig overrides) → verdict and score z's."""
    from aslm_core.diagnosis import DiagnosisConfig, diagnose
    from aslm_sim import make_cases
    from benchmarks.diagnosis_rates import pmu_window

    fs, level, i, seed, (shape, cls), config = job
    case = make_cases(1, level=level, seed=seed * 100_000 + int(fs) * 100 + i, fs=fs, input_noise=False)[0]
    w = pmu_window(case, case.window, fs, shape, cls, np.random.default_rng([seed, int(fs), level, i, 13]))
    rep = diagnose(w, None, config=DiagnosisConfig(**config)).to_dict()
    return {"fs": fs, "level": level, "i": i, "verdict": rep["verdict"], "cause": rep["cause"],
            "z": {e["name"]: e["score_z"] for e in rep["missing_physics"] if e["score_z"] is not None}}


def width(rows: list[dict]) -> float:
    """E[z²] over the rows and :data:`CANDIDATES` (a candidate not tested on a window counts as z = 0)."""
    z = np.array([[r["z"].get(n, 0.0) for n in CANDIDATES] for r in rows])
    return float(np.mean(z**2))


def main(argv=None) -> dict:
    from benchmarks.diagnosis import config_overrides

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=88)
    ap.add_argument("--n", type=int, default=20, help="windows per rate and level")
    ap.add_argument("--rates", type=float, nargs="+", default=[25.0, 50.0, 100.0])
    ap.add_argument("--levels", type=int, nargs="+", default=[2, 3])
    ap.add_argument("--pmu", default="white:1e-3", metavar="SHAPE:CLASS")
    ap.add_argument("--config", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--tag", default="")
    args = ap.parse_args(argv)
    shape, _, cls = args.pmu.partition(":")
    config = config_overrides(args.config)
    jobs = [(fs, lv, i, args.seed, (shape, float(cls)), config) for fs in args.rates for lv in args.levels
            for i in range(args.n)]
    with ProcessPoolExecutor(args.workers) as ex:
        rows = list(ex.map(scored, jobs, chunksize=2))
    out = {"args": vars(args), "verdicts": dict(Counter(r["verdict"] for r in rows)), "width": width(rows),
           "width_per_rate": {f"{fs:g}": width([r for r in rows if r["fs"] == fs]) for fs in args.rates},
           "rows": rows}
    print(f"E[z²] {out['width']:.2f} (per rate: " + ", ".join(f"{k} {v:.2f}" for k, v in out["width_per_rate"].items())
          + f"); verdicts {out['verdicts']}")
    if args.tag:
        common.write_json(f"diagnosis_score_width_{args.tag}", out)
    return out


if __name__ == "__main__":
    main()
