"""ASLM numerics: hierarchical ambient-signal identification of ZIP + induction-motor loads.

Pure numerics (numpy, scipy, numba): no I/O and no service imports.
"""

from aslm_core.errors import NoEquilibriumError, WindowError
from aslm_core.identify import identify, identify_many, warmup
from aslm_core.result import IdentificationResult, IdentifyConfig
from aslm_core.window import Window

__all__ = [
    "IdentificationResult",
    "IdentifyConfig",
    "NoEquilibriumError",
    "Window",
    "WindowError",
    "identify",
    "identify_many",
    "warmup",
]
