"""Reading PMU recordings (.npz, .csv; COMTRADE through a bus mapping) into :class:`aslm_core.Window`."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from aslm_core.window import Window

REQUIRED = ("t", "V", "theta", "P", "Q")


COMTRADE_SUFFIXES = (".cfg", ".cff")


def read_window(path: str | Path, f0: float | None = None, mapping: str | Path | None = None,
                bus: str | None = None) -> Window:
    """Load one recording.

    Parameters
    ----------
    path : str or Path
        ``.npz`` with arrays ``t`` [s], ``V`` [pu], ``theta`` [rad], ``P``, ``Q`` [pu], optional ``f`` [Hz]
        and scalar ``f0`` [Hz]; or ``.csv`` with those column names; or COMTRADE (``.cfg``/``.cff``),
        which needs ``mapping``.
    f0 : float, optional
        Nominal frequency [Hz]; overrides the file's, default 50 Hz when neither gives it.
    mapping : str or Path, optional
        TOML bus mapping (docs/protocols.md) saying which COMTRADE channels form the bus.
    bus : str, optional
        The mapping's bus to read (default its first).

    Raises
    ------
    ValueError
        Unknown extension or a missing column, with the file named.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in COMTRADE_SUFFIXES:
        return _read_comtrade(path, f0, mapping, bus)
    if suffix == ".npz":
        with np.load(path, allow_pickle=False) as z:
            cols = {k: np.asarray(z[k]) for k in z.files}
    elif suffix == ".csv":
        with path.open(newline="") as fh:
            reader = csv.DictReader(fh)
            rows = list(reader)
            names = reader.fieldnames or []
        cols = {k.strip(): np.array([float(r[k]) for r in rows]) for k in names}
    else:
        raise ValueError(f"{path}: unsupported file type {suffix!r} (use .npz, .csv, or COMTRADE .cfg/.cff)")
    missing = [k for k in REQUIRED if k not in cols]
    if missing:
        raise ValueError(f"{path}: missing column(s) {', '.join(missing)}; need {', '.join(REQUIRED)}")
    file_f0 = cols.get("f0")
    if f0 is None:
        f0 = float(np.ravel(file_f0)[0]) if file_f0 is not None else 50.0
    f = cols.get("f")
    return Window(
        t=cols["t"], V=cols["V"], theta=cols["theta"], P=cols["P"], Q=cols["Q"],
        f=None if f is None or np.ndim(f) == 0 else f, f0=f0, bus=path.stem,
    )


def read_windows(path: str | Path, f0: float | None = None, mapping: str | Path | None = None) -> list[Window]:
    """Every bus of one recording: all the mapping's buses of a COMTRADE file, else :func:`read_window`."""
    if Path(path).suffix.lower() not in COMTRADE_SUFFIXES:
        return [read_window(path, f0)]
    from service.readers.comtrade import comtrade_window

    return [comtrade_window(path, b, f0=f0) for b in _mapped_buses(path, mapping)]


def _mapped_buses(path: Path, mapping: str | Path | None):
    from service.protocols.mapping import load_mapping

    if mapping is None:
        raise ValueError(f"{path}: a COMTRADE file needs --mapping (which channels form the load bus)")
    return load_mapping(mapping).buses


def _read_comtrade(path: Path, f0: float | None, mapping: str | Path | None, bus: str | None) -> Window:
    from service.readers.comtrade import comtrade_window

    buses = _mapped_buses(path, mapping)
    chosen = buses[0] if bus is None else next((b for b in buses if b.bus == bus), None)
    if chosen is None:
        raise ValueError(f"{mapping}: no bus {bus!r}; it has {', '.join(b.bus for b in buses)}")
    return comtrade_window(path, chosen, f0=f0)


def write_window(path: str | Path, window: Window) -> None:
    """Write a window as ``.npz`` (or ``.csv`` by extension) in the format :func:`read_window` reads."""
    path = Path(path)
    cols = {"t": window.t, "V": window.V, "theta": window.theta, "P": window.P, "Q": window.Q}
    if window.f is not None:
        cols["f"] = window.f
    if path.suffix.lower() == ".csv":
        names = list(cols)
        with path.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(names)
            w.writerows(zip(*(np.asarray(cols[k]) for k in names), strict=True))
    else:
        np.savez(path, f0=np.float64(window.f0), **cols)
