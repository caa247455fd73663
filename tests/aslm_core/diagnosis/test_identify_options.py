"""The identifier options the diagnosis relies on are pinned, not inherited from IdentifyConfig's defaults."""

from __future__ import annotations

import dataclasses

import pytest

from aslm_core.diagnosis.identify_options import PINNED, pinned_config
from aslm_core.result import IdentifyConfig


def test_every_identifier_option_is_pinned():
    # A new IdentifyConfig field would otherwise reach the diagnosis through its default, unnoticed.
    assert {f.name for f in dataclasses.fields(IdentifyConfig)} == set(PINNED)


def test_the_pinned_values_reach_the_config_and_overrides_apply():
    cfg = pinned_config(skip_s=0.5, n_starts=1)
    assert cfg.skip_s == 0.5 and cfg.n_starts == 1
    assert cfg.input_weighting == PINNED["input_weighting"] == "none"
    assert all(getattr(cfg, k) == v for k, v in PINNED.items() if k not in ("skip_s", "n_starts"))


def test_an_unknown_option_is_refused():
    with pytest.raises(TypeError, match="not a pinned"):
        pinned_config(input_weighting_typo="spectral")
