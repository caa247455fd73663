"""The tracked model's joint pooled fit in the service (track_joint_fit): the ring of each pool's windows,
the background fits on real worker processes, and what a failed fit leaves."""

from __future__ import annotations

import json
import time
from concurrent.futures import Future

import numpy as np
import pytest
from service_helpers import client_session, free_port, settings_for

from aslm_core import identify
from aslm_core.params import DYNAMIC_NAMES
from aslm_core.pooled import identify_pooled
from aslm_core.tracking import TrackerConfig
from aslm_core.window import Window
from aslm_sim.cases import make_cases
from aslm_sim.network import draw_network
from aslm_sim.truth import random_truth
from service.buffers import BufferStore
from service.context import Context
from service.executors.base import WindowTask
from service.executors.local import LocalPool
from service.joint_fit import JointFits
from service.latest import LatestResults
from service.metrics import ServiceMetrics
from service.models import BusResult, PeriodSummary, TrackedModel
from service.sinks import records as records_sink
from service.sinks.base import ResultBatch
from service.sinks.tracking import TrackingSink, build
from service.storage import Storage
from service.window_ring import CompactWindow

T = 900.0
D = np.array([22.796, 19.159, 1.0, 0.2])
SE = 0.02 * D


class HeldExecutor:
    """Takes tasks and never runs them (what is planned, without workers)."""

    def __init__(self) -> None:
        self.tasks: list[WindowTask] = []

    def submit(self, task: WindowTask) -> Future:
        self.tasks.append(task)
        return Future()

    def submit_many(self, tasks: list[WindowTask]) -> list[Future]:
        return [self.submit(t) for t in tasks]

    def close(self) -> None:
        """Nothing runs."""


def _tiny_window(i: int) -> Window:
    t = 1e9 + T * i + np.arange(20) / 50.0
    return Window(t, 1.0 + 0.001 * np.sin(t), 0.3 + 0.01 * np.cos(t), np.full(20, 0.8), np.full(20, 0.3))


def _result(bus: str, period: float, d, se) -> BusResult:
    return BusResult(bus=bus, period=period, period_s=T, status="ok", completed_at=period + 1, parameters={
        "dynamic": dict(zip(DYNAMIC_NAMES, np.asarray(d, dtype=float).tolist(), strict=True)),
        "static": {"Pz": 0.1}, "objective": 0.1, "fit": {"fd_p": 0.9, "fd_q": 0.9},
        "stderr": dict(zip(DYNAMIC_NAMES, np.asarray(se, dtype=float).tolist(), strict=True))})


def _write(sink: TrackingSink, results: list[BusResult], windows: list[Window]) -> None:
    """Write results as the scheduler does: a batch carrying the windows identified."""
    sink.write_results(ResultBatch(results, {r.bus: w for r, w in zip(results, windows, strict=True)}),
                       [""] * len(results))


def _period(sink: TrackingSink, period: float) -> None:
    sink.write_period(PeriodSummary(period=period, period_s=T, n_ok=1, n_failed=0, n_skipped=0, latency_s=0.0,
                                    completed_at=period))


@pytest.mark.parametrize("fit_suspects", [True, False])
def test_the_ring_holds_the_pool_and_stays_bounded_and_a_change_empties_it(tmp_path, fit_suspects):
    k = 4
    storage = Storage(tmp_path / "a.sqlite")
    ex = HeldExecutor()
    joint = JointFits(ex, max_buses=10, in_flight=100, fit_suspects=fit_suspects)
    sink = TrackingSink(storage, TrackerConfig(pool_windows=k), joint=joint)
    rng = np.random.default_rng(5)
    one = CompactWindow.of(_tiny_window(0)).nbytes
    outlier = 30
    for i in range(60):
        d = D + SE * rng.standard_normal(4)
        if i == outlier:
            d = D * np.array([1.0, 1.0, 1.0, 1.5])  # one window far out, not confirmed by the next
        _write(sink, [_result("b1", T * i, d, SE)], [_tiny_window(i)])
        _period(sink, T * i)
        tr, b = sink.trackers["b1"], joint.buses["b1"]
        held = [tr.suspect.t] if tr.suspect is not None else []
        fitted = [e.t for e in tr.pool if e.t not in b.winsorised]
        assert list(b.ring.windows) == sorted(fitted + held)
        assert len(b.ring) <= k + 1 and b.ring.nbytes <= (k + 1) * one
        if i == outlier:  # held out of the pool and the fit, kept in the ring until the next window
            assert tr.suspect is not None and T * outlier in b.ring.windows and T * outlier not in b.key
        if i == outlier + 1:  # the outlier joined the pool clipped; fitted with the rest unless fit_suspects is off
            assert T * outlier in [e.t for e in tr.pool]
            assert (T * outlier in b.ring.windows) is fit_suspects and (T * outlier in b.key) is fit_suspects
            assert (T * outlier in b.winsorised) is not fit_suspects
    assert len(joint.buses) == 1 and joint.nbytes == len(joint.buses["b1"].ring) * one
    # A fit is planned for each new pool of at least two windows; the task carries the pool's windows.
    task = ex.tasks[-1]
    assert task.fn == "service.worker:pooled_window" and task.background and task.bus == "b1"
    assert [w.t0 for w in task.pool] == [float(_tiny_window(int(p / T)).t[0]) for p in joint.buses["b1"].key]
    # A step: the suspect is held in the ring, its confirmation restarts the pool and empties the ring to the two.
    for i in (60, 61):
        _write(sink, [_result("b1", T * i, D * [1.2, 1.0, 1.2, 1.2], SE)], [_tiny_window(i)])
        _period(sink, T * i)
    assert storage.changes("b1") and list(joint.buses["b1"].ring.windows) == [T * 60, T * 61]
    assert json.loads(storage.tracked("b1"))["estimator"] == "mean"  # no fit has run
    assert json.loads(storage.tracked("b1"))["disturbance"] is None
    storage.close()


def test_without_the_setting_or_an_executor_no_ring_is_kept(tmp_path):
    def sink_of(executor, **overrides) -> TrackingSink:
        s = settings_for(tmp_path, 7447, sinks=["storage", "tracking"], **overrides)
        storage = Storage(s.storage_path)
        return build(Context(s, storage, LatestResults(), ServiceMetrics(BufferStore(10.0, 50.0, 1.0)),
                             executor=executor))

    assert isinstance(sink_of(HeldExecutor()).joint, JointFits)  # on by default, with the service's executor
    assert sink_of(HeldExecutor()).joint.max_buses == 1000
    assert sink_of(HeldExecutor(), track_joint_fit=False).joint is None
    assert sink_of(HeldExecutor(), track_joint_fit_buses=0).joint is None
    assert sink_of(None).joint is None
    off = sink_of(HeldExecutor(), track_joint_fit=False)
    for i in range(5):
        _write(off, [_result("b1", T * i, D, SE)], [_tiny_window(i)])
        off.write_period(PeriodSummary(period=T * i, period_s=T, n_ok=1, n_failed=0, n_skipped=0, latency_s=0,
                                       completed_at=T * i))
    assert json.loads(off.storage.tracked("b1"))["estimator"] == "mean"


def test_buses_beyond_the_cap_keep_the_mean(tmp_path):
    storage = Storage(tmp_path / "c.sqlite")
    joint = JointFits(HeldExecutor(), max_buses=2)
    sink = TrackingSink(storage, TrackerConfig(pool_windows=4), joint=joint)
    for i in range(3):
        _write(sink, [_result(f"b{j}", T * i, D, SE) for j in range(5)], [_tiny_window(i)] * 5)
    assert sorted(joint.buses) == ["b0", "b1"]
    storage.close()


# --- real worker processes -----------------------------------------------------------------------------

def _bus_windows(n: int, seed: int) -> list[Window]:
    rng = np.random.default_rng([seed, 0])
    truth = random_truth(rng)
    net = draw_network(rng, truth, 50.0)
    cases = make_cases(n, snr_db=22.0, seed=seed, input_noise=False, truths=[truth] * n, networks=[net] * n)
    return [c.window for c in cases]


@pytest.fixture(scope="module")
def windows():
    """Four stationary windows of one bus (22 dB), stamped one period apart, and their estimates."""
    ws = []
    for i, w in enumerate(_bus_windows(4, 1818)):
        ws.append(Window(w.t + 1e9 + T * i, w.V, w.theta, w.P, w.Q, w.f, w.f0, "bus-j"))
    fits, warm = [], None
    for w in ws:
        fits.append(identify(w, warm_start=warm))
        warm = fits[-1].d
    return ws, fits


@pytest.fixture(scope="module")
def pool():
    # The default function is the fit itself: no identification warm-up delays the workers' start.
    p = LocalPool(1, "service.worker:pooled_window", timeout_s=120)
    yield p
    p.close()


def _feed(sink: TrackingSink, ws, fits, periods) -> None:
    for i in periods:
        r = fits[i]
        _write(sink, [_result("bus-j", T * i, r.d, [r.stderr[k] for k in DYNAMIC_NAMES])], [ws[i]])
        _period(sink, T * i)


def _wait(cond, timeout: float = 180.0) -> None:
    end = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.05)


@pytest.mark.slow
def test_the_joint_fit_replaces_the_mean_and_equals_identify_pooled(tmp_path, windows, pool):
    ws, fits = windows
    storage = Storage(tmp_path / "j.sqlite")
    puts = []
    joint = JointFits(pool, max_buses=10)
    sink = TrackingSink(storage, TrackerConfig(pool_windows=4), put=lambda k, p: puts.append((k, json.loads(p))),
                        joint=joint)
    _feed(sink, ws, fits, range(4))
    model = lambda: TrackedModel.model_validate_json(storage.tracked("bus-j"))  # noqa: E731
    _wait(lambda: model().estimator == "joint" and model().n_windows == 4)
    got = model()
    assert got.disturbance == "none"  # grid-excited: the white-noise pool
    assert puts[-1][1] == json.loads(got.model_dump_json())  # published as stored
    ring = joint.buses["bus-j"].ring
    ref = identify_pooled([w.window() for w in ring.get(sorted(ring.windows))], start=fits[-1].d)
    for k in DYNAMIC_NAMES:
        assert got.dynamic[k] == pytest.approx(ref.dynamic[k], rel=1e-4)
        assert got.stderr[k] == pytest.approx(ref.stderr[k], rel=1e-2)
    # The float32 ring against the original float64 windows: the same fit within a fraction of its SE.
    full = identify_pooled(ws, start=fits[-1].d)
    for k in DYNAMIC_NAMES:
        assert abs(got.dynamic[k] - full.dynamic[k]) < 0.05 * full.stderr[k]
    # The mean it replaced: the same pool, a different estimator.
    mean = [p for _, p in puts if p["estimator"] == "mean" and p["n_windows"] == 4]
    assert mean and mean[-1]["dynamic"] != got.dynamic
    assert joint.failed == 0
    storage.close()


@pytest.mark.slow
def test_the_tracked_model_of_an_own_dominated_bus_is_the_pooled_iv(tmp_path, pool):
    """Where the load's own fluctuation dominates P (own ratio ~0.8: a closed loop through the network), the worker's
    joint fit is the pooled IV's answer (identify_pooled's gated default), within 3 SE of the truth; the white-noise
    pool (the joint fit until stop 38) is off by more than 10 % in a on the same windows."""
    rng = np.random.default_rng([78, 0])
    truth = random_truth(rng)
    net = draw_network(rng, truth, 50.0)
    cases = make_cases(4, level=2, seed=7800, input_noise=False, truths=[truth] * 4, networks=[net] * 4,
                       own_sigma=0.008)
    ws = [Window(c.window.t + 1e9 + T * i, c.window.V, c.window.theta, c.window.P, c.window.Q, c.window.f,
                 c.window.f0, "bus-o") for i, c in enumerate(cases)]
    fits = [identify(w) for w in ws]
    storage = Storage(tmp_path / "o.sqlite")
    joint = JointFits(pool, max_buses=10)
    sink = TrackingSink(storage, TrackerConfig(pool_windows=4), joint=joint)
    for i, r in enumerate(fits):
        _write(sink, [_result("bus-o", T * i, r.d, [r.stderr[k] for k in DYNAMIC_NAMES])], [ws[i]])
        _period(sink, T * i)
    model = lambda: TrackedModel.model_validate_json(storage.tracked("bus-o"))  # noqa: E731
    _wait(lambda: model().estimator == "joint" and model().n_windows == 4)
    got = model()
    assert got.disturbance == "ar_iv"
    ring = joint.buses["bus-o"].ring
    pooled = [w.window() for w in ring.get(sorted(ring.windows))]
    iv = identify_pooled(pooled, start=fits[-1].d, disturbance="ar_iv")
    white = identify_pooled(pooled, start=fits[-1].d, disturbance="none")
    d = np.array([got.dynamic[k] for k in DYNAMIC_NAMES])
    se = np.array([got.stderr[k] for k in DYNAMIC_NAMES])
    assert np.all(np.abs(d - iv.d) < 0.05 * se)  # the worker started from the tracker's mean
    assert np.all(np.abs(d - truth.d) < 3 * se)
    assert abs(white.d[0] / truth.d[0] - 1.0) > 0.1
    assert joint.failed == 0
    storage.close()


@pytest.mark.slow
def test_a_failing_fit_leaves_the_mean_and_the_next_pool_is_fitted(tmp_path, windows, pool):
    ws, fits = windows
    storage = Storage(tmp_path / "f.sqlite")
    joint = JointFits(pool, max_buses=10)
    sink = TrackingSink(storage, TrackerConfig(pool_windows=4), joint=joint)
    _feed(sink, ws, fits, range(2))
    _wait(lambda: joint.failed == 1 or json.loads(storage.tracked("bus-j"))["estimator"] == "joint")
    # The pool of three: its task's newest window is spoilt (NaN samples) before the round goes out.
    _write(sink, [_result("bus-j", T * 2, fits[2].d, [fits[2].stderr[k] for k in DYNAMIC_NAMES])], [ws[2]])
    task = joint._round[-1]
    bad = task.pool[-1]
    task.pool[-1] = CompactWindow(np.full_like(bad.rows, np.nan), bad.t0, bad.theta0, bad.f0, bad.bus)
    _period(sink, T * 2)
    _wait(lambda: joint.failed == 1)
    body = json.loads(storage.tracked("bus-j"))
    assert body["estimator"] == "mean" and body["n_windows"] == 3
    assert body["dynamic"] == sink.trackers["bus-j"].model()["dynamic"]
    # Nothing else is lost: the ring still holds the pool's windows, and the next pool's fit arrives.
    assert len(joint.buses["bus-j"].ring) == 3
    _feed(sink, ws, fits, [3])
    _wait(lambda: json.loads(storage.tracked("bus-j"))["estimator"] == "joint")
    assert json.loads(storage.tracked("bus-j"))["n_windows"] == 4 and joint.failed == 1
    storage.close()


@pytest.mark.slow
def test_a_failed_or_timed_out_fit_leaves_the_mean_and_loses_nothing_else(tmp_path, windows):
    ws, fits = windows
    storage = Storage(tmp_path / "t.sqlite")
    # Every fit outlives its 1 ms limit: the pool kills the worker running it and replaces it.
    short = LocalPool(1, "service.worker:pooled_window", timeout_s=0.001)
    try:
        joint = JointFits(short, max_buses=10)
        sink = TrackingSink(storage, TrackerConfig(pool_windows=4), joint=joint)
        _feed(sink, ws, fits, range(4))
        _wait(lambda: joint.failed >= 1 and not joint.pending)
        assert short.replaced >= 1
        body = TrackedModel.model_validate_json(storage.tracked("bus-j"))
        tr = sink.trackers["bus-j"]
        assert body.estimator == "mean" and body.n_windows == 4
        assert body.dynamic == tr.model()["dynamic"]  # the mean of the four windows' estimates
    finally:
        short.close()
    storage.close()


@pytest.mark.slow
def test_the_records_on_zenoh_follow_the_joint_fit_when_it_arrives(tmp_path, windows, pool):
    """The records sink republishes a bus's records from its tracked model once the pool's joint fit arrives."""
    ws, fits = windows
    zport = free_port()
    s = settings_for(tmp_path, zport, sinks=["storage", "records", "tracking"])
    storage = Storage(s.storage_path)
    ctx = Context(s, storage, LatestResults(), ServiceMetrics(BufferStore(10.0, 50.0, 1.0)), executor=pool)
    records = records_sink.build(ctx)  # built before the tracking sink, as in the settings' order
    sink = build(ctx)
    assert ctx.tracked_listeners == [records.tracked_changed]
    got: list[dict] = []
    client = client_session(zport)
    sub = client.declare_subscriber(f"{s.prefix}/records/andes/bus-j",
                                    lambda sample: got.append(json.loads(sample.payload.to_string())))
    try:
        time.sleep(1.0)  # the subscription reaches the service's peer
        for i in range(4):
            r = fits[i]
            res = _result("bus-j", T * i, r.d, [r.stderr[k] for k in DYNAMIC_NAMES])
            res.parameters.static = dict(r.static)  # records need the whole ZIP part
            sink.write_results(ResultBatch([res], {"bus-j": ws[i]}), [""])
            records.write_results([res], [""])  # with each result: the tracked model as it is (the mean)
            _period(sink, T * i)
        model = lambda: TrackedModel.model_validate_json(storage.tracked("bus-j"))  # noqa: E731
        _wait(lambda: model().estimator == "joint" and model().n_windows == 4)
        tm = model().dynamic["Tm"]
        assert all("content" in p for p in got), got[:1]
        _wait(lambda: any(json.loads(p["content"])["Motor3"][0]["c1"] == pytest.approx(tm) for p in got), 30.0)
        assert all(p["model"] == "tracked" for p in got)
        # The last result's records carried the mean of the four; the republished ones carry the joint fit.
        firsts = [json.loads(p["content"])["Motor3"][0]["c1"] for p in got]
        assert firsts[-1] == pytest.approx(tm) and any(c != pytest.approx(tm) for c in firsts[:-1])
    finally:
        sub.undeclare()
        client.close()
        ctx.close()
        storage.close()
