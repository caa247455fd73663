"""Applying a registered effect to a synthetic case, concealed from the plain ZIP + IM fit."""

from __future__ import annotations

import numpy as np

from aslm_core.diagnosis.identify_options import pinned_config
from aslm_core.identify import identify
from aslm_core.window import Window
from aslm_sim.cases import SyntheticCase, make_cases
from aslm_sim.effects import EFFECTS
from aslm_sim.effects.base import EffectCase

__all__ = ["apply_effect", "make_effect_cases"]

#: The identifier that decides whether an effect is concealed: pinned, so the self-test's cases do not move
#: with the identifier's defaults.
_CONCEAL = pinned_config()


def apply_effect(case: SyntheticCase, name: str, magnitude: float | None = None, *, seed: int = 0,
                 conceal: bool = True, max_tries: int = 6, conceal_case: SyntheticCase | None = None) -> EffectCase:
    """Add an effect to a synthetic case (noise: the case's own realisation).

    Parameters
    ----------
    case : SyntheticCase
        Made with ``input_noise=False`` (noise on P and Q only, the paper's protocol) or ``True`` (V, θ
        and f noisy too: the window keeps them; the effect is computed from the noise-free V and θ, as the
        load sees them).
    name : str
        A key of :data:`aslm_sim.effects.EFFECTS`, or ``none``.
    magnitude : float, optional
        In the effect's unit (see its module); default drawn from its ``magnitude`` range.
    seed : int
        Seed of the effect's own random draws.
    conceal : bool
        Reduce the magnitude (×0.7 per try) until the plain fit has FD ≥ 0.9 on P and Q.
    max_tries : int
        Reductions tried before giving up (the last one is returned, flagged by ``fd_plain``).
    conceal_case : SyntheticCase, optional
        Conceal on this case instead — e.g. the same seed without input noise, whose plain fit is not
        degraded by noisy V and θ — and apply the magnitude found there to ``case`` (same draws);
        ``fd_plain`` and ``scale`` are then the twin's.

    Returns
    -------
    EffectCase
    """
    rng_m = np.random.default_rng([seed, 7])
    w = case.window
    if name == "none":
        r = identify(w, config=_CONCEAL)
        return EffectCase(w, "none", {}, case, fd_plain=dict(r.fit))
    if name not in EFFECTS:
        raise ValueError(f"unknown effect {name!r}")
    effect = EFFECTS[name]
    if magnitude is None:
        magnitude = float(rng_m.uniform(*effect.magnitude))
    if conceal and conceal_case is not None:
        twin = apply_effect(conceal_case, name, magnitude, seed=seed, conceal=True, max_tries=max_tries)
        mag = magnitude * twin.scale if effect.concealable else magnitude
        ec = apply_effect(case, name, mag, seed=seed, conceal=False)
        ec.fd_plain, ec.scale = twin.fd_plain, twin.scale
        return ec
    scale = 1.0
    model = None
    if effect.user_model:
        tr = case.truth
        model = {"dynamic": tr.dynamic, "static": tr.static_identifiable}
    for _ in range(max_tries):
        rng = np.random.default_rng([seed, 11])  # same draws at every scale
        dp, dq, truth = effect.generate(case, magnitude * scale if effect.concealable else magnitude, rng)
        win = Window(t=w.t, V=w.V, theta=w.theta, P=w.P + dp, Q=w.Q + dq, f=w.f, f0=w.f0, bus=w.bus,
                     meta={**w.meta, "effect": name})
        if not conceal:
            return EffectCase(win, name, truth, case, model, {}, scale)
        r = identify(win, config=_CONCEAL)
        if min(r.fit["fd_p"], r.fit["fd_q"]) >= 0.9 or not effect.concealable:
            return EffectCase(win, name, truth, case, model, dict(r.fit), scale)
        scale *= 0.7
    return EffectCase(win, name, truth, case, model, dict(r.fit), scale)


def make_effect_cases(name: str, n: int, *, level: int, seed: int = 0, f0: float = 50.0) -> list[EffectCase]:
    """Concealed cases of one effect at a noise level.

    Parameters
    ----------
    name : str
        Effect (see :func:`apply_effect`).
    n : int
        Number of cases.
    level : int
        Noise level of :data:`aslm_sim.noise.NOISE_LEVELS`.
    seed : int
        Seed of the synthetic cases (``make_cases(n, seed=seed)``) and of the effects.
    f0 : float
        Nominal frequency [Hz].

    Returns
    -------
    list of EffectCase
    """
    cases = make_cases(n, level=level, seed=seed, input_noise=False, f0=f0)
    return [apply_effect(c, name, seed=seed * 100003 + i) for i, c in enumerate(cases)]
