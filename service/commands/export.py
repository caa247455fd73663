"""``aslm export RESULT.json --format andes|psse|pslf [--xp …] [--loading …]``: records for a simulator."""

from __future__ import annotations

import argparse
import json
import sys

from aslm_core.records import FORMATS, Assumptions, RecordError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="write an identified model as ANDES, PSS/E or PSLF records",
                       description="Invert the transformed motor under stated assumptions (docs/records.md) and "
                                   "write the records of a simulator.")
    p.add_argument("result", metavar="RESULT.json",
                   help="aslm identify --json output, or a service result (REST/Zenoh); JSON lines: one record each")
    p.add_argument("--format", required=True, choices=FORMATS)
    free = p.add_mutually_exclusive_group()
    free.add_argument("--xp", type=float, default=None,
                      help="transient reactance X' on the motor base [pu] (the free quantity; default 0.2)")
    free.add_argument("--td0", type=float, default=None, help="open-circuit transient time constant Td0 [s] instead")
    p.add_argument("--loading", type=float, default=0.8, help="motor power / motor MVA rating (default 0.8)")
    p.add_argument("--xs-over-xr", type=float, default=1.0, help="stator / rotor leakage reactance (default 1)")
    p.add_argument("--v0", type=float, default=1.0, help="operating (power-flow) voltage of the bus [pu] (default 1)")
    p.add_argument("--f0", type=float, default=50.0, help="nominal frequency of the identification [Hz] (default 50)")
    p.add_argument("--sbase", type=float, default=100.0, help="system base of the per-unit values [MVA] (default 100)")
    p.add_argument("--static-qz-nonnegative", action="store_true",
                   help="refuse X' that leaves the static Qz negative")
    p.add_argument("--bus-number", type=int, default=None, help="bus number in the records (default: from the name)")
    p.add_argument("--kv", type=float, default=138.0, help="rated voltage of the bus [kV] (default 138)")
    p.add_argument("--json", action="store_true", help="the whole payload (assumptions, values, SE, intervals)")
    p.add_argument("-o", "--output", default=None, help="write here instead of standard output")
    p.set_defaults(func=run)


def _objects(path: str) -> list[dict]:
    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    try:
        obj = json.loads(text)
        return obj if isinstance(obj, list) else [obj]
    except json.JSONDecodeError:
        return [json.loads(line) for line in text.splitlines() if line.strip()]


def run(args: argparse.Namespace) -> int:
    from service.records import record_payload

    asm = Assumptions(xp=args.xp, td0=args.td0, loading=args.loading, xs_over_xr=args.xs_over_xr, v0=args.v0,
                      f0=args.f0, sbase_mva=args.sbase, require_static_qz_nonnegative=args.static_qz_nonnegative)
    try:
        objs = _objects(args.result)
    except (OSError, ValueError) as exc:
        print(f"{args.result}: error: {exc}", file=sys.stderr)
        return 1
    out, status = [], 0
    for obj in objs:
        try:
            payload = record_payload(obj, args.format, asm, number=args.bus_number, kv=args.kv)
        except RecordError as exc:
            status = 1
            print(f"{args.result}: error: {exc}", file=sys.stderr)
            continue
        out.append(json.dumps(payload) if args.json else payload["content"].rstrip("\n"))
    text = "\n".join(out) + ("\n" if out else "")
    if args.output:
        with open(args.output, "w", encoding="utf-8") as fh:
            fh.write(text)
    else:
        sys.stdout.write(text)
    return status
