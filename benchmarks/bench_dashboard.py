"""Dashboard with 10,000 buses: page load and interaction times in headless Chromium, and the server
side (/fleet pages, /metrics with the per-bus gauges).

The REST server is the service's own (uvicorn in a thread, ``create_app``) on a view holding N buses'
latest results in memory (as a running service after a period) and 96 periods of history and 10
diagnoses for one bus (a day at T = 15 min).  No workers: the playback chart says so, which does not
delay the rest of the page.

    .venv/bin/python benchmarks/bench_dashboard.py --buses 10000 --repeat 5
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

import httpx  # noqa: E402
from browser_helpers import headless_chromium, missing, wait_js  # noqa: E402
from service_helpers import settings_for  # noqa: E402
from test_dashboard_api import report, result  # noqa: E402
from test_service_api import View  # noqa: E402

from service import fleet  # noqa: E402
from service.api import create_app  # noqa: E402
from service.buffers import BufferStore  # noqa: E402
from service.context import Context  # noqa: E402
from service.http_server import HttpServer  # noqa: E402
from service.latest import LatestResults  # noqa: E402
from service.metrics import ServiceMetrics  # noqa: E402
from service.sinks.base import SinkChain  # noqa: E402
from service.sinks.bus_metrics import BusMetricsSink  # noqa: E402
from service.sinks.storage import StorageSink  # noqa: E402
from service.storage import Storage  # noqa: E402

PAGE_BUS = "bus00042"

# JS run in the page: do something, then resolve with the ms until the fleet table's first row or the
# row count changed and the browser painted it (the next animation frame).
_TIMED = """
const done = arguments[arguments.length - 1];
const first = () => { const r = document.querySelector('#fleet tbody tr'); return r ? r.dataset.bus + '|' + document.querySelector('#fleet').dataset.matched : ''; };
const before = first(), t0 = performance.now();
(%s)();
const poll = () => first() !== before ? requestAnimationFrame(() => done(performance.now() - t0)) : setTimeout(poll, 2);
poll();
"""


def build(n_buses: int, tmp: Path) -> tuple[HttpServer, View]:
    """A view with ``n_buses`` latest results, one bus's day of history, per-bus gauges; served."""
    settings = settings_for(Path(tempfile.mkdtemp(dir=tmp)), 7447, period_s=900.0)  # a fresh SQLite file
    store = BufferStore(settings.window_s, settings.frame_rate, settings.late_s)
    storage = Storage(settings.storage_path)
    view = View(settings, store, storage, LatestResults(), ServiceMetrics(store), 900.0)
    gauges = BusMetricsSink(Context(settings, storage, view.latest, view.metrics))
    now = time.time()
    hist = [result(PAGE_BUS, now - 900.0 * k, a=40.0 + k % 7, completed_at=now - 900.0 * k + 20) for k in range(95, -1, -1)]
    SinkChain([StorageSink(storage, 1e9), view.latest, view.metrics, gauges], on_error=print).write_results(hist)
    for k in range(10):
        p = now - 9 * 900.0 * k
        storage.save_diagnosis(PAGE_BUS, p, report(PAGE_BUS, p, ("consistent", "explained")[k % 2], "second_motor"))
    # The fleet's latest results go to memory only (the fleet table never reads SQLite).
    chain = SinkChain([view.latest, view.metrics, gauges], on_error=print)
    batch = [result(f"bus{i:05d}", now - 900.0, "ok" if i % 50 else "failed", a=20.0 + (i * 7919) % 80,
                    completed_at=now - 880.0) for i in range(n_buses) if f"bus{i:05d}" != PAGE_BUS]
    for i in range(0, len(batch), 1000):
        chain.write_results(batch[i:i + 1000])
    for i in range(0, n_buses, 10):
        chain.write_diagnosis(f"bus{i:05d}", now - 900.0, report(f"bus{i:05d}", now - 900.0,
                                                                  ("consistent", "explained", "unexplained")[i % 3]))
    server = HttpServer(create_app(view), "127.0.0.1", 0)
    server.start()
    return server, view


def http_times(url: str, repeat: int) -> dict[str, list[float]]:
    """Wall times [ms] of the server side of each page view and of a Prometheus scrape."""
    paths = {
        "GET /fleet (first page of 100)": "/fleet?limit=100",
        "GET /fleet sorted by a, descending": "/fleet?limit=100&sort=a&desc=true",
        "GET /fleet filtered (failed)": "/fleet?limit=100&state=failed",
        "GET /fleet page 50 of 100": "/fleet?limit=100&offset=4900",
        "GET /metrics (per-bus gauges)": "/metrics",
    }
    out: dict[str, list[float]] = {}
    with httpx.Client(base_url=url, timeout=60) as client:
        for label, path in paths.items():
            client.get(path).raise_for_status()
            times = []
            for _ in range(repeat * 4):
                t0 = time.perf_counter()
                client.get(path).raise_for_status()
                times.append(1e3 * (time.perf_counter() - t0))
            out[label] = times
    return out


def server_cpu(view: View, repeat: int) -> dict[str, list[float]]:
    """CPU time [ms] of this process building a /fleet answer (rows, filter/sort/page, counts, JSON).

    Wall times on a shared machine measure the other jobs too; this is the work a page view costs.
    """
    out: dict[str, list[float]] = {"/fleet answer, CPU (rows + sort by a + page + JSON)": []}
    for _ in range(repeat * 4):
        t0 = time.process_time()
        rows = fleet.fleet_rows(view.latest, view.store.buses(), time.time(), view.period_s)
        matched, page = fleet.select(rows, sort="a", desc=True, limit=100)
        fleet.FleetPage(total=len(rows), matched=matched, offset=0, limit=100, sort="a", desc=True,
                        counts=fleet.counts(rows), now=time.time(), period_s=view.period_s,
                        rows=page).model_dump_json()
        out["/fleet answer, CPU (rows + sort by a + page + JSON)"].append(1e3 * (time.process_time() - t0))
    return out


def browser_times(url: str, repeat: int, profile: Path) -> dict[str, list[float]]:
    """Times [ms] in Chromium: loads from navigation start to the first drawn data, and interactions."""
    out: dict[str, list[float]] = {k: [] for k in (
        "fleet page load (navigation → 100 rows drawn)", "next page (click → drawn)",
        "sort by a (click → drawn)", "filter by name (typed → drawn, incl. 250 ms debounce)",
        "bus page load (navigation → charts drawn, 96 periods)")}
    driver = headless_chromium(profile)
    try:
        driver.set_window_size(1400, 1800)
        for _ in range(repeat):
            driver.get("about:blank")
            driver.get(f"{url}/ui/")
            wait_js(driver, "return document.querySelector('#fleet')?.dataset.shown === '100'", 60, 0.01)
            out["fleet page load (navigation → 100 rows drawn)"].append(
                float(wait_js(driver, "return document.body.dataset.firstRenderMs", 10, 0.01)))
            out["next page (click → drawn)"].append(driver.execute_async_script(
                _TIMED % "() => document.querySelector('#next').click()"))
            out["sort by a (click → drawn)"].append(driver.execute_async_script(
                _TIMED % "() => document.querySelector(\"th[data-sort='a']\").click()"))
            out["filter by name (typed → drawn, incl. 250 ms debounce)"].append(driver.execute_async_script(
                _TIMED % "() => { const q = document.querySelector('#q'); q.value = 'bus0999'; "
                         "q.dispatchEvent(new Event('input')); }"))
            driver.get("about:blank")
            driver.get(f"{url}/ui/#/bus/{PAGE_BUS}")
            wait_js(driver, "return +document.querySelector('#chart-Tm')?.dataset.points === 96", 60, 0.01)
            out["bus page load (navigation → charts drawn, 96 periods)"].append(
                float(wait_js(driver, "return document.body.dataset.firstRenderMs", 10, 0.01)))
        driver.save_screenshot(str(profile.parent / "bus-page.png"))
        driver.get(f"{url}/ui/")
        wait_js(driver, "return document.querySelector('#fleet')?.dataset.shown === '100'", 60, 0.01)
        driver.save_screenshot(str(profile.parent / "fleet-page.png"))
    finally:
        driver.quit()
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--buses", type=int, default=10000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--out", type=Path, default=None, help="keep the screenshots here (default: a temporary folder)")
    args = ap.parse_args(argv)
    if (why := missing()) is not None:
        sys.exit(f"cannot run: {why}")
    tmp = args.out or Path(tempfile.mkdtemp(prefix="aslm-dash-"))
    tmp.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    server, view = build(args.buses, tmp)
    print(f"{args.buses} buses served in {time.perf_counter() - t0:.1f} s set-up; "
          f"/metrics is {len(view.metrics.render()) / 1e6:.1f} MB")
    url = f"http://127.0.0.1:{server.port}"
    load0 = os.getloadavg()[0]
    try:
        rows = {**server_cpu(view, args.repeat), **http_times(url, args.repeat),
                **browser_times(url, args.repeat, tmp / "profile")}
    finally:
        server.stop()
    print(f"\nload average {load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the end ({os.cpu_count()} cores)")
    print(f"\n| what ({args.buses} buses) | median [ms] | max [ms] | n |\n|---|---|---|---|")
    for label, times in rows.items():
        print(f"| {label} | {statistics.median(times):.0f} | {max(times):.0f} | {len(times)} |")
    print(f"\nscreenshots in {tmp}")


if __name__ == "__main__":
    main()
