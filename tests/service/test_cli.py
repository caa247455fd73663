"""`aslm identify` end to end: real files, a real subprocess, the JSON contract of DESIGN §4."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from aslm_sim.cases import make_case
from service.files import write_window


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    d = tmp_path_factory.mktemp("rec")
    case = make_case(21, level=3, input_noise=False)
    write_window(d / "bus.npz", case.window)
    write_window(d / "bus.csv", case.window)
    np.savez(d / "broken.npz", t=case.window.t, V=case.window.V)  # no theta, P, Q
    return d, case


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "service.cli", *args], capture_output=True, text=True,
                          timeout=300)


def test_identify_json_one_line_per_file_with_contract_fields(recordings):
    d, case = recordings
    proc = run_cli("identify", "--json", str(d / "bus.npz"), str(d / "bus.csv"))
    assert proc.returncode == 0, proc.stderr
    lines = [json.loads(x) for x in proc.stdout.splitlines()]
    assert len(lines) == 2
    for out in lines:
        assert set(out["dynamic"]) == {"a", "b", "H2", "Tm"}
        assert set(out["static"]) == {"Pz", "Pi", "Pp", "Qz", "Qi", "Qp"}
        assert out["objective"] > 0 and set(out["fit"]) == {"fd_p", "fd_q"}
        assert 0 < out["elapsed_s"] < 5
        d_out = np.array([out["dynamic"][k] for k in ("a", "b", "H2", "Tm")])
        np.testing.assert_allclose(d_out, case.truth.d, rtol=0.05)
        # One default with the Python API and the service (issues 11 and 20).
        assert out["config"]["disturbance"] == "gated" and out["config"]["input_weighting"] == "spectral"
    # .npz and .csv hold the same samples: the same answer.
    assert lines[0]["dynamic"] == pytest.approx(lines[1]["dynamic"], rel=1e-9)


def test_identify_reports_bad_file_and_goes_on(recordings):
    d, _ = recordings
    proc = run_cli("identify", "--json", str(d / "broken.npz"), str(d / "bus.npz"))
    assert proc.returncode == 1
    first, second = (json.loads(x) for x in proc.stdout.splitlines())
    assert "missing column" in first["error"] and "theta" in first["error"]
    assert "dynamic" in second


def test_f0_flag_overrides_the_file(recordings):
    d, _ = recordings
    at50 = json.loads(run_cli("identify", "--json", str(d / "bus.npz")).stdout)
    at60 = json.loads(run_cli("identify", "--json", "--f0", "60", str(d / "bus.npz")).stdout)
    # ω0 enters eq. 4 only through s·ω0 and ds/dt ∝ 1/H2, so the data fix H2/ω0: H2 scales with f0.
    assert at60["dynamic"]["H2"] == pytest.approx(at50["dynamic"]["H2"] * 60 / 50, rel=1e-3)
    assert at60["dynamic"]["a"] == pytest.approx(at50["dynamic"]["a"], rel=1e-3)


def test_human_output_shows_the_identifiable_static_part_and_the_disturbance_flag_works(recordings):
    d, case = recordings
    proc = run_cli("identify", str(d / "bus.npz"))
    assert proc.returncode == 0, proc.stderr
    assert "static at V0=" in proc.stdout and "dPdV=" in proc.stdout and "static_split_unidentifiable" in proc.stdout
    # The identifiable part first; the split after it, with its standard errors and said to be unidentifiable.
    split = proc.stdout.split("static split: ")[1].splitlines()[0]
    assert proc.stdout.index("static at V0=") < proc.stdout.index("static split: ")
    assert "Pz=" in split and "±" in split and split.endswith("(not identifiable from this window)")
    out = json.loads(run_cli("identify", "--json", "--disturbance", "ar", str(d / "bus.npz")).stdout)
    assert out["config"]["disturbance"] == "ar" and "ar_order_p" in out["quality"]
    iv = json.loads(run_cli("identify", "--json", "--disturbance", "ar_iv", str(d / "bus.npz")).stdout)
    assert iv["config"]["disturbance"] == "ar_iv" and 0.0 < iv["quality"]["iv_strength_p"] <= 1.0
    gated = json.loads(run_cli("identify", "--json", "--disturbance", "gated", "--input-weighting", "spectral",
                               str(d / "bus.npz")).stdout)
    assert gated["config"]["disturbance"] == "gated" and gated["config"]["input_weighting"] == "spectral"
    assert gated["quality"]["gated_ar_iv"] in (0.0, 1.0)
    assert {"P0", "dPdV", "Q0", "dQdV"} <= set(out["static_local"])


def test_identify_warns_in_words_when_the_input_noise_swamps_v(tmp_path, capsys):
    from service.cli import main

    w = make_case(21, level=2, input_noise=False).window
    rng = np.random.default_rng(0)
    noisy = type(w)(t=w.t, V=w.V + 1e-2 * rng.standard_normal(w.V.size),
                    theta=w.theta + 1e-2 * rng.standard_normal(w.V.size), P=w.P, Q=w.Q, f0=w.f0)
    write_window(tmp_path / "noisy.npz", noisy)
    assert main(["identify", str(tmp_path / "noisy.npz")]) == 0
    out = capsys.readouterr().out
    assert "input_noise_too_large" in out and "warning: input noise too large" in out and "not trustworthy" in out


def test_identify_says_in_words_when_the_loads_own_fluctuation_chose_the_estimator(tmp_path, capsys):
    from aslm_sim.cases import make_cases
    from service.cli import main

    # Grid-excited windows whose own fluctuation is about 0.6 of P's ambient std: the default's gate opens.
    cases = make_cases(3, level=2, seed=21, input_noise=False, own_sigma=0.0015)
    for i, c in enumerate(cases):
        write_window(tmp_path / f"own{i}.npz", c.window)
    assert main(["identify", *(str(tmp_path / f"own{i}.npz") for i in range(3))]) == 0
    out = capsys.readouterr().out
    assert "estimator: instrumental variables" in out and "of P's ambient std" in out
    assert "half of its variance below " in out  # the own fluctuation's spectrum (lowpass 2 Hz here: near 1 Hz)
    assert ("iv_error_may_exceed_20pct" in out) == ("an error above 20 % is not a rare draw" in out)


def test_identify_says_in_words_when_the_input_noise_correction_moved_d_far(tmp_path, capsys):
    """The own bench's seed-245 window 28 (0.1 % / 1e-3 rad): the S-weighted answer is 2.6 SE from output error's
    without the spectrum's tail (2.7 before stop 49's 4 Hz band; with the tail, the default, no such warning); the
    words give that distance, above the flag's threshold."""
    import re

    from aslm_core.identify import WEIGHTED_SHIFT_Z_MAX
    from benchmarks.own_fluctuation import bench_window
    from service.cli import main

    w, _ = bench_window(28, 0.0, "lowpass", 2, seed=245)
    write_window(tmp_path / "w.npz", w)
    assert main(["identify", "--no-input-spectrum-tail", str(tmp_path / "w.npz")]) == 0
    out = capsys.readouterr().out
    said = re.search(r"the input-noise correction moved D by ([0-9.]+) of its standard", out)
    assert "input_noise_correction_large" in out and said and float(said.group(1)) > WEIGHTED_SHIFT_Z_MAX
