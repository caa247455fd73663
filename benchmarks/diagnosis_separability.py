"""Can the held-out data separate the frequency dependence from the speed-dependent torque? An oracle (issue 12).

    .venv/bin/python -m benchmarks.diagnosis_separability --sets dev,confirm,confirm2,dev3,confirm3,confirm4

On the *noise-free* cached ANDES recordings of the two kinds (:mod:`benchmarks.diagnosis_independent`'s
windows), the plain ZIP + IM, the ``frequency_dependence`` and the ``speed_dependent_torque`` candidates are
fitted on the training samples exactly as the diagnosis fits them (ambient band, P and Q weighted by white
noise ∝ each channel's std: a fixed SNR).  With r_X the held-out ambient-band residual left by candidate X
(DCT coefficients over σ_ch) and D = r_B − r_A the held-out difference of the two corrections, the paired
statistic of the verdict (A the best, B the rival) has on noisy data the expectation

    z(A over B) = Dᵀ·r_B / ‖D‖

at unit SNR, scaled by 10^(SNR/20) at a level's SNR (the nominal 14 / 22 / 28 dB).  The true member
separates from the other at a level when z(true over other) ≥ 1.645 (one-sided 5 %, the verdict's Holm
level for one rival) and the reverse z(other over true) < 1.645 (else the reverse comparison makes the pair
``ambiguous``).  Also per window: each candidate's held-out residual ‖r_X‖ against the plain model's ‖r_0‖
(the oracle z of :mod:`benchmarks.diagnosis_detectability`), its parameters.  What the oracle leaves out: the
estimation error of fits on noisy training data (the real statistics scatter about these values with sd ≈ 1).
Raw output: ``docs/results/diagnosis_separability<tag>.json``.

``--library`` (stop 31): every inside-library kind's true form (``KINDS[kind].expected``) against every other
candidate the diagnosis tries, in both noise modes, each case at its own drawn SNR:

    .venv/bin/python -m benchmarks.diagnosis_separability --library --sets confirm8 \
        --verdicts confirm8:diagnosis_independent_confirm8 --out diagnosis_separability_confirm8

All the z's are the V/θ oracle's (:func:`benchmarks.diagnosis_detectability.vtheta_z`) in the covariance
C_k = diag(σ_P², σ_Q²)·10^(−SNR/10) + G_k, G_k the bench's true V/θ noise through the noise-free plain fit
(zero for ``pq``, where it is the pair mode's metric above).  A candidate is a rival of the true one when its
oracle score z (its correction against the plain fit) passes the diagnosis's critical value and its fit is
plausible, or when the true one declares it a look-alike.  The true form is *separable* when Holm's step-down at
the verdict's 5 % rejects every forward statistic z(true over rival) and no reverse z(rival over true) passes
Holm over the separated rivals (with the verdict's reverse margin, not between look-alikes).  The tally puts
each case's verdict of the run of record beside its oracle: detectable (z_oracle ≥ critical, as
:mod:`benchmarks.diagnosis_detectability`), detectable and separable, right among those.  Left out, as above:
the estimation error of noisy fits, the prediction-error term of C, the motor-outside-the-box rival and the
challengers' stricter level; G_k is the plain fit's for every candidate.

The power reading (stop 44): the oracle's z's are expectations and the real statistics scatter about them with sd ≈ 1
(the measured efficiency is ≈ 1), so a case at exactly the critical value is named in half the draws by any test at
the diagnosis's level.  ``--margin 1 --detect-margin 1`` counts a case only where its detection and every separation
pass in ≈ 84 % of draws, and ``--readable set:diagnosis_shunt_state_<set>`` leaves out the switched capacitor's V/θ
cases whose bank state no setting of the two-state form reads from the PMU's V (the oracle fits noise-free V and
cannot see that):

    .venv/bin/python -m benchmarks.diagnosis_separability --library --sets confirm20 \
        --windows-from diagnosis_separability_confirm20 --margin 1 --detect-margin 1 \
        --readable confirm20:diagnosis_shunt_state_confirm20 --out diagnosis_separability_confirm20_power
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy import stats

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from aslm_sim.noise import NOISE_LEVELS  # noqa: E402
from benchmarks.diagnosis_independent import SETS, jobs  # noqa: E402

RESULTS = ROOT / "docs" / "results"
PAIR = ("frequency_dependence", "speed_dependent_torque")
TRUTH = {"frequency_dependence": "frequency_dependence", "speed_dependent_torque": "speed_dependent_torque"}
Z_ONE = 1.6448536269514722  # one-sided 5 %, one comparison


def window_pair(kind: str, seed: int) -> list[dict]:
    """Unit-SNR held-out residuals and paired statistics of the pair on each window of one cached scenario."""
    from aslm_core.diagnosis import engine
    from aslm_core.diagnosis.candidates import LIBRARY
    from aslm_core.diagnosis.pipeline import DiagnosisConfig
    from aslm_sim.andes.effects import cache_dir, recording
    from benchmarks.diagnosis_detectability import noise_free_plain
    from benchmarks.diagnosis_independent import TF, TSTEP, WINDOWS

    if not any(cache_dir().glob(f"v*-{kind}-{seed}-*.npz")):
        return []
    rec = recording(kind, seed, tf=TF, tstep=TSTEP)
    config = DiagnosisConfig()
    out = []
    for t0, t1 in WINDOWS:
        seg, ctx, noise, plain, (sp, sq) = noise_free_plain(rec, t0, t1, config)
        scale = np.array([sp, sq])
        r0 = _held_out_coefficients(seg, plain, config.band_hz) / scale
        fits = {m: engine.fit_candidate(LIBRARY[m], seg, ctx, noise, d_start=plain.d) for m in PAIR}
        res = {m: _held_out_coefficients(seg, f, config.band_hz) / scale for m, f in fits.items()}
        row = {"kind": kind, "seed": seed, "window": [t0, t1], "truth": TRUTH[kind],
               "z_plain_unit": float(np.linalg.norm(r0)),
               "left_unit": {m: float(np.linalg.norm(res[m])) for m in PAIR},
               "params": {m: {k: float(v) for k, v in f.params.items() if not k.startswith("D.")}
                          for m, f in fits.items()},
               "paired_unit": {}}
        for a, b in (PAIR, PAIR[::-1]):
            d = res[b] - res[a]
            nd = float(np.linalg.norm(d))
            row["paired_unit"][f"{a}>{b}"] = float(np.sum(d * res[b]) / nd) if nd > 0 else 0.0
        out.append(row)
    return out


def _held_out_coefficients(seg, fit, band_hz: float) -> np.ndarray:
    """Ambient-band DCT coefficients of a fit's held-out residual, columns P and Q [pu]."""
    from aslm_core.diagnosis.noise import dct_band

    te = seg.test
    return dct_band(np.column_stack([(seg.P - fit.model_p)[te], (seg.Q - fit.model_q)[te]]), seg.fs, band_hz)


def per_level(rows: list[dict]) -> dict:
    """Per kind and nominal level: windows where the true member separates rightly, and both ways."""
    out: dict = {}
    for r in rows:
        x = r["truth"]
        y = PAIR[1] if x == PAIR[0] else PAIR[0]
        for lvl, snr in NOISE_LEVELS.items():
            s = 10 ** (snr / 20)
            zx, zy = r["paired_unit"][f"{x}>{y}"] * s, r["paired_unit"][f"{y}>{x}"] * s
            cell = out.setdefault(r["kind"], {}).setdefault(f"L{lvl}", {"windows": 0, "separable": 0, "both_ways": 0,
                                                                          "true_loses": 0, "neither": 0})
            cell["windows"] += 1
            if zx >= Z_ONE and zy < Z_ONE:
                cell["separable"] += 1
            elif zx >= Z_ONE:
                cell["both_ways"] += 1
            elif zy >= Z_ONE:
                cell["true_loses"] += 1
            else:
                cell["neither"] += 1
    return out


ALPHA_SEP = 0.05  # the verdict's separation_alpha and encompassing_alpha (DiagnosisConfig)
MODES = ("pq", "input")


def window_library(kind: str, seed: int) -> list[dict]:
    """Per window of one cached scenario and per level (its drawn SNR) and noise mode: the oracle z of the
    effect, each candidate's oracle score z and the paired z's of the true form against every other candidate."""
    from aslm_core.diagnosis import engine
    from aslm_core.diagnosis.candidates import LIBRARY
    from aslm_core.diagnosis.pipeline import DiagnosisConfig
    from aslm_sim.andes.effects import KINDS, cache_dir, recording
    from benchmarks.diagnosis_detectability import input_noise_coefficients, noise_free_plain
    from benchmarks.diagnosis_detectability import true_input_sigmas as sigmas
    from benchmarks.diagnosis_independent import LEVELS, TF, TSTEP, WINDOWS, noise_draw

    if not any(cache_dir().glob(f"v*-{kind}-{seed}-*.npz")):
        return []
    rec = recording(kind, seed, tf=TF, tstep=TSTEP)
    config = DiagnosisConfig()
    true = KINDS[kind].expected
    out = []
    for t0, t1 in WINDOWS:
        seg, ctx, noise, plain, (sp, sq) = noise_free_plain(rec, t0, t1, config)
        names = [n for n in config.candidates if not LIBRARY[n].not_applicable(ctx)]
        r0 = _held_out_coefficients(seg, plain, config.band_hz)
        fits = {n: engine.fit_candidate(LIBRARY[n], seg, ctx, noise, d_start=plain.d) for n in names}
        res = {n: _held_out_coefficients(seg, f, config.band_hz) for n, f in fits.items() if f.ok}
        gp, gq, gpq = input_noise_coefficients(seg, ctx, plain, *sigmas(seg))
        row = {"kind": kind, "seed": seed, "window": [t0, t1], "truth": true, "failed": sorted(set(names) - set(res)),
               "implausible": sorted(n for n in res if LIBRARY[n].implausible(fits[n].params, seg, ctx) is not None),
               "levels": {}}
        for lvl in LEVELS:
            snr = noise_draw(f"{kind}/{seed}", lvl, t0)[1]
            cell = {"snr_db": snr}
            for mode in MODES:
                g = (gp, gq, gpq) if mode == "input" else (np.zeros_like(gp),) * 3
                cell[mode] = pair_zs(r0, res, true, snr, (sp, sq), g)
            row["levels"][str(lvl)] = cell
        out.append(row)
    return out


def pair_zs(r0: np.ndarray, res: dict[str, np.ndarray], true: str, snr_db: float, sigma_unit: tuple[float, float],
            g: tuple[np.ndarray, np.ndarray, np.ndarray]) -> dict:
    """The oracle z's of one window at one SNR [dB] in the covariance C_k = diag(σ²)·10^(−SNR/10) + G_k.

    ``r0`` and ``res[X]`` are the held-out ambient-band coefficients (columns P, Q) [pu] left by the plain fit
    and candidate X; ``sigma_unit`` the channels' std [pu]; ``g`` = (G_P, G_Q, G_PQ) per coefficient [pu²].
    Returns z_oracle = √(r0ᵀC⁻¹r0), each candidate's score z (its correction m_X − m_0 = r0 − r_X against
    r0) and, when the true form was fitted, z(true over X) = Dᵀ C⁻¹ r_X / √(DᵀC⁻¹D) with D = r_X − r_true,
    and z(X over true) in turn.
    """
    from benchmarks.diagnosis_detectability import vtheta_z

    base = {"sigma_p_unit": sigma_unit[0], "sigma_q_unit": sigma_unit[1], "g_p": g[0], "g_q": g[1], "g_pq": g[2]}

    def z(r: np.ndarray, d: np.ndarray | None = None) -> float:
        vt = {**base, "r_p": r[:, 0], "r_q": r[:, 1]}
        if d is None:
            return vtheta_z(vt, snr_db)
        return vtheta_z({**vt, "d_p": d[:, 0], "d_q": d[:, 1]}, snr_db, "d")

    out = {"z_oracle": z(r0), "score": {n: z(r0, r0 - r) for n, r in res.items()}, "fwd": {}, "back": {}}
    if true in res:
        rt = res[true]
        for n, r in res.items():
            if n != true:
                out["fwd"][n] = z(r, r - rt)
                out["back"][n] = z(rt, rt - r)
    return out


def separation(cell: dict, true: str, zcrit: float, implausible: list[str], margin: float = 0.0) -> dict:
    """Whether the true form is separable from all its rivals in one window's oracle z's (:func:`pair_zs`).

    The verdict's procedure on expected statistics: the rivals are the other plausible candidates whose score z
    passes ``zcrit`` and the true form's declared look-alikes; Holm's step-down at 5 % over the forward
    z(true over rival), then Holm over the separated rivals on the reverse z(rival over true) with the verdict's
    reverse margin ρ (shift √ρ·z_true, not between look-alikes).  ``margin`` [-] asks each forward z to clear its
    Holm critical value by that much more (1: the test passes in ≈ 84 % of noisy draws instead of half).  Returns the rivals, the ones not separated
    (forward) and the ones that beat the true form back (reverse), and ``separable``.
    """
    from aslm_core.diagnosis.candidates import LIBRARY
    from aslm_core.diagnosis.pipeline import DiagnosisConfig, _look_alikes

    if true not in cell["score"]:
        return {"separable": False, "rivals": [], "not_forward": [], "reverse": [], "true_failed": True}
    look = set(LIBRARY[true].confusable)
    rivals = [n for n, z in cell["score"].items() if n != true and n not in implausible
              and (z >= zcrit or n in look)]
    p = {n: float(stats.norm.sf(cell["fwd"][n] - margin)) for n in rivals}
    separated = _holm(p, ALPHA_SEP)
    rho = DiagnosisConfig().reverse_margin
    zt = max(cell["score"][true], 0.0)
    pb = {}
    for n in separated:
        r = 0.0 if _look_alikes(true, n) else rho
        pb[n] = float(stats.norm.sf((cell["back"][n] - np.sqrt(r) * zt) / np.sqrt(1.0 + r)))
    reverse = _holm(pb, ALPHA_SEP)
    not_fwd = [n for n in rivals if n not in separated]
    return {"separable": not not_fwd and not reverse, "rivals": rivals, "not_forward": not_fwd,
            "reverse": sorted(reverse), "true_failed": False}


def _holm(p: dict[str, float], alpha: float) -> list[str]:
    """The hypotheses Holm's step-down rejects at family-wise ``alpha`` (names, smallest p first)."""
    out = []
    for j, n in enumerate(sorted(p, key=p.get)):
        if p[n] > alpha / (len(p) - j):
            break
        out.append(n)
    return out


def library_cases(windows: list[dict], sets: list[str], stems: dict[str, str], zcrit: float,
                  margin: float = 0.0, detect_margin: float = 0.0, unreadable: frozenset = frozenset()) -> list[dict]:
    """Every case (window, level, noise mode) of the sets with its oracle and its run-of-record verdict.

    ``detect_margin`` [-]: detectable when the oracle z clears the critical value by that much more (1: the real
    statistic, sd 1 about it, passes in ≈ 84 % of draws).  ``unreadable``: (set, kind, seed, window start, level) of the
    switched capacitor's V/θ cases whose bank state no setting of the two-state form reads from the PMU's V
    (:func:`unreadable_banks`); not detectable in the input mode (the oracle fits noise-free V)."""
    from aslm_core.diagnosis.candidates import LIBRARY
    from benchmarks.diagnosis_detectability import _records

    by_key = {(w["kind"], w["seed"], w["window"][0]): w for w in windows}
    out = []
    for st in sets:
        seeds = set(jobs(st))
        for mode in MODES:
            recs = {(r["kind"], r["seed"], r["window"][0], r["level"]): r
                    for r in _records(stems[st], mode == "input")}
            for (k, s, t0w), w in by_key.items():
                if (k, s) not in seeds:
                    continue
                for lvl, lc in w["levels"].items():
                    cell = lc[mode]
                    sep = separation(cell, w["truth"], zcrit, w["implausible"], margin)
                    row = {"set": st, "mode": mode, "kind": k, "seed": s, "window": t0w, "level": int(lvl),
                           "snr_db": lc["snr_db"], "expected": w["truth"], "z_oracle": cell["z_oracle"],
                           "detectable": bool(cell["z_oracle"] >= zcrit + detect_margin
                                              and not (mode == "input" and (st, k, s, t0w, int(lvl)) in unreadable)),
                           "z_true": cell["score"].get(w["truth"]), **sep}
                    r = recs.get((k, s, t0w, int(lvl)))
                    if r is not None:
                        row["snr_record_db"] = r["snr_db"]
                        row["outcome"] = r["cause"] if r["verdict"] == "explained" else r["verdict"]
                        if r["verdict"] == "ambiguous":
                            row["causes"] = {n: [cell["fwd"].get(n), cell["back"].get(n)]
                                             for n in r.get("report_extra", {}).get("causes", []) if n != w["truth"]}
                        true_z = [x["z"] for x in r["candidates"] if x["name"] == w["truth"]]
                        row["z_true_diag"] = true_z[0] if true_z else None
                        named = row["outcome"]
                        if named in cell["fwd"]:  # a wrong name: the true form against the named one
                            row["named"] = {"fwd": cell["fwd"][named], "back": cell["back"][named],
                                            "score": cell["score"][named], "rival": named in sep["rivals"]}
                    row["fwd_look_alikes"] = {n: cell["fwd"][n] for n in LIBRARY[w["truth"]].confusable
                                              if n in cell["fwd"]}
                    out.append(row)
    return out


READABLE = 0.97  # stop 40: the share of held-out samples whose bank state a reader must get right


def unreadable_banks(stems: dict[str, str]) -> frozenset:
    """(set, kind, seed, window start, level) of the capacitor's V/θ cases in which even the two-state form with the
    truth choosing its settings reads less than :data:`READABLE` of the held-out state from the PMU's V
    (``agreement_best_two_state_noisy_v`` of :mod:`benchmarks.diagnosis_shunt_state`'s rows)."""
    out = set()
    for st, stem in stems.items():
        path = RESULTS / f"{stem}.json"
        if not path.exists():
            raise SystemExit(f"--readable {st}:{stem}: no {path} (run benchmarks.diagnosis_shunt_state --set {st} first)")
        for r in json.loads(path.read_text())["rows"]:
            if r["agreement_best_two_state_noisy_v"] < READABLE:
                out.add((st, "switched_capacitor", r["seed"], float(r["window"][0]), int(r["level"])))
    return frozenset(out)


def look_alike_margins(cases: list[dict]) -> dict:
    """{(mode, kind, look-alike): [forward z's of the detectable cases at L1, L2, L3]}."""
    out: dict = {}
    for c in cases:
        if c["detectable"]:
            for n, z in c.get("fwd_look_alikes", {}).items():
                out.setdefault((c["mode"], c["kind"], n), [[], [], []])[c["level"] - 1].append(z)
    return out


def library_table(cases: list[dict]) -> list[dict]:
    """Per noise mode, kind and level: detectable, detectable and separable, right among those, and what the
    verdict said on the detectable cases that are not separable."""
    agg: dict = {}
    for c in cases:
        if "outcome" not in c:
            continue
        a = agg.setdefault((c["mode"], c["kind"], c["level"]), {
            "cases": 0, "right": 0, "detectable": 0, "right_det": 0, "det_sep": 0, "right_det_sep": 0,
            "ambiguous_det_sep": 0, "det_not_sep": 0, "det_sep_outcomes": {}, "det_not_sep_outcomes": {}})
        right = c["outcome"] == c["expected"]
        a["cases"] += 1
        a["right"] += right
        if not c["detectable"]:
            continue
        a["detectable"] += 1
        a["right_det"] += right
        o = c["outcome"] if c["outcome"] in (c["expected"], "ambiguous", "consistent", "unexplained") else "wrong"
        o = "right" if o == c["expected"] else o
        if c["separable"]:
            a["det_sep"] += 1
            a["right_det_sep"] += right
            a["ambiguous_det_sep"] += o == "ambiguous"
            a["det_sep_outcomes"][o] = a["det_sep_outcomes"].get(o, 0) + 1
        else:
            a["det_not_sep"] += 1
            a["det_not_sep_outcomes"][o] = a["det_not_sep_outcomes"].get(o, 0) + 1
    from aslm_sim.andes.effects import KINDS

    order = list(KINDS)
    return [{"mode": m, "kind": k, "level": lvl, **v}
            for (m, k, lvl), v in sorted(agg.items(), key=lambda x: (MODES.index(x[0][0]), order.index(x[0][1]),
                                                                       x[0][2]))]


def reachable(cases: list[dict], zcrit: float) -> list[dict]:
    """Per mode and level, the right names any test at the diagnosis's level could give in expectation: the sum over
    the inside-library cases of Φ(z_oracle − zcrit), the chance that a statistic with that expectation and sd 1 is
    detected at all (an upper bound: a right name needs the detection), and the same over the separable cases only.
    The oracle's z is the most powerful linear statistic's expectation given the true correction, so with the
    diagnosis's critical value (fixed by its wrong-name budget) no test expects more detections."""
    out = []
    for mode in MODES:
        for lvl in sorted({c["level"] for c in cases}):
            rows = [c for c in cases if c["mode"] == mode and c["level"] == lvl]
            if not rows:
                continue
            p = np.array([stats.norm.cdf(c["z_oracle"] - zcrit) for c in rows])
            sep = np.array([bool(c["separable"]) for c in rows])
            out.append({"mode": mode, "level": lvl, "cases": len(rows), "detected": float(p.sum()),
                        "detected_and_separable": float(p[sep].sum())})
    return out


def honest_targets(tab: list[dict]) -> list[dict]:
    """Per mode and level, pooled over the kinds: right among detectable-and-separable against 80 % (60 % at
    L1), and the kinds that carry the misses (detectable and separable, not named right)."""
    out = []
    for mode in MODES:
        for lvl in sorted({t["level"] for t in tab}):
            rows = [t for t in tab if t["mode"] == mode and t["level"] == lvl]
            n = sum(t["det_sep"] for t in rows)
            right = sum(t["right_det_sep"] for t in rows)
            goal = 0.6 if lvl == 1 else 0.8
            out.append({"mode": mode, "level": lvl, "cases": sum(t["cases"] for t in rows),
                        "detectable": sum(t["detectable"] for t in rows), "det_sep": n, "right_det_sep": right,
                        "share": right / n if n else None, "goal": goal, "met": bool(n) and right >= goal * n,
                        "misses": {t["kind"]: t["det_sep"] - t["right_det_sep"] for t in rows
                                   if t["det_sep"] > t["right_det_sep"]}})
    return out


def library_markdown(tab: list[dict], targets: list[dict], cases: list[dict], zcrit: float) -> str:
    lines = [f"critical z = {zcrit:.2f}; detectable: oracle z ≥ critical; separable: the true form beats every "
             "rival (Holm 5 %) and none beats it back; outcomes other than right", "",
             "| mode | kind | level | cases | right | detectable | right among detectable | detectable & separable | "
             "right among det. & sep. | det. & sep.: outcomes | det. not separable: outcomes |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for t in tab:
        oc = ", ".join(f"{k} {v}" for k, v in sorted(t["det_not_sep_outcomes"].items())) or "-"
        sep_oc = ", ".join(f"{k} {v}" for k, v in sorted(t["det_sep_outcomes"].items()) if k != "right") or "-"
        lines.append(f"| {t['mode']} | {t['kind']} | L{t['level']} | {t['cases']} | {t['right']} | {t['detectable']} | "
                     f"{t['right_det']}/{t['detectable']} | {t['det_sep']} | {t['right_det_sep']}/{t['det_sep']} | "
                     f"{sep_oc} | {oc} |")
    lines += ["", "| mode | level | cases | detectable | det. & sep. | right among det. & sep. | goal | met? | "
              "misses (kind: det. & sep. not right) |", "|---|---|---|---|---|---|---|---|---|"]
    for g in targets:
        share = "-" if g["share"] is None else f"{100 * g['share']:.0f} %"
        miss = ", ".join(f"{k} {v}" for k, v in g["misses"].items()) or "-"
        lines.append(f"| {g['mode']} | L{g['level']} | {g['cases']} | {g['detectable']} | {g['det_sep']} | "
                     f"{g['right_det_sep']}/{g['det_sep']} = {share} | {100 * g['goal']:.0f} % | "
                     f"{'met' if g['met'] else 'not met'} | {miss} |")
    lines += ["", "The diagnosis's score z of the true candidate over the oracle's (detectable cases): median (quartiles)", ""]
    for mode in MODES:
        q = [c["z_true_diag"] / c["z_true"] for c in cases if c["mode"] == mode and c["detectable"]
             and c.get("z_true_diag") is not None and c.get("z_true")]
        if q:
            lo, mid, hi = np.percentile(q, [25, 50, 75])
            lines.append(f"* {mode}: {mid:.2f} ({lo:.2f}–{hi:.2f}), {len(q)} cases")
    lines += ["", "The true form over its declared look-alike, detectable windows: median (range) of the oracle's forward z",
              "", "| mode | kind | look-alike | L1 | L2 | L3 |", "|---|---|---|---|---|---|"]
    for (mode, kind, other), per in look_alike_margins(cases).items():
        cells = [f"{np.median(z):.1f} ({min(z):.1f}–{max(z):.1f}), {len(z)}" if z else "-" for z in per]
        lines.append(f"| {mode} | {kind} | {other} | " + " | ".join(cells) + " |")
    amb = [c for c in cases if c.get("outcome") == "ambiguous" and c["detectable"] and c["separable"]]
    if amb:
        lines += ["", "Detectable, separable and `ambiguous`: the oracle's z of the true form over each other listed "
                  "cause, and back", "", "| mode | kind | seed | window | level | z_oracle | listed with (fwd / back) |",
                  "|---|---|---|---|---|---|---|"]
        for c in amb:
            listed = "; ".join(f"{n} {_f(zs[0])} / {_f(zs[1])}" for n, zs in c.get("causes", {}).items()) or "-"
            lines.append(f"| {c['mode']} | {c['kind']} | {c['seed']} | {c['window']:g} | L{c['level']} | "
                         f"{c['z_oracle']:.1f} | {listed} |")
    wrong = [c for c in cases if "named" in c]
    if wrong:
        lines += ["", "Wrong names: the true form against the named one (oracle z forward = true over named, back = "
                  "named over true)", "",
                  "| mode | kind | seed | window | level | named | z_oracle | z true / named | fwd | back | rival? | "
                  "separable from all? | not separable from |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for c in wrong:
            nm = c["named"]
            zt = "-" if c["z_true"] is None else f"{c['z_true']:.1f}"
            lines.append(f"| {c['mode']} | {c['kind']} | {c['seed']} | {c['window']:g} | L{c['level']} | {c['outcome']} "
                         f"| {c['z_oracle']:.1f} | {zt} / {nm['score']:.1f} | {nm['fwd']:.2f} | {nm['back']:.2f} | "
                         f"{'yes' if nm['rival'] else 'no'} | {'yes' if c['separable'] else 'no'} | "
                         f"{', '.join(c['not_forward'] + c['reverse']) or '-'} |")
    return "\n".join(lines)


def _f(x: float | None) -> str:
    return "-" if x is None else f"{x:.1f}"


def _sets(arg: str) -> list[str]:
    """The comma-separated set names, refused when unknown or fixed for a later confirmation."""
    sets = [s for s in arg.split(",") if s]
    if "confirm5" in sets:
        raise SystemExit("confirm5 is fixed for a later confirmation: not for development")
    unknown = [s for s in sets if s not in SETS]
    if unknown:
        raise SystemExit(f"unknown sets {unknown}")
    return sets


def library_main(args, argv) -> int:
    """``--library``: :func:`window_library` on the sets' inside-library kinds, tallied against the verdicts."""
    from aslm_core.diagnosis.candidates import LIBRARY
    from aslm_sim.andes.effects import KINDS, cache_dir
    from benchmarks.diagnosis_detectability import _load_windows, critical_z

    sets = _sets(args.sets)
    kinds = [k for k in (args.kinds.split(",") if args.kinds else KINDS) if KINDS[k].expected in LIBRARY]
    stems = {s: f"diagnosis_independent_{s}" for s in sets}
    stems.update(dict(kv.split(":", 1) for kv in args.verdicts.split(",") if kv))
    todo = list(dict.fromkeys(j for st in sets for j in jobs(st, kinds)))
    t0 = time.perf_counter()
    windows = _load_windows(args.windows_from) if args.windows_from else []
    have = {(w["kind"], w["seed"]) for w in windows}
    todo = [j for j in todo if j not in have]
    partial = cache_dir() / f"{args.out}.partial.jsonl"  # every scenario's windows as they come
    with ProcessPoolExecutor(max_workers=args.workers) as pool, (partial.open("a") if todo else open(os.devnull, "w")) as fh:
        for job, ws in zip(todo, pool.map(window_library, *zip(*todo, strict=True)) if todo else [], strict=True):
            windows += ws
            fh.writelines(json.dumps(w, default=float) + "\n" for w in ws)
            fh.flush()
            print(f"{job[0]}/{job[1]}: {len(ws)} windows, {time.perf_counter() - t0:.0f} s", flush=True)
    zcrit = critical_z()
    unread = unreadable_banks(dict(kv.split(":", 1) for kv in args.readable.split(",") if kv))
    cases = library_cases([w for w in windows if w["kind"] in kinds], sets, stems, zcrit, args.margin,
                          args.detect_margin, unread)
    tab = library_table(cases)
    targets = honest_targets(tab)
    reach = reachable(cases, zcrit)
    print(library_markdown(tab, targets, cases, zcrit))
    print("\nRight names any test at the diagnosis's level could give, in expectation (Σ Φ(z_oracle − critical)):\n")
    print("| mode | level | cases | detected | detected, separable cases only |\n|---|---|---|---|---|")
    for r in reach:
        print(f"| {r['mode']} | L{r['level']} | {r['cases']} | {r['detected']:.1f} = {r['detected'] / r['cases']:.0%} | "
              f"{r['detected_and_separable']:.1f} = {r['detected_and_separable'] / r['cases']:.0%} |")
    print(f"\n{len(windows)} windows, {len(cases)} cases, {time.perf_counter() - t0:.0f} s, load {os.getloadavg()}")
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"{args.out}.json").write_text(json.dumps({
        "sets": sets, "critical_z": zcrit, "alpha": ALPHA_SEP, "margin": args.margin,
        "detect_margin": args.detect_margin, "readable_from": args.readable, "verdicts_from": stems, "targets": targets,
        "reachable": reach,
        "table": tab, "cases": cases, "windows": windows, "load_avg": os.getloadavg(),
        "wall_s": time.perf_counter() - t0,
        "command": "benchmarks/diagnosis_separability.py " + " ".join(argv if argv is not None else sys.argv[1:])},
        indent=1, default=float))
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sets", default="dev,confirm,confirm2,dev3,confirm3,confirm4")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--tag", default="", help="written as diagnosis_separability_<tag>.json")
    p.add_argument("--library", action="store_true", help="every inside-library kind's true form against every "
                   "other candidate, both noise modes, tallied against --verdicts (stop 31)")
    p.add_argument("--kinds", default="", help="--library: kinds (default: those whose cause is a candidate)")
    p.add_argument("--verdicts", default="", help="--library: set:results-file-stem pairs of the runs of record "
                   "(default diagnosis_independent_<set>; several stems joined by +)")
    p.add_argument("--margin", type=float, default=0.0, help="--library: forward z's must clear Holm's critical "
                   "value by this much more")
    p.add_argument("--detect-margin", type=float, default=0.0, help="--library: the oracle z must clear the "
                   "critical value by this much more to count as detectable")
    p.add_argument("--readable", default="", help="--library: set:stem pairs of diagnosis_shunt_state runs; the "
                   "capacitor's V/θ cases whose state the two-state form cannot read are not detectable")
    p.add_argument("--out", default="diagnosis_separability_library", help="--library: output stem")
    p.add_argument("--windows-from", default="", help="--library: reuse the windows of an earlier output (stem or "
                   ".partial.jsonl path), computing only the missing scenarios")
    args = p.parse_args(argv)
    if args.library:
        return library_main(args, argv)
    sets = _sets(args.sets)
    todo = sorted({j for st in sets for j in jobs(st, list(PAIR))})
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        rows = [w for ws in pool.map(window_pair, *zip(*todo, strict=True)) for w in ws]
    summary = per_level(rows)
    print(f"{'kind':24s} level  windows  separable  both-ways  true-loses  neither")
    for kind, lv in summary.items():
        for lvl, c in lv.items():
            print(f"{kind:24s} {lvl:5s}  {c['windows']:7d}  {c['separable']:9d}  {c['both_ways']:9d}  "
                  f"{c['true_loses']:10d}  {c['neither']:7d}")
    print(f"{len(rows)} windows, {time.perf_counter() - t0:.0f} s, load {os.getloadavg()}")
    RESULTS.mkdir(parents=True, exist_ok=True)
    name = "diagnosis_separability" + (f"_{args.tag}" if args.tag else "")
    (RESULTS / f"{name}.json").write_text(json.dumps({
        "sets": sets, "levels_db": NOISE_LEVELS, "z_one": Z_ONE, "summary": summary, "windows": rows,
        "load_avg": os.getloadavg(), "wall_s": time.perf_counter() - t0,
        "command": "benchmarks/diagnosis_separability.py " + " ".join(argv if argv is not None else sys.argv[1:])},
        indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
