"""Audit log of run-time configuration changes: who, when, old → new, kept in the service's SQLite file.

Who is the operator token's fingerprint (the first 12 hex digits of its SHA-256: it tells which token
was used without revealing it) and the client's address.  Requests refused for a missing or wrong token
are logged, not stored: anyone who can reach REST could otherwise grow the table without bound.
"""

from __future__ import annotations

import hashlib
import json
import sqlite3
import threading
import time
from pathlib import Path
from typing import Any

from pydantic import BaseModel, Field

from service.timefmt import utc_iso

_SCHEMA = """
CREATE TABLE IF NOT EXISTS config_audit (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    at REAL NOT NULL,
    token TEXT,
    address TEXT,
    field TEXT NOT NULL,
    old TEXT NOT NULL,
    new TEXT NOT NULL
);
"""


def token_identity(token: str | None) -> str | None:
    """Fingerprint of an operator token, ``sha256:<12 hex>``; None without a token."""
    if not token:
        return None
    return "sha256:" + hashlib.sha256(token.encode()).hexdigest()[:12]


class AuditEntry(BaseModel):
    """One run-time configuration change."""

    at: float = Field(description="When the change was accepted, UTC since the epoch [s]")
    at_utc: str = Field(description="The same time, ISO 8601 UTC")
    token: str | None = Field(description="Fingerprint of the operator token used: sha256 of it, 12 hex digits")
    address: str | None = Field(description="Client address and port the request came from")
    field: str = Field(description="Setting changed, e.g. period_s")
    old: Any = Field(description="Value in force before the change")
    new: Any = Field(description="Value in force after the change")


class AuditLog:
    """Configuration changes in table ``config_audit`` of a SQLite file (its own connection, WAL).

    Parameters
    ----------
    path : str or Path
        The service's SQLite file (``:memory:`` for a throw-away log).
    """

    def __init__(self, path: str | Path) -> None:
        self._lock = threading.Lock()
        self._db = sqlite3.connect(str(path), check_same_thread=False, isolation_level=None)
        with self._lock:
            self._db.execute("PRAGMA busy_timeout=5000")  # the results writer may hold the file briefly
            self._db.executescript(_SCHEMA)

    def record(self, field: str, old: Any, new: Any, *, token: str | None, address: str | None,
               at: float | None = None) -> AuditEntry:
        """Store one change and return it; ``token`` is the fingerprint, never the token."""
        at = time.time() if at is None else at
        with self._lock:
            self._db.execute(
                "INSERT INTO config_audit (at, token, address, field, old, new) VALUES (?, ?, ?, ?, ?, ?)",
                (at, token, address, field, json.dumps(old), json.dumps(new)))
        return AuditEntry(at=at, at_utc=utc_iso(at), token=token, address=address, field=field, old=old, new=new)

    def entries(self, limit: int = 100) -> list[AuditEntry]:
        """Changes, newest first."""
        with self._lock:
            rows = self._db.execute(
                "SELECT at, token, address, field, old, new FROM config_audit ORDER BY id DESC LIMIT ?",
                (int(limit),)).fetchall()
        return [AuditEntry(at=at, at_utc=utc_iso(at), token=tok, address=addr, field=f, old=json.loads(o),
                           new=json.loads(n)) for at, tok, addr, f, o, n in rows]

    def close(self) -> None:
        """Close the connection."""
        with self._lock:
            self._db.close()


__all__ = ["AuditEntry", "AuditLog", "token_identity"]
