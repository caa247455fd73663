"""``exponential_static``: static load with non-integer voltage exponents, P = P0·V^np, Q = Q0·V^nq.

Notes
-----
Lower-stage extra columns ln V on P and Q (the exponential model's first-order regressor, exact to
O((ln V)²), as in :func:`aslm_core.static.regressors`)::

    P = P_static(V) + cP·ln V,   Q = Q_static(V) + cQ·ln V

Parameters: cP, cQ [pu] — the change of V·dP/dV of the static part; the exponent is
np = (V·dPs/dV + cP)/Ps at the mean voltage [-] (reported as ``np``, ``nq``).

Identifiability with ambient data, honestly: ambient V moves by a few tenths of a percent, over which
ZIP's [1, V, V²] reproduces V^n to O(ΔV³) ≈ 1e-8 — ln V lies in the span of the ZIP regressors to that
order.  So when the static part is re-identified (the default), a non-integer exponent is NOT detectable
and this candidate cannot improve the fit; what ambient data fix is the static part's local slope dP/dV
(hence one "effective exponent" per channel), not its shape.  The candidate is useful against a
*user-supplied* model (``--model``, e.g. a planning database's ZIP with the wrong voltage dependence):
then the static slope is frozen and the residual is coherent with V (in phase, no lag).

Signature: residual coherent with V (not with dV/dt or Δf), in phase.
"""

from __future__ import annotations

import numpy as np

from aslm_core import static
from aslm_core.diagnosis.candidates.base import Candidate, Context
from aslm_core.diagnosis.segment import Segment


class ExponentialStatic(Candidate):
    name = "exponential_static"
    magnitude = ("cP", "cQ")
    lin_p = ("cP",)
    lin_q = ("cQ",)
    lin_units = {"cP": "pu", "cQ": "pu", "np": "-", "nq": "-"}
    signature = "residual coherent with V in phase (only detectable against a frozen user model)"

    def not_applicable(self, ctx: Context) -> str | None:
        if ctx.free:
            return ("not identifiable with ambient data against a re-identified ZIP: over the ambient voltage "
                    "range [1, V, V²] reproduces V^n to O(ΔV³); diagnose against a user model (--model) instead")
        return None

    def extra_columns(self, seg: Segment, d: np.ndarray, z: np.ndarray):
        col = np.log(seg.V)[:, None]
        return col, col

    def describe(self, params: dict[str, float], seg: Segment, ctx: Context) -> dict[str, float]:
        if ctx.free or ctx.static_user is None:
            return {}
        vm = float(np.mean(seg.V))
        h = 1e-4
        p0, q0 = static.static_power(np.array([vm]), ctx.static_user)
        p1, q1 = static.static_power(np.array([vm * (1 + h)]), ctx.static_user)
        out = {}
        for name, c, y0, y1 in (("np", params.get("cP", 0.0), p0[0], p1[0]), ("nq", params.get("cQ", 0.0), q0[0], q1[0])):
            slope = (y1 - y0) / h  # V·dY/dV at vm
            if abs(y0) > 1e-9:
                out[name] = float((slope + c) / y0)
        return out


#: The library entry (registered by module name in :mod:`aslm_core.diagnosis.candidates`).
CANDIDATE = ExponentialStatic()
