"""Discrepancy diagnosis (DESIGN §3): playback, locate, candidate physics, held-out proof, verdict."""

from aslm_core.diagnosis.pipeline import DiagnosisConfig, diagnose, diagnose_dict
from aslm_core.diagnosis.playback import Playback, playback
from aslm_core.diagnosis.report import DiagnosisReport

__all__ = ["DiagnosisConfig", "DiagnosisReport", "Playback", "diagnose", "diagnose_dict", "playback"]
