"""The whitening of a two-channel stationary series over a finite window, by the multichannel Levinson recursion.

The refinement's time-domain form (:mod:`aslm_core.input_weighting`) whitens the [P; Q] residuals of a window by the
covariance its disturbance spectrum implies over the window's samples: a block-Toeplitz matrix of 2l × 2l.  Its dense
Cholesky factor costs O(l³); the Whittle–Wiggins–Robinson recursion gives the same factorisation of a block-Toeplitz
matrix in O(l²): the innovation of sample t is the error of the best linear predictor of order t, and the innovations of
a window are uncorrelated with each other (Whittle 1963).  Measurements: docs/numerics.md, "Stop 48".
"""

from __future__ import annotations

import numba as nb
import numpy as np
from scipy.linalg import blas


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _whitener(c: np.ndarray) -> tuple[np.ndarray, bool]:
    l = c.shape[0]
    w = np.zeros((2 * l, 2 * l))
    # Forward predictor of order p: A_j (coefficient of x_{t−j}, A_0 = I); backward: B_j (B_p = I).  Entries as
    # arrays of shape (4, l): [00, 01, 10, 11] — scalar arithmetic, no 2×2 temporaries in the O(l²) loops.
    a = np.zeros((4, l))
    b = np.zeros((4, l))
    an = np.zeros((4, l))
    bn = np.zeros((4, l))
    a[0, 0] = a[3, 0] = b[0, 0] = b[3, 0] = 1.0
    v00, v01, v10, v11 = c[0, 0, 0], c[0, 0, 1], c[0, 1, 0], c[0, 1, 1]
    u00, u01, u10, u11 = v00, v01, v10, v11
    for p in range(l):
        det_v = v00 * v11 - v01 * v10
        if not (v00 > 0.0 and det_v > 0.0):  # also NaN
            return w, False
        # L⁻¹ of V's lower Cholesky factor (V symmetrised).
        vs = 0.5 * (v01 + v10)
        l00 = np.sqrt(v00)
        l10 = vs / l00
        l11 = np.sqrt(max(v11 - l10 * l10, 1e-300))
        i00, i10, i11 = 1.0 / l00, -l10 / (l00 * l11), 1.0 / l11
        r0, r1 = 2 * p, 2 * p + 1
        for j in range(p + 1):
            col = p - j
            w[r0, 2 * col] = i00 * a[0, j]
            w[r0, 2 * col + 1] = i00 * a[1, j]
            w[r1, 2 * col] = i10 * a[0, j] + i11 * a[2, j]
            w[r1, 2 * col + 1] = i10 * a[1, j] + i11 * a[3, j]
        if p == l - 1:
            break
        # Δ = Σ_j A_j·R(p + 1 − j)
        d00 = d01 = d10 = d11 = 0.0
        for j in range(p + 1):
            k = p + 1 - j
            c00, c01, c10, c11 = c[k, 0, 0], c[k, 0, 1], c[k, 1, 0], c[k, 1, 1]
            d00 += a[0, j] * c00 + a[1, j] * c10
            d01 += a[0, j] * c01 + a[1, j] * c11
            d10 += a[2, j] * c00 + a[3, j] * c10
            d11 += a[2, j] * c01 + a[3, j] * c11
        # K_f = Δ·U⁻¹, K_b = Δᵀ·V⁻¹
        det_u = u00 * u11 - u01 * u10
        if not det_u > 0.0:
            return w, False
        ui00, ui01, ui10, ui11 = u11 / det_u, -u01 / det_u, -u10 / det_u, u00 / det_u
        vi00, vi01, vi10, vi11 = v11 / det_v, -v01 / det_v, -v10 / det_v, v00 / det_v
        f00, f01 = d00 * ui00 + d01 * ui10, d00 * ui01 + d01 * ui11
        f10, f11 = d10 * ui00 + d11 * ui10, d10 * ui01 + d11 * ui11
        g00, g01 = d00 * vi00 + d10 * vi10, d00 * vi01 + d10 * vi11
        g10, g11 = d01 * vi00 + d11 * vi10, d01 * vi01 + d11 * vi11
        # A'_j = A_j − K_f·B_{j−1};  B'_j = B_{j−1} − K_b·A_j  (A_{p+1} = 0, B_{−1} = 0)
        for j in range(p + 2):
            a00 = a[0, j] if j <= p else 0.0
            a01 = a[1, j] if j <= p else 0.0
            a10 = a[2, j] if j <= p else 0.0
            a11 = a[3, j] if j <= p else 0.0
            b00 = b[0, j - 1] if j >= 1 else 0.0
            b01 = b[1, j - 1] if j >= 1 else 0.0
            b10 = b[2, j - 1] if j >= 1 else 0.0
            b11 = b[3, j - 1] if j >= 1 else 0.0
            an[0, j] = a00 - (f00 * b00 + f01 * b10)
            an[1, j] = a01 - (f00 * b01 + f01 * b11)
            an[2, j] = a10 - (f10 * b00 + f11 * b10)
            an[3, j] = a11 - (f10 * b01 + f11 * b11)
            bn[0, j] = b00 - (g00 * a00 + g01 * a10)
            bn[1, j] = b01 - (g00 * a01 + g01 * a11)
            bn[2, j] = b10 - (g10 * a00 + g11 * a10)
            bn[3, j] = b11 - (g10 * a01 + g11 * a11)
        # V' = V − K_f·Δᵀ;  U' = U − K_b·Δ
        v00, v01 = v00 - (f00 * d00 + f01 * d01), v01 - (f00 * d10 + f01 * d11)
        v10, v11 = v10 - (f10 * d00 + f11 * d01), v11 - (f10 * d10 + f11 * d11)
        u00, u01 = u00 - (g00 * d00 + g01 * d10), u01 - (g00 * d01 + g01 * d11)
        u10, u11 = u10 - (g10 * d00 + g11 * d10), u11 - (g10 * d01 + g11 * d11)
        a, an = an, a
        b, bn = bn, b
    return w, True


def whitening_matrix(c: np.ndarray) -> np.ndarray | None:
    """A square root of the inverse covariance of a stationary two-channel series over l consecutive samples.

    Parameters
    ----------
    c : ndarray, shape (l, 2, 2)
        The series' autocovariance at lags 0 … l − 1: c[τ, i, k] = E[x_i(t + τ)·x_k(t)] [unit²].

    Returns
    -------
    ndarray, shape (2l, 2l), or None
        The lower-triangular W with W·Σ·Wᵀ = I, Σ the covariance of the time-major stack [x_0(0), x_1(0), x_0(1), …]
        (:func:`interleaved`): a sum of squares of W·x is xᵀ·Σ⁻¹·x.  Row pair (2t, 2t + 1) is the innovation of sample
        t scaled to unit covariance [1/unit].  None when the covariance is not positive definite.
    """
    w, ok = _whitener(np.ascontiguousarray(c, dtype=np.float64))
    return w if ok else None


def interleaved(x0: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """The time-major stack of two channels' columns (time along axis 0): rows x0[0], x1[0], x0[1], …, Fortran-ordered
    for :func:`whitened`."""
    out = np.empty((2 * x0.shape[0], x0.shape[1]), order="F")
    out[0::2], out[1::2] = x0, x1
    return out


def whitened(w: np.ndarray, x: np.ndarray) -> np.ndarray:
    """W·x for the lower-triangular W of :func:`whitening_matrix` and x from :func:`interleaved`, by the triangular
    product (BLAS trmm), which reads half of W."""
    return blas.dtrmm(1.0, w.T, np.asfortranarray(x), side=0, lower=0, trans_a=1)
