"""Tolerances in one place, with named profiles.

Every numerical threshold fixplan uses lives here, so a reader can see what "touching" or
"balanced" means without hunting for literals.
"""

from __future__ import annotations

from dataclasses import dataclass, replace


@dataclass(frozen=True)
class Tolerances:
    """Numerical thresholds.

    Attributes
    ----------
    touch_m : float
        A locator touches the workpiece when its gap is at most this [m].
    penetration_m : float
        Largest start-pose penetration of a locator tip accepted by the loader [m].
    goal_gap_m : float
        Largest gap accepted at a given or computed goal pose [m].
    balance_rel : float
        Static balance holds when the least M⁻¹-weighted residual is at most this fraction of
        the wrench's own M⁻¹-norm (scale-free, so a wrench of 1e-6 N and of 1e6 N get the same
        verdict).
    cone_eps : float
        Solver accuracy requested from the cone-program backends (relative).
    slip_rel : float
        A contact's tangential acceleration counts as slipping above this fraction of the body
        acceleration.
    """

    touch_m: float = 1e-6
    penetration_m: float = 1e-6
    goal_gap_m: float = 1e-6
    balance_rel: float = 1e-6
    cone_eps: float = 1e-9
    slip_rel: float = 1e-6

    def with_(self, **changes: float) -> Tolerances:
        """A copy with some fields changed."""
        return replace(self, **changes)


PROFILES: dict[str, Tolerances] = {
    "strict": Tolerances(balance_rel=1e-8, cone_eps=1e-10, slip_rel=1e-8),
    "default": Tolerances(),
    "haptic": Tolerances(balance_rel=1e-4, cone_eps=1e-7, slip_rel=1e-4),
}

DEFAULT = PROFILES["default"]
