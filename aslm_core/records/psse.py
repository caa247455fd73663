"""PSS/E records: a ``CIM5BL`` single-cage induction motor (``.dyr``) and two load records (``.raw`` v33).

Field orders from the PSS/E Model Library (CIM5BL: ICON IT; CONs RA, XA, XM, R1, X1, R2, X2, E1, SE(E1),
E2, SE(E2), MBASE, PMULT, H, VT, TV, TB, D, TNOM; impedances in pu on the motor base MBASE [MVA], H [s]
on MBASE, torque T = TNOM·(1 + Δω)^D) and the Data Formats Reference Manual (load data, v33: I, ID,
STATUS, AREA, ZONE, PL, QL, IP, IQ, YP, YQ, OWNER, SCALE, INTRPT; PL/QL [MW/Mvar], IP/IQ and YP/YQ
[MW/Mvar at 1 pu voltage]; YQ is negative for an inductive load).  The same order is what the open
readers of CIM5BL records use (e.g. uqgrid's ``parse_psse.add_dyr``), and PowerWorld documents the same
CIM5 parameters ("Load Characteristic CIM5").

The motor is one load (ID ``M``) carrying the motor's power at the operating voltage; a CIM5BL record
with MBASE > 0 takes its rating from MBASE.  Single cage: R2 = X2 = 0.  No saturation (E1 = SE1 = E2 =
SE2 = 0), no undervoltage trip (VT = 0), constant torque (D = 0).  The static load is a second load
(ID ``S``) with the identified ZIP (the motor's 1/X' removed) in PL/IP/YP and QL/IQ/YQ.
"""

from __future__ import annotations

from aslm_core.records.inverse import MotorRecord

CIM5BL_ICONS = ("IT",)
CIM5BL_CONS = ("RA", "XA", "XM", "R1", "X1", "R2", "X2", "E1", "SE1", "E2", "SE2", "MBASE", "PMULT", "H", "VT",
               "TV", "TB", "D", "TNOM")
LOAD_FIELDS = ("I", "ID", "STATUS", "AREA", "ZONE", "PL", "QL", "IP", "IQ", "YP", "YQ", "OWNER", "SCALE", "INTRPT")


def cim5bl_values(rec: MotorRecord) -> dict[str, float]:
    """The CIM5BL ICON and CONs (in :data:`CIM5BL_ICONS` + :data:`CIM5BL_CONS` order) of a record."""
    v = rec.values
    return {"IT": 1, "RA": v["Rs"], "XA": v["Xs"], "XM": v["Xm"], "R1": v["Rr"], "X1": v["Xr"], "R2": 0.0, "X2": 0.0,
            "E1": 0.0, "SE1": 0.0, "E2": 0.0, "SE2": 0.0, "MBASE": v["motor_mva"], "PMULT": 0.0, "H": v["H"],
            "VT": 0.0, "TV": 0.0, "TB": 0.0, "D": 0.0, "TNOM": 0.0}


def load_values(rec: MotorRecord, bus: int) -> list[dict[str, float | int | str]]:
    """The two load records (motor ``M``, static ``S``) as field → value, MW and Mvar."""
    v, sb = rec.values, rec.assumptions.sbase_mva
    common = {"I": bus, "STATUS": 1, "AREA": 1, "ZONE": 1}
    tail = {"OWNER": 1, "SCALE": 1, "INTRPT": 0}
    motor = {**common, "ID": "M", "PL": v["P_motor"] * sb, "QL": v["Q_motor"] * sb, "IP": 0.0, "IQ": 0.0,
             "YP": 0.0, "YQ": 0.0, **tail}
    static = {**common, "ID": "S", "PL": v["Pp"] * sb, "QL": v["Qp"] * sb, "IP": v["Pi"] * sb, "IQ": v["Qi"] * sb,
              "YP": v["Pz"] * sb, "YQ": -v["Qz"] * sb, **tail}
    return [motor, static]


def _num(x: float | int | str) -> str:
    if isinstance(x, str):
        return f"'{x}'"
    if isinstance(x, int):
        return str(x)
    return f"{x:.10g}"


def write(rec: MotorRecord, *, bus: int = 1) -> str:
    """``.raw`` load records and the ``.dyr`` CIM5BL record of one bus, as text with both sections marked."""
    loads = "\n".join(", ".join(_num(row[f]) for f in LOAD_FIELDS) for row in load_values(rec, bus))
    cv = cim5bl_values(rec)
    dyr = f"{bus} 'CIM5BL' 'M' " + " ".join(_num(cv[k]) for k in (*CIM5BL_ICONS, *CIM5BL_CONS)) + " /"
    asm = rec.assumptions
    return (f"@! ASLM records for PSS/E: free quantity {asm.free}, X' {rec.values['Xp']:.6g} pu (motor base), "
            f"loading {asm.loading:g}, Xs/Xr {asm.xs_over_xr:g}, v0 {asm.v0:g} pu, f0 {asm.f0:g} Hz, "
            f"system base {asm.sbase_mva:g} MVA\n"
            f"@! .raw load data (v33: {', '.join(LOAD_FIELDS)})\n{loads}\n"
            f"@! .dyr (CIM5BL: IBUS 'CIM5BL' ID {' '.join(CIM5BL_ICONS + CIM5BL_CONS)} /)\n{dyr}\n")
