"""Reading PMU recordings (.npz, .csv) into :class:`aslm_core.Window`."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from aslm_core.window import Window

REQUIRED = ("t", "V", "theta", "P", "Q")


def read_window(path: str | Path, f0: float | None = None) -> Window:
    """Load one recording.

    Parameters
    ----------
    path : str or Path
        ``.npz`` with arrays ``t`` [s], ``V`` [pu], ``theta`` [rad], ``P``, ``Q`` [pu], optional ``f`` [Hz]
        and scalar ``f0`` [Hz]; or ``.csv`` with those column names.
    f0 : float, optional
        Nominal frequency [Hz]; overrides the file's, default 50 Hz when neither gives it.

    Raises
    ------
    ValueError
        Unknown extension or a missing column, with the file named.
    """
    path = Path(path)
    suffix = path.suffix.lower()
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
        raise ValueError(f"{path}: unsupported file type {suffix!r} (use .npz or .csv)")
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
