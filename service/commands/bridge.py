"""``aslm bridge c37118 MAPPING``: follow a PMU/PDC's C37.118.2 stream and publish its buses on Zenoh."""

from __future__ import annotations

import argparse
import json
import logging
import sys
import threading

from service.commands._common import add_publisher_flags, setup_logging, stop_event_on_signals

log = logging.getLogger("aslm.bridge")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bridge", help="publish a grid protocol's PMU stream onto {prefix}/pmu/{bus}")
    p.add_argument("protocol", choices=["c37118"], help="protocol of the stream")
    p.add_argument("mapping", metavar="MAPPING", help="TOML mapping: the [c37118] stream and [buses.NAME] tables")
    p.add_argument("--host", help="PMU/PDC address (overrides the mapping's)")
    p.add_argument("--port", type=int, help="PMU/PDC TCP port (overrides the mapping's)")
    p.add_argument("--idcode", type=int, help="IDCODE of the stream (overrides the mapping's)")
    p.add_argument("--udp", type=int, metavar="PORT", help="take data over UDP on this local port")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    add_publisher_flags(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    setup_logging(args.log_level)
    from service.protocols.mapping import MappingError
    from service.sources.c37118 import C37118Client, load

    try:
        stream, mapping = load(args.mapping)
    except MappingError as exc:
        print(f"aslm bridge: {exc}", file=sys.stderr)
        return 2
    for name in ("host", "port", "idcode"):
        if getattr(args, name) is not None:
            setattr(stream, name, getattr(args, name))
    if args.udp is not None:
        stream.transport, stream.udp_port = "udp", args.udp

    import zenoh

    from service.replay import FramePublisher
    from service.zenoh_config import zenoh_config

    stop = stop_event_on_signals()
    if args.duration:
        threading.Timer(args.duration, stop.set).start()
    session = zenoh.open(zenoh_config(args.mode, connect=args.connect or ["tcp/127.0.0.1:7447"],
                                      listen=args.listen or []))
    pub = FramePublisher(session, args.prefix, "binary")
    client = C37118Client(stream, mapping, pub.send)
    log.info("following C37.118 stream %d at %s:%d (%s data) for %d bus(es) onto %s/pmu/*", stream.idcode,
             stream.host, stream.port, stream.transport, len(mapping.buses), args.prefix)
    client.start_thread()
    try:
        while not stop.wait(0.5):
            pass
    finally:
        client.close()
        counts = {**client.counts(), "published": pub.frames_sent, "messages": pub.messages_sent}
        pub.close()
        session.close()
        print(json.dumps(counts, sort_keys=True))
    return 0
