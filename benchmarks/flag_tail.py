"""Windows off by more than 20 % without a warning flag, and the price of the flags, from benches' records.

Reads the per-window records (errors, standard errors, flags, quality) of ``benchmarks.own_fluctuation`` and of
``benchmarks.input_noise --rates`` (no identification) and prints, for the default candidate:

* every window off by more than 20 % that carries none of :data:`benchmarks.own_gate.WARNING_FLAGS`, with the
  path that answered (IV through the gate, S-weighted refinement, output error), its errors, standard errors
  and z = error/SE, and its indicators (input ratio, own ratio, excitation share, ``iv_overid``,
  ``weighted_shift_z``, ``halves_z``);
* per path and in all: answers off by more than 20 % (of them unflagged without and with stop 28's flags), answers
  within 10 %, and of those the share with a warning flag (the price) without and with stop 28's flags, with
  each of those flags (and by it alone);
* with ``--before``: the same windows' D in another run of the same seed, to check that it did not move (for
  rates runs recorded without per-window records: their μ, σ, coverage and median |error| per cell).

    .venv/bin/python -m benchmarks.flag_tail docs/results/own_fluctuation_flags.json [...]
        [--before docs/results/own_fluctuation_cover_dev_after.json] [--cells] [--json NAME]
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from benchmarks import common
from benchmarks.own_cover import path_of
from benchmarks.own_gate import WARNING_FLAGS

DEFAULTS = ("gated, spectral weighting", "default")
#: The flags of stop 28 (docs/numerics.md, "Flags that catch the tail").
NEW_FLAGS = ("input_noise_correction_large", "error_may_exceed_20pct", "halves_disagree")
INDICATORS = ("input_ratio_v", "own_ratio_p", "excitation_share_p", "iv_overid", "weighted_shift_z", "halves_z")


def cells(recorded: dict) -> list[tuple[str, dict]]:
    """(label, records) per cell of an own-fluctuation run (``runs``) or a rates run (``rates``)."""
    out = []
    for run in recorded.get("runs", []):
        name = next(k for k in DEFAULTS if k in run["errors"])
        out.append((f"{run['ratio']:g} {run['shape']}, {run['input_noise']}",
                    {k: run[k][name] for k in ("errors", "stderr", "flags", "quality")}))
    for fs, per in recorded.get("rates", {}).items():
        for cls, by in per.items():
            name = next(k for k in DEFAULTS if k in by)
            if "records" in by[name]:
                out.append((f"{fs} frames/s, {cls}", by[name]["records"]))
    return out


def warned(flags: list[str], ignore: tuple[str, ...] = ()) -> bool:
    """A warning flag among ``flags`` (those starting with one of ``ignore`` not counted)."""
    return any(f.startswith(WARNING_FLAGS) and not f.startswith(ignore) for f in flags)


def tally(recorded: dict) -> dict:
    """The unflagged misses and the counts per path of the module docstring."""
    misses, counts = [], {}
    for label, rec in cells(recorded):
        for i, (e, s, f, q) in enumerate(zip(rec["errors"], rec["stderr"], rec["flags"], rec["quality"],
                                             strict=True)):
            if e is None:
                continue
            e, s = np.array(e), np.array(s)
            worst, path = float(np.abs(e).max()), path_of(q)
            c = counts.setdefault(path, {"n": 0, "off": 0, "off_unflagged": 0, "off_unflagged_before": 0,
                                         "within10": 0, "within10_warned": 0, "within10_warned_before": 0, **{f"within10_{k}": 0 for k in NEW_FLAGS},
                                         **{f"within10_only_{k}": 0 for k in NEW_FLAGS},
                                         **{f"off_caught_{k}": 0 for k in NEW_FLAGS}})
            c["n"] += 1
            if worst > 0.2:
                c["off"] += 1
                c["off_unflagged_before"] += not warned(f, NEW_FLAGS)
                for k in NEW_FLAGS:
                    c[f"off_caught_{k}"] += k in f and not warned(f, NEW_FLAGS)
                if not warned(f):
                    c["off_unflagged"] += 1
                    misses.append({"cell": label, "window": i, "path": path, "error": e.tolist(), "se": s.tolist(),
                                   "z": (e / s).tolist(), "flags": f,
                                   **{k: q.get(k) for k in INDICATORS if q.get(k) is not None}})
            elif worst <= 0.1:
                c["within10"] += 1
                c["within10_warned"] += warned(f)
                c["within10_warned_before"] += warned(f, NEW_FLAGS)
                for k in NEW_FLAGS:
                    c[f"within10_{k}"] += k in f
                    c[f"within10_only_{k}"] += k in f and not warned(f, (k,))
    total = {k: sum(c[k] for c in counts.values()) for k in next(iter(counts.values()))} if counts else {}
    return {"misses": misses, "paths": counts, "all": total}


def cell_rows(recorded: dict) -> list[list]:
    """Per cell: answers, off by more than 20 % (unflagged before / now), within 10 % and of them warned before /
    now."""
    out = []
    for label, rec in cells(recorded):
        ok = [(np.abs(np.array(e)).max(), f) for e, f in zip(rec["errors"], rec["flags"], strict=True) if e is not None]
        off = [f for w, f in ok if w > 0.2]
        good = [f for w, f in ok if w <= 0.1]
        out.append([label, len(ok), f"{len(off)} ({sum(not warned(f, NEW_FLAGS) for f in off)} / "
                    f"{sum(not warned(f) for f in off)})", len(good),
                    f"{sum(warned(f, NEW_FLAGS) for f in good)} / {sum(warned(f) for f in good)}"])
    return out


def same_d(recorded: dict, before: dict) -> dict:
    """Largest |ΔD/D| between two runs of the same windows, and how many differ at all; for rates runs made
    before per-window records, the largest difference of μ, σ and coverage per rate and class instead."""
    if "rates" in before and "records" not in next(iter(next(iter(before["rates"].values())).values()))["default"]:
        keys = ("mu", "sigma", "coverage_95", "median_abs_err")
        diffs = [abs(by["default"][k][p] - before["rates"][fs][cls]["default"][k][p])
                 for fs, per in recorded["rates"].items() for cls, by in per.items() for k in keys
                 for p in common.PARAMS]
        return {"summaries": len(diffs), "differ": sum(d > 0 for d in diffs), "max_abs_diff": max(diffs)}
    worst, differ, n = 0.0, 0, 0
    for (_, a), (_, b) in zip(cells(recorded), cells(before), strict=True):
        for ea, eb in zip(a["errors"], b["errors"], strict=True):
            if ea is None or eb is None:
                continue
            n += 1
            d = float(np.max(np.abs(np.array(ea) - np.array(eb))))
            worst, differ = max(worst, d), differ + (d > 0)
    return {"windows": n, "differ": differ, "max_rel_diff": worst}


def _fmt(v: float) -> str:
    return f"{v:.2f}" if isinstance(v, float) and math.isfinite(v) else str(v)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("records", nargs="+", help="JSON records of own_fluctuation or input_noise --rates runs")
    ap.add_argument("--before", default=None, help="a run of the same windows (one records file): D moved?")
    ap.add_argument("--cells", action="store_true", help="also the counts per cell")
    ap.add_argument("--json", default=None, help="write the report to docs/results/NAME.json")
    args = ap.parse_args(argv)
    out = {}
    for path in args.records:
        with open(path) as fh:
            rep = tally(json.load(fh))
        out[path] = rep
        print(f"\n== {path}")
        for m in rep["misses"]:
            print(f"  UNFLAGGED {m['cell']} #{m['window']} ({m['path']}): error "
                  + " / ".join(f"{100 * x:+.1f}" for x in m["error"]) + " %, z "
                  + " / ".join(f"{x:+.1f}" for x in m["z"]) + ", "
                  + ", ".join(f"{k} {_fmt(m[k])}" for k in INDICATORS if k in m) + f", flags {m['flags']}")
        head = ["path", "answers", "off > 20 %", "unflagged: before / now", "within 10 %",
                "of them warned: before / now"] + [f"with {k} (alone)" for k in NEW_FLAGS] + [
                "unflagged before, caught by " + " / ".join(NEW_FLAGS)]
        body = [[p, c["n"], c["off"], f"{c['off_unflagged_before']} / {c['off_unflagged']}", c["within10"],
                 f"{c['within10_warned_before']} / {c['within10_warned']} "
                 f"({100 * c['within10_warned_before'] / max(c['within10'], 1):.0f} / "
                 f"{100 * c['within10_warned'] / max(c['within10'], 1):.0f} %)"]
                + [f"{c[f'within10_{k}']} ({c[f'within10_only_{k}']})" for k in NEW_FLAGS]
                + [" / ".join(str(c[f"off_caught_{k}"]) for k in NEW_FLAGS)]
                for p, c in [*rep["paths"].items(), ("all", rep["all"])]]
        print(common.md_table(head, body))
        if args.cells:
            print(common.md_table(["cell", "answers", "off > 20 % (unflagged before / now)", "within 10 %",
                                   "of them warned before / now"], cell_rows(json.load(open(path)))))
    if args.before:
        with open(args.before) as fh:
            before = json.load(fh)
        with open(args.records[0]) as fh:
            out["same_d"] = same_d(json.load(fh), before)
        print(f"\nD against {args.before}: {out['same_d']}")
    if args.json:
        common.write_json(args.json, out)
    return out


if __name__ == "__main__":
    main()
