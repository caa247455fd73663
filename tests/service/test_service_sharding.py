"""Sharding: three ``aslm serve`` processes and a Zenoh router on loopback share 60 buses.

Every bus is identified exactly once per period; one instance killed (SIGKILL) → from the
next-but-one period every bus again exactly once; the instance back → the same.  Short periods
(2 s, 1 s windows) and the stand-in ``fake_identify``: the numerics are not under test here.
"""

from __future__ import annotations

import math
import time

import httpx
import pytest
from service_helpers import HERE, NoiseStreamer, wait_for

from service.sharding import owner
from service.testing_fleet import Fleet, Instance, ResultLog, wait_until

pytestmark = pytest.mark.slow

T, LATE = 2.0, 0.5
SETTLE = 4.0  # after boundary + late allowance: the period's results are published by then (even under load)
BUSES = [f"area{i % 3}/bus{i:02d}" for i in range(60)]
SETTINGS = {"period_s": T, "window_s": 1.0, "late_s": LATE, "frame_rate": 50.0, "workers": 1,
            "identify_fn": "service_helpers:fake_identify", "diagnose_every": 0, "n_starts": 1}
NAMES = ["shard-a", "shard-b", "shard-c"]


def boundary_after(t: float) -> float:
    return (math.floor(t / T) + 1) * T


def up(inst: Instance) -> bool:
    try:
        return httpx.get(f"{inst.url}/health", timeout=2).status_code == 200
    except httpx.HTTPError:
        assert inst.process.poll() is None, inst.log_path.read_text()[-3000:]
        return False


def settled(log: ResultLog, period: float) -> bool:
    """Whether every bus was identified exactly once for ``period`` by ``period + LATE + SETTLE``.

    A duplicate arriving later is caught by the test's final check over every period.
    """
    wait_until(period + LATE)
    while not log.exactly_once(period, BUSES) and time.time() < period + LATE + SETTLE:
        time.sleep(0.1)
    return log.exactly_once(period, BUSES)


def test_three_instances_share_the_buses_and_take_over_from_each_other(tmp_path):
    with Fleet(NAMES, BUSES, tmp_path, SETTINGS, NoiseStreamer, pythonpath=[str(HERE)]) as cluster:
        fleet, log = cluster.instances, cluster.log
        for inst in fleet.values():
            wait_for(lambda inst=inst: up(inst), 180)
        # 1. Steady state: exactly once per period, two periods running.
        first = wait_for(lambda: next((p for p in [boundary_after(time.time())] if settled(log, p)), None), 60)
        assert settled(log, first + T), log.identified(first + T)
        # Any instance answers REST for every bus, whichever owns it.
        for bus in BUSES:
            r = httpx.get(f"{fleet['shard-a'].url}/buses/{bus}/parameters/latest", timeout=5)
            assert r.status_code == 200 and r.json()["status"] == "ok", (bus, r.text)
        owned_by_c = [b for b in BUSES if owner(b, NAMES) == "shard-c"]
        assert 5 < len(owned_by_c) < 40

        # 2. Kill one: its buses come back from the next-but-one period.
        fleet["shard-c"].kill()
        killed = boundary_after(time.time())
        for period in (killed + T, killed + 2 * T):
            assert settled(log, period), (period - killed, log.identified(period))

        # 3. Bring it back (same name): the buses it owned return to it, again within two periods.
        cluster.start("shard-c")
        wait_for(lambda: up(fleet["shard-c"]), 180)
        back = boundary_after(time.time())
        for period in (back + T, back + 2 * T):
            assert settled(log, period), (period - back, log.identified(period))
        # Never a bus identified twice in one period, transitions included.
        assert all(max(c.values()) == 1 for c in log.by_period.values())
        # The returned instance identifies its own buses again.
        r = httpx.get(f"{fleet['shard-c'].url}/buses", timeout=5).json()
        assert {b["bus"] for b in r if b["frames_buffered"] > 0} == set(owned_by_c)
