"""Diagnosis benchmark: concealed effects on synthetic cases, three noise levels, confusion matrix.

    .venv/bin/python benchmarks/diagnosis.py            # 12 cases per effect per level, 20 clean per level
    .venv/bin/python benchmarks/diagnosis.py --quick    # ~2 min smoke run
    .venv/bin/python benchmarks/diagnosis.py --input-noise   # V, θ, f noisy too (PMU-like)
    .venv/bin/python benchmarks/diagnosis.py --timing 30     # CPU time per diagnosis, one process
    .venv/bin/python benchmarks/diagnosis.py --fs 50         # the same cases at 50 frames/s (the service's default)

Each library effect (and two effects outside the library) is applied to synthetic ZIP + IM cases
(``input_noise=False``: noise on P and Q at the level's SNR, paper eq. 10) by :mod:`aslm_sim.effects`
and concealed (plain-fit FD ≥ 0.9 on P and Q).  ``exponential_static`` is diagnosed against a user model
(the true ZIP + IM with the old exponents) because it is not identifiable against a re-identified ZIP;
clean cases are diagnosed both ways.  ``--input-noise`` makes the cases with ``input_noise=True`` (V, θ and f
noisy at the same SNR as P and Q; the effects are still computed from the noise-free V and θ, and concealed on
the same case without input noise, so both modes carry the same effects at the same magnitudes).  Results go to
``docs/results/diagnosis.json`` (``diagnosis_input_noise.json`` with ``--input-noise``; ``_quick`` for
``--quick``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
import zlib
from collections import Counter, defaultdict
from concurrent.futures import ProcessPoolExecutor
from functools import lru_cache
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from aslm_sim.effects import EFFECTS, LIBRARY_EFFECTS, OUTSIDE_EFFECTS  # noqa: E402

RESULTS = ROOT / "docs" / "results" / "diagnosis.json"
LEVELS = (1, 2, 3)


@lru_cache(maxsize=64)
def _base(level: int, i: int, input_noise: bool = False):
    from aslm_sim.cases import make_case

    return make_case(10_000 * level + i, level=level, input_noise=input_noise, fs=_FS)


def case(job: tuple):
    """One case's input: (effect, level, case index[, input_noise]) → (base case, concealed effect case, the user
    model or None, whether the diagnosis is against a user model)."""
    from aslm_sim.effects import apply_effect

    effect, level, i, *rest = job
    input_noise = bool(rest[0]) if rest else False
    base = _base(level, i, input_noise)
    user = effect == "none_user" or (effect in EFFECTS and EFFECTS[effect].user_model)
    seed = zlib.crc32(f"{effect}/{level}/{i}".encode())  # deterministic (str hash() is salted per process)
    # With input noise the effect is concealed on the same case without it (same clean record, same P/Q
    # noise): noisy V/θ lower the plain fit's FD by themselves, which would shrink every effect.
    twin = _base(level, i, False) if input_noise else None
    ec = apply_effect(base, "none" if effect.startswith("none") else effect, seed=seed, conceal_case=twin)
    model = ec.model
    if effect == "none_user":
        model = {"dynamic": base.truth.dynamic, "static": base.truth.static_identifiable}
    return base, ec, model, user


def run_one(job: tuple) -> dict:
    """One diagnosis: (effect, level, case index[, input_noise]) → record."""
    from aslm_core.diagnosis import diagnose

    effect, level, i, *rest = job
    input_noise = bool(rest[0]) if rest else False
    base, ec, model, user = case(job)
    t0, c0 = time.perf_counter(), time.process_time()
    rep = diagnose(ec.window, model, config=diagnosis_config())
    elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
    top = next((e for e in rep.missing_physics if e.tested), None)
    rec = {
        "effect": effect, "level": level, "case": i, "snr_db": base.snr_db, "mode": "user" if user else "identified",
        "input_noise": input_noise,
        "verdict": rep.verdict, "cause": rep.cause, "causes": rep.causes, "top": top.name if top else None,
        "top_significant": bool(top and top.significant), "fd_plain": ec.fd_plain, "conceal_scale": ec.scale,
        "fit_before": rep.fit_before.to_dict(), "fit_after": rep.fit_after.to_dict(), "elapsed_s": elapsed, "cpu_s": cpu,
        "located": rep.located.channels, "truth": {k: float(v) for k, v in ec.truth.items()},
    }
    if rep.cause:
        e = rep.candidate(rep.cause)
        rec["improvement"] = e.improvement.to_dict()
        rec["excess_reduction"] = e.excess_reduction.to_dict()
        rec["improvement_band"] = e.improvement_band.to_dict()
        rec["parameters"] = {**e.parameters, **e.derived}
        rec["stderr"] = e.stderr
    return rec


def _jobs(n_eff: int, n_clean: int, n_user: int, input_noise: bool = False) -> list[tuple[str, int, int, bool]]:
    jobs = []
    for lvl in LEVELS:
        for eff in (*LIBRARY_EFFECTS, *OUTSIDE_EFFECTS):
            jobs += [(eff, lvl, i, input_noise) for i in range(n_eff)]
        jobs += [("none", lvl, i, input_noise) for i in range(n_clean)]
        jobs += [("none_user", lvl, i, input_noise) for i in range(n_user)]
    return jobs


def summarise(recs: list[dict]) -> dict:
    """Confusion matrix, accuracy per level, false-explained rate, improvements, timing."""
    conf: dict[str, Counter] = defaultdict(Counter)
    for r in recs:
        pred = r["cause"] if r["verdict"] == "explained" else r["verdict"]
        conf[r["effect"]][pred] += 1
    acc = {}
    for lvl in LEVELS:
        lib = [r for r in recs if r["level"] == lvl and r["effect"] in LIBRARY_EFFECTS]
        acc[lvl] = {
            "named_correctly": float(np.mean([r["cause"] == r["effect"] for r in lib])) if lib else float("nan"),
            "top_ranked": float(np.mean([r["top"] == r["effect"] for r in lib])) if lib else float("nan"),
            "n": len(lib),
            "per_effect": {e: float(np.mean([r["cause"] == e for r in lib if r["effect"] == e])) for e in LIBRARY_EFFECTS
                           if any(r["effect"] == e for r in lib)},
        }
    clean = [r for r in recs if r["effect"] == "none"]
    clean_user = [r for r in recs if r["effect"] == "none_user"]
    wrong = [r for r in recs if r["verdict"] == "explained" and r["cause"] != r["effect"]]
    outside = [r for r in recs if r["effect"] in OUTSIDE_EFFECTS]
    imp = {}
    for e in LIBRARY_EFFECTS:
        ok = [r for r in recs if r["effect"] == e and r["cause"] == e]
        if not ok:
            continue
        chans = EFFECTS[e].channels  # "variance reduced on the channels it acts on"
        red_ok = [all(r["improvement"][c.lower()] >= 0.5 for c in chans) for r in ok]
        band = [[r["improvement_band"][c.lower()] for c in chans] for r in ok]
        band_ok = [all(x is not None and x >= 0.5 for x in b) for b in band]
        imp[e] = {
            "n": len(ok),
            "median_var_reduction_p": float(np.median([r["improvement"]["p"] for r in ok])),
            "median_var_reduction_q": float(np.median([r["improvement"]["q"] for r in ok])),
            "share_reduced_50pct_on_acting_channels": float(np.mean(red_ok)),
            "median_band_reduction_p": float(np.nanmedian([np.nan if r["improvement_band"]["p"] is None
                                                           else r["improvement_band"]["p"] for r in ok])),
            "median_band_reduction_q": float(np.nanmedian([np.nan if r["improvement_band"]["q"] is None
                                                           else r["improvement_band"]["q"] for r in ok])),
            "share_band_reduced_50pct_on_acting_channels": float(np.mean(band_ok)),
            "median_excess_reduction": float(np.nanmedian([np.nanmean([np.nan if r["excess_reduction"][c.lower()] is None
                                                                  else r["excess_reduction"][c.lower()] for c in chans])
                                                       for r in ok])),
            "median_fd_gain_p": float(np.median([r["fit_after"]["fd_p"] - r["fit_before"]["fd_p"] for r in ok])),
            "median_fd_gain_q": float(np.median([r["fit_after"]["fd_q"] - r["fit_before"]["fd_q"] for r in ok])),
            "share_fd_raised_on_acting_channels": float(np.mean(
                [all(r["fit_after"][f"fd_{c.lower()}"] > r["fit_before"][f"fd_{c.lower()}"] for c in chans) for r in ok])),
        }
        name = EFFECTS[e].main_parameter
        errs = [abs(r["parameters"].get(name, np.nan) / r["truth"][name] - 1.0) for r in ok if name in r["truth"]]
        if errs:
            imp[e][f"median_rel_error_{name}"] = float(np.nanmedian(errs))
    times = np.array([r["elapsed_s"] for r in recs])
    return {
        "confusion": {k: dict(v) for k, v in conf.items()},
        "accuracy": acc,
        "clean_consistent": float(np.mean([r["verdict"] == "consistent" for r in clean])) if clean else float("nan"),
        "clean_user_consistent": float(np.mean([r["verdict"] == "consistent" for r in clean_user])) if clean_user else float("nan"),
        "false_explained_rate": len(wrong) / len(recs),
        "false_explained_cases": [(r["effect"], r["level"], r["case"], r["cause"]) for r in wrong],
        "outside_unexplained": float(np.mean([r["verdict"] == "unexplained" for r in outside])) if outside else float("nan"),
        "outside_named": float(np.mean([r["verdict"] == "explained" for r in outside])) if outside else float("nan"),
        "ambiguous_rate": float(np.mean([r["verdict"] == "ambiguous" for r in recs])),
        # An ambiguous verdict names no cause; whether the true one is among those it lists:
        "ambiguous_with_truth": float(np.mean([r["effect"] in (r.get("causes") or []) for r in recs
                                               if r["verdict"] == "ambiguous"] or [float("nan")])),
        "improvement_when_explained": imp,
        "time_s": {"median": float(np.median(times)), "p95": float(np.percentile(times, 95)), "max": float(times.max())},
        "n_cases": len(recs),
        "concealed_share": float(np.mean([min(r["fd_plain"].values()) >= 0.9 for r in recs if r["fd_plain"]])),
    }


def markdown(s: dict) -> str:
    s = {**s, "accuracy": {int(k): v for k, v in s["accuracy"].items()}}  # JSON turns the level keys into str
    # Candidates without a synthetic effect (issue 12's, proven on ANDES) get a column when they are named.
    named = sorted({c for row in s["confusion"].values() for c in row} - set(LIBRARY_EFFECTS)
                   - {"ambiguous", "consistent", "unexplained"})
    cols = [*LIBRARY_EFFECTS, *named, "ambiguous", "consistent", "unexplained"]
    short = {**{n: e.label for n, e in EFFECTS.items()}, **{v: v for v in (*named, "ambiguous", "consistent", "unexplained")}}
    lines = ["| true \\ verdict | " + " | ".join(short[c] for c in cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for eff in (*LIBRARY_EFFECTS, *OUTSIDE_EFFECTS, "none", "none_user"):
        row = s["confusion"].get(eff)
        if row:
            lines.append(f"| {eff} | " + " | ".join(str(row.get(c, 0)) for c in cols) + " |")
    lines += ["", "| level | named correctly (explained, right cause) | top-ranked right | n |", "|---|---|---|---|"]
    for lvl, a in s["accuracy"].items():
        lines.append(f"| {lvl} | {100 * a['named_correctly']:.1f} % | {100 * a['top_ranked']:.1f} % | {a['n']} |")
    lines += ["", "| effect | " + " | ".join(f"L{lvl}" for lvl in LEVELS) + " |", "|---" * (len(LEVELS) + 1) + "|"]
    for e in LIBRARY_EFFECTS:
        vals = [s["accuracy"][lvl]["per_effect"].get(e) for lvl in LEVELS]
        lines.append(f"| {e} | " + " | ".join("-" if v is None else f"{100 * v:.0f} %" for v in vals) + " |")
    lines += ["", f"- clean cases `consistent` (identified model): {100 * s['clean_consistent']:.1f} %",
              f"- clean cases `consistent` (true model as user model): {100 * s['clean_user_consistent']:.1f} %",
              f"- a cause named that is absent (`explained`, wrong name), all cases: {100 * s['false_explained_rate']:.1f} %",
              f"- outside-library effects `unexplained`: {100 * s['outside_unexplained']:.1f} % (named: {100 * s['outside_named']:.1f} %)",
              f"- `ambiguous`: {100 * s.get('ambiguous_rate', 0.0):.1f} % of all cases; the true cause among those listed in "
              f"{100 * s.get('ambiguous_with_truth', float('nan')):.0f} % of them",
              f"- time per diagnosis: median {s['time_s']['median']:.2f} s, p95 {s['time_s']['p95']:.2f} s, max {s['time_s']['max']:.2f} s",
              f"- concealed (plain FD ≥ 0.9 on P and Q): {100 * s['concealed_share']:.1f} % of cases; {s['n_cases']} cases", "",
              "| effect (when named) | n | median ΔVar P | median ΔVar Q | ≥50 % on acting channels | in-band ΔVar P | in-band ΔVar Q | ≥50 % in band on acting channels | median excess removed | median ΔFD P | median ΔFD Q | FD raised | parameter error |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for e, v in s["improvement_when_explained"].items():
        perr = next(((k.replace("median_rel_error_", ""), x) for k, x in v.items() if k.startswith("median_rel_error_")), None)
        lines.append(f"| {e} | {v['n']} | {100 * v['median_var_reduction_p']:.0f} % | {100 * v['median_var_reduction_q']:.0f} % | "
                     f"{100 * v['share_reduced_50pct_on_acting_channels']:.0f} % | "
                     f"{100 * v['median_band_reduction_p']:.0f} % | {100 * v['median_band_reduction_q']:.0f} % | "
                     f"{100 * v['share_band_reduced_50pct_on_acting_channels']:.0f} % | {100 * v['median_excess_reduction']:.0f} % | "
                     f"{v['median_fd_gain_p']:+.4f} | "
                     f"{v['median_fd_gain_q']:+.4f} | {100 * v['share_fd_raised_on_acting_channels']:.0f} % | "
                     + (f"{perr[0]}: {100 * perr[1]:.1f} %" if perr else "-") + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="1 case per effect per level, 2 clean per level")
    p.add_argument("--per-level", type=int, default=12, help="cases per effect per level")
    p.add_argument("--clean", type=int, default=20, help="clean cases per level")
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    p.add_argument("--input-noise", action="store_true",
                   help="noise on V, θ and f too (synthetic input_noise=True); default: P and Q only (paper protocol)")
    p.add_argument("--only", default="", help="comma-separated effects to run (e.g. none,measurement_skew)")
    p.add_argument("--cases", default="", help="comma-separated cases effect/level/i to run (e.g. a rerun of the ones "
                                               "a rule change can touch)")
    p.add_argument("--timing", type=int, default=0, metavar="N",
                   help="only time N diagnoses one after another in this process (CPU time of one core)")
    p.add_argument("--no-write", action="store_true")
    p.add_argument("--tag", default="", help="written as diagnosis[_input_noise]_<tag>.json (a rerun that must not "
                                             "overwrite the run of record)")
    p.add_argument("--config", action="append", default=[], metavar="NAME=VALUE",
                   help="a DiagnosisConfig option other than its default (repeatable; e.g. cross_fit=true)")
    p.add_argument("--fs", type=float, default=100.0,
                   help="the cases' reporting rate [frames/s] (the same cases, sampled at this rate; written with "
                        "_fs<rate> in the name unless 100)")
    args = p.parse_args(argv)
    overrides = config_overrides(args.config)
    if args.timing:
        return _timing(args.timing, args.input_noise, overrides, args.fs)
    n_eff, n_clean, n_user = (1, 2, 1) if args.quick else (args.per_level, args.clean, max(4, args.clean // 3))
    jobs = _jobs(n_eff, n_clean, n_user, args.input_noise)
    if args.only:
        keep = set(args.only.split(","))
        jobs = [j for j in jobs if j[0] in keep]
    if args.cases:
        keep = set(args.cases.split(","))
        jobs = [j for j in jobs if f"{j[0]}/{j[1]}/{j[2]}" in keep]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers, initializer=_init, initargs=(overrides, args.fs)) as pool:
        recs = list(pool.map(run_one, jobs, chunksize=1))
    wall = time.perf_counter() - t0
    s = summarise(recs)
    s["wall_s"] = wall
    s["command"] = "benchmarks/diagnosis.py" + (" --quick" if args.quick else "") + (
        " --input-noise" if args.input_noise else "") + (f" --only {args.only}" if args.only else "") + (
        f" --cases {args.cases}" if args.cases else "") + "".join(f" --config {c}" for c in args.config) + (
        f" --fs {args.fs:g}" if args.fs != 100.0 else "")
    s["input_noise"] = args.input_noise
    s["fs"] = args.fs
    s["machine"] = {"cpus": os.cpu_count(), "python": platform.python_version(), "workers": args.workers}
    print(markdown(s))
    print(f"\nwall {wall:.0f} s for {len(recs)} diagnoses ({args.workers} workers)")
    if not args.no_write:
        RESULTS.parent.mkdir(parents=True, exist_ok=True)
        stem = "diagnosis" + ("_input_noise" if args.input_noise else "") + ("_quick" if args.quick else "")
        if args.fs != 100.0:
            stem += f"_fs{args.fs:g}"
        if args.only or args.cases:
            stem += "_only"
        if args.tag:
            stem += f"_{args.tag}"
        RESULTS.with_name(stem + ".json").write_text(
            json.dumps({"summary": s, "records": recs}, indent=1, default=float))
    return 0


def _timing(n: int, input_noise: bool, overrides: dict | None = None, fs: float = 100.0) -> int:
    """N diagnoses in this process (effects and levels interleaved); CPU time per diagnosis."""
    _init(overrides, fs)
    effects = [*LIBRARY_EFFECTS, *OUTSIDE_EFFECTS, "none"]
    jobs = [(effects[k % len(effects)], 1 + k % 3, k // len(effects), input_noise) for k in range(n + 1)]
    recs = [run_one(j) for j in jobs][1:]  # the first one pays for loading compiled kernels
    cpu = np.array([r["cpu_s"] for r in recs])
    wall = np.array([r["elapsed_s"] for r in recs])
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    print(f"{n} diagnoses{' (input noise)' if input_noise else ''}: CPU median {np.median(cpu):.2f} s, "
          f"p95 {np.percentile(cpu, 95):.2f} s, max {cpu.max():.2f} s; wall median {np.median(wall):.2f} s; "
          f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    return 0


#: The diagnosis's options in this process (``--config``; None: its defaults), set by :func:`_init`.
_CONFIG_OVERRIDES: dict | None = None
#: The cases' reporting rate in this process [frames/s] (``--fs``), set by :func:`_init`.
_FS = 100.0


def _init(overrides: dict | None = None, fs: float = 100.0) -> None:
    global _CONFIG_OVERRIDES, _FS
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from aslm_core import warmup

    _CONFIG_OVERRIDES = overrides
    if fs != _FS:
        _base.cache_clear()
    _FS = fs
    warmup()


def diagnosis_config():
    """The :class:`~aslm_core.diagnosis.DiagnosisConfig` of this process: the defaults with ``--config``'s changes."""
    from aslm_core.diagnosis.pipeline import DiagnosisConfig

    return DiagnosisConfig(**(_CONFIG_OVERRIDES or {}))


def config_overrides(items: list[str]) -> dict:
    """``--config`` values ``NAME=VALUE`` (VALUE read as JSON where it parses, else as text) as a dict; a name
    :class:`~aslm_core.diagnosis.DiagnosisConfig` does not have is a clear error."""
    from dataclasses import fields

    from aslm_core.diagnosis.pipeline import DiagnosisConfig

    known = {f.name for f in fields(DiagnosisConfig)}
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or name not in known:
            raise SystemExit(f"--config {item!r}: expected NAME=VALUE with NAME one of {sorted(known)}")
        try:
            out[name] = json.loads(value)
        except json.JSONDecodeError:
            out[name] = value
    return out


if __name__ == "__main__":
    sys.exit(main())
