"""identify_many: every pool gives one-by-one identify's results, bit for bit, in order, bad windows isolated."""

from __future__ import annotations

import os
import pickle
import threading

import numpy as np
import pytest

from aslm_core import IdentificationResult, Window, WindowError, identify, identify_many
from aslm_core.batch import PROCESS_MIN_WINDOWS_PER_WORKER, pool_kind
from aslm_sim.cases import make_cases


@pytest.fixture(scope="module")
def batch():
    """Five windows, the third too short (5 s needed); a warm start on the fourth."""
    cases = make_cases(4, level=2, seed=71, input_noise=False)
    w = cases[0].window
    short = Window(w.t[:300], w.V[:300], w.theta[:300], w.P[:300], w.Q[:300], f0=w.f0)
    windows = [cases[0].window, cases[1].window, short, cases[2].window, cases[3].window]
    warm = [None, None, None, cases[2].truth.d * 1.03, None]
    return windows, warm


def _fields(r: IdentificationResult | WindowError) -> dict | tuple:
    if isinstance(r, WindowError):
        return ("WindowError", r.reason, str(r))
    return {k: v for k, v in r.to_dict().items() if k != "elapsed_s"}


@pytest.mark.parametrize("pool", ["process", "thread"])
def test_pools_equal_one_by_one_identify_in_order(batch, pool):
    windows, warm = batch
    expected = []
    for w, s in zip(windows, warm, strict=True):
        try:
            expected.append(_fields(identify(w, warm_start=s)))
        except WindowError as exc:
            expected.append(_fields(exc))
    out = identify_many(windows, warm_starts=warm, workers=2, pool=pool)
    assert [type(r) for r in out] == [IdentificationResult] * 2 + [WindowError] + [IdentificationResult] * 2
    assert out[2].reason == "too_short"
    assert [_fields(r) for r in out] == expected


def test_window_error_survives_pickling():
    err = pickle.loads(pickle.dumps(WindowError("gaps", "V has a gap of 9 samples")))
    assert (err.reason, err.message, str(err)) == ("gaps", "V has a gap of 9 samples", "gaps: V has a gap of 9 samples")


def test_auto_forks_large_batches_of_a_single_threaded_caller_only(monkeypatch):
    from aslm_core import batch as batch_module

    # Other tests of the session may leave threads behind: count only the one started here.
    n_threads = threading.active_count()
    monkeypatch.setattr(batch_module.threading, "active_count", lambda: len(threading.enumerate()) - n_threads + 1)
    big = PROCESS_MIN_WINDOWS_PER_WORKER * 2
    assert pool_kind("auto", 2, big) == "process"
    assert pool_kind("auto", 2, big - 1) == "thread"
    assert pool_kind("thread", 2, big) == "thread"
    assert pool_kind("process", 1, big) == "serial"
    assert pool_kind("process", 2, 1) == "serial"
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        assert pool_kind("auto", 2, big) == "thread"  # a fork would copy locks the other thread may hold
    finally:
        stop.set()
        other.join()
    with pytest.raises(ValueError, match="pool must be one of"):
        pool_kind("fork", 2, big)


def test_auto_pool_on_a_batch_matches_serial(batch, monkeypatch):
    from aslm_core import batch as batch_module

    monkeypatch.setattr(batch_module.threading, "active_count", lambda: 1)  # as in a single-threaded caller
    windows, warm = batch
    many = windows * (PROCESS_MIN_WINDOWS_PER_WORKER // 2 + 1)  # enough for auto to fork on 2 workers
    assert pool_kind("auto", 2, len(many)) == "process"
    serial = identify_many(many, warm_starts=warm * (len(many) // len(warm)), workers=1)
    forked = identify_many(many, warm_starts=warm * (len(many) // len(warm)), workers=2)
    assert [_fields(r) for r in forked] == [_fields(r) for r in serial]
    assert np.all([isinstance(r, WindowError) for r in forked[2::5]])


def test_a_worker_that_dies_fails_the_call_instead_of_hanging(batch, monkeypatch):
    from concurrent.futures.process import BrokenProcessPool

    from aslm_core import batch as batch_module

    parent = os.getpid()
    real = batch_module._one

    def crash_in_child(window, warm, config):
        if os.getpid() != parent:
            os._exit(3)  # what a segfault in a kernel looks like to the parent
        return real(window, warm, config)

    monkeypatch.setattr(batch_module, "_one", crash_in_child)  # inherited by the forked workers
    windows, warm = batch
    with pytest.raises(BrokenProcessPool):
        identify_many(windows, warm_starts=warm, workers=2, pool="process")
