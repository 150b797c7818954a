"""Compiled per-tick arithmetic of the interactive loop (numba, cached)."""

from __future__ import annotations

import numpy as np
from numba import njit

from fixplan.haptics._kernels import log_so3


@njit(cache=True)
def coordinates3(R, p, com_world, twist, R0):
    """Device coordinates of the part (body origin, rotation vector of R R0ᵀ) and their rates.

    ``twist`` is ``(v, ω)`` of the centre of mass; the origin's velocity is ``v + ω × (p − c)``.
    """
    rot = log_so3(R @ R0.T)
    o = p - com_world
    w = twist[3:]
    x = np.empty(6)
    v = np.empty(6)
    x[:3] = p
    x[3:] = rot
    v[0] = twist[0] + w[1] * o[2] - w[2] * o[1]
    v[1] = twist[1] + w[2] * o[0] - w[0] * o[2]
    v[2] = twist[2] + w[0] * o[1] - w[1] * o[0]
    v[3:] = w
    return x, v
