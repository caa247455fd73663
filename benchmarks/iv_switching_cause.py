"""Why ``disturbance="ar_iv"`` failed on the synthetic bench's step switching (issue 20): the input smoother.

On the development windows of ``benchmarks.own_fluctuation`` (seed 43, own switching at own/clean P std 0.9,
exact V and θ, P and Q at DL 2), per window:

* the input floors' tilt (``floor_tilt_v``, ``_theta``: above :data:`aslm_core.preprocess.FLOOR_TILT_MAX` an input
  is taken as exact and not smoothed) and the low-pass the default ``wiener_lowpass`` smoother chose;
* the IV criterion at the *true* D (Sargan's white statistic over its degrees of freedom, ~1 when the lag-2/3
  instruments are uncorrelated with the whitened residual), with the windows prepared as the default does, with no
  input smoother, with the Wiener step only, with only the causal low-pass (at the cut-off the default chose),
  and with no smoother and the true own ΔP, ΔQ removed from P and Q (oracle);
* ``ar_iv``'s estimate under the same preparations, and from output error's optimum with the instruments
  starting at lag 4 or 6 under the default preparation.

    .venv/bin/python -m benchmarks.iv_switching_cause [--n 16] [--andes]

``--andes`` adds the floor tilts of the ANDES bench's switching windows (development own seed 1).  Results in
``docs/results/iv_switching_cause.json``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import time  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import IdentifyConfig, Window, disturbance, identify, instrumental  # noqa: E402
from aslm_core.identify import SE_SMOOTH_HZ, Problem  # noqa: E402
from aslm_core.preprocess import prepare  # noqa: E402
from aslm_sim.cases import make_cases  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.own_fluctuation import LEVEL, SEED, own_cases  # noqa: E402

RATIO, SHAPE = 0.9, "switching"
IV = IdentifyConfig(disturbance="ar_iv")


def preparations(lowpass_hz: float) -> dict[str, IdentifyConfig]:
    """The window preparations compared; ``lowpass_hz``: the cut-off the default chose on the window."""
    return {"default (wiener_lowpass)": IV, "no input smoother": replace(IV, input_smoother="none"),
            "Wiener step only": replace(IV, input_smoother="wiener"),
            "low-pass only": replace(IV, input_smoother="none", lowpass_hz=lowpass_hz or None)}


def criterion_at(window: Window, d: np.ndarray, cfg: IdentifyConfig) -> float:
    """Sargan's white IV statistic over its degrees of freedom at D = d, the AR models from the residual at d."""
    prep = prepare(window, max_gap_samples=cfg.max_gap_samples, min_duration_s=cfg.min_duration_s,
                   lowpass_hz=cfg.lowpass_hz, floors=True, input_smoother=cfg.input_smoother)
    pb = Problem(prep, window.f0, cfg)
    r = pb.residuals(d, jacobian=False)
    polys = (disturbance.ar_whitener(r[0]), disturbance.ar_whitener(r[1]))
    wp = instrumental.Instrumented(pb, polys, d)
    es, _ = wp.residuals(d)
    dof = sum(q.shape[1] - wp.n_static for q in wp.bases) - 4
    return 2.0 * wp.cost(es) / dof


def iv_from_output_error(window: Window, first_lag: int) -> dict:
    """``ar_iv``'s fit under the default preparation from output error's optimum, instruments from ``first_lag``."""
    oe = identify(window)
    cfg = IdentifyConfig()
    prep = prepare(window, floors=True, input_smoother=cfg.input_smoother)
    pb = Problem(prep, window.f0, replace(cfg, skip_s=oe.quality["skip_s"]))
    return instrumental.fit(pb, oe.d, first_lag=first_lag, se_smooth_hz=SE_SMOOTH_HZ)


def one(case) -> dict:
    """Every measurement of the module docstring on one case."""
    w, truth = case.window, case.truth.d
    prep = prepare(w, floors=True, input_smoother="wiener_lowpass")
    rec = {"floor_tilt_v": prep.noise["floor_tilt_v"], "floor_tilt_theta": prep.noise["floor_tilt_theta"],
           "lowpass_hz": prep.lowpass_hz, "overid_at_truth": {}, "errors": {}, "stderr": {}, "overid": {}}
    oracle = replace(w, P=w.P - case.states["P_own"], Q=w.Q - case.states["Q_own"])
    preps = preparations(prep.lowpass_hz)
    for name, cfg in preps.items():
        rec["overid_at_truth"][name] = criterion_at(w, truth, cfg)
    rec["overid_at_truth"]["oracle: own ΔP, ΔQ removed, no smoother"] = criterion_at(oracle, truth, preps["no input smoother"])
    for name, cfg in preps.items():
        r = identify(w, config=cfg)
        rec["errors"][name] = (r.d / truth - 1).tolist()
        rec["stderr"][name] = (np.array([r.stderr[k] for k in common.PARAMS]) / truth).tolist()
        rec["overid"][name] = r.quality["iv_overid"]
    for lag in (4, 6):
        name = f"default preparation, instruments from lag {lag}"
        f = iv_from_output_error(w, lag)
        rec["errors"][name] = (f["d"] / truth - 1).tolist()
        rec["stderr"][name] = (np.sqrt(np.maximum(np.diag(f["cov"]), 0.0)) / truth).tolist()
        rec["overid"][name] = f["overid"]
    r = identify(w)
    rec["errors"]["output error (default)"] = (r.d / truth - 1).tolist()
    rec["stderr"]["output error (default)"] = (np.array([r.stderr[k] for k in common.PARAMS]) / truth).tolist()
    return rec


def andes_tilts(n: int) -> dict:
    """Floor tilts of V and θ and the default's low-pass on the ANDES bench's switching windows (own seed 1)."""
    from aslm_sim.andes import own_fluctuation as andes_own
    from benchmarks.own_fluctuation_andes import F0, FS, SHAPES, TF, TSTEP, windows
    from benchmarks.own_fluctuation_andes import SEED as ANDES_SEED

    grid = andes_own.grid_recording(tf=TF, tstep=TSTEP, seed=ANDES_SEED, fs=FS)
    own = andes_own.own_recording(SHAPE, tf=TF, tstep=TSTEP, seed=ANDES_SEED)
    out = {}
    for ri, ratio in ((1, 0.5), (2, 0.9)):
        ws = windows(grid, own, ratio, n, np.random.default_rng([ANDES_SEED, ri, SHAPES.index(SHAPE)]))
        preps = [prepare(Window(x["t"], x["V"], x["theta"], x["P"], x["Q"], f0=F0), floors=True,
                         input_smoother="wiener_lowpass") for x in ws]
        out[f"{ratio:g}"] = {"floor_tilt_v": [p.noise["floor_tilt_v"] for p in preps],
                             "floor_tilt_theta": [p.noise["floor_tilt_theta"] for p in preps],
                             "lowpass_hz": [p.lowpass_hz for p in preps]}
    return out


def summary(recs: list[dict]) -> tuple[list[list], list[list]]:
    """Markdown rows: the criterion at the truth per preparation; ar_iv's accuracy per variant."""
    crit = [[name, f"{np.median(v):.2f}", f"{np.min(v):.2f}–{np.max(v):.2f}"]
            for name in recs[0]["overid_at_truth"] for v in [[r["overid_at_truth"][name] for r in recs]]]
    acc = []
    for name in recs[0]["errors"]:
        e = np.array([r["errors"][name] for r in recs])
        se = np.array([r["stderr"][name] for r in recs])
        ov = [r["overid"].get(name, np.nan) for r in recs]
        acc.append([name, " / ".join(f"{100 * v:.1f}" for v in np.median(np.abs(e), axis=0)),
                    " / ".join(f"{100 * v:+.1f}" for v in e.mean(axis=0)),
                    " / ".join(f"{100 * v:.0f}" for v in np.mean(np.abs(e) <= 1.96 * se, axis=0)),
                    "–" if np.all(np.isnan(ov)) else f"{np.nanmedian(ov):.2f}"])
    return crit, acc


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=None, help="windows (default 16; --quick: 3)")
    ap.add_argument("--andes", action="store_true", help="also the ANDES switching windows' floor tilts")
    args = ap.parse_args(argv)
    n = args.n or (3 if args.quick else 16)
    t0 = time.perf_counter()
    base = make_cases(n, level=LEVEL, seed=SEED, input_noise=False)
    cases = own_cases(n, RATIO, SHAPE, base)
    recs = [one(c) for c in cases]
    crit, acc = summary(recs)
    out = {"machine": common.machine(), "seed": SEED, "ratio": RATIO, "shape": SHAPE, "n": n, "windows": recs}
    print(f"floor tilt V: median {np.median([r['floor_tilt_v'] for r in recs]):.1f} "
          f"(range {min(r['floor_tilt_v'] for r in recs):.1f}–{max(r['floor_tilt_v'] for r in recs):.1f}), "
          f"θ: median {np.median([r['floor_tilt_theta'] for r in recs]):.1f}; default low-pass median "
          f"{np.median([r['lowpass_hz'] for r in recs]):.1f} Hz")
    print(common.md_table(["preparation", "IV criterion / dof at the true D, median", "range"], crit))
    print(common.md_table(["ar_iv variant", "median |err| a / b / H2 / Tm [%]", "bias μ−1 [%]",
                           "±1.96 SE cover [%]", "iv_overid median"], acc))
    if args.andes:
        out["andes_switching"] = andes_tilts(8)
        for ratio, v in out["andes_switching"].items():
            print(f"ANDES switching {ratio}: floor tilt V {np.min(v['floor_tilt_v']):.1f}–{np.max(v['floor_tilt_v']):.1f}, "
                  f"θ {np.min(v['floor_tilt_theta']):.1f}–{np.max(v['floor_tilt_theta']):.1f}, low-pass "
                  f"{sorted(set(v['lowpass_hz']))} Hz")
    out["total_s"] = time.perf_counter() - t0
    if not args.no_write:
        common.write_json("iv_switching_cause" + ("_quick" if args.quick else ""), out)
    return out


if __name__ == "__main__":
    main()
