"""Memory soak: the service with N buses streamed in real time and period T; RSS sampled every period.

The replayer runs as a separate process (``aslm replay``) so the RSS printed is the service's own (main
process) plus, separately, its workers'.  Printed per period: ok/failed/skipped, latency, RSS; at the
end the RSS change from the first full period to the last.

    .venv/bin/python benchmarks/bench_soak.py --buses 200 --period 60 --minutes 30
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))


def rss_mb(pid: int) -> float:
    """Resident set size of a process [MB]."""
    with open(f"/proc/{pid}/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--buses", type=int, default=200)
    ap.add_argument("--period", type=float, default=60.0)
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--port", type=int, default=17711)
    args = ap.parse_args()

    from service.app import Service
    from service.settings import load_settings

    tmp = tempfile.TemporaryDirectory()
    settings = load_settings(period_s=args.period, window_s=10, late_s=1, http_port=0, instance="soak",
                             storage_url=str(Path(tmp.name) / "soak.sqlite"),
                             zenoh_listen=[f"tcp/127.0.0.1:{args.port}"])
    svc = Service(settings).start()
    rep = subprocess.Popen([sys.executable, "-m", "service.cli", "replay", "--buses", str(args.buses),
                            "--connect", f"tcp/127.0.0.1:{args.port}", "--log-level", "WARNING"],
                           cwd=os.path.join(os.path.dirname(__file__), ".."))
    samples = []
    seen = set()
    end = time.time() + 60 * args.minutes
    try:
        while time.time() < end:
            time.sleep(2.0)
            for p in svc.storage.periods(limit=3):
                if p.period in seen:
                    continue
                seen.add(p.period)
                workers = sum(rss_mb(pid) for pid in svc.executor.pids())
                main_rss = rss_mb(os.getpid())
                tot = svc.store.totals()
                samples.append((p, main_rss))
                print(f"{time.strftime('%H:%M:%S')} period ok={p.n_ok} failed={p.n_failed} skipped={p.n_skipped} "
                      f"latency={p.latency_s:.2f}s  service RSS {main_rss:.0f} MB (workers {workers:.0f} MB)  "
                      f"frames {tot.frames_received:,} dropped {sum(tot.frames_rejected.values())}", flush=True)
    finally:
        rep.terminate()
        rep.wait(10)
        svc.stop()
    full = [(p, r) for p, r in samples if p.n_ok > 0]
    if len(full) >= 2:
        first, last = full[0][1], full[-1][1]
        peak = max(r for _, r in full)
        print(f"RSS over {len(full)} full periods: first {first:.0f} MB, last {last:.0f} MB "
              f"({100 * (last - first) / first:+.1f} %), peak {peak:.0f} MB")


if __name__ == "__main__":
    main()
