"""``aslm bridge c37118 MAPPING``: follow a PMU/PDC's C37.118.2 stream and publish its buses on Zenoh.

``aslm bridge sttp MAPPING``: the same from an STTP (IEEE 2664) publisher, e.g. openPDC or openHistorian.

``aslm bridge pmu CAPTURE --port 4712``: the other end, for trials: serve a capture file (IEEE 1344, or a
pcap of C37.118) as a C37.118.2 PMU, its frames re-stamped to the present.
"""

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
    p.add_argument("protocol", choices=["c37118", "sttp", "pmu"],
                   help="c37118: follow a stream; sttp: subscribe to an STTP publisher (openPDC, openHistorian); "
                        "pmu: serve a capture file as a PMU")
    p.add_argument("mapping", metavar="MAPPING|CAPTURE",
                   help="c37118/sttp: TOML mapping ([c37118] or [sttp], and [buses.NAME] tables); pmu: a "
                        ".PmuCapture (IEEE 1344) or .pcap (C37.118) file")
    p.add_argument("--host", help="PMU/PDC/publisher address (overrides the mapping's; pmu: address to listen on)")
    p.add_argument("--port", type=int,
                   help="PMU/PDC/publisher TCP port (overrides the mapping's; pmu: port to listen on)")
    p.add_argument("--loop", action="store_true", help="pmu: play the capture again after its end")
    p.add_argument("--idcode", type=int, help="c37118: IDCODE of the stream (overrides the mapping's)")
    p.add_argument("--udp", type=int, metavar="PORT", help="c37118: take data over UDP on this local port")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    add_publisher_flags(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    setup_logging(args.log_level)
    if args.protocol == "pmu":
        return serve_capture(args)
    from service.protocols.mapping import MappingError

    try:
        make_client, what = (_sttp if args.protocol == "sttp" else _c37118)(args)
    except MappingError as exc:
        print(f"aslm bridge: {exc}", file=sys.stderr)
        return 2

    import zenoh

    from service.replay import FramePublisher
    from service.zenoh_config import zenoh_config

    stop = stop_event_on_signals()
    if args.duration:
        threading.Timer(args.duration, stop.set).start()
    session = zenoh.open(zenoh_config(args.mode, connect=args.connect or ["tcp/127.0.0.1:7447"],
                                      listen=args.listen or []))
    pub = FramePublisher(session, args.prefix, "binary")
    client = make_client(pub.send)
    log.info("following %s onto %s/pmu/*", what, args.prefix)
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


def _c37118(args: argparse.Namespace):
    """A C37.118 client factory for the mapping and flags, and what it follows (for the log)."""
    from service.sources.c37118 import C37118Client, load

    stream, mapping = load(args.mapping)
    for name in ("host", "port", "idcode"):
        if getattr(args, name) is not None:
            setattr(stream, name, getattr(args, name))
    if args.udp is not None:
        stream.transport, stream.udp_port = "udp", args.udp
    what = (f"C37.118 stream {stream.idcode} at {stream.host}:{stream.port} ({stream.transport} data) for "
            f"{len(mapping.buses)} bus(es)")
    return (lambda emit: C37118Client(stream, mapping, emit)), what


def _sttp(args: argparse.Namespace):
    """An STTP subscriber factory for the mapping and flags, and what it follows (for the log)."""
    from service.sources.sttp import SttpClient, load

    settings, mapping = load(args.mapping)
    for name in ("host", "port"):
        if getattr(args, name) is not None:
            setattr(settings, name, getattr(args, name))
    what = f"STTP publisher {settings.host}:{settings.port} for {len(mapping.buses)} bus(es)"
    return (lambda emit: SttpClient(settings, mapping, emit)), what


def serve_capture(args: argparse.Namespace) -> int:
    """Serve a capture as a PMU until its end (or Ctrl-C with ``--loop``)."""
    from service.protocols.pmu_server import CapturePmu, capture_stream

    try:
        cfg, frames = capture_stream(args.mapping, idcode=args.idcode or 1)
    except (OSError, ValueError) as exc:
        print(f"aslm bridge: {exc}", file=sys.stderr)
        return 2
    stop = stop_event_on_signals()
    if args.duration:
        threading.Timer(args.duration, stop.set).start()
    pmu = CapturePmu(cfg, frames, host=args.host or "127.0.0.1", port=args.port or 4712, loop=args.loop).start()
    log.info("serving %d frames of stream %d at %g frames/s as a C37.118 PMU on port %d", len(frames), cfg.idcode,
             cfg.data_rate, pmu.port)
    try:
        while not stop.wait(0.5) and not pmu.finished.is_set():
            pass
    finally:
        pmu.close()
        print(json.dumps({"frames": len(frames), "sent": pmu.sent, "idcode": cfg.idcode}))
    return 0
