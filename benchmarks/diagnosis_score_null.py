"""The held-out score statistic's null distribution on clean data (issue 12, seventh round).

    .venv/bin/python -m benchmarks.diagnosis_score_null --input-noise --clean 60   # the self-test's clean cases
    .venv/bin/python -m benchmarks.diagnosis_score_null --records docs/results/diagnosis_independent_confirm6.json

Synthetic: each clean case of the self-test (``benchmarks.diagnosis.case``, effect ``none``, levels 1-3, cases
0..N-1) is analysed as the diagnosis does (``pipeline._analyse``) and every candidate's score z is kept, with its
penalised held-out gain two ways — the library's (per channel, P and Q taken as independent) and the gain of
commit 8469a3f (P and Q decorrelated per coefficient first, :func:`decorrelated_gain`) — and the score z again
with the plain model's prediction covariance taken as the sandwich A⁻¹·JᵀΣJ·A⁻¹ (Σ: the training noise's P/Q
correlation, which the diagonally weighted fit's (JᵀJ)⁻¹ ignores).  ``--records``: the clean cases' candidate z
of a recorded ANDES run (``benchmarks.diagnosis_independent``), per noise mode.  Under the null every z is
N(0, 1); the summary gives mean, sd, percentiles and the counts above 2, 2.5 and the Holm critical value.
Raw summary to ``docs/results/diagnosis_score_null<_tag>.json`` (no per-sample series).
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

RESULTS = ROOT / "docs" / "results"
LEVELS = (1, 2, 3)


def decorrelated_gain(m: int, R0p, R0q, Dp, Dq, vp, vq, cpq, probes_dct=None) -> float:
    """The held-out gain of commit 8469a3f [nats]: per coefficient P, then Q given P, whitened by the noise
    model's 2×2 covariance, then the per-channel profile likelihood (m/2)·ln(S0/S1); S1 raised by twice the
    errors-in-variables bias in the same coordinates (``probes_dct`` = (G0p, G0q, dGp, dGq))."""
    a = cpq / vp
    sc = np.sqrt(vp)
    sq_c = np.sqrt(np.maximum(vq - cpq * a, 1e-9 * vq))

    def white(xp, xq):
        if xp.ndim == 2:
            return xp / sc[:, None], (xq - a[:, None] * xp) / sq_c[:, None]
        return xp / sc, (xq - a * xp) / sq_c

    u0p, u0q = white(R0p, R0q)
    u1p, u1q = white(R0p - Dp, R0q - Dq)
    bp = bq = 0.0
    if probes_dct is not None:
        g0p, g0q = white(*probes_dct[:2])
        dgp, dgq = white(*probes_dct[2:])
        bp = float(np.mean(-np.sum(g0p * dgp, axis=0)))
        bq = float(np.mean(-np.sum(g0q * dgq, axis=0)))
    s0p, s0q = float(u0p @ u0p), float(u0q @ u0q)
    s1p, s1q = float(u1p @ u1p) + 2.0 * bp, float(u1q @ u1q) + 2.0 * bq
    return 0.5 * m * (math.log(s0p / max(s1p, 1e-300)) + math.log(s0q / max(s1q, 1e-300)))


def sandwich_cov(cand, seg, ctx, fit, noise):
    """``engine.prediction_cov`` with the parameters' covariance as the sandwich A⁻¹·JᵀΣJ·A⁻¹ (A = JᵀJ of the
    diagonally whitened training Jacobian, Σ the P/Q correlation c_PQ/√(v_P·v_Q) per coefficient)."""
    from aslm_core.diagnosis import engine
    from aslm_core.diagnosis.noise import dct_band

    out = engine.prediction_cov(cand, seg, ctx, fit, noise)
    if out is None:
        return None
    jp_te, jq_te, cov = out
    pr = cand.predict(seg, ctx, fit.d, fit.z)
    x_nl = np.concatenate([fit.d, fit.z]) if ctx.free else np.asarray(fit.z, float)
    base_p, base_q = pr.mp + pr.xp @ fit.beta_p, pr.mq + pr.xq @ fit.beta_q
    cols_p, cols_q = [], []
    for j in range(x_nl.size):  # the same forward differences as prediction_cov
        h = 1e-6 * max(abs(x_nl[j]), 1e-3)
        x = x_nl.copy()
        x[j] += h
        d, z = (x[:4], x[4:]) if ctx.free else (fit.d, x)
        pj = cand.predict(seg, ctx, d, z)
        cols_p.append((pj.mp + pj.xp @ fit.beta_p - base_p) / h)
        cols_q.append((pj.mq + pj.xq @ fit.beta_q - base_q) / h)
    n, kp, kq, k = seg.n, pr.xp.shape[1], pr.xq.shape[1], x_nl.size
    jp, jq = np.zeros((n, k + kp + kq)), np.zeros((n, k + kp + kq))
    if k:
        jp[:, :k], jq[:, :k] = np.column_stack(cols_p), np.column_stack(cols_q)
    jp[:, k:k + kp], jq[:, k + kp:] = pr.xp, pr.xq
    tr = seg.train
    vp, vq, cpq = noise.coefficients(tr)
    ap = dct_band(jp[tr], noise.fs, noise.band_hz) / np.sqrt(vp)[:, None]
    aq = dct_band(jq[tr], noise.fs, noise.band_hz) / np.sqrt(vq)[:, None]
    rho = (cpq / np.sqrt(vp * vq))[:, None]
    meat = ap.T @ ap + aq.T @ aq + ap.T @ (rho * aq) + aq.T @ (rho * ap)
    cs = cov @ meat @ cov
    return jp_te, jq_te, 0.5 * (cs + cs.T)


def _score_parts(seg, plain, cand, noise, probes, pcov):
    """The score z of ``engine.compare`` and the held-out band coefficients it is built from."""
    from aslm_core.diagnosis import engine
    from aslm_core.diagnosis.noise import dct_band

    te = seg.test
    r0p, r0q = (seg.P - plain.model_p)[te], (seg.Q - plain.model_q)[te]
    r1p, r1q = (seg.P - cand.model_p)[te], (seg.Q - cand.model_q)[te]
    vp, vq, cpq = noise.coefficients(te)
    R0p, R0q, Dp, Dq = dct_band(np.column_stack([r0p, r0q, r0p - r1p, r0q - r1q]), noise.fs, noise.band_hz).T
    cinv = engine._gls_metric(vp, vq, cpq, pcov)
    wDp, wDq = cinv(Dp, Dq)
    num, den2 = float(np.sum(wDp * R0p + wDq * R0q)), float(np.sum(wDp * Dp + wDq * Dq))
    dct = None
    if probes is not None:
        (g0p, g0q), (g1p, g1q) = probes
        dct = tuple(dct_band(x[:, te].T, noise.fs, noise.band_hz) for x in (g0p, g0q, g1p - g0p, g1q - g0q))
        G0p, G0q, dGp, dGq = dct
        wp, wq = cinv(dGp, dGq)
        a = -np.sum(wp * G0p + wq * G0q, axis=0)
        den2 += float(np.var(a, ddof=1)) * (1.0 + 1.0 / a.size)
        den2 += float(np.mean(np.sum(wp**2 * noise.sigma_p**2 + wq**2 * noise.sigma_q**2, axis=0)))
        num -= float(a.mean())
    w0p, w0q = cinv(R0p, R0q)
    q0 = float(np.sum(w0p * R0p + w0q * R0q)) / (2 * R0p.size)
    return num / math.sqrt(max(den2, 1e-300)), q0, (R0p, R0q, Dp, Dq, vp, vq, cpq), dct


def synthetic_case(level: int, i: int, input_noise: bool) -> dict:
    """Every candidate's statistics on one clean self-test case."""
    from aslm_core.diagnosis import engine
    from benchmarks.diagnosis import case

    dg = importlib.import_module("aslm_core.diagnosis.pipeline")
    _, ec, _, _ = case(("none", level, i, input_noise))
    a = dg._analyse(ec.window, None, None, dg.DiagnosisConfig())
    pcov = engine.prediction_cov(dg._PLAIN, a.seg, a.ctx, a.plain, a.weights)
    psand = sandwich_cov(dg._PLAIN, a.seg, a.ctx, a.plain, a.weights)
    g0 = (a.noise.probes_p, a.noise.probes_q) if a.noise.has_inputs else None
    out = {"level": level, "case": i, "candidates": {}}
    for name, comp in a.comps.items():
        g1 = a.probes.get(name)
        probes = (g0, g1) if g1 is not None else None
        z, q0, coeffs, dct = _score_parts(a.seg, a.plain, a.fits[name], a.noise, probes, pcov)
        zs, q0s, _, _ = _score_parts(a.seg, a.plain, a.fits[name], a.noise, probes, psand)
        m = coeffs[0].size
        k = dg.LIBRARY[name].n_params
        gd = decorrelated_gain(m, *coeffs, probes_dct=dct)
        out["candidates"][name] = {"z": comp.score_z, "z_check": z, "z_sandwich": zs, "q0": q0, "q0_sandwich": q0s,
                                   "pg": comp.penalised_gain, "pg_decorrelated": gd - 0.5 * k * math.log(m)}
    return out


def summary(z) -> dict:
    """Mean, sd, percentiles and exceedances of a sample of z (N(0, 1) under the null)."""
    z = np.asarray([x for x in z if x is not None and math.isfinite(x)], dtype=float)
    crit = float(stats.norm.isf(0.01 / 9))  # Holm's first critical value, alpha 0.01 over 9 tested candidates
    return {"n": int(z.size), "mean": float(z.mean()), "sd": float(z.std()), "p95": float(np.percentile(z, 95)),
            "p99": float(np.percentile(z, 99)), "max": float(z.max()),
            "above_2": int(np.sum(z > 2)), "above_2_5": int(np.sum(z > 2.5)), "above_crit": int(np.sum(z > crit)),
            "expected_above_2": float(z.size * stats.norm.sf(2)), "expected_above_2_5": float(z.size * stats.norm.sf(2.5)),
            "expected_above_crit": float(z.size * stats.norm.sf(crit)), "crit": crit}


def summarise_synthetic(recs: list[dict]) -> dict:
    cands = [c for r in recs for c in r["candidates"].values()]
    crit = float(stats.norm.isf(0.01 / 9))
    s = {"cases": len(recs), "z": summary([c["z"] for c in cands]),
         "z_sandwich": summary([c["z_sandwich"] for c in cands]),
         "q0_mean": float(np.mean([next(iter(r["candidates"].values()))["q0"] for r in recs])),
         "q0_sandwich_mean": float(np.mean([next(iter(r["candidates"].values()))["q0_sandwich"] for r in recs])),
         "per_level": {lvl: summary([c["z"] for r in recs if r["level"] == lvl for c in r["candidates"].values()])
                       for lvl in LEVELS if any(r["level"] == lvl for r in recs)},
         "per_candidate": {n: summary([r["candidates"][n]["z"] for r in recs if n in r["candidates"]])
                           for n in sorted({n for r in recs for n in r["candidates"]})}}
    for g in ("pg", "pg_decorrelated"):
        s[f"cases_z_above_crit_and_{g}_positive"] = sum(
            any(c["z"] > crit and c[g] > 0 for c in r["candidates"].values()) for r in recs)
        s[f"share_{g}_positive"] = float(np.mean([c[g] > 0 for c in cands]))
    s["cases_z_above_crit"] = sum(any(c["z"] > crit for c in r["candidates"].values()) for r in recs)
    s["tail"] = sorted(([r["level"], r["case"], n, round(c["z"], 3), round(c["pg"], 3), round(c["pg_decorrelated"], 3)]
                        for r in recs for n, c in r["candidates"].items() if c["z"] > 2.5), key=lambda x: -x[3])
    return s


def summarise_records(paths: list[str]) -> dict:
    out = {}
    for p in paths:
        recs = json.loads(Path(p).read_text())["records"]
        for mode, lab in ((False, "pq"), (True, "vtheta")):
            z = [c["z"] for r in recs if r.get("kind") == "clean" and r.get("input_noise") == mode
                 for c in r["candidates"] if c["tested"]]
            if z:
                out[f"{Path(p).stem}/{lab}"] = summary(z)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--input-noise", action="store_true", help="the self-test's cases with noise on V, θ and f too")
    p.add_argument("--clean", type=int, default=60, help="clean cases per level")
    p.add_argument("--records", nargs="*", default=[], help="recorded ANDES runs to summarise instead")
    p.add_argument("--tag", default="")
    p.add_argument("--no-write", action="store_true")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    if args.records:
        s = {"records": summarise_records(args.records)}
    else:
        recs = []
        for lvl in LEVELS:
            for i in range(args.clean):
                recs.append(synthetic_case(lvl, i, args.input_noise))
                print(lvl, i, f"max z {max(c['z'] for c in recs[-1]['candidates'].values()):.2f}", flush=True)
        s = summarise_synthetic(recs)
    s["wall_s"] = time.perf_counter() - t0
    s["command"] = "benchmarks/diagnosis_score_null.py " + " ".join(argv if argv is not None else sys.argv[1:])
    print(json.dumps({k: v for k, v in s.items() if k != "tail"}, indent=1, default=float))
    if not args.no_write:
        name = "diagnosis_score_null" + ("_records" if args.records else "_vtheta" if args.input_noise else "_pq")
        (RESULTS / f"{name}{'_' + args.tag if args.tag else ''}.json").write_text(json.dumps(s, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
