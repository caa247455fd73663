"""Where in frequency ``inverter_der``'s held-out improvement lies (issue 12, stop 32).

    .venv/bin/python -m benchmarks.der_tone --sets confirm6,confirm7,confirm8,confirm9,confirm10 --self-test 12

For each window it fits the plain model and ``inverter_der`` exactly as the diagnosis does (its ``_analyse`` with
the library reduced to that one candidate) and splits the held-out comparison per ambient-band DCT coefficient k
(frequency k·fs/(2n) [Hz]) of P and Q, noise-weighted by the noise model's per-coefficient variances v_k:

* the gain per coefficient, g_k = (R_k² − (R_k − D_k)²)/v_k, R the plain model's held-out residual and D the
  candidate's held-out correction; their sum is the numerator of the explained fraction;
* the *tone*: the ±``--half-width`` Hz around the frequency where D's own weighted power D_k²/v_k (P and Q summed,
  three bins smoothed) peaks — for an oscillating load its line, for a real droop wherever V's ambient part is largest;
* ``tone_share``: the share of Σg_k inside the tone;
* ``z_all`` and ``z_off``: the score statistic ΣR_k·D_k/v_k / √(ΣD_k²/v_k) over all coefficients and over those
  outside the tone (P and Q covariance ignored: a measurement, not the pipeline's test).

Only cached ANDES recordings are read (never simulated); raw records to ``docs/results/der_tone.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

RESULTS = ROOT / "docs" / "results"
FORBIDDEN = ("confirm11",)


def spectral_split(a, half_width: float) -> dict:
    """The held-out comparison of ``inverter_der`` against the plain fit of one window analysis, per frequency."""
    from aslm_core.diagnosis.noise import dct_band

    seg, noise = a.seg, a.noise
    te = seg.test
    vp, vq, _ = noise.coefficients(te)
    f1 = a.fits["inverter_der"]
    n = te.stop - te.start
    gains, rd, dd = [], [], []
    for y, m0, m1, v in ((seg.P, a.plain.model_p, f1.model_p, vp), (seg.Q, a.plain.model_q, f1.model_q, vq)):
        c = dct_band(np.column_stack([(y - m0)[te], (m1 - m0)[te]]), noise.fs, noise.band_hz)
        r, d = c[:, 0], c[:, 1]
        gains.append((r * r - (r - d) ** 2) / v)
        rd.append(r * d / v)
        dd.append(d * d / v)
    g, rd, dd = (np.sum(x, axis=0) for x in (gains, rd, dd))
    f = np.arange(g.size) * noise.fs / (2.0 * n)
    peak = float(f[int(np.argmax(np.convolve(dd, np.ones(3) / 3, mode="same")))])
    tone = np.abs(f - peak) <= half_width
    off = ~tone
    z_all = float(rd.sum() / np.sqrt(dd.sum())) if dd.sum() > 0 else 0.0
    z_off = float(rd[off].sum() / np.sqrt(dd[off].sum())) if dd[off].sum() > 0 else 0.0
    return {"peak_hz": peak, "tone_share": float(g[tone].sum() / g.sum()) if g.sum() != 0 else None,
            "gain_sum": float(g.sum()), "gain_tone": float(g[tone].sum()), "gain_off": float(g[off].sum()),
            "z_all": z_all, "z_off": z_off, "bin_hz": float(f[1]), "tone_bins": int(tone.sum()),
            "gain_bins": [round(float(x), 2) for x in g[:12]], "corr_bins": [round(float(x), 2) for x in dd[:12]],
            "params": {k: float(v) for k, v in f1.params.items() if not k.startswith("D.")}}


def analyse(w, half_width: float) -> dict:
    from aslm_core.diagnosis.pipeline import DiagnosisConfig, _analyse

    a = _analyse(w, None, None, DiagnosisConfig(candidates=("inverter_der",)))
    return spectral_split(a, half_width)


def andes_records(sets: list[str], half_width: float, kinds: list[str]) -> list[dict]:
    from aslm_sim.andes.effects import cache_dir, recording
    from benchmarks.diagnosis_independent import LEVELS, SETS, TF, TSTEP, WINDOWS, _window

    out = []
    for s in sets:
        if s in FORBIDDEN:
            raise SystemExit(f"{s} is the fresh confirmation set: never looked at")
        for kind in kinds:
            for seed in SETS[s]["clean" if kind == "clean" else "effect"]:
                if not any(cache_dir().glob(f"v*-{kind}-{seed}-*.npz")):
                    continue
                rec = recording(kind, seed, tf=TF, tstep=TSTEP)
                own = rec["meta"]["drawn"].get("effect", {}).get("own", {})
                for input_noise in (False, True):
                    for t0, t1 in WINDOWS:
                        for level in LEVELS:
                            w, _ = _window(rec, t0, t1, level, input_noise, f"{kind}/{seed}")
                            r = analyse(w, half_width)
                            r.update(set=s, kind=kind, seed=seed, window=[t0, t1], level=level,
                                     input_noise=input_noise, own_hz=own.get("hz"))
                            out.append(r)
                            print(json.dumps({k: r[k] for k in ("kind", "seed", "window", "level", "input_noise",
                                                                "own_hz", "peak_hz", "tone_share", "z_all", "z_off")}),
                                  flush=True)
    return out


def self_test_records(n: int, half_width: float, effects: list[str]) -> list[dict]:
    from benchmarks.diagnosis import LEVELS, case

    out = []
    for eff in effects:
        for level in LEVELS:
            for i in range(n):
                _, ec, _, _ = case((eff, level, i, False))
                r = analyse(ec.window, half_width)
                r.update(set="self-test", kind=eff, level=level, case=i, truth={k: float(v) for k, v in ec.truth.items()})
                out.append(r)
                print(json.dumps({k: r[k] for k in ("kind", "level", "case", "peak_hz", "tone_share", "z_all", "z_off")}),
                      flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sets", default="", help="comma-separated sets of benchmarks.diagnosis_independent (cached only)")
    p.add_argument("--kinds", default="oscillating_load")
    p.add_argument("--self-test", type=int, default=0, metavar="N", help="cases per level of the self-test's effects")
    p.add_argument("--effects", default="inverter_der,none")
    p.add_argument("--half-width", type=float, default=0.15, help="half-width of the tone band [Hz]")
    p.add_argument("--out", default="der_tone")
    args = p.parse_args(argv)
    recs = []
    if args.sets:
        recs += andes_records(args.sets.split(","), args.half_width, args.kinds.split(","))
    if args.self_test:
        recs += self_test_records(args.self_test, args.half_width, args.effects.split(","))
    (RESULTS / f"{args.out}.json").write_text(json.dumps({"argv": sys.argv[1:], "half_width_hz": args.half_width,
                                                          "records": recs}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
