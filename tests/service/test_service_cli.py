"""The service sub-commands as a user runs them (real subprocesses)."""

from __future__ import annotations

import os
import re
import sqlite3
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def aslm(*args: str, timeout: float, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "service.cli", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout, env={**os.environ, **(env or {})})


def test_serve_refuses_invalid_settings_with_clear_message():
    r = aslm("serve", "--period", "5", "--window", "10", timeout=60)
    assert r.returncode == 2
    assert "period_s (5 s) must be at least window_s + late_s" in r.stderr
    r = aslm("serve", "--executor", "yarn", timeout=60)
    assert r.returncode == 2 and "executor must be 'local' or a Dask scheduler address" in r.stderr
    r = aslm("serve", timeout=60, env={"ASLM_WORKERS": "-3"})
    assert r.returncode == 2 and "workers" in r.stderr


def test_demo_runs_one_period_exits_and_keeps_its_history(tmp_path):
    out = tmp_path / "demo"
    r = aslm("demo", "--periods", "1", "--period", "12", "--buses", "4", "--port", "0", "--duration", "200",
             "--out", str(out), timeout=260)
    assert r.returncode == 0, r.stderr
    assert "REST: http://127.0.0.1:" in r.stdout
    assert "ok=4 failed=0" in r.stdout
    assert r.stdout.count(" ok ") + r.stdout.count(" ok* ") >= 4
    assert "aslm demo: stopped" in r.stdout
    # The first hour: it says what the start waits for, times are readable, nothing prints "()".
    assert "load the compiled numerical kernels" in r.stdout and "workers ready after" in r.stdout
    assert "()" not in r.stdout and not re.search(r"period \d{9,}", r.stdout)
    assert re.search(r"period \d{4}-\d\d-\d\d \d\d:\d\d:\d\d UTC", r.stdout)
    # The history stays where it said, and a second run would add to it.
    db = out / "aslm-demo.sqlite"
    assert f"history kept in {db}" in r.stdout
    with sqlite3.connect(db) as con:
        assert con.execute("SELECT COUNT(*) FROM results WHERE status = 'ok'").fetchone()[0] >= 4


def test_serve_refuses_an_unusable_storage_path_with_one_line(tmp_path):
    (tmp_path / "file").write_text("not a directory")
    for path in (tmp_path / "file" / "aslm.sqlite", tmp_path):  # below a file; a directory
        r = aslm("serve", "--storage", str(path), "--port", "0", timeout=60)
        assert r.returncode == 2, r.stderr
        lines = r.stderr.strip().splitlines()
        assert lines[-1].startswith(f"aslm serve: storage_url: cannot use {path} as the SQLite file") and len(lines) == 1, r.stderr
