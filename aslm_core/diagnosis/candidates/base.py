"""What every candidate physics is: a small extension of ZIP + IM fitted in the hierarchical framework.

A candidate maps (D, z) — the motor parameters D = [a, b, H2, Tm] and its own nonlinear parameters z —
to a :class:`Prediction`: the part of P and Q that is nonlinear in the parameters (``mp``, ``mq``) and
the columns that enter linearly (``xp``, ``xq``: the static regressors plus the candidate's linear
extras).  The engine (:mod:`aslm_core.diagnosis.engine`) then does what the identifier does: the lower
stage regresses the linear coefficients on the training samples, the upper stage optimises (D, z).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aslm_core import motor, static
from aslm_core.diagnosis.segment import Segment

#: A fitted parameter this close to a bound of its box, as a share of the box's width, sits on the bound: a
#: converged fit reaches a binding bound to rounding (1e-12 on the out-of-box ANDES windows), one stopped at its
#: evaluation cap only nearly.
BOUND_TOL = 1e-3


@dataclass
class Context:
    """The model being diagnosed.

    Attributes
    ----------
    mode : {"identified", "user"}
        ``identified``: D and the ZIP coefficients are free (re-fitted with each candidate).
        ``user``: the user's model is frozen — D and the static part are fixed, only the operating
        point (a constant per channel) is re-aligned; candidates add their own parameters on top.
    d0 : ndarray
        D of the model (identified: the plain fit on the training samples; user: the given one).
    static_user : dict or None
        The user's static coefficients (ZIP or exponential, see :func:`aslm_core.static.static_power`).
    """

    mode: str
    d0: np.ndarray
    static_user: dict | None = None
    extras: dict = field(default_factory=dict)

    @property
    def free(self) -> bool:
        return self.mode == "identified"


@dataclass
class Prediction:
    """Model output of one candidate for given parameters.

    Attributes
    ----------
    mp, mq : ndarray, shape (n,)
        Parts of P and Q not linear in coefficients (motor, fixed user static) [pu].
    xp, xq : ndarray, shape (n, k)
        Columns entering P and Q linearly (static regressors first, then the candidate's extras).
    """

    mp: np.ndarray
    mq: np.ndarray
    xp: np.ndarray
    xq: np.ndarray


def simulate_motor(seg: Segment, d: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """P_im, Q_im of eq. 4–5 driven by the segment's voltage (RK4, steady-state start) [pu].

    Returns None when D has no equilibrium or the trajectory diverges.
    """
    d = np.ascontiguousarray(d, dtype=np.float64)
    v2 = seg.vd[0] ** 2 + seg.vq[0] ** 2
    if d[0] * v2 <= 2.0 * d[1] * d[3] or d[1] <= 0 or d[2] <= 0:
        return None
    n = seg.n
    p = np.empty(n)
    q = np.empty(n)
    x = np.empty((n, 3))
    dummy = np.empty((1, 4))
    ok = motor.simulate_kernel(seg.vd, seg.vq, seg.vdm, seg.vqm, d, seg.dt, seg.omega0, True, False, p, q,
                               dummy, dummy, x, True, 0, p, q, dummy)
    return (p, q) if ok else None


def static_part(seg: Segment, ctx: Context, V: np.ndarray | None = None):
    """Static load in the lower stage: fixed part and regressors for P and Q.

    Identified mode: nothing fixed, regressors [1, V, V²] (eq. 6).  User mode: the user's static power is
    fixed, the regressor is [1] (operating-point alignment).

    Returns
    -------
    fp, fq : ndarray
        Fixed static P, Q [pu].
    sx : ndarray, shape (n, 3) or (n, 1)
        Static regressors (the same for both channels).
    """
    global _LAST_STATIC
    V = seg.V if V is None else V
    # The upper stage asks for the same V and model at every residual evaluation: the last answer is kept
    # (keyed on the objects themselves, read-only so that no caller can change it for the next one).
    last = _LAST_STATIC
    if last is not None and last[0] is V and last[1] is ctx and last[2] is ctx.static_user and last[3] == ctx.mode:
        return last[4]
    if ctx.free:
        out = np.zeros_like(V), np.zeros_like(V), static.regressors(V, "zip")
    else:
        fp, fq = static.static_power(V, ctx.static_user)
        out = fp, fq, np.ones((V.shape[0], 1))
    for a in out:
        a.setflags(write=False)
    _LAST_STATIC = (V, ctx, ctx.static_user, ctx.mode, out)
    return out


_LAST_STATIC: tuple | None = None  # (V, ctx, its static_user, its mode, static_part's answer)


class Candidate:
    """Base class: the plain ZIP + IM model (no extension).

    Subclasses set the class attributes and override :meth:`predict` (or :meth:`extra_columns`).

    Attributes
    ----------
    name : str
        Library name (the JSON ``name``).
    nl_names, nl_units : tuple of str
        The candidate's nonlinear parameters z (upper stage) and their units.
    lin_p, lin_q : tuple of str
        Names of the linear extra coefficients on P and on Q (lower stage).
    lin_units : dict
        Units of the linear coefficients.
    signature : str
        What in the residual makes this candidate plausible (shown in reports).
    magnitude : tuple of str
        The parameters that are zero when the physics is absent (e.g. the second motor's torque); a
        candidate is only named if at least one of them is at least ``magnitude_z_min`` standard errors
        from zero.
    magnitude_z_min : float
        That threshold [-] (2 by default).
    scanned : tuple of str
        Nonlinear parameters of a discrete law (thresholds, delays), chosen by a scan in :meth:`starts`: the
        residual is piecewise constant in them, so they have no standard error (left out of ``stderr``).
    confusable : tuple of str
        Candidates that produce a similar signature from other physics: this one is named only when the
        paired held-out test separates it from each of them (whether or not they are significant themselves).
    motor_form : bool
        The candidate changes or extends the induction motor itself (its circuit, rotor, torque law, or a
        second group), so its fit re-places D: a motor-form cause whose D stays on the plain fit's bound has
        not undone what pinned it (``DiagnosisConfig.bound_rule``).
    broadband : bool
        The candidate is a linear response to V at every frequency (a droop), so a real one improves the held-out
        fit wherever V moves: its held-out gain outside the narrow band where its correction peaks must be positive,
        else it is refuted like an implausible fit (:func:`aslm_core.diagnosis.pipeline.off_peak_gain`).
    time_ordered_only : bool
        The candidate's law is learnt from discrete events in its training samples (a relay's switchings and its
        state before them), so it is judged on the time-ordered fold only: a cross-fitted window's mirrored fold
        trains on the window's later part, which need not hold an event its held-out samples hold
        (``DiagnosisConfig.cross_fit``).
    """

    name = "plain"
    nl_names: tuple[str, ...] = ()
    nl_units: tuple[str, ...] = ()
    lin_p: tuple[str, ...] = ()
    lin_q: tuple[str, ...] = ()
    lin_units: dict[str, str] = {}
    signature = ""
    magnitude: tuple[str, ...] = ()
    magnitude_z_min = 2.0
    scanned: tuple[str, ...] = ()
    confusable: tuple[str, ...] = ()
    motor_form = False
    broadband = False
    time_ordered_only = False
    max_nfev = 40  # upper-stage function evaluations per start (each iteration adds a Jacobian)

    @property
    def n_params(self) -> int:
        """Parameters added to ZIP + IM (the penalty's k)."""
        return len(self.nl_names) + len(self.lin_p) + len(self.lin_q)

    def not_applicable(self, ctx: Context) -> str | None:
        """Why the candidate cannot be tested against this model (None: it can)."""
        return None

    def starts(self, seg: Segment, ctx: Context) -> list[np.ndarray]:
        """Initial z values (one upper-stage run per start)."""
        return [np.zeros(0)]

    def bounds(self, seg: Segment, ctx: Context) -> tuple[np.ndarray, np.ndarray]:
        """Box bounds of z."""
        return np.zeros(0), np.zeros(0)

    def extra_columns(self, seg: Segment, d: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Linear extra columns for P and Q, shapes (n, len(lin_p)) and (n, len(lin_q))."""
        n = seg.n
        return np.zeros((n, 0)), np.zeros((n, 0))

    def motor_power(self, seg: Segment, d: np.ndarray, z: np.ndarray):
        """Motor P, Q [pu] (plain eq. 4–5 unless overridden); None on failure."""
        return simulate_motor(seg, d)

    def predict(self, seg: Segment, ctx: Context, d: np.ndarray, z: np.ndarray) -> Prediction | None:
        """Model output for (D, z): motor + static + linear extras."""
        m = self.motor_power(seg, d, z)
        if m is None:
            return None
        fp, fq, sx = static_part(seg, ctx)
        ep, eq = self.extra_columns(seg, d, z)
        return Prediction(m[0] + fp, m[1] + fq, np.hstack([sx, ep]), np.hstack([sx, eq]))

    def implausible(self, params: dict[str, float], seg: Segment, ctx: Context) -> str | None:
        """Why fitted parameters are outside what the physics can be (None: plausible); such a fit is never
        significant, however well it predicts (it is fitting something else)."""
        return None

    def describe(self, params: dict[str, float], seg: Segment, ctx: Context) -> dict[str, float]:
        """Derived quantities worth reporting (e.g. an exponent from a coefficient); default none."""
        return {}
