"""The network's vectors are addressed by name: one declaration of each layout, and a row that says what it holds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from aslm_sim import network
from aslm_sim.network import NPAR, NX, PARAMETER_FIELDS, STATE_FIELDS, Par, State
from aslm_sim.truth import random_truth


@pytest.mark.parametrize(("enum", "fields", "size"), [(Par, PARAMETER_FIELDS, NPAR), (State, STATE_FIELDS, NX)])
def test_layout_is_contiguous_in_declaration_order(enum, fields, size):
    assert [m.name for m in enum] == [f[0] for f in fields]
    offsets = [int(m) for m in enum]
    lengths = [f[1] for f in fields]
    assert offsets == [sum(lengths[:i]) for i in range(len(fields))]
    assert size == sum(lengths)
    assert all(f[2] and "[" in f[2] for f in fields), "every field says what it is and its unit"


def test_steady_state_row_holds_each_quantity_under_its_name():
    rng = np.random.default_rng(8)
    tr = random_truth(rng)
    net = network.draw_network(rng, tr, 60.0)
    p, x0, vl0 = network.steady_state(tr, net)
    assert p.shape == (NPAR,) and x0.shape == (NX,)
    assert (p[Par.XP], p[Par.H2], p[Par.TM]) == (tr.Xp, tr.H2, tr.Tm)
    assert (p[Par.PZ], p[Par.QP]) == (tr.Pz, tr.Qp)
    for field, key in ((Par.ZS, "z_s"), (Par.ZG, "z_g"), (Par.ZL, "z_L"), (Par.ZN, "z_N")):
        assert complex(p[field], p[field + 1]) == net[key]
    assert (p[Par.PN], p[Par.QN]) == (net["P_N"], net["Q_N"])
    assert p[Par.W0] == pytest.approx(2 * math.pi * 60.0)
    assert (p[Par.VS], p[Par.VS + 1], p[Par.YF], p[Par.YF + 1]) == (1.0, 0.0, 0.0, 0.0)
    assert x0[State.DOMEGA] == 0.0
    assert x0[State.S] == pytest.approx(tr.slip0(abs(vl0), 60.0), rel=1e-12)
    # The motor's E' as the network sees it: the motor's current (V − E')/jX' carries its P.
    e_m = complex(x0[State.ED], x0[State.EQ])
    assert (vl0 * ((vl0 - e_m) / (1j * tr.Xp)).conjugate()).real == pytest.approx(tr.Tm, rel=1e-9)
