"""The inverse map: from the identified D = [a, b, H2, Tm] and ZIP to a motor a simulator takes.

The identifier fixes (docs/numerics.md, eq. 4–5, system base)::

    a = (X/X' − 1)/(Td0·X'),   b = X/(Td0·X'),   H2 = 2H,   Tm,   Qz ∋ 1/X'

so a/b = 1/X' − 1/X: two equations for three unknowns (X, X', Td0).  One of them is free; this module
takes X' (on the motor's own base) or Td0 as the stated assumption and solves the rest in closed form::

    X = X'·b/(b − a·X'),   Td0 = 1/(b − a·X')          (X' < b/a, i.e. Td0 > 1/b)

A record also needs the motor's MVA rating, which the data cannot give either: at the equilibrium
(rs = 0) the motor's electrical power equals Tm, so a loading factor LF (electrical power over rating)
gives S_motor = Tm/LF (system pu).  The equivalent circuit (Rs = 0) follows from a second assumption,
the split Xs/Xr of the leakage (default Xs = Xr)::

    X = Xs + Xm,   X' = Xs + Xr·Xm/(Xr + Xm),   Td0 = (Xr + Xm)/(ω0·Rr)

and the static part loses the motor's V²/X' from Qz (that term is the motor's, in the record's motor).
Every assumption is a field of :class:`Assumptions`; the payloads echo them.  Standard errors of D are
carried to every derived quantity by the delta method (central differences of this closed form).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np

# Typical transient reactance of an induction motor on its own rating (e.g. 0.197 pu for the motor of
# docs/andes_crosscheck.md); only the default of Assumptions.xp, stated in every payload.
DEFAULT_XP = 0.2
DYNAMIC = ("a", "b", "H2", "Tm")
ZIP = ("Pz", "Pi", "Pp", "Qz", "Qi", "Qp")


class RecordError(ValueError):
    """The identified model cannot be written under the stated assumptions (the message says why)."""


@dataclass(frozen=True)
class Assumptions:
    """What the data cannot fix, stated explicitly.

    Attributes
    ----------
    xp : float or None
        Transient reactance X' on the motor's base [pu].  The free quantity; default
        :data:`DEFAULT_XP` (0.2) when neither ``xp`` nor ``td0`` is given.  Admissible: 0 < X' < (b/a)·S_motor.
    td0 : float or None
        Open-circuit transient time constant Td0 [s], instead of ``xp``.  Admissible: Td0 > 1/b.
    loading : float
        Loading factor: the motor's electrical power at the operating point over its MVA rating (0, 1].
        Sets the motor base S_motor = Tm/loading.  Default 0.8.
    xs_over_xr : float
        Stator over rotor leakage reactance, Xs/Xr (>= 0); default 1 (Xs = Xr).
    sbase_mva : float
        System base of the identified per-unit values [MVA]; default 100.
    f0 : float
        Nominal frequency the identification used [Hz] (sets Rr and the slip); default 50.
    v0 : float
        Operating voltage for the power-flow split between motor and static load [pu]; default 1.
    require_static_qz_nonnegative : bool
        Also require the static Qz − 1/X' >= 0 (no capacitive constant-impedance part left).  Off by
        default: the ZIP split is not identifiable from ambient data (docs/andes_crosscheck.md), so Qz
        alone is a weak constraint; the bound is reported either way.
    """

    xp: float | None = None
    td0: float | None = None
    loading: float = 0.8
    xs_over_xr: float = 1.0
    sbase_mva: float = 100.0
    f0: float = 50.0
    v0: float = 1.0
    require_static_qz_nonnegative: bool = False

    def resolved(self) -> Assumptions:
        """The same assumptions with the default X' filled in when neither X' nor Td0 is given."""
        if self.xp is not None and self.td0 is not None:
            raise RecordError("give X' (xp) or Td0 (td0), not both: they are the same free quantity")
        if self.xp is None and self.td0 is None:
            return replace(self, xp=DEFAULT_XP)
        return self

    @property
    def free(self) -> str:
        """Which quantity was assumed: ``"xp"`` or ``"td0"``."""
        return "td0" if self.td0 is not None else "xp"


@dataclass(frozen=True)
class MotorRecord:
    """The identified load as a simulator's motor + static load, with what was assumed.

    Attributes
    ----------
    assumptions : Assumptions
        As resolved (the default X' filled in).
    values : dict
        Derived quantities (names and units in :data:`QUANTITIES`).
    stderr : dict
        Standard errors of ``values`` from those of D (delta method; NaN where D had none).
    admissible : dict
        Intervals [lower, upper] of the free quantity: ``xp`` [pu, motor base], ``td0`` [s], and
        ``xp_static_qz_nonnegative`` (X' for which the static Qz stays >= 0; None if none).
    """

    assumptions: Assumptions
    values: dict[str, float]
    stderr: dict[str, float]
    admissible: dict[str, list[float] | None]

    def to_dict(self) -> dict:
        """Plain JSON dict; ``assumptions`` records ``free`` too.  Non-finite numbers become null (strict JSON):
        an unbounded interval end, or a standard error that D's did not give."""
        return {"assumptions": {**asdict(self.assumptions), "free": self.assumptions.free},
                "values": _finite(self.values), "stderr": _finite(self.stderr),
                "admissible": {k: None if iv is None else [_num(x) for x in iv] for k, iv in self.admissible.items()},
                "units": dict(QUANTITIES)}


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _finite(d: dict[str, float]) -> dict[str, float | None]:
    return {k: _num(v) for k, v in d.items()}


# name → unit and base of every derived quantity.
QUANTITIES: dict[str, str] = {
    "motor_mva": "MVA (motor rating, S_motor·sbase)",
    "X": "pu, motor base (synchronous reactance Xs + Xm)",
    "Xp": "pu, motor base (transient reactance X')",
    "Td0": "s (open-circuit transient time constant)",
    "H": "s, motor base (inertia constant)",
    "Tm": "pu, motor base (load torque; equals the loading factor)",
    "Rs": "pu, motor base (stator resistance; 0 in the transformed model)",
    "Xs": "pu, motor base (stator leakage)",
    "Xm": "pu, motor base (magnetising)",
    "Xr": "pu, motor base (rotor leakage)",
    "Rr": "pu, motor base (rotor resistance)",
    "X_sys": "pu, system base", "Xp_sys": "pu, system base", "H2_sys": "s, system base (2H)",
    "Tm_sys": "pu, system base",
    "Pz": "pu, system base (static, of V²)", "Pi": "pu, system base (static, of V)", "Pp": "pu, system base",
    "Qz": "pu, system base (static, of V², the motor's 1/X' removed)", "Qi": "pu, system base (of V)",
    "Qp": "pu, system base",
    "v0": "pu (operating voltage)", "slip0": "- (motor slip at v0)",
    "P_motor": "pu, system base (motor at v0)", "Q_motor": "pu, system base (motor at v0, its V²/X' included)",
    "P_static": "pu, system base (static at v0)", "Q_static": "pu, system base (static at v0)",
}


def _leakage_split(x: float, xp: float, k: float) -> tuple[float, float, float]:
    """Xs, Xm, Xr from X, X' with Xs = k·Xr (any base).

    X' = Xs + Xr·Xm/(Xr + Xm) with Xm = X − k·Xr is the quadratic
    k²·Xr² − (X'·(k − 1) + X·(k + 1))·Xr + X·X' = 0; its smaller root keeps Xm > 0.
    """
    bq = xp * (k - 1.0) + x * (k + 1.0)
    if k == 0.0:
        xr = x * xp / (x - xp)
    else:
        disc = bq * bq - 4.0 * k * k * x * xp
        if disc < 0.0:
            raise RecordError(f"no leakage split Xs = {k:g}·Xr gives X = {x:.4g}, X' = {xp:.4g}")
        xr = 2.0 * x * xp / (bq + math.sqrt(disc))  # the smaller root, cancellation-free
    xs = k * xr
    xm = x - xs
    if not (xm > 0.0 and xr > 0.0):
        raise RecordError(f"no positive magnetising reactance for X = {x:.4g}, X' = {xp:.4g}, Xs/Xr = {k:g}")
    return xs, xm, xr


def _check_d(d: np.ndarray, v0: float) -> None:
    a, b, h2, tm = d
    if not np.all(np.isfinite(d)):
        raise RecordError(f"D = {d.tolist()} is not finite")
    if a <= 0.0 or b <= 0.0 or h2 <= 0.0:
        raise RecordError(f"a, b and H2 must be positive for a motor (D = {d.tolist()})")
    if tm <= 0.0:
        raise RecordError(f"Tm = {tm:.4g}: the identified motor carries no load, so it has no rating to write "
                          "(the loading factor sets the motor base from Tm)")
    if a * v0 * v0 < 2.0 * b * tm:
        raise RecordError(f"no motor equilibrium at v0 = {v0:.4g} pu: a·v0² = {a * v0 * v0:.4g} must exceed "
                          f"2b·Tm = {2 * b * tm:.4g} (the load torque exceeds the breakdown torque)")


def admissible(d: np.ndarray, static: dict[str, float], assumptions: Assumptions) -> dict[str, list[float] | None]:
    """Intervals of the free quantity for which the record exists.

    Parameters
    ----------
    d : array_like
        D = [a [1/s], b [1/s], H2 [s], Tm [pu]].
    static : dict
        Identified ZIP {Pz, Pi, Pp, Qz, Qi, Qp} [pu]; Qz includes the motor's 1/X'.
    assumptions : Assumptions

    Returns
    -------
    dict
        ``xp``: open interval (0, (b/a)·S_motor) [pu, motor base]; ``td0``: (1/b, inf) [s];
        ``xp_static_qz_nonnegative``: [S_motor/Qz, (b/a)·S_motor) where Qz > 0, else None.
    """
    a, b, _, tm = (float(x) for x in d)
    sm = tm / assumptions.loading
    upper = b / a * sm
    qz = float(static["Qz"])
    lo_q = sm / qz if qz > 0.0 else math.inf
    return {"xp": [0.0, upper], "td0": [1.0 / b, math.inf],
            "xp_static_qz_nonnegative": [lo_q, upper] if lo_q < upper else None}


def _solve(d: np.ndarray, static: dict[str, float], asm: Assumptions) -> dict[str, float]:
    """Every derived quantity (see :data:`QUANTITIES`) for one D; RecordError when none exists."""
    _check_d(d, asm.v0)
    a, b, h2, tm = (float(x) for x in d)
    sm = tm / asm.loading  # motor base [system pu]
    if asm.td0 is not None:
        if not asm.td0 > 1.0 / b:
            raise RecordError(f"Td0 = {asm.td0:.4g} s is outside its admissible interval Td0 > 1/b = {1 / b:.4g} s")
        xp_sys = (b - 1.0 / asm.td0) / a
    else:
        xp_sys = asm.xp / sm
        if not 0.0 < xp_sys < b / a:
            raise RecordError(
                f"X' = {asm.xp:.4g} pu (motor base) is outside its admissible interval "
                f"(0, {b / a * sm:.4g}) = (0, (b/a)·Tm/loading): a/b = 1/X' − 1/X needs X' < b/a on the system "
                f"base ({b / a:.4g} pu); choose a smaller X', or a smaller loading factor")
    td0 = 1.0 / (b - a * xp_sys)
    x_sys = xp_sys * b * td0
    qz_static = float(static["Qz"]) - 1.0 / xp_sys
    if asm.require_static_qz_nonnegative and qz_static < 0.0:
        raise RecordError(f"static Qz − 1/X' = {qz_static:.4g} < 0 with X' = {xp_sys * sm:.4g} pu (motor base); "
                          f"the interval where it stays >= 0 is {admissible(d, static, asm)['xp_static_qz_nonnegative']}")
    xs, xm, xr = _leakage_split(x_sys * sm, xp_sys * sm, asm.xs_over_xr)
    w0 = 2.0 * math.pi * asm.f0
    rr = (xr + xm) / (w0 * td0)
    v0 = asm.v0
    # Low-slip equilibrium of eq. 4 at v0 (motor.steady_state, restated here without numba).
    c = 2.0 * tm * b * b / (a * v0 * v0 + math.sqrt(max(a * a * v0**4 - 4.0 * tm * tm * b * b, 0.0)))
    q_motor = v0 * v0 / xp_sys - a * b * v0 * v0 / (b * b + c * c)
    out = {
        "motor_mva": sm * asm.sbase_mva, "X": x_sys * sm, "Xp": xp_sys * sm, "Td0": td0, "H": h2 / (2.0 * sm),
        "Tm": tm / sm, "Rs": 0.0, "Xs": xs, "Xm": xm, "Xr": xr, "Rr": rr,
        "X_sys": x_sys, "Xp_sys": xp_sys, "H2_sys": h2, "Tm_sys": tm,
        "Pz": float(static["Pz"]), "Pi": float(static["Pi"]), "Pp": float(static["Pp"]),
        "Qz": qz_static, "Qi": float(static["Qi"]), "Qp": float(static["Qp"]),
        "v0": v0, "slip0": c / w0, "P_motor": tm, "Q_motor": q_motor,
    }
    out["P_static"] = out["Pz"] * v0 * v0 + out["Pi"] * v0 + out["Pp"]
    out["Q_static"] = out["Qz"] * v0 * v0 + out["Qi"] * v0 + out["Qp"]
    return out


def _stderr(d: np.ndarray, static: dict[str, float], asm: Assumptions, base: dict[str, float],
            cov: np.ndarray) -> dict[str, float]:
    """Delta method: sqrt(diag(J·cov·Jᵀ)) with J by central differences (one-sided at an interval edge)."""
    names = list(base)
    jac = np.zeros((len(names), 4))
    for j in range(4):
        h = 1e-6 * max(abs(d[j]), 1e-6)
        vals = []
        for sgn in (1.0, -1.0):
            dj = d.copy()
            dj[j] += sgn * h
            try:
                vals.append(_solve(dj, static, asm))
            except RecordError:
                vals.append(None)
        hi, lo = vals
        for i, n in enumerate(names):
            if hi is not None and lo is not None:
                jac[i, j] = (hi[n] - lo[n]) / (2 * h)
            elif hi is not None:
                jac[i, j] = (hi[n] - base[n]) / h
            elif lo is not None:
                jac[i, j] = (base[n] - lo[n]) / h
            else:
                jac[i, j] = np.nan
    var = np.einsum("ij,jk,ik->i", jac, cov, jac)
    return {n: float(math.sqrt(v)) if v >= 0.0 else math.nan for n, v in zip(names, var, strict=True)}


def invert(dynamic: dict[str, float], static: dict[str, float], assumptions: Assumptions | None = None,
           stderr: dict[str, float | None] | None = None, cov: np.ndarray | None = None) -> MotorRecord:
    """Third-order motor, equivalent circuit and static load from an identified model.

    Parameters
    ----------
    dynamic : dict
        D = {a [1/s], b [1/s], H2 [s], Tm [pu, system base]}.
    static : dict
        ZIP {Pz, Pi, Pp, Qz, Qi, Qp} [pu, system base], Qz including the motor's 1/X'.  The exponential
        static model is refused (its Q0 cannot give up a V² term and stay exponential).
    assumptions : Assumptions, optional
        Defaults: X' = 0.2 pu on the motor base, loading 0.8, Xs = Xr, 100 MVA, 50 Hz, v0 = 1 pu.
    stderr : dict, optional
        Standard errors of D (as identified); treated as uncorrelated unless ``cov`` is given.
    cov : ndarray (4, 4), optional
        Covariance of D, overriding ``stderr``.

    Returns
    -------
    MotorRecord

    Raises
    ------
    RecordError
        Infeasible D (no motor, no equilibrium at v0), an assumption outside its admissible interval, or a
        static model that is not ZIP; the message names the bound.
    """
    asm = (assumptions or Assumptions()).resolved()
    if not 0.0 < asm.loading <= 1.0:
        raise RecordError(f"loading factor {asm.loading:g} must lie in (0, 1]")
    if asm.xs_over_xr < 0.0 or asm.sbase_mva <= 0.0 or asm.f0 <= 0.0 or asm.v0 <= 0.0:
        raise RecordError("xs_over_xr must be >= 0 and sbase_mva, f0, v0 positive")
    missing = [k for k in ZIP if k not in static]
    if missing:
        raise RecordError(f"records need the ZIP static model; missing {missing} (identify with --static zip)")
    try:
        d = np.array([float(dynamic[k]) for k in DYNAMIC])
    except KeyError as exc:
        raise RecordError(f"D is missing {exc.args[0]!r}") from None
    values = _solve(d, static, asm)
    if cov is None:
        se = np.array([float(s) if s is not None else math.nan for s in ((stderr or {}).get(k) for k in DYNAMIC)])
        cov = np.diag(se * se)
    return MotorRecord(asm, values, _stderr(d, static, asm, values, np.asarray(cov, dtype=float)),
                       admissible(d, static, asm))


def transformed(values: dict[str, float], f0: float) -> dict[str, float]:
    """D = [a, b, H2, Tm] (system base) back from an equivalent circuit on the motor base.

    Parameters
    ----------
    values : dict
        ``motor_mva``, ``Xs``, ``Xm``, ``Xr``, ``Rr``, ``H``, ``Tm`` (motor base) and the system base in
        ``sbase_mva`` [MVA].
    f0 : float
        Nominal frequency [Hz].

    Returns
    -------
    dict
        {a [1/s], b [1/s], H2 [s], Tm [pu]} on the system base: what the identifier would see.
    """
    sm = values["motor_mva"] / values["sbase_mva"]
    x = (values["Xs"] + values["Xm"]) / sm
    xp = (values["Xs"] + values["Xr"] * values["Xm"] / (values["Xr"] + values["Xm"])) / sm
    td0 = (values["Xr"] + values["Xm"]) / (2.0 * math.pi * f0 * values["Rr"])
    return {"a": (x / xp - 1.0) / (td0 * xp), "b": x / (td0 * xp), "H2": 2.0 * values["H"] * sm,
            "Tm": values["Tm"] * sm}
