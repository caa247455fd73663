"""Upper stage: constrained Levenberg–Marquardt over D on the projected (lower-stage) residuals.

Compiled end to end with numba: one iteration is one simulation with sensitivities plus O(n) work,
no Python in the loop.  Bounds are handled by freezing variables at an active bound and clipping;
the equilibrium constraint a·Vmin² − 2b·Tm > margin·a·Vmin² by backtracking into the feasible set.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from aslm_core.motor import simulate_kernel

OBJECTIVE_CODES = {"paper": 0, "ml": 1, "ssq": 2}
STATUS_NAMES = ("converged", "max_iter", "duplicate", "failed", "stalled")
# A start this close (relative, every parameter) to an optimum already found is in its basin: stop it.
DUPLICATE_RTOL = 2e-2


@nb.njit(cache=True)
def project_into(y, basis, out):
    """out = (I − B·Bᵀ)·y for an orthonormal basis B (l×m)."""
    m = basis.shape[1]
    l = y.shape[0]
    for j in range(m):
        c = 0.0
        for i in range(l):
            c += basis[i, j] * y[i]
        if j == 0:
            for i in range(l):
                out[i] = y[i] - basis[i, j] * c
        else:
            for i in range(l):
                out[i] -= basis[i, j] * c


@nb.njit(cache=True)
def feasible(d, lower, upper, vmin, margin):
    for i in range(4):
        if d[i] < lower[i] or d[i] > upper[i]:
            return False
    av = d[0] * vmin * vmin
    return av - 2.0 * d[1] * d[3] > margin * av


@nb.njit(cache=True)
def cost_of(rp, rq, objective, l):
    sp = 0.0
    sq = 0.0
    for i in range(rp.shape[0]):
        sp += rp[i] * rp[i]
        sq += rq[i] * rq[i]
    if objective == 0:
        return (math.sqrt(sp) + math.sqrt(sq)) / l
    if objective == 1:
        return 0.5 * l * (math.log(sp + 1e-300) + math.log(sq + 1e-300))
    return 0.5 * (sp + sq)


@nb.njit(cache=True)
def residuals_into(d, vd, vq, vdm, vqm, dt, w0, rk4, with_jac, basis, p_meas, q_meas, k0,
                   p, q, dp, dq, x, yp, yq, rp, rq, jp, jq):
    """Simulate D, project P/Q residuals (and Jacobians) over samples k0..n-1; False on failure."""
    ok = simulate_kernel(vd, vq, vdm, vqm, d, dt, w0, rk4, with_jac, p, q, dp, dq, x)
    if not ok:
        return False
    l = p_meas.shape[0]
    for i in range(l):
        yp[i] = p_meas[i] - p[k0 + i]
        yq[i] = q_meas[i] - q[k0 + i]
    project_into(yp, basis, rp)
    project_into(yq, basis, rq)
    if with_jac:
        for j in range(4):
            for i in range(l):
                yp[i] = -dp[k0 + i, j]
                yq[i] = -dq[k0 + i, j]
            project_into(yp, basis, jp[:, j])
            project_into(yq, basis, jq[:, j])
    return True


@nb.njit(cache=True)
def _normal_equations(jp, jq, rp, rq, wp, wq, A, g):
    l = rp.shape[0]
    for a in range(4):
        ga = 0.0
        for i in range(l):
            ga += wp * jp[i, a] * rp[i] + wq * jq[i, a] * rq[i]
        g[a] = ga
        for b in range(a, 4):
            s = 0.0
            for i in range(l):
                s += wp * jp[i, a] * jp[i, b] + wq * jq[i, a] * jq[i, b]
            A[a, b] = s
            A[b, a] = s


@nb.njit(cache=True)
def _weights(rp, rq, objective, l):
    sp = 0.0
    sq = 0.0
    for i in range(rp.shape[0]):
        sp += rp[i] * rp[i]
        sq += rq[i] * rq[i]
    if objective == 0:
        return 1.0 / max(math.sqrt(sp), 1e-300), 1.0 / max(math.sqrt(sq), 1e-300)
    if objective == 1:
        return l / max(sp, 1e-300), l / max(sq, 1e-300)
    return 1.0, 1.0


@nb.njit(cache=True)
def lm_kernel(d0, vd, vq, vdm, vqm, dt, w0, rk4, basis, p_meas, q_meas, k0, lower, upper, vmin,
              margin, objective, max_iter, xtol, known, n_known, out_d):
    """Levenberg–Marquardt from d0 (feasible). Returns (cost, iterations, evaluations, status code).

    Status: 0 converged, 1 max_iter, 2 duplicate (came within DUPLICATE_RTOL of a row of ``known``),
    3 failed (no finite objective at the start), 4 stalled (no descent step found).
    """
    n = vd.shape[0]
    l = p_meas.shape[0]
    p = np.empty(n)
    q = np.empty(n)
    dp = np.empty((n, 4))
    dq = np.empty((n, 4))
    x = np.empty((n, 3))
    yp = np.empty(l)
    yq = np.empty(l)
    rp = np.empty(l)
    rq = np.empty(l)
    jp = np.empty((l, 4))
    jq = np.empty((l, 4))
    rp_t = np.empty(l)
    rq_t = np.empty(l)
    jp_t = np.empty((l, 4))
    jq_t = np.empty((l, 4))
    A = np.empty((4, 4))
    g = np.empty(4)
    d = d0.copy()
    trial = np.empty(4)
    step = np.empty(4)
    evals = 1
    if not residuals_into(d, vd, vq, vdm, vqm, dt, w0, rk4, True, basis, p_meas, q_meas, k0,
                          p, q, dp, dq, x, yp, yq, rp, rq, jp, jq):
        out_d[:] = d
        return math.inf, 0, evals, 3
    cost = cost_of(rp, rq, objective, l)
    lam = 1e-3
    status = 1
    it = 0
    while it < max_iter:
        it += 1
        wp, wq = _weights(rp, rq, objective, l)
        _normal_equations(jp, jq, rp, rq, wp, wq, A, g)
        dmax = 0.0
        for a in range(4):
            dmax = max(dmax, A[a, a])
        idx = np.empty(4, dtype=np.int64)
        nf = 0
        for a in range(4):
            at_lo = d[a] <= lower[a] and g[a] > 0.0
            at_hi = d[a] >= upper[a] and g[a] < 0.0
            if not (at_lo or at_hi):
                idx[nf] = a
                nf += 1
        accepted = False
        moved = 0.0
        for _ in range(14):
            for a in range(4):
                step[a] = 0.0
            if nf > 0:
                M = np.empty((nf, nf))
                rhs = np.empty(nf)
                for u in range(nf):
                    for v in range(nf):
                        M[u, v] = A[idx[u], idx[v]]
                    M[u, u] += lam * max(A[idx[u], idx[u]], 1e-12 * dmax + 1e-300)
                    rhs[u] = -g[idx[u]]
                sol = np.linalg.solve(M, rhs)
                for u in range(nf):
                    step[idx[u]] = sol[u]
            alpha = 1.0
            ok_feas = False
            for _b in range(25):
                for a in range(4):
                    trial[a] = min(max(d[a] + alpha * step[a], lower[a]), upper[a])
                if feasible(trial, lower, upper, vmin, margin):
                    ok_feas = True
                    break
                alpha *= 0.5
            if ok_feas:
                evals += 1
                if residuals_into(trial, vd, vq, vdm, vqm, dt, w0, rk4, True, basis, p_meas, q_meas, k0,
                                  p, q, dp, dq, x, yp, yq, rp_t, rq_t, jp_t, jq_t):
                    cost_t = cost_of(rp_t, rq_t, objective, l)
                    if cost_t < cost:
                        moved = 0.0
                        for a in range(4):
                            moved = max(moved, abs(trial[a] - d[a]) / (abs(d[a]) + 1e-3))
                            d[a] = trial[a]
                        cost = cost_t
                        rp, rp_t = rp_t, rp
                        rq, rq_t = rq_t, rq
                        jp, jp_t = jp_t, jp
                        jq, jq_t = jq_t, jq
                        lam = max(lam * 0.2, 1e-10)
                        accepted = True
                        break
            lam *= 8.0
        if not accepted:
            status = 4
            break
        if moved < xtol:
            status = 0
            break
        dup = False
        for k in range(n_known):
            close = True
            for a in range(4):
                if abs(d[a] - known[k, a]) > DUPLICATE_RTOL * abs(known[k, a]) + 1e-9:
                    close = False
            if close:
                dup = True
        if dup:
            status = 2
            break
    out_d[:] = d
    return cost, it, evals, status
