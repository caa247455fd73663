"""SQLite (WAL) store of results history, completed periods and run-time configuration.

One connection guarded by a lock: writes come from the scheduler thread in one transaction per
period, reads from REST handlers; SQLite in WAL mode keeps readers off the writer's way on disk.
"""

from __future__ import annotations

import json
import sqlite3
import threading
import time
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from service.busnames import bus_name_problem
from service.models import BusResult, PeriodSummary

_SCHEMA = """
CREATE TABLE IF NOT EXISTS results (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    bus TEXT NOT NULL,
    period REAL NOT NULL,
    status TEXT NOT NULL,
    completed_at REAL NOT NULL,
    body TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS results_bus_period ON results (bus, period);
CREATE INDEX IF NOT EXISTS results_period ON results (period);
CREATE TABLE IF NOT EXISTS periods (
    period REAL PRIMARY KEY,
    body TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS diagnoses (
    bus TEXT NOT NULL,
    period REAL NOT NULL,
    body TEXT NOT NULL,
    PRIMARY KEY (bus, period)
);
CREATE TABLE IF NOT EXISTS running (
    period REAL PRIMARY KEY,
    period_s REAL NOT NULL,
    buses TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS tracked (
    bus TEXT PRIMARY KEY,
    period REAL NOT NULL,
    body TEXT NOT NULL,
    state TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS changes (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    bus TEXT NOT NULL,
    t REAL NOT NULL,
    body TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS changes_bus_t ON changes (bus, t);
CREATE TABLE IF NOT EXISTS config (
    key TEXT PRIMARY KEY,
    value TEXT NOT NULL,
    updated REAL NOT NULL
);
"""


class StorageError(RuntimeError):
    """The SQLite file cannot be opened or initialised (one line an operator can act on)."""


class Storage:
    """Results history and persisted configuration in one SQLite file.

    Parameters
    ----------
    path : str or Path
        Database file; created with its parent directory.  ``:memory:`` for a throw-away store.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._lock = threading.Lock()
        try:
            if str(path) != ":memory:":
                self.path.parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(str(path), check_same_thread=False, isolation_level=None)
            with self._lock:
                self._db.execute("PRAGMA journal_mode=WAL")
                self._db.execute("PRAGMA synchronous=NORMAL")  # durable at checkpoints; fine for results
                self._db.executescript(_SCHEMA)
        except (OSError, sqlite3.Error) as exc:
            raise StorageError(f"storage_url: cannot use {self.path} as the SQLite file: {exc}") from None

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        """One transaction under the lock, rolled back if anything in it raises (a transaction left open
        would make every later ``BEGIN`` fail, and so every later write)."""
        with self._lock:
            self._db.execute("BEGIN")
            try:
                yield self._db
            except BaseException:
                if self._db.in_transaction:
                    self._db.execute("ROLLBACK")
                raise
            self._db.execute("COMMIT")

    def close(self) -> None:
        """Close the connection."""
        with self._lock:
            self._db.close()

    # --- results -----------------------------------------------------------------------------------
    def save_results(self, results: list[BusResult], bodies: list[str] | None = None) -> None:
        """Append results in one transaction; ``bodies`` are their JSON if the caller has it already.

        Raises
        ------
        ValueError
            A result's bus name breaks :mod:`service.busnames` (nothing of the batch is written).
        """
        _check_buses(r.bus for r in results)
        bodies = bodies if bodies is not None else [r.model_dump_json() for r in results]
        rows = [(r.bus, r.period, r.status, r.completed_at, b) for r, b in zip(results, bodies, strict=True)]
        with self._transaction() as db:
            db.executemany(
                "INSERT INTO results (bus, period, status, completed_at, body) VALUES (?, ?, ?, ?, ?)", rows)

    def latest(self, bus: str, *, ok_only: bool = False) -> BusResult | None:
        """Most recent result of ``bus`` (only successful ones with ``ok_only``)."""
        sql = "SELECT body FROM results WHERE bus = ?" + (" AND status = 'ok'" if ok_only else "")
        sql += " ORDER BY period DESC, id DESC LIMIT 1"
        with self._lock:
            row = self._db.execute(sql, (bus,)).fetchone()
        return BusResult.model_validate_json(row[0]) if row else None

    def latest_all(self, *, ok_only: bool = False) -> dict[str, BusResult]:
        """Most recent result of every bus."""
        cond = "WHERE status = 'ok'" if ok_only else ""
        sql = (f"SELECT r.body FROM results r JOIN (SELECT bus, MAX(id) AS id FROM results {cond} "
               "GROUP BY bus) m ON r.id = m.id")
        with self._lock:
            rows = self._db.execute(sql).fetchall()
        out = [BusResult.model_validate_json(r[0]) for r in rows]
        return {r.bus: r for r in out}

    def history(self, bus: str, since: float | None = None, until: float | None = None,
                limit: int = 100) -> list[BusResult]:
        """Results of ``bus`` with ``since <= period <= until`` [s], newest first."""
        sql = "SELECT body FROM results WHERE bus = ? AND period >= ? AND period <= ? ORDER BY period DESC, id DESC LIMIT ?"
        args = (bus, since if since is not None else -1e300, until if until is not None else 1e300, int(limit))
        with self._lock:
            rows = self._db.execute(sql, args).fetchall()
        return [BusResult.model_validate_json(r[0]) for r in rows]

    def buses(self) -> list[str]:
        """Buses with at least one result, sorted."""
        with self._lock:
            rows = self._db.execute("SELECT DISTINCT bus FROM results ORDER BY bus").fetchall()
        return [r[0] for r in rows]

    # --- periods -----------------------------------------------------------------------------------
    def save_period(self, summary: PeriodSummary) -> None:
        """Record a completed period."""
        with self._lock:
            self._db.execute("INSERT OR REPLACE INTO periods (period, body) VALUES (?, ?)",
                             (summary.period, summary.model_dump_json()))

    def periods(self, limit: int = 20) -> list[PeriodSummary]:
        """Completed periods, newest first."""
        with self._lock:
            rows = self._db.execute("SELECT body FROM periods ORDER BY period DESC LIMIT ?", (limit,)).fetchall()
        return [PeriodSummary.model_validate_json(r[0]) for r in rows]

    def purge(self, before: float) -> int:
        """Delete results and periods with ``period < before`` [s]; returns the results deleted."""
        with self._transaction() as db:
            n = db.execute("DELETE FROM results WHERE period < ?", (before,)).rowcount
            db.execute("DELETE FROM periods WHERE period < ?", (before,))
            db.execute("DELETE FROM changes WHERE t < ?", (before,))
        return n

    # --- periods that have started and not completed (a crash leaves them) ----------------------------
    def mark_running(self, period: float, period_s: float, buses: list[str]) -> None:
        """Record that the period of boundary ``period`` [s] has started with ``buses`` known."""
        with self._lock:
            self._db.execute("INSERT OR REPLACE INTO running (period, period_s, buses) VALUES (?, ?, ?)",
                             (period, period_s, json.dumps(buses)))

    def clear_running(self, period: float) -> None:
        """The period of boundary ``period`` [s] is over (completed, or recorded as interrupted)."""
        with self._lock:
            self._db.execute("DELETE FROM running WHERE period = ?", (period,))

    def interrupted(self, now: float, late_s: float) -> list[PeriodSummary]:
        """Periods that started and never completed (the process was killed or failed while they ran).

        Parameters
        ----------
        now : float
            Time of this check, UTC [s]: their ``completed_at``.
        late_s : float
            Late-data allowance [s]: ``latency_s`` counts from boundary + ``late_s``.

        Returns
        -------
        list of PeriodSummary
            Status ``interrupted``, the results each period got counted by status, and the buses known at
            its start that got none.  A period whose completed summary was stored is not among them.
        """
        with self._lock:
            marks = self._db.execute("SELECT period, period_s, buses FROM running ORDER BY period").fetchall()
            done = {p for (p,) in self._db.execute(
                "SELECT period FROM periods WHERE period IN (SELECT period FROM running)").fetchall()}
            got = {p: self._db.execute("SELECT bus, status FROM results WHERE period = ?", (p,)).fetchall()
                   for p, _, _ in marks if p not in done}
        out = []
        for period, period_s, buses in marks:
            if period in done:
                continue
            status = dict(got[period])
            counts = Counter(status.values())
            out.append(PeriodSummary(
                period=period, period_s=period_s, n_ok=counts["ok"], n_failed=counts["failed"],
                n_skipped=counts["skipped"], latency_s=now - (period + late_s), completed_at=now,
                status="interrupted", no_result=[b for b in json.loads(buses) if b not in status]))
        return out

    # --- tracked models and change events (service/sinks/tracking.py) ---------------------------------
    def save_tracking(self, tracked: list[tuple[str, float, str, str]], changes: list[tuple[str, float, str]]) -> None:
        """Replace tracked models and append change events, in one transaction.

        Parameters
        ----------
        tracked : list of (bus, period [s], model JSON, tracker state JSON)
        changes : list of (bus, t [s], event JSON)
        """
        _check_buses([b for b, *_ in tracked] + [b for b, *_ in changes])
        with self._transaction() as db:
            db.executemany("INSERT OR REPLACE INTO tracked (bus, period, body, state) VALUES (?, ?, ?, ?)", tracked)
            db.executemany("INSERT INTO changes (bus, t, body) VALUES (?, ?, ?)", changes)

    def tracked(self, bus: str) -> str | None:
        """JSON of the bus's tracked model, or None."""
        with self._lock:
            row = self._db.execute("SELECT body FROM tracked WHERE bus = ?", (bus,)).fetchone()
        return row[0] if row else None

    def tracker_states(self) -> dict[str, str]:
        """bus → JSON of its tracker's state (to resume tracking after a restart)."""
        with self._lock:
            return dict(self._db.execute("SELECT bus, state FROM tracked").fetchall())

    def changes(self, bus: str, since: float | None = None, limit: int = 100) -> list[str]:
        """JSON of the change events of ``bus`` with ``t >= since`` [s], newest first."""
        with self._lock:
            rows = self._db.execute("SELECT body FROM changes WHERE bus = ? AND t >= ? ORDER BY t DESC, id DESC "
                                    "LIMIT ?", (bus, since if since is not None else -1e300, int(limit))).fetchall()
        return [r[0] for r in rows]

    # --- configuration -------------------------------------------------------------------------------
    # --- diagnoses -------------------------------------------------------------------------------
    def save_diagnosis(self, bus: str, period: float, report_json: str) -> None:
        """Store one diagnosis report (JSON) of a bus for a period (replacing an earlier one).

        Raises
        ------
        ValueError
            ``bus`` breaks :mod:`service.busnames`.
        """
        _check_buses((bus,))
        with self._lock:
            self._db.execute("INSERT OR REPLACE INTO diagnoses (bus, period, body) VALUES (?, ?, ?)",
                             (bus, period, report_json))

    def latest_diagnoses(self) -> dict[str, str]:
        """bus → JSON of its most recent diagnosis report."""
        with self._lock:
            rows = self._db.execute(
                "SELECT d.bus, d.body FROM diagnoses d JOIN (SELECT bus, MAX(period) AS p FROM diagnoses "
                "GROUP BY bus) m ON d.bus = m.bus AND d.period = m.p").fetchall()
        return dict(rows)

    def diagnoses(self, bus: str, since: float | None = None, limit: int = 100) -> list[str]:
        """JSON of the diagnosis reports of ``bus`` with ``period >= since`` [s], newest first."""
        with self._lock:
            rows = self._db.execute(
                "SELECT body FROM diagnoses WHERE bus = ? AND period >= ? ORDER BY period DESC LIMIT ?",
                (bus, since if since is not None else -1e300, int(limit))).fetchall()
        return [r[0] for r in rows]

    def set_config(self, values: dict[str, Any]) -> None:
        """Persist run-time configuration changes (JSON values)."""
        now = time.time()
        with self._transaction() as db:
            db.executemany("INSERT OR REPLACE INTO config (key, value, updated) VALUES (?, ?, ?)",
                           [(k, json.dumps(v), now) for k, v in values.items()])

    def get_config(self) -> dict[str, Any]:
        """Persisted run-time configuration."""
        with self._lock:
            rows = self._db.execute("SELECT key, value FROM config").fetchall()
        return {k: json.loads(v) for k, v in rows}


def _check_buses(buses) -> None:
    """Refuse names the ingest would never have made (a wildcard row would answer for other buses)."""
    bad = {b: p for b in buses if (p := bus_name_problem(b)) is not None}
    if bad:
        raise ValueError(f"refusing to store {len(bad)} result(s) of invalid bus names: {next(iter(bad.values()))}")
