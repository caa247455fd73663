"""The candidates' fits on noisy V and θ against their noise-free fits, per window (issue 12, stop 31).

    PYTHONPATH=$PWD .venv/bin/python -m benchmarks.diagnosis_eiv --cases confirm8:frequency_dependence \
        --out diagnosis_eiv_confirm8

For each window of the cached scenarios asked (``set:kind[:seed[:t0]]``; default every seed of the set's kind, both
windows), the noise-free recording is fitted by the plain model and the candidates exactly as the separability
oracle fits them (``diagnosis_detectability.noise_free_plain``, ``engine.fit_candidate``), and the bench's noisy
window (``diagnosis_independent._window``) at each level goes through the diagnosis's analysis (``pipeline._analyse``,
the candidates asked only) in variants that move one suspect at a time (:data:`VARIANTS`): ``vt`` the V/θ mode as
the diagnosis runs it; ``vt_smoothed_columns`` with Δf and dV/dt built from the Wiener conditional mean of V and θ;
``vt_clean_columns`` with them taken from the P/Q-mode window (no input noise); ``vt_tf_clean`` with the frequency
term's lag held at its noise-free fit's; ``vt_wiener_inputs`` with the model's inputs V and θ replaced by their
Wiener conditional mean too (regression calibration of the whole fit; its z and gain are not the diagnosis's);
``v_only`` / ``theta_only`` with the input noise on V or on θ alone; ``pq`` the P/Q mode.  Per case: each
candidate's own parameters, score z and penalised gain, the verdict's paired z of each candidate over each other
one (``pipeline.paired_comparisons``), the plain D, the lag scan's start, and the Δf and dV/dt
columns against the noise-free window's on the training samples in the fits' band (DCT coefficients 0–5 Hz): the
error's rms over the signal's, and the attenuation λ = cov(x₀, x)/var(x) (1: a consistent regressor; < 1: a
coefficient fitted on it shrinks by λ).
Reads cached recordings only; simulates nothing.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "docs" / "results"
CANDS = ("frequency_dependence", "motor_stator_dynamics", "speed_dependent_torque")


def _band(x: np.ndarray, seg, band_hz: float) -> np.ndarray:
    from aslm_core.diagnosis.noise import dct_band

    tr = seg.train
    return dct_band(x[tr] - np.mean(x[tr]), seg.fs, band_hz)


def column_quality(seg, seg0, band_hz: float) -> dict:
    """Δf and dV/dt of a noisy segment against the noise-free one's, on the training samples in the band."""
    out = {}
    for name in ("dfreq", "dvdt"):
        x, x0 = _band(getattr(seg, name), seg, band_hz), _band(getattr(seg0, name), seg0, band_hz)
        e = x - x0
        out[name] = {"err_over_signal": float(np.linalg.norm(e) / np.linalg.norm(x0)),
                     "attenuation": float(x0 @ x / (x @ x))}
    return out


def _fit_row(fit, comp) -> dict:
    return {"ok": bool(fit.ok), "params": {k: round(float(v), 6) for k, v in fit.params.items()},
            "z": None if comp is None else float(comp.score_z),
            "gain": None if comp is None else float(comp.penalised_gain)}


VARIANTS = ("vt", "vt_smoothed_columns", "vt_clean_columns", "vt_tf_clean", "vt_wiener_inputs", "v_only",
            "theta_only", "pq")


def smoothed_columns(window, seg):
    """Δf and dV/dt as ``make_segment`` builds them, but from the Wiener conditional mean of V and θ given the
    window (:func:`aslm_core.preprocess.prepare` with ``input_smoother="wiener"``; exact inputs pass unchanged)."""
    import math

    from aslm_core.diagnosis.segment import FREQ_LOWPASS_HZ, _lowpass
    from aslm_core.preprocess import prepare

    drv = prepare(window, input_smoother="wiener")
    df = np.gradient(drv.theta, seg.dt) / (2.0 * math.pi)
    df = _lowpass(df - np.median(df), seg.fs, FREQ_LOWPASS_HZ)
    return df, _lowpass(np.gradient(drv.V, seg.dt), seg.fs, FREQ_LOWPASS_HZ)


def _variant_segment(variant: str, wn, sn, sp, config):
    """The segment a variant's analysis runs on (``sn``/``sp``: the V/θ-noisy and the P/Q-noisy segments)."""
    from dataclasses import replace

    from aslm_core import Window
    from aslm_core.diagnosis.segment import make_segment
    from aslm_core.preprocess import prepare

    if variant == "vt_smoothed_columns":
        df, dv = smoothed_columns(wn, sn)
        return replace(sn, dfreq=df, dvdt=dv)
    if variant == "vt_wiener_inputs":  # the model's inputs V and θ too (regression calibration of the whole fit)
        pr = prepare(wn, input_smoother="wiener")
        return make_segment(Window(pr.t, pr.V, pr.theta, wn.P, wn.Q, f0=wn.f0, bus=wn.bus),
                            skip_s=config.skip_s, train_fraction=config.train_fraction)
    return {"vt": sn, "vt_tf_clean": sn, "vt_clean_columns": replace(sn, dfreq=sp.dfreq, dvdt=sp.dvdt),
            "v_only": replace(sn, theta=sp.theta, dfreq=sp.dfreq), "theta_only": replace(sn, V=sp.V, dvdt=sp.dvdt),
            "pq": sp}[variant]


def _paired(a, cands: tuple[str, ...], config) -> dict:
    """The verdict's paired held-out z of each candidate over each other one ("x>y": x explains what y leaves)."""
    from aslm_core.diagnosis.pipeline import paired_comparisons

    out = {}
    for x in cands:
        for y in cands:
            if x != y and x in a.fits and y in a.fits:
                comps = paired_comparisons([a], x, y, config)
                out[f"{x}>{y}"] = None if comps is None else float(comps[0].score_z)
    return out


def run_window(kind: str, seed: int, t0: float, cands: tuple[str, ...], levels: tuple[int, ...],
               variants: tuple[str, ...] = VARIANTS) -> dict:
    """One window: the noise-free fits and, per level and variant, the noisy analysis's fits."""
    from aslm_core.diagnosis import engine, pipeline
    from aslm_core.diagnosis.candidates import LIBRARY
    from aslm_core.diagnosis.candidates.frequency_dependence import TF_GRID_S
    from aslm_core.diagnosis.lag import lag_start
    from aslm_core.diagnosis.segment import make_segment
    from aslm_sim.andes.effects import recording
    from benchmarks.diagnosis_detectability import noise_free_plain
    from benchmarks.diagnosis_independent import TF, TSTEP, WINDOWS, _window

    config = pipeline.DiagnosisConfig(candidates=cands)
    rec = recording(kind, seed, tf=TF, tstep=TSTEP)
    t1 = dict(WINDOWS)[t0]
    seg0, ctx0, noise0, plain0, _ = noise_free_plain(rec, t0, t1, config)
    clean = {n: _fit_row(engine.fit_candidate(LIBRARY[n], seg0, ctx0, noise0, d_start=plain0.d), None) for n in cands}
    out = {"kind": kind, "seed": seed, "window": [t0, t1], "clean_plain_d": [float(v) for v in plain0.d],
           "clean": clean, "cases": []}
    fd = LIBRARY["frequency_dependence"]
    tf0 = clean.get("frequency_dependence", {}).get("params", {}).get("Tf")
    orig = pipeline.make_segment
    try:
        for level in levels:
            wn, snr = _window(rec, t0, t1, level, True, f"{kind}/{seed}")
            wp, _ = _window(rec, t0, t1, level, False, f"{kind}/{seed}")
            kw = {"skip_s": config.skip_s, "train_fraction": config.train_fraction}
            sn, sp = make_segment(wn, **kw), make_segment(wp, **kw)
            for variant in variants:
                if variant == "vt_tf_clean" and tf0 is None:
                    continue
                seg = _variant_segment(variant, wn, sn, sp, config)
                pipeline.make_segment = lambda *a, _s=seg, **k: _s
                if variant == "vt_tf_clean":  # the lag held at the noise-free fit's (an instance attribute, undone)
                    fd.bounds = lambda s, c, _t=tf0: (np.array([_t * 0.999]), np.array([_t * 1.001]))
                    fd.starts = lambda s, c, _t=tf0: [np.array([_t])]
                c0 = time.process_time()
                try:
                    a = pipeline._analyse(wp if variant == "pq" else wn, None, None, config)
                finally:
                    fd.__dict__.pop("bounds", None)
                    fd.__dict__.pop("starts", None)
                out["cases"].append({
                    "level": level, "snr_db": snr, "variant": variant, "cpu_s": time.process_time() - c0,
                    "plain_d": [float(v) for v in a.plain.d],
                    "tf_scan": lag_start(a.seg, a.ctx, a.seg.dfreq, TF_GRID_S, 0.0),
                    "columns": column_quality(a.seg, seg0, config.band_hz),
                    # z and gain of the Wiener-input variant are not the diagnosis's: its noise model sees
                    # smoothed inputs (no white floor) and leaves the smoother's error out.
                    "fits": {n: _fit_row(a.fits[n], a.comps.get(n)) for n in cands if n in a.fits},
                    "paired": _paired(a, cands, config)})
    finally:
        pipeline.make_segment = orig
    return out


def _median(xs: list) -> float:
    xs = [x for x in xs if x is not None and np.isfinite(x)]
    return float(np.median(xs)) if xs else float("nan")


def summarise(windows: list[dict], oracle_sets: tuple[str, ...] = ("confirm7", "confirm8")) -> dict:
    """Per variant (frequency-term windows): the lag, the coefficients and D against the noise-free fit, the score
    z's and the paired z's; per case the V/θ-mode figures beside the separability oracle's
    (``diagnosis_separability_<set>.json``, forward z of the true form over each rival, same window and level)."""
    from benchmarks.diagnosis_independent import SETS

    oracle, verdict = {}, {}
    for set_name in oracle_sets:
        path = RESULTS / f"diagnosis_separability_{set_name}.json"
        if not path.exists():
            continue
        sep = json.loads(path.read_text())
        for w in sep["windows"]:
            for lv, row in w["levels"].items():
                oracle[(w["kind"], int(w["seed"]), float(w["window"][0]), int(lv))] = row.get("input", {})
        for c in sep["cases"]:
            if c["mode"] == "input":
                verdict[(c["kind"], int(c["seed"]), float(c["window"]), int(c["level"]))] = c["outcome"]
    fd, msd, sdt = "frequency_dependence", "motor_stator_dynamics", "speed_dependent_torque"
    per_variant, cases = {}, []
    for w in windows:
        if w["kind"] != fd:
            continue
        cl = w["clean"][fd]["params"]
        for c in w["cases"]:
            f = c["fits"][fd]
            v = per_variant.setdefault(c["variant"], {k: [] for k in (
                "tf", "kpf_ratio", "kqf_err", "a_ratio", "z_fd", "z_msd", "z_sdt", "fd>msd", "fd>sdt", "msd>fd")})
            v["tf"].append(f["params"]["Tf"])
            v["kpf_ratio"].append(f["params"]["Kpf"] / cl["Kpf"])
            v["kqf_err"].append(abs(f["params"]["Kqf"] - cl["Kqf"]) / abs(cl["Kpf"]))
            v["a_ratio"].append(c["plain_d"][0] / w["clean_plain_d"][0])
            for n, key in ((fd, "z_fd"), (msd, "z_msd"), (sdt, "z_sdt")):
                v[key].append(c["fits"][n]["z"] if n in c["fits"] else None)
            for key in ("fd>msd", "fd>sdt", "msd>fd"):
                a, b = key.split(">")
                full = {"fd": fd, "msd": msd, "sdt": sdt}
                v[key].append(c["paired"].get(f"{full[a]}>{full[b]}"))
            if c["variant"] == "vt":
                key = (w["kind"], w["seed"], w["window"][0], c["level"])
                o = oracle.get(key, {})
                cases.append({"seed": w["seed"], "window": w["window"][0], "level": c["level"], "tf": f["params"]["Tf"],
                              "tf_clean": cl["Tf"], "z_fd": f["z"], "z_fd_oracle": o.get("score", {}).get(fd),
                              "z_msd": c["fits"][msd]["z"], "z_msd_oracle": o.get("score", {}).get(msd),
                              "fd>msd": c["paired"].get(f"{fd}>{msd}"), "fd>msd_oracle": o.get("fwd", {}).get(msd),
                              "fd>sdt": c["paired"].get(f"{fd}>{sdt}"), "fd>sdt_oracle": o.get("fwd", {}).get(sdt),
                              "outcome_of_record": verdict.get(key),
                              "set": next((sn for sn in oracle_sets if w["seed"] in SETS[sn]["effect"]), None)})
    table = {}
    for name, v in per_variant.items():
        table[name] = {"cases": len(v["tf"]), "tf_median": _median(v["tf"]),
                       "tf_below_0.03": int(sum(t < 0.03 for t in v["tf"])),
                       **{f"{k}_median": _median(v[k]) for k in v if k != "tf"}}
    return {"variants": table, "vt_cases": cases}


def main(argv: list[str] | None = None) -> int:
    from benchmarks.diagnosis_independent import SETS, WINDOWS

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cases", default="", help="comma-separated set:kind[:seed[:t0]]")
    p.add_argument("--summarise", default="", help="only tally docs/results/<this>.json (a run of this script)")
    p.add_argument("--candidates", default=",".join(CANDS))
    p.add_argument("--levels", default="1,2,3")
    p.add_argument("--out", default="")
    p.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated, of " + ", ".join(VARIANTS))
    args = p.parse_args(argv)
    cands = tuple(c for c in args.candidates.split(",") if c)
    if args.summarise:
        s = summarise(json.loads((RESULTS / f"{args.summarise}.json").read_text())["windows"])
        for name, row in s["variants"].items():
            print(f"{name:20s} " + " ".join(f"{k} {v:.3g}" for k, v in row.items()))
        for c in s["vt_cases"]:
            print(" ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in c.items()))
        return 0
    rows = []
    for spec in [c for c in args.cases.split(",") if c]:
        parts = spec.split(":")
        set_name, kind = parts[0], parts[1]
        seeds = [int(parts[2])] if len(parts) > 2 else list(SETS[set_name]["clean" if kind == "clean" else "effect"])
        t0s = [float(parts[3])] if len(parts) > 3 else [w[0] for w in WINDOWS]
        for s in seeds:
            for t0 in t0s:
                r = run_window(kind, s, t0, cands, tuple(int(x) for x in args.levels.split(",")),
                               tuple(v for v in args.variants.split(",") if v))
                rows.append(r)
                cl = r["clean"].get("frequency_dependence", {}).get("params", {})
                print(f"{kind}/{s} {t0:g} clean a {r['clean_plain_d'][0]:.1f} fd "
                      + " ".join(f"{k}={v:.3g}" for k, v in cl.items() if not k.startswith("D.")), flush=True)
                for x in r["cases"]:
                    print(f"  L{x['level']} {x['variant']:20s} a {x['plain_d'][0]:5.1f} scan {x['tf_scan']:.2f} "
                          f"df err {x['columns']['dfreq']['err_over_signal']:.2f} "
                          f"lam {x['columns']['dfreq']['attenuation']:.2f} | "
                          + " | ".join(f"{n[:4]} z {f['z']:.1f} g {f['gain']:.1f} "
                                       + " ".join(f"{k}={v:.3g}" for k, v in f["params"].items()
                                                  if not k.startswith("D."))
                                       for n, f in x["fits"].items())
                          + " | fd>msd {:.1f} msd>fd {:.1f} fd>sdt {:.1f} sdt>fd {:.1f}".format(
                              *(x["paired"].get(k) or float("nan") for k in (
                                  "frequency_dependence>motor_stator_dynamics",
                                  "motor_stator_dynamics>frequency_dependence",
                                  "frequency_dependence>speed_dependent_torque",
                                  "speed_dependent_torque>frequency_dependence"))), flush=True)
    if args.out:
        RESULTS.mkdir(parents=True, exist_ok=True)
        (RESULTS / f"{args.out}.json").write_text(json.dumps(
            {"command": "benchmarks/diagnosis_eiv.py " + " ".join(argv if argv is not None else sys.argv[1:]),
             "summary": summarise(rows), "windows": rows}, indent=None, separators=(",", ":")))
    return 0


if __name__ == "__main__":
    sys.exit(main())
