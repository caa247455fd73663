"""A measurement window of one bus: uniformly sampled V, θ, P, Q (and optional f)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Every channel a window can hold, in the one order used end to end (ring-buffer rows, the binary
#: frame layout): time [s], voltage magnitude [pu], angle [rad], active and reactive power [pu],
#: bus frequency [Hz].
CHANNELS: tuple[str, ...] = ("t", "V", "theta", "P", "Q", "f")
#: The channels every window has (the bus frequency is optional).
REQUIRED: tuple[str, ...] = CHANNELS[:5]
#: The sampled signals that are conditioned together before identification (time and f aside).
SIGNALS: tuple[str, ...] = CHANNELS[1:5]

_F64 = np.dtype(np.float64)


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
        # Float64 arrays are kept as they are, without a call to np.asarray per channel.  Writing
        # __dict__ is how a frozen dataclass converts its own fields.
        d = self.__dict__
        for name in CHANNELS:
            x = d[name]
            if x.__class__ is not np.ndarray or x.dtype is not _F64:
                if x is None and name == "f":
                    continue
                d[name] = np.asarray(x, dtype=np.float64)

    @classmethod
    def from_rows(cls, rows: np.ndarray, *, with_f: bool, f0: float = 50.0, bus: str = "") -> Window:
        """A window whose channels are the rows of one float64 array, in :data:`CHANNELS` order.

        Parameters
        ----------
        rows : ndarray of float64, shape (5, n) or (6, n)
            t [s], V [pu], θ [rad], P [pu], Q [pu] and, if ``with_f``, f [Hz].  The channels are
            views of these rows (no copy).
        with_f : bool
            Row 5 is the bus frequency; otherwise ``f`` is None.
        f0 : float
            Nominal system frequency [Hz].
        bus : str
            Identifier of the bus.

        Returns
        -------
        Window

        Notes
        -----
        Equal to ``Window(*rows[:5], f=...)``, built without ``__init__``: the service cuts one
        window per bus per period on its scheduling thread, where the dataclass's frozen ``__init__``
        and conversions are a per-bus cost (docs/service.md, "One window type").
        """
        if rows.__class__ is not np.ndarray or rows.dtype is not _F64:
            rows = np.asarray(rows, dtype=np.float64)
        window = object.__new__(cls)
        # Spelled out rather than zipped with CHANNELS: 0.2 µs less; tests/aslm_core/test_public_api.py checks both agree.
        window.__dict__.update(t=rows[0], V=rows[1], theta=rows[2], P=rows[3], Q=rows[4],
                               f=rows[5] if with_f else None, f0=f0, bus=bus, meta={})
        return window

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
