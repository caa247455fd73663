"""``aslm demo``: the service and a synthetic fleet on loopback, identified vs true parameters per period.

Everything runs on 127.0.0.1: a Zenoh peer listening on a free port, the replayer connecting to it, a
local process pool, SQLite in ``--out`` (``aslm-demo/``, kept after exit; ``--temp`` for a throw-away
directory), REST on ``--port`` (8080, or any free port if taken).  Ctrl-C stops cleanly;
``--periods``/``--duration`` stop by themselves.
"""

from __future__ import annotations

import argparse
import json
import logging
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path

from aslm_core.params import DYNAMIC_NAMES, DYNAMIC_PARAMS
from service.commands._common import setup_logging, stop_event_on_signals
from service.timefmt import utc_text

log = logging.getLogger("aslm.demo")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="service + synthetic PMU fleet on loopback; prints identified vs true")
    p.add_argument("--buses", type=int, default=10, help="synthetic buses (default 10)")
    p.add_argument("--period", type=float, default=20.0, help="period T [s] (default 20)")
    p.add_argument("--window", type=float, default=10.0, help="window [s] (default 10)")
    p.add_argument("--late", type=float, default=1.0, help="late-data allowance [s] (default 1)")
    p.add_argument("--rate", type=float, default=50.0, help="frames/s per bus (default 50)")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--level", type=int, default=2, help="measurement-noise level (default 2)")
    p.add_argument("--seed", type=int, default=0, help="seed of the synthetic fleet")
    p.add_argument("--periods", type=int, default=None, help="exit after N periods with results")
    p.add_argument("--diagnose-every", type=int, default=4,
                   help="discrepancy diagnosis of every bus each k-th period (default 4; 0: off)")
    p.add_argument("--duration", type=float, default=None, help="exit after this many seconds")
    p.add_argument("--port", type=int, default=8080, help="REST port (default 8080; any free port if taken)")
    p.add_argument("--out", default="aslm-demo",
                   help="directory of the SQLite history, kept after exit; a second run adds to it "
                        "(default: aslm-demo in the current directory)")
    p.add_argument("--temp", action="store_true",
                   help="keep the history in a temporary directory instead, deleted on exit")
    p.add_argument("--encoding", choices=["binary", "json"], default="binary", help="frame encoding on Zenoh")
    p.add_argument("--log-level", default="WARNING", help="logging level")
    p.set_defaults(func=run)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _port_free(port: int) -> bool:
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
            return True
        except OSError:
            return False


# What a skip reason means to someone watching the demo start (service.md, skip reasons).
SKIP_MEANING = {
    "no_data": "no frames in the window yet",
    "coverage": "the window is not full yet",
    "gap": "a gap in the frames",
    "no_excitation": "too little voltage variation",
}


def format_skipped(summary, reasons: set[str]) -> str:
    """One line for a period without results: when, how many buses, why (no empty parentheses)."""
    when = utc_text(summary.period)
    if summary.n_skipped == 0:
        return f"period {when}: no bus has sent frames yet - waiting for the fleet"
    why = "; ".join(f"{r}: {SKIP_MEANING[r]}" if r in SKIP_MEANING else r for r in sorted(reasons) if r)
    n = f"all {summary.n_skipped} buses" if summary.n_skipped > 1 else "the only bus"
    return f"period {when}: {n} skipped" + (f" ({why})" if why else "") + " - waiting for a full window"


class _Ticker:
    """Prints what the demo waits for every ``every`` seconds until stopped (the first start compiles)."""

    def __init__(self, what: str, every: float = 15.0) -> None:
        self._what, self._every, self._done = what, every, threading.Event()
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="demo-ticker", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._done.wait(self._every):
            print(f"  ... {self._what} ({time.monotonic() - self._t0:.0f} s)", flush=True)

    def stop(self) -> None:
        self._done.set()
        self._thread.join()


def format_period(summary, results: dict, truth: dict) -> str:
    """Table of one period: identified vs true D per bus, with relative errors."""
    head = (f"period {utc_text(summary.period)}  "
            f"T={summary.period_s:g}s  ok={summary.n_ok} failed={summary.n_failed} skipped={summary.n_skipped}  "
            f"latency={summary.latency_s:.2f}s")
    lines = [head, f"  {'bus':8s} {'status':8s}" + "".join(f"{f'{p.name} [{p.unit}]':>22s}" for p in DYNAMIC_PARAMS)
             + "   FD(P)"]
    for bus in sorted(results):
        r = results[bus]
        tr = truth.get(bus, {}).get("dynamic", {})
        if r.status != "ok" or r.parameters is None:
            lines.append(f"  {bus:8s} {r.status:8s} {r.reason or ''}")
            continue
        cells = []
        for k in DYNAMIC_NAMES:
            est, true = r.parameters.dynamic.get(k), tr.get(k)
            err = f"{100 * (est - true) / true:+4.0f}%" if true else ""
            cells.append(f"{est:7.3f} /{true:7.3f} {err:>5s}" if true is not None else f"{est:7.3f}")
        fd = r.parameters.fit.get("fd_p")
        lines.append(f"  {bus:8s} {'ok' + ('*' if r.warm_start else ''):8s}" + "".join(f"{c:>22s}" for c in cells)
                     + (f"   {fd:.3f}" if fd is not None else ""))
    lines.append("  (identified / true  error;  ok* = warm-started from the previous period)")
    return "\n".join(lines)


def format_diagnoses(reports: dict[str, str]) -> str:
    """One line per bus: the verdict of its latest discrepancy diagnosis and what it names."""
    lines = ["discrepancy diagnosis (held-out fit of the identified model):"]
    for bus in sorted(reports):
        rep = json.loads(reports[bus])
        named = [m["name"] for m in rep.get("missing_physics", []) if m.get("significant")]
        fit = rep.get("fit_before") or {}
        fd = "  ".join(f"{k}={v:.3f}" for k, v in fit.items() if isinstance(v, float))
        lines.append(f"  {bus:8s} {rep.get('verdict', '?'):12s} {', '.join(named) or '-':24s} {fd}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    setup_logging(args.log_level)
    import zenoh

    from aslm_sim.fleet import SyntheticFleet
    from service.app import Service
    from service.replay import FleetReplayer, FramePublisher
    from service.settings import SettingsError, load_settings
    from service.zenoh_config import zenoh_config

    stop = stop_event_on_signals()
    zport = _free_port()
    http_port = args.port if args.port == 0 or _port_free(args.port) else 0
    tmp = None
    if args.temp:
        tmp = tempfile.TemporaryDirectory(prefix="aslm-demo-")
        out = Path(tmp.name)
    else:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
    try:
        settings = load_settings(
            period_s=args.period, window_s=args.window, late_s=args.late, frame_rate=args.rate,
            workers=args.workers, storage_url=str(out / "aslm-demo.sqlite"), http_host="127.0.0.1",
            http_port=http_port, zenoh_mode="peer", zenoh_listen=[f"tcp/127.0.0.1:{zport}"], zenoh_connect=[],
            zenoh_multicast_scouting=False, executor="local", instance="demo",
            diagnose_every=args.diagnose_every,
        )
    except SettingsError as exc:
        print(f"aslm demo: {exc}", file=sys.stderr)
        return 2
    started = time.time()
    print(f"aslm demo: {args.buses} synthetic buses at {args.rate:g} frames/s, period {args.period:g} s, "
          f"window {args.window:g} s", flush=True)
    kept = "deleted on exit (--temp)" if tmp is not None else "kept after exit (--temp for a throw-away one)"
    print(f"history: {settings.storage_path}, {kept}", flush=True)
    print(f"starting {args.workers} worker processes: they load the compiled numerical kernels (numba). "
          "The first run after an install compiles them, 1-2 min (scripts/setup does it ahead); "
          "later starts take seconds.", flush=True)
    svc = Service(settings)
    session = None
    rep = None
    received = {"n": 0}
    try:
        ticker = _Ticker("workers still compiling or loading the kernels")
        try:
            svc.start()
        finally:
            ticker.stop()
        print(f"workers ready after {time.time() - started:.0f} s", flush=True)
        print(f"REST: {svc.url}  (OpenAPI {svc.url}/docs, metrics {svc.url}/metrics); "
              f"Zenoh: tcp/127.0.0.1:{zport}", flush=True)
        session = zenoh.open(zenoh_config("peer", connect=[f"tcp/127.0.0.1:{zport}"], listen=[]))
        sub = session.declare_subscriber(f"{settings.prefix}/params/**",  # noqa: F841 - kept alive
                                         lambda s: received.__setitem__("n", received["n"] + 1))
        fleet = SyntheticFleet(args.buses, fs=args.rate, level=args.level, seed=args.seed, t0=time.time())
        rep = FleetReplayer(FramePublisher(session, settings.prefix, args.encoding), fleet, batch_s=0.2)
        truth = rep.truth()
        rep.start()
        print(f"streaming; first results after the first {args.period:g} s boundary with {args.window:g} s "
              "of data. Ctrl-C to stop.", flush=True)
        seen = {p.period for p in svc.storage.periods(limit=5)}  # an earlier run's, in a kept history
        diagnosed: dict[str, str] = {}
        with_results = 0
        status = 0
        while not stop.wait(0.5):
            if rep.error is not None:
                print(f"aslm demo: replayer failed: {rep.error}", file=sys.stderr)
                return 1
            for summary in reversed(svc.storage.periods(limit=5)):
                if summary.period in seen:
                    continue
                seen.add(summary.period)
                results = {r.bus: r for r in (svc.storage.history(b, summary.period, summary.period, 1)[0:1]
                                              for b in fleet.bus_names) for r in r}
                if summary.n_ok + summary.n_failed == 0:
                    print(format_skipped(summary, {r.reason or "" for r in results.values()}), flush=True)
                    continue
                with_results += 1
                print(format_period(summary, results, truth), flush=True)
                print(f"  results received over Zenoh so far: {received['n']}", flush=True)
            fresh = {b: js for b, js in svc.latest.diagnoses_json.items() if diagnosed.get(b) != js}
            if fresh:
                diagnosed.update(fresh)
                print(format_diagnoses(fresh), flush=True)
            if args.periods is not None and with_results >= args.periods:
                break
            if args.duration is not None and time.time() - started >= args.duration:
                if args.periods is not None and with_results < args.periods:
                    print(f"aslm demo: only {with_results} of {args.periods} periods with results within "
                          f"--duration {args.duration:g} s", file=sys.stderr)
                    status = 1
                break
    finally:
        if rep is not None:
            rep.stop()
        if session is not None:
            session.close()
        svc.stop()
        if tmp is not None:
            tmp.cleanup()
    if tmp is None:
        print(f"history kept in {settings.storage_path}: `aslm serve --storage {settings.storage_path}` "
              "serves it, the next `aslm demo` adds to it; delete the directory to start afresh", flush=True)
    print("aslm demo: stopped", flush=True)
    return status
