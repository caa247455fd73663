"""The ANDES own bench's ramp stretch: what sets its failing windows apart.

On own seed 31 the coupled default is off by more than 20 % on 27 of the 50 ramp windows at own/total 0.9 (3 at 0.5),
most of them starting 40–110 s (docs/numerics.md, "P and Q together").  The bench scales the own run per window
(``cut_windows``: k so that std(own ΔP) / std(grid P) hits the ratio), so a window where the ramp is nearly flat gets
a large k, and with it k × everything the own run has accumulated by then: the network's settled response to the own
level reached so far, a frequency offset that turns θ.  Per window: k, the share of the window's own ΔP a straight
line explains, and what the scaled own run adds to V and θ (its std over the grid-side run's) and its frequency offset
(the slope of the added θ), for the windows off by more than 20 % in the run of record and for the others.

    .venv/bin/python -m benchmarks.own_ramp_stretch [--own-seed 31] [--ratio 0.9] [--superposition [K ...]] [--checks]
        [--horizon S]

Also the windows by their k: how many are off by more than 20 %, and the median |error| there.  ``--superposition``
measures the superposition that builds the windows against one ANDES run with both excitations
(:func:`aslm_sim.andes.own_fluctuation.superposition_error`, 60 s of the own seed's ramp, its own grid seed) at the
scales K (default: the two groups' median k): the superposed channel's error over the joint run's std (~45 s of ANDES
each).

Reads ``docs/results/own_fluctuation_andes_coupled_own<seed>.json`` (the run of record, for the errors); writes
``docs/results/own_ramp_stretch_own<seed>_r<ratio>.json``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from aslm_core import Window, identify, motor
from aslm_core.static import static_power
from aslm_sim.andes import own_fluctuation as andes_own
from aslm_sim.cases import make_cases
from benchmarks import common
from benchmarks import own_fluctuation_andes as bench

CANDIDATE = "default, coupled channels"


def derotated(ws: list[dict], err: np.ndarray, truth: np.ndarray) -> dict:
    """The default on the windows as they are and with θ's straight line removed (the frequency offset taken out):
    windows off by more than 20 % in the worst parameter, among the run of record's far-off windows and the others."""
    out = {}
    for name, fix in (("as is", False), ("θ de-rotated", True)):
        worst = []
        for w in ws:
            win = bench.as_window(w)
            if fix:
                t = win.t - win.t[0]
                win = replace(win, theta=win.theta - np.polyval(np.polyfit(t, win.theta, 1), t))
            worst.append(100.0 * float(np.max(np.abs(identify(win).d / truth - 1.0))))
        worst = np.array(worst)
        out[name] = {"off_20_of_far_off": int(np.sum(worst[err > 20.0] > 20.0)), "far_off": int(np.sum(err > 20.0)),
                     "off_20_of_others": int(np.sum(worst[err <= 20.0] > 20.0)), "others": int(np.sum(err <= 20.0))}
        print(f"{name}: off > 20 % on {out[name]['off_20_of_far_off']} of the {out[name]['far_off']} far-off windows, "
              f"{out[name]['off_20_of_others']} of the {out[name]['others']} others", flush=True)
    return out


def frequency_offset_check(n: int = 12, offsets=(0.0, 0.01, 0.02, 0.05, 0.1)) -> dict:
    """The identifier on its own model's data under a steady frequency offset: the synthetic bench's clean inputs
    (seed 5) with θ turning at the offset, the motor run 20 s beforehand under it (settled, as in a long recording),
    P and Q from the true load plus 25 dB noise; the median |error| per parameter at each offset [%]."""
    cases = make_cases(n, level=None, seed=5, input_noise=False)
    out = {}
    for off in offsets:
        errs = []
        for c in cases:
            w = c.clean
            dt = float(w.t[1] - w.t[0])
            m = int(round(20.0 / dt))
            t = np.arange(m + w.t.size) * dt
            v = np.concatenate([np.full(m, w.V[0]), w.V])
            th = np.concatenate([np.full(m, w.theta[0]), w.theta]) + 2.0 * np.pi * off * t
            d = np.asarray(c.truth.d, dtype=np.float64)
            p_im, q_im, _ = motor.simulate(v, th, d, dt, motor.omega0_of(w.f0))
            ps, qs = static_power(v[m:], c.truth.static)
            rng = np.random.default_rng(1)
            p, q = p_im[m:] + ps, q_im[m:] + qs
            p = p + 10 ** (-25 / 20) * np.std(p) * rng.standard_normal(p.size)
            q = q + 10 ** (-25 / 20) * np.std(q) * rng.standard_normal(q.size)
            r = identify(Window(w.t, v[m:], th[m:], p, q, f0=w.f0))
            errs.append(100.0 * np.abs(r.d / d - 1.0))
        out[f"{off:g}"] = np.median(errs, axis=0).tolist()
        print(f"frequency offset {off:g} Hz: median |error| a / b / H2 / Tm "
              + " / ".join(f"{x:.1f}" for x in out[f"{off:g}"]) + " %", flush=True)
    return out


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--own-seed", type=int, default=31)
    ap.add_argument("--ratio", type=float, default=0.9)
    ap.add_argument("--checks", action="store_true",
                    help="also the two checks that ruled causes out: θ de-rotated, and a frequency offset on the "
                         "identifier's own model")
    ap.add_argument("--superposition", nargs="*", type=float, default=None, metavar="K",
                    help="also check the superposition at these scales (none given: the two groups' median k)")
    ap.add_argument("--horizon", type=float, default=None,
                    help="build the windows with cut_windows' horizon_s (the groups stay the run of record's)")
    args = ap.parse_args(argv)
    recorded = common.read_json(f"own_fluctuation_andes_coupled_own{args.own_seed}")
    run = next(r for r in recorded["runs"] if r["shape"] == "ramp" and r["ratio"] == args.ratio)
    err = 100.0 * np.abs(np.array(run["errors"][CANDIDATE], dtype=float)).max(axis=1)
    grid = andes_own.grid_recording(tf=bench.TF, tstep=bench.TSTEP, seed=bench.SEED, fs=bench.FS)
    own = andes_own.own_recording("ramp", tf=bench.TF, tstep=bench.TSTEP, seed=args.own_seed)
    ws = bench.row_windows(grid, own, args.ratio, "ramp", err.size, args.own_seed, horizon_s=args.horizon)
    per = []
    for i, w in enumerate(ws):
        a = int(round((bench.START_S + i * bench.STRIDE_S) * bench.FS))
        sl = slice(a, a + w["t"].size)
        x = w["dp_own"][int(bench.FS):]
        t = np.arange(x.size)
        line = np.polyval(np.polyfit(t, x, 1), t)
        th_own, v_own = w["theta"] - grid["theta"][sl], w["V"] - grid["V"][sl]
        per.append({"start_s": float(w["t"][0]), "error_pct": float(err[i]), "k": float(w["k"]),
                    "line_r2": float(1.0 - np.var(x - line) / np.var(x)),
                    "theta_ratio": float(np.std(th_own) / np.std(grid["theta"][sl])),
                    "v_ratio": float(np.std(v_own) / np.std(grid["V"][sl])),
                    "f_offset_hz": float(abs(np.polyfit(w["t"] - w["t"][0], th_own, 1)[0]) / (2 * np.pi)),
                    # How far the scaled own run has moved the bus's operating point (stop 36).
                    "v_shift_pct": float(100.0 * abs(v_own.mean()) / grid["V"][sl].mean()),
                    "p_shift_pct": float(100.0 * abs((w["P"] - grid["P"][sl]).mean()) / grid["P"][sl].mean())})
    rows, out = [], {"own_seed": args.own_seed, "ratio": args.ratio, "candidate": CANDIDATE, "windows": per}
    for name, sel in (("off > 20 %", err > 20.0), ("within 20 %", err <= 20.0)):
        g = [p for p, s in zip(per, sel, strict=True) if s]
        if not g:
            continue
        keys = ("k", "line_r2", "theta_ratio", "v_ratio", "f_offset_hz", "v_shift_pct", "p_shift_pct")
        med = {k: float(np.median([p[k] for p in g])) for k in keys}
        span = {f"{k}_range": [min(p[k] for p in g), max(p[k] for p in g)] for k in ("v_shift_pct", "p_shift_pct")}
        out[name] = {"n": len(g), **med, **span}
        rows.append([name, len(g), f"{med['k']:.1f}", f"{med['line_r2']:.3f}", f"{med['theta_ratio']:.2f}",
                     f"{med['v_ratio']:.2f}", f"{med['f_offset_hz']:.4f}",
                     f"{med['v_shift_pct']:.2f} [{span['v_shift_pct_range'][0]:.2f}, {span['v_shift_pct_range'][1]:.2f}]",
                     f"{med['p_shift_pct']:.1f} [{span['p_shift_pct_range'][0]:.1f}, {span['p_shift_pct_range'][1]:.1f}]"])
    print(common.md_table(["windows", "n", "k (median)", "straight line's R² of own ΔP", "added θ std / grid θ std",
                           "added V std / grid V std", "added frequency offset [Hz]",
                           "|mean V shift| [%] (median [range])", "|mean P shift| [%] (median [range])"], rows))
    # The windows by the scale of their own run: how many are off, and the coupled default's median |error|.
    edges = (0.0, 20.0, 40.0, 70.0, np.inf)
    k_all = np.array([p["k"] for p in per])
    err4 = 100.0 * np.abs(np.array(run["errors"][CANDIDATE], dtype=float))
    binned = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        m = (k_all > lo) & (k_all <= hi)
        if m.any():
            med = np.median(err4[m], axis=0)
            out.setdefault("by_k", []).append({"k_from": lo, "k_to": hi, "n": int(m.sum()), "off_20": int((err[m] > 20).sum()),
                                               "median_abs_pct": med.tolist()})
            binned.append([f"{lo:g}–{hi:g}", int(m.sum()), int((err[m] > 20).sum()), " / ".join(f"{x:.1f}" for x in med)])
    print(common.md_table(["k", "windows", "off > 20 %", "median |error| a / b / H2 / Tm [%]"], binned))
    if args.superposition is not None:
        scales = args.superposition or [round(out[g]["k"]) for g in ("within 20 %", "off > 20 %") if g in out]
        check = []
        for scale in scales:
            err_s = andes_own.superposition_error(tf=60.0, tstep=bench.TSTEP, shape="ramp", seed=args.own_seed,
                                                  scale=float(scale))
            out.setdefault("superposition", {})[f"{scale:g}"] = err_s
            check.append([f"{scale:g}", *(f"{100 * err_s[c]:.1f}" for c in ("V", "theta", "P", "Q"))])
            print(f"superposition at k = {scale:g}: done", flush=True)
        print(common.md_table(["k", "V error [%]", "θ error [%]", "P error [%]", "Q error [%]"], check))
    if args.checks:
        out["derotated"] = derotated(ws, err, np.asarray(grid["truth"], dtype=np.float64))
        out["frequency_offset"] = frequency_offset_check()
    if not args.no_write:
        common.write_json(f"own_ramp_stretch_own{args.own_seed}_r{args.ratio:g}"
                          + ("" if args.horizon is None else f"_horizon{args.horizon:g}"), out)
    return out


if __name__ == "__main__":
    main()
