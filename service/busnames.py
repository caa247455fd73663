"""The grammar of bus names, one for every entry: sources, REST paths, storage and publication.

A bus name becomes part of Zenoh keys (``{prefix}/params/{bus}``) and of REST paths, so it must be a
plain key expression that designates exactly one key.  Allowed: one or more chunks separated by ``/``,
each non-empty, of any characters except the key-expression specials ``*``, ``$``, ``?``, ``#`` and
control characters, at most :data:`MAX_BUS_LEN` characters in all.  A name that matched several keys
(``*``, ``**``, ``a/*/b``) would let one publisher's frames come out as results of other buses.
"""

from __future__ import annotations

import re

MAX_BUS_LEN = 128
"""Longest bus name [characters]: room for ``shard/substation/pmu/bus`` paths, bounded for keys and logs."""

_CHUNK = r"[^*$?#/\x00-\x1f\x7f]+"
_NAME = re.compile(rf"{_CHUNK}(?:/{_CHUNK})*")
_SPECIALS = frozenset("*$?#")


def bus_name_problem(name: str) -> str | None:
    """Why ``name`` is not a valid bus name, or None if it is.

    Parameters
    ----------
    name : str
        Candidate bus name (for Zenoh, the key after ``{prefix}/pmu/``).

    Returns
    -------
    str or None
        A one-line explanation for logs and REST errors.
    """
    if not isinstance(name, str) or not name:
        return "bus name is empty"
    if len(name) > MAX_BUS_LEN:
        return f"bus name longer than {MAX_BUS_LEN} characters ({len(name)})"
    if _NAME.fullmatch(name):
        return None
    if _SPECIALS.intersection(name):
        return f"bus name {name[:40]!r} holds a key-expression character (* $ ? #)"
    if any(ord(c) < 0x20 or ord(c) == 0x7F for c in name):
        return f"bus name {name[:40]!r} holds a control character"
    return f"bus name {name[:40]!r} has an empty chunk (leading, trailing or doubled '/')"


def check_bus_name(name: str) -> str:
    """``name`` if it is a valid bus name.

    Raises
    ------
    ValueError
        With :func:`bus_name_problem`'s explanation.
    """
    problem = bus_name_problem(name)
    if problem is not None:
        raise ValueError(problem)
    return name
