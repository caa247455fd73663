"""Discrepancy diagnosis in the running service: every k-th period each identified bus is diagnosed in the
worker pool; the report is stored, put on ``aslm/diagnosis/{bus}`` and served by REST."""

from __future__ import annotations

import json
import time

import httpx
from service_helpers import client_session, free_port, settings_for, wait_for

from aslm_sim.fleet import SyntheticFleet
from service.app import Service
from service.replay import FleetReplayer, FramePublisher
from service.storage import Storage

N_BUSES = 3


def test_diagnosis_reaches_rest_zenoh_and_storage(tmp_path):
    zport = free_port()
    settings = settings_for(tmp_path, zport, period_s=12.0, window_s=10.0, late_s=1.0, task_timeout_s=120,
                            diagnose_every=1)
    with Service(settings) as svc:
        sess = client_session(zport)
        got: dict[str, dict] = {}
        sub = sess.declare_subscriber(  # noqa: F841 - kept alive for the test
            "aslm/diagnosis/**",
            lambda s: got.__setitem__(str(s.key_expr).rsplit("/", 1)[1], json.loads(s.payload.to_bytes())))
        fleet = SyntheticFleet(N_BUSES, level=3, seed=4, t0=time.time())
        rep = FleetReplayer(FramePublisher(sess, "aslm"), fleet, batch_s=0.2).start()
        try:
            wait_for(lambda: len(got) == N_BUSES, 150, 0.5)
        finally:
            rep.stop()
        assert rep.error is None
        for bus in fleet.bus_names:
            rest = httpx.get(f"{svc.url}/buses/{bus}/diagnosis/latest", timeout=5).json()
            assert rest == got[bus]
            # The DESIGN §4 contract.  (The verdict itself is the diagnosis tests' business, input noise
            # included: tests/aslm_core/diagnosis/test_diagnosis_input_noise.py.)
            assert rest["verdict"] in {"consistent", "explained", "ambiguous", "unexplained"}, rest
            assert {"located", "missing_physics", "fit_before", "fit_after"} <= set(rest)
            assert set(rest["fit_before"]) >= {"fd_p", "fd_q"}
            assert rest["bus"] == bus and rest["period"] > 0
        missing = httpx.get(f"{svc.url}/buses/nobus/diagnosis/latest", timeout=5)
        assert missing.status_code == 404
        metrics = httpx.get(f"{svc.url}/metrics").text
        counted = sum(float(line.rsplit(" ", 1)[1]) for line in metrics.splitlines()
                      if line.startswith("aslm_diagnoses_total{"))
        assert counted >= N_BUSES
        sess.close()
    # Persisted: a restarted service serves the same latest diagnoses.
    assert set(Storage(settings.storage_path).latest_diagnoses()) == set(fleet.bus_names)
