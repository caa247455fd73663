"""``aslm simulate FILE``: write a synthetic PMU recording with known truth for ``aslm identify``/``diagnose``.

The recording comes from the test bench (:mod:`aslm_sim`): a random ZIP + induction-motor load in a
small simulated network, ambient excitation, and PMU noise at a chosen level (or none); optionally
with a concealed effect (missing physics such as a second motor) that ``aslm diagnose`` should find.
The true parameters go to ``--truth`` (JSON) and are printed.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="write a synthetic recording with known parameters (.npz or .csv)",
                       description="A synthetic recording for `aslm identify` / `aslm diagnose`, from the "
                                   "simulation test bench; the true parameters are printed and, with "
                                   "--truth, written as JSON.")
    p.add_argument("file", metavar="FILE", help="output recording: .npz or .csv (t, V, theta, P, Q, f)")
    p.add_argument("--seed", type=int, default=0, help="seed of the load, network and noise")
    p.add_argument("--level", type=int, choices=[0, 1, 2, 3], default=2,
                   help="measurement-noise level: 1 = 14 dB, 2 = 22 dB, 3 = 28 dB mean SNR of P and Q; 0 = none")
    p.add_argument("--duration", type=float, default=10.0, help="length [s]")
    p.add_argument("--rate", type=float, default=100.0, help="frames/s")
    p.add_argument("--f0", type=float, default=50.0, help="nominal frequency [Hz]")
    p.add_argument("--effect", default="none",
                   help="concealed effect to add, e.g. second_motor (see aslm_sim/effects/); none: plain "
                        "ZIP + IM load")
    p.add_argument("--truth", metavar="FILE.json", default=None, help="write the true parameters here")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from aslm_sim.cases import make_case
    from aslm_sim.effects import EFFECTS
    from service.files import write_window

    path = Path(args.file)
    if path.suffix.lower() not in (".npz", ".csv"):
        print(f"aslm simulate: {path}: use a .npz or .csv file name", file=sys.stderr)
        return 2
    if args.effect != "none" and args.effect not in EFFECTS:
        print(f"aslm simulate: unknown effect {args.effect!r}; one of: none, {', '.join(sorted(EFFECTS))}",
              file=sys.stderr)
        return 2
    case = make_case(args.seed, level=args.level or None, duration_s=args.duration, fs=args.rate, f0=args.f0)
    window, truth = case.window, {"load": case.truth.to_dict(), "snr_db": case.snr_db, "effect": None}
    if args.effect != "none":
        from aslm_sim.effects.apply import apply_effect

        eff = apply_effect(case, args.effect, seed=args.seed)
        window = eff.window
        truth["effect"] = {"name": args.effect, "parameters": eff.truth, "model": eff.model}
    path.parent.mkdir(parents=True, exist_ok=True)
    write_window(path, window)
    text = json.dumps(truth, indent=2, default=float)
    if args.truth:
        Path(args.truth).write_text(text)
    dyn = truth["load"].get("dynamic", {})
    noise = f"SNR {case.snr_db:.1f} dB" if args.level else "noise-free"
    print(f"{path}: {len(window.t)} frames, {args.duration:g} s at {args.rate:g} frames/s, f0 {args.f0:g} Hz, "
          f"{noise}" + (f", effect {args.effect}" if args.effect != "none" else ""))
    print("  true D = " + "  ".join(f"{k}={v:.4g}" for k, v in dyn.items())
          + (f"   (all true parameters in {args.truth})" if args.truth else ""))
    print(f"  next: aslm identify {path}   or   aslm diagnose {path} --report report/")
    return 0
