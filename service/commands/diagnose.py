"""``aslm diagnose FILE [--json] [--model MODEL.json] [--report DIR]``: why a model and a recording differ."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from aslm_core import WindowError, warmup
from aslm_core.diagnosis import DiagnosisConfig, DiagnosisReport, diagnose
from service.commands._common import add_mapping_flags
from service.files import read_window


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("diagnose", help="locate and explain the mismatch between a load model and a recording")
    p.add_argument("file", metavar="FILE", help=".npz or .csv with t, V, theta, P, Q (optional f)")
    p.add_argument("--json", action="store_true", help="print the report as one JSON object")
    p.add_argument("--model", metavar="MODEL.json", default=None,
                   help="user model {dynamic: {a, b, H2, Tm}, static: {...}} (e.g. `aslm identify --json` output); "
                        "default: identified from the recording")
    p.add_argument("--report", metavar="DIR", default=None, help="write a Markdown report with PNG figures to DIR")
    p.add_argument("--f0", type=float, default=None, help="nominal frequency [Hz] (default: file's, else 50)")
    add_mapping_flags(p)
    p.add_argument("--train-fraction", type=float, default=0.65,
                   help="share of the window the time-ordered fold is fitted on (the rest held out)")
    p.add_argument("--one-fold", action="store_true",
                   help="judge on the time-ordered fold only (default: cross-fitted, a mirrored fold judged too)")
    p.add_argument("--input-noise", choices=["auto", "measured"], default="auto",
                   help="measured: the file is a PMU's recording, whose noise floor may fall above its reporting "
                        "filter's passband (an M-class PMU's); auto (default): such inputs are taken as exact "
                        "(docs/diagnosis.md, \"Stop 55: a PMU's reporting filter\")")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        window = read_window(args.file, f0=args.f0, mapping=args.mapping, bus=args.bus)
        model = None
        if args.model:
            model = json.loads(Path(args.model).read_text())
        warmup()
        config = DiagnosisConfig(train_fraction=args.train_fraction, cross_fit=not args.one_fold,
                                 input_noise=args.input_noise)
        report = diagnose(window, model, config=config)
    except (OSError, ValueError, WindowError, KeyError) as exc:
        if args.json:
            print(json.dumps({"file": args.file, "error": str(exc), "reason": getattr(exc, "reason", "input")}))
        else:
            print(f"{args.file}: error: {exc}", file=sys.stderr)
        return 1
    out = {"file": args.file, **report.to_dict()}
    if args.report:
        from service.report import write_report

        out["report"] = str(write_report(report, args.report, title=Path(args.file).name))
    if args.json:
        print(json.dumps(out))
    else:
        print(_human(args.file, report, out.get("report")))
    return 0


def _human(path: str, report: DiagnosisReport, report_path: str | None) -> str:
    fb, fa = report.fit_before, report.fit_after
    lines = [f"{path}: {report.verdict}" + (f" — {' | '.join(report.causes)}" if report.causes else ""), f"  {report.message}",
             f"  held-out FD before: P {fb.fd_p:.4f}  Q {fb.fd_q:.4f}   after: P {fa.fd_p:.4f}  Q {fa.fd_q:.4f}"]
    loc = report.located
    if loc.channels:
        for ch in loc.channels:
            bands = ", ".join(f"{b[0]:g}–{b[1]:g} Hz" for b in loc.bands.get(ch, []))
            segs = ", ".join(f"{s[-2]:.1f}–{s[-1]:.1f} s" for s in loc.time_segments.get(ch, []))
            lines.append(f"  {ch}: residual above noise in {bands}; segments {segs or '-'}")
    for e in report.missing_physics:
        if not e.tested:
            continue
        pars = ", ".join(f"{k}={v:.4g}±{e.stderr.get(k, float('nan')):.2g}" for k, v in e.parameters.items())
        lines.append(f"  {'*' if e.significant else ' '} {e.name:<24} z={e.score_z:7.2f}  "
                     f"ΔVar P {100 * e.improvement.p:6.1f} %  Q {100 * e.improvement.q:6.1f} %  {pars}")
    if report_path:
        lines.append(f"  report: {report_path}")
    return "\n".join(lines)
