"""Errors raised for input that cannot give a trustworthy identification."""

from __future__ import annotations


class WindowError(ValueError):
    """A window that cannot be identified.

    Attributes
    ----------
    reason : str
        Machine-readable code: ``too_short``, ``non_finite``, ``non_uniform``, ``gaps``,
        ``non_monotonic``, ``shape``, ``no_excitation``, ``bad_range``.
    """

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(f"{reason}: {message}")
        self.reason = reason
        self.message = message

    def __reduce__(self) -> tuple:
        # Pickled with both arguments (the default passes ``args``, the joined text, alone): forked batch
        # workers (:func:`aslm_core.identify_many`) send rejected windows' errors back to the parent.
        return type(self), (self.reason, self.message)


class NoEquilibriumError(ValueError):
    """The motor D has no steady state at the given voltage (a·V² <= 2b·Tm)."""
