"""The ``aslm`` command line: one sub-command per module in :mod:`service.commands`."""

from __future__ import annotations

import argparse
import sys

from service.commands import bridge as bridge_cmd
from service.commands import demo as demo_cmd
from service.commands import diagnose as diagnose_cmd
from service.commands import export as export_cmd
from service.commands import identify as identify_cmd
from service.commands import replay as replay_cmd
from service.commands import serve as serve_cmd
from service.commands import simulate as simulate_cmd

COMMANDS = (identify_cmd, serve_cmd, replay_cmd, demo_cmd, diagnose_cmd, export_cmd, bridge_cmd, simulate_cmd)


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """Appends ``(default: X)`` to an option's help unless it says its default already or has none."""

    def _get_help_string(self, action: argparse.Action) -> str:
        help_ = action.help or ""
        if ("default" in help_ or action.default is None or action.default is False
                or action.default == argparse.SUPPRESS or not action.option_strings):
            return help_
        return f"{help_} (default: %(default)s)"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="aslm", description="Ambient-signal load modelling from PMU data.")
    sub = parser.add_subparsers(dest="command", required=True)
    for module in COMMANDS:
        module.add_parser(sub)
    for command in sub.choices.values():  # every command's --help shows its defaults
        command.formatter_class = DefaultsHelpFormatter
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
