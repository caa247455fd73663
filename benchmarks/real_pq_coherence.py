"""How much of a real recording's P fluctuation moves its Q: the P–Q correlation of the Shelby line flows.

The identifier's AR and IV fits take Q − k·P as their second channel (docs/numerics.md, "P and Q together"): it
removes the part of the own fluctuation that moves P and Q together, so what it gains depends on that correlation.
The one real recording here (``../shared/data/real/tva-shelby-2007-ieee1344.PmuCapture``, IEEE 1344, 2007, a 500 kV
substation, 33 s at 30 frames/s) has line flows, not a load bus; per line: the flow's mean P and Q [MW, Mvar], the
standard deviations of their fluctuations (a straight line over the recording removed), their correlation over
all samples and after a 1 s moving average (the band where a load's own switching lives), and k as
:func:`aslm_core.disturbance.coupling` reads it.

    .venv/bin/python -m benchmarks.real_pq_coherence [--out docs/results/real_pq_coherence.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from aslm_core.disturbance import coupling
from service.readers.ieee1344 import read_1344

CAPTURE = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "tva-shelby-2007-ieee1344.PmuCapture"
#: The bus voltage phasor and the three line currents of the recording (its README).
VOLTAGE, LINES = 0, {"Cordova": 2, "Dell": 3, "Lagoon Creek": 4}


def line_rows(path: Path = CAPTURE) -> list[dict]:
    """Per line: mean flow, fluctuation std, P–Q correlation (all samples and under 1 Hz) and k."""
    cap = read_1344(path)
    t = cap.t - cap.t[0]
    v = cap.values[:, VOLTAGE]
    width = int(round(cap.rate))  # 1 s moving average

    def fluct(x: np.ndarray) -> np.ndarray:
        return x - np.polyval(np.polyfit(t, x, 1), t)

    def smooth(x: np.ndarray) -> np.ndarray:
        return np.convolve(x, np.ones(width) / width, mode="valid")

    rows = []
    for name, j in LINES.items():
        s = 3.0 * v * np.conj(cap.values[:, j]) / 1e6  # three-phase MVA from the positive-sequence phasors
        dp, dq = fluct(s.real), fluct(s.imag)
        rows.append({"line": name, "p_mw": float(s.real.mean()), "q_mvar": float(s.imag.mean()),
                     "std_p_mw": float(dp.std()), "std_q_mvar": float(dq.std()),
                     "corr": float(np.corrcoef(dp, dq)[0, 1]),
                     "corr_under_1hz": float(np.corrcoef(smooth(dp), smooth(dq))[0, 1]),
                     "k": coupling(dp, dq)})
    return rows


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None, help="write the rows as JSON here")
    args = ap.parse_args(argv)
    rows = line_rows()
    print("| line | P [MW] | Q [Mvar] | std ΔP [MW] | std ΔQ [Mvar] | corr(ΔP, ΔQ) | under 1 Hz | k |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['line']} | {r['p_mw']:.0f} | {r['q_mvar']:.0f} | {r['std_p_mw']:.2f} | {r['std_q_mvar']:.2f} | "
              f"{r['corr']:.2f} | {r['corr_under_1hz']:.2f} | {r['k']:.3f} |")
    if args.out:
        args.out.write_text(json.dumps(rows, indent=1) + "\n")
    return rows


if __name__ == "__main__":
    main()
