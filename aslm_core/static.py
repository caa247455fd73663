"""Static load models of the lower stage: regressors and their coefficients (paper eq. 6).

Both models are linear in their coefficients for a regressor matrix that depends only on the measured V,
so for a given motor D the static part is an ordinary least-squares fit.
"""

from __future__ import annotations

import numpy as np


def regressors(V: np.ndarray, model: str = "zip") -> np.ndarray:
    """Regressor matrix of the static model.

    Parameters
    ----------
    V : ndarray
        Voltage magnitude [pu].
    model : {"zip", "exponential"}
        ``zip``: columns [1, V, V²] (eq. 6).  ``exponential``: columns [1, ln V], the first-order form of
        P0·V^np around V = 1 pu, exact to O((ln V)²) — about 1e-5 relative for ambient voltage
        excursions of a few tenths of a percent.

    Returns
    -------
    ndarray, shape (n, 3) or (n, 2)
    """
    if model == "zip":
        return np.column_stack([np.ones_like(V), V, V * V])
    if model == "exponential":
        return np.column_stack([np.ones_like(V), np.log(V)])
    raise ValueError(f"unknown static model {model!r} (use 'zip' or 'exponential')")


def coefficients(beta_p: np.ndarray, beta_q: np.ndarray, model: str = "zip") -> dict[str, float]:
    """Named static coefficients from the regression solutions of P and Q.

    Parameters
    ----------
    beta_p, beta_q : ndarray
        Least-squares coefficients of the columns of :func:`regressors` for P and Q [pu].
    model : {"zip", "exponential"}
        Static model the regressors belong to.

    Returns
    -------
    dict
        ``zip``: Pz, Pi, Pp, Qz, Qi, Qp [pu].  ``exponential``: P0 [pu], np [-], Q0 [pu], nq [-].
    """
    if model == "zip":
        return {
            "Pz": float(beta_p[2]), "Pi": float(beta_p[1]), "Pp": float(beta_p[0]),
            "Qz": float(beta_q[2]), "Qi": float(beta_q[1]), "Qp": float(beta_q[0]),
        }
    return {
        "P0": float(beta_p[0]), "np": float(beta_p[1] / beta_p[0]) if beta_p[0] != 0 else float("nan"),
        "Q0": float(beta_q[0]), "nq": float(beta_q[1] / beta_q[0]) if beta_q[0] != 0 else float("nan"),
    }


def static_power(V: np.ndarray, static: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    """P and Q of a static model given by its named coefficients [pu].

    Parameters
    ----------
    V : ndarray
        Voltage magnitude [pu].
    static : dict
        ZIP {Pz, Pi, Pp, Qz, Qi, Qp} or exponential {P0, np, Q0, nq}.
    """
    if "Pz" in static:
        p = static["Pz"] * V * V + static["Pi"] * V + static["Pp"]
        q = static["Qz"] * V * V + static["Qi"] * V + static["Qp"]
        return p, q
    if "P0" in static:
        return static["P0"] * V ** static["np"], static["Q0"] * V ** static["nq"]
    raise ValueError(f"unknown static model with keys {sorted(static)}")
