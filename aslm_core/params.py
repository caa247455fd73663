"""Declaration of every model parameter: name, unit, meaning and identification bounds.

The transformed third-order induction motor (paper eq. 4) has D = [a, b, H2, Tm]; the static part
is ZIP (eq. 6) or exponential.  Bounds are the paper's §V.A box; Tm's upper bound is the window's
mean active power, and a·Vmin² > 2b·Tm keeps an equilibrium in existence.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ParamSpec:
    """One identified parameter."""

    name: str
    unit: str
    description: str
    lower: float
    upper: float | None  # None: set from the data (Tm <= mean P)
    #: The range the physics allows, past the box (lower, upper; None: as ``upper``); for D only.  The diagnosis
    #: opens its box to it where the plain fit is pinned (:func:`physical_bounds`).
    physical: tuple[float, float | None] | None = None


DYNAMIC_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("a", "1/s", "(X/X' - 1)/(Td0 X'): drive of the rotor flux by the voltage", 10.0, 80.0, (1.0, 200.0)),
    ParamSpec("b", "1/s", "X/(Td0 X'): decay rate of the rotor flux", 3.0, 30.0, (1.0, 100.0)),
    ParamSpec("H2", "s", "inertia constant (2H) of the slip equation", 0.5, 3.0, (0.1, 10.0)),
    ParamSpec("Tm", "pu", "mechanical load torque on the system base", 0.0, None, (0.0, None)),
)
DYNAMIC_NAMES: tuple[str, ...] = tuple(p.name for p in DYNAMIC_PARAMS)

ZIP_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("Pz", "pu", "constant-impedance active power coefficient (of V^2)", -np.inf, np.inf),
    ParamSpec("Pi", "pu", "constant-current active power coefficient (of V)", -np.inf, np.inf),
    ParamSpec("Pp", "pu", "constant-power active power", -np.inf, np.inf),
    ParamSpec("Qz", "pu", "constant-impedance reactive coefficient (includes the motor's V^2/X')", -np.inf, np.inf),
    ParamSpec("Qi", "pu", "constant-current reactive power coefficient (of V)", -np.inf, np.inf),
    ParamSpec("Qp", "pu", "constant-power reactive power", -np.inf, np.inf),
)
ZIP_NAMES: tuple[str, ...] = tuple(p.name for p in ZIP_PARAMS)

EXPONENTIAL_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("P0", "pu", "static active power at V = 1 pu", -np.inf, np.inf),
    ParamSpec("np", "-", "voltage exponent of the static active power", -np.inf, np.inf),
    ParamSpec("Q0", "pu", "static reactive power at V = 1 pu (includes the motor's V^2/X')", -np.inf, np.inf),
    ParamSpec("nq", "-", "voltage exponent of the static reactive power", -np.inf, np.inf),
)
EXPONENTIAL_NAMES: tuple[str, ...] = tuple(p.name for p in EXPONENTIAL_PARAMS)


def dynamic_bounds(p_mean: float) -> tuple[np.ndarray, np.ndarray]:
    """Box bounds of D = [a, b, H2, Tm].

    Parameters
    ----------
    p_mean : float
        Mean measured active power of the window [pu]; the upper bound of Tm.

    Returns
    -------
    lower, upper : ndarray of shape (4,)
    """
    lower = np.array([p.lower for p in DYNAMIC_PARAMS])
    upper = np.array([p.upper if p.upper is not None else max(p_mean, 0.0) for p in DYNAMIC_PARAMS])
    return lower, upper


def physical_bounds(p_mean: float) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of D = [a, b, H2, Tm] that the motor's physics allows (``ParamSpec.physical``), wider than the box.

    a and H2 scale with the motor's rating on the system base (X' ∝ Sb/Sn, H2 = 2H·Sn/Sb) and b not (paper
    eq. 4–5), so a small or light motor on a 100 MVA base leaves the paper's §V.A box (a 22 MVA motor with
    H = 1 s has H2 = 0.44 s).  a ∈ [1, 200] /s, b ∈ [1, 100] /s (rotor resistance up to about 0.04 pu on the
    motor's base with typical reactances) and H2 ∈ [0.1, 10] s are meant to hold any induction motor up to the
    bus's own size (chosen from the transform, not tuned); Tm's box is its physical range already
    (0 ≤ Tm ≤ mean P).  At 50 frames/s or more the flux mode's b·dt stays inside RK4's stability interval.

    Parameters
    ----------
    p_mean : float
        Mean measured active power of the window [pu]; the upper bound of Tm.

    Returns
    -------
    lower, upper : ndarray of shape (4,)
    """
    lower, upper = dynamic_bounds(p_mean)
    for i, p in enumerate(DYNAMIC_PARAMS):
        lo, hi = p.physical if p.physical is not None else (p.lower, p.upper)
        lower[i] = min(lower[i], lo)
        if hi is not None:
            upper[i] = max(upper[i], hi)
    return lower, upper


def equilibrium_margin(d: np.ndarray, v_min: float) -> float:
    """Margin of the equilibrium-existence constraint a·Vmin² − 2b·Tm [pu·1/s].

    Positive when the motor's maximum torque a·V²/(2b) exceeds Tm at the lowest voltage of the window.
    """
    return float(d[0] * v_min * v_min - 2.0 * d[1] * d[3])
