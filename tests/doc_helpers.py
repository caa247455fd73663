"""Shared by the public-surface tests: which arguments a function's docstring leaves undocumented."""

from __future__ import annotations

import inspect


def undocumented(func) -> list[str]:
    """Arguments of func not named in its docstring as ``name :`` or ``name, `` (numpy style)."""
    doc = inspect.getdoc(func) or ""
    params = [p for p in inspect.signature(func).parameters if p not in ("self", "cls")]
    return [p for p in params if f"{p} :" not in doc and f"{p}, " not in doc]
