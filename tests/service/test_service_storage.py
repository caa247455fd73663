"""SQLite results history and configuration persistence on a real file."""

from __future__ import annotations

from service.models import BusResult, Identified, PeriodSummary
from service.storage import Storage


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
