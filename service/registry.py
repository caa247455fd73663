"""Name → ``module:factory`` registries (sources, sinks): resolved lazily, checked by the settings.

The factories are imported only when a service builds what they make, so a component's optional
dependencies are needed only where it is used, and the settings check names without importing any.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable


def check(registry: dict[str, str], names: list[str], what: str) -> list[str]:
    """Refuse unknown or repeated names.

    Parameters
    ----------
    registry : dict
        name → ``module:factory``.
    names : list of str
    what : str
        What the names are, for the message (e.g. ``sources``).

    Raises
    ------
    ValueError
        Naming the unknown or repeated names and the known ones.
    """
    unknown = [n for n in names if n not in registry]
    if unknown:
        raise ValueError(f"unknown {what} {unknown}; known: {sorted(registry)}")
    if len(set(names)) != len(names):
        raise ValueError(f"{what} repeated: {names}")
    return names


def load(registry: dict[str, str], name: str) -> Callable:
    """Import the factory registered as ``name`` (``module:function``).

    Raises
    ------
    ValueError
        ``name`` is not registered.
    """
    check(registry, [name], "name")
    module, _, attr = registry[name].partition(":")
    return getattr(importlib.import_module(module), attr)
