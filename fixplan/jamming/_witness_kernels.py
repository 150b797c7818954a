"""Compiled kernels for :mod:`fixplan.jamming.sliding` (numba, cached on disk).

Data layout shared with the Python side:

- ``J`` (m × ndof): stacked contact rows, contact ``i`` at rows ``off[i] : off[i] + size[i]``
  (normal, tangents, [spin]);
- ``D`` (k × 3): scale of the tangent rows in the cone's standard form (1, 1, e_r);
- ``role`` (k,): the codes of :mod:`._roles`, ``ROLE_SLIDING`` (kept, friction at its limit),
  ``ROLE_STICKING`` (no relative acceleration), ``ROLE_OPENING`` (no force, no equation; its
  opening is checked afterwards);
- unknowns ``z = (a, per contact: f_n,i if sliding, λ_i if sticking, nothing if open)``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from fixplan.jamming._roles import ROLE_OPENING, ROLE_STICKING


@njit(cache=True)
def system(M, J, off, size, mu, D, w, z, role):
    """Residual F, Jacobian and the stacked contact forces λ for the role pattern ``role``."""
    ndof = M.shape[0]
    k = off.shape[0]
    nz = z.shape[0]
    F = np.zeros(nz)
    Jac = np.zeros((nz, nz))
    lam = np.zeros(J.shape[0])
    a = z[:ndof]
    for r in range(ndof):
        acc = 0.0
        for c in range(ndof):
            acc += M[r, c] * a[c]
            Jac[r, c] = M[r, c]
        F[r] = acc - w[r]
    col = ndof
    row = ndof
    for i in range(k):
        o = off[i]
        sz = size[i]
        if role[i] == ROLE_OPENING:
            continue
        if role[i] == ROLE_STICKING:
            for q in range(sz):
                li = z[col + q]
                lam[o + q] = li
                for r in range(ndof):
                    F[r] -= J[o + q, r] * li
                    Jac[r, col + q] = -J[o + q, r]
                acc = 0.0
                for c in range(ndof):
                    acc += J[o + q, c] * a[c]
                    Jac[row + q, c] = J[o + q, c]
                F[row + q] = acc
            col += sz
            row += sz
            continue
        fn = z[col]
        lam[o] = fn
        g = np.zeros(ndof)
        for r in range(ndof):
            g[r] = J[o, r]
        nt = sz - 1
        if mu[i] > 0.0 and nt > 0:
            s = np.zeros(nt)
            for q in range(nt):
                acc = 0.0
                for c in range(ndof):
                    acc += J[o + 1 + q, c] * a[c]
                s[q] = D[i, q] * acc
            ns = np.sqrt(np.sum(s * s))
            if ns > 0.0:
                d = s / ns
                for q in range(nt):
                    lam[o + 1 + q] = -mu[i] * fn * D[i, q] * d[q]
                    for r in range(ndof):
                        g[r] -= mu[i] * J[o + 1 + q, r] * D[i, q] * d[q]
                # ∂/∂a of μ fn Σ_q J_tq D_q d_q = μ fn (DT)ᵀ (I − d dᵀ)/‖s‖ (DT)
                for p in range(nt):
                    for q in range(nt):
                        P = ((1.0 if p == q else 0.0) - d[p] * d[q]) / ns
                        if P == 0.0:
                            continue
                        coef = mu[i] * fn * P * D[i, p] * D[i, q]
                        for r in range(ndof):
                            jr = J[o + 1 + p, r] * coef
                            for c in range(ndof):
                                Jac[r, c] += jr * J[o + 1 + q, c]
        for r in range(ndof):
            F[r] -= fn * g[r]
            Jac[r, col] = -g[r]
        acc = 0.0
        for c in range(ndof):
            acc += J[o, c] * a[c]
            Jac[row, c] = J[o, c]
        F[row] = acc
        col += 1
        row += 1
    return F, Jac, lam


@njit(cache=True)
def _solve(A, b):
    """LU solve, falling back to least squares for a singular matrix."""
    try:
        x = np.linalg.solve(A, b)
        if np.all(np.isfinite(x)):
            return x
    except Exception:  # noqa: BLE001 - numba raises a plain exception on singular A
        pass
    return np.linalg.lstsq(A, b)[0]


@njit(cache=True)
def newton(M, J, off, size, mu, D, w, z0, role, iterations):
    """Damped Newton on :func:`system`; returns the last iterate."""
    z = z0.copy()
    F, Jac, lam = system(M, J, off, size, mu, D, w, z, role)
    scale = max(np.sqrt(np.sum(w * w)), 1e-300)
    for _ in range(iterations):
        nF = np.sqrt(np.sum(F * F))
        if nF <= 1e-14 * scale:
            break
        step = _solve(Jac, -F)
        alpha = 1.0
        improved = False
        while alpha > 1e-4:
            trial = z + alpha * step
            Ft, Jt, lt = system(M, J, off, size, mu, D, w, trial, role)
            if np.sqrt(np.sum(Ft * Ft)) < nF:
                z = trial
                F = Ft
                Jac = Jt
                improved = True
                break
            alpha *= 0.5
        if not improved:
            break
    return z


@njit(cache=True)
def fixed_point(M, J, off, size, mu, D, w, z0, sweeps):
    """All-slide start: freeze slip directions at the current a, solve the linear system, repeat."""
    ndof = M.shape[0]
    k = off.shape[0]
    z = z0.copy()
    for _ in range(sweeps):
        K = np.zeros((ndof + k, ndof + k))
        rhs = np.zeros(ndof + k)
        for r in range(ndof):
            rhs[r] = w[r]
            for c in range(ndof):
                K[r, c] = M[r, c]
        for i in range(k):
            o = off[i]
            g = J[o, :].copy()
            nt = size[i] - 1
            if mu[i] > 0.0 and nt > 0:
                s = np.zeros(nt)
                for q in range(nt):
                    s[q] = D[i, q] * np.dot(J[o + 1 + q, :], z[:ndof])
                ns = np.sqrt(np.sum(s * s))
                if ns > 0.0:
                    for q in range(nt):
                        g -= mu[i] * J[o + 1 + q, :] * D[i, q] * s[q] / ns
            for r in range(ndof):
                K[r, ndof + i] = -g[r]
                K[ndof + i, r] = J[o, r]
        z = _solve(K, rhs)
    return z
