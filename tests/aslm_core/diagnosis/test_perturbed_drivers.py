"""The noise model's input-noise draws reach Δf and dV/dt as the measured noise does (docs/diagnosis.md, stop 31)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from aslm_core.diagnosis.noise import perturbed
from aslm_core.diagnosis.segment import make_segment
from aslm_sim.cases import make_case


@pytest.fixture(scope="module")
def window():
    return replace(make_case(5, level=2, input_noise=False).window, f=None)


def _draw(n: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(7)
    return 1e-3 * rng.standard_normal(n), 1e-3 * rng.standard_normal(n)


def test_a_draw_moves_the_drivers_as_a_noisy_window_would(window):
    seg = make_segment(window)
    ev, et = _draw(seg.n)
    # The measured inputs (no conditional mean): the draw's change is the window's.
    noisy = make_segment(replace(window, V=window.V + ev, theta=window.theta + et), input_mean=False)
    p = perturbed(seg, seg.V + ev, seg.theta + et)
    assert np.allclose(p.vd, noisy.vd) and np.allclose(p.vq, noisy.vq)
    # dV/dt is linear in V; Δf too but for its median, a constant.
    assert np.max(np.abs(p.dvdt - noisy.dvdt)) < 1e-9 * np.max(np.abs(noisy.dvdt - seg.dvdt))
    off = p.dfreq - noisy.dfreq
    moved = np.max(np.abs(noisy.dfreq - seg.dfreq))
    assert moved > 0.0 and np.ptp(off) < 1e-9 * moved


def test_a_recorded_frequency_is_not_moved_by_theta(window):
    seg = make_segment(replace(window, f=window.f0 + 0.01 * np.sin(window.t)))
    assert not seg.dfreq_from_theta
    ev, et = _draw(seg.n)
    p = perturbed(seg, seg.V + ev, seg.theta + et)
    assert np.array_equal(p.dfreq, seg.dfreq)
    assert not np.array_equal(p.dvdt, seg.dvdt)
