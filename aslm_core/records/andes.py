"""ANDES records: ``Motor3`` + ``ZIP`` on a ``PQ``, in ANDES's JSON case format.

Field names, units and bases from ANDES 2.0's own model definitions (``andes/models/motor/motorbase.py``,
``motor3.py``, ``andes/models/dynload/zip.py``, ``andes/models/static/pq.py``) and its JSON reader
(``andes/io/json.py``: ``{model: [ {param: value, ...}, ...], "_config": [{section, key, value}, ...]}``):

* ``Motor3`` device data are on the motor's base (``Sn`` [MVA], ``Vn`` [kV]): ``xs``, ``xr1``, ``xm``,
  ``rr1`` (impedances, ``z=True``), ``Hm`` [s] (``power=True``).  ANDES converts them to the system
  base itself.  The torque coefficients ``c1``–``c3`` are *not* converted (no ``power`` flag): ``c1`` is the
  load torque on the system base (docs/andes_crosscheck.md), and c2 = c3 = 0 is the constant torque of
  the transformed model.  ``rs`` must be non-zero in ANDES: the record's Rs = 0 is written as
  :data:`RS_FLOOR` (its effect: 0.2 % on P in the cross-check's conversion check).
* ``PQ`` ``p0``, ``q0`` are on the system base: the static load's power at the operating voltage.
* ``ZIP`` takes percentages of the PQ's power-flow power (``kpp + kpi + kpz = 100``), evaluated at the
  bus's power-flow voltage; the percentages here are at the assumed ``v0``, so the record is exact when
  ``v0`` is the power-flow voltage (re-export with the solved voltage otherwise).
* ``_config``: PQ ``p2p = q2q = 1`` and the other conversions 0, as ``ZIP``'s documentation asks (this
  section applies to every PQ of a case the fragment is merged into), and ``pq2z = 0`` so that the
  power flow keeps the PQ at constant power.

ANDES's power flow starts Motor3 at slip 1 and may converge to the high-slip root or not at all; set its
states to the low-slip equilibrium first (``benchmarks/andes_crosscheck.py::_init_motor_guess``).
"""

from __future__ import annotations

import json

from aslm_core.records.inverse import MotorRecord, RecordError

RS_FLOOR = 1e-5  # [pu, motor base] ANDES refuses rs = 0
PQ_CONFIG = {"p2p": 1.0, "p2i": 0.0, "p2z": 0.0, "q2q": 1.0, "q2i": 0.0, "q2z": 0.0, "pq2z": 0}


def _shares(z: float, i: float, p: float, v0: float, total: float, what: str) -> tuple[float, float, float]:
    """ZIP percentages of ``total`` (the static power at v0)."""
    if abs(total) < 1e-9 * max(abs(z), abs(i), abs(p), 1e-12):
        raise RecordError(f"static {what} at v0 is {total:.3g} pu: ANDES's ZIP (percentages of the PQ's power) "
                          "cannot hold a ZIP whose parts cancel there")
    if total == 0.0:
        return 0.0, 0.0, 100.0
    return 100.0 * z * v0 * v0 / total, 100.0 * i * v0 / total, 100.0 * p / total


def devices(rec: MotorRecord, *, bus: int | str = 1, name: str = "ASLM", kv: float = 138.0) -> dict[str, list[dict]]:
    """The load of one bus as ANDES devices: a PQ (static power at v0), its ZIP and a Motor3.

    Parameters
    ----------
    rec : MotorRecord
        From :func:`aslm_core.records.invert`.
    bus : int or str
        ANDES ``Bus`` idx the load sits on.
    name : str
        Prefix of the device idx and names.
    kv : float
        Rated voltage of the bus [kV] (``Vn`` of the PQ and the motor).

    Returns
    -------
    dict
        ``{"PQ": [...], "ZIP": [...], "Motor3": [...], "_config": [...]}`` in ANDES's JSON layout.
    """
    v = rec.values
    asm = rec.assumptions
    kpz, kpi, kpp = _shares(v["Pz"], v["Pi"], v["Pp"], v["v0"], v["P_static"], "P")
    kqz, kqi, kqp = _shares(v["Qz"], v["Qi"], v["Qp"], v["v0"], v["Q_static"], "Q")
    pq = f"{name}_PQ"
    return {
        "_config": [{"section": "PQ", "key": k, "value": val} for k, val in PQ_CONFIG.items()],
        "PQ": [{"idx": pq, "u": 1, "name": pq, "bus": bus, "Vn": kv, "p0": v["P_static"], "q0": v["Q_static"],
                "vmax": 1.2, "vmin": 0.8}],
        "ZIP": [{"idx": f"{name}_ZIP", "u": 1, "name": f"{name}_ZIP", "pq": pq, "kpp": kpp, "kpi": kpi, "kpz": kpz,
                 "kqp": kqp, "kqi": kqi, "kqz": kqz}],
        "Motor3": [{"idx": f"{name}_M", "u": 1, "name": f"{name}_M", "bus": bus, "Sn": v["motor_mva"], "Vn": kv,
                    "fn": asm.f0, "rs": RS_FLOOR, "xs": v["Xs"], "xr1": v["Xr"], "xm": v["Xm"], "rr1": v["Rr"],
                    "Hm": v["H"], "c1": v["Tm_sys"], "c2": 0.0, "c3": 0.0, "zb": 1}],
    }


def two_bus_case(rec: MotorRecord, *, x_line: float = 0.05, faults: list[dict] | None = None,
                kv: float = 138.0) -> dict[str, list[dict]]:
    """A two-bus ANDES case around the record: a slack (an infinite bus in the time domain) feeding
    bus 2 through a reactance, bus 2 holding the exported load.

    Parameters
    ----------
    rec : MotorRecord
    x_line : float
        Line reactance [pu, system base]; with a bus fault of reactance xf it sets the sag depth.
    faults : list of dict, optional
        ANDES ``Fault`` rows on bus 2 ({tf [s], tc [s], xf [pu], rf [pu]}).
    kv : float
        Rated voltage of both buses [kV].

    Returns
    -------
    dict
        A complete case in ANDES's JSON layout (``json.dumps`` it to a ``.json`` file for ``andes.load``).
    """
    case = devices(rec, bus=2, kv=kv)
    case["_config"] = [{"section": "System", "key": "freq", "value": rec.assumptions.f0},
                       {"section": "System", "key": "mva", "value": rec.assumptions.sbase_mva}, *case["_config"]]
    case["Bus"] = [{"idx": i, "u": 1, "name": f"BUS{i}", "Vn": kv, "v0": 1.0, "a0": 0.0} for i in (1, 2)]
    case["Slack"] = [{"idx": 1, "u": 1, "name": "SLACK", "bus": 1, "Sn": 100.0 * rec.assumptions.sbase_mva,
                      "Vn": kv, "v0": 1.0, "a0": 0.0, "p0": 0.0, "q0": 0.0, "pmax": 999.0, "pmin": -999.0,
                      "qmax": 999.0, "qmin": -999.0}]
    case["Line"] = [{"idx": "L1", "u": 1, "name": "L1", "bus1": 1, "bus2": 2, "Vn1": kv, "Vn2": kv,
                     "fn": rec.assumptions.f0, "r": 0.0, "x": x_line, "b": 0.0}]
    if faults:
        case["Fault"] = [{"idx": f"F{k}", "u": 1, "name": f"F{k}", "bus": 2, **f} for k, f in enumerate(faults, 1)]
    return case


def dumps(case: dict) -> str:
    """The case as ANDES JSON text."""
    return json.dumps(case, indent=1)
