"""A bus's recent windows as the spectrum of its inputs: what one 10 s window cannot estimate.

The S-weighted refinement smooths V and θ with a Wiener smoother whose signal spectrum one window reads only
down to its white PMU floor; the average of K windows' periodograms has √K less scatter and resolves the
signal beneath it (docs/numerics.md, "Stop 32: the inputs' spectrum from the bus's previous windows").  A
caller that sees a bus window after window (the service's scheduler) keeps an :class:`InputHistory` per bus
and hands :meth:`InputHistory.spectrum` to :func:`aslm_core.identify`.  The evidence for it is on stationary
buses over one to five minutes, so the history holds only windows that do not overlap and that began at most
``max_age_s`` before the window identified, and gives a spectrum only when it holds ``k`` of them.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from aslm_core.noise import (
    FLOOR_FROM_HZ,
    InputPeriodogram,
    InputSpectrum,
    poolable,
    pooled_spectrum,
    spectrum_at,
)

#: Windows pooled into the inputs' spectrum (a minute of 10 s windows: the development runs' K = 6) [-].
HISTORY_WINDOWS = 6
#: Oldest start of a pooled window before the start of the window identified [s] (the runs' five minutes).
HISTORY_MAX_AGE_S = 300.0
#: Width of the moving average across frequency over the pooled periodograms [Hz]: none, since the refinement given
#: a history drops its residual floor (:data:`aslm_core.input_weighting.HISTORY_BAND_HZ`) and needs the spectrum's
#: fine structure (docs/numerics.md, "Stop 47").
HISTORY_SMOOTH_HZ = 0.0
#: Largest :func:`staleness` of a window against its history's spectrum for the history to be used: above it the
#: minute before describes another load or network, and a history from another one is worse than none
#: (docs/numerics.md, "Stop 48") [-].
HISTORY_STALE_MAX = 3.0
#: Width of the bands :func:`staleness` compares [Hz].
STALE_BAND_HZ = 0.5


class InputHistory:
    """The input periodograms of a bus's last non-overlapping windows, oldest first.

    Parameters
    ----------
    k : int
        Windows pooled; :meth:`spectrum` gives one only when this many are usable.
    max_age_s : float
        A held window that began more than this before the window to identify is not used [s].
    """

    def __init__(self, k: int = HISTORY_WINDOWS, max_age_s: float = HISTORY_MAX_AGE_S) -> None:
        if k < 1:
            raise ValueError(f"k must be at least 1, got {k}")
        self.k = k
        self.max_age_s = max_age_s
        self._held: deque[tuple[float, float, InputPeriodogram, int]] = deque(maxlen=k)
        self._added = 0  # windows kept so far: numbers them, so the cache knows which ones it pooled
        self._cached: tuple[tuple[int, ...], InputSpectrum] | None = None

    def __len__(self) -> int:
        return len(self._held)

    def add(self, start: float, end: float, periodogram: InputPeriodogram) -> bool:
        """Keep a window's periodogram (:func:`aslm_core.preprocess.input_periodogram`).

        Parameters
        ----------
        start, end : float
            Times of the window's first and last samples [s].
        periodogram : InputPeriodogram

        Returns
        -------
        bool
            Whether it was kept: a window that overlaps (or precedes) the newest held one is not, since
            overlapping windows share their noise and would count it twice; one at another sample rate or bin
            spacing restarts the history.
        """
        if self._held:
            _, e0, g0, _ = self._held[-1]
            if not poolable(periodogram, g0):
                self._held.clear()
            elif start <= e0:
                return False
        self._added += 1
        self._held.append((float(start), float(end), periodogram, self._added))
        return True

    def spectrum(self, start: float) -> InputSpectrum | None:
        """The inputs' spectrum pooled for a window beginning at ``start`` [s], or None.

        Parameters
        ----------
        start : float
            Time of the first sample of the window to identify [s].

        Returns
        -------
        InputSpectrum or None
            :func:`aslm_core.noise.pooled_spectrum` of the held windows that ended before ``start`` and began
            at most ``max_age_s`` before it, not smoothed across frequency (:data:`HISTORY_SMOOTH_HZ`); None unless
            there are ``k`` of them.
        """
        usable = [h for h in self._held if h[1] < start and h[0] >= start - self.max_age_s]
        if len(usable) < self.k:
            return None
        key = tuple(h[3] for h in usable)
        if self._cached is None or self._cached[0] != key:
            self._cached = (key, pooled_spectrum([h[2] for h in usable], smooth_hz=HISTORY_SMOOTH_HZ))
        return self._cached[1]


def staleness(periodogram: InputPeriodogram, spectrum: InputSpectrum) -> float:
    """How far a window's inputs depart from its history's spectrum, per degree of freedom (about 1 when they agree).

    Parameters
    ----------
    periodogram : InputPeriodogram
        The window's own (:func:`aslm_core.noise.input_periodogram` of its V [pu] and θ [rad]).
    spectrum : InputSpectrum
        The history's signal spectrum (:meth:`InputHistory.spectrum`).

    Returns
    -------
    float
        Per channel and band of :data:`STALE_BAND_HZ` from the first bin to 5 Hz, r = the window's periodogram over
        the history's signal spectrum plus the window's own white floor, each averaged over the band's m bins; the
        deviance Σ 2m·(r − 1 − log r) of these χ²(2m)/(2m) ratios over the number of terms [-].
    """
    f = periodogram.freqs
    model = spectrum_at(spectrum, f)
    sel = (f > 0) & (f < FLOOR_FROM_HZ)
    if not np.any(sel):
        return math.nan
    band = np.floor((f[sel] - f[sel][0]) / STALE_BAND_HZ).astype(int)
    dev, terms = 0.0, 0
    for c in range(min(periodogram.p.shape[1], model.shape[1])):
        obs = periodogram.p[sel, c, c].real
        exp = model[sel, c, c].real + periodogram.floor[c]
        for b in np.unique(band):
            m = int(np.sum(band == b))
            r = max(float(obs[band == b].mean() / exp[band == b].mean()), 1e-12)  # a dead channel: far off
            dev += 2 * m * (r - 1.0 - math.log(r))
            terms += 1
    return dev / terms
