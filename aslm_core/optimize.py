"""Upper stage: constrained Levenberg–Marquardt over D on the projected (lower-stage) residuals.

Compiled end to end with numba: one iteration is one simulation with sensitivities plus O(n) work,
no Python in the loop.  The kernels here compile motor.simulate_kernel into themselves, and numba's cache
only watches this file: a change to the motor kernel must touch this file too (or clear ``__pycache__``),
or the cached kernels keep the old one (seen with the RK4 sub-steps).  Each step solves the damped model in the box and the linearised equilibrium
constraint a·Vmin²·(1 − margin) − 2b·Tm > 0 (a 4-variable active-set QP); the constraint's curvature is
corrected along Tm, with backtracking as the fallback.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from aslm_core.motor import normal_equations, simulate_kernel

OBJECTIVE_CODES = {"paper": 0, "ml": 1, "ssq": 2}
STATUS_NAMES = ("converged", "max_iter", "duplicate", "failed", "stalled")
# A start this close (relative, every parameter) to an optimum already found is in its basin: stop it.
DUPLICATE_RTOL = 0.1
# Relative objective decrease below which a step is not worth an evaluation (rounding level).
FTOL = 1e-10


@nb.njit(cache=True, nogil=True, error_model="numpy")
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


@nb.njit(cache=True, nogil=True, error_model="numpy")
def thin_qr(A):
    """Thin QR factors (Q l×m orthonormal, R m×m upper triangular) of a tall matrix.

    Classical Gram–Schmidt with one reorthogonalisation ("twice is enough"): orthogonal to rounding
    for the nearly collinear [1, V, V²] of ambient data, without LAPACK's call overhead for m = 2–3.
    """
    l, m = A.shape
    T = np.empty((m, l))  # Qᵀ: rows contiguous
    R = np.zeros((m, m))
    c = np.empty(m)
    for j in range(m):
        for i in range(l):
            T[j, i] = A[i, j]
        for _ in range(2):
            for u in range(j):
                acc = 0.0
                for i in range(l):
                    acc += T[u, i] * T[j, i]
                c[u] = acc
                R[u, j] += acc
            for u in range(j):
                for i in range(l):
                    T[j, i] -= c[u] * T[u, i]
        nrm = 0.0
        for i in range(l):
            nrm += T[j, i] * T[j, i]
        nrm = math.sqrt(nrm)
        R[j, j] = nrm
        for i in range(l):
            T[j, i] /= nrm
    Q = np.empty((l, m))
    for i in range(l):
        for j in range(m):
            Q[i, j] = T[j, i]
    return Q, R


@nb.njit(cache=True, nogil=True, error_model="numpy")
def solve_upper(R, B):
    """X with R·X = B for upper-triangular R (m×m) by back substitution; B is m×k."""
    m, k = B.shape
    X = np.empty((m, k))
    for c in range(k):
        for i in range(m - 1, -1, -1):
            acc = B[i, c]
            for j in range(i + 1, m):
                acc -= R[i, j] * X[j, c]
            X[i, c] = acc / R[i, i]
    return X


@nb.njit(cache=True, nogil=True, error_model="numpy")
def static_covariances(r_factor, basis, dp, dq, k0, cov_d, var_p, var_q, out):
    """Covariances of the static coefficients of P and Q into out (2×m×m).

    β = R⁻¹Bᵀ(y − m(D)) over the regression samples k0.. (basis B, l×m), so cov(β) = σ²·R⁻¹R⁻ᵀ plus
    G·cov(D)·Gᵀ with G = R⁻¹Bᵀ·∂m/∂D (its sign cancels); non-finite entries of ``cov_d`` count as 0.
    """
    m = r_factor.shape[0]
    l = basis.shape[0]
    eye = np.eye(m)
    rinv = solve_upper(r_factor, eye)
    bg = np.empty((m, 4))
    g = np.empty((m, 4))
    gc = np.empty((m, 4))
    for c in range(2):
        grad = dp if c == 0 else dq
        var = var_p if c == 0 else var_q
        for u in range(m):
            for j in range(4):
                acc = 0.0
                for i in range(l):
                    acc += basis[i, u] * grad[k0 + i, j]
                bg[u, j] = acc
        for u in range(m):
            for j in range(4):
                acc = 0.0
                for w in range(m):
                    acc += rinv[u, w] * bg[w, j]
                g[u, j] = acc
        for u in range(m):
            for j in range(4):
                acc = 0.0
                for k in range(4):
                    v = cov_d[j, k]
                    if np.isfinite(v):
                        acc += g[u, k] * v
                gc[u, j] = acc
        for u in range(m):
            for w in range(m):
                acc = 0.0
                for j in range(m):
                    acc += rinv[u, j] * rinv[w, j]
                acc *= var
                for j in range(4):
                    acc += gc[u, j] * g[w, j]
                out[c, u, w] = acc


@nb.njit(cache=True, nogil=True, error_model="numpy")
def feasible(d, lower, upper, vmin, margin):
    for i in range(4):
        if d[i] < lower[i] or d[i] > upper[i]:
            return False
    av = d[0] * vmin * vmin
    return av - 2.0 * d[1] * d[3] > margin * av


@nb.njit(cache=True, nogil=True, error_model="numpy")
def residuals_into(d, vd, vq, vdm, vqm, dt, w0, rk4, with_jac, basis, p_meas, q_meas, k0,
                   p, q, dp, dq, x, yp, yq, rp, rq, jp, jq):
    """Simulate D, project P/Q residuals (and Jacobians) over samples k0..n-1; False on failure."""
    ok = simulate_kernel(vd, vq, vdm, vqm, d, dt, w0, rk4, with_jac, p, q, dp, dq, x,
                         True, k0, p_meas, q_meas, dp)
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


@nb.njit(cache=True, nogil=True, error_model="numpy")
def fit_statistics(dp, dq, p_meas, q_meas, p_model, q_model, basis, V, theta, JJ, bty):
    """Sums describing the final fit, in one pass (the result's standard errors, FD, SNR, static part).

    ``p_model``, ``dp`` (n, and n×4) are the motor's P and its D-gradient over the whole window, the
    measurements and the orthonormal ``basis`` (l×m, constant column first) cover the regression samples
    k0 = n − l onwards.  Fills JJ (2×4×4) with JᵀJ of the projected Jacobians J = −P⊥·∂m/∂D of P and Q
    (as MᵀM − (BᵀM)ᵀ(BᵀM), rows shifted by the first one so that few digits cancel), and bty (2×m) with
    Bᵀ(measured − motor).  Returns ‖r_p‖², ‖r_q‖², the lag-1 autocorrelations of r_p and r_q, the centred
    sums of squares of the measured P and Q, the std of V relative to its mean, and the std of the
    sample-to-sample change of θ [rad].
    """
    l = p_meas.shape[0]
    m = basis.shape[1]
    k0 = p_model.shape[0] - l
    rr = np.zeros(2)
    lag = np.zeros(2)
    ss = np.zeros(2)
    y = np.empty(l)
    bm = np.empty((m, 4))
    mm = np.empty((4, 4))
    for c in range(2):
        meas = p_meas if c == 0 else q_meas
        model = p_model if c == 0 else q_model
        grad = dp if c == 0 else dq
        for i in range(l):
            y[i] = meas[i] - model[k0 + i]
        for u in range(m):
            acc = 0.0
            for i in range(l):
                acc += basis[i, u] * y[i]
            bty[c, u] = acc
        prev = 0.0
        for i in range(l):
            r = y[i]
            for u in range(m):
                r -= basis[i, u] * bty[c, u]
            rr[c] += r * r
            if i > 0:
                lag[c] += r * prev
            prev = r
        mean = 0.0
        for i in range(l):
            mean += meas[i]
        mean /= l
        for i in range(l):
            ss[c] += (meas[i] - mean) ** 2
        bm[:, :] = 0.0
        mm[:, :] = 0.0
        for i in range(l):
            for v in range(4):
                g = grad[k0 + i, v] - grad[k0, v]
                for u in range(m):
                    bm[u, v] += basis[i, u] * g
                for w in range(v, 4):
                    mm[v, w] += g * (grad[k0 + i, w] - grad[k0, w])
        for v in range(4):
            for w in range(v, 4):
                acc = mm[v, w]
                for u in range(m):
                    acc -= bm[u, v] * bm[u, w]
                JJ[c, v, w] = acc
                JJ[c, w, v] = acc
    n = V.shape[0]
    v_mean = 0.0
    for i in range(n):
        v_mean += V[i]
    v_mean /= n
    v_var = 0.0
    for i in range(n):
        v_var += (V[i] - v_mean) ** 2
    dth_mean = (theta[n - 1] - theta[0]) / (n - 1)
    dth_var = 0.0
    for i in range(1, n):
        dth_var += (theta[i] - theta[i - 1] - dth_mean) ** 2
    return (rr[0], rr[1], lag[0] / max(rr[0], 1e-300), lag[1] / max(rr[1], 1e-300), ss[0], ss[1],
            math.sqrt(v_var / n) / v_mean, math.sqrt(dth_var / (n - 1)))


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _cost_rr(rr_p, rr_q, objective, l):
    if objective == 0:
        return (math.sqrt(rr_p) + math.sqrt(rr_q)) / l
    if objective == 1:
        return 0.5 * l * (math.log(rr_p + 1e-300) + math.log(rr_q + 1e-300))
    return 0.5 * (rr_p + rr_q)


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _weights_rr(rr_p, rr_q, objective, l):
    """Channel weights w with ∇cost = Σ w·Jᵀr: the IRLS form of the configured objective."""
    if objective == 0:
        return 1.0 / max(math.sqrt(rr_p), 1e-300), 1.0 / max(math.sqrt(rr_q), 1e-300)
    if objective == 1:
        return l / max(rr_p, 1e-300), l / max(rr_q, 1e-300)
    return 1.0, 1.0


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _evaluate(d, vd, vq, vdm, vqm, dt, w0, rk4, k0, p_meas, q_meas, basis2, X, G, Ap, Aq, gp, gq, d1, d2):
    """Simulation with sensitivities + normal equations of both channels; returns (ok, ‖r_p‖², ‖r_q‖²)."""
    ok = simulate_kernel(vd, vq, vdm, vqm, d, dt, w0, rk4, True, d1, d1, d2, d2, d2, False, k0, p_meas,
                         q_meas, X)
    if not ok:
        return False, 0.0, 0.0
    normal_equations(X, basis2, G)
    for u in range(4):
        gp[u] = -G[1 + u, 0]
        gq[u] = -G[6 + u, 5]
        for v in range(4):
            Ap[u, v] = G[1 + u, 1 + v]
            Aq[u, v] = G[6 + u, 6 + v]
    return True, max(G[0, 0], 0.0), max(G[5, 5], 0.0)


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _near_known(d, known, n_known, rtol):
    """True when d is within rtol (relative, every parameter) of a row of known."""
    for k in range(n_known):
        close = True
        for u in range(4):
            if abs(d[u] - known[k, u]) > rtol * abs(known[k, u]) + 1e-9:
                close = False
        if close:
            return True
    return False


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _solve_small(M, rhs, n):
    """Solve the leading n×n system M·x = rhs in place (x into rhs), partial pivoting; False if singular.

    LAPACK's call overhead is larger than the work for n ≤ 4.
    """
    for k in range(n):
        p = k
        for i in range(k + 1, n):
            if abs(M[i, k]) > abs(M[p, k]):
                p = i
        if not abs(M[p, k]) > 0.0:
            return False
        if p != k:
            for j in range(n):
                M[k, j], M[p, j] = M[p, j], M[k, j]
            rhs[k], rhs[p] = rhs[p], rhs[k]
        for i in range(k + 1, n):
            f = M[i, k] / M[k, k]
            for j in range(k, n):
                M[i, j] -= f * M[k, j]
            rhs[i] -= f * rhs[k]
    for k in range(n - 1, -1, -1):
        acc = rhs[k]
        for j in range(k + 1, n):
            acc -= M[k, j] * rhs[j]
        rhs[k] = acc / M[k, k]
    return True


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _eqp_direction(M, q, gc, work, free, use_con, p, w, idx):
    """Direction p minimising qᵀp + ½pᵀMp with p = 0 off ``free`` (and gcᵀp = 0 if ``use_con``).

    Returns (ok, ν): ν is the multiplier of the linear constraint (q + M·p = ν·gc on the free variables).
    """
    nf = 0
    for u in range(4):
        p[u] = 0.0
        if free[u]:
            idx[nf] = u
            nf += 1
    if nf == 0:
        return True, 0.0
    for u in range(nf):
        for v in range(nf):
            work[u, v] = M[idx[u], idx[v]]
        w[u] = -q[idx[u]]
    if not _solve_small(work, w, nf):
        return False, 0.0
    for u in range(nf):
        p[idx[u]] = w[u]
    if not use_con:
        return True, 0.0
    for u in range(nf):
        for v in range(nf):
            work[u, v] = M[idx[u], idx[v]]
        w[u] = gc[idx[u]]
    if not _solve_small(work, w, nf):
        return False, 0.0
    cp = 0.0
    cmc = 0.0
    for u in range(nf):
        cp += gc[idx[u]] * p[idx[u]]
        cmc += gc[idx[u]] * w[u]
    if not cmc > 0.0:
        return True, 0.0  # no free variable enters the constraint: the bounds hold it
    nu = -cp / cmc
    for u in range(nf):
        p[idx[u]] += nu * w[u]
    return True, nu


@nb.njit(cache=True, nogil=True, error_model="numpy")
def qp_step(M, g, d, lower, upper, gc, c_d, s, work, vec, ivec):
    """Step s minimising gᵀs + ½sᵀMs with lower ≤ d + s ≤ upper and gcᵀs ≥ −c_d; False if singular.

    ``work`` (4×4), ``vec`` (3×4) and ``ivec`` (3×4, int64) are scratch space (no allocation per step).

    Primal active-set method from s = 0 (feasible when d is): the damped LM subproblem with the bounds
    and the linearised equilibrium constraint.  A bound or the constraint leaves the working set when
    its multiplier is negative, so an iterate stops only at a KKT point of the model, not at a corner
    where freezing variables by the sign of the gradient alone would hold it.
    """
    state = ivec[0]  # 0 free, −1 at lower, +1 at upper
    free = ivec[1]
    idx = ivec[2]
    w = vec[0]
    p = vec[1]
    q = vec[2]
    for u in range(4):
        s[u] = 0.0
        state[u] = 0
        if d[u] <= lower[u] and g[u] > 0.0:
            state[u] = -1
        elif d[u] >= upper[u] and g[u] < 0.0:
            state[u] = 1
    con = False
    gscale = 0.0
    for u in range(4):
        gscale = max(gscale, abs(g[u]) * (abs(d[u]) + 1e-3))
    for _ in range(12):
        for u in range(4):
            free[u] = 1 if state[u] == 0 else 0
            acc = g[u]
            for v in range(4):
                acc += M[u, v] * s[v]
            q[u] = acc
        ok, nu = _eqp_direction(M, q, gc, work, free, con, p, w, idx)
        if not ok:
            return False
        # Longest feasible fraction of p; the first constraint it meets joins the working set.
        alpha = 1.0
        block = -1
        for u in range(4):
            if free[u]:
                if p[u] < 0.0 and d[u] + s[u] + p[u] < lower[u]:
                    a_u = (lower[u] - d[u] - s[u]) / p[u]
                    if a_u < alpha:
                        alpha, block = a_u, u
                elif p[u] > 0.0 and d[u] + s[u] + p[u] > upper[u]:
                    a_u = (upper[u] - d[u] - s[u]) / p[u]
                    if a_u < alpha:
                        alpha, block = a_u, u
        if not con:
            cp = 0.0
            cs = c_d
            for u in range(4):
                cp += gc[u] * p[u]
                cs += gc[u] * s[u]
            if cp < 0.0 and cs + cp < 0.0:
                a_c = max(cs, 0.0) / -cp
                if a_c < alpha:
                    alpha, block = a_c, 4
        alpha = max(alpha, 0.0)
        for u in range(4):
            s[u] += alpha * p[u]
        if block >= 0:
            if block == 4:
                con = True
            else:
                state[block] = -1 if p[block] < 0.0 else 1
                s[block] = (lower[block] if p[block] < 0.0 else upper[block]) - d[block]
            continue
        # Full step: a minimiser on the working set.  Release the constraint with the most negative
        # multiplier, if any (q + M·p = ν·gc on the free variables; on a bound, its component).
        worst = 0.0
        drop = -1
        tol = -1e-12 * gscale
        if con and nu * gc[0] * abs(d[0]) < tol:
            worst, drop = nu * gc[0] * abs(d[0]), 4
        for u in range(4):
            if state[u] != 0:
                r = q[u] - (nu * gc[u] if con else 0.0)
                for v in range(4):
                    r += M[u, v] * p[v]
                lam_u = r if state[u] < 0 else -r
                lam_u *= abs(d[u]) + 1e-3
                if lam_u < tol and lam_u < worst:
                    worst, drop = lam_u, u
        if drop < 0:
            return True
        if drop == 4:
            con = False
        else:
            state[drop] = 0
    return True


@nb.njit(cache=True, nogil=True, error_model="numpy")
def lm_kernel(d0, vd, vq, vdm, vqm, dt, w0, rk4, basis2, p_meas, q_meas, k0, lower, upper, vmin,
              margin, objective, max_iter, xtol, ftol, dup_rtol, known, n_known, out_d):
    """Levenberg–Marquardt from d0 (feasible). Returns (cost, iterations, evaluations, status code).

    ``basis2`` holds the non-constant orthonormal static regressors over the regression samples (l×2).
    ``ftol`` is the relative objective decrease below which a step is not worth an evaluation; ``dup_rtol``
    the closeness (relative, every parameter) to a row of ``known`` at which a start is stopped.
    Status: 0 converged, 1 max_iter, 2 duplicate (the iterate, or the model's next point, came within
    ``dup_rtol`` of a row of ``known``), 3 failed (no finite objective at the start), 4 stalled (no
    descent step found).
    """
    l = p_meas.shape[0]
    X = np.empty((l, 10))
    G = np.empty((10, 10))
    Ap = np.empty((4, 4))
    Aq = np.empty((4, 4))
    gp = np.empty(4)
    gq = np.empty(4)
    Ap_t = np.empty((4, 4))
    Aq_t = np.empty((4, 4))
    gp_t = np.empty(4)
    gq_t = np.empty(4)
    dummy1 = np.empty(1)
    dummy2 = np.empty((1, 4))
    A = np.empty((4, 4))
    g = np.empty(4)
    M = np.empty((4, 4))
    gc = np.empty(4)
    qp_work = np.empty((4, 4))
    qp_vec = np.empty((3, 4))
    qp_int = np.empty((3, 4), dtype=np.int64)
    d = d0.copy()
    trial = np.empty(4)
    step = np.empty(4)
    evals = 1
    ok, rr_p, rr_q = _evaluate(d, vd, vq, vdm, vqm, dt, w0, rk4, k0, p_meas, q_meas, basis2, X, G,
                               Ap, Aq, gp, gq, dummy1, dummy2)
    if not ok:
        out_d[:] = d
        return math.inf, 0, evals, 3
    cost = _cost_rr(rr_p, rr_q, objective, l)
    lam = 1e-3
    nu = 2.0
    # d(cost) = scale·gᵀδ for the IRLS weights of each objective (eq. 7 carries the 1/l).
    scale = 1.0 / l if objective == 0 else 1.0
    status = 1
    it = 0
    while it < max_iter:
        it += 1
        wp, wq = _weights_rr(rr_p, rr_q, objective, l)
        dmax = 0.0
        for u in range(4):
            g[u] = wp * gp[u] + wq * gq[u]
            for v in range(4):
                A[u, v] = wp * Ap[u, v] + wq * Aq[u, v]
            dmax = max(dmax, A[u, u])
        gc[0] = vmin * vmin * (1.0 - margin)
        gc[1] = -2.0 * d[3]
        gc[2] = 0.0
        gc[3] = -2.0 * d[1]
        c_d = gc[0] * d[0] - 2.0 * d[1] * d[3]  # > 0 inside the equilibrium set
        accepted = False
        converged = False
        moved = 0.0
        heading_to_known = False
        for attempt in range(14):
            for u in range(4):
                for v in range(4):
                    M[u, v] = A[u, v]
                M[u, u] += lam * max(A[u, u], 1e-12 * dmax + 1e-300)
            if not qp_step(M, g, d, lower, upper, gc, c_d, step, qp_work, qp_vec, qp_int):
                lam *= nu
                nu *= 2.0
                continue
            if attempt == 0 and n_known > 0:
                # The model's next point already lies in a known optimum's neighbourhood: same basin.
                for u in range(4):
                    trial[u] = min(max(d[u] + step[u], lower[u]), upper[u])
                if _near_known(trial, known, n_known, dup_rtol):
                    heading_to_known = True
                    break
            # Predicted decrease of the step (the model's minimiser in the box and the linearised
            # equilibrium set, so ≥ 0): the convergence test.
            pred_full = 0.0
            for u in range(4):
                pred_full -= g[u] * step[u]
                for v in range(4):
                    pred_full -= 0.5 * step[u] * A[u, v] * step[v]
            if scale * pred_full <= ftol * cost:
                converged = True  # the model promises less than the objective's rounding
                break
            for u in range(4):
                trial[u] = min(max(d[u] + step[u], lower[u]), upper[u])
            if not feasible(trial, lower, upper, vmin, margin):
                # The constraint is bilinear: a step on its tangent leaves the set at second order.
                # Back onto it along Tm.
                tm_max = (1.0 - margin) * trial[0] * vmin * vmin / (2.0 * trial[1]) * (1.0 - 1e-9)
                if lower[3] <= tm_max < trial[3]:
                    step[3] = tm_max - d[3]
            alpha = 1.0
            ok_feas = False
            for _b in range(25):
                for u in range(4):
                    trial[u] = min(max(d[u] + alpha * step[u], lower[u]), upper[u])
                if feasible(trial, lower, upper, vmin, margin):
                    ok_feas = True
                    break
                alpha *= 0.5
            if ok_feas:
                pred = 0.0
                for u in range(4):
                    su = trial[u] - d[u]
                    pred -= g[u] * su
                    for v in range(4):
                        pred -= 0.5 * su * A[u, v] * (trial[v] - d[v])
                if pred <= 0.0:
                    lam *= nu
                    nu *= 2.0
                    continue
                evals += 1
                ok, rr_pt, rr_qt = _evaluate(trial, vd, vq, vdm, vqm, dt, w0, rk4, k0, p_meas, q_meas, basis2,
                                             X, G, Ap_t, Aq_t, gp_t, gq_t, dummy1, dummy2)
                if ok:
                    cost_t = _cost_rr(rr_pt, rr_qt, objective, l)
                    if cost_t < cost:
                        rho = (cost - cost_t) / (scale * pred)
                        # Nielsen's damping update: smooth in the gain ratio, fewer rejected steps.
                        lam = max(lam * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), 1e-12)
                        nu = 2.0
                        moved = 0.0
                        for u in range(4):
                            moved = max(moved, abs(trial[u] - d[u]) / (abs(d[u]) + 1e-3))
                            d[u] = trial[u]
                        if alpha < 1.0:
                            moved = math.inf  # a cut-short step is no sign of convergence
                        cost = cost_t
                        rr_p = rr_pt
                        rr_q = rr_qt
                        Ap, Ap_t = Ap_t, Ap
                        Aq, Aq_t = Aq_t, Aq
                        gp, gp_t = gp_t, gp
                        gq, gq_t = gq_t, gq
                        accepted = True
                        break
            lam *= nu
            nu *= 2.0
        if heading_to_known:
            status = 2
            break
        if converged:
            status = 0
            break
        if not accepted:
            status = 4
            break
        if moved < xtol:
            status = 0
            break
        if _near_known(d, known, n_known, dup_rtol):
            status = 2
            break
    out_d[:] = d
    return cost, it, evals, status
