"""Records a downstream simulator loads: the inverse map of the transformed motor and record writers."""

from aslm_core.records.inverse import DEFAULT_XP, Assumptions, MotorRecord, RecordError, admissible, invert, transformed

__all__ = ["DEFAULT_XP", "Assumptions", "MotorRecord", "RecordError", "admissible", "invert", "transformed"]
