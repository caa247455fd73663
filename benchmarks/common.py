"""Shared helpers of the reproduction benchmarks: case generation, statistics, markdown/JSON output."""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import sys
import time
from pathlib import Path

import numpy as np

from aslm_sim.cases import make_cases
from aslm_sim.network import MAX_FORCING_STEP_S

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "reproduction.md"
RESULTS = ROOT / "docs" / "results"
PARAMS = ("a", "b", "H2", "Tm")
#: ``IdentifyConfig`` options of output error without the noisy-input weighting: the identifier before the one
#: default of issues 11 and 20 (``input_weighting="spectral"``, ``disturbance="gated"``), named by baselines.
OUTPUT_ERROR = {"input_weighting": "none", "disturbance": "none"}
PAPER_TABLE1 = {  # DL: (mean SNR, σ(a), μ(a), σ(b), μ(b), σ(H2), μ(H2), σ(Tm), μ(Tm))
    1: (14.24, 0.030, 1.001, 0.029, 1.005, 0.034, 0.993, 0.021, 1.000),
    2: (21.77, 0.022, 0.999, 0.024, 1.002, 0.028, 0.999, 0.016, 1.000),
    3: (28.03, 0.020, 0.999, 0.022, 1.001, 0.023, 1.000, 0.014, 1.000),
}
PAPER_TABLE2 = {  # DL: (M(FD), %>0.9, %>0.95) for Fault YC and Fault XLS
    1: ((0.981, 85.5, 76.4), (0.977, 89.7, 79.4)),
    2: ((0.988, 97.5, 94.2), (0.984, 98.5, 95.8)),
    3: ((0.991, 99.0, 97.4), (0.987, 99.1, 97.9)),
}


def parser(description: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--quick", action="store_true", help="small counts: a 1–2 minute smoke run")
    p.add_argument("--no-write", action="store_true", help="print only; do not update docs/")
    return p


def cases(n: int, *, level: int | None, seed: int, input_noise: bool = False, fs: float = 100.0) -> list:
    """``make_cases`` in chunks of 250 (bounded memory); chunk k uses seed·1000 + k, so the set is
    deterministic for (seed, n) and the same seed at different levels gives the same clean records.
    ``fs``: the reporting rate [frames/s]."""
    out = []
    chunk = 250
    for k, start in enumerate(range(0, n, chunk)):
        m = min(chunk, n - start)
        out.extend(make_cases(m, level=level, seed=seed * 1000 + k, input_noise=input_noise, fs=fs))
    return out


def bootstrap_mu_sigma(ratios: np.ndarray, n_boot: int = 2000) -> dict:
    """95 % bootstrap intervals (percentile, cases resampled) of μ and σ per parameter of (n, 4) ratios.

    Returns ``{"mu": {p: [lo, hi]}, "sigma": {p: [lo, hi]}}``.
    """
    r = np.asarray(ratios, dtype=float).reshape(-1, 4)
    rng = np.random.default_rng(0)
    idx = rng.integers(0, len(r), (n_boot, len(r)))
    boot = r[idx]  # (n_boot, n, 4)
    out = {}
    for key, stat in (("mu", boot.mean(axis=1)), ("sigma", boot.std(axis=1, ddof=1))):
        lo, hi = np.percentile(stat, [2.5, 97.5], axis=0)
        out[key] = {p: [float(a), float(b)] for p, a, b in zip(PARAMS, lo, hi, strict=True)}
    return out


def ratio_stats(ratios: np.ndarray) -> dict:
    """μ, σ, median and max |r − 1| per parameter of an (n, 4) array of D_opt/D_real."""
    r = np.asarray(ratios, dtype=float).reshape(-1, 4)
    return {
        "n": int(r.shape[0]),
        "mu": dict(zip(PARAMS, np.mean(r, axis=0).tolist(), strict=True)),
        "sigma": dict(zip(PARAMS, np.std(r, axis=0, ddof=1).tolist(), strict=True)) if r.shape[0] > 1 else None,
        "median": dict(zip(PARAMS, np.median(r, axis=0).tolist(), strict=True)),
        "max_abs_err": dict(zip(PARAMS, np.max(np.abs(r - 1.0), axis=0).tolist(), strict=True)),
        "n_off_20pct": int(np.sum(np.any(np.abs(r - 1.0) > 0.2, axis=1))),
    }


def md_table(headers: list[str], rows: list[list]) -> str:
    def cell(x):
        if isinstance(x, float):
            return f"{x:.4g}" if abs(x) >= 1e-3 or x == 0 else f"{x:.2e}"
        return str(x)

    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    lines += ["| " + " | ".join(cell(x) for x in r) + " |" for r in rows]
    return "\n".join(lines)


def machine() -> dict:
    try:
        load = os.getloadavg()
    except OSError:  # pragma: no cover
        load = (float("nan"),) * 3
    cpu = platform.processor()
    try:
        with open("/proc/cpuinfo") as f:
            m = re.search(r"model name\s*:\s*(.*)", f.read())
            cpu = m.group(1) if m else cpu
    except OSError:  # pragma: no cover
        pass
    import numba
    import scipy

    return {
        "cpus": os.cpu_count(), "cpu": cpu, "load_avg_at_start": [round(x, 2) for x in load],
        "python": sys.version.split()[0], "numpy": np.__version__, "scipy": scipy.__version__,
        "numba": numba.__version__, "forcing_step_s": MAX_FORCING_STEP_S,
        "date": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
    }


def write_json(name: str, obj: dict) -> Path:
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    path.write_text(json.dumps(obj, indent=1, default=_default) + "\n")
    return path


def read_json(name: str) -> dict:
    """A run of record written by :func:`write_json` (``docs/results/<name>.json``)."""
    return json.loads((RESULTS / f"{name}.json").read_text())


def _default(o):
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o))


def write_section(name: str, body: str) -> None:
    """Replace (or append) the block between ``<!-- BEGIN name -->`` and ``<!-- END name -->`` of the doc.

    Smoke runs (``--quick``, names ending in ``-quick``) leave the document alone: their numbers go to
    ``docs/results/*_quick.json`` only.
    """
    if name.endswith("-quick"):
        return
    DOC.parent.mkdir(parents=True, exist_ok=True)
    text = DOC.read_text() if DOC.exists() else "# Reproduction of the paper's case study\n"
    begin, end = f"<!-- BEGIN {name} -->", f"<!-- END {name} -->"
    block = f"{begin}\n{body.strip()}\n{end}"
    if begin in text and end in text:
        pre, rest = text.split(begin, 1)
        _, post = rest.split(end, 1)
        text = pre + block + post
    else:
        text = text.rstrip() + "\n\n" + block + "\n"
    DOC.write_text(text)


def command(module: str, quick: bool) -> str:
    return f".venv/bin/python -m benchmarks.{module}" + (" --quick" if quick else "")
