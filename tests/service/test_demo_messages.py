"""What `aslm demo` prints while it waits: readable UTC times, reasons in words, no empty parentheses."""

from __future__ import annotations

from service.commands.demo import format_skipped
from service.models import PeriodSummary
from service.timefmt import utc_iso, utc_text

T = 1795444580.0  # the raw epoch a first user was shown


def _summary(n_skipped: int) -> PeriodSummary:
    return PeriodSummary(period=T, period_s=20.0, n_ok=0, n_failed=0, n_skipped=n_skipped, latency_s=0.01,
                         completed_at=T + 1.0)


def test_readable_utc():
    assert utc_text(T) == "2026-11-23 14:36:20 UTC"
    assert utc_iso(T) == "2026-11-23T14:36:20Z" and utc_iso(T + 0.25) == "2026-11-23T14:36:20.250Z"


def test_a_period_without_buses_says_so_without_empty_parentheses():
    line = format_skipped(_summary(0), set())
    assert line == "period 2026-11-23 14:36:20 UTC: no bus has sent frames yet - waiting for the fleet"


def test_skipped_buses_give_their_reasons_in_words():
    line = format_skipped(_summary(10), {"coverage", "no_data"})
    assert line == ("period 2026-11-23 14:36:20 UTC: all 10 buses skipped (coverage: the window is not full "
                    "yet; no_data: no frames in the window yet) - waiting for a full window")
    assert "()" not in format_skipped(_summary(3), {""}) and "1795444580" not in line
