"""Compiled per-tick arithmetic of the haptic loop (numba, cached): the coupling, and the device coordinates."""

from __future__ import annotations

import numpy as np
from numba import njit

from fixplan._spatial_kernels import log_so3, relative_rotation3, rotate3, shifted_velocity3


@njit(cache=True)
def coupling3(R, p, com_b, v, w, R0, x_d, v_d, K, B):
    """Coupling wrench on the workpiece (about its body origin) from device and workpiece coordinates.

    ``v`` is the velocity of the centre of mass ``c = p + R com_b``; the device couples to the
    body origin ``p``, whose velocity is ``v + ω × (p − c)``.
    """
    c_world = p + rotate3(R, com_b)
    rot = log_so3(relative_rotation3(R, R0))
    r = p - c_world  # lever from the centre of mass to the body origin
    v_origin = np.array(shifted_velocity3(v[0], v[1], v[2], w[0], w[1], w[2], r[0], r[1], r[2]))
    out = np.empty(6)
    for i in range(3):
        out[i] = K[i] * (x_d[i] - p[i]) + B[i] * (v_d[i] - v_origin[i])
        out[3 + i] = K[3 + i] * (x_d[3 + i] - rot[i]) + B[3 + i] * (v_d[3 + i] - w[i])
    return out


@njit(cache=True)
def coordinates3(R, p, com_world, twist, R0):
    """Device coordinates of the part (body origin, rotation vector of R R0ᵀ) and their rates.

    The compiled twin of :func:`fixplan.haptics.coordinates.workpiece_coordinates` in 3D.
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
