"""`aslm diagnose` end to end: real files, a real subprocess, JSON fields, report files."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from aslm_sim.cases import make_case
from aslm_sim.effects import apply_effect
from service.files import write_window

ROOT = Path(__file__).resolve().parents[2]


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "service.cli", *args], capture_output=True, text=True, cwd=ROOT,
                          timeout=300)


@pytest.fixture(scope="module")
def skewed(tmp_path_factory):
    d = tmp_path_factory.mktemp("diag")
    ec = apply_effect(make_case(31, level=3, input_noise=False), "measurement_skew", 0.03, seed=4)
    path = d / "skewed.npz"
    write_window(path, ec.window)
    model = d / "model.json"
    tr = ec.base.truth
    model.write_text(json.dumps({"dynamic": tr.dynamic, "static": tr.static_identifiable}))
    return path, model, d


def test_cli_json_fields_and_report_files(skewed):
    path, _, d = skewed
    out = d / "report"
    proc = run_cli("diagnose", str(path), "--json", "--report", str(out))
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    assert res["verdict"] == "explained" and res["cause"] == "measurement_skew"
    for k in ("verdict", "located", "missing_physics", "fit_before", "fit_after"):
        assert k in res
    assert res["missing_physics"][0]["name"] == "measurement_skew"
    assert res["fit_after"]["fd_p"] > res["fit_before"]["fd_p"]
    for name in ("report.md", "report.json", "overlay.png", "spectrum.png", "coherence.png"):
        f = out / name
        assert f.exists() and f.stat().st_size > 500, name
    assert (out / "overlay.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "measurement_skew" in (out / "report.md").read_text()
    assert res["held_out"]["folds"] == 2 and len(res["held_out"]["t_start"]) == 2
    one = run_cli("diagnose", str(path), "--json", "--one-fold")
    assert one.returncode == 0, one.stderr
    res1 = json.loads(one.stdout)
    assert res1["held_out"]["folds"] == 1 and res1["held_out"]["n"] * 2 == res["held_out"]["n"]
    assert res1["cause"] == "measurement_skew"


def test_cli_with_user_model_and_bad_file(skewed):
    path, model, d = skewed
    proc = run_cli("diagnose", str(path), "--json", "--model", str(model))
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    # The skew is the only departure from the true model: named, as against an identified one.
    assert res["mode"] == "user" and res["verdict"] == "explained" and res["cause"] == "measurement_skew"
    assert res["parameter_mismatch"]["significant"] is False
    bad = d / "bad.txt"
    bad.write_text("x")
    proc = run_cli("diagnose", str(bad), "--json")
    err = json.loads(proc.stdout)
    assert proc.returncode == 1 and err["reason"] == "input" and "unsupported file type '.txt'" in err["error"]
