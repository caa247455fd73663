"""The windows of each bus's tracked pool, kept compactly for the joint pooled fit (docs/tracking.md).

The joint fit (:func:`aslm_core.pooled.identify_pooled`) re-simulates every pooled window at each of its
iterations, so it needs the windows' samples, not a summary of them; the scheduler forgets a window once it
is identified and a worker is not sticky per bus, so the tracking sink keeps them here, in the scheduler
process.  A window is stored as one float32 array (t as offsets from its first sample, θ minus its first
sample, so that float32 keeps µs and nrad resolution): 6 channels × 4 B per sample, 12 kB for a 10 s
window at 50 frames/s.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from aslm_core.window import Window


@dataclass(frozen=True)
class CompactWindow:
    """One window in float32 (what the joint fit's task carries to the worker).

    Attributes
    ----------
    rows : ndarray of float32, shape (5, n) or (6, n)
        t − t0 [s], V [pu], θ − θ0 [rad], P, Q [pu] and, if present, f [Hz].
    t0 : float
        Time of the first sample [s].
    theta0 : float
        Angle of the first sample [rad].
    f0 : float
        Nominal frequency [Hz].
    bus : str
    """

    rows: np.ndarray
    t0: float
    theta0: float
    f0: float
    bus: str

    @classmethod
    def of(cls, window: Window, bus: str | None = None) -> CompactWindow:
        """The compact copy of ``window`` (named ``bus`` if given, else the window's own bus)."""
        t0, theta0 = float(window.t[0]), float(window.theta[0])
        channels = [window.t - t0, window.V, window.theta - theta0, window.P, window.Q]
        if window.f is not None:
            channels.append(window.f)
        return cls(np.array(channels, dtype=np.float32), t0, theta0, float(window.f0),
                   window.bus if bus is None else bus)

    def window(self) -> Window:
        """The window back in float64 (equal to the original up to float32 rounding)."""
        rows = self.rows.astype(np.float64)
        rows[0] += self.t0
        rows[2] += self.theta0
        return Window.from_rows(rows, with_f=rows.shape[0] == 6, f0=self.f0, bus=self.bus)

    @property
    def nbytes(self) -> int:
        """Bytes of its samples."""
        return int(self.rows.nbytes)


class WindowRing:
    """One bus's compact windows by period [s], oldest first: the tracker's pool and its held suspect.

    Parameters
    ----------
    bus : str
        The bus the windows are named after (the joint fit's task reports under it).
    """

    def __init__(self, bus: str) -> None:
        self.bus = bus
        self.windows: dict[float, CompactWindow] = {}

    def add(self, period: float, window: Window) -> None:
        """Keep ``window`` as the window of ``period`` [s]."""
        self.windows[period] = CompactWindow.of(window, self.bus)

    def keep(self, periods: Iterable[float]) -> None:
        """Drop every window whose period is not in ``periods``."""
        wanted = set(periods)
        for p in [p for p in self.windows if p not in wanted]:
            del self.windows[p]

    def covers(self, periods: Iterable[float]) -> bool:
        """Whether the ring holds the window of every period in ``periods``."""
        return all(p in self.windows for p in periods)

    def get(self, periods: Iterable[float]) -> list[CompactWindow]:
        """The windows of ``periods``, in that order."""
        return [self.windows[p] for p in periods]

    def __len__(self) -> int:
        return len(self.windows)

    @property
    def nbytes(self) -> int:
        """Bytes of the samples held."""
        return sum(w.nbytes for w in self.windows.values())
