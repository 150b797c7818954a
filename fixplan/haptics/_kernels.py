"""Compiled per-tick arithmetic of the haptic loop (numba, cached)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def log_so3(R):
    """Rotation vector of R (same branch handling as :func:`fixplan.pose.log_so3`)."""
    c = min(1.0, max(-1.0, (R[0, 0] + R[1, 1] + R[2, 2] - 1.0) / 2.0))
    th = math.acos(c)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if th < 1e-8:
        return 0.5 * v
    if math.pi - th < 1e-6:
        B = (R + np.eye(3)) / 2.0
        k = 0
        for i in range(1, 3):
            if B[i, i] > B[k, k]:
                k = i
        axis = B[:, k] / math.sqrt(max(B[k, k], 1e-300))
        axis /= math.sqrt(np.sum(axis * axis))
        if np.sum(axis * v) < 0:
            axis = -axis
        return th * axis
    return th / (2.0 * math.sin(th)) * v


@njit(cache=True)
def coupling3(R, p, com_b, v, w, R0, x_d, v_d, K, B):
    """Coupling wrench on the workpiece (about its body origin) from device and workpiece coordinates."""
    c = p + R @ com_b
    Rrel = R @ R0.T
    rot = log_so3(Rrel)
    o = p - c
    v_o = np.array(
        [v[0] + w[1] * o[2] - w[2] * o[1], v[1] + w[2] * o[0] - w[0] * o[2], v[2] + w[0] * o[1] - w[1] * o[0]]
    )
    out = np.empty(6)
    for i in range(3):
        out[i] = K[i] * (x_d[i] - p[i]) + B[i] * (v_d[i] - v_o[i])
        out[3 + i] = K[3 + i] * (x_d[3 + i] - rot[i]) + B[3 + i] * (v_d[3 + i] - w[i])
    return out
