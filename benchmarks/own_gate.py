"""Per-window records of the own-fluctuation benches, and the gated composite computed from them.

The gated default under study (issue 20): output error's answer where its own ``own_ratio_p`` is at most
:data:`aslm_core.identify.OWN_UNMODELLED_RATIO` (the threshold of ``own_fluctuation_unmodelled``, fixed on the
development windows), ``disturbance="ar_iv"``'s otherwise; optionally falling back to output error where the
IV's own over-identification test rejects its instruments (``iv_overid`` above a bound).  Computed from the
records, without identifying again.
"""

from __future__ import annotations

import math

import numpy as np

from aslm_core import WindowError
from aslm_core.identify import OWN_UNMODELLED_RATIO
from benchmarks import common

#: Every flag that tells the user not to trust a window's D.
WARNING_FLAGS = ("uncertain", "poor_fit", "at_bound", "restarts", "unexplained_fluctuation", "low_excitation",
                 "equilibrium_constraint_active", "own_fluctuation_unmodelled", "iv_instruments_rejected",
                 "iv_error_may_exceed", "input_noise_too_large", "error_may_exceed", "input_noise_correction_large",
                 "halves_disagree")
#: Per-window quality entries kept in the JSON (to develop flags and gates on).
QUALITY_KEYS = ("own_ratio_p", "own_ratio_q", "excitation_share_p", "iv_strength_p", "iv_strength_q", "iv_overid",
                "iv_overid_white", "ar_order_p", "static_cond", "lowpass_hz", "gated_ar_iv",
                "weighted_chi2", "input_ratio_v", "weighted_shift_z", "halves_z")
CONFIRM_HEAD = ["own/total", "shape, V/θ noise", "windows to the IV", "median |err| a / b / H2 / Tm [%]: output error",
                "gated", "gated / output error", "off > 20 % (unflagged)", "within 20 % with `iv_error_may_exceed_20pct`"]
GATE_HEAD = ["own/total", "shape", "windows switched", "median |err| a / b / H2 / Tm [%]", "worst [%]",
             "bias μ−1 a / b / H2 / Tm [%]", "±1.96 SE cover [%]", "off > 20 % (unflagged)"]


def window_records(truths: list[np.ndarray], results: list[dict], names: list[str]) -> dict:
    """Per candidate and window: relative errors and standard errors of D [-], flags, ``QUALITY_KEYS``.

    ``results``: per window, {name: (IdentificationResult or WindowError, seconds)}; a failed window is None
    (flags ``["error"]``).
    """
    def per(fn, failed):
        return {name: [failed if isinstance(r[name][0], WindowError) else fn(r[name][0], truth)
                       for r, truth in zip(results, truths, strict=True)] for name in names}

    return {
        "flags": per(lambda r, t: r.flags, ["error"]),
        "errors": per(lambda r, t: (r.d / t - 1).tolist(), None),
        "stderr": per(lambda r, t: [r.stderr[k] / v for k, v in zip(common.PARAMS, t, strict=True)], None),
        "quality": per(lambda r, t: {k: r.quality.get(k, math.nan) for k in QUALITY_KEYS}, None),
        "own_ratio_p": per(lambda r, t: r.quality.get("own_ratio_p", math.nan), None),
    }


def gated_row(run: dict, fallback: str = "output error", model: str = "AR disturbance (IV)",
              overid_max: float | None = None, label: str | None = None) -> list:
    """One row of the gated composite from a run's records: ``fallback``'s window where its ``own_ratio_p`` is at
    most :data:`aslm_core.identify.OWN_UNMODELLED_RATIO`, ``model``'s otherwise; with ``overid_max``, also
    ``fallback``'s where ``model``'s ``iv_overid`` exceeds it (its instruments rejected).  ``label``: the
    shape column (default the run's shape).
    """
    picked, switched = [], 0
    quality = run.get("quality", {}).get(model)
    for i, ratio in enumerate(run["own_ratio_p"][fallback]):
        use = model if ratio is not None and ratio > OWN_UNMODELLED_RATIO else fallback
        if use == model and overid_max is not None and quality is not None and quality[i] is not None \
                and not quality[i]["iv_overid"] <= overid_max:
            use = fallback
        switched += use == model
        if run["errors"][use][i] is not None:
            picked.append((run["errors"][use][i], run["stderr"][use][i], run["flags"][use][i]))
    err = np.array([e for e, _, _ in picked])
    se = np.array([s for _, s, _ in picked])
    off = [np.max(np.abs(e)) > 0.2 for e, _, _ in picked]
    unflagged = sum(o and not any(f.startswith(WARNING_FLAGS) for f in fl) for o, (_, _, fl) in zip(off, picked, strict=True))
    return [f"{run['ratio']:g}", label or run["shape"], f"{switched} / {len(run['own_ratio_p'][fallback])}",
            " / ".join(f"{100 * v:.1f}" for v in np.median(np.abs(err), axis=0)), f"{100 * np.abs(err).max():.0f}",
            " / ".join(f"{100 * v:+.1f}" for v in err.mean(axis=0)),
            " / ".join(f"{100 * v:.0f}" for v in np.mean(np.abs(err) <= 1.96 * se, axis=0)),
            f"{sum(off)} ({unflagged})"]


def confirm_row(run: dict, label: str, gated: str = "gated", fallback: str = "output error") -> tuple[list, dict]:
    """One row of the gated estimator's confirmation from a run's records, and its counts.

    Windows the IV answered (``gated_ar_iv`` 1), median |error| of output error and of ``gated`` and their ratio,
    ``gated``'s windows off by more than 20 % (of them without a warning flag), and its IV-answered windows within
    20 % that carry ``iv_error_may_exceed_20pct`` (of them with no other warning flag).
    """
    idx = [i for i, e in enumerate(run["errors"][gated]) if e is not None and run["errors"][fallback][i] is not None]
    eg = np.abs(np.array([run["errors"][gated][i] for i in idx]))
    eo = np.abs(np.array([run["errors"][fallback][i] for i in idx]))
    iv = [i for i in idx if run["quality"][gated][i]["gated_ar_iv"] == 1.0]

    def warned(flags: list, ignore: tuple[str, ...] = ()) -> bool:
        return any(f.startswith(WARNING_FLAGS) and not f.startswith(ignore) for f in flags)

    off = [i for i in idx if max(abs(x) for x in run["errors"][gated][i]) > 0.2]
    counts = {"windows": len(idx), "to_iv": len(iv), "off": len(off),
              "off_unflagged": sum(not warned(run["flags"][gated][i]) for i in off),
              "iv_within": sum(max(abs(x) for x in run["errors"][gated][i]) <= 0.2 for i in iv)}
    within_flagged = [i for i in iv if i not in off and "iv_error_may_exceed_20pct" in run["flags"][gated][i]]
    counts["iv_within_flagged"] = len(within_flagged)
    counts["iv_within_flagged_only_by_it"] = sum(not warned(run["flags"][gated][i], ("iv_error_may_exceed",))
                                                 for i in within_flagged)
    mg, mo = np.median(eg, axis=0), np.median(eo, axis=0)
    counts["median_gated"], counts["median_output_error"] = mg.tolist(), mo.tolist()
    row = [f"{run['ratio']:g}", label, f"{len(iv)} / {len(idx)}", " / ".join(f"{100 * v:.1f}" for v in mo),
           " / ".join(f"{100 * v:.1f}" for v in mg), " / ".join(f"{g / o:.2f}" for g, o in zip(mg, mo, strict=True)),
           f"{len(off)} ({counts['off_unflagged']})",
           f"{len(within_flagged)} of {counts['iv_within']} ({counts['iv_within_flagged_only_by_it']} by it alone)"]
    return row, counts


def print_confirm(recorded: dict, label=lambda run: run["shape"]) -> dict:
    """Print the confirmation table of each gated candidate of a run (``gated``, ``gated, ...``; output error among
    the candidates too) and return its counts per row, by candidate."""
    out = {}
    for name in (k for k in recorded["candidates"] if k.startswith("gated")):
        body, counts = [], []
        for run in recorded["runs"]:
            row, c = confirm_row(run, label(run), gated=name)
            body.append(row)
            counts.append({"shape": run["shape"], "ratio": run["ratio"], "input_noise": run.get("input_noise"), **c})
        print(f"\n{name}\n" + common.md_table(CONFIRM_HEAD, body))
        out[name] = {"rows": counts}
    return out
