"""COMTRADE recordings (IEEE C37.111 1999 and 2013; ASCII, binary, binary32, float32; ``.cfg``+``.dat`` or
``.cff``) to a load bus's :class:`~aslm_core.window.Window`, through the same mapping as the C37.118 bridge.

The ``comtrade`` package parses the files.  A name in the mapping is either

- an analog channel holding a waveform (instantaneous volts or amperes, line-to-neutral for voltages):
  its RMS phasor is estimated by a one-cycle DFT at the nominal frequency,
  ``X(t) = √2/N · Σ x(t_k)·e^{-jω₀t_k}`` over the N samples of the cycle ending at t, reported at
  ``rate`` frames/s; the angle is referred to UTC through t_k, as a PMU's is; or
- a phasor recorded by a PMU or PDC export: two analog channels ``NAME_mag`` (RMS) and ``NAME_ang``
  (degrees), used sample by sample.

Channel values are the file's a·x + b in the unit the file states (a ``k`` prefix is scaled away);
secondary values (``S``) are brought to primary with the channel's ratio.
"""

from __future__ import annotations

import datetime as dt
import warnings
from pathlib import Path

import numpy as np

from aslm_core.window import Window
from service.protocols.mapping import BusMap, bus_batch


class ComtradeReadError(ValueError):
    """A COMTRADE file the mapping cannot be applied to (names the channels it has)."""


def load(path: str | Path):
    """Parse a ``.cfg`` (its ``.dat`` beside it) or a ``.cff`` with the ``comtrade`` package."""
    import comtrade

    path = Path(path)
    rec = comtrade.Comtrade(ignore_warnings=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if path.suffix.lower() == ".cff":
            rec.load(str(path))
        else:
            dat = next((path.with_suffix(s) for s in (".dat", ".DAT") if path.with_suffix(s).is_file()), None)
            if dat is None:
                raise ComtradeReadError(f"{path}: no .dat beside the .cfg")
            rec.load(str(path), str(dat))
    return rec


def _channels(rec) -> dict[str, np.ndarray]:
    out = {}
    for ch, values in zip(rec.cfg.analog_channels, rec.analog, strict=True):
        x = np.asarray(values, dtype=np.float64)
        unit = (ch.uu or "").strip()
        if unit[:1] == "k" and len(unit) > 1:
            x = x * 1e3
        if (ch.pors or "P").upper() == "S" and ch.secondary:
            x = x * (ch.primary / ch.secondary)
        out[ch.name.strip()] = x
    return out


def _start(rec) -> float:
    start = rec.start_timestamp
    if start.tzinfo is None:
        start = start.replace(tzinfo=dt.timezone.utc)  # COMTRADE times are local to the recorder; UTC assumed
    return start.timestamp()


def dft_phasors(x: np.ndarray, t: np.ndarray, f0: float, step: int) -> tuple[np.ndarray, np.ndarray]:
    """One-cycle DFT phasors of a waveform every ``step`` samples.

    Parameters
    ----------
    x : ndarray
        Samples [V or A].
    t : ndarray
        Sample times [s] (uniform) from a whole UTC second: for a 50 or 60 Hz nominal (whole cycles per
        second) the angles are then UTC's, without the 1e-4 rad rounding of 2π·f0·t at t ~ 1.7e9 s.
    f0 : float
        Nominal frequency [Hz].
    step : int
        Samples between reported phasors.

    Returns
    -------
    t_out, X : ndarray
        Time of the last sample of each cycle (same origin as ``t``) [s] and the RMS phasor there.
    """
    fs = 1.0 / np.median(np.diff(t))
    n = int(round(fs / f0))
    if n < 4 or x.size < n:
        raise ComtradeReadError(f"{fs:g} samples/s gives {n} per cycle at {f0:g} Hz: too few for a phasor")
    z = x * np.exp(-2j * np.pi * f0 * t)
    c = np.concatenate([[0.0], np.cumsum(z)])
    ends = np.arange(n, x.size + 1, step)
    return t[ends - 1], np.sqrt(2.0) / n * (c[ends] - c[ends - n])


def _phasor(name: str, ch: dict[str, np.ndarray], t: np.ndarray, f0: float, step: int):
    if f"{name}_mag" in ch and f"{name}_ang" in ch:
        return t, ch[f"{name}_mag"] * np.exp(1j * np.deg2rad(ch[f"{name}_ang"]))
    if name in ch:
        return dft_phasors(ch[name], t, f0, step)
    raise ComtradeReadError(f"no channel {name!r} (nor {name}_mag/{name}_ang); the file has {', '.join(ch)}")


def comtrade_window(path: str | Path, bus: BusMap, *, f0: float | None = None, rate: float | None = None) -> Window:
    """The load bus ``bus`` of a COMTRADE recording as a window.

    Parameters
    ----------
    path : str or Path
        ``.cfg`` (with its ``.dat``) or ``.cff``.
    bus : BusMap
        Which channels form the bus (``pmu`` is not used: one file is one recorder).
    f0 : float, optional
        Nominal frequency [Hz] (default the file's line frequency).
    rate : float, optional
        Phasors per second from waveforms (default f0: one per cycle).
    """
    rec = load(path)
    f0 = float(f0 or rec.frequency or 50.0)
    ch = _channels(rec)
    start = _start(rec)
    second = float(np.floor(start))
    t = (start - second) + np.asarray(rec.time, dtype=np.float64)  # from a whole second, see dft_phasors
    fs = 1.0 / np.median(np.diff(t))
    step = max(1, int(round(fs / (rate or f0))))
    names = [*bus.voltage, *(n for fd in bus.feeders for n in fd.phasors)]
    phasors = {n: _phasor(n, ch, t, f0, step) for n in names}
    t_out = phasors[names[0]][0]
    if any(p[0].shape != t_out.shape for p in phasors.values()):
        raise ComtradeReadError(f"{path}: mixing waveform and phasor channels in one bus is not supported")

    def stack(group):
        cols = [phasors[n][1] for n in group]
        return cols[0] if len(cols) == 1 else np.stack(cols, axis=1)

    batch = bus_batch(bus, second + t_out, stack(bus.voltage), [stack(fd.phasors) for fd in bus.feeders], None, None)
    return Window(t=batch.t, V=batch.V, theta=batch.theta, P=batch.P, Q=batch.Q, f=None, f0=f0, bus=bus.bus)
