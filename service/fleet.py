"""The fleet table of the dashboard: one row per bus, filtered, sorted and paged on the server.

Built from :class:`service.latest.LatestResults` (memory only, no SQLite), so a page of a
10,000-bus fleet is answered without reading the history.  ``GET /fleet`` serves it.
"""

from __future__ import annotations

import math
from typing import Any

from pydantic import BaseModel, Field

from aslm_core.params import DYNAMIC_NAMES
from service.latest import LatestResults

#: States a row can be in (``state``) and verdicts of its latest diagnosis (``verdict``), counted over
#: the fleet in this order.
STATES = ("ok", "stale", "failed", "skipped", "pending")
VERDICTS = ("explained", "ambiguous", "unexplained", "consistent", "failed")

#: A result older than this many periods marks its bus stale (one missed period is tolerated).
STALE_PERIODS = 2.0

SORT_KEYS = ("bus", "state", "status", "age_s", "period", "verdict", *DYNAMIC_NAMES,
             *(f"se_{k}" for k in DYNAMIC_NAMES), "fd_p", "fd_q", "flags")


class FleetRow(BaseModel):
    """One bus in the fleet table."""

    bus: str
    state: str = Field(description="ok, stale (latest result older than 2 periods), failed, skipped, "
                                   "pending (known to the ingest, no result yet)")
    status: str | None = Field(description="Status of the latest result (ok, failed, skipped)")
    reason: str | None = Field(description="Why the latest result failed or was skipped")
    period: float | None = Field(description="Period of the latest result, UTC [s]")
    age_s: float | None = Field(description="Time since the latest result was recorded [s]")
    ok_period: float | None = Field(description="Period of the last successful result, the one the "
                                                "values below come from, UTC [s]")
    dynamic: dict[str, float | None] | None = Field(description="D of the last successful result")
    stderr: dict[str, float | None] | None = Field(description="Standard errors of D")
    static: dict[str, float | None] | None = Field(description="Static part (ZIP or exponential)")
    static_local: dict[str, float | None] | None = Field(
        default=None, description="What ambient data identify of the static part (as in the parameters' "
                                  "static_local): V0, P0, Q0 [pu], dPdV, dQdV [pu/pu], kpv, kqv [-], each with *_se")
    fit: dict[str, float | None] | None = Field(description="Fit degrees {fd_p, fd_q}")
    flags: list[str] = Field(description="Quality flags of the last successful result")
    verdict: str | None = Field(description="Latest diagnosis verdict: explained, ambiguous, consistent, unexplained, failed")
    cause: str | None = Field(description="Named cause of an explained verdict")
    diagnosis_period: float | None = Field(description="Period of the latest diagnosis, UTC [s]")


class FleetPage(BaseModel):
    """A page of the fleet table and the counts over the whole fleet."""

    total: int = Field(description="Buses in the fleet")
    matched: int = Field(description="Buses matching the filter")
    offset: int
    limit: int
    sort: str
    desc: bool
    counts: dict[str, dict[str, int]] = Field(
        description="Over the whole fleet: {state: {ok, stale, failed, skipped, pending}, "
                    "verdict: {explained, ambiguous, unexplained, consistent, failed}}")
    now: float = Field(description="Server time the ages are counted from, UTC [s]")
    period_s: float = Field(description="Period T in force [s]")
    rows: list[FleetRow]


def fleet_rows(latest: LatestResults, buses: list[str], now: float, period_s: float) -> list[dict[str, Any]]:
    """One row (a :class:`FleetRow` as a dict) per bus with a result or known to the ingest.

    Parameters
    ----------
    latest : LatestResults
    buses : list of str
        Buses the ingest knows (those without a result yet are ``pending``).
    now : float
        Current time, UTC [s].
    period_s : float
        Period T in force [s] (staleness is counted in periods).
    """
    results, last_ok, verdicts = latest.results.copy(), latest.last_ok.copy(), latest.verdicts.copy()
    rows = []
    for bus in sorted(set(results) | set(buses)):
        res, ok, ver = results.get(bus), last_ok.get(bus), verdicts.get(bus)
        par = ok.parameters if ok is not None else None
        age = now - res.completed_at if res is not None else None
        if res is None:
            state = "pending"
        elif age is not None and age > STALE_PERIODS * period_s:
            state = "stale"
        else:
            state = res.status
        rows.append({
            "bus": bus, "state": state, "status": res.status if res else None,
            "reason": res.reason if res else None, "period": res.period if res else None, "age_s": age,
            "ok_period": ok.period if ok else None,
            "dynamic": par.dynamic if par else None, "stderr": par.stderr if par else None,
            "static": par.static if par else None, "static_local": par.static_local if par else None,
            "fit": par.fit if par else None,
            "flags": par.flags if par else [],
            "verdict": ver.verdict if ver else None, "cause": ver.cause if ver else None,
            "diagnosis_period": ver.period if ver else None,
        })
    return rows


def _sort_value(row: dict[str, Any], key: str):
    """The value a row sorts by (None for missing, which sorts last either way)."""
    if key in DYNAMIC_NAMES:
        return (row["dynamic"] or {}).get(key)
    if key.startswith("se_"):
        return (row["stderr"] or {}).get(key[3:])
    if key in ("fd_p", "fd_q"):
        return (row["fit"] or {}).get(key)
    if key == "flags":
        return len(row["flags"])
    return row[key]


def select(rows: list[dict[str, Any]], *, q: str = "", states: list[str] | None = None,
           verdicts: list[str] | None = None, sort: str = "bus", desc: bool = False, offset: int = 0,
           limit: int = 100) -> tuple[int, list[dict[str, Any]]]:
    """Filter, sort and page fleet rows.

    Parameters
    ----------
    q : str
        Case-insensitive substring of the bus name ("" matches every bus).
    states, verdicts : list of str or None
        Keep rows whose ``state`` is one of ``states`` and whose ``verdict`` is one of ``verdicts``
        (None or empty: no condition).
    sort : str
        One of :data:`SORT_KEYS`; missing values sort last in both directions, then by bus.
    desc : bool
    offset, limit : int
        The page.

    Returns
    -------
    matched, page : int, list of dict
    """
    if sort not in SORT_KEYS:
        raise ValueError(f"sort must be one of {', '.join(SORT_KEYS)}")
    needle = q.lower()
    st, vd = set(states or ()), set(verdicts or ())
    kept = [r for r in rows if (not needle or needle in r["bus"].lower())
            and (not st or r["state"] in st) and (not vd or r["verdict"] in vd)]
    present, missing = [], []
    for r in kept:
        v = _sort_value(r, sort)
        (missing if v is None or (isinstance(v, float) and math.isnan(v)) else present).append((v, r))
    # Rows arrive sorted by bus and both sorts are stable: ties stay in bus order.
    present.sort(key=lambda vr: vr[0], reverse=desc)
    ordered = [r for _, r in present] + [r for _, r in missing]
    return len(kept), ordered[offset:offset + limit]


def counts(rows: list[dict[str, Any]]) -> dict[str, dict[str, int]]:
    """Buses by state and by diagnosis verdict (every name present, zeros included)."""
    state, verdict = dict.fromkeys(STATES, 0), dict.fromkeys(VERDICTS, 0)
    for r in rows:
        state[r["state"]] += 1
        if r["verdict"] is not None:
            verdict[r["verdict"]] = verdict.get(r["verdict"], 0) + 1
    return {"state": state, "verdict": verdict}
