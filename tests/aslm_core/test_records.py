"""aslm_core.records: the inverse map reproduces D, refuses what cannot be written, and the PSS/E, PSLF and
ANDES records parse back field by field to the same values (and to the same D)."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from aslm_core.records import Assumptions, RecordError, admissible, export, invert, pslf, psse, transformed

STATIC = {"Pz": 0.06, "Pi": 0.045, "Pp": 0.045, "Qz": 1.3105, "Qi": 0.03, "Qp": 0.03}
D_ANDES = {"a": 22.796, "b": 19.159, "H2": 1.0, "Tm": 0.2}
NAMES = ("a", "b", "H2", "Tm")


def _cases(n: int = 40, seed: int = 3) -> list[dict]:
    """Random D in the paper's box with an equilibrium at 1 pu (margin 10 %)."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        a, b, h2 = rng.uniform(10, 80), rng.uniform(3, 30), rng.uniform(0.5, 3)
        tm = rng.uniform(0.02, min(1.0, 0.9 * a / (2 * b)))
        out.append({"a": a, "b": b, "H2": h2, "Tm": tm})
    return out


def _assert_d(values: dict, asm: Assumptions, d: dict) -> None:
    back = transformed({**values, "sbase_mva": asm.sbase_mva}, asm.f0)
    for k in NAMES:
        assert back[k] == pytest.approx(d[k], rel=1e-10), (k, back, d, asm)


@pytest.mark.parametrize("loading", [0.3, 0.8, 1.0])
@pytest.mark.parametrize("xs_over_xr", [0.0, 0.5, 1.0, 2.0])
def test_inverse_reproduces_d_for_every_xp_in_range(loading, xs_over_xr):
    for d in _cases(15):
        base = Assumptions(loading=loading, xs_over_xr=xs_over_xr, f0=60.0, sbase_mva=100.0)
        lo, hi = admissible(np.array([d[k] for k in NAMES]), STATIC, base)["xp"]
        for frac in (0.01, 0.25, 0.5, 0.75, 0.99):
            asm = Assumptions(xp=lo + frac * (hi - lo), loading=loading, xs_over_xr=xs_over_xr, f0=60.0)
            rec = invert(d, STATIC, asm)
            v = rec.values
            _assert_d(v, asm, d)
            # The third-order form gives the same D (a, b from X, X', Td0 on the system base).
            sm = v["motor_mva"] / asm.sbase_mva
            x, xp = v["X"] / sm, v["Xp"] / sm
            assert (x / xp - 1) / (v["Td0"] * xp) == pytest.approx(d["a"], rel=1e-10)
            assert x / (v["Td0"] * xp) == pytest.approx(d["b"], rel=1e-10)
            # The motor's 1/X' leaves the static Qz and nothing else changes.
            assert v["Qz"] + 1 / v["Xp_sys"] == pytest.approx(STATIC["Qz"], rel=1e-12)
            assert v["P_static"] + v["P_motor"] == pytest.approx(
                sum(STATIC[k] for k in ("Pz", "Pi", "Pp")) + d["Tm"], rel=1e-12)


def test_inverse_with_td0_free_matches_the_same_xp():
    for d in _cases(10, seed=5):
        hi = admissible(np.array([d[k] for k in NAMES]), STATIC, Assumptions(loading=0.5))["xp"][1]
        rec = invert(d, STATIC, Assumptions(f0=50.0, xp=0.4 * hi, loading=0.5))
        back = invert(d, STATIC, Assumptions(f0=50.0, td0=rec.values["Td0"], loading=0.5))
        assert back.values["Xp"] == pytest.approx(rec.values["Xp"], rel=1e-9)
        assert back.assumptions.free == "td0"
        _assert_d(back.values, back.assumptions, d)


def test_default_assumptions_recover_the_andes_crosscheck_motor():
    """X' = 0.2 and loading 0.8 are the cross-check's motor (25 MVA, x' = 0.1968): its rating comes back."""
    rec = invert(D_ANDES, STATIC, Assumptions(f0=60.0))
    assert rec.values["motor_mva"] == pytest.approx(25.0)
    assert rec.values["H"] == pytest.approx(2.0)
    assert rec.assumptions.xp == 0.2 and rec.assumptions.free == "xp"


@pytest.mark.parametrize("asm, match", [
    (Assumptions(xp=0.3, f0=60.0), "admissible interval"),        # b/a·S = 0.21 pu
    (Assumptions(xp=-0.1, f0=60.0), "admissible interval"),
    (Assumptions(td0=0.04, f0=60.0), "Td0 > 1/b"),
    (Assumptions(xp=0.1, td0=1.0), "not both"),
    (Assumptions(loading=0.0), "loading factor"),
    (Assumptions(loading=1.5), "loading factor"),
    (Assumptions(xp=0.1, f0=60.0, require_static_qz_nonnegative=True), "static Qz"),
])
def test_out_of_range_assumptions_are_refused(asm, match):
    with pytest.raises(RecordError, match=match):
        invert(D_ANDES, STATIC, asm)


@pytest.mark.parametrize("dyn, static, match", [
    ({**D_ANDES, "Tm": 0.0}, STATIC, "carries no load"),
    ({"a": 10.0, "b": 30.0, "H2": 1.0, "Tm": 0.5}, STATIC, "no motor equilibrium"),
    ({**D_ANDES, "a": -1.0}, STATIC, "positive"),
    (D_ANDES, {"P0": 0.1, "np": 1.0, "Q0": 0.1, "nq": 2.0}, "ZIP static model"),
    ({"a": 1.0}, STATIC, "missing"),
])
def test_infeasible_models_are_refused(dyn, static, match):
    with pytest.raises(RecordError, match=match):
        invert(dyn, static, Assumptions())


def test_admissible_interval_edges():
    d = np.array([D_ANDES[k] for k in NAMES])
    adm = admissible(d, STATIC, Assumptions(loading=0.8))
    assert adm["xp"][1] == pytest.approx(19.159 / 22.796 * 0.25)
    assert adm["td0"][0] == pytest.approx(1 / 19.159)
    lo, hi = adm["xp_static_qz_nonnegative"]
    assert lo == pytest.approx(0.25 / STATIC["Qz"]) and hi == adm["xp"][1]
    assert admissible(d, {**STATIC, "Qz": -1.0}, Assumptions())["xp_static_qz_nonnegative"] is None


def test_delta_method_carries_the_standard_errors():
    se = {"a": 0.3, "b": 0.2, "H2": 0.01, "Tm": 0.002}
    rec = invert(D_ANDES, STATIC, Assumptions(f0=60.0, loading=0.8), stderr=se)
    s = rec.stderr
    assert s["H2_sys"] == pytest.approx(0.01, rel=1e-5)
    assert s["Tm_sys"] == pytest.approx(0.002, rel=1e-5)
    assert s["motor_mva"] == pytest.approx(0.002 / 0.8 * 100, rel=1e-5)
    # Against Monte Carlo through the closed form (small errors: the map is nearly linear there).
    rng = np.random.default_rng(0)
    small = {k: v / 20 for k, v in se.items()}
    draws = [invert({k: D_ANDES[k] + small[k] * rng.standard_normal() for k in NAMES}, STATIC,
                    Assumptions(f0=60.0)).values["Td0"] for _ in range(2000)]
    lin = invert(D_ANDES, STATIC, Assumptions(f0=60.0), stderr=small).stderr["Td0"]
    assert np.std(draws) == pytest.approx(lin, rel=0.1)
    assert math.isnan(invert(D_ANDES, STATIC, Assumptions(f0=60.0)).stderr["Td0"])  # no SE given


def _exported(fmt: str, **asm) -> tuple[dict, Assumptions]:
    a = Assumptions(f0=60.0, v0=0.98, loading=0.7, xp=0.15, **asm)
    return export({"dynamic": D_ANDES, "static": STATIC}, fmt, a, bus_number=9, bus_name="LOAD9", kv=138.0), a


def test_psse_records_parse_back_field_by_field():
    out, asm = _exported("psse")
    rec = invert(D_ANDES, STATIC, asm)
    lines = [ln for ln in out["content"].splitlines() if ln and not ln.startswith("@!")]
    loads = [[f.strip().strip("'") for f in ln.split(",")] for ln in lines[:2]]
    dyr = lines[2].split()
    assert dyr[0] == "9" and dyr[1] == "'CIM5BL'" and dyr[2] == "'M'" and dyr[-1] == "/"
    fields = dict(zip(psse.CIM5BL_ICONS + psse.CIM5BL_CONS, dyr[3:-1], strict=True))
    expected = psse.cim5bl_values(rec)
    for k, text in fields.items():
        assert float(text) == pytest.approx(expected[k], rel=1e-9, abs=1e-12), k
    v = rec.values
    assert float(fields["XA"]) == pytest.approx(v["Xs"]) and float(fields["X1"]) == pytest.approx(v["Xr"])
    assert float(fields["MBASE"]) == pytest.approx(v["motor_mva"]) and float(fields["H"]) == pytest.approx(v["H"])
    # The parsed circuit is the identified D again.
    parsed = {"motor_mva": float(fields["MBASE"]), "sbase_mva": 100.0, "Xs": float(fields["XA"]),
              "Xm": float(fields["XM"]), "Xr": float(fields["X1"]), "Rr": float(fields["R1"]),
              "H": float(fields["H"]), "Tm": v["Tm"]}
    back = transformed(parsed, 60.0)
    for k in ("a", "b", "H2"):
        assert back[k] == pytest.approx(D_ANDES[k], rel=1e-8)
    motor, static = (dict(zip(psse.LOAD_FIELDS, row, strict=True)) for row in loads)
    assert (motor["I"], motor["ID"], static["ID"]) == ("9", "M", "S")
    assert float(motor["PL"]) == pytest.approx(v["P_motor"] * 100) and float(motor["QL"]) == pytest.approx(v["Q_motor"] * 100)
    for f, k, sign in (("PL", "Pp", 1), ("QL", "Qp", 1), ("IP", "Pi", 1), ("IQ", "Qi", 1), ("YP", "Pz", 1), ("YQ", "Qz", -1)):
        assert float(static[f]) == pytest.approx(sign * v[k] * 100, rel=1e-9), f


def test_pslf_record_parses_back_field_by_field():
    out, asm = _exported("pslf")
    rec = invert(D_ANDES, STATIC, asm)
    line = next(ln for ln in out["content"].splitlines() if ln.startswith("motorw"))
    head, _, body = line.partition(":")
    assert head.split()[:2] == ["motorw", "9"] and '"LOAD9"' in head and '"M "' in head
    assert body.split()[0] == "#9"
    mva = float(re.search(r"mva=(\S+)", body).group(1))
    params = {k: float(x) for k, x in re.findall(r'"(\w+)"\s+(\S+)', body)}
    assert list(params) == list(pslf.MOTORW_FIELDS)
    expected = pslf.motorw_values(rec)
    assert mva == pytest.approx(expected["mva"], rel=1e-9)
    for k, x in params.items():
        assert x == pytest.approx(expected[k], rel=1e-9, abs=1e-12), k
    # ls, lp, tpo on Mbase give the identified a, b back.
    sm = mva / 100.0
    x, xp, td0 = params["ls"] / sm, params["lp"] / sm, params["tpo"]
    assert (x / xp - 1) / (td0 * xp) == pytest.approx(D_ANDES["a"], rel=1e-8)
    assert x / (td0 * xp) == pytest.approx(D_ANDES["b"], rel=1e-8)
    assert 2 * params["h"] * sm == pytest.approx(D_ANDES["H2"], rel=1e-8)
    static = dict(re.findall(r"(\w+) (\S+)", out["content"].splitlines()[2].split(":", 1)[1]))
    assert float(static["b"]) == pytest.approx(rec.values["Qz"] * 100, rel=1e-9)


def test_andes_record_converts_back_with_andes_formulas():
    """ANDES's own per-unit conversion (z × Sb/Sn, Hm × Sn/Sb, c1 unconverted; motorbase.py) gives D."""
    out, _ = _exported("andes")
    case = json.loads(out["content"])
    m = case["Motor3"][0]
    r = 100.0 / m["Sn"]
    xs, xr1, xm, rr1 = (m[k] * r for k in ("xs", "xr1", "xm", "rr1"))
    x0, x1 = xs + xm, xs + xr1 * xm / (xr1 + xm)
    t10 = (xr1 + xm) / (2 * math.pi * m["fn"] * rr1)
    assert (x0 / x1 - 1) / (t10 * x1) == pytest.approx(D_ANDES["a"], rel=1e-10)
    assert x0 / (t10 * x1) == pytest.approx(D_ANDES["b"], rel=1e-10)
    assert 2 * m["Hm"] / r == pytest.approx(D_ANDES["H2"], rel=1e-10)
    assert m["c1"] == D_ANDES["Tm"] and m["c2"] == m["c3"] == 0.0
    z = case["ZIP"][0]
    assert z["kpp"] + z["kpi"] + z["kpz"] == pytest.approx(100.0)
    assert z["kqp"] + z["kqi"] + z["kqz"] == pytest.approx(100.0)
    assert z["pq"] == case["PQ"][0]["idx"]


def test_export_payload_states_its_assumptions():
    out, _ = _exported("psse")
    a = out["assumptions"]
    assert a["xp"] == 0.15 and a["loading"] == 0.7 and a["v0"] == 0.98 and a["free"] == "xp"
    assert out["admissible"]["xp"][1] > 0.15 and out["format"] == "psse"
    assert set(out["values"]) == set(out["units"]) == set(out["stderr"])
    assert out["stderr"]["Td0"] is None and out["admissible"]["td0"][1] is None  # strict JSON: no NaN, no inf
    json.dumps(out, allow_nan=False)
    with pytest.raises(RecordError, match="unknown record format"):
        export({"dynamic": D_ANDES, "static": STATIC}, "matpower")


def test_records_import_without_numba():
    """The service's main process (REST, the records sink) builds records without the identifier's kernels."""
    from fresh_interpreter import run_python

    code = "import sys, aslm_core.records, service.records\nprint('numba' in sys.modules)"
    assert run_python(code) == "False"
