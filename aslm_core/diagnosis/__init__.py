"""Discrepancy diagnosis (DESIGN §3): playback, locate, candidate physics, held-out proof, verdict."""

from aslm_core.diagnosis.pipeline import DiagnosisConfig, DiagnosisReport, diagnose, diagnose_dict
from aslm_core.diagnosis.playback import Playback, playback

__all__ = ["DiagnosisConfig", "DiagnosisReport", "Playback", "diagnose", "diagnose_dict", "playback"]
