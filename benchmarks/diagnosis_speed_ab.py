"""Interleaved A/B of the diagnosis's filter-design and relay-V caches: CPU per diagnosis, both in one process.

    .venv/bin/python -m benchmarks.diagnosis_speed_ab [--repeats 2]

Seven cached ANDES windows (the four slowest of ``confirm3`` among them, noise on V and θ) are diagnosed with
the caches on (after) and off (before: the Butterworth design and the switched-shunt candidate's low-passed V
recomputed at every call, as before round 4), alternating the order per repeat.  The reports must be
identical — the caches change no number, only the time.
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


def main(argv: list[str] | None = None) -> int:
    from aslm_core.diagnosis import diagnose, locate, segment
    from aslm_core.diagnosis.candidates import switched_shunt
    from aslm_sim.andes.effects import recording
    from benchmarks.diagnosis_independent import TF, TSTEP, _window

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=2)
    args = p.parse_args(argv)
    cached_sos, cached_relay = segment.butter_sos, switched_shunt.SwitchedShunt._relay_v

    def uncached_sos(fc: float, fs: float) -> np.ndarray:
        return signal.butter(4, fc, fs=fs, output="sos")

    def uncached_relay(self, seg) -> np.ndarray:
        return segment._lowpass(seg.V, seg.fs, segment.FREQ_LOWPASS_HZ)

    def caches(on: bool) -> None:
        segment.butter_sos = locate.butter_sos = cached_sos if on else uncached_sos
        switched_shunt.SwitchedShunt._relay_v = cached_relay if on else uncached_relay

    windows = [_window(recording(k, s, tf=TF, tstep=TSTEP), t0, t0 + 10.0, lvl, inp, f"{k}/{s}")[0]
               for k, s, t0, lvl, inp in CASES]
    diagnose(windows[0])  # numba compilation outside the timing
    cpu: dict[str, list[float]] = {"before": [], "after": []}
    identical = True
    for rep in range(args.repeats):
        for w in windows:
            out = {}
            for on in ((False, True) if rep % 2 == 0 else (True, False)):
                caches(on)
                c0 = time.process_time()
                d = diagnose(w).to_dict()
                cpu["after" if on else "before"].append(time.process_time() - c0)
                d.pop("elapsed_s", None)
                out[on] = json.dumps(d, sort_keys=True, default=str)
            identical &= out[True] == out[False]
    caches(True)
    for k, v in cpu.items():
        t = np.array(v)
        print(f"{k}: CPU per diagnosis median {np.median(t):.2f} s, max {t.max():.2f} s, total {t.sum():.1f} s")
    print(f"reports identical: {identical}; load average {os.getloadavg()}")
    return 0 if identical else 1


if __name__ == "__main__":
    sys.exit(main())
