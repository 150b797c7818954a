"""Compiled per-tick arithmetic of the interactive loop (numba, cached)."""

from __future__ import annotations

import numpy as np
from numba import njit

from fixplan._spatial_kernels import log_so3, relative_rotation3, shifted_velocity3


@njit(cache=True)
def coordinates3(R, p, com_world, twist, R0):
    """Device coordinates of the part (body origin, rotation vector of R R0ᵀ) and their rates.

    ``twist`` is ``(v, ω)`` of the centre of mass; the origin's velocity is ``v + ω × (p − c)``.
    """
    rot = log_so3(relative_rotation3(R, R0))
    r = p - com_world  # lever from the centre of mass to the body origin
    x = np.empty(6)
    v = np.empty(6)
    x[:3] = p
    x[3:] = rot
    v[0], v[1], v[2] = shifted_velocity3(twist[0], twist[1], twist[2], twist[3], twist[4], twist[5], r[0], r[1], r[2])
    v[3:] = twist[3:]
    return x, v
