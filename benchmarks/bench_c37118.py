"""C37.118 bridge throughput: one PDC connection carrying N PMUs at R frames/s, bridged onto Zenoh.

A spawned process plays the PDC (a C37.118.2 server sending one data frame of N PMU blocks per 1/R s,
re-stamped to the present) and subscribes to ``{prefix}/pmu/**`` to count what arrives on Zenoh.  This
process runs the bridge (C37118Client → FramePublisher) and measures its CPU time.  Printed: PMU frames
per second received, the bridge's CPU share of one core, and the accounting
frames received = delivered + rejected, delivered = published = arrived on Zenoh.

    .venv/bin/python benchmarks/bench_c37118.py --pmus 200 --rate 60 --seconds 30
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from service.protocols import c37118 as c37  # noqa: E402
from service.protocols.mapping import parse_mapping  # noqa: E402

PREFIX = "bench"


def pdc_config(n: int, rate: float) -> c37.Config:
    """N PMUs, each a positive-sequence V and one feeder current, float polar, float FREQ."""
    pmus = [c37.PmuConfig(f"PMU{k:04d}", 1000 + k, 0xF, [c37.Phasor("V1", c37.VOLTAGE), c37.Phasor("I1", c37.CURRENT)],
                          [], 0, 60.0, 0) for k in range(n)]
    return c37.Config(7, 1_000_000, pmus, rate)


def pdc_frames(cfg: c37.Config, count: int) -> list[bytes]:
    rng = np.random.default_rng(0)
    n = len(cfg.pmus)
    vln = 132.79e3
    frames = []
    for k in range(count):
        v = vln * (1 + 0.01 * rng.standard_normal(n)) * np.exp(1j * 0.1)
        i = 300 * np.exp(1j * (0.1 - 0.3 + 0.01 * rng.standard_normal(n)))
        frames.append(c37.encode_data(cfg, k / cfg.data_rate, [0] * n, list(np.stack([v, i], axis=1)),
                                      [60.0] * n, [0.0] * n))
    return frames


def pdc_process(n: int, rate: float, seconds: float, port_q, result_q, zport: int) -> None:
    import zenoh

    from service.frames import decode_binary
    from service.protocols.pmu_server import CapturePmu
    from service.zenoh_config import zenoh_config

    cfg = pdc_config(n, rate)
    frames = pdc_frames(cfg, int(rate))  # one second of distinct frames, looped
    session = zenoh.open(zenoh_config("peer", connect=[], listen=[f"tcp/127.0.0.1:{zport}"]))
    arrived = [0]

    def on_sample(s):
        arrived[0] += len(decode_binary(s.payload.to_bytes()))

    sub = session.declare_subscriber(f"{PREFIX}/pmu/**", on_sample)
    pmu = CapturePmu(cfg, frames, loop=True).start()
    port_q.put(pmu.port)
    deadline = time.time() + seconds + 60
    while pmu.sent < seconds * rate and time.time() < deadline:
        time.sleep(0.05)
    sent = pmu.sent
    pmu.close()  # data off: the bridge's connection ends
    time.sleep(3.0)
    result_q.put({"frames_sent": sent, "pmu_frames_sent": sent * n, "arrived_on_zenoh": arrived[0]})
    sub.undeclare()
    session.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pmus", type=int, default=200)
    ap.add_argument("--rate", type=float, default=60.0)
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--batch", type=float, default=0.2, help="seconds of frames per Zenoh message")
    ap.add_argument("--out", help="write the result JSON here")
    args = ap.parse_args()

    import zenoh

    from service.replay import FramePublisher
    from service.sources.c37118 import C37118Client, StreamSettings
    from service.zenoh_config import zenoh_config

    zport = 17000 + os.getpid() % 20000
    ctx = mp.get_context("spawn")
    port_q, result_q = ctx.Queue(), ctx.Queue()
    proc = ctx.Process(target=pdc_process, args=(args.pmus, args.rate, args.seconds, port_q, result_q, zport))
    proc.start()
    port = port_q.get(timeout=120)
    session = zenoh.open(zenoh_config("peer", connect=[f"tcp/127.0.0.1:{zport}"], listen=[]))
    pub = FramePublisher(session, PREFIX)
    buses = {f"b{k:04d}": {"pmu": 1000 + k, "voltage": "V1", "current": "I1", "base_kv": 230.0}
             for k in range(args.pmus)}
    client = C37118Client(StreamSettings(port=port, idcode=7, batch_s=args.batch, backoff_s=(60.0, 60.0)),
                          parse_mapping({"buses": buses}), pub.send)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    client.start_thread()
    res = result_q.get(timeout=args.seconds + 180)
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    client.close()
    proc.join(10)
    c = client.counts()
    out = {
        "pmus": args.pmus, "rate": args.rate, "seconds": round(wall, 1), **res,
        "received": c["frames"], "delivered": c["delivered"], "rejected": c["rejected"],
        "bad_frames": c["bad_frames"], "published": pub.frames_sent, "zenoh_messages": pub.messages_sent,
        "offered_pmu_frames_per_s": round(args.pmus * args.rate),
        # over the whole run, connection set-up and the final drain included: a lower bound
        "received_pmu_frames_per_s_whole_run": round(c["frames"] / wall),
        "bridge_cpu_share_of_one_core": round(cpu / wall, 3),
        "cpu_us_per_pmu_frame": round(cpu / max(c["frames"], 1) * 1e6, 2),
        "books_balance": c["frames"] == c["delivered"] + sum(c["rejected"].values()),
        "nothing_lost": c["frames"] == res["pmu_frames_sent"] and pub.frames_sent == res["arrived_on_zenoh"]
        == c["delivered"],
    }
    pub.close()
    session.close()
    print(json.dumps(out, indent=1))
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
