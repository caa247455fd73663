"""ASLM service: I/O, scheduling, APIs and the command line, on top of :mod:`aslm_core`."""
