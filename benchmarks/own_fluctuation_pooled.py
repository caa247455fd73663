"""Pooled windows under the load's own fluctuation (issue 20's k = 16 target) on the ANDES bench.

The windows of ``benchmarks.own_fluctuation_andes`` (IEEE 14-bus, Motor3 + ZIP at bus 9, P and Q at 22 dB), at
own/total 0.9 per shape (``--ratio``), but not overlapping: 16 windows of 10 s, one every 10 s from 5 s, per own seed
(the own process and the P/Q noise; the grid-side run is the same for every seed, so the pools share its
excitation).  Per pool: ``identify_pooled`` with white noise (``disturbance="none"``), with ``disturbance="ar_iv"``
and with the default ``disturbance="gated"`` (which of the two it returned, and the pool's own ratio it read), and
the single-window ``ar_iv`` fits of the same windows.  Median and worst |error| over the pools, bias, coverage of
±1.96 SE, ``iv_instruments_rejected`` count, and for the gated pool how many took the IV.

    .venv/bin/python -m benchmarks.own_fluctuation_pooled [--seeds 1 2 3 4 5 6] [--shapes ...] [--k 16]
        [--ratio 0.9] [--coherence 1] [--horizon S] [--iv-estimator 2sls|liml] [--iv-whitening residual|own]

Seeds 1–6 are the development pools; :data:`CONFIRM_SEEDS` were fixed before any run on them.  Results in
``docs/results/own_fluctuation_pooled[_confirm].json``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import time  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import IdentifyConfig, Window, WindowError, identify  # noqa: E402
from aslm_core.pooled import identify_pooled  # noqa: E402
from aslm_sim.andes import own_fluctuation as andes_own  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.own_fluctuation_andes import F0, FS, LENGTH_S, SEED, SHAPES, SNR_DB, START_S, TF, TSTEP  # noqa: E402

RATIO = 0.9
DEV_SEEDS = (1, 2, 3, 4, 5, 6)
#: Own seeds of the confirmation pools, fixed before any run on them; 21–30: the IV by LIML with the own fluctuation's
#: AR models (stop 37), ``--seeds 21 … 30 --coherence 0.7 --horizon 0 --iv-estimator liml --iv-whitening own`` against
#: the same with the defaults.
CONFIRM_SEEDS = tuple(range(11, 21))
CONFIRM_SEEDS_37 = tuple(range(21, 31))
#: 31–40: the gated pool (stop 38, the service's tracked model), fixed before any run on them, ``--seeds 31 … 40
#: --horizon 0 --tag gated`` at ``--ratio`` 0.9, 0.5 and 0 (and ``--coherence 0.7`` at 0.9).
CONFIRM_SEEDS_38 = tuple(range(31, 41))
#: 41–50: the pooled IV's options (stop 38: LIML with the own fluctuation's AR models as identify_pooled's default
#: against 2SLS with the residual's), fixed before any run on them, ``--seeds 41 … 50 --horizon 0`` with
#: ``--iv-estimator liml --iv-whitening own --tag iv_liml_own`` and ``--iv-estimator 2sls --iv-whitening residual
#: --tag iv_2sls``, at ``--coherence`` 1 and 0.7 (own/total 0.9; tags with ``_coh0.7``) and ``--ratio 0.5``.
CONFIRM_SEEDS_38_IV = tuple(range(41, 51))
#: The single-window IV (since stop 34 coupled, as the pooled one: ``couple_channels`` is the default).
IV = IdentifyConfig(disturbance="ar_iv")
#: The pooled fits per row name: ``identify_pooled``'s ``disturbance`` (``gated``: its default since stop 38).
POOLED = {"pooled, white": "none", "pooled ar_iv": "ar_iv", "pooled, gated": "gated"}


def pool_windows(grid: dict, own: dict, k: int, seed: int, shape: str, horizon_s: float | None = None,
                 ratio: float = RATIO) -> list[Window]:
    """k non-overlapping windows at own/total ``ratio`` (``horizon_s``: :func:`aslm_sim.andes.own_fluctuation.cut_windows`)."""
    ws = andes_own.cut_windows(grid, own, ratio, length_s=LENGTH_S, start_s=START_S, stride_s=LENGTH_S, n=k,
                               snr_db=SNR_DB, rng=np.random.default_rng([seed, 2, SHAPES.index(shape), 16]),
                               horizon_s=horizon_s)
    return [Window(w["t"], w["V"], w["theta"], w["P"], w["Q"], f0=F0, bus="andes-ieee14-bus9") for w in ws]


def one_pool(windows: list[Window], truth: np.ndarray, iv_estimator: str = "2sls", iv_whitening: str = "residual") -> dict:
    """Pooled white, pooled ``ar_iv``, pooled gated and the single-window ``ar_iv`` fits: relative errors and SEs,
    flags, time, and the gated pool's answer and own ratio (``iv_estimator``, ``iv_whitening``: the IV's criterion
    and AR models in all, as ``IdentifyConfig``'s)."""
    out = {}
    iv = replace(IV, iv_estimator=iv_estimator, iv_whitening=iv_whitening)
    t0 = time.perf_counter()
    single = []
    for w in windows:
        try:
            single.append(identify(w, config=iv))
        except WindowError:
            continue
    out["single ar_iv"] = {"errors": [(r.d / truth - 1).tolist() for r in single],
                           "stderr": [[r.stderr[p] / t for p, t in zip(common.PARAMS, truth, strict=True)] for r in single],
                           "seconds": time.perf_counter() - t0}
    for name, dist in POOLED.items():
        t0 = time.perf_counter()
        r = identify_pooled(windows, disturbance=dist, iv_estimator=iv_estimator, iv_whitening=iv_whitening)
        out[name] = {"errors": (r.d / truth - 1).tolist(),
                     "stderr": [r.stderr[p] / t for p, t in zip(common.PARAMS, truth, strict=True)],
                     "flags": r.flags, "seconds": time.perf_counter() - t0,
                     "disturbance": r.disturbance, "own_ratio_p": r.own_ratio_p}
    return out


def summary(pools: list[dict], name: str) -> list:
    """Median and worst |error|, bias, coverage over the pools (or over every window for ``single ar_iv``)."""
    if name == "single ar_iv":
        e = np.array([x for p in pools for x in p[name]["errors"]])
        s = np.array([x for p in pools for x in p[name]["stderr"]])
        flagged = "–"
    else:
        e = np.array([p[name]["errors"] for p in pools])
        s = np.array([p[name]["stderr"] for p in pools])
        flagged = str(sum("iv_instruments_rejected" in p[name]["flags"] for p in pools))
        if name == "pooled, gated":
            flagged += f"; IV {sum(p[name]['disturbance'] == 'ar_iv' for p in pools)} of {len(pools)}"
    return [" / ".join(f"{100 * v:.1f}" for v in np.median(np.abs(e), axis=0)), f"{100 * np.abs(e).max():.0f}",
            " / ".join(f"{100 * v:+.1f}" for v in e.mean(axis=0)),
            " / ".join(f"{100 * v:.0f}" for v in np.mean(np.abs(e) <= 1.96 * s, axis=0)), flagged, str(len(e))]


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--seeds", nargs="+", type=int, default=list(DEV_SEEDS))
    ap.add_argument("--shapes", nargs="+", default=list(SHAPES), choices=SHAPES)
    ap.add_argument("--k", type=int, default=16, help="windows per pool")
    ap.add_argument("--ratio", type=float, default=RATIO, help="own/total of the windows (0: grid-excited only)")
    ap.add_argument("--tag", default="", help="name suffix of the JSON")
    ap.add_argument("--coherence", type=float, default=1.0,
                    help="correlation of the own ΔQ with the own ΔP (1: ΔQ = 0.33·ΔP, the bench as it was)")
    ap.add_argument("--horizon", type=float, default=None,
                    help="superpose only the own run's last HORIZON s before each window and the window itself "
                         "(default: the whole own run from t = 0, the bench as it was)")
    ap.add_argument("--iv-estimator", choices=["2sls", "liml"], default="2sls",
                    help="the IV criterion of the single-window and pooled ar_iv fits (default 2sls, the bench as it was; "
                         "identify_pooled's own default since stop 38: liml)")
    ap.add_argument("--iv-whitening", choices=["residual", "own"], default="residual",
                    help="the AR models of the ar_iv fits (default residual, the bench as it was; identify_pooled's own "
                         "default since stop 38: own)")
    args = ap.parse_args(argv)
    t_all = time.perf_counter()
    grid = andes_own.grid_recording(tf=TF, tstep=TSTEP, seed=SEED, fs=FS)
    truth = np.asarray(grid["truth"], dtype=float)
    out = {"machine": common.machine(), "ratio": args.ratio, "k": args.k, "seeds": args.seeds, "truth": truth.tolist(),
           "coherence": args.coherence, "horizon_s": args.horizon, "iv_estimator": args.iv_estimator,
           "iv_whitening": args.iv_whitening, "runs": []}
    table = []
    for shape in args.shapes:
        pools = []
        for seed in args.seeds:
            own = andes_own.own_recording(shape, tf=TF, tstep=TSTEP, seed=seed, coherence=args.coherence)
            pools.append(one_pool(pool_windows(grid, own, args.k, seed, shape, args.horizon, args.ratio), truth,
                                  args.iv_estimator, args.iv_whitening))
            print(f"{shape} seed {seed}: done ({time.perf_counter() - t_all:.0f} s)", flush=True)
        out["runs"].append({"shape": shape, "pools": pools})
        table.extend([[shape, name, *summary(pools, name)] for name in ("single ar_iv", *POOLED)])
    out["total_s"] = time.perf_counter() - t_all
    print(common.md_table([f"shape ({args.ratio:g})", "estimator", "median |err| a / b / H2 / Tm [%]", "worst [%]",
                           "bias μ−1 [%]", "±1.96 SE cover [%]", "iv_instruments_rejected", "fits"], table))
    if not args.no_write:
        confirm = set(args.seeds) <= {*CONFIRM_SEEDS, *CONFIRM_SEEDS_37, *CONFIRM_SEEDS_38, *CONFIRM_SEEDS_38_IV}
        common.write_json("own_fluctuation_pooled" + (f"_{args.tag}" if args.tag else "")
                          + ("" if args.ratio == RATIO else f"_ratio{args.ratio:g}") + ("_confirm" if confirm else "")
                          + ("_quick" if args.quick else ""), out)
    return out


if __name__ == "__main__":
    main()
