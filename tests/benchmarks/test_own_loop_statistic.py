"""The loop statistic of ``benchmarks.own_hausman``: the own fluctuation's feedback through the network, seen per window."""

from aslm_core import identify
from aslm_sim.cases import make_cases
from benchmarks.own_fluctuation import LEVEL, own_cases
from benchmarks.own_hausman import PEM, Z_LOOP, loop_z
from benchmarks.own_loop import open_loop_window


def test_loop_statistic_sees_switching_through_the_network_and_nothing_with_the_loop_cut():
    base = make_cases(3, level=LEVEL, seed=243, input_noise=False)
    for b, c in zip(base, own_cases(3, 0.9, "switching", base, 243, 1.0), strict=True):
        closed, cut = c.window, open_loop_window(b, c)
        # The same own ΔP and ΔQ in P and Q both times; only the closed window's V carries its innovations.
        assert loop_z(closed, identify(closed, config=PEM).d) < -3 * Z_LOOP
        assert abs(loop_z(cut, identify(cut, config=PEM).d)) < Z_LOOP
