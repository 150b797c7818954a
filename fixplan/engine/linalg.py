"""Small dense linear algebra for the compiled time step, without BLAS and without allocation.

numba's ``@`` on small arrays calls BLAS (microseconds per call); the time step of
:mod:`fixplan.engine.step` multiplies 2×2 … 6×6 blocks thousands of times per second, so these
loops do it by hand. The ``*_into`` forms write into caller-owned buffers (the 3D step allocates
nothing per step); the others return a new array (the planar step).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def mv(A, x):
    """``A @ x`` for small dense matrices without a BLAS call (numba's ``@`` calls BLAS)."""
    n, m = A.shape
    out = np.zeros(n)
    for i in range(n):
        acc = 0.0
        for j in range(m):
            acc += A[i, j] * x[j]
        out[i] = acc
    return out


@njit(cache=True, inline="always")
def mtv(A, x):
    """``A.T @ x`` without BLAS."""
    n, m = A.shape
    out = np.zeros(m)
    for i in range(n):
        xi = x[i]
        for j in range(m):
            out[j] += A[i, j] * xi
    return out


@njit(cache=True, inline="always")
def mm(A, B):
    """``A @ B`` without BLAS."""
    n, k = A.shape
    m = B.shape[1]
    out = np.zeros((n, m))
    for i in range(n):
        for p in range(k):
            a = A[i, p]
            if a != 0.0:
                for j in range(m):
                    out[i, j] += a * B[p, j]
    return out


@njit(cache=True)
def mv3_into(A, x, out):
    """``out = A @ x`` (3×3; ``out`` distinct from ``x``); same sums as :func:`mv`."""
    for i in range(3):
        acc = 0.0
        for j in range(3):
            acc += A[i, j] * x[j]
        out[i] = acc


@njit(cache=True)
def mtv3_into(A, x, out):
    """``out = A.T @ x`` (3×3; ``out`` distinct from ``x``); same sums as :func:`mtv`."""
    for j in range(3):
        out[j] = 0.0
    for i in range(3):
        xi = x[i]
        for j in range(3):
            out[j] += A[i, j] * xi


@njit(cache=True)
def mm3_into(A, B, out):
    """``out = A @ B`` (3×3; ``out`` distinct from both); same sums as :func:`mm`."""
    for i in range(3):
        for j in range(3):
            out[i, j] = 0.0
        for p in range(3):
            a = A[i, p]
            if a != 0.0:
                for j in range(3):
                    out[i, j] += a * B[p, j]


@njit(cache=True)
def invert_small(A, out):
    """Inverse of a small block (cofactors for 3×3, Gauss–Jordan otherwise); False when (nearly) singular."""
    d = A.shape[0]
    if d == 3:
        c00 = A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]
        c01 = A[1, 2] * A[2, 0] - A[1, 0] * A[2, 2]
        c02 = A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]
        det = A[0, 0] * c00 + A[0, 1] * c01 + A[0, 2] * c02
        scale = 0.0
        for i in range(3):
            for j in range(3):
                scale = max(scale, abs(A[i, j]))
        if not (abs(det) > 1e-10 * scale * scale * scale):
            return False
        inv_det = 1.0 / det
        out[0, 0] = c00 * inv_det
        out[1, 0] = c01 * inv_det
        out[2, 0] = c02 * inv_det
        out[0, 1] = (A[0, 2] * A[2, 1] - A[0, 1] * A[2, 2]) * inv_det
        out[1, 1] = (A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]) * inv_det
        out[2, 1] = (A[0, 1] * A[2, 0] - A[0, 0] * A[2, 1]) * inv_det
        out[0, 2] = (A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]) * inv_det
        out[1, 2] = (A[0, 2] * A[1, 0] - A[0, 0] * A[1, 2]) * inv_det
        out[2, 2] = (A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]) * inv_det
        return True
    M = np.zeros((d, 2 * d))
    scale = 0.0
    for i in range(d):
        for j in range(d):
            M[i, j] = A[i, j]
            scale = max(scale, abs(A[i, j]))
        M[i, d + i] = 1.0
    if scale == 0.0:
        return False
    for c in range(d):
        piv = c
        for r in range(c + 1, d):
            if abs(M[r, c]) > abs(M[piv, c]):
                piv = r
        if abs(M[piv, c]) <= 1e-10 * scale:
            return False
        if piv != c:
            for j in range(2 * d):
                M[c, j], M[piv, j] = M[piv, j], M[c, j]
        f = 1.0 / M[c, c]
        for j in range(2 * d):
            M[c, j] *= f
        for r in range(d):
            if r != c and M[r, c] != 0.0:
                g = M[r, c]
                for j in range(2 * d):
                    M[r, j] -= g * M[c, j]
    for i in range(d):
        for j in range(d):
            out[i, j] = M[i, d + j]
    return True
