"""The diagnosis at every PMU reporting rate: model-true windows should come out ``consistent`` at 25–120 frames/s as
at 100, and a concealed effect should still be named (issue 11: "every reporting rate ... with the same protocol").

    .venv/bin/python -m benchmarks.diagnosis_rates [--seed 71] [--n 20] [--rates 25 30 50 60 100 120] [--levels 1 2 3]
        [--input-noise] [--effect NAME] [--workers 2] [--tag NAME] [--config NAME=VALUE ...] [--pmu fs5:1e-3]
    .venv/bin/python -m benchmarks.diagnosis_rates --andes 1 2 3 4 5 6 7 8 9 10 [--snr 22]

Per rate and level, ``n`` windows of the project's generator (``aslm_sim``, 1 ms steps; other records at each rate), plain ZIP + IM (the model
the diagnosis holds the recordings against), P and Q at the level's SNR (``--input-noise``: V, θ and f too), each
diagnosed with the default :class:`DiagnosisConfig` (``--config``: fields of it changed, e.g.
``exact_inputs_quiet=true``).  Tallied: the verdicts (on a model-true window anything but
``consistent`` is a false finding), the cause named, and the plain model's D/D_real − 1 (its median |error|).  With
``--effect``, the named effect of :mod:`aslm_sim.effects` is added to each window (concealed, as in
``benchmarks.diagnosis``) and the count that names it is the power.  With ``--andes``, an independent simulator's
model-true windows instead: ANDES's ``model`` scenario (``benchmarks.andes_rates``' records and decimation).  Written to
``docs/results/diagnosis_rates_seed<seed>[_<tag>].json`` (``diagnosis_rates_andes[_<tag>].json``).  With ``--pmu
SHAPE:CLASS``, every channel's noise a PMU's of that reporting-filter shape and class instead
(:func:`pmu_window`; with ``--config input_noise=measured`` the diagnosis reads it as a PMU's, stop 55).

With ``--andes`` and ``--pmu``, ANDES's records with a PMU's noise on every channel (stop 56; the rule
:data:`ANDES_PMU_RULE` fixed before its runs):

    for c in 1e-3 3e-4; do for a in "white auto" "fs5 measured" "fs5 auto"; do set -- $a
      .venv/bin/python -m benchmarks.diagnosis_rates --andes 31 32 33 34 35 36 37 38 39 40 --pmu $1:$c \
          --config input_noise=$2 --tag pmu_$1_$2_${c}_c; done; done
    .venv/bin/python -m benchmarks.diagnosis_rates --andes-pmu-report

and its second run (:data:`ANDES_PMU_SEEDS_SECOND`): the same with ``--andes 41 … 50``, tags ending ``_d``, then
``--andes-pmu-report --suffix _d``.

The code before a change is measured by running this module with that commit's tree first on ``PYTHONPATH`` (the
module imports only the public API).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import time  # noqa: E402
import zlib  # noqa: E402
from collections import Counter  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402

import numpy as np  # noqa: E402

from benchmarks import common  # noqa: E402

RATES = (25.0, 30.0, 50.0, 60.0, 100.0, 120.0)
#: Stop 56: the diagnosis on an independent simulator's model-true records with an M-class PMU's noise, fixed before
#: its runs on fresh ambient seeds (development: seeds 1–5, tags ending ``_dev56``; commands in the module docstring).
ANDES_PMU_RULE = ("on ANDES's model records (ambient seeds 31-40, seven windows each at 100, 50 and 25 frames/s: 210 a "
                  "class, P and Q at 22 dB), the verdicts other than 'consistent' with the fs5 filter and "
                  "input_noise='measured' at most the white PMU's (default) + 3, per class (1e-3, 3e-4)")
ANDES_PMU_SEEDS = tuple(range(31, 41))
#: The same rule's second run, after the diagnosis went back to the identifier's raises for P and Q (stop 56), on fresh
#: ambient seeds, tags ending ``_d``; fixed before the runs.
ANDES_PMU_SEEDS_SECOND = tuple(range(41, 51))


def andes_pmu_verdict(read=common.read_json, suffix: str = "_c") -> dict:
    """:data:`ANDES_PMU_RULE` on the stored runs ``diagnosis_rates_andes_pmu_{white_auto,fs5_measured,fs5_auto}_<class>``
    (+ ``suffix``): per class the false findings of each, and whether the rule is met."""
    out = {"rule": ANDES_PMU_RULE, "classes": {}}
    ok = True
    for cls in ("1e-3", "3e-4"):
        row = {}
        for key in ("white_auto", "fs5_measured", "fs5_auto"):
            cells = read(f"diagnosis_rates_andes_pmu_{key}_{cls}{suffix}")["cells"]
            n = sum(c["n"] for c in cells)
            row[key] = {"n": n, "false_findings": n - sum(c["verdicts"].get("consistent", 0) for c in cells)}
        out["classes"][cls] = row
        ok &= row["fs5_measured"]["false_findings"] <= row["white_auto"]["false_findings"] + 3
    out["met"] = bool(ok)
    return out


def diagnosed(job: tuple) -> dict:
    """One window's diagnosis: (rate, level, index, seed, input_noise, effect, DiagnosisConfig overrides) → verdict, cause,
    D/D_real."""
    from aslm_sim import make_cases

    fs, level, i, seed, input_noise, effect, config, *pmu = job
    case = make_cases(1, level=level, seed=seed * 100_000 + int(fs) * 100 + i, fs=fs, input_noise=input_noise)[0]
    window, model = case.window, None
    if effect:
        from aslm_sim.effects import apply_effect

        ec = apply_effect(case, effect, seed=zlib.crc32(f"{effect}/{fs}/{level}/{i}".encode()))
        window, model = ec.window, ec.model
    if pmu and pmu[0]:
        window = pmu_window(case, window, fs, *pmu[0], np.random.default_rng([seed, int(fs), level, i, 13]))
    return _row(window, model, case.truth.d, config, fs=fs, level=level, i=i)


def pmu_window(case, window, fs: float, shape: str, v_rel: float, rng: np.random.Generator):
    """``window`` (the case's, or its effect's) with all four channels' noise replaced by a PMU's of ``shape`` and
    class ``v_rel`` (:func:`benchmarks.pmu_filter.noisy_window`: V at v_rel, θ at v_rel rad, P and Q at the
    generator's own noise std), the effect's own part of P and Q kept."""
    from aslm_core import Window
    from benchmarks.pmu_filter import noisy_window

    w = noisy_window(case, fs, v_rel, v_rel, shape, rng)
    return Window(t=w.t, V=w.V, theta=w.theta, P=w.P + (window.P - case.window.P), Q=w.Q + (window.Q - case.window.Q),
                  f0=w.f0, bus=w.bus, meta=window.meta)


def _row(window, model, truth: np.ndarray, config: dict, **key) -> dict:
    from aslm_core.diagnosis import DiagnosisConfig, diagnose

    t0 = time.perf_counter()
    r = diagnose(window, model, config=DiagnosisConfig(**config))
    d = np.array([r.model.dynamic[k] for k in ("a", "b", "H2", "Tm")])
    return {**key, "verdict": r.verdict, "cause": r.cause, "d_ratio": (d / truth).tolist(),
            "elapsed_s": time.perf_counter() - t0}


def andes_record(seed: int) -> tuple[dict, np.ndarray]:
    """ANDES's 72 s record of the ``model`` scenario (bus 9's ZIP load and Motor3: the plain model holds) and its D."""
    from benchmarks.andes_crosscheck import scenario_record
    from benchmarks.andes_history import TF

    rec, facts = scenario_record("model", tf=TF, tstep=0.01, amp=0.15, seed=seed)
    return rec, np.asarray(facts["truth"])


def andes_diagnosed(job: tuple) -> dict:
    """One ANDES window's diagnosis: (ambient seed, window, rate, P/Q SNR [dB], config[, (shape, class)]); P and Q
    noisy, V and θ exact, the lower rates every second or fourth sample of the 100 frames/s window
    (``benchmarks.andes_rates``'s protocol).  With a PMU (shape, class): every channel's noise a PMU's of that
    reporting-filter shape drawn at the rate after the decimation, V at the class × its mean, θ at the class [rad], P
    and Q at the SNR (:func:`benchmarks.andes_rates.pmu_noisy`)."""
    from benchmarks.andes_crosscheck import noisy_window
    from benchmarks.andes_rates import STEPS, WINDOWS, decimated, pmu_noisy

    seed, j, fs, snr, config, *pmu = job
    rec, truth = andes_record(seed)
    if pmu and pmu[0]:
        shape, cls = pmu[0]
        base = decimated(noisy_window(rec, *WINDOWS[j], None, None), STEPS[fs])
        w = pmu_noisy(base, fs, cls, cls, snr, shape, np.random.default_rng([seed, j, int(fs), 17]))
        return _row(w, None, truth, config, fs=fs, level=f"andes {snr:g} dB", i=seed * 100 + j)
    w = noisy_window(rec, *WINDOWS[j], snr, np.random.default_rng([seed, j, int(round(snr * 10))]))
    return _row(decimated(w, STEPS[fs]), None, truth, config, fs=fs, level=f"andes {snr:g} dB", i=seed * 100 + j)


def summary(rows: list[dict], effect: str | None) -> list[dict]:
    """Per rate and level: the verdicts, the causes named and the plain model's median |D/D_real − 1|."""
    out = []
    for fs in sorted({r["fs"] for r in rows}):
        for level in sorted({r["level"] for r in rows}):
            cell = [r for r in rows if r["fs"] == fs and r["level"] == level]
            if not cell:
                continue
            err = np.abs(np.array([r["d_ratio"] for r in cell]) - 1.0)
            out.append({"fs": fs, "level": level, "n": len(cell),
                        "verdicts": dict(Counter(r["verdict"] for r in cell)),
                        "causes": dict(Counter(r["cause"] for r in cell if r["cause"])),
                        "named_effect": sum(r["cause"] == effect for r in cell) if effect else None,
                        "median_abs_error": np.median(err, axis=0).tolist(), "max_abs_error": err.max(axis=0).tolist()})
    return out


def main() -> None:
    p = common.parser(__doc__.splitlines()[0])
    p.add_argument("--seed", type=int, default=71)
    p.add_argument("--n", type=int, default=20, help="windows per rate and level")
    p.add_argument("--rates", type=float, nargs="+", default=list(RATES))
    p.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3])
    p.add_argument("--input-noise", action="store_true", help="V, θ and f noisy too (the generator's SNR rule)")
    p.add_argument("--effect", default="", help="a concealed effect of aslm_sim.effects added to every window")
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    p.add_argument("--andes", type=int, nargs="*", default=None, metavar="SEED",
                   help="instead: ANDES's model-scenario records of these ambient seeds (seven 10 s windows each, P and "
                        "Q at --snr, exact V and θ) at 100, 50 and 25 frames/s")
    p.add_argument("--snr", type=float, default=22.0, help="P/Q SNR of the ANDES windows [dB]")
    p.add_argument("--pmu", default="", metavar="SHAPE:CLASS",
                   help="every channel's noise a PMU's instead (benchmarks.pmu_filter): SHAPE white, fs5 or 5hz, CLASS "
                        "V's std over its mean and θ's [rad], e.g. fs5:1e-3")
    p.add_argument("--tag", default="")
    p.add_argument("--config", action="append", default=[], metavar="NAME=VALUE",
                   help="a DiagnosisConfig field changed for every window (repeatable)")
    p.add_argument("--andes-pmu-report", action="store_true", help="judge the stored ANDES --pmu runs by ANDES_PMU_RULE")
    p.add_argument("--suffix", default="_c", help="with --andes-pmu-report: the runs' tags end in this (_d: the second)")
    args = p.parse_args()
    if args.andes_pmu_report:
        v = andes_pmu_verdict(suffix=args.suffix)
        print(f"rule: {v['rule']}")
        for cls, row in v["classes"].items():
            print(f"  {cls}: false findings of {row['white_auto']['n']}: " + ", ".join(
                f"{k.replace('_', ' ')} {r['false_findings']}" for k, r in row.items()))
        print(f"verdict: {'met' if v['met'] else 'not met'}")
        return
    from benchmarks.diagnosis import config_overrides

    config = config_overrides(args.config)
    n = 2 if args.quick else args.n
    if n >= 100:  # window i of rate fs is seeded seed·100000 + fs·100 + i: more would reuse another rate's windows
        raise SystemExit("--n: at most 99 windows per rate and level")
    t0 = time.perf_counter()
    pmu = None
    if args.pmu:
        shape, _, cls = args.pmu.partition(":")
        pmu = (shape, float(cls))
    with ProcessPoolExecutor(args.workers) as ex:
        if args.andes is not None:
            from benchmarks.andes_rates import STEPS, WINDOWS

            list(ex.map(andes_record, args.andes))  # simulated once per seed (cached) before the windows share it
            jobs = [(seed, j, fs, args.snr, config, pmu) for seed in args.andes for j in range(len(WINDOWS))
                    for fs in STEPS]
            rows = list(ex.map(andes_diagnosed, jobs, chunksize=3))
        else:
            jobs = [(fs, level, i, args.seed, args.input_noise, args.effect or None, config, pmu)
                    for fs in args.rates for level in args.levels for i in range(n)]
            rows = list(ex.map(diagnosed, jobs, chunksize=2))
    cells = summary(rows, args.effect or None)
    table = []
    for c in cells:
        v = c["verdicts"]
        wrong = c["n"] - (c["named_effect"] if args.effect else v.get("consistent", 0))
        table.append([f"{c['fs']:g}", c["level"], c["n"], v.get("consistent", 0),
                      c["named_effect"] if args.effect else "–", wrong,
                      ", ".join(f"{k} {m}" for k, m in sorted(c["causes"].items())) or "–",
                      " / ".join(f"{100 * x:.1f}" for x in c["median_abs_error"])])
    print(common.md_table(["frames/s", "DL", "n", "consistent", "effect named", "other verdict or cause",
                           "causes named", "plain D median |error| a / b / H2 / Tm [%]"], table))
    print(f"{time.perf_counter() - t0:.0f} s")
    if not args.no_write:
        name = ("diagnosis_rates_andes" if args.andes is not None else f"diagnosis_rates_seed{args.seed}") + (
            f"_{args.tag}" if args.tag else "")
        path = common.write_json(name, {"args": vars(args), "machine": common.machine(), "cells": cells, "rows": rows})
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
