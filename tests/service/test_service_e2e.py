"""End to end on loopback: a 20-bus synthetic fleet with known parameters over Zenoh → the service (real
identifier in spawned workers) → results over REST, a Zenoh subscriber, the queryable and the history; the
tracked models (the tracking sink) over REST and on {prefix}/tracked/{bus}."""

from __future__ import annotations

import json
import time

import httpx
from service_helpers import client_session, free_port, periods, settings_for, wait_for

from aslm_sim.fleet import SyntheticFleet
from service.app import Service
from service.replay import FleetReplayer, FramePublisher

N_BUSES = 20
# Noise-free fleet: the identifier recovers D within ~3 % offline (see docs/service.md), so anything the
# transport, buffers or window cut did wrong would show as a larger error.
REL_TOL = 0.10


def test_fleet_to_parameters_over_rest_and_zenoh(tmp_path):
    zport = free_port()
    # objective 'ml': a non-default identifier option travels from the settings to every worker.
    settings = settings_for(tmp_path, zport, period_s=12.0, window_s=10.0, late_s=1.0, task_timeout_s=120,
                            objective="ml", sinks=["storage", "tracking", "zenoh"])
    with Service(settings) as svc:
        sess = client_session(zport)
        got: dict[tuple[str, float], dict] = {}
        tracked: dict[str, dict] = {}
        sub_tracked = sess.declare_subscriber(  # noqa: F841 - kept alive for the test
            "aslm/tracked/**", lambda s: tracked.__setitem__(str(s.key_expr).rsplit("/", 1)[1],
                                                            json.loads(s.payload.to_bytes())))
        sub = sess.declare_subscriber(  # noqa: F841 - kept alive for the test
            "aslm/params/**", lambda s: got.__setitem__(
                (str(s.key_expr).rsplit("/", 1)[1], json.loads(s.payload.to_bytes())["period"]),
                json.loads(s.payload.to_bytes())))
        fleet = SyntheticFleet(N_BUSES, level=None, seed=1, t0=time.time())
        pub = FramePublisher(sess, "aslm")
        rep = FleetReplayer(pub, fleet, batch_s=0.2).start()
        try:
            done = wait_for(lambda: [p for p in periods(svc.url) if p["n_ok"] == N_BUSES], 150, 0.5)[0]
        finally:
            rep.stop()
        assert rep.error is None
        truth = rep.truth()
        # REST: latest parameters of every bus, within tolerance of the truth.
        for bus in fleet.bus_names:
            res = httpx.get(f"{svc.url}/buses/{bus}/parameters/latest", timeout=5).json()
            assert res["status"] == "ok", res
            est, true = res["parameters"]["dynamic"], truth[bus]["dynamic"]
            errors = {k: abs(est[k] - true[k]) / true[k] for k in ("a", "b", "H2", "Tm")}
            assert max(errors.values()) <= REL_TOL, (bus, est, true)
            assert res["n_frames"] >= 0.9 * 10 * 50
            assert res["parameters"]["config"]["objective"] == "ml"
        # The same results over Zenoh: a subscriber got each bus's result of that period.
        wait_for(lambda: all((b, done["period"]) in got for b in fleet.bus_names), 10, 0.1)
        for bus in fleet.bus_names:
            zres = got[(bus, done["period"])]
            rest = httpx.get(f"{svc.url}/buses/{bus}/parameters",
                             params={"since": done["period"], "until": done["period"]}).json()
            assert len(rest) == 1 and zres["parameters"]["dynamic"] == rest[0]["parameters"]["dynamic"]
        # The tracked model of every bus: on REST and on Zenoh, pooled from its successful windows.
        wait_for(lambda: set(tracked) == set(fleet.bus_names), 10, 0.1)
        for bus in fleet.bus_names:
            model = httpx.get(f"{svc.url}/buses/{bus}/tracked", timeout=5).json()
            assert model["n_windows"] + model["suspect"] >= 1 and model["last_change"] is None, model
            true = truth[bus]["dynamic"]
            assert abs(model["dynamic"]["Tm"] - true["Tm"]) <= REL_TOL * true["Tm"], (bus, model, true)
            assert tracked[bus]["bus"] == bus and httpx.get(f"{svc.url}/buses/{bus}/changes").json() == []
        # The queryable answers "latest" for every bus.
        replies = [r.ok for r in sess.get("aslm/params/**", timeout=5) if r.ok is not None]
        assert {str(s.key_expr).rsplit("/", 1)[1] for s in replies} == set(fleet.bus_names)
        one = [r.ok for r in sess.get(f"aslm/params/{fleet.bus_names[3]}", timeout=5) if r.ok is not None]
        assert len(one) == 1
        # Liveliness token of the instance.
        alive = [r.ok for r in sess.liveliness().get("aslm/service/**", timeout=5) if r.ok is not None]
        assert [str(s.key_expr) for s in alive] == [f"aslm/service/{settings.instance}"]
        # Nothing lost on the way in: every frame sent was buffered (none rejected).
        tot = wait_for(lambda: (t := svc.store.totals()).frames_received == pub.frames_sent and t, 10, 0.1)
        assert tot.frames_buffered == pub.frames_sent and tot.frames_rejected == {}
        metrics = httpx.get(f"{svc.url}/metrics").text
        assert 'aslm_windows_total{status="ok"}' in metrics and "aslm_period_latency_seconds_count" in metrics
        pub.close()
        sess.close()
