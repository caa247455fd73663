"""The lower stage of the upper stage's residual function, compiled: the projected training residual.

For given (D, z) the engine's lower stage regresses the measured training samples, minus the model's part
nonlinear in the parameters, on the linear columns, in the noise-weighted ambient band (DCT coefficients
below 5 Hz), and the upper stage sees what is left (variable projection, :mod:`aslm_core.diagnosis.engine`).
That projection is called once per residual evaluation — thousands of times per diagnosis — and in NumPy it
cost more than the motor's simulation (a dozen small array calls and an SVD per channel, about 0.1 ms each
of interpreter overhead, issue 12's sixth round).  Here the constant parts (the DCT basis, the measured
samples' coefficients, the weights) are computed once per fit and the rest runs in one compiled call: the
DCT of the model's columns, their column scaling, classical Gram–Schmidt with reorthogonalisation (as
accurate as Householder QR for the few columns here) and the residual of the projection.

A column set that is (nearly) rank deficient — a zero or duplicated extra column — is left to the SVD with
the engine's cut-off (:func:`aslm_core.diagnosis.engine._lstsq`), as every evaluation was before.
"""

from __future__ import annotations

from collections.abc import Callable

import numba as nb
import numpy as np

from aslm_core.diagnosis.noise import NoiseModel, band_basis

#: A scaled column this close to the span of the others (its Gram–Schmidt norm, columns of unit norm) is
#: treated as rank deficient and the channel solved by the SVD; far above the SVD's own cut-off (1e-10 of
#: the largest singular value), so the SVD decides every case near it.
RANK_TOL = 1e-8


@nb.njit(cache=True, nogil=True, error_model="numpy")
def project_kernel(basis: np.ndarray, y: np.ndarray, cols: np.ndarray, w: np.ndarray, out: np.ndarray) -> bool:
    """Weighted ambient-band residual of y − cols[:, 0] after regression on cols[:, 1:], into ``out``.

    Parameters
    ----------
    basis : ndarray, shape (m, n)
        DCT rows of the band (:func:`aslm_core.diagnosis.noise.band_basis`).
    y : ndarray, shape (m,)
        Band coefficients of the measured samples [pu].
    cols : ndarray, shape (n, 1 + k)
        The model's nonlinear part [pu], then its k linear columns, on the training samples.
    w : ndarray, shape (m,)
        Weights 1/σ per coefficient [1/pu].
    out : ndarray, shape (m,)
        The whitened residual [-].

    Returns
    -------
    bool
        False when the columns are rank deficient (``out`` then undefined).
    """
    c = basis @ cols
    m, k1 = c.shape
    k = k1 - 1
    q = np.empty((m, k))
    for i in range(m):
        out[i] = (y[i] - c[i, 0]) * w[i]
    for j in range(k):
        s = 0.0
        for i in range(m):
            v = c[i, j + 1] * w[i]
            q[i, j] = v
            s += v * v
        if s == 0.0:
            return False
        s = 1.0 / np.sqrt(s)
        for i in range(m):
            q[i, j] *= s
        for _ in range(2):  # twice is enough (Kahan–Parlett)
            for l in range(j):
                h = 0.0
                for i in range(m):
                    h += q[i, l] * q[i, j]
                for i in range(m):
                    q[i, j] -= h * q[i, l]
        s = 0.0
        for i in range(m):
            s += q[i, j] * q[i, j]
        s = np.sqrt(s)
        if s <= RANK_TOL:
            return False
        for i in range(m):
            q[i, j] /= s
    for _ in range(2):
        for l in range(k):
            h = 0.0
            for i in range(m):
                h += q[i, l] * out[i]
            for i in range(m):
                out[i] -= h * q[i, l]
    return True


@nb.njit(cache=True, nogil=True, error_model="numpy")
def project_pair(basis: np.ndarray, k0: int, yp: np.ndarray, mp: np.ndarray, xp: np.ndarray, wp: np.ndarray,
                 yq: np.ndarray, mq: np.ndarray, xq: np.ndarray, wq: np.ndarray, out: np.ndarray) -> int:
    """:func:`project_kernel` for P into ``out[:m]`` and Q into ``out[m:]``, the training samples k0 … k0 + n
    of the whole-window model parts (mp, mq) and columns (xp, xq) copied here, in one call.

    Returns
    -------
    int
        Bit 0 set when P's columns are rank deficient, bit 1 for Q's (that half of ``out`` then undefined).
    """
    m, n = basis.shape
    flags = 0
    for ch in range(2):
        mm, xx = (mp, xp) if ch == 0 else (mq, xq)
        cols = np.empty((n, 1 + xx.shape[1]))
        for i in range(n):
            cols[i, 0] = mm[k0 + i]
            for j in range(xx.shape[1]):
                cols[i, 1 + j] = xx[k0 + i, j]
        if ch == 0:
            if not project_kernel(basis, yp, cols, wp, out[:m]):
                flags |= 1
        elif not project_kernel(basis, yq, cols, wq, out[m:]):
            flags |= 2
    return flags


class Projector:
    """The upper stage's residual for one fit: the constant parts computed once (segment and noise fixed).

    Parameters
    ----------
    seg : Segment
        The segment; its training samples are regressed.
    noise : NoiseModel
        The weights (variances per band coefficient).
    fallback : callable
        ``fallback(xw, yw) -> beta``, the SVD least squares used when the columns are rank deficient.
    """

    def __init__(self, seg, noise: NoiseModel, fallback: Callable[[np.ndarray, np.ndarray], np.ndarray]):
        tr = seg.train
        self.tr = tr
        vp, vq, _ = noise.coefficients(tr)
        self.basis = band_basis(tr.stop - tr.start, noise.fs, noise.band_hz)
        self.wp, self.wq = 1.0 / np.sqrt(vp), 1.0 / np.sqrt(vq)
        self.yp, self.yq = self.basis @ seg.P[tr], self.basis @ seg.Q[tr]
        self.fallback = fallback

    def _svd(self, y: np.ndarray, m: np.ndarray, x: np.ndarray, w: np.ndarray) -> np.ndarray:
        """One channel's residual by the SVD (rank-deficient columns)."""
        c = self.basis @ np.column_stack([m[self.tr], x[self.tr]])
        yw, xw = (y - c[:, 0]) * w, c[:, 1:] * w[:, None]
        return yw - xw @ self.fallback(xw, yw)

    def residuals(self, pr) -> np.ndarray:
        """Whitened ambient-band training residuals of P, then Q, after the lower stage [-].

        Parameters
        ----------
        pr : Prediction
            The candidate's output for one (D, z).
        """
        m = self.yp.size
        out = np.empty(2 * m)
        flags = project_pair(self.basis, self.tr.start, self.yp, pr.mp, np.ascontiguousarray(pr.xp), self.wp,
                             self.yq, pr.mq, np.ascontiguousarray(pr.xq), self.wq, out)
        if flags & 1:
            out[:m] = self._svd(self.yp, pr.mp, pr.xp, self.wp)
        if flags & 2:
            out[m:] = self._svd(self.yq, pr.mq, pr.xq, self.wq)
        return out
