"""A benchmark run under a variant of the diagnosis, for before/after measurements on the same code.

    .venv/bin/python -m benchmarks.diagnosis_variant --reverse-margin 0 independent --set confirm4 --seeds 9303 \
        --kinds clean --noise both --cached-only --workers 1 --tag margin0
    .venv/bin/python -m benchmarks.diagnosis_variant --declare-msd-fd selftest --only motor_stator_dynamics --workers 1
    .venv/bin/python -m benchmarks.diagnosis_variant --no-bound-rule selftest --cases second_motor/1/10 --workers 1

``--reverse-margin X``: every diagnosis with ``DiagnosisConfig(reverse_margin=X)`` (0: the reverse rule of the third
to fifth rounds of issue 12).  ``--no-bound-rule``: ``DiagnosisConfig(bound_rule=False)`` (a name is not withheld
when the plain fit sits on a bound of the box).  ``--declare-msd-fd``: `motor_stator_dynamics` and `frequency_dependence` declared
look-alikes of each other (issue 12, sixth round: with noise on V and θ the lagged frequency term's penalty leaves it
out of the rivals of a stator dynamics that fits the same Δf response, which is then named).  Both are patched in
before the worker processes fork; everything else is the benchmark's own (``independent`` or ``selftest``).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace


def declare_msd_fd() -> None:
    """Each of the two candidates lists the other in ``confusable`` (in this process and the workers it forks)."""
    from aslm_core.diagnosis.candidates import LIBRARY

    for a, b in (("motor_stator_dynamics", "frequency_dependence"), ("frequency_dependence", "motor_stator_dynamics")):
        if b not in LIBRARY[a].confusable:
            LIBRARY[a].confusable = (*LIBRARY[a].confusable, b)


def set_config(**fields) -> None:
    """Make ``DiagnosisConfig()`` — what the benchmarks' ``diagnose`` calls use — carry ``fields`` (a field given
    explicitly by the caller still wins)."""
    from aslm_core.diagnosis import pipeline

    base = pipeline.DiagnosisConfig

    def config(**kw):
        return replace(base(**kw), **{k: kw.get(k, v) for k, v in fields.items()})

    pipeline.DiagnosisConfig = config


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--reverse-margin", type=float, default=None)
    p.add_argument("--declare-msd-fd", action="store_true")
    p.add_argument("--no-bound-rule", action="store_true")
    p.add_argument("benchmark", choices=("independent", "selftest"))
    args, rest = p.parse_known_args(argv)
    if args.declare_msd_fd:
        declare_msd_fd()
    fields = {"reverse_margin": args.reverse_margin, "bound_rule": False if args.no_bound_rule else None}
    if any(v is not None for v in fields.values()):
        set_config(**{k: v for k, v in fields.items() if v is not None})
    if args.benchmark == "independent":
        from benchmarks.diagnosis_independent import main as run
    else:
        from benchmarks.diagnosis import main as run
    return run(rest)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
