"""One identified model → one simulator's records, with the assumptions and derived values beside them."""

from __future__ import annotations

from aslm_core.records import andes, pslf, psse
from aslm_core.records.inverse import Assumptions, RecordError, invert

FORMATS: tuple[str, ...] = ("andes", "psse", "pslf")
MEDIA = {"andes": "application/json", "psse": "text/plain", "pslf": "text/plain"}


def export(identified: dict, fmt: str, assumptions: Assumptions | None = None, *, bus_number: int = 1,
           bus_name: str = "ASLM", kv: float = 138.0) -> dict:
    """Records of an identified model in one simulator's format.

    Parameters
    ----------
    identified : dict
        ``{"dynamic": D, "static": ZIP, "stderr": SE of D (optional)}``, e.g. ``IdentificationResult.to_dict()``.
    fmt : {"andes", "psse", "pslf"}
        ANDES JSON case fragment, PSS/E ``.raw`` load records + ``.dyr`` CIM5BL, or PSLF ``.dyd`` motorw.
    assumptions : Assumptions, optional
        The free quantity and the others (defaults documented in :class:`Assumptions`).
    bus_number, bus_name, kv
        Where the records put the load: bus number (PSS/E, PSLF; ANDES bus idx), name, rated kV.

    Returns
    -------
    dict
        ``format``, ``assumptions`` (as resolved, with ``free``), ``values`` and ``stderr`` of the derived
        quantities, ``units``, ``admissible`` intervals, and ``content``: the record text.

    Raises
    ------
    RecordError
        Unknown format, infeasible model or an assumption out of its admissible interval.
    """
    if fmt not in FORMATS:
        raise RecordError(f"unknown record format {fmt!r} (use one of {', '.join(FORMATS)})")
    try:
        dyn, sta = identified["dynamic"], identified["static"]
    except (KeyError, TypeError):
        raise RecordError("an identified model needs 'dynamic' and 'static' entries") from None
    rec = invert(dyn, sta, assumptions, stderr=identified.get("stderr"))
    if fmt == "andes":
        content = andes.dumps(andes.devices(rec, bus=bus_number, name=bus_name, kv=kv))
    elif fmt == "psse":
        content = psse.write(rec, bus=bus_number)
    else:
        content = pslf.write(rec, bus=bus_number, name=bus_name, kv=kv)
    return {"format": fmt, **rec.to_dict(), "content": content}
