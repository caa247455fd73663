"""Readable UTC times for messages, logs and REST (the service's times are seconds since the epoch)."""

from __future__ import annotations

from datetime import datetime, timezone


def utc_iso(t: float) -> str:
    """ISO 8601 UTC of ``t`` [s since the epoch], to the second or finer: ``2026-11-24T06:50:00Z``."""
    dt = datetime.fromtimestamp(t, tz=timezone.utc)
    spec = "seconds" if dt.microsecond == 0 else "milliseconds"
    return dt.isoformat(timespec=spec).replace("+00:00", "Z")


def utc_text(t: float) -> str:
    """``2026-11-24 06:50:00 UTC`` for ``t`` [s since the epoch], to the second, for people."""
    return datetime.fromtimestamp(t, tz=timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")


__all__ = ["utc_iso", "utc_text"]
