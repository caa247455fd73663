"""Which windows of the pooled bench the floor test's slope rule changed (issue 20, the stop-28 switching moves).

Between the pooled bench's run of stop 26 (2026-11-24 18:44 UTC) and its rerun at stop 28, D moved on a few
switching windows only.  Bisected to 716b89f (the floor test on step-driven exact inputs): a window moves where its
V or θ was taken for white PMU noise by the floor band's tilt alone (``floor_tilt_*`` ≤ ``FLOOR_TILT_MAX``) and is
taken as exact by today's rule (:func:`aslm_core.preprocess.white_floor`).  Per shape and seed, every window of
``benchmarks.own_fluctuation_pooled``'s pools: the floor statistics and both verdicts; where the verdicts differ,
the single-window ``ar_iv`` fit and the pool's ``ar_iv`` fit with today's rule and with the tilt-alone rule patched
in (no identification elsewhere).

    .venv/bin/python -m benchmarks.pooled_floor_check [--seeds 11 ... 20] [--shapes ...] [--no-write]

Results in ``docs/results/pooled_floor_check[_dev].json`` (``_dev`` unless every seed is a confirmation seed).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import contextlib  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import identify, input_weighting, noise, preprocess  # noqa: E402
from aslm_core.pooled import identify_pooled  # noqa: E402
from aslm_sim.andes import own_fluctuation as andes_own  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.own_fluctuation_andes import FS, SEED, SHAPES, TF, TSTEP  # noqa: E402
from benchmarks.own_fluctuation_pooled import CONFIRM_SEEDS, IV, pool_windows  # noqa: E402

CHANNELS = ("v", "theta")


def tilt_alone(floors: dict[str, float], channel: str) -> bool:
    """The floor test before 716b89f: an input's band is white noise where its tilt is at most FLOOR_TILT_MAX."""
    return floors[f"floor_tilt_{channel}"] <= preprocess.FLOOR_TILT_MAX


@contextlib.contextmanager
def floor_rule(rule):
    """``rule`` in place of :func:`aslm_core.preprocess.white_floor` (the smoother's and the weighting's test)."""
    saved = preprocess.white_floor, input_weighting.white_floor
    preprocess.white_floor = input_weighting.white_floor = rule
    try:
        yield
    finally:
        preprocess.white_floor, input_weighting.white_floor = saved


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--seeds", nargs="+", type=int, default=list(CONFIRM_SEEDS))
    ap.add_argument("--shapes", nargs="+", default=list(SHAPES), choices=SHAPES)
    ap.add_argument("--k", type=int, default=16, help="windows per pool (the pooled bench's)")
    args = ap.parse_args(argv)
    t_all = time.perf_counter()
    grid = andes_own.grid_recording(tf=TF, tstep=TSTEP, seed=SEED, fs=FS)
    truth = np.asarray(grid["truth"], dtype=float)
    out = {"machine": common.machine(), "seeds": args.seeds, "k": args.k, "truth": truth.tolist(), "shapes": []}
    for shape in args.shapes:
        floors, moved = [], []
        for seed in args.seeds:
            own = andes_own.own_recording(shape, tf=TF, tstep=TSTEP, seed=seed)
            windows = pool_windows(grid, own, args.k, seed, shape)
            differ = []
            for i, w in enumerate(windows):
                f = noise.channel_floors(w.V, w.theta, w.P, w.Q, 1.0 / float(w.t[1] - w.t[0]))
                floors.append([f[f"floor_{s}_{c}"] for s in ("tilt", "slope") for c in CHANNELS])
                old = [c for c in CHANNELS if tilt_alone(f, c)]
                now = [c for c in CHANNELS if preprocess.white_floor(f, c)]
                if old != now:
                    differ.append({"window": i, "noisy_tilt_alone": old, "noisy_now": now,
                                   "floors": {k: f[k] for k in sorted(f) if k.startswith("floor_")}})
            if not differ:
                continue
            fits = {}
            for name, rule in (("now", preprocess.white_floor), ("tilt alone", tilt_alone)):
                with floor_rule(rule):
                    single = {d["window"]: (identify(windows[d["window"]], config=IV).d / truth - 1).tolist()
                              for d in differ}
                    # The pool's IV as it was when this check was made (2SLS, the residual's AR; stop 38 changed
                    # identify_pooled's default).
                    pooled = (identify_pooled(windows, disturbance="ar_iv", iv_estimator="2sls",
                                              iv_whitening="residual").d / truth - 1).tolist()
                fits[name] = {"single ar_iv": single, "pooled ar_iv": pooled}
            moved.append({"seed": seed, "windows": differ, "errors": fits})
            for d in differ:
                print(f"{shape} seed {seed} window {d['window']}: noisy by the tilt alone {d['noisy_tilt_alone']}, "
                      f"now {d['noisy_now']}; single ar_iv error a/b/H2/Tm [%] now "
                      f"{np.round(100 * np.array(fits['now']['single ar_iv'][d['window']]), 1)}, tilt alone "
                      f"{np.round(100 * np.array(fits['tilt alone']['single ar_iv'][d['window']]), 1)}", flush=True)
            print(f"{shape} seed {seed} pool ar_iv error [%] now {np.round(100 * np.array(fits['now']['pooled ar_iv']), 1)}, "
                  f"tilt alone {np.round(100 * np.array(fits['tilt alone']['pooled ar_iv']), 1)}", flush=True)
        fl = np.array(floors)
        rng = {f"{s}_{c}": [float(fl[:, j].min()), float(fl[:, j].max())]
               for j, (s, c) in enumerate((s, c) for s in ("tilt", "slope") for c in CHANNELS)}
        out["shapes"].append({"shape": shape, "windows": len(fl), "floor_ranges": rng, "changed": moved})
        print(f"{shape}: {len(fl)} windows, floor ranges {({k: [round(x, 2) for x in v] for k, v in rng.items()})}, "
              f"verdict changed in {sum(len(m['windows']) for m in moved)}", flush=True)
    out["total_s"] = time.perf_counter() - t_all
    if not args.no_write:
        confirm = set(args.seeds) <= set(CONFIRM_SEEDS)
        common.write_json("pooled_floor_check" + ("" if confirm else "_dev"), out)
    return out


if __name__ == "__main__":
    main()
