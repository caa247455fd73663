"""ANDES as an independent simulator for the benchmarks: IEEE 14-bus scenarios around one load bus.

:mod:`~aslm_sim.andes.scenario` builds the system (the load bus, ambient noise on the other loads, power
flow, time-domain simulation, resampling); :mod:`~aslm_sim.andes.effects` the concealed effects of the
independent diagnosis benchmark; :mod:`~aslm_sim.andes.own_fluctuation` the load's own fluctuation added to a
grid-driven run.  ``andes`` is an optional dependency (the ``andes`` extra): these
modules import it only when a simulation runs, so importing them is cheap and works without it.
"""
