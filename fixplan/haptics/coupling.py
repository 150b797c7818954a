"""The virtual coupling between the device handle and the simulated workpiece.

A spring–damper ``w = K (x_d − x_w) + B (ẋ_d − ẋ_w)`` acts on the workpiece (and its reaction,
what the user feels, on the device). Sampled at period ``T`` and displayed through a device whose
own viscous damping is ``b``, the loop is passive (Colgate & Schenkel 1997) when

    b > K T / 2 + |B|

for every coordinate's gains. :func:`check_passivity` refuses gains that break it; the margin is
kept in the result so a caller can report it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fixplan.errors import InputError

FloatArray = NDArray[np.float64]


def passivity_margin(K: float, B: float, T: float, b: float) -> float:
    """``b − (K T / 2 + |B|)``: positive when passive."""
    return b - (K * T / 2.0 + abs(B))


def compensable_damping(b: ArrayLike, kp: ArrayLike, T: float, safety: float) -> FloatArray:
    """How much of the handle's own damping ``b`` a hand may cancel: what exceeds ``safety · kp T``.

    A hand that holds the handle on the part with a PD of stiffness ``kp`` (sampled at ``T``) and
    cancels the handle's damping ``b`` with the part's speed makes the part and the handle, moving
    together, an active pair: their common motion grows at a rate about ``α b / (inertia)`` once
    the damping left, ``(1 − α) b``, falls below ``kp T`` (the sampled loop's eigenvalues, for
    every part and coordinate: e.g. a slender shaft's spin about its own axis doubled every 50 ms
    with ``α = 1``). Keeping ``safety · kp T`` of it keeps the pair passive.
    """
    b_arr, kp_arr = np.asarray(b, dtype=float), np.asarray(kp, dtype=float)
    return np.maximum(b_arr - safety * kp_arr * T, 0.0)


def check_passivity(K: float, B: float, T: float, b: float) -> float:
    """Return the margin, or raise :class:`InputError` when ``b > K T/2 + |B|`` fails."""
    for name, value in (("stiffness K", K), ("sample time T", T), ("device damping b", b)):
        if not (value > 0 and np.isfinite(value)):
            raise InputError(f"coupling {name} must be positive and finite, got {value}")
    margin = passivity_margin(K, B, T, b)
    if margin <= 0.0:
        K_max = 2.0 * (b - abs(B)) / T
        raise InputError(
            f"coupling gains are not passive: need b > K·T/2 + |B|, got {b:g} ≤ {K * T / 2 + abs(B):g} "
            f"(K = {K:g} N/m, B = {B:g} N·s/m, T = {T:g} s); with this B, K must stay below {max(K_max, 0):g} N/m"
        )
    return margin


@dataclass(frozen=True)
class VirtualCoupling:
    """Stiffness and damping per coordinate (translational, rotational) and the sample period."""

    K_lin: float  # [N/m]
    B_lin: float  # [N·s/m]
    K_rot: float  # [N·m/rad]
    B_rot: float  # [N·m·s/rad]
    period_s: float
    device_damping: float  # b [N·s/m] of the handle, translational
    device_damping_rot: float  # rotational

    def __post_init__(self) -> None:
        check_passivity(self.K_lin, self.B_lin, self.period_s, self.device_damping)
        check_passivity(self.K_rot, self.B_rot, self.period_s, self.device_damping_rot)

    @property
    def margins(self) -> tuple[float, float]:
        return (
            passivity_margin(self.K_lin, self.B_lin, self.period_s, self.device_damping),
            passivity_margin(self.K_rot, self.B_rot, self.period_s, self.device_damping_rot),
        )

    def wrench(self, dx: ArrayLike, dv: ArrayLike, d: int) -> FloatArray:
        """Coupling wrench on the workpiece for a device-minus-workpiece offset ``dx`` and rate ``dv``."""
        dx = np.asarray(dx, dtype=float)
        dv = np.asarray(dv, dtype=float)
        k = np.concatenate([np.full(d, self.K_lin), np.full(dx.shape[0] - d, self.K_rot)])
        b = np.concatenate([np.full(d, self.B_lin), np.full(dx.shape[0] - d, self.B_rot)])
        return k * dx + b * dv
