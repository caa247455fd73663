"""``aslm replay``: publish a synthetic PMU fleet with known truth (or recorded files) onto Zenoh in real time."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from service.commands._common import (
    add_mapping_flags,
    add_publisher_flags,
    setup_logging,
    stop_event_on_signals,
)

log = logging.getLogger("aslm.replay")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="publish a synthetic fleet (or recordings) onto {prefix}/pmu/{bus}")
    p.add_argument("files", nargs="*", metavar="FILE",
                   help=".npz/.csv recordings (one bus each) or COMTRADE with --mapping; none: synthetic")
    p.add_argument("--buses", type=int, default=10, help="synthetic buses (default 10)")
    p.add_argument("--rate", type=float, default=50.0, help="frames/s per bus (default 50)")
    p.add_argument("--batch", type=float, default=0.2, help="seconds of frames per message (default 0.2)")
    p.add_argument("--encoding", choices=["binary", "json"], default="binary", help="frame encoding")
    p.add_argument("--level", type=int, default=2, help="measurement-noise level of the fleet (default 2)")
    p.add_argument("--seed", type=int, default=0, help="seed of the synthetic fleet")
    p.add_argument("--f0", type=float, default=50.0, help="nominal frequency [Hz]")
    p.add_argument("--truth", metavar="FILE", help="write the true parameters (JSON) here")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--loop", action="store_true", help="repeat recordings")
    add_publisher_flags(p)
    add_mapping_flags(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    setup_logging(args.log_level)
    import zenoh

    from service.replay import FleetReplayer, FramePublisher, replay_files, write_truth
    from service.zenoh_config import zenoh_config

    stop = stop_event_on_signals()
    session = zenoh.open(zenoh_config(args.mode, connect=args.connect or ["tcp/127.0.0.1:7447"],
                                      listen=args.listen or []))
    pub = FramePublisher(session, args.prefix, args.encoding)
    try:
        if args.files:
            paths = [Path(f) for f in args.files]
            missing = [str(p) for p in paths if not p.is_file()]
            if missing:
                print(f"aslm replay: no such file: {', '.join(missing)}", file=sys.stderr)
                return 2
            if args.duration:
                import threading
                threading.Timer(args.duration, stop.set).start()
            replay_files(pub, paths, batch_s=args.batch, loop=args.loop, stop=stop, mapping=args.mapping)
        else:
            from aslm_sim.fleet import SyntheticFleet

            fleet = SyntheticFleet(args.buses, fs=args.rate, f0=args.f0, level=args.level, seed=args.seed,
                                   t0=time.time())
            rep = FleetReplayer(pub, fleet, batch_s=args.batch)
            if args.truth:
                write_truth(args.truth, rep.truth())
                log.info("truth of %d buses written to %s", args.buses, args.truth)
            log.info("publishing %d buses at %g frames/s (%s, %d frames/message) on %s/pmu/*", args.buses,
                     args.rate, args.encoding, rep.n_batch, args.prefix)
            rep.start(args.duration)
            while rep._thread.is_alive() and not stop.wait(0.5):
                pass
            rep.stop()
        log.info("sent %d frames in %d messages", pub.frames_sent, pub.messages_sent)
    finally:
        pub.close()
        session.close()
    return 0
