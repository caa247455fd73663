"""``aslm identify FILE... [--json] [--f0 HZ]``: identify the load model of recorded windows."""

from __future__ import annotations

import argparse
import json
import sys
from typing import get_args

from aslm_core import IdentifyConfig, WindowError, identify, warmup
from aslm_core.preprocess import INPUT_SMOOTHERS
from aslm_core.result import Disturbance, InputNoise, InputWeighting, IvEstimator, IvWhitening
from service.commands._common import add_mapping_flags
from service.files import read_window


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("identify", help="identify ZIP+IM parameters of .npz/.csv recordings")
    p.add_argument("files", nargs="+", metavar="FILE", help=".npz or .csv with t, V, theta, P, Q")
    p.add_argument("--json", action="store_true", help="one JSON object per line per FILE")
    p.add_argument("--f0", type=float, default=None, help="nominal frequency [Hz] (default: file's, else 50)")
    add_mapping_flags(p)
    p.add_argument("--integrator", choices=["rk4", "euler"], default="rk4", help="motor model integrator")
    p.add_argument("--objective", choices=["paper", "ml", "ssq"], default="paper",
                   help="objective: the paper's eq. 7, Gaussian likelihood or sum of squares")
    p.add_argument("--static", choices=["zip", "exponential"], default="zip", help="static load model")
    p.add_argument("--lowpass", type=float, default=None, metavar="HZ",
                   help="fixed causal low-pass cut-off [Hz] (default: chosen from the inputs' noise floors)")
    p.add_argument("--input-smoother", choices=list(INPUT_SMOOTHERS), default=IdentifyConfig.input_smoother,
                   help="smoother of the noisy inputs V and θ (default %(default)s, docs/numerics.md)")
    p.add_argument("--input-noise", choices=list(get_args(InputNoise)), default=IdentifyConfig.input_noise,
                   help="auto (default): V and θ whose noise floor above 5 Hz falls are taken as exact (simulated data); "
                        "measured: the file is a PMU's recording, whose channels always carry noise, and a falling "
                        "floor is its reporting filter's (an M-class PMU's), read where the filter is flat "
                        "(docs/numerics.md, \"Stop 55: a PMU's reporting filter\")")
    p.add_argument("--starts", type=int, default=3, help="random feasible starts")
    p.add_argument("--disturbance", choices=list(get_args(Disturbance)), default=IdentifyConfig.disturbance,
                   help="noise model of P and Q: none (white), ar (the load's own fluctuation, prediction error), "
                        "ar_iv (the same solved by instrumental variables, for own fluctuation fed back through the "
                        "network) or gated (none, and ar_iv where the window's own fluctuation share is above 0.3 "
                        "and its instruments pass; docs/numerics.md)")
    p.add_argument("--input-weighting", choices=list(get_args(InputWeighting)), default=IdentifyConfig.input_weighting,
                   help="spectral (default): refine D by weighting the residuals per frequency with the noise V and "
                        "θ carry through the model (noisy inputs only; about 2x the time there); none: the "
                        "output-error fit alone (docs/numerics.md)")
    p.add_argument("--input-spectrum-tail", action=argparse.BooleanOptionalAction,
                   default=IdentifyConfig.input_spectrum_tail,
                   help="the refinement's smoother continues V's and θ's spectrum above its cut-off by a fitted power law "
                        "up to 5 Hz (docs/numerics.md, \"Stop 41: the signal above the smoother's cut-off\")")
    p.add_argument("--couple-channels", action=argparse.BooleanOptionalAction, default=IdentifyConfig.couple_channels,
                   help="the AR and IV fits take Q − k·P as the second channel, k the own fluctuation's ΔQ/ΔP read "
                        "from the residuals (default on; docs/numerics.md, \"P and Q together\")")
    p.add_argument("--iv-estimator", choices=list(get_args(IvEstimator)), default=IdentifyConfig.iv_estimator,
                   help="criterion of the IV fit (ar_iv, and gated where the IV answers): 2sls or liml, which does "
                        "not pull toward the loop-biased least-squares answer when the instruments are weak "
                        "(default %(default)s; docs/numerics.md)")
    p.add_argument("--iv-whitening", choices=list(get_args(IvWhitening)), default=IdentifyConfig.iv_whitening,
                   help="AR noise models of the IV fit: of the residual (own fluctuation plus the PMU's white noise) "
                        "or of the own fluctuation alone, the white noise taken off where the residual's "
                        "autocovariance is exponential (default %(default)s; docs/numerics.md)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    config = IdentifyConfig(
        integrator=args.integrator, objective=args.objective, static=args.static,
        lowpass_hz=args.lowpass, input_smoother=args.input_smoother, n_starts=args.starts,
        disturbance=args.disturbance, input_weighting=args.input_weighting, couple_channels=args.couple_channels,
        input_spectrum_tail=args.input_spectrum_tail,
        iv_estimator=args.iv_estimator, iv_whitening=args.iv_whitening, input_noise=args.input_noise,
    )
    warmup()  # load the compiled kernels first so elapsed_s measures the identification alone
    status = 0
    for path in args.files:
        try:
            window = read_window(path, f0=args.f0, mapping=args.mapping, bus=args.bus)
            result = identify(window, config=config)
        except (OSError, ValueError, WindowError) as exc:
            status = 1
            if args.json:
                print(json.dumps({"file": path, "error": str(exc), "reason": getattr(exc, "reason", "input")}))
            else:
                print(f"{path}: error: {exc}", file=sys.stderr)
            continue
        out = {"file": path, **result.to_dict()}
        if args.json:
            print(json.dumps(out))
        else:
            print(_human(path, result))
    return status


def _human(path: str, result) -> str:
    d, s, se = result.dynamic, result.static, result.stderr
    dyn = "  ".join(f"{k}={v:.4g}±{se.get(k, float('nan')):.2g}" for k, v in d.items())
    sse = result.static_stderr
    sta = "  ".join(f"{k}={v:.4g}±{sse.get(k, float('nan')):.2g}" for k, v in s.items())
    if "static_split_unidentifiable" in result.flags:  # its coefficients are noise; P0 and dP/dV above are not
        sta += "  (not identifiable from this window)"
    flags = ", ".join(result.flags) or "none"
    loc = result.static_local
    at_v0 = "  ".join(f"{k}={loc[k]:.4g}±{loc[k + '_se']:.2g}" for k in ("P0", "dPdV", "Q0", "dQdV") if k in loc)
    q = result.quality
    warn = ""
    if "input_noise_too_large" in result.flags:
        warn = (f"\n  warning: input noise too large: V moves by {q['input_ratio_v']:.2g}× its PMU noise std "
                f"({q['noise_v']:.2g} pu), below 2×: D is not trustworthy from this window")
    if q.get("gated_ar_iv") == 1.0:
        warn += (f"\n  estimator: instrumental variables with an AR model of the load's own fluctuation, which is "
                 f"{q['own_ratio_p']:.2g} of P's ambient std (output error is not consistent above 0.3)")
        if "own_median_hz_p" in q:
            warn += f", half of its variance below {q['own_median_hz_p']:.2g} Hz"
    if "iv_error_may_exceed_20pct" in result.flags or "error_may_exceed_20pct" in result.flags:
        warn += "\n  warning: a standard error is above 6 % of its parameter: an error above 20 % is not a rare draw"
    if "input_noise_correction_large" in result.flags:
        warn += (f"\n  warning: the input-noise correction moved D by {q['weighted_shift_z']:.2g} of its standard "
                 f"errors from the output-error fit: D rests on the estimated PMU noise of V and θ")
    if "halves_disagree" in result.flags:
        warn += (f"\n  warning: the window's two halves give D {q['halves_z']:.2g} combined standard errors apart: "
                 f"the answer depends on which half the window saw")
    return (
        f"{path}\n  dynamic: {dyn}\n  static at V0={loc.get('V0', float('nan')):.4g}: {at_v0}\n  static split: {sta}\n"
        f"  objective={result.objective:.4g}  FD(P)={result.fit['fd_p']:.4f}  FD(Q)={result.fit['fd_q']:.4f}"
        f"  flags: {flags}  ({result.elapsed_s * 1e3:.1f} ms)" + warn
    )
