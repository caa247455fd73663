"""Data objects shared by storage, publication and the REST API (pydantic, so they document OpenAPI)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from aslm_core.params import DYNAMIC_PARAMS, EXPONENTIAL_PARAMS, ZIP_PARAMS, ParamSpec

Status = Literal["ok", "failed", "skipped"]


def _listed(params: tuple[ParamSpec, ...]) -> str:
    """``{a [1/s], b [1/s], ...}``: names and units as :mod:`aslm_core.params` declares them."""
    return "{" + ", ".join(f"{p.name} [{p.unit}]" for p in params) + "}"


class Identified(BaseModel):
    """Output of :func:`aslm_core.identify` for one window (``IdentificationResult.to_dict()``)."""

    model_config = ConfigDict(extra="allow")

    dynamic: dict[str, float] = Field(description=f"D = {_listed(DYNAMIC_PARAMS)}")
    static: dict[str, float] = Field(
        description=f"ZIP {_listed(ZIP_PARAMS)} or exponential {_listed(EXPONENTIAL_PARAMS)}")
    objective: float | None = Field(description="Objective value at the optimum")
    fit: dict[str, float | None] = Field(description="Fit degree of P and Q (paper eq. 9): {fd_p, fd_q}")
    stderr: dict[str, float | None] = Field(default_factory=dict, description="Standard errors of D (null: not available)")
    quality: dict[str, float | None] = Field(default_factory=dict, description="SNR [dB], excitation, margins")
    flags: list[str] = Field(default_factory=list, description="Quality flags, e.g. at_bound:H2")
    elapsed_s: float = Field(0.0, description="Identification time in the worker [s]")


class BusResult(BaseModel):
    """One bus, one period: identified parameters, or why there are none."""

    bus: str = Field(description="Bus identifier (the {bus} of {prefix}/pmu/{bus})")
    period: float = Field(description="Period boundary, UTC since the epoch [s]")
    period_s: float = Field(description="Period length T in force for this period [s]")
    status: Status = Field(description="ok, failed (worker error/timeout/crash) or skipped (window quality)")
    reason: str | None = Field(None, description="Why failed or skipped, e.g. coverage, timeout, worker_crashed")
    window_start: float | None = Field(None, description="PMU time of the window's first frame [s]")
    window_end: float | None = Field(None, description="PMU time of the window's last frame [s]")
    n_frames: int = Field(0, description="Frames in the window")
    warm_start: bool = Field(False, description="Started from the bus's previous result")
    completed_at: float = Field(description="Wall-clock time the result was recorded [s]")
    parameters: Identified | None = Field(None, description="Identification output when status is ok")


class PeriodSummary(BaseModel):
    """One completed period."""

    period: float = Field(description="Boundary, UTC since the epoch [s]")
    period_s: float = Field(description="Period length T [s]")
    n_ok: int
    n_failed: int
    n_skipped: int
    latency_s: float = Field(description="From the end of the late-data allowance to the last result published [s]")
    completed_at: float
