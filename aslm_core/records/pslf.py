"""PSLF records: a ``motorw`` induction motor in a ``.dyd`` file, with the static load's ZIP.

The ``.dyd`` syntax is PSLF's: ``model bus "name" kV "id" : #9 mva=MVA "param" value ...`` (parameters by
name, so their order is free; omitted ones take PSLF's defaults).  motorw's parameters and meaning as
documented for PSLF's MOTORW by PowerWorld ("Load Characteristic MOTORW", which reads DYD files): Mbase
(the ``mva=`` of the record), Pul (fraction of the load's constant-power part the motor represents), Ls
(synchronous reactance X), Lp (transient reactance X'), Ra, Tpo (Td0 [s]), H [s], D (the power's speed
exponent: T = T0·ω^(D−1), so D = 1 is the constant torque of the transformed model), Lpp and Tppo
(subtransient; Lpp = Lp and Tppo = 0 make the motor single-cage, third order).  Impedances and H on
Mbase.  PowerWorld's validation lowers Lp to 0.4·Ls when Lp > 0.4·Ls: keep X'/X below 0.4.

The motor sits on a load (id ``M``) with Pul = 1, whose power at the operating voltage is the motor's;
the static load (id ``S``) is written as comment lines with its constant-power, -current and
-admittance parts [MW/Mvar at 1 pu] for the EPC load record.
"""

from __future__ import annotations

from aslm_core.records.inverse import MotorRecord

MOTORW_FIELDS = ("pul", "ls", "lp", "ra", "tpo", "h", "d", "lpp", "tppo")
STATIC_FIELDS = ("p", "q", "ip", "iq", "g", "b")


def motorw_values(rec: MotorRecord) -> dict[str, float]:
    """``mva`` and the motorw parameters of :data:`MOTORW_FIELDS`."""
    v = rec.values
    return {"mva": v["motor_mva"], "pul": 1.0, "ls": v["X"], "lp": v["Xp"], "ra": v["Rs"], "tpo": v["Td0"],
            "h": v["H"], "d": 1.0, "lpp": v["Xp"], "tppo": 0.0}


def static_values(rec: MotorRecord) -> dict[str, float]:
    """The static load's parts [MW, Mvar at 1 pu]: p/q constant power, ip/iq current, g/b admittance (b > 0
    inductive, as a load)."""
    v, sb = rec.values, rec.assumptions.sbase_mva
    return {"p": v["Pp"] * sb, "q": v["Qp"] * sb, "ip": v["Pi"] * sb, "iq": v["Qi"] * sb, "g": v["Pz"] * sb,
            "b": v["Qz"] * sb}


def write(rec: MotorRecord, *, bus: int = 1, name: str = "ASLM", kv: float = 138.0) -> str:
    """The ``.dyd`` text of one bus: comment lines (assumptions, static load) and the motorw record."""
    mv = motorw_values(rec)
    sv = static_values(rec)
    asm = rec.assumptions
    params = " ".join(f'"{k}" {mv[k]:.10g}' for k in MOTORW_FIELDS)
    return (f"# ASLM records for PSLF: free quantity {asm.free}, X' {rec.values['Xp']:.6g} pu (motor base), "
            f"loading {asm.loading:g}, Xs/Xr {asm.xs_over_xr:g}, v0 {asm.v0:g} pu, f0 {asm.f0:g} Hz, "
            f"system base {asm.sbase_mva:g} MVA\n"
            f"# motor load \"M\": p {rec.values['P_motor'] * asm.sbase_mva:.10g} MW, "
            f"q {rec.values['Q_motor'] * asm.sbase_mva:.10g} Mvar at v0\n"
            f"# static load \"S\" (MW, Mvar at 1 pu): "
            + " ".join(f"{k} {sv[k]:.10g}" for k in STATIC_FIELDS) + "\n"
            f'motorw {bus} "{name}" {kv:g} "M " : #9 mva={mv["mva"]:.10g} {params}\n')
