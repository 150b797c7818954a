"""The compiled twin of :mod:`fixplan.spatial`, for numba kernels (engine, haptics, interactive).

The same formulas as the numpy versions, written on scalars or into caller-owned buffers so that
hot loops allocate nothing; ``tests/test_spatial.py`` pins each one to its numpy original on
seeded random inputs. The conventions (lever ``r = b − a`` from the old point ``a`` to the new
point ``b``, world axes) are in :mod:`fixplan.spatial`'s docstring:

- wrench: ``m_b = m_a + f × r`` (2D ``m_b = m_a − f_y r_x + f_x r_y``);
- twist: ``v_b = v_a + ω × r`` (2D ``v_b = v_a + ω (−r_y, r_x)``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def shifted_moment3(f0, f1, f2, m0, m1, m2, r0, r1, r2):
    """The moment about ``b = a + r`` of a wrench ``(f, m_a)``: ``m_a + f × r`` (:func:`fixplan.spatial.shift_wrench_by`)."""
    return m0 + (f1 * r2 - f2 * r1), m1 + (f2 * r0 - f0 * r2), m2 + (f0 * r1 - f1 * r0)


@njit(cache=True, inline="always")
def shifted_moment2(f0, f1, m, r0, r1):
    """The planar moment about ``b = a + r``: ``m_a − f_y r_x + f_x r_y``."""
    return m - f1 * r0 + f0 * r1


@njit(cache=True, inline="always")
def shifted_velocity3(v0, v1, v2, w0, w1, w2, r0, r1, r2):
    """The velocity of ``b = a + r`` from the twist ``(v_a, ω)``: ``v_a + ω × r`` (:func:`fixplan.spatial.shift_twist_by`)."""
    return v0 + (w1 * r2 - w2 * r1), v1 + (w2 * r0 - w0 * r2), v2 + (w0 * r1 - w1 * r0)


@njit(cache=True, inline="always")
def shifted_velocity2(v0, v1, w, r0, r1):
    """The planar velocity of ``b = a + r``: ``v_a + ω (−r_y, r_x)``."""
    return v0 - w * r1, v1 + w * r0


@njit(cache=True, inline="always")
def tangents3(n0, n1, n2):
    """``(t1, t2)`` of a unit 3D normal as six scalars (:func:`fixplan.spatial.tangent_basis`)."""
    if abs(n0) < 0.9:
        e0, e1, e2 = 1.0, 0.0, 0.0
    else:
        e0, e1, e2 = 0.0, 1.0, 0.0
    dot = e0 * n0 + e1 * n1 + e2 * n2
    s0, s1, s2 = e0 - dot * n0, e1 - dot * n1, e2 - dot * n2
    nrm = math.sqrt(s0**2 + s1**2 + s2**2)
    s0, s1, s2 = s0 / nrm, s1 / nrm, s2 / nrm
    return s0, s1, s2, n1 * s2 - n2 * s1, n2 * s0 - n0 * s2, n0 * s1 - n1 * s0


@njit(cache=True)
def exp_so3_into(x, y, z, R):
    """``R = exp([x, y, z]^)`` by Rodrigues' formula, entry by entry (:func:`fixplan.spatial.exp_so3`)."""
    th2 = x * x + y * y + z * z
    th = math.sqrt(th2)
    if th < 1e-8:
        a, b = 1.0, 0.5
    else:
        a, b = math.sin(th) / th, (1.0 - math.cos(th)) / th2
    R[0, 0] = 1.0 - b * (y * y + z * z)
    R[1, 1] = 1.0 - b * (x * x + z * z)
    R[2, 2] = 1.0 - b * (x * x + y * y)
    R[0, 1] = -a * z + b * x * y
    R[1, 0] = a * z + b * x * y
    R[0, 2] = a * y + b * x * z
    R[2, 0] = -a * y + b * x * z
    R[1, 2] = -a * x + b * y * z
    R[2, 1] = a * x + b * y * z


@njit(cache=True)
def quat_into(R, out):
    """Unit quaternion ``(w, x, y, z)``, ``w ≥ 0`` (as :func:`fixplan.spatial.quaternion_wxyz_from_matrix`)."""
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        out[0] = 0.25 * s
        out[1] = (R[2, 1] - R[1, 2]) / s
        out[2] = (R[0, 2] - R[2, 0]) / s
        out[3] = (R[1, 0] - R[0, 1]) / s
    else:
        i = 0
        if R[1, 1] > R[i, i]:
            i = 1
        if R[2, 2] > R[i, i]:
            i = 2
        j, m = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(1.0 + R[i, i] - R[j, j] - R[m, m])
        out[0] = (R[m, j] - R[j, m]) / s
        out[1 + i] = 0.25 * s
        out[1 + j] = (R[j, i] + R[i, j]) / s
        out[1 + m] = (R[m, i] + R[i, m]) / s
    nq = math.sqrt(out[0] ** 2 + out[1] ** 2 + out[2] ** 2 + out[3] ** 2)
    sgn = 1.0 if out[0] / nq >= 0 else -1.0
    for a in range(4):
        out[a] = sgn * out[a] / nq


@njit(cache=True)
def rotate3(R, x):
    """``R @ x`` for a 3×3 ``R`` written out (numba's ``@`` calls BLAS, which imports SciPy)."""
    out = np.empty(3)
    for i in range(3):
        out[i] = R[i, 0] * x[0] + R[i, 1] * x[1] + R[i, 2] * x[2]
    return out


@njit(cache=True)
def relative_rotation3(R, R0):
    """``R @ R0.T`` for 3×3 rotations, written out (see :func:`rotate3`)."""
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            out[i, j] = R[i, 0] * R0[j, 0] + R[i, 1] * R0[j, 1] + R[i, 2] * R0[j, 2]
    return out


@njit(cache=True)
def log_so3(R):
    """Rotation vector of R (the branches of :func:`fixplan.spatial.log_so3`)."""
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
