"""Playback: drive a composite-load model with measured V and θ and form the P and Q residuals."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aslm_core import motor, static
from aslm_core.params import DYNAMIC_NAMES
from aslm_core.preprocess import prepare
from aslm_core.window import Window


@dataclass
class Playback:
    """Model output against the measurements on the window's grid.

    Attributes
    ----------
    t : ndarray
        Sample times [s].
    P, Q : ndarray
        Measured powers [pu].
    P_model, Q_model : ndarray
        Model powers (motor eq. 4–5 plus static eq. 6) [pu].
    rp, rq : ndarray
        Residuals measured − model [pu].
    """

    t: np.ndarray
    P: np.ndarray
    Q: np.ndarray
    P_model: np.ndarray
    Q_model: np.ndarray

    @property
    def rp(self) -> np.ndarray:
        return self.P - self.P_model

    @property
    def rq(self) -> np.ndarray:
        return self.Q - self.Q_model


def model_dict(model) -> dict:
    """A model as ``{"dynamic": {a, b, H2, Tm}, "static": {...}}`` from a dict or an IdentificationResult."""
    if hasattr(model, "dynamic") and hasattr(model, "static"):
        return {"dynamic": dict(model.dynamic), "static": dict(model.static)}
    if not isinstance(model, dict) or "dynamic" not in model or "static" not in model:
        raise ValueError("a model needs 'dynamic' {a, b, H2, Tm} and 'static' (ZIP or exponential) entries")
    missing = [k for k in DYNAMIC_NAMES if k not in model["dynamic"]]
    if missing:
        raise ValueError(f"model 'dynamic' lacks {', '.join(missing)}")
    return {"dynamic": {k: float(model["dynamic"][k]) for k in DYNAMIC_NAMES},
            "static": {k: float(v) for k, v in model["static"].items()}}


def model_power(V: np.ndarray, theta: np.ndarray, model: dict, dt: float, f0: float) -> tuple[np.ndarray, np.ndarray]:
    """P and Q [pu] of a ZIP (or exponential) + transformed-IM model driven by V [pu], θ [rad].

    Parameters
    ----------
    V, theta : ndarray
        Voltage magnitude [pu] and unwrapped angle [rad] on a uniform grid.
    model : dict
        ``{"dynamic": {a [1/s], b [1/s], H2 [s], Tm [pu]}, "static": ZIP {Pz, Pi, Pp, Qz, Qi, Qp} or
        exponential {P0, np, Q0, nq}}`` — the identifier's convention: Qz includes the motor's V²/X'.
    dt : float
        Sample step [s].
    f0 : float
        Nominal frequency [Hz].
    """
    m = model_dict(model)
    d = np.array([m["dynamic"][k] for k in DYNAMIC_NAMES])
    p_im, q_im, _ = motor.simulate(V, theta, d, dt, motor.omega0_of(f0))
    p_st, q_st = static.static_power(V, m["static"])
    return p_im + p_st, q_im + q_st


def playback(window: Window, model) -> Playback:
    """Play a model back on a window's measured V and θ.

    Parameters
    ----------
    window : Window
    model : dict or IdentificationResult
        See :func:`model_power`.

    Returns
    -------
    Playback
    """
    prep = prepare(window)
    p, q = model_power(prep.V, prep.theta, model, prep.dt, window.f0)
    return Playback(prep.t, prep.P, prep.Q, p, q)
