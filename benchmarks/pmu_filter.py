"""Identification when a PMU's reporting filter shapes its noise (an M-class PMU, C37.118.1): issue 11 on real channels.

The supplement and the rates benches add white noise to each reported sample, as a P-class PMU's short filter leaves
it.  An M-class PMU low-passes its phasors before it reports them (the standard's out-of-band test; ABB's REC670
manual: every aliasing frequency at least −40 dB), so its noise is flat only up to the filter's passband and falls
towards the reporting Nyquist frequency: the floor band above 5 Hz that the identifier reads the noise from holds
the filter's roll-off, not the in-band level.

Noise model (:func:`filtered_noise`), per channel: white noise at ``UP`` × the reporting rate, through a linear-phase
FIR low-pass (equiripple, passband flat within 1 %, stopband from fs/2 at −40 dB or better), taken at the reporting
instants.  Its density in the passband is that of white noise of the class's std at the reporting rate, so the noise
in the band the identifier uses is the same as the white benches'; only the band above differs.  Two passbands:

* ``fs5``: flat up to a fifth of the rate (the M class's measurement bandwidth, min(fs/5, 5 Hz), met with room at
  fs ≥ 25, as designs that keep the whole of fs/5 do);
* ``5hz``: flat only up to 5 Hz at every rate (the least the standard's min(fs/5, 5 Hz) asks; a long roll-off at high
  rates).

V: the class's std × mean V; θ: the class's std [rad]; P and Q: the std of the generator's own white noise at the
level's SNR (so ``white`` reproduces the supplement's windows).  ``white``: every channel white (a P-class PMU).

Per rate, level, PMU class and noise shape, every window (the generator's, ``--seed``, the same clean records and draws
for every shape) is identified with ``input_noise="auto"`` (the default) and ``input_noise="measured"``: μ and σ of
D/D_real, coverage of ±1.96 SE, V's noise estimate over the in-band std, the share of windows whose inputs were
taken as exact, and of those flagged.  JSON ``docs/results/pmu_filter[_<tag>].json``.

    .venv/bin/python -m benchmarks.pmu_filter [--rates 25 30 50 60 100 120] [--levels 2 3] [--n 100] [--seed 80]
    .venv/bin/python -m benchmarks.pmu_filter --n 300 --seed 81 --tag confirm55     # the confirmation, RULE
    .venv/bin/python -m benchmarks.pmu_filter --report pmu_filter_confirm55          # its verdict from the JSON

Development: seed 80, 100 windows (``--tag dev80``).  The confirmation's rule (:data:`RULE`, :func:`verdict`) was
fixed before its run on seed 81.

The diagnosis on the same noise (``benchmarks.diagnosis_rates --pmu``; :data:`DIAGNOSIS_RULE`, fixed before the runs):

    for c in 1e-3 3e-4; do
      .venv/bin/python -m benchmarks.diagnosis_rates --seed 84 --n 20 --rates 25 50 100 --levels 2 3 --pmu white:$c --tag pmu_white_$c
      .venv/bin/python -m benchmarks.diagnosis_rates --seed 84 --n 20 --rates 25 50 100 --levels 2 3 --pmu fs5:$c --tag pmu_fs5_$c
      .venv/bin/python -m benchmarks.diagnosis_rates --seed 84 --n 20 --rates 25 50 100 --levels 2 3 --pmu fs5:$c \
          --config input_noise=measured --tag pmu_fs5_measured_$c; done
    for pmu in white:3e-4 fs5:3e-4; do .venv/bin/python -m benchmarks.diagnosis_rates --seed 85 --n 15 --rates 50 100 \
          --levels 2 3 --effect second_motor --pmu $pmu --tag pmu_${pmu%%:*}_second_motor \
          $([ ${pmu%%:*} = fs5 ] && echo --config input_noise=measured); done
    .venv/bin/python -m benchmarks.pmu_filter --diagnosis-report

The second confirmation (:data:`SECOND`), after the measured mode read its level from V's incoherent part (a89aef5)
instead of the band's lowest 1 Hz, which the ANDES cross-check had failed: the same rules on fresh seeds, fixed
before the runs:

    .venv/bin/python -m benchmarks.pmu_filter --n 300 --seed 87 --tag confirm55b
    # the diagnosis's commands above with --seed 88 (clean) and --seed 89 (second motor), each --tag ending in _b
    .venv/bin/python -m benchmarks.pmu_filter --diagnosis-report --second

The third confirmation (:data:`THIRD`, stop 56), after V and θ each read their own noise and the diagnosis P's and Q's
at their own incoherent levels; the same rules on fresh seeds, fixed before the runs, with the ``5hz`` shape through
the diagnosis too:

    .venv/bin/python -m benchmarks.pmu_filter --n 300 --seed 90 --tag confirm56
    for c in 1e-3 3e-4; do
      .venv/bin/python -m benchmarks.diagnosis_rates --seed 91 --n 20 --rates 25 50 100 --levels 2 3 --pmu white:$c --tag pmu_white_${c}_c
      for s in fs5 5hz; do
        .venv/bin/python -m benchmarks.diagnosis_rates --seed 91 --n 20 --rates 25 50 100 --levels 2 3 --pmu $s:$c --tag pmu_${s}_${c}_c
        .venv/bin/python -m benchmarks.diagnosis_rates --seed 91 --n 20 --rates 25 50 100 --levels 2 3 --pmu $s:$c \
            --config input_noise=measured --tag pmu_${s}_measured_${c}_c; done; done
    for pmu in white:3e-4 fs5:3e-4 5hz:3e-4; do .venv/bin/python -m benchmarks.diagnosis_rates --seed 92 --n 15 \
          --rates 50 100 --levels 2 3 --effect second_motor --pmu $pmu --tag pmu_${pmu%%:*}_second_motor_c \
          $([ ${pmu%%:*} = white ] || echo --config input_noise=measured); done
    .venv/bin/python -m benchmarks.pmu_filter --diagnosis-report --third

The fourth (:data:`FOURTH`), of the diagnosis after it went back to the identifier's raises for P and Q: the third's
diagnosis commands with ``--seed 93`` (clean) and ``--seed 94`` (power), tags ending in ``_d``, then
``--diagnosis-report --fourth``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from functools import lru_cache  # noqa: E402

import numpy as np  # noqa: E402
from scipy import signal  # noqa: E402

from aslm_core import IdentifyConfig, Window, WindowError, identify, preprocess  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.input_noise import INPUT_NOISE  # noqa: E402

#: Oversampling of the noise before the reporting filter [-].
UP = 8
#: The noise shapes: None (white at the reporting rate) or the filter's passband edge as a function of the rate [Hz].
SHAPES = {"white": None, "fs5": lambda fs: fs / 5.0, "5hz": lambda fs: 5.0}
#: The configurations compared.
CONFIGS = {"auto": IdentifyConfig(), "measured": IdentifyConfig(input_noise="measured")}
#: Passband ripple and stopband gain the designs meet [-].
RIPPLE, STOP = 0.01, 0.01
#: The diagnosis on an M-class PMU (stop 55), fixed before its runs on seeds 84 and 85 (commands in the docstring).
DIAGNOSIS_RULE = ("(1) on model-true windows (seed 84, 120 a class), the verdicts other than 'consistent' with the fs5 "
                  "filter and input_noise='measured' at most the white PMU's (default) + 3, per class; (2) a concealed "
                  "second motor (seed 85, 60 windows at 0.03 %) named with fs5 and 'measured' in at least the white "
                  "PMU's count - 6")
#: Stop 55's second confirmation: the seeds of the identifier's rule, the diagnosis's clean and power runs, and the
#: tags' suffix.
SECOND = {"identify": 87, "clean": 88, "power": 89, "suffix": "_b"}
#: Stop 56's confirmation, after each input's noise was read at its own incoherent level and the diagnosis's P and Q
#: floors at theirs (the false findings of :data:`SECOND`'s clean run at 0.1 %): :data:`RULE` on seed 90,
#: :data:`DIAGNOSIS_RULE` on seeds 91 (clean) and 92 (power) for each reporting-filter shape, the ``5hz`` one's
#: clean and power runs judged as the ``fs5`` one's, and ``benchmarks.andes_rates.PMU_CHECK`` on ANDES's fresh ambient
#: seeds ``benchmarks.andes_rates.PMU_CHECK_THIRD_SEEDS``; fixed before the runs.
THIRD = {"identify": 90, "clean": 91, "power": 92, "suffix": "_c", "shapes": ("fs5", "5hz")}
#: Stop 56's fourth confirmation, of the diagnosis only, after it went back to the identifier's raises for P's and Q's
#: floors (their own incoherent levels hid a speed-dependent torque on ANDES's records): :data:`DIAGNOSIS_RULE` on
#: seeds 93 (clean) and 94 (power), both shapes; fixed before the runs.  The identifier is unchanged since THIRD.
FOURTH = {"clean": 93, "power": 94, "suffix": "_d", "shapes": ("fs5", "5hz")}
#: Issue 11's bias targets per PMU class (|μ − 1| at most).
BIAS_TARGET = {"0.03 % / 3e-4 rad": 0.01, "0.1 % / 1e-3 rad": 0.02}
#: Stop 55's confirmation (seed 81, 300 windows a cell, DL 2–3, the six rates), fixed before its run: on the M-class
#: rows, ``measured`` does on a filtered PMU what the default does on a white one.
RULE = ("over the M-class rows (fs5, 5hz) with input_noise='measured', DL 2-3, every rate and class: (1) no cell x "
        "parameter whose 95 % interval of the bias lies wholly outside issue 11's target, and the share with the point "
        "estimate outside at most the white rows' (default) share + 3 points; (2) sigma over the white rows' sigma in "
        "the same cell: median at most 1.10; (3) coverage of +-1.96 SE inside 88-97 % in at least 90 % of the cells x "
        "parameters; (4) on the white rows, 'measured' gives the default's answers (every cell's statistics equal)")


@lru_cache(maxsize=64)
def reporting_filter(fs: float, passband_hz: float) -> np.ndarray:
    """A linear-phase FIR low-pass at ``UP`` × fs: flat within :data:`RIPPLE` up to ``passband_hz``, at most
    :data:`STOP` from fs/2 [Hz]; the shortest odd length (in steps of 2·UP) that meets both."""
    taps = 4 * UP + 1
    while True:
        h = signal.remez(taps, [0.0, passband_hz, fs / 2.0, UP * fs / 2.0], [1.0, 0.0], weight=[1.0, 10.0],
                         fs=UP * fs)
        w, resp = signal.freqz(h, worN=8192, fs=UP * fs)
        amp = np.abs(resp)
        if amp[w >= fs / 2.0].max() <= STOP and np.abs(amp[w <= passband_hz] - 1.0).max() <= RIPPLE:
            return h
        taps += 2 * UP
        if taps > 4001:
            raise RuntimeError(f"no filter of ≤ 4001 taps meets the specification at {fs} frames/s")


def filtered_noise(n: int, std: float, fs: float, shape: str, rng: np.random.Generator) -> np.ndarray:
    """n reported samples of noise whose density below the passband is white noise's of ``std`` at fs: white itself
    for ``shape`` "white", else through :func:`reporting_filter` (module docstring)."""
    edge = SHAPES[shape]
    if edge is None:
        return std * rng.standard_normal(n)
    h = reporting_filter(fs, edge(fs))
    e = std * np.sqrt(UP) * rng.standard_normal(n * UP + h.size - 1)
    return np.convolve(e, h, mode="valid")[::UP][:n]


def noisy_window(case, fs: float, v_rel: float, th: float, shape: str, rng: np.random.Generator) -> Window:
    """The case's clean record with noise of ``shape`` on all four channels: V and θ at the class, P and Q at the
    std of the generator's own white noise in this window."""
    c, w = case.clean, case.window
    n = c.V.size
    sp, sq = float(np.std(w.P - c.P)), float(np.std(w.Q - c.Q))
    return Window(t=w.t, V=c.V + filtered_noise(n, v_rel * float(np.mean(c.V)), fs, shape, rng),
                  theta=c.theta + filtered_noise(n, th, fs, shape, rng),
                  P=c.P + filtered_noise(n, sp, fs, shape, rng), Q=c.Q + filtered_noise(n, sq, fs, shape, rng),
                  f0=w.f0, bus=w.bus, meta=w.meta)


def _job(args) -> list[dict]:
    """Every class, shape and configuration on one case: rows of (class, shape, config, answer)."""
    i, case, fs, level, seed = args
    rows = []
    for k, (cls, v_rel, th) in enumerate(INPUT_NOISE):
        if cls == "none":
            continue
        for j, shape in enumerate(SHAPES):
            w = noisy_window(case, fs, v_rel, th, shape, np.random.default_rng([seed, level, i, k, j]))
            floors = preprocess.prepare(w, floors=True).noise
            exact = not preprocess.white_floor(floors, "v")
            for name, config in CONFIGS.items():
                row = {"class": cls, "shape": shape, "config": name, "exact_by_floor": exact}
                try:
                    r = identify(w, config=config)
                except WindowError as exc:
                    rows.append({**row, "error": exc.reason})
                    continue
                row.update(d=(r.d / case.truth.d).tolist(),
                           cover=[bool(abs(r.dynamic[p] - case.truth.dynamic[p]) < 1.96 * r.stderr[p])
                                  for p in common.PARAMS],
                           noise_v=r.quality["noise_v"] / (v_rel * float(np.mean(case.clean.V))),
                           flags=r.flags)
                rows.append(row)
    return rows


def summary(rows: list[dict]) -> dict:
    """Per (class, shape, config): n, μ − 1, σ, coverage, median noise estimate / in-band, the share taken as exact by
    the floor test and the share of answers with a warning flag."""
    out: dict[str, dict] = {}
    keys = sorted({(r["class"], r["shape"], r["config"]) for r in rows})
    for key in keys:
        sel = [r for r in rows if (r["class"], r["shape"], r["config"]) == key and "d" in r]
        d = np.array([r["d"] for r in sel])
        out["|".join(key)] = {
            "n": len(sel), "bias": (d.mean(axis=0) - 1.0).tolist(), "sigma": d.std(axis=0, ddof=1).tolist(),
            "coverage_95": np.mean([r["cover"] for r in sel], axis=0).tolist(),
            "noise_v_over_inband": float(np.median([r["noise_v"] for r in sel])),
            "exact_by_floor": float(np.mean([r["exact_by_floor"] for r in sel])),
            "flagged": float(np.mean([any(f.startswith(("error_may", "iv_error_may", "input_noise_too_large"))
                                          for f in r["flags"]) for r in sel])),
            "filtered_flag": float(np.mean(["input_noise_filtered" in r["flags"] for r in sel])),
        }
    return out


def verdict(cells_by_rate: dict[str, dict]) -> dict:
    """:data:`RULE` on :func:`main`'s ``cells``: each criterion's figures and whether it is met."""
    outside = missed = n_m = cov_ok = white_out = n_w = 0
    ratios, white_diff = [], []
    for cells in cells_by_rate.values():
        for key, c in cells.items():
            cls, shape, name = key.split("|")
            b, sig, n = np.array(c["bias"]), np.array(c["sigma"]), c["n"]
            target = BIAS_TARGET[cls]
            if shape == "white":
                if name == "auto":
                    white_out += int((np.abs(b) > target).sum())
                    n_w += b.size
                else:
                    white_diff.append(c != cells[f"{cls}|white|auto"])
                continue
            if name != "measured":
                continue
            n_m += b.size
            outside += int((np.abs(b) > target).sum())
            missed += int((np.abs(b) - 1.96 * sig / np.sqrt(n) > target).sum())
            cov = np.array(c["coverage_95"])
            cov_ok += int(((cov >= 0.88) & (cov <= 0.97)).sum())
            ratios.extend((sig / np.array(cells[f"{cls}|white|auto"]["sigma"])).tolist())
    share, white_share = outside / max(n_m, 1), white_out / max(n_w, 1)
    out = {"rule": RULE, "bias_outside": outside, "bias_missed": missed, "n": n_m, "white_outside": white_out,
           "white_n": n_w, "sigma_ratio_median": float(np.median(ratios)) if ratios else float("nan"),
           "sigma_ratio_max": float(np.max(ratios)) if ratios else float("nan"), "coverage_inside": cov_ok,
           "white_rows_differ": int(sum(white_diff))}
    out["met"] = {"bias": missed == 0 and share <= white_share + 0.03, "sigma": out["sigma_ratio_median"] <= 1.10,
                  "coverage": cov_ok >= 0.9 * n_m, "white_unchanged": out["white_rows_differ"] == 0}
    return out


def diagnosis_verdict(read=common.read_json, seeds: tuple[int, int] = (84, 85), suffix: str = "",
                      shapes: tuple[str, ...] = ("fs5",)) -> dict:
    """:data:`DIAGNOSIS_RULE` on the stored ``diagnosis_rates`` runs of the docstring's commands (``seeds``: the
    clean runs' and the power runs'; ``suffix``: their tags', as :data:`SECOND`'s; ``shapes``: the reporting filters
    judged, each as the rule judges ``fs5``)."""
    def counts(name: str, effect: str | None = None) -> tuple[int, int]:
        cells = read(name)["cells"]
        n = sum(c["n"] for c in cells)
        hit = sum(c["named_effect"] if effect else c["verdicts"].get("consistent", 0) for c in cells)
        return n, hit

    out = {"rule": DIAGNOSIS_RULE, "clean": {}, "met": {}}
    ok = True
    for cls in ("1e-3", "3e-4"):
        tags = [("white", f"pmu_white_{cls}")]
        for shape in shapes:
            tags += [(f"{shape}_auto", f"pmu_{shape}_{cls}"), (f"{shape}_measured", f"pmu_{shape}_measured_{cls}")]
        row = {}
        for key, tag in tags:
            n, consistent = counts(f"diagnosis_rates_seed{seeds[0]}_{tag}{suffix}")
            row[key] = {"n": n, "false_findings": n - consistent}
        out["clean"][cls] = row
        ok &= all(row[f"{s}_measured"]["false_findings"] <= row["white"]["false_findings"] + 3 for s in shapes)
    out["met"]["clean"] = bool(ok)
    nw, hw = counts(f"diagnosis_rates_seed{seeds[1]}_pmu_white_second_motor{suffix}", "second_motor")
    out["power"] = {"white": {"n": nw, "named": hw}}
    ok = True
    for shape in shapes:
        nm, hm = counts(f"diagnosis_rates_seed{seeds[1]}_pmu_{shape}_second_motor{suffix}", "second_motor")
        out["power"][f"{shape}_measured"] = {"n": nm, "named": hm}
        ok &= hm >= hw - 6
    out["met"]["power"] = bool(ok)
    return out


def _print_verdict(v: dict) -> None:
    print(f"rule: {v['rule']}")
    print(f"(1) bias: {v['bias_missed']} missed, {v['bias_outside']} of {v['n']} point estimates outside "
          f"(white rows: {v['white_outside']} of {v['white_n']}): {'met' if v['met']['bias'] else 'not met'}")
    print(f"(2) σ over the white rows': median {v['sigma_ratio_median']:.3f} (max {v['sigma_ratio_max']:.2f}): "
          f"{'met' if v['met']['sigma'] else 'not met'}")
    print(f"(3) coverage inside 88–97 %: {v['coverage_inside']} of {v['n']}: {'met' if v['met']['coverage'] else 'not met'}")
    print(f"(4) white rows differing between the configurations: {v['white_rows_differ']}: "
          f"{'met' if v['met']['white_unchanged'] else 'not met'}")


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rates", type=float, nargs="+", default=[25.0, 30.0, 50.0, 60.0, 100.0, 120.0])
    ap.add_argument("--levels", type=int, nargs="+", default=[2, 3])
    ap.add_argument("--n", type=int, default=100, help="windows per rate and level")
    ap.add_argument("--seed", type=int, default=80)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--tag", default="")
    ap.add_argument("--report", default=None, metavar="NAME", help="judge a stored run by RULE without running")
    ap.add_argument("--diagnosis-report", action="store_true", help="judge the diagnosis's runs by DIAGNOSIS_RULE")
    ap.add_argument("--second", action="store_true", help="with --diagnosis-report: the second confirmation's runs")
    ap.add_argument("--third", action="store_true", help="with --diagnosis-report: the third confirmation's runs")
    ap.add_argument("--fourth", action="store_true", help="with --diagnosis-report: the fourth confirmation's runs")
    args = ap.parse_args(argv)
    if args.diagnosis_report:
        conf = SECOND if args.second else THIRD if args.third else FOURTH if args.fourth else None
        v = (diagnosis_verdict(seeds=(conf["clean"], conf["power"]), suffix=conf["suffix"],
                               shapes=conf.get("shapes", ("fs5",))) if conf else diagnosis_verdict())
        print(f"rule: {v['rule']}")
        for cls, row in v["clean"].items():
            print(f"  {cls}: false findings of {row['white']['n']}: " + ", ".join(
                f"{k.replace('_', ' ')} {r['false_findings']}" for k, r in row.items()))
        print(f"  second motor named of {v['power']['white']['n']}: " + ", ".join(
            f"{k.replace('_', ' ')} {r['named']}" for k, r in v["power"].items()))
        print(f"verdict: clean {'met' if v['met']['clean'] else 'not met'}, power {'met' if v['met']['power'] else 'not met'}")
        return v
    if args.report:
        v = verdict(common.read_json(args.report)["cells"])
        _print_verdict(v)
        return v
    t0 = time.perf_counter()
    out = {"machine": common.machine(), "seed": args.seed, "n": args.n, "up": UP, "cells": {}}
    print("| frames/s | DL | class | noise | config | bias a / b / H2 / Tm [%] | σ a / b / H2 / Tm | cover [%] | "
          "noise V / in-band | taken exact | flagged |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    with ProcessPoolExecutor(args.workers) as ex:
        for fs in args.rates:
            for level in args.levels:
                cases = common.cases(args.n, level=level, seed=args.seed, fs=fs)
                jobs = [(i, c, fs, level, args.seed) for i, c in enumerate(cases)]
                rows = [r for part in ex.map(_job, jobs, chunksize=4) for r in part]
                cells = summary(rows)
                out["cells"][f"{fs:g}|{level}"] = cells
                for key, c in cells.items():
                    cls, shape, name = key.split("|")
                    print(f"| {fs:g} | {level} | {cls} | {shape} | {name} | "
                          + " / ".join(f"{100 * b:+.1f}" for b in c["bias"]) + " | "
                          + " / ".join(f"{s:.3f}" for s in c["sigma"]) + " | "
                          + " / ".join(f"{100 * x:.0f}" for x in c["coverage_95"])
                          + f" | {c['noise_v_over_inband']:.2f} | {100 * c['exact_by_floor']:.0f} % | "
                          f"{100 * c['flagged']:.0f} % |", flush=True)
    out["total_s"] = time.perf_counter() - t0
    out["verdict"] = verdict(out["cells"])
    _print_verdict(out["verdict"])
    common.write_json("pmu_filter" + (f"_{args.tag}" if args.tag else ""), out)
    return out


if __name__ == "__main__":
    main()
