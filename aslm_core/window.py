"""A measurement window of one bus: uniformly sampled V, θ, P, Q (and optional f)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Window:
    """PMU measurements of one load bus over one identification window.

    Attributes
    ----------
    t : ndarray
        Sample times [s] (any origin; seconds since epoch for live data).
    V : ndarray
        Voltage magnitude [pu].
    theta : ndarray
        Voltage angle [rad]; unwrapped before use.
    P, Q : ndarray
        Active and reactive power drawn by the load [pu on the stated base].
    f : ndarray or None
        Measured bus frequency [Hz], if the PMU reports it.
    f0 : float
        Nominal system frequency [Hz] (50 or 60).
    bus : str
        Identifier of the bus, for messages.
    """

    t: np.ndarray
    V: np.ndarray
    theta: np.ndarray
    P: np.ndarray
    Q: np.ndarray
    f: np.ndarray | None = None
    f0: float = 50.0
    bus: str = ""
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        for name in ("t", "V", "theta", "P", "Q"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=np.float64))
        if self.f is not None:
            object.__setattr__(self, "f", np.asarray(self.f, dtype=np.float64))

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.t.shape[0])

    @property
    def dt(self) -> float:
        """Median sample step [s]."""
        return float(np.median(np.diff(self.t))) if self.n > 1 else float("nan")

    @property
    def duration(self) -> float:
        """Time span covered [s]."""
        return float(self.t[-1] - self.t[0]) if self.n > 1 else 0.0
