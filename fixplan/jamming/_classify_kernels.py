"""Compiled kernels of :mod:`fixplan.jamming.classify` (numba, cached).

``nnls`` is :func:`fixplan.nnls.nnls` (Lawson–Hanson, the same control flow and tolerances)
with the least-squares subproblem solved by a QR factorization of the passive columns
(Gram–Schmidt, orthogonalized twice) instead of ``np.linalg.lstsq`` (an SVD per inner step):
the classifier's first test, "normal forces alone balance the wrench", took about 250 µs per
wrench in NumPy, more than the static-balance SOCP after it; compiled it takes a few µs.
Lawson–Hanson keeps the passive columns linearly independent, so a plain QR suffices; a pivot
below 1e-12 of its column's norm (rounding made them dependent) returns ``ok = False`` and the
caller uses the NumPy version.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _lstsq_passive(A, b, passive, z, Q, Rm, cols):
    """``z`` = argmin ‖A_P z_P − b‖ on the passive columns (0 elsewhere); False if rank-deficient."""
    m, n = A.shape
    k = 0
    for j in range(n):
        z[j] = 0.0
        if passive[j]:
            cols[k] = j
            k += 1
    for c in range(k):
        col = cols[c]
        norm0 = 0.0
        for i in range(m):
            Q[i, c] = A[i, col]
            norm0 += A[i, col] * A[i, col]
        for a in range(c + 1):
            Rm[a, c] = 0.0
        for _ in range(2):
            for a in range(c):
                r = 0.0
                for i in range(m):
                    r += Q[i, a] * Q[i, c]
                Rm[a, c] += r
                for i in range(m):
                    Q[i, c] -= r * Q[i, a]
        nv = 0.0
        for i in range(m):
            nv += Q[i, c] * Q[i, c]
        nv = math.sqrt(nv)
        if not (nv > 1e-12 * math.sqrt(norm0)):
            return False
        Rm[c, c] = nv
        for i in range(m):
            Q[i, c] /= nv
    for c in range(k - 1, -1, -1):
        y = 0.0
        for i in range(m):
            y += Q[i, c] * b[i]
        for a in range(c + 1, k):
            y -= Rm[c, a] * z[cols[a]]
        z[cols[c]] = y / Rm[c, c]
    return True


@njit(cache=True)
def nnls(A, b, maxiter, tol):
    """``(x, ‖A x − b‖, ok)``: :func:`fixplan.nnls.nnls` compiled; ``ok = False``: use that one."""
    m, n = A.shape
    x = np.zeros(n)
    z = np.zeros(n)
    w = np.zeros(n)
    r = np.zeros(m)
    passive = np.zeros(n, dtype=np.bool_)
    Q = np.zeros((m, max(n, 1)))
    Rm = np.zeros((max(n, 1), max(n, 1)))
    cols = np.zeros(max(n, 1), dtype=np.int64)
    for _ in range(maxiter):
        for i in range(m):
            s = b[i]
            for j in range(n):
                s -= A[i, j] * x[j]
            r[i] = s
        best = -np.inf
        jbest = -1
        for j in range(n):
            s = 0.0
            for i in range(m):
                s += A[i, j] * r[i]
            w[j] = s
            if not passive[j] and s > best:
                best = s
                jbest = j
        if jbest < 0 or best <= tol:
            break
        passive[jbest] = True
        while True:
            if not _lstsq_passive(A, b, passive, z, Q, Rm, cols):
                return x, 0.0, False
            all_pos = True
            for j in range(n):
                if passive[j] and not (z[j] > 0.0):
                    all_pos = False
            if all_pos:
                for j in range(n):
                    x[j] = z[j]
                break
            alpha = np.inf
            for j in range(n):
                if passive[j] and z[j] <= 0.0:
                    alpha = min(alpha, x[j] / (x[j] - z[j]))
            any_passive = False
            for j in range(n):
                x[j] = x[j] + alpha * (z[j] - x[j])
                passive[j] = passive[j] and x[j] > tol
                if not passive[j]:
                    x[j] = 0.0
                any_passive = any_passive or passive[j]
            if not any_passive:
                break
    res = 0.0
    for i in range(m):
        s = -b[i]
        for j in range(n):
            s += A[i, j] * x[j]
        res += s * s
    return x, math.sqrt(res), True
