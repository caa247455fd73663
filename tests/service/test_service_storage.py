"""SQLite results history and configuration persistence on a real file."""

from __future__ import annotations

import pytest

from service.models import BusResult, Identified, PeriodSummary
from service.sinks.base import SinkChain
from service.sinks.storage import StorageSink
from service.storage import Storage
from service.testing import MemorySink


def result(bus: str, period: float, status: str = "ok", a: float = 40.0) -> BusResult:
    params = Identified(dynamic={"a": a, "b": 10, "H2": 1, "Tm": 0.3}, static={"Pz": 0.1}, objective=0.1,
                        fit={"fd_p": 0.9, "fd_q": 0.9}) if status == "ok" else None
    return BusResult(bus=bus, period=period, period_s=60, status=status, completed_at=period + 5,
                     reason=None if status == "ok" else "timeout", parameters=params)


def test_history_survives_reopen(tmp_path):
    path = tmp_path / "db" / "aslm.sqlite"
    st = Storage(path)
    st.save_results([result("b1", 60.0, a=30), result("b2", 60.0)])
    st.save_results([result("b1", 120.0, a=31), result("b2", 120.0, status="failed")])
    st.set_config({"period_s": 30.0})
    st.save_period(PeriodSummary(period=120, period_s=60, n_ok=1, n_failed=1, n_skipped=0, latency_s=0.5,
                                 completed_at=125))
    st.close()
    st = Storage(path)
    assert st.buses() == ["b1", "b2"]
    assert st.latest("b1").parameters.dynamic["a"] == 31
    assert st.latest("b2").status == "failed"
    assert st.latest("b2", ok_only=True).period == 60.0
    assert [r.period for r in st.history("b1")] == [120.0, 60.0]
    assert [r.period for r in st.history("b1", since=100)] == [120.0]
    assert [r.period for r in st.history("b1", until=100)] == [60.0]
    assert len(st.history("b1", limit=1)) == 1
    assert set(st.latest_all()) == {"b1", "b2"}
    assert st.latest_all(ok_only=True)["b2"].period == 60.0
    assert st.get_config() == {"period_s": 30.0}
    assert st.periods()[0].n_failed == 1
    assert st.latest("nope") is None
    st.close()


def test_purge_removes_only_old_results(tmp_path):
    st = Storage(tmp_path / "aslm.sqlite")
    st.save_results([result("b1", 60.0), result("b1", 120.0), result("b2", 60.0)])
    st.save_period(PeriodSummary(period=60, period_s=60, n_ok=2, n_failed=0, n_skipped=0, latency_s=0.1,
                                 completed_at=61))
    assert st.purge(before=100.0) == 2
    assert [r.period for r in st.history("b1")] == [120.0]
    assert st.history("b2") == [] and st.periods() == []
    st.close()


def _disk_full(st: Storage, full: bool) -> None:
    """SQLite's own 'database or disk is full': no page beyond those the file has (or room again)."""
    pages = st._db.execute("PRAGMA page_count").fetchone()[0]
    st._db.execute(f"PRAGMA max_page_count = {pages if full else 1 << 30}")


def test_a_write_failing_inside_a_transaction_leaves_the_storage_usable(tmp_path):
    st = Storage(tmp_path / "aslm.sqlite")
    with pytest.raises(Exception):  # noqa: B017 - whatever the driver raises for an unbindable body
        st.save_results([result("b1", 60.0)], bodies=[object()])
    st.save_results([result("b1", 120.0)])  # before: "cannot start a transaction within a transaction"
    st.set_config({"period_s": 30.0})
    assert [r.period for r in st.history("b1")] == [120.0] and st.get_config() == {"period_s": 30.0}
    st.close()


def test_results_outlive_a_storage_failure_published_kept_and_retried(tmp_path):
    st = Storage(tmp_path / "aslm.sqlite")
    lost: list[tuple[str, int]] = []
    sink = StorageSink(st, 1e9, backlog_limit=120, on_lost=lambda kind, n: lost.append((kind, n)))
    published, errors = MemorySink("zenoh"), []
    chain = SinkChain([published, sink], on_error=errors.append)
    _disk_full(st, True)
    batch = [result(f"b{i:03d}", 60.0) for i in range(100)]
    chain.write_results(batch)
    chain.write_period(PeriodSummary(period=60, period_s=60, n_ok=100, n_failed=0, n_skipped=0, latency_s=0.5,
                                     completed_at=65))
    assert [r.bus for r in published.results] == [r.bus for r in batch]  # published although not stored
    assert errors == ["storage", "storage"] and sink.held == 101
    assert "storage writes failing (OperationalError: database or disk is full); 101 records kept" in sink.problem()
    _disk_full(st, False)
    chain.write_results([result("b000", 120.0)])  # the next write stores what was kept first, in order
    assert sink.held == 0 and sink.problem() is None and lost == []
    assert [r.period for r in st.history("b000")] == [120.0, 60.0] and len(st.latest_all()) == 100
    assert st.periods()[0].period == 60
    _disk_full(st, True)
    for period in (180.0, 240.0):  # 200 records > backlog_limit 120: the oldest batch is dropped and counted
        chain.write_results([result(f"b{i:03d}", period) for i in range(100)])
    assert lost == [("results", 100)] and sink.held == 100 and sink.lost == {"results": 100}
    st.close()
