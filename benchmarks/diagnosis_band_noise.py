"""One self-test case's band tests against the same tests on its injected noise alone (stop 53).

Stop 52's option ``DiagnosisConfig(exact_inputs_quiet=True)`` turned one clean self-test case at 25 frames/s
(``none/2/1`` and its user-model twin ``none_user/2/1``) from ``consistent`` into ``unexplained``.  Per case and option
this prints the location's band tests on P and Q (each band's mean periodogram over the modelled floor), and the same
tests run on the injected P and Q noise alone (the noisy window minus the clean record, over the same samples) against
that noise's own floor (:func:`aslm_core.noise.noise_floor`).  Where the two agree, the finding is the noise draw's, not
the model's nor the playback's.

    .venv/bin/python -m benchmarks.diagnosis_band_noise [--cases none/2/1,none_user/2/1] [--fs 25]
    .venv/bin/python -m benchmarks.diagnosis_band_noise --white 4000 [--fs 25 [30 ...]] [--seed S] [--out NAME]

``--white N``: the same band tests on N draws of white noise alone over a 10 s window at ``--fs`` (the regression
samples of the self-test's windows), against each draw's own floor: how often some band is significant, which the
test's level (``alpha`` 0.01 over 8 tests, P and Q) puts at 0.005 a channel.  Since stop 54 the diagnosis counts the
floor (a median of M bins) as 2·M·ln² 2 degrees of freedom; ``mean_dof`` is the test before, which counted it as a
mean's 2·M.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402

from benchmarks import diagnosis as selftest  # noqa: E402


def rows(job: tuple, fs: float) -> list[dict]:
    """Per option (default, ``exact_inputs_quiet``) and channel: the verdict, the located channels, the diagnosis's band
    ratios, and the injected noise's band ratios against its own floor."""
    from aslm_core.diagnosis import diagnose
    from aslm_core.diagnosis.locate import band_excess
    from aslm_core.diagnosis.pipeline import DiagnosisConfig
    from aslm_core.diagnosis.segment import make_segment
    from aslm_core.noise import noise_floor

    selftest._init(None, fs)
    base, ec, model, _ = selftest.case(job)
    seg = make_segment(ec.window)
    win = slice(seg.k0, seg.ke)
    out = []
    for quiet in (False, True):
        rep = diagnose(ec.window, model, config=DiagnosisConfig(exact_inputs_quiet=quiet))
        for ch in ("P", "Q"):
            noise = (getattr(base.window, ch) - getattr(base.clean, ch))[win]
            floor = noise_floor(noise, seg.fs)
            alone = band_excess(noise, seg.fs, floor)
            out.append({"case": "/".join(map(str, job)), "quiet": quiet, "verdict": rep.verdict,
                        "located": list(rep.located.channels), "channel": ch,
                        "bands": [b.band for b in rep.located.spectrum[ch]],
                        "ratio": [b.ratio for b in rep.located.spectrum[ch]],
                        "noise_alone_ratio": [b["ratio"] for b in alone],
                        "noise_alone_p": [b["p_value"] for b in alone],
                        "noise_alone_p_mean_dof": [_p_mean_dof(b, noise.size, seg.fs, floor["bins"])
                                                   for b in alone]})
    return out


def _p_mean_dof(band: dict, n: int, fs: float, floor_bins: int) -> float:
    """A band test's p-value as before stop 54: the floor's degrees of freedom those of a mean of its M bins, 2·M."""
    from scipy import stats

    return float(stats.f.sf(band["ratio"], 2 * _bins(band["band"], n, fs), 2 * floor_bins))


def white_false_alarms(draws: int, fs: float, seed: int = 3) -> dict[str, float]:
    """Share of white-noise draws (the samples a 10 s window's location tests, from 1 s to 0.1 s before its end) in
    which some band of :func:`~aslm_core.diagnosis.locate.band_excess` is significant against the draw's own floor
    (``diagnosis``: the floor a median of M bins, 2·M·ln² 2 degrees of freedom), and the same with the floor taken
    as a mean of its M bins, 2·M (``mean_dof``, the test before stop 54)."""

    import numpy as np

    from aslm_core.diagnosis.locate import band_excess
    from aslm_core.noise import noise_floor

    n = int(round(10.0 * fs)) - int(round(1.0 * fs)) - max(1, int(round(0.1 * fs)))
    rng = np.random.default_rng(seed)
    hits = {"diagnosis": 0, "mean_dof": 0}
    for _ in range(draws):
        e = rng.standard_normal(n)
        floor = noise_floor(e, fs)
        bands = band_excess(e, fs, floor)
        hits["diagnosis"] += any(b["significant"] for b in bands)
        hits["mean_dof"] += any(_p_mean_dof(b, n, fs, floor["bins"]) < 0.01 / 8 for b in bands)
    return {k: v / draws for k, v in hits.items()}


def _bins(band: list[float], n: int, fs: float) -> int:
    """Periodogram bins of n samples at fs in [lo, hi) (as :func:`~aslm_core.diagnosis.locate.band_excess` counts)."""
    import numpy as np

    f = np.fft.rfftfreq(n, 1.0 / fs)
    return int(((f >= band[0]) & (f < band[1])).sum())


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="none/2/1,none_user/2/1", help="effect/level/i, comma-separated")
    ap.add_argument("--fs", type=float, nargs="+", default=[25.0], help="reporting rate(s) [frames/s]")
    ap.add_argument("--white", type=int, default=0, metavar="N", help="the false-alarm share on N white-noise draws")
    ap.add_argument("--seed", type=int, default=3, help="the white-noise draws' seed")
    ap.add_argument("--out", default="", help="write docs/results/<out>.json")
    args = ap.parse_args(argv)
    if args.white:
        out = []
        for fs in args.fs:
            share = white_false_alarms(args.white, fs, args.seed)
            se = (0.005 * 0.995 / args.white) ** 0.5
            print(f"{fs:g} frames/s, {args.white} draws of white noise alone (seed {args.seed}): some band significant "
                  f"in {share['diagnosis']:.4f} (the diagnosis), {share['mean_dof']:.4f} (the floor as a mean, before "
                  f"stop 54); the level 0.0050, its simulation error ±{se:.4f}")
            out.append({"fs": fs, "draws": args.white, "seed": args.seed, **share})
        _write(args.out, out)
        return out
    out = []
    for item in args.cases.split(","):
        effect, level, i = item.split("/")
        out += rows((effect, int(level), int(i)), args.fs[0])
    for r in out:
        print(f"{r['case']:16s} quiet={str(r['quiet']):5s} {r['verdict']:12s} located {r['located']!s:10s} "
              f"{r['channel']}: diagnosis " + " / ".join(f"{x:.2f}" for x in r["ratio"])
              + "   noise alone " + " / ".join(f"{x:.2f}" for x in r["noise_alone_ratio"])
              + "   its p " + " / ".join(f"{x:.1e}" for x in r["noise_alone_p"])
              + " (the floor as a mean, before stop 54: " + " / ".join(f"{x:.1e}" for x in r["noise_alone_p_mean_dof"])
              + ")")
    _write(args.out, out)
    return out


def _write(name: str, rows: list[dict]) -> None:
    """docs/results/<name>.json, if a name is given."""
    if name:
        import json
        from pathlib import Path

        path = Path(__file__).resolve().parent.parent / "docs" / "results" / f"{name}.json"
        path.write_text(json.dumps(rows, indent=1) + "\n")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
