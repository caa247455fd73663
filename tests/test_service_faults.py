"""The service under operational faults, on a manual clock without Zenoh: a bad persisted period, a crash
mid-period, a failing storage, and what /health and the metrics say about them (issue 17)."""

from __future__ import annotations

import math

import pytest
from service_helpers import settings_for

from service.app import Service
from service.storage import Storage

T0 = 1_000_000.0
FAKE = "service_helpers:fake_identify"


@pytest.mark.parametrize("bad", [math.inf, math.nan, 1e12, 1.0])
def test_a_bad_persisted_period_is_never_reloaded(tmp_path, bad):
    settings = settings_for(tmp_path, 7447, sources=[], sinks=["storage"], period_s=60.0, window_s=2.0, late_s=0.5)
    storage = Storage(settings.storage_path)
    storage.set_config({"period_s": bad})
    storage.close()
    svc = Service(settings, rest=False)
    try:
        assert svc.period_s == 60.0
    finally:
        svc.storage.close()
