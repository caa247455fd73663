"""The identifier's options the diagnosis (and its self-test's concealment) rely on, pinned.

The diagnosis starts every fit from a ZIP + IM identified by :func:`aslm_core.identify.identify`, and the
self-test conceals its effects until that identifier accepts the window; both were tuned and confirmed with
these options.  They are spelt out rather than taken from :class:`~aslm_core.result.IdentifyConfig`'s
defaults so that a change of the identifier's defaults (e.g. the noisy-input weighting becoming the default)
does not move the diagnosis's figures unnoticed.
"""

from __future__ import annotations

from aslm_core.result import IdentifyConfig

#: IdentifyConfig's values when the diagnosis's thresholds were tuned (issue 12, rounds 1-4).
PINNED: dict = {
    "integrator": "rk4", "objective": "paper", "static": "zip", "skip_s": 1.0, "transient_tau": 5.0,
    "skip_max_s": 3.0, "n_starts": 3, "lowpass_hz": None, "input_smoother": "wiener_lowpass",
    "input_cutoff_hz": 3.0, "max_iter": 60, "seed": 0, "max_gap_samples": 5, "min_duration_s": 5.0,
    "coarse_to_fine": True, "disturbance": "none", "ar_max_order": 30, "couple_channels": False,
    "stderr_method": "spectral",
    "input_weighting": "none", "input_spectrum_tail": False, "iv_estimator": "2sls",
    "iv_whitening": "residual", "input_noise": "auto",
}


def pinned_config(**overrides) -> IdentifyConfig:
    """An :class:`IdentifyConfig` with every option of :data:`PINNED`, some overridden by keyword."""
    unknown = set(overrides) - set(PINNED)
    if unknown:
        raise TypeError(f"not a pinned identifier option: {sorted(unknown)}")
    return IdentifyConfig(**{**PINNED, **overrides})
