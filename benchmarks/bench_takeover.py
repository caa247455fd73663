"""Takeover and hand-back in a sharded fleet: periods without results for a killed instance's buses.

Three ``aslm serve`` processes (``zenoh-sharded`` source) and a Zenoh router on loopback share N buses
of a real-time noise stream; the identification is the stand-in ``fake_identify`` (ownership is under
test, not numerics).  One instance is killed (SIGKILL) in steady state, then started again under the
same name.  For each of its buses: periods between its last result before the event and its first
after it (gap; the target is ≤ 2 periods), and whether any (bus, period) was identified twice.

    .venv/bin/python benchmarks/bench_takeover.py --buses 300 --period 4
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from service_helpers import NoiseStreamer  # noqa: E402

from service.sharding import owner  # noqa: E402
from service.testing_fleet import Fleet, ResultLog, wait_until  # noqa: E402

NAMES = ["shard-a", "shard-b", "shard-c"]


def gaps(log: ResultLog, buses: list[str], event: float, period_s: float) -> list[int]:
    """Per bus: periods without a result between the last before ``event`` and the first after it."""
    out = []
    for bus in buses:
        ok = sorted(p for p, c in log.by_period.items() if c.get(bus))
        before = [p for p in ok if p < event]
        after = [p for p in ok if p >= event]
        if not before or not after:
            out.append(-1)  # never identified on one side: reported as such
            continue
        out.append(round((after[0] - before[-1]) / period_s) - 1)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--buses", type=int, default=300)
    ap.add_argument("--period", type=float, default=4.0, help="period T [s] (window T/2)")
    args = ap.parse_args()
    T = args.period
    buses = [f"area{i % 7}/bus{i:04d}" for i in range(args.buses)]
    settings = {"period_s": T, "window_s": T / 2, "late_s": 0.5, "frame_rate": 50.0, "workers": 1,
                "identify_fn": "service_helpers:fake_identify", "diagnose_every": 0, "n_starts": 1}
    tmp = Path(tempfile.mkdtemp(prefix="aslm-takeover-"))
    cluster = Fleet(NAMES, buses, tmp, settings, NoiseStreamer, pythonpath=[str(ROOT / "tests")])
    fleet, log = cluster.instances, cluster.log
    mine = [b for b in buses if owner(b, NAMES) == "shard-c"]
    try:
        t0 = time.time()
        while not log.exactly_once(max(log.by_period, default=0.0), buses):
            assert time.time() - t0 < 300, "the fleet did not reach a steady state in 300 s"
            time.sleep(0.5)
        print(f"steady state {time.time() - t0:.0f} s after start; {len(mine)} of {len(buses)} buses on shard-c")
        wait_until(time.time() + 2 * T)
        killed = time.time()
        fleet["shard-c"].kill()
        wait_until(killed + 5 * T)
        back = time.time()  # its buses are identified by the others until its token appears
        cluster.start("shard-c")
        while (tmp / "shard-c.log").read_text().count("serving") < 2:  # the log is appended to
            assert time.time() - back < 300, "shard-c did not come back in 300 s"
            time.sleep(0.5)
        print(f"shard-c serving again {time.time() - back:.0f} s after its start")
        wait_until(time.time() + 5 * T)
        dup = sum(c > 1 for counter in log.by_period.values() for c in counter.values())
        for name, event in (("takeover after SIGKILL", killed), ("hand-back after restart", back)):
            g = gaps(log, mine, event, T)
            worst = max(g)
            print(f"{name}: T = {T:g} s, {len(mine)} buses: periods without a result: max {worst}, "
                  f"histogram {dict(sorted((k, g.count(k)) for k in set(g)))} (target <= 2: "
                  f"{'met' if 0 <= worst <= 2 else 'NOT met'})")
        print(f"(bus, period) identified more than once: {dup}; load average {os.getloadavg()[0]:.1f} "
              f"on {os.cpu_count()} cores")
    finally:
        cluster.close()


if __name__ == "__main__":
    main()
