"""Headless Debian Chromium driven by Selenium through the system chromedriver (no browser download).

Used by the dashboard's browser tests and its page-load benchmark.  ``scripts/setup`` installs the
``chromium`` and ``chromium-driver`` packages where they are missing.
"""

from __future__ import annotations

import shutil
import time
from pathlib import Path

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"

# Headless, and none of the background traffic a closed network refuses (component updates, sync,
# first-run pages); a fresh profile each time.
FLAGS = ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--window-size=1400,1000")


def missing() -> str | None:
    """Why a browser test cannot run here (None when it can)."""
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed (the dev extra)"
    for path in (CHROMIUM, CHROMEDRIVER):
        if not Path(path).is_file():
            return f"{path} is missing: scripts/setup installs Debian's chromium and chromium-driver"
    return None


def headless_chromium(profile: Path):
    """A Selenium Chrome driver on Debian's chromium, with a fresh profile in ``profile``."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for flag in FLAGS:
        opts.add_argument(flag)
    opts.add_argument(f"--user-data-dir={profile}")
    return webdriver.Chrome(options=opts, service=Service(executable_path=CHROMEDRIVER))


def wait_js(driver, script: str, timeout: float, interval: float = 0.1):
    """Run ``script`` (a JS expression body, e.g. ``return ...``) until it returns something truthy."""
    end = time.monotonic() + timeout
    while True:
        value = driver.execute_script(script)
        if value:
            return value
        if time.monotonic() > end:
            raise TimeoutError(f"not true within {timeout} s: {script}")
        time.sleep(interval)


#: JS: non-transparent pixels of the canvases under the element given as arguments[0] (a CSS selector).
CANVAS_INK = """
let n = 0;
for (const c of document.querySelectorAll(arguments[0] + ' canvas')) {
  const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
  for (let i = 3; i < d.length; i += 4) if (d[i] > 0) n++;
}
return n;
"""
