"""Settings of the streaming service: one pydantic-settings object.

Precedence (lowest to highest): field defaults < TOML file < ``ASLM_*`` environment < CLI flags
(passed as keyword arguments).  A period changed at run time through ``PUT /config`` is stored in
the results database and applied on top of these at the next start (see :mod:`service.storage`).
"""

from __future__ import annotations

import json
import math
import os
import re
import socket
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, SecretStr, ValidationError, field_validator, model_validator
from pydantic_settings import (
    BaseSettings,
    PydanticBaseSettingsSource,
    SettingsConfigDict,
    TomlConfigSettingsSource,
)

from aslm_core.tracking import TrackerConfig
from service import registry
from service.executors import executor_module
from service.sinks import SINKS
from service.sources import SOURCES

_KEY_CHUNK = re.compile(r"^[A-Za-z0-9_\-.]+(/[A-Za-z0-9_\-.]+)*$")

PERIOD_MAX_S = 86400.0
#: Sources whose frames come from PMUs over a grid protocol: their channels always carry a PMU's noise.
GRID_PROTOCOL_SOURCES = ("c37118", "sttp")
"""Longest period T [s] the service accepts, at start and through ``PUT /config`` (one day)."""

CONFIG_ENV = "ASLM_CONFIG"
"""Environment variable naming the TOML settings file (the ``--config`` flag overrides it)."""


class ServiceSettings(BaseSettings):
    """Everything the service needs to run; every field is also ``ASLM_<NAME>`` in the environment.

    Lists (Zenoh endpoints) are JSON in the environment, e.g.
    ``ASLM_ZENOH_CONNECT='["tcp/zenoh-router:7447"]'``.
    """

    # allow_inf_nan=False: NaN or ±inf in any float setting is refused (an infinite period killed the
    # scheduler thread with OverflowError, issue 17).
    model_config = SettingsConfigDict(env_prefix="ASLM_", extra="forbid", validate_default=True,
                                      allow_inf_nan=False)

    # --- topics and timing -------------------------------------------------------------------
    prefix: str = Field("aslm", description="Zenoh key-expression prefix (aslm/pmu/**, aslm/params/**, ...)")
    pmu_keys: str = Field(
        "**", description="Key expression below {prefix}/pmu/ this instance ingests (shards buses, e.g. 'north/**')",
    )
    period_s: float = Field(900.0, description="Identification period T [s], aligned to the wall clock")
    window_s: float = Field(10.0, description="Identification window length [s]")
    frame_rate: float = Field(50.0, description="Nominal PMU frame rate [frames/s]")
    late_s: float = Field(2.0, description="Late-data allowance [s]: wait after a boundary, accept reordering")
    max_future_s: float = Field(5.0, description="Frames stamped further ahead of this clock are rejected [s]")
    f0: float = Field(50.0, description="Nominal system frequency [Hz]")
    # --- window quality -----------------------------------------------------------------------
    min_coverage: float = Field(0.9, description="Minimum fraction of the window's expected frames present [-]")
    max_gap_s: float = Field(0.2, description="Longest tolerated gap between frames in a window [s]")
    min_v_std: float = Field(1e-5, description="Minimum std of V in a window (excitation) [pu]")
    # --- compute -------------------------------------------------------------------------------
    workers: int = Field(2, description="Local worker processes (spawned)")
    executor: str = Field("local", description="'local' (process pool) or a Dask scheduler address tcp://host:port")
    task_timeout_s: float = Field(60.0, description="Per-window identification timeout [s]")
    n_starts: int = Field(3, description="Random starts of the identifier for a bus without a warm start")
    n_starts_warm: int = Field(
        1, description="Random starts besides the warm start for a bus that has one (its previous successful D): "
                       "a cheaper steady state; n_starts applies to buses without one",
    )
    lowpass_hz: float | None = Field(
        None, description="Fixed causal low-pass of V, θ, P, Q before identification [Hz]; None (default): the "
                          "identifier's own default, which smooths V and θ and low-passes only where their PMU "
                          "noise floor calls for it (IdentifyConfig.input_smoother, docs/numerics.md)",
    )
    objective: Literal["paper", "ml", "ssq"] = Field(
        "paper", description="Identifier objective: 'paper' (eq. 7, (‖r_P‖ + ‖r_Q‖)/l), 'ml' (Gaussian likelihood, "
                             "one noise variance per channel: efficient when P and Q differ in SNR), 'ssq'",
    )
    input_noise: Literal["auto", "measured"] | None = Field(
        None, description="What the PMU channels' noise is taken to be (IdentifyConfig.input_noise): 'measured' reads "
                          "a noise floor that falls towards the Nyquist frequency as a reporting filter's (an M-class "
                          "PMU's) instead of taking V and θ as exact; 'auto' takes such inputs as exact (simulated "
                          "data). Unset (default): 'measured' when a grid-protocol source ('c37118', 'sttp') is "
                          "configured, else 'auto' (docs/numerics.md, \"Stop 55: a PMU's reporting filter\")",
    )
    input_history_windows: int = Field(
        0, description="Noisy V and θ: k > 0 has the identifier's refinement smooth them with their spectrum pooled "
                       "from the k windows just before the one identified, cut from the bus's buffer (which then holds "
                       "k·window_s more), and whiten its fit in the time domain (~0.02 s per window instead of "
                       "~0.008 s); a window whose V and θ depart from that spectrum is identified alone (flag "
                       "input_history_stale); 6 is the measured choice; 0 (default): each window alone, as the CLI and the Python API "
                       "(docs/numerics.md, \"Stop 47\", \"Stop 48\")",
    )
    diagnose_every: int = Field(
        4, description="Discrepancy diagnosis of every identified bus each k-th period (0: off); ~0.7 s of one "
                       "core per bus and diagnosis, queued after the period's identifications: raise k (or 0) "
                       "for large fleets. Models PMU noise on V and θ (docs/diagnosis.md)",
    )
    identify_fn: str = Field(
        "service.worker:identify_window",
        description="module:function run in the workers (a seam for tests and alternative identifiers)",
    )
    # --- inputs and outputs ----------------------------------------------------------------------
    sources: list[str] = Field(
        default_factory=lambda: ["zenoh"],
        description="Sources of PMU frames started by the service (service/sources/): 'zenoh' subscribes to "
                    "{prefix}/pmu/{pmu_keys}; 'zenoh-sharded' only to the buses this instance owns among the "
                    "live instances (docs/cluster.md)",
    )
    pmu_mapping: Path | None = Field(
        None, description="TOML file of the grid-protocol sources ('c37118', 'sttp'): where the stream is and which "
                          "phasors form each bus (docs/protocols.md)",
    )
    sinks: list[str] = Field(
        default_factory=lambda: ["storage", "zenoh"],
        description="Sinks of results, diagnoses and periods (service/sinks/): 'storage' (SQLite history, "
                    "always written first), 'zenoh' ({prefix}/params/{bus}, the latest queryable, liveliness)",
    )
    # --- tracking (the 'tracking' sink) ---------------------------------------------------------
    track_pool_windows: int = Field(
        16, ge=1, description="Longest pool k of the tracked model: the last k windows since the last change",
    )
    track_false_alarms_per_day: float = Field(
        TrackerConfig.false_alarms_per_day, gt=0, description="Change detector's false-alarm rate per bus and day under a stationary load",
    )
    track_joint_fit: bool = Field(
        True, description="Refit the tracked model jointly on its pool's windows (a background worker task per "
                          "bus and period, docs/tracking.md); off: the mean of the windows' estimates",
    )
    track_joint_fit_buses: int = Field(
        1000, ge=0, description="Buses whose pool's windows are kept for the joint fit (the first to be tracked); "
                                "the others keep the mean [buses]",
    )
    # --- storage -------------------------------------------------------------------------------
    storage_url: str = Field("aslm.sqlite", description="SQLite file path or sqlite:///path URL")
    retention_days: float = Field(90.0, description="Results and periods older than this are deleted [days]")
    # --- ingest limits (hostile input) -----------------------------------------------------------
    max_message_bytes: int = Field(
        1 << 20, description="Largest PMU message accepted [bytes]; larger ones are refused (too_large) undecoded",
    )
    max_buses: int = Field(
        100_000, description="Bus buffers kept at most; a new bus beyond it evicts those longest without a valid frame",
    )
    bus_idle_s: float = Field(
        3600.0, description="A bus with no message for this long is forgotten after the next period [s]",
    )
    # --- zenoh ---------------------------------------------------------------------------------
    zenoh_mode: Literal["peer", "client", "router"] = Field("peer", description="Zenoh session mode")
    zenoh_connect: list[str] = Field(default_factory=list, description="Zenoh endpoints to connect to")
    zenoh_listen: list[str] = Field(
        default_factory=lambda: ["tcp/127.0.0.1:7447"],
        description="Zenoh endpoints to listen on (default loopback only; [] in client mode)",
    )
    zenoh_multicast_scouting: bool = Field(False, description="Zenoh multicast scouting (off: explicit endpoints)")
    zenoh_config_file: Path | None = Field(
        None, description="Zenoh JSON5 config (TLS certificates, ...); the fields above override it",
    )
    # --- REST ------------------------------------------------------------------------------------
    http_host: str = Field("127.0.0.1", description="REST bind address")
    http_port: int = Field(8080, description="REST port (0: pick a free one)")
    operator_token: SecretStr | None = Field(
        None, description="Bearer token for mutating endpoints (PUT /config); unset: they are refused",
    )
    instance: str = Field(
        default_factory=lambda: f"{socket.gethostname()}-{os.getpid()}",
        description="Instance name of the liveliness token {prefix}/service/{instance}",
    )

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        # First wins: CLI flags (init kwargs) > environment > TOML file.
        sources: list[PydanticBaseSettingsSource] = [init_settings, env_settings]
        if cls.model_config.get("toml_file"):
            sources.append(TomlConfigSettingsSource(settings_cls))
        return tuple(sources)

    # --- validation ------------------------------------------------------------------------------
    @field_validator("period_s", "window_s", "frame_rate", "task_timeout_s", "f0", "max_gap_s", "retention_days")
    @classmethod
    def _positive(cls, v: float, info) -> float:
        if not v > 0:
            raise ValueError(f"{info.field_name} must be > 0 (got {v})")
        return v

    @field_validator("late_s", "max_future_s", "min_v_std")
    @classmethod
    def _non_negative(cls, v: float, info) -> float:
        if not v >= 0:
            raise ValueError(f"{info.field_name} must be >= 0 (got {v})")
        return v

    @field_validator("max_message_bytes", "max_buses", "bus_idle_s")
    @classmethod
    def _ingest_limit(cls, v: float, info) -> float:
        floor = {"max_message_bytes": 1024, "max_buses": 1, "bus_idle_s": 1.0}[info.field_name]
        if not (v >= floor and math.isfinite(v)):
            raise ValueError(f"{info.field_name} must be a finite number >= {floor:g} (got {v})")
        return v

    @property
    def identify_input_noise(self) -> str:
        """``input_noise`` as the identifier gets it: the setting, or derived from the sources when unset."""
        if self.input_noise is not None:
            return self.input_noise
        return "measured" if any(name in GRID_PROTOCOL_SOURCES for name in self.sources) else "auto"

    @field_validator("lowpass_hz")
    @classmethod
    def _cutoff(cls, v: float | None) -> float | None:
        if v is not None and not v > 0:
            raise ValueError(f"lowpass_hz must be > 0 Hz or null (got {v})")
        return v

    @field_validator("workers", "n_starts", "n_starts_warm", "diagnose_every", "input_history_windows")
    @classmethod
    def _count(cls, v: int, info) -> int:
        if v < (1 if info.field_name in ("workers", "n_starts") else 0):
            raise ValueError(f"{info.field_name} must be a positive count (got {v})")
        return v

    @field_validator("min_coverage")
    @classmethod
    def _fraction(cls, v: float) -> float:
        if not 0.0 < v <= 1.0:
            raise ValueError(f"min_coverage must be in (0, 1] (got {v})")
        return v

    @field_validator("executor")
    @classmethod
    def _executor(cls, v: str) -> str:
        if executor_module(v) is None:
            raise ValueError(f"executor must be 'local' or a Dask scheduler address like tcp://host:8786 (got {v!r})")
        return v

    @field_validator("prefix")
    @classmethod
    def _prefix(cls, v: str) -> str:
        if not _KEY_CHUNK.match(v):
            raise ValueError(f"prefix must be a plain key expression without wildcards (got {v!r})")
        return v

    @field_validator("pmu_keys")
    @classmethod
    def _pmu_keys(cls, v: str) -> str:
        if not v or v.startswith("/") or v.endswith("/") or " " in v:
            raise ValueError(f"pmu_keys must be a relative key expression like '**' or 'north/**' (got {v!r})")
        return v

    @field_validator("http_port")
    @classmethod
    def _port(cls, v: int) -> int:
        if not 0 <= v <= 65535:
            raise ValueError(f"http_port must be in 0..65535 (got {v})")
        return v

    @field_validator("identify_fn")
    @classmethod
    def _fn(cls, v: str) -> str:
        if ":" not in v:
            raise ValueError(f"identify_fn must be 'module:function' (got {v!r})")
        return v

    @field_validator("sources")
    @classmethod
    def _sources(cls, v: list[str]) -> list[str]:
        return registry.check(SOURCES, v, "sources")

    @field_validator("sinks")
    @classmethod
    def _sinks(cls, v: list[str]) -> list[str]:
        return registry.check(SINKS, v, "sinks")

    @field_validator("zenoh_config_file")
    @classmethod
    def _zfile(cls, v: Path | None) -> Path | None:
        if v is not None and not Path(v).is_file():
            raise ValueError(f"zenoh_config_file {v} does not exist")
        return v

    @model_validator(mode="after")
    def _coherent(self) -> ServiceSettings:
        check_period(self.period_s, self)
        if self.window_s * self.frame_rate < 10:
            raise ValueError("window_s * frame_rate gives fewer than 10 frames per window")
        for name in GRID_PROTOCOL_SOURCES:
            if name in self.sources and self.pmu_mapping is None:
                raise ValueError(f"sources has '{name}': pmu_mapping must name the mapping file (docs/protocols.md)")
        return self

    # --- derived -----------------------------------------------------------------------------------
    @property
    def storage_path(self) -> Path:
        """Filesystem path of the SQLite database."""
        url = self.storage_url
        for scheme in ("sqlite:///", "sqlite://"):
            if url.startswith(scheme):
                return Path(url[len(scheme):])
        if "://" in url:
            raise ValueError(f"storage_url {url!r}: only SQLite (a path or sqlite:///path) is supported")
        return Path(url)

    def public_dict(self) -> dict[str, Any]:
        """Settings as JSON-able dict with the operator token masked."""
        out = json.loads(self.model_dump_json())
        out["operator_token"] = "***" if self.operator_token else None
        return out


def check_period(period_s: float, settings: ServiceSettings) -> None:
    """Refuse a period [s] that is not finite, longer than :data:`PERIOD_MAX_S` or shorter than a window
    plus the late-data allowance (start-up settings, ``PUT /config`` and the persisted value alike).

    Raises
    ------
    ValueError
        With a message naming the values involved.
    """
    if not math.isfinite(period_s):
        raise ValueError(f"period_s must be a finite number of seconds (got {period_s})")
    if period_s > PERIOD_MAX_S:
        raise ValueError(f"period_s ({period_s:g} s) must be at most {PERIOD_MAX_S:g} s")
    if period_s < settings.window_s + settings.late_s:
        raise ValueError(
            f"period_s ({period_s:g} s) must be at least window_s + late_s "
            f"({settings.window_s:g} + {settings.late_s:g} s)"
        )


class SettingsError(ValueError):
    """Invalid settings, with a message an operator can act on."""


def load_settings(config_file: str | Path | None = None, **overrides: Any) -> ServiceSettings:
    """Build the settings from a TOML file, the environment and explicit overrides.

    Parameters
    ----------
    config_file : str or Path, optional
        TOML file; default ``$ASLM_CONFIG`` if set.  Its keys are the field names.
    **overrides
        CLI flags; ``None`` values are ignored (flag not given).

    Raises
    ------
    SettingsError
        Missing file or invalid values, one line per problem.
    """
    overrides = {k: v for k, v in overrides.items() if v is not None}
    config_file = config_file or os.environ.get(CONFIG_ENV)
    cls: type[ServiceSettings] = ServiceSettings
    if config_file:
        path = Path(config_file)
        if not path.is_file():
            raise SettingsError(f"settings file {path} does not exist")
        cls = type("ServiceSettingsFromFile", (ServiceSettings,), {
            "model_config": SettingsConfigDict(**{**ServiceSettings.model_config, "toml_file": path}),
        })
    try:
        return cls(**overrides)
    except ValidationError as exc:
        lines = []
        for err in exc.errors():
            where = ".".join(str(p) for p in err["loc"]) or "settings"
            lines.append(f"  {where}: {err['msg']}")
        raise SettingsError("invalid settings:\n" + "\n".join(lines)) from None
