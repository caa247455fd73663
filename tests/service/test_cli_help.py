"""Every command's --help tells the defaults a user gets (in-process: argparse only, no service)."""

from __future__ import annotations

import argparse

import pytest

from service.cli import build_parser
from service.commands._common import SETTING_FLAGS
from service.settings import ServiceSettings

PARSER = build_parser()
COMMANDS = PARSER._subparsers._group_actions[0].choices


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_option_with_a_default_shows_it(name):
    command: argparse.ArgumentParser = COMMANDS[name]
    for action in command._actions:
        if (not action.option_strings or action.default is None or action.default is False
                or action.default == argparse.SUPPRESS):
            continue
        formatter = command._get_formatter()  # what --help prints for this option
        formatter.add_argument(action)
        shown = " ".join(formatter.format_help().split())
        assert "default" in shown, f"aslm {name}: {shown!r}"


def test_serve_help_shows_the_settings_defaults_though_its_flags_default_to_none():
    # The flags must stay None (a flag not given leaves the file/environment value alone) ...
    args = PARSER.parse_args(["serve"])
    assert all(getattr(args, field) is None for _, field, _, _ in SETTING_FLAGS)
    # ... and the help still says what T is without them: 15 min surprised a first user.
    text = " ".join(COMMANDS["serve"].format_help().split())
    assert "period T [s] (default: 900.0, unless the settings file or $ASLM_PERIOD_S sets it)" in text
    for _, field, _, _ in SETTING_FLAGS:
        default = ServiceSettings.model_fields[field].default
        assert f"default: {'none' if default is None else default}" in text, field
