"""The effect registry: one module per effect, each registered, and what it declares matches what it makes."""

from __future__ import annotations

import pkgutil

import numpy as np
import pytest

import aslm_sim.effects as effects
from aslm_sim.cases import make_case
from aslm_sim.effects import EFFECTS, LIBRARY_EFFECTS, OUTSIDE_EFFECTS, apply_effect

MACHINERY = {"base", "apply"}


@pytest.fixture(scope="module")
def case():
    return make_case(4, level=2, input_noise=False)


def test_every_effect_module_is_registered_under_its_own_name():
    modules = {m.name for m in pkgutil.iter_modules(effects.__path__)} - MACHINERY
    assert set(EFFECTS) == modules
    assert LIBRARY_EFFECTS + OUTSIDE_EFFECTS == tuple(EFFECTS)  # library first: the benchmark's row order
    assert len({e.label for e in EFFECTS.values()}) == len(EFFECTS)


@pytest.mark.parametrize("name", list(EFFECTS))
def test_declaration_matches_the_generated_effect(case, name):
    e = EFFECTS[name]
    lo, hi = e.magnitude
    assert 0.0 < lo < hi and e.channels in ("P", "Q", "PQ")
    dp, dq, truth = e.generate(case, hi, np.random.default_rng(1))
    assert dp.shape == dq.shape == case.clean.P.shape
    for ch, d in (("P", dp), ("Q", dq)):
        if ch in e.channels:
            assert np.std(d) > 0.0, ch
    if e.in_library:
        assert e.main_parameter in truth
    # Same draws, same effect: concealment retries rely on it.
    dp2, _, truth2 = e.generate(case, hi, np.random.default_rng(1))
    np.testing.assert_array_equal(dp, dp2)
    assert truth == truth2


def test_unknown_effect_is_refused(case):
    with pytest.raises(ValueError, match="unknown effect 'no_such_effect'"):
        apply_effect(case, "no_such_effect")
