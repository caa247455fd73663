"""A benchmark run with `motor_stator_dynamics` and `frequency_dependence` declared look-alikes of each other.

    .venv/bin/python -m benchmarks.diagnosis_confusable independent --set confirm4 --seeds 9301,9303 \
        --kinds frequency_dependence --noise input --cached-only --workers 1 --tag confusable
    .venv/bin/python -m benchmarks.diagnosis_confusable selftest --only motor_stator_dynamics --workers 1 --tag confusable

Measures the declaration before it is made (issue 12, sixth round): with noise on V and θ the lagged frequency term's
penalty leaves it out of the rivals of a stator dynamics that fits the same Δf response, which is then named.  The
declaration is patched into the library before the worker processes fork (``diagnosis_variant --declare-msd-fd``
does the same); everything else is the benchmark's own.
"""

from __future__ import annotations

import sys

from benchmarks.diagnosis_variant import declare_msd_fd


def main(argv: list[str]) -> int:
    which, rest = argv[0], argv[1:]
    declare_msd_fd()
    if which == "independent":
        from benchmarks.diagnosis_independent import main as run
    else:
        from benchmarks.diagnosis import main as run
    return run(rest)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
