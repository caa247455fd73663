"""Records a downstream simulator loads: the inverse map of the transformed motor and record writers.

Pure numerics and text (no I/O, no numba): the service's main process builds records without loading
the identifier's kernels.
"""

from aslm_core.records.export import FORMATS, MEDIA, export
from aslm_core.records.inverse import (
    DEFAULT_XP,
    Assumptions,
    MotorRecord,
    RecordError,
    admissible,
    invert,
    transformed,
)

__all__ = ["DEFAULT_XP", "FORMATS", "MEDIA", "Assumptions", "MotorRecord", "RecordError", "admissible", "export",
           "invert", "transformed"]
