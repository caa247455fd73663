"""STTP source, assembly only: the CPU cost of turning measurements into per-bus frames.

N PMUs (a voltage and a current phasor as magnitude and angle, and a frequency: 5 measurements each) at
R frames/s, as ``sttp.transport.measurement.Measurement`` objects in packets of one timestamp each
(shuffled within the packet), fed to :class:`service.sources.sttp.FrameAssembler` on one core, its frames
taken as batches every 0.2 s of data as the source does.  What is
measured is this project's part of the STTP source (assembly, phasors to V, θ, P, Q, hand-on); the
``sttpapi`` socket reading and TSSC decoding before it are the package's and are not included.

    .venv/bin/python benchmarks/bench_sttp_assembly.py --pmus 200 --rate 60 --seconds 10
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import uuid

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from service.protocols.mapping import parse_mapping  # noqa: E402
from service.sources.sttp import UNIX_TICKS, BusSignals, FrameAssembler  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pmus", type=int, default=200)
    ap.add_argument("--rate", type=float, default=60.0)
    ap.add_argument("--seconds", type=float, default=10.0, help="of data (not of wall time)")
    ap.add_argument("--out", help="write the result JSON here")
    args = ap.parse_args()

    from sttp.transport.measurement import Measurement

    buses = {f"b{k}": {"pmu": f"PMU{k}", "voltage": "V1", "current": "I1", "base_kv": 230.0}
             for k in range(args.pmus)}
    plans = [BusSignals(bm, [uuid.uuid4() for _ in range(5)], 1, [1], True)
             for bm in parse_mapping({"buses": buses}).buses]
    asm = FrameAssembler(plans, lag_s=2.0)
    n = int(args.seconds * args.rate)
    rng = np.random.default_rng(0)
    t0 = UNIX_TICKS + 17_000_000_000_000_000
    step = round(1e7 / args.rate)
    values = [132e3, 5.0, 250.0, -20.0, 60.0]
    packets = []
    for k in range(n):
        ts = np.uint64(t0 + k * step)
        ms = [Measurement(sid, np.float64(v), ts) for p in plans for sid, v in zip(p.slots, values, strict=True)]
        order = rng.permutation(len(ms))
        packets.append([ms[i] for i in order])
    start = time.process_time()
    per_take = max(1, round(args.rate * 0.2))  # the source takes frames every batch_s = 0.2 s
    for k, ms in enumerate(packets):
        asm.add(ms)
        if k % per_take == per_take - 1:
            asm.take()
    asm.take()
    cpu = time.process_time() - start
    c = asm.counts()
    frames = c["delivered"]
    measurements = c["measurements"]
    out = {"pmus": args.pmus, "rate": args.rate, "seconds_of_data": args.seconds, "measurements": measurements,
           "frames_delivered": frames, "frames_expected": n * args.pmus, "cpu_s": round(cpu, 3),
           "us_per_measurement": round(cpu / measurements * 1e6, 3),
           "measurements_per_cpu_s": round(measurements / cpu),
           "share_of_one_core_at_rate": round(cpu / args.seconds, 3), "load_average": os.getloadavg()}
    print(json.dumps(out, indent=1))
    if args.out:
        with open(args.out, "w", encoding="utf-8") as fh:
            fh.write(json.dumps(out, indent=1) + "\n")
    return 0 if frames == n * args.pmus else 1


if __name__ == "__main__":
    sys.exit(main())
