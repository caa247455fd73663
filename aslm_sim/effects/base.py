"""What a concealed effect declares (:class:`Effect`) and what applying one gives (:class:`EffectCase`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from aslm_core.window import Window
from aslm_sim.cases import SyntheticCase

__all__ = ["Effect", "EffectCase", "EffectOutput"]

#: What a generator returns: ΔP, ΔQ [pu] at the case's samples and the effect's own parameters.
EffectOutput = tuple[np.ndarray, np.ndarray, dict[str, float]]


@dataclass(frozen=True)
class Effect:
    """One concealed effect: its name, where it acts, how large it is drawn, and the code that makes it.

    Attributes
    ----------
    name : str
        For a library effect, the name of the candidate that should find it.
    generate : callable
        ``generate(case, magnitude, rng) -> (dP, dQ, truth)``: the effect on the case's noise-free
        record (``case.clean``, ``case.truth``) computed with its own model code, independent of the
        candidate: ΔP, ΔQ [pu] and its parameters in the candidate's units.  Its random draws come from
        ``rng`` only, in a fixed order, so that every concealment try sees the same effect.
    magnitude : tuple of float
        Range of the magnitude drawn when none is given (uniform), in the effect's own unit (its module
        says which).
    channels : str
        Channels it acts on: ``"P"``, ``"Q"`` or ``"PQ"``.
    in_library : bool
        A candidate of the diagnosis library models it; otherwise the right verdict is ``unexplained``.
    label : str
        Short name (a column of the benchmark's confusion matrix).
    main_parameter : str or None
        The entry of ``truth`` whose recovery the benchmark reports.
    concealable : bool
        Concealment may shrink the magnitude; False keeps the drawn value (a physical exponent, say).
    user_model : bool
        Not identifiable against a re-identified model: diagnosed against the case's true model.
    """

    name: str
    generate: Callable[[SyntheticCase, float, np.random.Generator], EffectOutput]
    magnitude: tuple[float, float]
    channels: str
    in_library: bool
    label: str
    main_parameter: str | None = None
    concealable: bool = True
    user_model: bool = False


@dataclass
class EffectCase:
    """A synthetic case with a concealed effect.

    Attributes
    ----------
    window : Window
        Noisy record with the effect.
    effect : str
        Effect name (``none`` for the clean case).
    truth : dict
        The effect's own parameters, in the candidate's units.
    base : SyntheticCase
        The case it was built on.
    model : dict or None
        The user model to diagnose against (effects with ``user_model`` only).
    fd_plain : dict
        FD of the plain ZIP + IM fit of the whole window (concealment check).
    scale : float
        Factor the drawn magnitude was reduced by for concealment.
    """

    window: Window
    effect: str
    truth: dict
    base: SyntheticCase
    model: dict | None = None
    fd_plain: dict = field(default_factory=dict)
    scale: float = 1.0
