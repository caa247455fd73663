"""The real 2007 Shelby recording through the C37.118 path end to end, at its own 30 frames/s.

IEEE 1344 capture → C37.118.2 frames (the PMU's own integer counts and PHUNIT scales) → a PMU on
127.0.0.1 that sends them in real time, re-stamped to the present → the service (``sources =
["c37118"]``, the mapping below) → buffers → scheduler → identifier and diagnosis in a worker process →
SQLite.  Printed (and written with ``--out``): what the source counted, and each period's result and
diagnosis verdict.

    .venv/bin/python benchmarks/real_capture.py --out docs/results/real_capture.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from service.app import Service  # noqa: E402
from service.protocols.pmu_server import CapturePmu  # noqa: E402
from service.readers.ieee1344 import read_1344, to_c37118  # noqa: E402
from service.settings import load_settings  # noqa: E402

CAPTURE = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "tva-shelby-2007-ieee1344.PmuCapture"

# Bus 1's voltage and the three measured line currents taken together: the "load" is what leaves the
# 500 kV bus through those lines (P + jQ = 3·V·conj(ΣI)); the transformers and other bays are not measured.
MAPPING = """
[c37118]
host = "127.0.0.1"
port = {port}
idcode = 2
batch_s = 0.2
timeout_s = 3600.0  # the PMU falls silent when the recording ends: do not reconnect (it would replay)

[buses.shelby]
pmu = 2
voltage = "Bus 1"
current = ["Cordova", "Dell", "Lagoon Creek"]
base_kv = 500.0
base_mva = 100.0
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--capture", default=str(CAPTURE))
    ap.add_argument("--period", type=float, default=11.0, help="period T [s] (window 10 s, late 1 s)")
    ap.add_argument("--out", help="write the summary JSON here")
    args = ap.parse_args()

    cap = read_1344(args.capture)
    cfg, frames = to_c37118(cap, idcode=2)
    pmu = CapturePmu(cfg, frames).start()
    tmp = Path(tempfile.mkdtemp(prefix="aslm-real-"))
    (tmp / "shelby.toml").write_text(MAPPING.format(port=pmu.port))
    settings = load_settings(
        sources=["c37118"], sinks=["storage"], pmu_mapping=str(tmp / "shelby.toml"),
        storage_url=str(tmp / "aslm.sqlite"), frame_rate=cap.rate, f0=cap.fnom, window_s=10.0, late_s=1.0,
        period_s=args.period, workers=1, diagnose_every=1, task_timeout_s=600.0, zenoh_listen=[],
    )
    t_start = time.time()
    svc = Service(settings, rest=False).start()
    try:
        pmu.finished.wait(cap.t[-1] - cap.t[0] + 30)
        sent_s = time.time() - t_start
        # the last period that holds recorded data, its identification and its diagnosis
        deadline = time.time() + args.period + 900
        while time.time() < deadline:
            done = [p for p in svc.storage.periods(100) if p.period <= t_start + sent_s + args.period]
            diags = svc.storage.latest_diagnoses()
            if done and max(p.period for p in done) > t_start + sent_s and diags:
                break
            time.sleep(2)
        source = svc.sources[0].client.counts()
        results = [json.loads(r.model_dump_json()) for r in svc.storage.history("shelby")]
        diagnoses = {bus: json.loads(d) for bus, d in svc.storage.latest_diagnoses().items()}
    finally:
        svc.stop()
        pmu.close()
    summary = {
        "capture": Path(args.capture).name, "frames_recorded": int(cap.t.size), "frames_sent": pmu.sent,
        "send_seconds": round(sent_s, 1), "source_counts": source,
        "results": [{k: r[k] for k in ("period", "status", "reason", "n_frames", "parameters")} for r in results],
        "diagnosis": diagnoses,
    }
    text = json.dumps(summary, indent=1, default=str)
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
