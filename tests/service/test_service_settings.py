"""Settings precedence (TOML < env < CLI) and refusal of invalid values."""

from __future__ import annotations

import pytest

from service.settings import SettingsError, load_settings
from service.sinks import SINKS
from service.sources import SOURCES


def test_defaults():
    # tests/test_hermetic.py runs this test with ASLM_* variables set: the defaults must still hold.
    s = load_settings()
    assert (s.prefix, s.period_s, s.window_s, s.frame_rate, s.workers, s.executor) == (
        "aslm", 900.0, 10.0, 50.0, 2, "local")
    assert (s.n_starts, s.n_starts_warm) == (3, 1)
    assert s.objective == "paper"
    assert (s.sources, s.sinks) == (["zenoh"], ["storage", "zenoh"])


def test_precedence_toml_env_cli(tmp_path, monkeypatch):
    cfg = tmp_path / "aslm.toml"
    cfg.write_text('period_s = 120\nworkers = 3\nprefix = "grid"\nzenoh_connect = ["tcp/127.0.0.1:7447"]\n')
    s = load_settings(cfg)
    assert (s.period_s, s.workers, s.prefix, s.zenoh_connect) == (120, 3, "grid", ["tcp/127.0.0.1:7447"])
    monkeypatch.setenv("ASLM_PERIOD_S", "60")
    monkeypatch.setenv("ASLM_ZENOH_CONNECT", '["tcp/10.0.0.1:7447"]')
    s = load_settings(cfg)
    assert (s.period_s, s.workers, s.zenoh_connect) == (60, 3, ["tcp/10.0.0.1:7447"])
    s = load_settings(cfg, period_s=30, workers=None)  # None: flag not given
    assert (s.period_s, s.workers) == (30, 3)
    monkeypatch.setenv("ASLM_CONFIG", str(cfg))
    assert load_settings().prefix == "grid"


@pytest.mark.parametrize("overrides,needle", [
    ({"period_s": 5, "window_s": 10}, "period_s (5 s) must be at least window_s + late_s"),
    ({"workers": -1}, "workers"),
    ({"workers": 0}, "workers"),
    ({"n_starts_warm": -1}, "n_starts_warm"),
    ({"n_starts": 0}, "n_starts must be a positive count"),
    ({"objective": "l1"}, "objective"),
    ({"executor": "spark"}, "executor must be 'local' or a Dask scheduler address"),
    ({"prefix": "aslm/**"}, "prefix"),
    ({"late_s": -1}, "late_s must be >= 0"),
    ({"http_port": 70000}, "http_port"),
    ({"storage_url": "postgres://x"}, None),
    ({"no_such_field": 1}, "no_such_field"),
    # the known names come from the registries, so adding a source or sink does not touch this test
    ({"sources": ["no-such-source"]}, f"unknown sources ['no-such-source']; known: {sorted(SOURCES)}"),
    ({"sinks": ["storage", "kafka"]}, f"unknown sinks ['kafka']; known: {sorted(SINKS)}"),
    ({"sinks": ["zenoh", "zenoh"]}, "sinks repeated"),
    # The bounds PUT /config applies hold for the start-up settings too (issue 17, defect 2).
    ({"period_s": float("nan")}, "period_s"),
    ({"period_s": float("inf")}, "period_s"),
    ({"period_s": 1e12}, "period_s (1e+12 s) must be at most 86400 s"),
    ({"window_s": float("inf")}, "window_s"),
    ({"late_s": float("nan")}, "late_s"),
    ({"task_timeout_s": float("inf")}, "task_timeout_s"),
])
def test_invalid_values_refused_with_clear_message(overrides, needle):
    if needle is None:  # checked when the path is used
        with pytest.raises(ValueError, match="only SQLite"):
            _ = load_settings(**overrides).storage_path
        return
    with pytest.raises(SettingsError) as info:
        load_settings(**overrides)
    assert needle in str(info.value)


def test_invalid_env_refused(monkeypatch):
    monkeypatch.setenv("ASLM_WORKERS", "many")
    with pytest.raises(SettingsError, match="workers"):
        load_settings()


def test_missing_file_refused(tmp_path):
    with pytest.raises(SettingsError, match="does not exist"):
        load_settings(tmp_path / "nope.toml")


def test_dask_address_accepted_and_token_masked():
    s = load_settings(executor="tcp://scheduler:8786", operator_token="secret")
    assert s.executor == "tcp://scheduler:8786"
    assert s.public_dict()["operator_token"] == "***"
    assert "secret" not in repr(s)


def test_non_finite_period_from_the_environment_is_refused(monkeypatch):
    monkeypatch.setenv("ASLM_PERIOD_S", "inf")
    with pytest.raises(SettingsError, match="period_s"):
        load_settings()


def test_input_noise_follows_the_sources_unless_set(tmp_path):
    """PMU streams over a grid protocol always carry a PMU's noise: 'measured' unless set; the synthetic fleet's
    Zenoh default 'auto' (its inputs are simulated); an explicit setting wins."""
    assert load_settings().identify_input_noise == "auto"
    mapping = tmp_path / "pdc.toml"
    mapping.write_text("")
    cfg = tmp_path / "aslm.toml"
    cfg.write_text(f'sources = ["c37118"]\npmu_mapping = "{mapping}"\n')
    assert load_settings(cfg).identify_input_noise == "measured"
    cfg.write_text(f'sources = ["c37118"]\npmu_mapping = "{mapping}"\ninput_noise = "auto"\n')
    assert load_settings(cfg).identify_input_noise == "auto"
    cfg.write_text('input_noise = "measured"\n')
    assert load_settings(cfg).identify_input_noise == "measured"
    cfg.write_text('input_noise = "filtered"\n')
    with pytest.raises(SettingsError, match="input_noise"):
        load_settings(cfg)
