"""Helpers shared by the service sub-commands: settings flags, logging, waiting for Ctrl-C."""

from __future__ import annotations

import argparse
import logging
import signal
import threading

# CLI flag → settings field; a flag not given leaves the file/environment value alone.
SETTING_FLAGS: tuple[tuple[str, str, type, str], ...] = (
    ("--prefix", "prefix", str, "Zenoh key prefix"),
    ("--period", "period_s", float, "period T [s]"),
    ("--window", "window_s", float, "window length [s]"),
    ("--frame-rate", "frame_rate", float, "nominal PMU frame rate [frames/s]"),
    ("--late", "late_s", float, "late-data allowance [s]"),
    ("--workers", "workers", int, "local worker processes"),
    ("--executor", "executor", str, "'local' or a Dask scheduler address tcp://host:8786"),
    ("--task-timeout", "task_timeout_s", float, "per-window identification timeout [s]"),
    ("--storage", "storage_url", str, "SQLite file (or sqlite:///path)"),
    ("--zenoh-mode", "zenoh_mode", str, "peer, client or router"),
    ("--zenoh-config", "zenoh_config_file", str, "Zenoh JSON5 config file (TLS, ...)"),
    ("--host", "http_host", str, "REST bind address"),
    ("--port", "http_port", int, "REST port (0: any free port)"),
    ("--f0", "f0", float, "nominal frequency [Hz]"),
)


def _setting_default(field: str) -> str:
    """`` (default: X; $ASLM_FIELD)``: the settings field's default, shown although the flag's is None."""
    from service.settings import ServiceSettings

    info = ServiceSettings.model_fields[field]
    value = info.default if info.default_factory is None else info.default_factory()
    shown = "none" if value is None else (" ".join(value) or "none") if isinstance(value, list) else value
    return f" (default: {shown}, unless the settings file or ${'ASLM_' + field.upper()} sets it)"


def add_setting_flags(p: argparse.ArgumentParser, skip: tuple[str, ...] = ()) -> None:
    """Add the settings flags.  Each defaults to None (not given: the file/environment value stands);
    the help shows the settings field's own default."""
    p.add_argument("--config", metavar="FILE", help="TOML settings file (default $ASLM_CONFIG)")
    for flag, field, typ, help_ in SETTING_FLAGS:
        if field not in skip:
            p.add_argument(flag, dest=field, type=typ, default=None, help=help_ + _setting_default(field))
    if "zenoh_connect" not in skip:
        p.add_argument("--connect", dest="zenoh_connect", action="append", metavar="ENDPOINT",
                       help="Zenoh endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)"
                       + _setting_default("zenoh_connect"))
        p.add_argument("--listen", dest="zenoh_listen", action="append", metavar="ENDPOINT",
                       help="Zenoh endpoint to listen on (repeatable)" + _setting_default("zenoh_listen"))
    p.add_argument("--log-level", default="INFO", help="logging level (default INFO)")


def add_publisher_flags(p: argparse.ArgumentParser) -> None:
    """Flags of a command that publishes frames onto Zenoh: prefix, session mode and endpoints, logging."""
    p.add_argument("--prefix", default="aslm", help="Zenoh key-expression prefix")
    p.add_argument("--mode", default="peer", choices=["peer", "client"], help="Zenoh mode")
    p.add_argument("--connect", action="append", metavar="ENDPOINT",
                   help="Zenoh endpoint (default tcp/127.0.0.1:7447; repeatable)")
    p.add_argument("--listen", action="append", metavar="ENDPOINT", help="Zenoh endpoint to listen on")
    p.add_argument("--log-level", default="INFO", help="logging level")


def add_mapping_flags(p: argparse.ArgumentParser) -> None:
    """``--mapping`` and ``--bus``: which channels of a COMTRADE file form the load bus."""
    p.add_argument("--mapping", metavar="TOML", help="bus mapping for COMTRADE .cfg/.cff files (docs/protocols.md)")
    p.add_argument("--bus", help="the mapping's bus to read (default its first)")


def setting_overrides(args: argparse.Namespace) -> dict:
    """The settings given on the command line."""
    names = [f for _, f, _, _ in SETTING_FLAGS] + ["zenoh_connect", "zenoh_listen"]
    return {n: getattr(args, n) for n in names if getattr(args, n, None) is not None}


def setup_logging(level: str) -> None:
    logging.basicConfig(level=level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def stop_event_on_signals() -> threading.Event:
    """An event set by SIGINT/SIGTERM (main thread only)."""
    stop = threading.Event()

    def handler(signum, frame):  # noqa: ARG001
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop
