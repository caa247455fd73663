"""ASLM numerics: hierarchical ambient-signal identification of ZIP + induction-motor loads.

Pure numerics (numpy, scipy, numba): no I/O and no service imports.

The public names are re-exported lazily (PEP 562): ``import aslm_core.params`` or ``aslm_core.window``
loads numpy only, so the service can use the parameter and window declarations without compiling or
loading numba; the identifier's modules load on first use of a name that needs them.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import Any

#: Public name → module that defines it.
_EXPORTS: dict[str, str] = {
    "IdentificationResult": "aslm_core.result",
    "IdentifyConfig": "aslm_core.result",
    "NoEquilibriumError": "aslm_core.errors",
    "Window": "aslm_core.window",
    "WindowError": "aslm_core.errors",
    "identify": "aslm_core.identify",
    "identify_many": "aslm_core.batch",
    "warmup": "aslm_core.identify",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        # AttributeError (not ImportError) lets ``from aslm_core import motor`` fall back to the submodule.
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later lookups are plain attribute hits
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _Package(types.ModuleType):
    """The package module, keeping ``aslm_core.identify`` the function.

    Why: importing the submodule ``aslm_core.identify`` (as ``aslm_core.diagnosis`` does) makes the
    import system set the package attribute ``identify`` to that module.  The eager re-export used
    to overwrite it with the function; lazily, that attribute write has to be refused instead.
    """

    def __setattr__(self, name: str, value: Any) -> None:
        if isinstance(value, types.ModuleType) and _EXPORTS.get(name) == value.__name__:
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
