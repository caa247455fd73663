"""What ambient data identify of the static part (level, slope, flagged split) and the excitation indicators."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from aslm_core import IdentifyConfig, identify
from aslm_sim.cases import make_cases
from tests.conftest import ZIP_P, equation_window


@pytest.fixture(scope="module")
def level3():
    cases = make_cases(24, level=3, seed=12, input_noise=False)
    return cases, [identify(c.window) for c in cases]


def _true_local(tr, v0: float) -> tuple[float, float]:
    return tr.Pz * v0 * v0 + tr.Pi * v0 + tr.Pp, 2.0 * tr.Pz * v0 + tr.Pi


def test_level_and_slope_of_the_static_part_are_recovered_with_calibrated_errors(level3):
    cases, results = level3
    z0, zd = [], []
    for c, r in zip(cases, results, strict=True):
        sl = r.static_local
        p0, dpdv = _true_local(c.truth, sl["V0"])
        assert sl["P0"] == pytest.approx(p0, abs=4 * sl["P0_se"])
        assert sl["dPdV"] == pytest.approx(dpdv, abs=4 * sl["dPdV_se"])
        assert sl["kpv"] == pytest.approx(sl["dPdV"] * sl["V0"] / sl["P0"])
        z0.append((sl["P0"] - p0) / sl["P0_se"])
        zd.append((sl["dPdV"] - dpdv) / sl["dPdV_se"])
    for z in (np.array(z0), np.array(zd)):
        assert 0.8 <= np.mean(np.abs(z) < 1.96) <= 1.0, z


def test_collinear_static_split_is_flagged_not_silent(level3):
    _, results = level3
    for r in results:
        assert "static_split_unidentifiable" in r.flags
        assert r.quality["static_cond"] > 1e4
        assert set(r.static_stderr) == set(r.static)
        # The coefficients it would otherwise present as an answer are uncertain by more than 10 % of the load.
        assert max(r.static_stderr.values()) > 0.1 * abs(r.static_local["P0"])


def test_wide_voltage_swing_identifies_the_split_without_the_flag():
    w = equation_window(v_std=0.03)
    r = identify(w)
    assert "static_split_unidentifiable" not in r.flags
    # ZIP_P is (Pz, Pi, Pp); Q is not compared: the motor's V²/X' joins Qz (paper §II.B.2).
    for name, true in zip(("Pz", "Pi", "Pp"), ZIP_P, strict=True):
        assert r.static[name] == pytest.approx(true, abs=max(4 * r.static_stderr[name], 1e-3))


def test_exponential_model_reports_its_exponent_with_an_error(level3):
    cases, _ = level3
    r = identify(cases[0].window, config=IdentifyConfig(static="exponential"))
    assert set(r.static_stderr) == {"P0", "np", "Q0", "nq"}
    assert "static_split_unidentifiable" not in r.flags
    assert np.isfinite(r.static_stderr["np"]) and r.static_stderr["np"] > 0


def test_excitation_share_is_near_one_without_own_fluctuation(level3):
    _, results = level3
    share = np.array([r.quality["excitation_share_p"] for r in results])
    own = np.array([r.quality["own_ratio_p"] for r in results])
    assert np.median(share) > 0.95 and share.min() > 0.85
    assert np.median(own) < 0.15
    # Nothing above the white floor: the own spectrum's reading is mostly absent (2 of 24 here), not the floor's scatter.
    assert sum("own_median_hz_p" in r.quality for r in results) <= 6


def test_result_dict_carries_the_new_keys_additively(level3):
    _, results = level3
    d = results[0].to_dict()
    assert {"static_local", "static_stderr"} <= set(d)
    assert dataclasses.asdict(results[0])["static"] == results[0].static
