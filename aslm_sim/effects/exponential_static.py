"""Exponential static load: the static P and Q get non-integer voltage exponents.

The exponents move by ± magnitude from the ZIP's local exponent at the first sample, so the static part
changes shape, not operating point.  Not detectable against a re-identified ZIP (see the candidate's
module): the case carries a user model (the true ZIP + IM with the old exponents) to be diagnosed with
``model=``.  Magnitude: |np − n_ZIP| [-].
"""

from __future__ import annotations

import numpy as np

from aslm_sim.cases import SyntheticCase
from aslm_sim.effects.base import Effect, EffectOutput


def generate(case: SyntheticCase, magnitude: float, rng: np.random.Generator) -> EffectOutput:
    """ΔP, ΔQ [pu] and the exponents {np, nq} [-] (see :class:`~aslm_sim.effects.base.Effect`)."""
    w = case.clean
    # Exponents of the static part as the identifier sees it (Qz includes the motor's V²/X').
    st = case.truth.static_identifiable
    v0 = float(w.V[0])
    ps0 = st["Pz"] * v0**2 + st["Pi"] * v0 + st["Pp"]
    qs0 = st["Qz"] * v0**2 + st["Qi"] * v0 + st["Qp"]
    n_zip_p = (2 * st["Pz"] * v0**2 + st["Pi"] * v0) / ps0
    n_zip_q = (2 * st["Qz"] * v0**2 + st["Qi"] * v0) / qs0
    np_ = n_zip_p + magnitude * rng.choice([-1.0, 1.0])
    nq_ = n_zip_q + magnitude * rng.choice([-1.0, 1.0])
    vr = w.V / v0
    ps_zip = st["Pz"] * w.V**2 + st["Pi"] * w.V + st["Pp"]
    qs_zip = st["Qz"] * w.V**2 + st["Qi"] * w.V + st["Qp"]
    return ps0 * vr**np_ - ps_zip, qs0 * vr**nq_ - qs_zip, {"np": np_, "nq": nq_}


EFFECT = Effect(name="exponential_static", generate=generate, magnitude=(0.7, 1.5), channels="PQ",
                in_library=True, label="exp", main_parameter="np", user_model=True)
