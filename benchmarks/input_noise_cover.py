"""Issue 11's coverage target read from runs of :mod:`benchmarks.input_noise`, with intervals (no identification).

Per cell (reporting rate or disturbance level, PMU class): coverage of ±1.96 SE per parameter with its Wilson 95 %
interval and the verdict against the 90–97 % target (``met``: the estimate inside; ``open``: outside, its interval
reaching the target; ``missed``), and σ of D_opt/D_real with its bootstrap interval.  A cell of 100 windows decides
the target only to about ±4 points; the confirmation seeds 49 (rates) and 50 (supplement) hold 300 per cell.

    .venv/bin/python -m benchmarks.input_noise_cover input_noise_rates_seed49 [input_noise_supplement_seed50 ...]
    .venv/bin/python -m benchmarks.input_noise_cover --pool input_noise_supplement_seed45 input_noise_supplement_seed50 \
        input_noise_supplement_seed51

``--pool``: the runs' windows counted together per cell (runs of the same kind on different seeds): a cell of 900
windows decides the target to about ±2 points.
"""

from __future__ import annotations

import argparse

from benchmarks import common
from benchmarks.own_targets import verdict, wilson

TARGET = (0.90, 0.97)
HEAD = ["run", "cell", "PMU class", "n", "coverage a / b / H2 / Tm [%] [Wilson 95 %]", "verdicts",
        "σ a / b / H2 / Tm [95 % bootstrap]"]


def cells(run: dict) -> list[tuple[str, str, dict]]:
    """(cell label, PMU class, the default's statistics) of a rates or supplement run."""
    rates = bool(run.get("rates"))
    out = []
    for key, classes in (run["rates"] if rates else run["levels"]).items():
        label = f"{key} frames/s" if rates else f"DL {key}"
        for cls, per in classes.items():
            out.append((label, cls, per["default"]))
    return out


def pooled(runs: list[list[tuple[str, str, dict]]]) -> list[tuple[str, str, dict]]:
    """The cells of several runs with their windows counted together: n summed, coverage the covered windows over
    it; σ the windows' RMS spread about each run's own mean (no bootstrap interval)."""
    out = []
    for parts in zip(*runs, strict=True):
        label, cls = parts[0][0], parts[0][1]
        if any((p[0], p[1]) != (label, cls) for p in parts):
            raise ValueError(f"runs do not share their cells: {[(p[0], p[1]) for p in parts]}")
        n = sum(p[2]["n"] for p in parts)
        cov = {k: sum(round(p[2]["coverage_95"][k] * p[2]["n"]) for p in parts) / n for k in common.PARAMS}
        sig = {k: (sum((p[2]["n"] - 1) * p[2]["sigma"][k] ** 2 for p in parts) / (n - len(parts))) ** 0.5
               for k in common.PARAMS}
        out.append((label, cls, {"n": n, "coverage_95": cov, "sigma": sig}))
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="JSON names under docs/results")
    ap.add_argument("--pool", action="store_true", help="count the runs' windows together per cell")
    args = ap.parse_args(argv)
    rows, summary = [], {}
    groups = ([("+".join(args.runs), pooled([cells(common.read_json(r)) for r in args.runs]))] if args.pool
              else [(r, cells(common.read_json(r))) for r in args.runs])
    for name, run_cells in groups:
        counts = {"met": 0, "open": 0, "missed": 0}
        for label, cls, st in run_cells:
            n, cov = st["n"], st["coverage_95"]  # both over the windows identified (failures apart)
            fig = {p: (cov[p], *wilson(round(cov[p] * n), n)) for p in common.PARAMS}
            verdicts = {p: verdict(*fig[p], TARGET) for p in common.PARAMS}
            if cls != "none":  # the target is under input noise
                for v in verdicts.values():
                    counts[v] += 1
            sig = st["sigma"]
            iv = st.get("intervals", {}).get("sigma", {})
            rows.append([name, label, cls, n, " / ".join(f"{100 * v:.0f} [{100 * lo:.0f}, {100 * hi:.0f}]"
                                                         for v, lo, hi in fig.values()),
                         " / ".join(verdicts.values()),
                         " / ".join(f"{sig[p]:.3f}" + (f" [{iv[p][0]:.3f}, {iv[p][1]:.3f}]" if p in iv else "")
                                    for p in common.PARAMS)])
        summary[name] = counts
    print(common.md_table(HEAD, rows))
    for name, counts in summary.items():
        print(f"{name}: noisy cells × parameters {counts}")
    return summary


if __name__ == "__main__":
    main()
