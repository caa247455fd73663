"""docs/architecture.md keeps its promise: its example sink is one module plus one registration line."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np
from service_helpers import settings_for

from service.app import Service
from service.clock import ManualClock
from service.sinks import SINKS
from service.sources.base import Inlet
from service.testing import MemorySource

ROOT = Path(__file__).resolve().parents[2]
T0, FS = 1_000_000.0, 50.0


def _example_module(name: str) -> str:
    """The documented module whose code block starts with ``# service/sinks/{name}.py``."""
    doc = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    for block in re.findall(r"```python\n(.*?)```", doc, flags=re.S):
        if block.startswith(f"# service/sinks/{name}.py"):
            return block
    raise AssertionError(f"docs/architecture.md has no example module service/sinks/{name}.py")


def test_the_documented_sink_runs_from_one_module_and_one_registry_line(tmp_path, monkeypatch):
    (tmp_path / "doc_example_jsonl.py").write_text(_example_module("jsonl"), encoding="utf-8")
    monkeypatch.setattr(sys, "path", [str(tmp_path), *sys.path])
    monkeypatch.setitem(SINKS, "jsonl", "doc_example_jsonl:build")  # the one registration line

    clock = ManualClock(T0 + 1.0)
    settings = settings_for(tmp_path, 7447, sources=[], sinks=["storage", "jsonl"], period_s=10.0, window_s=2.0,
                            late_s=0.5, identify_fn="service_helpers:fake_identify", diagnose_every=0, workers=1)
    svc = Service(settings, rest=False, clock=clock).start()
    try:
        clock.settle(30)
        feeder = MemorySource()
        feeder.start(Inlet(svc.store, max_future_s=settings.max_future_s, f0=settings.f0, clock=clock))
        clock.advance_to(T0 + 10)
        t = T0 + 10 - np.arange(150)[::-1] / FS
        v = 1 + 0.01 * np.random.default_rng(0).standard_normal(t.size)
        feeder.push_window("b1", t, v, np.zeros(t.size), np.full(t.size, 0.8), np.full(t.size, 0.3))
        clock.advance_to(T0 + 10.5)
        clock.settle(30)
    finally:
        svc.stop()
    lines = Path(str(settings.storage_path) + ".jsonl").read_text(encoding="utf-8").splitlines()
    written = [json.loads(line) for line in lines]
    assert [(r["bus"], r["period"], r["status"]) for r in written] == [("b1", T0 + 10, "ok")]
