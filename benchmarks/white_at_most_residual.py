"""Stop 58's confirmation: S's white P and Q levels at most what the residual reads inside the fitted band.

With an M-class PMU (``input_noise="measured"``) the refinement's S took P's white noise as its floor band's median
raised by V's passband ratio. At 25 frames/s that band holds the motor's own fast response, and on ANDES's records the
level S used was 4.9 × (0.03 %) and 8.6 × (0.1 %) the noise's std (development seeds 21–22). The weighting then treated
P's fitted bins as noise-dominated: a and b under-covered (88–89 %), H2 over-covered (97–98 %), σ of a was 11–32 %.
Inside the fitted band the residual is the white noise plus the inputs' error propagated through H, so its level bounds
the white part from above (:func:`aslm_core.input_weighting.white_at_most_residual`, docs/numerics.md, "Stop 58").

The rule (:data:`RULE`) was fixed in this file before any run on its seeds. It judges the change against the tree
before it (e0f8808) on the same windows and noise draws (the ``_before`` tags are that tree's runs):

    # ANDES's records, fresh ambient seeds 81-90, an M-class PMU and a white one:
    .venv/bin/python -m benchmarks.andes_rates --seeds 81 82 83 84 85 86 87 88 89 90 --pmu fs5 --input-noise measured \
        --tag cap58_fs5m
    .venv/bin/python -m benchmarks.andes_rates --seeds 81 82 83 84 85 86 87 88 89 90 --pmu white --tag cap58_white
    # the generator, fresh seed 97 at the six rates, and fresh seed 98 with a PMU's filter:
    for fs in 25 30 50 60 100 120; do
      .venv/bin/python -m benchmarks.input_noise_variants --seed 97 --n 300 --fs $fs --variants "" --tag confirm58; done
    .venv/bin/python -m benchmarks.pmu_filter --n 300 --seed 98 --tag confirm58
    .venv/bin/python -m benchmarks.white_at_most_residual --verdict
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks import common
from benchmarks.rates_bias import COVERAGE_TARGET as COVERAGE
from benchmarks.white_level import generator_comparison

#: The fresh ambient seeds of ANDES's records, the generator's fresh seed, and its fresh seed with a PMU's filter.
ANDES_SEEDS = tuple(range(81, 91))
SEED = 97
FILTER_SEED = 98
#: The runs' tags (this tree's; the tree before's end in ``_before``).
ANDES_MEASURED, ANDES_WHITE, TAG = "cap58_fs5m", "cap58_white", "confirm58"
#: The issue's bias target per ANDES class.
CLASS_TARGET = {"pmu003": 0.01, "pmu01": 0.02}
RULE = ("(A) ANDES, ambient seeds 81-90, an M-class PMU (andes_rates --pmu fs5 --input-noise measured), against the "
        "tree before (e0f8808) on the same draws: (A1) the noisy cells (0.03 % and 0.1 %, 25/50/100 frames/s) x "
        "parameters with coverage of +-1.96 SE outside 90-97 % at most the tree before's count - 2 (of 24); (A2) sigma "
        "at most 1.02 x the tree before's in every noisy cell x parameter at 25 frames/s, with the median over those 8 "
        "at most 0.95, and at most 1.03 x at 50 and 100; (A3) every noisy cell x parameter's |bias| within issue 11's "
        "target (0.01 at 0.03 %, 0.02 at 0.1 %) or, where the tree before's is not, at most the tree before's. (B) "
        "ANDES seeds 81-90, a white PMU and the default (--pmu white): (B1) sigma at most 1.02 x the tree before's in "
        "every noisy cell x parameter; (B2) coverage outside 90-97 % at most the tree before's count + 1. (C) the "
        "generator, seed 97, 300 windows a level, six rates (input_noise_variants --variants ''): (C1) coverage outside "
        "90-97 % at most the tree before's count + 2 (of 144); (C2) the median of sigma / the tree before's at most "
        "1.01; (C3) DL 2-3 point estimates outside issue 11's bias targets at most the tree before's count. (D) the "
        "generator with a PMU's filter, seed 98, 300 windows (pmu_filter): (D1) pmu_filter's RULE met; (D2) over the "
        "M-class rows with input_noise='measured', the median of sigma / the tree before's at most 1.01.")


def _andes(tag: str, read) -> dict:
    return {(c["class"], c["fs"]): c for c in read(f"andes_rates_{tag}")["cells"] if c["class"] != "exact"}


def _outside(cells) -> int:
    return sum(not COVERAGE[0] <= x <= COVERAGE[1] for c in cells for x in c)


def andes_verdict(read=common.read_json) -> dict:
    """(A) and (B) of :data:`RULE` on the stored ``andes_rates`` runs."""
    m, mb = _andes(ANDES_MEASURED, read), _andes(ANDES_MEASURED + "_before", read)
    w, wb = _andes(ANDES_WHITE, read), _andes(ANDES_WHITE + "_before", read)
    cells, at25 = [], []
    a2 = a3 = True
    for key in sorted(m):
        cls, fs = key
        n, o = m[key], mb[key]
        ratio = np.array(n["sigma"]) / np.array(o["sigma"])
        a2 &= bool(np.all(ratio <= (1.02 if fs == 25.0 else 1.03)))
        if fs == 25.0:
            at25 += ratio.tolist()
        t = CLASS_TARGET[cls]
        a3 &= all(abs(b) <= max(t, abs(a)) for b, a in zip(n["bias"], o["bias"], strict=True))
        cells.append({"class": cls, "fs": fs, "cover": n["cover"], "cover_before": o["cover"],
                      "sigma_ratio": ratio.tolist(), "bias": n["bias"], "bias_before": o["bias"]})
    a2 &= float(np.median(at25)) <= 0.95
    outside = (_outside(c["cover"] for c in m.values()), _outside(c["cover"] for c in mb.values()))
    white_ratio = np.array([np.array(w[k]["sigma"]) / np.array(wb[k]["sigma"]) for k in w]).ravel()
    white_outside = (_outside(c["cover"] for c in w.values()), _outside(c["cover"] for c in wb.values()))
    met = {"A1": outside[0] <= outside[1] - 2, "A2": a2, "A3": a3, "B1": bool(np.all(white_ratio <= 1.02)),
           "B2": white_outside[0] <= white_outside[1] + 1}
    return {"cells": cells, "outside": outside, "sigma_ratio_median_25": float(np.median(at25)),
            "white_outside": white_outside, "white_sigma_ratio_range": [float(white_ratio.min()), float(white_ratio.max())],
            "met": met}


def generator_verdict(read=common.read_json) -> dict:
    """(C) of :data:`RULE` on the stored ``input_noise_variants`` runs."""
    out = generator_comparison(TAG, TAG + "_before", SEED, read)
    del out["cells"]  # the runs' own JSONs hold them
    outside, off = out["coverage_outside"], out["bias_off_target"]
    out["met"] = {"C1": outside[0] <= outside[1] + 2, "C2": out["sigma_ratio_median"] <= 1.01, "C3": off[0] <= off[1]}
    return out


def filter_verdict(read=common.read_json) -> dict:
    """(D) of :data:`RULE` on the stored ``pmu_filter`` runs."""
    from benchmarks.pmu_filter import verdict

    new, old = read(f"pmu_filter_{TAG}"), read(f"pmu_filter_{TAG}_before")
    ratios = np.array([np.array(new["cells"][rl][k]["sigma"]) / np.array(old["cells"][rl][k]["sigma"])
                       for rl in new["cells"] for k in new["cells"][rl]
                       if k.endswith("|measured") and "|white|" not in k]).ravel()
    rule = all(verdict(new["cells"])["met"].values())
    return {"pmu_filter_rule": rule, "sigma_ratio_median": float(np.median(ratios)),
            "sigma_ratio_range": [float(ratios.min()), float(ratios.max())],
            "met": {"D1": rule, "D2": float(np.median(ratios)) <= 1.01}}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--verdict", action="store_true", help="judge the stored runs by RULE")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    out: dict = {"machine": common.machine(), "rule": RULE}
    if not args.verdict:
        ap.print_help()
        return out
    out["andes"], out["generator"], out["filter"] = andes_verdict(), generator_verdict(), filter_verdict()
    a = out["andes"]
    for c in a["cells"]:
        print(f"ANDES M-class {c['class']} {c['fs']:g} frames/s: cover " + " / ".join(f"{100 * x:.1f}" for x in c["cover"])
              + " (before " + " / ".join(f"{100 * x:.1f}" for x in c["cover_before"]) + "); sigma / before "
              + " / ".join(f"{x:.3f}" for x in c["sigma_ratio"]) + "; bias " + " / ".join(f"{100 * x:+.1f}" for x in c["bias"])
              + " (before " + " / ".join(f"{100 * x:+.1f}" for x in c["bias_before"]) + ")")
    print(f"ANDES M-class: coverage outside 90-97 % {a['outside'][0]} (before {a['outside'][1]}); sigma / before at 25 "
          f"frames/s median {a['sigma_ratio_median_25']:.3f}. White PMU: outside {a['white_outside'][0]} (before "
          f"{a['white_outside'][1]}), sigma / before {a['white_sigma_ratio_range'][0]:.3f}-{a['white_sigma_ratio_range'][1]:.3f}")
    g, f = out["generator"], out["filter"]
    print(f"generator seed {SEED}: coverage outside {g['coverage_outside'][0]} (before {g['coverage_outside'][1]}); bias "
          f"off target {g['bias_off_target'][0]} (before {g['bias_off_target'][1]}); sigma / before median "
          f"{g['sigma_ratio_median']:.4f}, range {g['sigma_ratio_range'][0]:.3f}-{g['sigma_ratio_range'][1]:.3f}")
    print(f"generator with a PMU's filter, seed {FILTER_SEED}: pmu_filter's rule {'met' if f['pmu_filter_rule'] else 'not met'}; "
          f"M-class measured sigma / before median {f['sigma_ratio_median']:.4f}, range {f['sigma_ratio_range'][0]:.3f}-"
          f"{f['sigma_ratio_range'][1]:.3f}")
    met = {**a["met"], **g["met"], **f["met"]}
    print("criteria: " + ", ".join(f"{k} {'met' if v else 'NOT met'}" for k, v in met.items()))
    out["met"] = all(met.values())
    print(f"verdict: {'met' if out['met'] else 'not met'}")
    if not args.no_write:
        common.write_json("white_at_most_residual_verdict", out)
    return out


if __name__ == "__main__":
    main()
