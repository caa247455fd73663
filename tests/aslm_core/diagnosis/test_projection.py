"""The compiled lower stage (aslm_core.diagnosis.projection) against the NumPy one it replaced in the upper stage."""

from __future__ import annotations

import numpy as np
import pytest

from aslm_core.diagnosis import engine
from aslm_core.diagnosis.candidates import Prediction
from aslm_core.diagnosis.noise import NoiseModel
from aslm_core.diagnosis.projection import Projector
from aslm_core.diagnosis.segment import make_segment
from aslm_sim.cases import make_case


@pytest.fixture(scope="module")
def seg():
    return make_segment(make_case(5, level=2, input_noise=False).window, skip_s=1.0, train_fraction=0.65)


def _prediction(seg, extra_q: np.ndarray | None = None) -> Prediction:
    rng = np.random.default_rng(3)
    V = seg.V
    sx = np.column_stack([np.ones_like(V), V, V * V])
    xq = sx if extra_q is None else np.column_stack([sx, extra_q])
    return Prediction(0.1 * rng.standard_normal(seg.n), 0.1 * rng.standard_normal(seg.n), sx, xq)


def test_the_projected_residual_is_the_svd_one_to_rounding(seg):
    noise = NoiseModel.white(1e-3, 2e-3, seg.fs)
    pr = _prediction(seg, extra_q=np.sin(np.arange(seg.n) * 0.05))
    rp, rq, *_ = engine._train_residuals(pr, seg, noise)
    r = Projector(seg, noise, engine._lstsq).residuals(pr)
    ref = np.concatenate([rp, rq])
    assert r.shape == ref.shape
    assert np.max(np.abs(r - ref)) <= 1e-9 * np.max(np.abs(ref))


def test_rank_deficient_columns_take_the_svd_path(seg):
    """A zero extra column (e.g. a relay that never switches in training): Gram–Schmidt would normalise noise
    into a spurious direction; the channel is solved by the SVD with its cut-off instead, as before."""
    noise = NoiseModel.white(1e-3, 2e-3, seg.fs)
    pr = _prediction(seg, extra_q=np.zeros(seg.n))
    calls = []

    def svd(xw, yw):
        calls.append(xw.shape)
        return engine._lstsq(xw, yw)

    r = Projector(seg, noise, svd).residuals(pr)
    rp, rq, *_ = engine._train_residuals(pr, seg, noise)
    assert calls == [(rq.size, 4)]  # Q only: P's columns are full rank
    for got, ref in ((r[:rp.size], rp), (r[rp.size:], rq)):
        assert np.max(np.abs(got - ref)) <= 1e-9 * np.max(np.abs(ref))
