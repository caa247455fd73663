"""``aslm serve``: run the streaming service until SIGINT/SIGTERM."""

from __future__ import annotations

import argparse
import logging
import sys

from service.commands._common import (
    add_setting_flags,
    setting_overrides,
    setup_logging,
    stop_event_on_signals,
)
from service.settings import SettingsError, load_settings

log = logging.getLogger("aslm.serve")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("serve", help="run the streaming identification service (Zenoh in, Zenoh + REST out)",
                       description="Settings: TOML file < ASLM_* environment < these flags. "
                                   "The operator token is read from ASLM_OPERATOR_TOKEN (or the file).")
    add_setting_flags(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    setup_logging(args.log_level)
    try:
        settings = load_settings(args.config, **setting_overrides(args))
        _ = settings.storage_path
    except (SettingsError, ValueError) as exc:
        print(f"aslm serve: {exc}", file=sys.stderr)
        return 2
    from service.app import Service
    from service.storage import StorageError

    stop = stop_event_on_signals()
    try:
        svc = Service(settings)
    except StorageError as exc:  # an unusable storage path: the one-line error of invalid settings
        print(f"aslm serve: {exc}", file=sys.stderr)
        return 2
    try:
        svc.start()
        log.info("serving: prefix %r, period %g s, window %g s, %s executor; REST %s (OpenAPI at /docs)",
                 settings.prefix, svc.period_s, settings.window_s, settings.executor, svc.url)
        while not stop.wait(1.0):
            pass
    finally:
        log.info("stopping")
        svc.stop()
    return 0
