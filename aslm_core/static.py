"""Static load models of the lower stage: regressors and their coefficients (paper eq. 6).

Both models are linear in their coefficients for a regressor matrix that depends only on the measured V,
so for a given motor D the static part is an ordinary least-squares fit.
"""

from __future__ import annotations

import math

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


#: A static coefficient's standard error above this fraction of the load |P + jQ| means the window cannot split the static part into Z, I and P (flag ``static_split_unidentifiable``).
SPLIT_SE_FRACTION = 0.1


def local_part(beta_p: np.ndarray, beta_q: np.ndarray, r_factor: np.ndarray, V: np.ndarray,
               covs: np.ndarray, model: str = "zip") -> tuple[dict[str, float], dict[str, float], float]:
    """What ambient data identify of the static part: its level and slope at the window's mean V.

    With V moving by tenths of a percent the columns [1, V, V²] are nearly collinear: their coefficients
    (the Z/I/P split) come with standard errors of tens to thousands of pu, while the level P0 and the local
    slope dP/dV are well determined.

    Parameters
    ----------
    beta_p, beta_q : ndarray
        Regression coefficients of P and Q on the columns of :func:`regressors` [pu].
    r_factor : ndarray
        R of the thin QR of the regressor matrix over the regression samples.
    V : ndarray
        Voltage over the regression samples [pu].
    covs : ndarray
        (2, m, m) covariances of beta_p and beta_q [pu²] (the regression's σ²·R⁻¹R⁻ᵀ, Φ = Q·R, plus what
        D's uncertainty adds; :func:`aslm_core.optimize.static_covariances`).
    model : {"zip", "exponential"}

    Returns
    -------
    local : dict
        ``V0`` [pu] (mean V), ``P0``, ``Q0`` [pu] (static power at V0), ``dPdV``, ``dQdV`` [pu/pu],
        ``kpv``, ``kqv`` [-] (the local exponents dP/dV·V0/P0, dQ/dV·V0/Q0), and ``*_se`` of each.
    coef_se : dict
        Standard error of each named static coefficient (keys as :func:`coefficients`).
    cond : float
        Condition number of the regressor matrix with unit-norm columns [-].
    """
    v0 = float(V.mean())
    m = r_factor.shape[0]
    if model == "zip":
        lin = np.array([[1.0, v0, v0 * v0], [0.0, 1.0, 2.0 * v0]])  # level and slope at V0
    else:
        lin = np.array([[1.0, math.log(v0)], [0.0, 1.0 / v0]])
    # Both channels at once, then plain floats: numpy's per-call overhead dominates at m ≤ 3.
    bs = np.empty((m, 2))
    bs[:, 0], bs[:, 1] = beta_p, beta_q
    vals = (lin @ bs).T.tolist()  # [[P0, dPdV], [Q0, dQdV]]
    c2 = (lin @ covs @ lin.T).tolist()  # per channel: 2×2 covariance of (level, slope)
    diag = np.diagonal(covs, axis1=1, axis2=2).tolist()
    betas = (beta_p.tolist(), beta_q.tolist())
    local: dict[str, float] = {"V0": v0}
    coef_se: dict[str, float] = {}
    for c, ch in enumerate(("P", "Q")):
        (x0, dx), ((vll, vls), (_, vss)) = vals[c], c2[c]
        # Local exponent k = dx·V0/x0; delta method on (x0, dx).
        k = k_se = float("nan")
        if x0 != 0.0:
            k, g0, g1 = dx * v0 / x0, -dx * v0 / (x0 * x0), v0 / x0
            k_se = math.sqrt(max(g0 * g0 * vll + 2.0 * g0 * g1 * vls + g1 * g1 * vss, 0.0))
        low = ch.lower()
        local.update({f"{ch}0": x0, f"d{ch}dV": dx, f"k{low}v": k, f"{ch}0_se": math.sqrt(max(vll, 0.0)),
                      f"d{ch}dV_se": math.sqrt(max(vss, 0.0)), f"k{low}v_se": k_se})
        se = [math.sqrt(max(v, 0.0)) for v in diag[c]]
        if model == "zip":
            coef_se.update({f"{ch}z": se[2], f"{ch}i": se[1], f"{ch}p": se[0]})
        else:
            b0, b1 = betas[c]
            n_se = float("nan")
            if b0 != 0.0:
                (v00, v01), (_, v11) = covs[c].tolist()
                g0, g1 = -b1 / (b0 * b0), 1.0 / b0
                n_se = math.sqrt(max(g0 * g0 * v00 + 2.0 * g0 * g1 * v01 + g1 * g1 * v11, 0.0))
            coef_se.update({f"{ch}0": se[0], f"n{low}": n_se})
    sv = np.linalg.svd(r_factor / np.sqrt(np.sum(r_factor * r_factor, axis=0))[None, :m], compute_uv=False)
    return local, coef_se, float(sv[0] / sv[-1])


def split_unidentifiable(coef_se: dict[str, float], s_load: float, model: str = "zip") -> bool:
    """True when a ZIP coefficient's standard error exceeds :data:`SPLIT_SE_FRACTION` of the load.

    Parameters
    ----------
    coef_se : dict
        Standard errors of the static coefficients (from :func:`local_part`) [pu].
    s_load : float
        Size of the whole load, |mean P + j·mean Q| over the window [pu] (the static part alone, or Q
        alone, can be near zero).
    model : {"zip", "exponential"}
        Always False for the exponential model, whose two coefficients are the level and the slope.
    """
    if model != "zip":
        return False
    return bool(max(coef_se.values()) > SPLIT_SE_FRACTION * max(abs(s_load), 1e-12))
