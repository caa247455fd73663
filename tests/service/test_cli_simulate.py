"""`aslm simulate` writes a recording that `aslm identify` and `aslm diagnose` read, with the truth beside it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aslm_core import identify
from service.cli import main
from service.files import read_window


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_simulated_recording_identifies_to_its_truth(tmp_path, capsys, suffix):
    rec, truth_file = tmp_path / f"rec{suffix}", tmp_path / "truth.json"
    assert main(["simulate", str(rec), "--seed", "3", "--level", "0", "--truth", str(truth_file)]) == 0
    out = capsys.readouterr().out
    assert "noise-free" in out and f"aslm identify {rec}" in out
    truth = json.loads(truth_file.read_text())
    window = read_window(rec)
    assert len(window.t) == 1000 and window.f is not None and window.f0 == 50.0
    est = identify(window).dynamic
    for k, true in truth["load"]["dynamic"].items():
        assert est[k] == pytest.approx(true, rel=0.01), k  # noise-free: the identifier recovers D


def test_noise_level_and_seed_are_reproducible(tmp_path, capsys):
    a, b, c = (tmp_path / n for n in ("a.npz", "b.npz", "c.npz"))
    for path, seed in ((a, 3), (b, 3), (c, 4)):
        assert main(["simulate", str(path), "--seed", str(seed), "--level", "2", "--duration", "5"]) == 0
    assert "--lowpass" not in capsys.readouterr().out  # the default handles PMU noise on V and θ
    wa, wb, wc = (read_window(p) for p in (a, b, c))
    assert len(wa.t) == 500 and np.array_equal(wa.P, wb.P) and not np.array_equal(wa.P, wc.P)


def test_effect_recording_goes_through_diagnose(tmp_path, capsys):
    rec, truth_file = tmp_path / "motor2.npz", tmp_path / "truth.json"
    assert main(["simulate", str(rec), "--seed", "1", "--effect", "second_motor", "--truth", str(truth_file)]) == 0
    assert json.loads(truth_file.read_text())["effect"]["name"] == "second_motor"
    capsys.readouterr()
    assert main(["diagnose", str(rec), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["verdict"] in ("explained", "ambiguous", "consistent", "unexplained")


def test_refuses_unknown_effect_and_file_type(tmp_path, capsys):
    assert main(["simulate", str(tmp_path / "x.npz"), "--effect", "gremlins"]) == 2
    assert main(["simulate", str(tmp_path / "x.mat")]) == 2
    err = capsys.readouterr().err
    assert "unknown effect 'gremlins'" in err and "use a .npz or .csv" in err
