"""Coverage of ±1.96 SE on the own-fluctuation bench, read from its per-window records (no identification).

Per row (own ratio, shape, V/θ noise): which path answered (``ar_iv`` through the gate, the S-weighted fit,
output error), coverage per parameter and whether it is inside the 90–97 % target, the z = error/SE statistics
(std, robust std 1.4826·MAD, median, excess kurtosis) per path; over the IV windows, coverage by
``iv_overid`` (Hansen's J / dof); with ``--before``, that D is bit for bit the same in two runs of the same
windows and how the standard errors changed.  Also the chance that a cell of n windows whose intervals cover
exactly 95 % lands inside the target (binomial), which says how many cells miss by chance alone; with
``--unscaled``, the coverage the IV's standard errors had before the reduced-χ² scaling (undone from the
recorded ``iv_overid``: D is the same); with ``--scaled``, the scaling applied to records made before it.

``--check-d SEED`` identifies instead: the bench's own-fluctuation windows of that seed, one thread, the default
with and without the scaling (``instrumental.OVERID_EXPECTED`` = ∞) on each window in turn, and checks that D is
bit for bit the same (two runs of the bench in a thread pool differ by up to ~1e-6 from run to run, so records
of two runs cannot show it).

    .venv/bin/python -m benchmarks.own_cover docs/results/own_fluctuation_cover_dev_after.json
        [--before docs/results/own_fluctuation_cover_dev.json] [--unscaled] [--candidate NAME]
    .venv/bin/python -m benchmarks.own_cover --check-d 43 [--n 50]
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
from scipy.stats import binom, kurtosis

from aslm_core import IdentifyConfig, WindowError, identify, instrumental
from aslm_core.identify import IV_SE_MAX
from benchmarks import common
from benchmarks.own_gate import WARNING_FLAGS

DEFAULT = "gated, spectral weighting"
TARGET = (0.90, 0.97)
OVERID_BINS = (0.0, 1.0, 1.5, 2.0, 3.0 + 1e-9)


def path_of(quality: dict) -> str:
    """Which estimate the gated default returned on a window: ``iv``, ``weighted`` or ``oe``."""
    if quality.get("gated_ar_iv") == 1.0:
        return "iv"
    chi2 = quality.get("weighted_chi2")
    return "weighted" if chi2 is not None and not math.isnan(chi2) else "oe"


def chance_in_target(n: int, p: float = 0.95) -> float:
    """Probability that a cell of n windows whose intervals cover exactly p shows a coverage in the target."""
    lo, hi = math.ceil(TARGET[0] * n - 1e-9), math.floor(TARGET[1] * n + 1e-9)
    return float(binom.cdf(hi, n, p) - binom.cdf(lo - 1, n, p))


def z_stats(z: np.ndarray) -> dict:
    """Coverage and the shape of z = error/SE per parameter."""
    return {"n": int(len(z)), "coverage": np.mean(np.abs(z) <= 1.96, axis=0).tolist(), "std": z.std(axis=0).tolist(),
            "robust_std": (1.4826 * np.median(np.abs(z - np.median(z, axis=0)), axis=0)).tolist(),
            "median": np.median(z, axis=0).tolist(), "kurtosis": kurtosis(z, axis=0).tolist()}


def windows(run: dict, name: str, iv_se: str = "recorded") -> list[tuple]:
    """(z, path, iv_overid, flags, |error|) per identified window of a run; ``iv_se``: the IV's standard errors as
    recorded, ``unscaled`` (the reduced-χ² scaling undone) or ``scaled`` (applied to records made before it)."""
    out = []
    for e, s, q, f in zip(run["errors"][name], run["stderr"][name], run["quality"][name], run["flags"][name],
                          strict=True):
        if e is not None:
            se = np.array(s)
            if iv_se != "recorded" and path_of(q) == "iv":
                k = math.sqrt(instrumental.covariance_scale(q["iv_overid"]))
                se = se / k if iv_se == "unscaled" else se * k
            out.append((np.array(e) / se, path_of(q), q.get("iv_overid", math.nan), f, np.abs(e)))
    return out


def report(recorded: dict, name: str = DEFAULT, before: dict | None = None, iv_se: str = "recorded") -> dict:
    """The diagnosis of the module docstring as a dict (and printed)."""
    rows, table, iv_all = [], [], []
    met = cells = 0
    for k, run in enumerate(recorded["runs"]):
        ws = windows(run, name, iv_se)
        z = np.array([w[0] for w in ws])
        paths = [w[1] for w in ws]
        st = z_stats(z)
        inside = [TARGET[0] <= c <= TARGET[1] + 1e-9 for c in st["coverage"]]
        if run["ratio"] > 0:
            met += sum(inside)
            cells += 4
        unflagged = sum(bool(w[4].max() > 0.2) and not any(f.startswith(WARNING_FLAGS) for f in w[3]) for w in ws)
        per_path = {p: z_stats(np.array([w[0] for w in ws if w[1] == p])) for p in ("iv", "weighted", "oe")
                    if paths.count(p)}
        iv_all += [w for w in ws if w[1] == "iv"]
        row = {"ratio": run["ratio"], "shape": run["shape"], "input_noise": run.get("input_noise", "none"), **st,
               "inside_target": [bool(v) for v in inside], "paths": {p: paths.count(p) for p in per_path}, "per_path": per_path,
               "off_20pct_unflagged": unflagged}
        if before is not None:
            row["se_change"] = _se_change(before["runs"][k], run, name)
        rows.append(row)
        table.append([f"{run['ratio']:g}", f"{run['shape']}, {run.get('input_noise', 'none')}",
                      " / ".join(str(paths.count(p)) for p in ("iv", "weighted", "oe")),
                      " / ".join(f"{100 * c:.0f}" + ("" if ok else "✗") for c, ok in zip(st["coverage"], inside,
                                                                                          strict=True)),
                      " / ".join(f"{v:.2f}" for v in st["robust_std"]), " / ".join(f"{v:+.2f}" for v in st["median"]),
                      " / ".join(f"{v:.1f}" for v in st["kurtosis"]), str(unflagged)]
                     + ([row["se_change"]["summary"]] if before is not None else []))
    head = ["own/total", "shape, V/θ noise", "IV / weighted / OE", "cover a / b / H2 / Tm [%] (✗ outside 90–97)",
            "robust std of z", "median z", "excess kurtosis of z", "off > 20 % unflagged"]
    print(common.md_table(head + (["D as before; SE new/old p10–p90"] if before is not None else []), table))
    n = len(recorded["runs"][0]["errors"][name])
    print(f"\nown-fluctuation cells inside 90–97 %: {met} of {cells}; a cell of {n} windows covering exactly 95 % "
          f"lands inside with probability {chance_in_target(n):.2f} (expected {chance_in_target(n) * cells:.0f} "
          f"of {cells})")
    by_overid = []
    for lo, hi in zip(OVERID_BINS[:-1], OVERID_BINS[1:], strict=True):
        sel = [w for w in iv_all if lo <= w[2] < hi]
        if sel:
            by_overid.append({"overid": [lo, hi], **z_stats(np.array([w[0] for w in sel]))})
            print(f"IV windows with iv_overid in [{lo:g}, {hi:.3g}): n = {len(sel)}, cover "
                  + " / ".join(f"{100 * c:.0f}" for c in by_overid[-1]["coverage"]) + ", robust std of z "
                  + " / ".join(f"{v:.2f}" for v in by_overid[-1]["robust_std"]))
    own = [w for r in recorded["runs"] if r["ratio"] > 0 for w in windows(r, name, iv_se)]
    pooled = {p: z_stats(np.vstack([w[0] for w in own if w[1] == p])) for p in ("iv", "weighted", "oe")
              if any(w[1] == p for w in own)}
    for p, st in pooled.items():
        print(f"pooled over own-fluctuation rows, path {p}: n = {st['n']}, cover "
              + " / ".join(f"{100 * c:.1f}" for c in st["coverage"]))
    wide = _iv_flag_counts(recorded, name, iv_se)
    print(f"IV answers within 20 % whose SE exceeds {IV_SE_MAX:g} of D (iv_error_may_exceed_20pct): "
          f"{wide['within_flagged']} of {wide['within']}; off by more than 20 %: {wide['off_flagged']} of {wide['off']}")
    return {"rows": rows, "cells_inside": met, "cells": cells, "chance_in_target": chance_in_target(n),
            "by_overid": by_overid, "pooled": pooled, "iv_flag": wide}


def _iv_flag_counts(recorded: dict, name: str, iv_se: str) -> dict:
    """IV answers within / off by more than 20 %, and of them those whose standard errors (as ``iv_se`` says)
    raise ``iv_error_may_exceed_20pct`` (some SE above ``IV_SE_MAX`` of the estimate)."""
    out = {"within": 0, "within_flagged": 0, "off": 0, "off_flagged": 0}
    for run in recorded["runs"]:
        for e, s, q in zip(run["errors"][name], run["stderr"][name], run["quality"][name], strict=True):
            if e is None or path_of(q) != "iv":
                continue
            k = math.sqrt(instrumental.covariance_scale(q["iv_overid"]))
            se = np.array(s) * {"recorded": 1.0, "unscaled": 1.0 / k, "scaled": k}[iv_se]
            flagged = bool(np.any(se > IV_SE_MAX * np.abs(1.0 + np.array(e))))
            key = "off" if np.max(np.abs(e)) > 0.2 else "within"
            out[key] += 1
            out[key + "_flagged"] += int(flagged)
    return out


def _se_change(old: dict, new: dict, name: str) -> dict:
    """Whether D is bit for bit the same in two runs of a row (errors equal), and the ratio new/old of the SEs."""
    same = old["errors"][name] == new["errors"][name]
    ratios = np.array([np.array(s1) / np.array(s0) for s0, s1 in zip(old["stderr"][name], new["stderr"][name],
                                                                      strict=True) if s0 is not None])
    lo, hi = np.percentile(ratios, [10, 90])
    return {"d_same": bool(same), "se_ratio_p10": float(lo), "se_ratio_p90": float(hi),
            "summary": ("yes" if same else "NO") + f"; {lo:.2f}–{hi:.2f}"}


def check_d(seed: int, n: int) -> dict:
    """Identify the bench's own-fluctuation windows of ``seed`` with and without the scaling; D bit for bit?"""
    from aslm_sim.cases import make_cases
    from benchmarks.input_noise import INPUT_NOISE, with_input_noise
    from benchmarks.own_fluctuation import LEVEL, RATIOS, own_cases

    config = IdentifyConfig()
    base = make_cases(n, level=LEVEL, seed=seed, input_noise=False)
    keep = instrumental.OVERID_EXPECTED
    rows, differ, ratios = [], 0, []
    for shape in ("lowpass", "switching", "pink"):
        for ratio in RATIOS[1:]:
            cs = own_cases(n, ratio, shape, base, seed)
            for k, (cls, v_rel, th) in enumerate(INPUT_NOISE if shape == "lowpass" else INPUT_NOISE[:1]):
                rng = np.random.default_rng([seed, int(100 * ratio), k])
                same = iv = 0
                for c in cs:
                    w = with_input_noise(c.window, c.clean, v_rel, th, rng)
                    out = []
                    for scale in (math.inf, keep):
                        instrumental.OVERID_EXPECTED = scale
                        try:
                            out.append(identify(w, config=config))
                        except WindowError:
                            out.append(None)
                    instrumental.OVERID_EXPECTED = keep
                    if out[0] is None or out[1] is None:
                        same += out[0] is out[1]
                        continue
                    same += bool(np.array_equal(out[0].d, out[1].d))
                    if out[1].quality.get("gated_ar_iv") == 1.0:
                        iv += 1
                        ratios.append([out[1].stderr[p] / out[0].stderr[p] for p in common.PARAMS])
                differ += len(cs) - same
                rows.append({"ratio": ratio, "shape": shape, "input_noise": cls, "windows": len(cs), "d_same": same,
                             "iv": iv})
                print(f"{ratio:g} {shape}, {cls}: D bit for bit the same on {same} of {len(cs)} ({iv} IV)", flush=True)
    r = np.array(ratios)
    print(f"windows where D differs: {differ}; IV SE new/old p10 / p50 / p90: "
          + ", ".join(" / ".join(f"{v:.2f}" for v in np.percentile(r[:, i], [10, 50, 90]))
                      for i in range(4)))
    return {"seed": seed, "n": n, "rows": rows, "windows_d_differs": differ,
            "iv_se_ratio_percentiles_10_50_90": np.percentile(r, [10, 50, 90], axis=0).tolist()}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("records", nargs="?", help="JSON of benchmarks.own_fluctuation with per-window records")
    ap.add_argument("--before", default=None, help="the same windows' records before a change of the SEs")
    ap.add_argument("--unscaled", action="store_true", help="the IV's SEs before the reduced-χ² scaling")
    ap.add_argument("--scaled", action="store_true", help="the scaling applied to records made before it")
    ap.add_argument("--candidate", default=DEFAULT)
    ap.add_argument("--check-d", type=int, default=None, metavar="SEED", help="identify: D with and without scaling")
    ap.add_argument("--n", type=int, default=50, help="windows per row with --check-d")
    ap.add_argument("--json", default=None, help="write the diagnosis here")
    args = ap.parse_args(argv)
    if args.check_d is not None:
        out = check_d(args.check_d, args.n)
    else:
        with open(args.records) as fh:
            recorded = json.load(fh)
        before = None
        if args.before:
            with open(args.before) as fh:
                before = json.load(fh)
        iv_se = "unscaled" if args.unscaled else ("scaled" if args.scaled else "recorded")
        out = report(recorded, args.candidate, before, iv_se)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1, default=lambda v: v.item() if hasattr(v, "item") else str(v))
    return out


if __name__ == "__main__":
    main()
