"""The dashboard in a real browser: headless Debian Chromium (Selenium, system chromedriver) on a running
service fed by the synthetic fleet over Zenoh, with the real identifier in spawned workers.

Screenshots of each page are saved in the test's temporary folder (the path is printed with ``-s``)."""

from __future__ import annotations

import re
import time

import httpx
import pytest
from browser_helpers import CANVAS_INK, headless_chromium, missing, wait_js
from service_helpers import client_session, free_port, periods, settings_for, wait_for

from aslm_sim.fleet import SyntheticFleet
from service.app import Service
from service.replay import FleetReplayer, FramePublisher

pytestmark = [pytest.mark.slow, pytest.mark.skipif(missing() is not None, reason=str(missing()))]

N_BUSES = 6
PERIOD_S = 12.0


def static_cells_match(driver, url: str) -> bool:
    """Whether every row's static cell shows its bus's static_local from ``GET /fleet`` (to the digits shown)
    and hides the Z/I/P split exactly where the flags say it is unidentifiable (False while the page and the API
    show different periods)."""
    api = {r["bus"]: r for r in httpx.get(f"{url}/fleet", timeout=5).json()["rows"]}
    cells = driver.execute_script("""
        return [...document.querySelectorAll('#fleet tbody tr')].map(tr => {
            const s = tr.querySelector('td.static-col span.static');
            return [tr.dataset.bus, s ? s.firstChild.textContent : '', s ? s.dataset.split : '', s ? s.textContent : '']; });""")
    for bus, text, split, whole in cells:
        loc, flags = api[bus]["static_local"], api[bus]["flags"]
        shown = dict(re.findall(r"(P0|kpv|Q0|kqv) (-?\d[\d.e+-]*)", text))  # "–" (no value) does not match
        if set(shown) != {"P0", "kpv", "Q0", "kqv"}:
            return False
        shown = {k: float(v) for k, v in shown.items()}
        if any(shown[k] != pytest.approx(loc[k], rel=6e-3) for k in shown):
            return False
        hidden = "static_split_unidentifiable" in flags
        if split != ("unidentifiable" if hidden else "identifiable") or (hidden and "Pz" in whole):
            return False
    return bool(cells)


def test_fleet_table_and_bus_page_in_chromium(tmp_path):
    zport = free_port()
    settings = settings_for(tmp_path, zport, period_s=PERIOD_S, window_s=10.0, late_s=1.0, task_timeout_s=120,
                            diagnose_every=0)
    with Service(settings) as svc:
        sess = client_session(zport)
        fleet = SyntheticFleet(N_BUSES, level=None, seed=1, t0=time.time())
        pub = FramePublisher(sess, "aslm")
        rep = FleetReplayer(pub, fleet, batch_s=0.2).start()
        driver = headless_chromium(tmp_path / "profile")
        try:
            wait_for(lambda: [p for p in periods(svc.url) if p["n_ok"] == N_BUSES], 150, 0.5)

            # The fleet table: every bus, each with its identified D (no "–" left in the D columns).
            driver.get(svc.url + "/")
            assert driver.current_url.endswith("/ui/")
            wait_js(driver, "return document.querySelector('#fleet')?.dataset.shown === arguments[0]"
                    .replace("arguments[0]", f"'{N_BUSES}'"), 30)
            rows = wait_js(driver, """
                const rows = [...document.querySelectorAll('#fleet tbody tr')].map(tr =>
                    [tr.dataset.bus, ...[...tr.children].slice(2, 6).map(td => td.firstChild.textContent)]);
                return rows.every(r => r.slice(1).every(v => v !== '–')) && rows;""", 30)
            assert [r[0] for r in rows] == sorted(fleet.bus_names)
            truth = rep.truth()
            for bus, *d in rows:  # what the page shows is what was identified: close to the truth
                for shown, k in zip(d, ("a", "b", "H2", "Tm"), strict=True):
                    assert float(shown) == pytest.approx(truth[bus]["dynamic"][k], rel=0.15), (bus, k, shown)
            assert "state-ok" in driver.find_element("css selector", "#fleet tbody tr").get_attribute("class")
            # The static column shows what ambient data identify, P0, kpv, Q0, kqv at V0, as the REST rows have
            # them, and leaves the Z/I/P split out of the cell where the identifier flags it unidentifiable.
            assert wait_for(lambda: static_cells_match(driver, svc.url), 20, 1.0)
            driver.save_screenshot(str(tmp_path / "fleet.png"))

            # Sorting by a column happens on the server and shows in the page.
            driver.find_element("css selector", "th[data-sort='a']").click()
            wait_js(driver, "return document.querySelector(\"th[data-sort='a']\").classList.contains('sorted')", 10)
            a_col = wait_js(driver, """
                const v = [...document.querySelectorAll('#fleet tbody tr')].map(tr => +tr.children[2].firstChild.textContent);
                return v.every((x, i) => i === 0 || v[i - 1] <= x) && v;""", 10)
            assert len(a_col) == N_BUSES

            # A bus page: its history charts and measured-vs-model charts are drawn.
            bus = fleet.bus_names[0]
            driver.set_window_size(1400, 1800)  # the whole bus page in its screenshots
            driver.find_element("css selector", f"#fleet tbody tr[data-bus='{bus}'] a").click()
            wait_js(driver, "return document.querySelector('#bus-name')?.textContent === arguments[0]"
                    .replace("arguments[0]", f"'{bus}'"), 10)
            wait_js(driver, "return +document.querySelector('#chart-a').dataset.points >= 1", 30)
            # The history's time axis spans the periods shown (a lone point: one period each side), not the
            # ~3 years uPlot gives a single time point by itself.
            pts, xspan = wait_js(driver, "const c = document.querySelector('#chart-a').dataset; "
                                 "return c.xspan && [+c.points, +c.xspan];", 10)
            assert xspan == 2 * PERIOD_S if pts == 1 else 0 < xspan < 3600, (pts, xspan)
            split = wait_js(driver, "return document.querySelector('#static-split')?.dataset.split", 10)
            latest = httpx.get(f"{svc.url}/buses/{bus}/parameters/latest", timeout=5).json()["parameters"]
            assert split == ("unidentifiable" if "static_split_unidentifiable" in latest["flags"] else "identifiable")
            # The excitation indicator: how much of P and Q the voltage explains, as the result's quality has it.
            excitation = wait_js(driver, "return document.querySelector('#excitation')?.textContent", 10)
            ok = [r["parameters"] for r in httpx.get(f"{svc.url}/buses/{bus}/parameters?limit=50", timeout=5).json()
                  if r["status"] == "ok"]
            assert excitation.startswith("V and θ explain ") and "of P's ambient std" in excitation
            pct_p, pct_q = (int(x.split(" %")[0]) for x in excitation.split("explain ")[1].split(" of P's and "))
            # The page shows its newest ok result's quality; results keep coming, so one of the bus's recent ones.
            assert (pct_p, pct_q) in {(round(100 * q["excitation_share_p"]), round(100 * q["excitation_share_q"]))
                                      for q in (p["quality"] for p in ok)}
            # The estimator the workers ran is named as the result records it (the library's default here).
            estimator = wait_js(driver, "return document.querySelector('#estimator')?.textContent", 10)
            assert estimator == (f"inputs {latest['config']['input_smoother']}, weighting "
                                 f"{latest['config']['input_weighting']}, disturbance {latest['config']['disturbance']}"
                                 + (" on P and Q − k·P" if latest["config"]["couple_channels"] else ""))
            assert "weighting spectral" in estimator and "disturbance gated on P and Q − k·P" in estimator
            assert driver.execute_script(CANVAS_INK, "#chart-a") > 200
            wait_js(driver, "return +document.querySelector('#chart-P').dataset.points > 100", 60)
            assert driver.execute_script(CANVAS_INK, "#chart-P") > 200
            assert driver.execute_script(CANVAS_INK, "#chart-Q") > 200
            first = driver.execute_script("return document.querySelector('#summary').dataset.latestPeriod")
            n_first = int(driver.execute_script("return document.querySelector('#chart-a').dataset.points"))
            driver.save_screenshot(str(tmp_path / "bus.png"))

            # It updates itself after the next period: a newer latest result, one more point in the history.
            wait_js(driver, f"return document.querySelector('#summary').dataset.latestPeriod > '{first}'",
                    PERIOD_S + 45)
            wait_js(driver, f"return +document.querySelector('#chart-a').dataset.points > {n_first}", 15)
            assert driver.execute_script(CANVAS_INK, "#chart-a") > 200
            driver.save_screenshot(str(tmp_path / "bus-next-period.png"))
            assert not driver.execute_script("return document.querySelector('#error').hidden === false")
            print(f"screenshots in {tmp_path}")
        finally:
            driver.quit()
            rep.stop()
            pub.close()
            sess.close()
    assert rep.error is None
