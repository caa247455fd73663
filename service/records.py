"""Records for downstream simulators from the service's results (REST, the ``records`` sink, ``aslm export``).

A thin layer over :mod:`aslm_core.records` (pure numerics, no numba): it takes a :class:`BusResult` or an
``aslm identify --json`` object, and names the load's bus in the records.
"""

from __future__ import annotations

import re

from aslm_core.records import Assumptions, RecordError, export
from service.models import BusResult


def bus_number(bus: str) -> int:
    """A bus number for PSS/E and PSLF records: the trailing integer of the bus name, else 1."""
    m = re.search(r"(\d+)$", bus)
    return int(m.group(1)) if m else 1


def identified_of(obj: dict) -> tuple[str, dict]:
    """(bus, identified model) of a BusResult-shaped or an ``aslm identify --json`` object.

    Raises
    ------
    RecordError
        A result without parameters (failed or skipped), or an object with neither shape.
    """
    if "parameters" in obj and "status" in obj:
        if obj["status"] != "ok" or not obj.get("parameters"):
            raise RecordError(f"result of bus {obj.get('bus')!r} at period {obj.get('period')} is {obj['status']} "
                              f"({obj.get('reason')}): no parameters to write")
        return str(obj.get("bus") or "ASLM"), obj["parameters"]
    if "dynamic" in obj and "static" in obj:
        return str(obj.get("bus") or "ASLM"), obj
    raise RecordError("expected an identification result (aslm identify --json) or a service result (REST/Zenoh)")


def record_payload(obj: dict | BusResult, fmt: str, assumptions: Assumptions, *, number: int | None = None,
                   kv: float = 138.0) -> dict:
    """The records of one result: ``bus``, ``period`` (if any), and :func:`aslm_core.records.export`'s payload.

    Parameters
    ----------
    obj : dict or BusResult
        A service result or an ``aslm identify --json`` object.
    fmt : {"andes", "psse", "pslf"}
    assumptions : Assumptions
    number : int, optional
        Bus number in the records (default: :func:`bus_number` of the bus name).
    kv : float
        Rated voltage of the bus [kV].
    """
    if isinstance(obj, BusResult):
        obj = obj.model_dump()
    bus, identified = identified_of(obj)
    out = export(identified, fmt, assumptions, bus_number=number if number is not None else bus_number(bus),
                 bus_name=bus, kv=kv)
    return {"bus": bus, "period": obj.get("period"), **out}
