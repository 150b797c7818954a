"""Compiled per-tick arithmetic of the interactive loop (numba, cached)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def coordinates3(R, p, com_world, twist, R0):
    """Device coordinates of the part (body origin, rotation vector of R R0ᵀ) and their rates.

    ``twist`` is ``(v, ω)`` of the centre of mass; the origin's velocity is ``v + ω × (p − c)``.
    """
    Rr = R @ R0.T
    c = min(1.0, max(-1.0, (Rr[0, 0] + Rr[1, 1] + Rr[2, 2] - 1.0) / 2.0))
    th = math.acos(c)
    a = np.array([Rr[2, 1] - Rr[1, 2], Rr[0, 2] - Rr[2, 0], Rr[1, 0] - Rr[0, 1]])
    if th < 1e-8:
        rot = 0.5 * a
    elif math.pi - th < 1e-6:
        B = (Rr + np.eye(3)) / 2.0
        k = 0
        for i in range(1, 3):
            if B[i, i] > B[k, k]:
                k = i
        axis = B[:, k] / math.sqrt(max(B[k, k], 1e-300))
        axis /= math.sqrt(np.sum(axis * axis))
        if np.sum(axis * a) < 0:
            axis = -axis
        rot = th * axis
    else:
        rot = th / (2.0 * math.sin(th)) * a
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
