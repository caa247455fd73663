"""How large each ANDES concealed effect is against the held-out test's noise: the oracle z (issue 12, round 4).

    .venv/bin/python -m benchmarks.diagnosis_detectability --sets dev,confirm,confirm2,confirm3 \
        --verdicts dev:diagnosis_independent_dev_round4,confirm3:diagnosis_independent_confirm3_holm

For every window of the cached ANDES scenarios (:mod:`benchmarks.diagnosis_independent`), the *noise-free*
recording is fitted by the plain ZIP + IM model as the diagnosis fits it (training samples, ambient band,
P and Q weighted by the case's white noise, which for a fixed SNR is ∝ the channel's std) and its held-out
ambient-band residual r is what no plain model explains: the visible part of the concealed effect.  An ideal
test that knew the effect's true form and parameters would correct the plain model by exactly r; its score
statistic then has expectation

    z_oracle = √(Σ_k r_P,k²/σ_P² + r_Q,k²/σ_Q²),   σ_ch = std(ch)·10^(−SNR/20)

(the case's own SNR, from the benchmark's records).  Below the diagnosis's critical value (its score test,
Bonferroni over the candidates) not even the oracle would detect the effect in more than half the draws: such
a case is beyond the data.  The library's candidate of the true kind, fitted on the same noise-free training
samples, gives the share of r its form captures (z_form = rᵀD/‖D‖, D its held-out correction): a form miss
when z_form ≪ z_oracle.  ``--noise input``: the V/θ mode's oracle, r normed in the P/Q noise plus the bench's
true V/θ noise propagated through the noise-free plain fit, P and Q correlated (:func:`vtheta_z`); ``--crosscheck``
puts that noise beside the diagnosis's own on noisy windows (docs/diagnosis.md, sixth round).  Raw output:
``docs/results/diagnosis_detectability*.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from aslm_sim.andes.effects import KINDS, cache_dir  # noqa: E402
from benchmarks.diagnosis_independent import LEVELS, WINDOWS, jobs  # noqa: E402

RESULTS = ROOT / "docs" / "results"
#: Kinds whose cause is a candidate (the oracle is computed for clean scenarios too, as the null's scale).
#: Draws of the V/θ noise through the plain model (the diagnosis uses 16 on estimated floors).
ORACLE_DRAWS = 64
KINDS_MEASURED = ("clean", "double_cage", "stator_resistance", "second_motor", "speed_dependent_torque",
                  "frequency_dependence", "measurement_skew", "switched_capacitor")


def window_oracle(kind: str, seed: int) -> list[dict]:
    """The unit-SNR oracle z and the true candidate's form share of each window of one cached scenario."""
    from aslm_sim.andes.effects import recording
    from benchmarks.diagnosis_independent import TF, TSTEP

    if not any(cache_dir().glob(f"v*-{kind}-{seed}-*.npz")):
        return []
    return recording_oracle(recording(kind, seed, tf=TF, tstep=TSTEP), kind, seed)


def recording_oracle(rec: dict, kind: str, seed: int, windows: tuple = WINDOWS) -> list[dict]:
    """:func:`window_oracle` on a given noise-free recording (``t``, ``V``, ``theta``, ``P``, ``Q``).

    ``windows`` are (start, end) pairs [s] inside the recording (default: the benchmark's two).
    """
    from aslm_core.diagnosis import engine
    from aslm_core.diagnosis.candidates import LIBRARY
    from aslm_core.diagnosis.noise import dct_band
    from aslm_core.diagnosis.pipeline import DiagnosisConfig

    config = DiagnosisConfig()
    expected = KINDS[kind].expected
    out = []
    for t0, t1 in windows:
        seg, ctx, noise, plain, (sp, sq) = noise_free_plain(rec, t0, t1, config)
        te = seg.test
        r = np.column_stack([(seg.P - plain.model_p)[te], (seg.Q - plain.model_q)[te]])
        c = dct_band(r, seg.fs, config.band_hz) / np.array([sp, sq])
        z_unit = float(np.sqrt(np.sum(c * c)))
        row = {"kind": kind, "seed": seed, "window": [t0, t1], "expected": expected, "z_unit": z_unit,
               "z_unit_p": float(np.sqrt(np.sum(c[:, 0] ** 2))), "z_unit_q": float(np.sqrt(np.sum(c[:, 1] ** 2))),
               "fd_p": engine.fd(seg.P[te], plain.model_p[te]), "fd_q": engine.fd(seg.Q[te], plain.model_q[te]),
               "plain_d": [float(x) for x in plain.d]}
        # The V/θ mode's ingredients, in pu (its z depends on the SNR through a sum, not a factor).
        gp, gq, gpq = input_noise_coefficients(seg, ctx, plain, *true_input_sigmas(seg))
        vt = {"sigma_p_unit": sp, "sigma_q_unit": sq, "r_p": c[:, 0] * sp, "r_q": c[:, 1] * sq,
              "g_p": gp, "g_q": gq, "g_pq": gpq}
        if expected in LIBRARY:
            f = engine.fit_candidate(LIBRARY[expected], seg, ctx, noise, d_start=plain.d)
            if f.ok:
                dd = np.column_stack([(f.model_p - plain.model_p)[te], (f.model_q - plain.model_q)[te]])
                draw = dct_band(dd, seg.fs, config.band_hz)
                dc = draw / np.array([sp, sq])
                nd = float(np.sqrt(np.sum(dc * dc)))
                row["z_form_unit"] = float(np.sum(dc * c) / nd) if nd > 0 else 0.0
                row["form_params"] = {k: float(v) for k, v in f.params.items() if not k.startswith("D.")}
                vt["d_p"], vt["d_q"] = draw[:, 0], draw[:, 1]
        row["vtheta"] = {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in vt.items()}
        out.append(row)
    return out


def true_input_sigmas(seg) -> tuple[float, float]:
    """The bench's V [pu] and θ [rad] noise std on a window (``INPUT_NOISE``: V's relative to its mean)."""
    from benchmarks.diagnosis_independent import INPUT_NOISE

    return INPUT_NOISE["V"] * float(np.mean(seg.V)), INPUT_NOISE["theta"]


def input_noise_coefficients(seg, ctx, plain, sigma_v: float, sigma_theta: float, n_draws: int = ORACLE_DRAWS,
                             seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """V/θ noise propagated through a fitted plain model, per held-out ambient-band DCT coefficient.

    Computed as :mod:`aslm_core.diagnosis.noise` does it (white V and θ draws pushed through the model with
    its parameters fixed, the coefficients' mean squares smoothed over ±½ Hz), but from the bench's true
    σ_V [pu] and σ_θ [rad] instead of estimated floors, and with more draws.

    Returns
    -------
    (g_p, g_q, g_pq) : ndarray
        Variances of P and Q and their covariance per coefficient of ``seg.test`` [pu²], without the P/Q
        measurement noise.
    """
    from aslm_core.diagnosis import engine
    from aslm_core.diagnosis.candidates import Candidate
    from aslm_core.diagnosis.noise import NoiseModel

    rng = np.random.default_rng(seed)
    nm = NoiseModel(0.0, 0.0, seg.fs, plain_band_hz(), sigma_v, sigma_theta,
                    inputs_v=sigma_v * rng.standard_normal((n_draws, seg.n)),
                    inputs_theta=sigma_theta * rng.standard_normal((n_draws, seg.n)))
    prop = nm.propagate(seg, lambda s: engine.output(Candidate(), s, ctx, plain), (plain.model_p, plain.model_q))
    if prop is None:
        raise ValueError("the plain model cannot be played back on noisy inputs")
    nm.probes_p, nm.probes_q = prop
    vp, vq, cpq = nm.coefficients(seg.test)
    return vp, vq, cpq


def plain_band_hz() -> float:
    """The diagnosis's ambient band [Hz]."""
    from aslm_core.diagnosis.pipeline import DiagnosisConfig

    return DiagnosisConfig().band_hz


def vtheta_z(vt: dict, snr_db: float, field: str = "r") -> float:
    """The V/θ mode's oracle z of one window at a case's SNR [dB]: √(rᵀC⁻¹r), C per coefficient the P/Q
    measurement noise (σ_ch = std(ch)·10^(−SNR/20)) plus the propagated input noise, P and Q correlated.

    ``field`` "d" gives the true form's z_form in the same metric (rᵀC⁻¹D/√(DᵀC⁻¹D)); None-safe: NaN
    when the window has no such field.
    """
    from aslm_core.diagnosis.engine import _gls_metric

    s2 = 10 ** (-snr_db / 10)
    vp = vt["sigma_p_unit"] ** 2 * s2 + np.asarray(vt["g_p"])
    vq = vt["sigma_q_unit"] ** 2 * s2 + np.asarray(vt["g_q"])
    cinv = _gls_metric(vp, vq, np.asarray(vt["g_pq"]), None)
    rp, rq = np.asarray(vt["r_p"]), np.asarray(vt["r_q"])
    if field == "r":
        wp, wq = cinv(rp, rq)
        return float(np.sqrt(max(float(wp @ rp + wq @ rq), 0.0)))
    if "d_p" not in vt:
        return float("nan")
    dp, dq = np.asarray(vt["d_p"]), np.asarray(vt["d_q"])
    wp, wq = cinv(dp, dq)
    nd = float(np.sqrt(max(float(wp @ dp + wq @ dq), 0.0)))
    return float(wp @ rp + wq @ rq) / nd if nd > 0 else 0.0


def noise_free_plain(rec: dict, t0: float, t1: float, config):
    """One window [t0, t1] [s] of a noise-free recording fitted by the plain model as the diagnosis fits it, at
    unit SNR: σ_ch = std(ch) (the benchmark's noise is std(ch)·10^(−SNR/20), so statistics scale by
    10^(SNR/20)).  Returns the segment, the context, the white noise model, the plain fit and (σ_P, σ_Q) [pu].
    """
    from aslm_core import Window
    from aslm_core.diagnosis import engine
    from aslm_core.diagnosis.candidates import Candidate, Context
    from aslm_core.diagnosis.noise import NoiseModel
    from aslm_core.diagnosis.pipeline import _plain_d
    from aslm_core.diagnosis.segment import make_segment

    sl = (rec["t"] >= t0 - 1e-9) & (rec["t"] <= t1 + 1e-9)
    ch = {k: rec[k][sl] for k in ("t", "V", "theta", "P", "Q")}
    w = Window(ch["t"], ch["V"], ch["theta"], ch["P"], ch["Q"], f0=60.0, bus="andes-bus9")
    seg = make_segment(w, skip_s=config.skip_s, train_fraction=config.train_fraction)
    sp, sq = float(np.std(ch["P"])), float(np.std(ch["Q"]))
    noise = NoiseModel.white(sp, sq, seg.fs, config.band_hz)
    ctx = Context("identified", _plain_d(seg, None, config))
    return seg, ctx, noise, engine.fit_candidate(Candidate(), seg, ctx, noise), (sp, sq)


def crosscheck(kind: str, seed: int, t0: float, level: int, window: dict) -> dict:
    """The oracle's V/θ noise against the diagnosis's own noise model on the same noisy window.

    The bench's noisy window (``diagnosis_independent._window``, V/θ noise on) goes through the diagnosis's
    analysis; its held-out noise per coefficient (estimated floors propagated through the noisy fit) is put
    beside the oracle's (true σ through the noise-free fit), and the oracle's noise-free residual r is
    normed in four metrics: the oracle's, the diagnosis's noise, the diagnosis's noise plus the plain
    model's own prediction error (the score test's C), and the P/Q mode's white noise.  ``window`` is the
    oracle's row of that window.
    """
    from aslm_core.diagnosis import engine
    from aslm_core.diagnosis.pipeline import _PLAIN, DiagnosisConfig, _analyse
    from aslm_sim.andes.effects import recording
    from benchmarks.diagnosis_independent import TF, TSTEP, WINDOWS, _window

    config = DiagnosisConfig()
    rec = recording(kind, seed, tf=TF, tstep=TSTEP)
    t1 = dict(WINDOWS)[t0]
    w, snr = _window(rec, t0, t1, level, True, f"{kind}/{seed}")
    a = _analyse(w, None, None, config)
    seg, te = a.seg, a.seg.test
    vp, vq, cpq = a.noise.coefficients(te)
    pcov = engine.prediction_cov(_PLAIN, seg, a.ctx, a.plain, a.weights)
    vt = window["vtheta"]
    s2 = 10 ** (-snr / 10)
    op = vt["sigma_p_unit"] ** 2 * s2 + np.asarray(vt["g_p"])
    oq = vt["sigma_q_unit"] ** 2 * s2 + np.asarray(vt["g_q"])
    rp, rq = np.asarray(vt["r_p"]), np.asarray(vt["r_q"])

    def norm(cinv) -> float:
        xp, xq = cinv(rp, rq)
        return float(np.sqrt(max(float(xp @ rp + xq @ rq), 0.0)))

    sv, st = true_input_sigmas(seg)
    return {"kind": kind, "seed": seed, "window": t0, "level": level, "snr_db": snr,
            "sigma_v": [a.weights.sigma_v, sv], "sigma_theta": [a.weights.sigma_theta, st],
            "sigma_p": [a.weights.sigma_p, vt["sigma_p_unit"] * 10 ** (-snr / 20)],
            "sigma_q": [a.weights.sigma_q, vt["sigma_q_unit"] * 10 ** (-snr / 20)],
            "rms_std_p": [float(np.sqrt(np.mean(vp))), float(np.sqrt(np.mean(op)))],
            "rms_std_q": [float(np.sqrt(np.mean(vq))), float(np.sqrt(np.mean(oq)))],
            "z_oracle": vtheta_z(vt, snr),
            "z_diag_noise": norm(engine._gls_metric(vp, vq, cpq, None)),
            "z_diag_noise_pcov": norm(engine._gls_metric(vp, vq, cpq, pcov)),
            "z_oracle_pcov": norm(engine._gls_metric(op, oq, np.asarray(vt["g_pq"]), pcov)),
            "z_pq": float(window["z_unit"] * 10 ** (snr / 20)),
            "candidate_z": {n: c.score_z for n, c in a.comps.items()}}


def _records(name: str, input_noise: bool = False) -> list[dict]:
    """The records of one noise mode in a results file, or in several joined by ``+`` (a set run in parts)."""
    out = []
    for part in name.split("+"):
        p = RESULTS / f"{part}.json"
        if p.exists():
            out += [r for r in json.loads(p.read_text())["records"] if bool(r.get("input_noise")) == input_noise]
    return out


def critical_z() -> float:
    """The diagnosis's score-test critical value for an identified model (Bonferroni over the tested candidates)."""
    from aslm_core.diagnosis import engine
    from aslm_core.diagnosis.candidates import LIBRARY, Context
    from aslm_core.diagnosis.pipeline import DiagnosisConfig

    ctx = Context("identified", np.zeros(4))
    n = sum(1 for name in DiagnosisConfig().candidates if not LIBRARY[name].not_applicable(ctx))
    return engine.dm_critical(DiagnosisConfig().alpha, n)


def table(rows: list[dict], zcrit: float) -> list[dict]:
    """Per kind and level: cases, oracle-detectable, right among them, and what the misses were."""
    agg: dict = defaultdict(lambda: defaultdict(int))
    for r in rows:
        a = agg[(r["kind"], r["level"])]
        det = r["z_oracle"] >= zcrit
        a["cases"] += 1
        a["detectable"] += det
        if "outcome" in r:
            a["with_verdict"] += 1
            a["right"] += r["outcome"] == r["expected"]
            if det:
                a["det_with_verdict"] += 1
                a["right_det"] += r["outcome"] == r["expected"]
                a["consistent_det"] += r["outcome"] == "consistent"
                a["ambiguous_det"] += r["outcome"] == "ambiguous"
            else:
                a["undet_with_verdict"] += 1
                a["right_undet"] += r["outcome"] == r["expected"]
        if det and r.get("z_form") is not None:
            a["form_below"] += r["z_form"] < zcrit
    return [{"kind": k, "level": lvl, **v} for (k, lvl), v in sorted(agg.items(), key=lambda x: (
        list(KINDS).index(x[0][0]), x[0][1]))]


def markdown(tab: list[dict], zcrit: float) -> str:
    lines = [f"critical z = {zcrit:.2f}; detectable: oracle z ≥ critical", "",
             "| kind | level | cases | oracle-detectable | right (all) | right among detectable | "
             "`consistent` among detectable | `ambiguous` among detectable | right among undetectable | "
             "detectable, true form's z_form < critical |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for t in tab:
        nv, nd, nu = t.get("with_verdict", 0), t.get("det_with_verdict", 0), t.get("undet_with_verdict", 0)
        lines.append(f"| {t['kind']} | L{t['level']} | {t['cases']} | {t['detectable']} | "
                     f"{t.get('right', 0)}/{nv} | {t.get('right_det', 0)}/{nd} | {t.get('consistent_det', 0)} | "
                     f"{t.get('ambiguous_det', 0)} | {t.get('right_undet', 0)}/{nu} | {t.get('form_below', 0)} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sets", default="dev,confirm,confirm2,confirm3")
    p.add_argument("--verdicts", default="", help="set:results-file-stem pairs whose P/Q verdicts are tallied "
                   "(default: diagnosis_independent_<set>)")
    p.add_argument("--noise", choices=("pq", "input"), default="pq",
                   help="the P/Q mode's oracle, or the V/θ mode's (input noise propagated through the plain model)")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--out", default="diagnosis_detectability")
    p.add_argument("--windows-from", default="", help="reuse the oracle windows of an earlier output (stem), "
                   "computing only the missing ones")
    p.add_argument("--crosscheck", default="", help="kind:seed:window-start:level,... — the oracle's V/θ noise "
                   "against the diagnosis's on those noisy windows (the oracle rows from --windows-from)")
    args = p.parse_args(argv)
    if args.crosscheck:
        return crosscheck_main(args, argv)
    sets = [s for s in args.sets.split(",") if s]
    stems = {s: f"diagnosis_independent_{s}" for s in sets}
    stems.update(dict(kv.split(":", 1) for kv in args.verdicts.split(",") if kv))
    # In the sets' order (a partial run covers the first sets whole), each scenario once.
    todo = list(dict.fromkeys((k, s) for st in sets for k, s in jobs(st, list(KINDS_MEASURED))))
    t0 = time.perf_counter()
    windows = []
    if args.windows_from:
        windows = _load_windows(args.windows_from)
        if args.noise == "input":  # earlier outputs may lack the V/θ ingredients
            windows = [w for w in windows if "vtheta" in w]
        have = {(w["kind"], w["seed"]) for w in windows}
        todo = [j for j in todo if j not in have]
    partial = cache_dir() / f"{args.out}.partial.jsonl"  # every scenario's windows as they come
    with ProcessPoolExecutor(max_workers=args.workers) as pool, partial.open("a") as fh:
        for job, ws in zip(todo, pool.map(_safe_oracle, todo), strict=True):
            windows += ws
            fh.writelines(json.dumps(w, default=float) + "\n" for w in ws)
            fh.flush()
            print(f"{job[0]}/{job[1]}: {len(ws)} windows, {time.perf_counter() - t0:.0f} s", flush=True)
    zcrit = critical_z()
    by_key = {(w["kind"], w["seed"], w["window"][0]): w for w in windows}
    rows = []
    for st in sets:
        seeds = {(k, s) for k, s in jobs(st, list(KINDS_MEASURED))}
        recs = {(r["kind"], r["seed"], r["window"][0], r["level"]): r
                for r in _records(stems[st], args.noise == "input")}
        for (k, s, t0w), w in by_key.items():
            if (k, s) not in seeds:
                continue
            for lvl in LEVELS:
                r = recs.get((k, s, t0w, lvl))
                if r is None:
                    continue
                scale = 10 ** (r["snr_db"] / 20)
                row = {"set": st, "kind": k, "seed": s, "window": t0w, "level": lvl, "snr_db": r["snr_db"],
                       "expected": w["expected"], "z_oracle": w["z_unit"] * scale,
                       "z_form": w["z_form_unit"] * scale if "z_form_unit" in w else None,
                       "outcome": r["cause"] if r["verdict"] == "explained" else r["verdict"]}
                if args.noise == "input":
                    zf = vtheta_z(w["vtheta"], r["snr_db"], "d")
                    row.update(z_oracle_pq=row["z_oracle"], z_oracle=vtheta_z(w["vtheta"], r["snr_db"]),
                               z_form=None if np.isnan(zf) else zf)
                true = next((c for c in r["candidates"] if c["name"] == w["expected"]), None)
                if true is not None:
                    row["z_true_candidate"] = true["z"]
                rows.append(row)
    tab = table(rows, zcrit)
    print(markdown(tab, zcrit))
    by_set = detectable_by_set(by_key, sets, zcrit, args.noise == "input")
    print("\n" + by_set_markdown(by_set, sets))
    print(f"\n{len(windows)} windows, {len(rows)} cases, {time.perf_counter() - t0:.0f} s, load {os.getloadavg()}")
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"{args.out}.json").write_text(json.dumps(
        {"critical_z": zcrit, "noise": args.noise, "sets": sets, "detectable_by_set": by_set, "verdicts_from": stems, "table": tab, "windows": windows, "cases": rows,
         "command": "benchmarks/diagnosis_detectability.py " + " ".join(argv if argv is not None else sys.argv[1:])},
        indent=1, default=float))
    return 0


def detectable_by_set(by_key: dict, sets: list[str], zcrit: float, input_noise: bool) -> dict:
    """Oracle-detectable cases per set, kind and level, every window at its drawn SNR (records not needed, so
    sets without a run of this noise mode count too): {set: {kind: [[detectable, cases] per level]}}."""
    from benchmarks.diagnosis_independent import noise_draw

    out: dict = {}
    for st in sets:
        seeds = set(jobs(st, list(KINDS_MEASURED)))
        per: dict = defaultdict(lambda: [[0, 0] for _ in LEVELS])
        for (k, s, t0w), w in by_key.items():
            if (k, s) not in seeds:
                continue
            for i, lvl in enumerate(LEVELS):
                snr = noise_draw(f"{k}/{s}", lvl, t0w)[1]
                z = vtheta_z(w["vtheta"], snr) if input_noise else w["z_unit"] * 10 ** (snr / 20)
                per[k][i][0] += z >= zcrit
                per[k][i][1] += 1
        out[st] = {k: per[k] for k in KINDS_MEASURED if k in per}
    return out


def by_set_markdown(by_set: dict, sets: list[str]) -> str:
    """Detectable / cases per kind (rows) and set (columns), L1 / L2 / L3 in each cell."""
    lines = ["| kind | " + " | ".join(sets) + " |", "|---" * (len(sets) + 1) + "|"]
    for k in KINDS_MEASURED:
        cells = []
        for st in sets:
            c = by_set.get(st, {}).get(k)
            cells.append("-" if c is None else " / ".join(str(d) for d, _ in c) + f" of {c[0][1]}")
        lines.append(f"| {k} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _load_windows(src: str) -> list[dict]:
    """Oracle windows of an earlier output: a results stem, or a ``.partial.jsonl`` path of a run."""
    if src.endswith(".jsonl"):
        return [json.loads(line) for line in Path(src).read_text().splitlines() if line.strip()]
    return json.loads((RESULTS / f"{src}.json").read_text())["windows"]


def crosscheck_main(args, argv) -> int:
    """``--crosscheck``: :func:`crosscheck` on the listed cases, printed and written to ``--out``."""
    t0 = time.perf_counter()
    windows = _load_windows(args.windows_from)
    by_key = {(w["kind"], w["seed"], w["window"][0]): w for w in windows}
    rows = []
    for spec in args.crosscheck.split(","):
        kind, seed, start, level = spec.split(":")
        row = crosscheck(kind, int(seed), float(start), int(level), by_key[(kind, int(seed), float(start))])
        rows.append(row)
        print(json.dumps({k: v for k, v in row.items() if k != "candidate_z"}, default=float), flush=True)
    print(f"{len(rows)} windows, {time.perf_counter() - t0:.0f} s, load {os.getloadavg()}")
    (RESULTS / f"{args.out}.json").write_text(json.dumps(
        {"crosscheck": rows, "windows_from": args.windows_from,
         "command": "benchmarks/diagnosis_detectability.py " + " ".join(argv if argv is not None else sys.argv[1:])},
        indent=1, default=float))
    return 0


def _safe_oracle(job: tuple[str, int]) -> list[dict]:
    try:
        return window_oracle(*job)
    except (RuntimeError, ValueError) as exc:
        print(f"{job}: {exc!r}", flush=True)
        return []


if __name__ == "__main__":
    sys.exit(main())
