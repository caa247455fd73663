"""Is the loop through the network what biases the prediction-error fit under own fluctuation?

Issue 20's own-fluctuation bench (:mod:`benchmarks.own_fluctuation`) simulates the load's own constant-power
fluctuation through the network, so it moves V and θ too (a closed loop).  Here the same windows are identified
twice: as simulated (the loop closed), and with the loop cut: the case's own ΔP and ΔQ (``states["P_own"]``,
``["Q_own"]``) added to the P and Q of the same case simulated without it (the same load, network, grid-side
forcing and noise), so V and θ carry none of it.  Candidates: the gate's two branches with the coupled channels,
``ar`` (prediction error) and ``ar_iv`` (instrumental variables).

Second, at the true D of each window: the correlation of the whitened, projected P residual with each whitened,
projected sensitivity (the prediction-error fit's normal equations at the truth, each term scaled), with the one-step
innovations of V and θ (each from its own AR model, order by BIC) at the lags given added to the projected nuisance
columns.  A consistent fit needs these near 0 (±1/√(windows·samples)); if the loop acted only through the inputs'
innovations at t and t + 1 (the model reads V(t + 1) through its cubic midpoint), projecting those would take the
correlation to 0.

    .venv/bin/python -m benchmarks.own_loop [--seed 243] [--n 30] [--shape switching] [--ratio 0.9] [--coherence 0.7]

With ``--andes`` the same comparison on the independent bench (:mod:`benchmarks.own_fluctuation_andes`: its
windows of own seed ``--own-seed``, and with the loop cut the own ΔP and ΔQ added to the grid-side run's P and Q
alone, :func:`aslm_sim.andes.own_fluctuation.cut_windows` with ``loop=False``); no score check there.

Results: ``docs/results/own_loop_<shape>_seed<seed>_coh<coherence>.json``, with ``--andes``
``own_loop_andes_<shape>_own<own seed>_coh<coherence>.json``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402
from scipy import signal  # noqa: E402

from aslm_core import IdentifyConfig, WindowError, disturbance, identify  # noqa: E402
from aslm_core.preprocess import prepare  # noqa: E402
from aslm_core.problem import Problem  # noqa: E402
from aslm_sim.cases import make_cases  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.own_fluctuation import LEVEL, own_cases  # noqa: E402

CANDIDATES = {"PEM": IdentifyConfig(disturbance="ar", input_weighting="none"),
              "IV": IdentifyConfig(disturbance="ar_iv", input_weighting="none")}
#: Lags of the inputs' innovations projected out in the score check [samples] (0: the same sample).
INNOVATION_LAGS = {"none": (), "t": (0,), "t, t+1": (0, 1), "t … t+3": (0, 1, 2, 3), "t−1 … t+3": (-1, 0, 1, 2, 3)}


def open_loop_window(base_case, own_case):
    """The window of ``base_case`` (no own fluctuation) with ``own_case``'s own ΔP and ΔQ added to P and Q."""
    w = base_case.window
    return replace(w, P=w.P + own_case.states["P_own"], Q=w.Q + own_case.states["Q_own"])


def innovations(x: np.ndarray) -> np.ndarray:
    """One-step prediction errors of x from its own past (AR model, order by BIC) [units of x]."""
    x = x - x.mean()
    return signal.lfilter(disturbance.ar_whitener(x), [1.0], x)


def score_correlations(case, lags: dict[str, tuple[int, ...]]) -> dict[str, list[float]]:
    """Per set of lags, corr(whitened sensitivity_j, whitened residual) of P at the true D, j = a, b, H2, Tm."""
    prep = prepare(case.window, floors=True)
    pb = Problem(prep, case.window.f0, CANDIDATES["PEM"])
    d = np.asarray(case.truth.d, dtype=np.float64)
    r = pb.residuals(d, jacobian=False)
    polys = (disturbance.ar_whitener(r[0]), disturbance.ar_whitener(r[1]))
    skip = max(len(a) for a in polys) - 1
    zf = disturbance.whitened_columns(pb, polys, d, skip)[0]
    n_rows = zf.shape[0]
    rows = np.arange(pb.k0 + skip, pb.k0 + skip + n_rows)
    theta = np.unwrap(prep.theta)
    k = np.arange(theta.size)
    eps = (innovations(prep.V), innovations(theta - np.polyval(np.polyfit(k, theta, 1), k)))
    out = {}
    for name, ks in lags.items():
        cols = [zf[:, 5:]]
        for lag in ks:
            for x in eps:
                j = rows + lag
                c = np.zeros(n_rows)
                ok = (j >= 0) & (j < x.size)
                c[ok] = x[j[ok]]
                cols.append(c[:, None])
        q, _ = np.linalg.qr(np.hstack(cols))
        proj = zf[:, :5] - q @ (q.T @ zf[:, :5])
        out[name] = [float(np.corrcoef(proj[:, 1 + j], proj[:, 0])[0, 1]) for j in range(4)]
    return out


def _fit_rows(pairs, truth_of, out: dict) -> list[list]:
    """Each candidate on the (closed, cut) window pairs; per loop and candidate the errors into ``out["fits"]``."""
    rows = []
    for li, loop in enumerate(("closed", "cut")):
        for name, cfg in CANDIDATES.items():
            errs = []
            for i, pair in enumerate(pairs):
                try:
                    errs.append(identify(pair[li], config=cfg).d / truth_of(i) - 1.0)
                except WindowError:
                    errs.append(np.full(4, np.nan))
            e = 100.0 * np.array(errs)
            med, bias = np.nanmedian(np.abs(e), axis=0), np.nanmean(e, axis=0)
            off = int(np.sum(np.nanmax(np.abs(e), axis=1) > 20.0))
            out["fits"][f"{name}, loop {loop}"] = {"errors_pct": e.tolist(), "median_abs_pct": med.tolist(),
                                                    "bias_pct": bias.tolist(), "off_20": off}
            rows.append([loop, name, " / ".join(f"{x:.1f}" for x in med), " / ".join(f"{x:+.1f}" for x in bias), off])
            print(f"loop {loop}, {name}: done", flush=True)
    return rows


def andes(args) -> dict:
    """The closed and cut loop on the ANDES own bench's windows."""
    from aslm_sim.andes import own_fluctuation as andes_own
    from benchmarks import own_fluctuation_andes as bench

    grid = andes_own.grid_recording(tf=bench.TF, tstep=bench.TSTEP, seed=bench.SEED, fs=bench.FS)
    truth = np.asarray(grid["truth"], dtype=np.float64)
    own = andes_own.own_recording(args.shape, tf=bench.TF, tstep=bench.TSTEP, seed=args.own_seed,
                                  coherence=args.coherence)
    cut = {loop: bench.row_windows(grid, own, args.ratio, args.shape, args.n, args.own_seed, loop)
           for loop in (True, False)}
    pairs = [(bench.as_window(a), bench.as_window(b)) for a, b in zip(cut[True], cut[False], strict=True)]
    out = {"machine": common.machine(), "bench": "andes", "own_seed": args.own_seed, "n": args.n, "shape": args.shape,
           "ratio": args.ratio, "coherence": args.coherence, "truth": truth.tolist(),
           "candidates": {k: v.to_dict() for k, v in CANDIDATES.items()}, "fits": {}}
    rows = _fit_rows(pairs, lambda i: truth, out)
    print(common.md_table(["loop", "fit", "median |err| a / b / H2 / Tm [%]", "bias [%]", "off > 20 %"], rows))
    if not args.no_write:
        common.write_json(f"own_loop_andes_{args.shape}_own{args.own_seed}_coh{args.coherence:g}", out)
    return out


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=243, help="seed of the bench's cases (243: development)")
    ap.add_argument("--n", type=int, default=30)
    ap.add_argument("--shape", default="switching")
    ap.add_argument("--ratio", type=float, default=0.9)
    ap.add_argument("--coherence", type=float, default=0.7)
    ap.add_argument("--andes", action="store_true", help="the ANDES own bench's windows instead (its rows have 50: --n 50)")
    ap.add_argument("--own-seed", type=int, default=1, help="with --andes: the own process's seed (1: development)")
    args = ap.parse_args(argv)
    if args.andes:
        return andes(args)
    base = make_cases(args.n, level=LEVEL, seed=args.seed, input_noise=False)
    cs = own_cases(args.n, args.ratio, args.shape, base, args.seed, args.coherence)
    out = {"machine": common.machine(), "seed": args.seed, "n": args.n, "shape": args.shape, "ratio": args.ratio,
           "coherence": args.coherence, "candidates": {k: v.to_dict() for k, v in CANDIDATES.items()}, "fits": {}}
    pairs = [(c.window, open_loop_window(b, c)) for b, c in zip(base, cs, strict=True)]
    rows = _fit_rows(pairs, lambda i: cs[i].truth.d, out)
    print(common.md_table(["loop", "fit", "median |err| a / b / H2 / Tm [%]", "bias [%]", "off > 20 %"], rows))
    per = [score_correlations(c, INNOVATION_LAGS) for c in cs]
    out["score_correlation"] = {k: np.mean([p[k] for p in per], axis=0).tolist() for k in INNOVATION_LAGS}
    out["score_correlation_scale"] = 1.0 / np.sqrt(len(cs) * 900)
    print(common.md_table(["inputs' innovations projected at", "mean corr(sensitivity, residual) a / b / H2 / Tm"],
                          [[k, " / ".join(f"{x:+.3f}" for x in v)] for k, v in out["score_correlation"].items()]))
    if not args.no_write:
        common.write_json(f"own_loop_{args.shape}_seed{args.seed}_coh{args.coherence:g}", out)
    return out


if __name__ == "__main__":
    main()
