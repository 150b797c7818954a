"""Nonsmooth Newton polish of a time step's contact problem where Gauss–Seidel stalls.

Why. NSGS converges linearly, and on some problems barely at all: two contacts sliding at once
on the boundary of their cones in a corner (a plate pushed into its base and side locators,
μ ≈ 0.77, ``W`` of rank 3 for 4 rows) crept from a residual of 1.4e-3 after 1000 sweeps to
1.4e-3 after 5000, and the unconverged impulses let the part sink into both contacts, which made
the next steps harder (residual 0.12 fifty steps on). The nonsmooth Newton iteration of
:mod:`fixplan.engine.newton` solves the same problem from the same start in three steps to 6e-13.

What. :func:`newton_polish` is that iteration on the step's dense ``W`` (a few contacts: ``m ≤``
4 × locators rows), compiled, with a dense LU of its own (partial pivoting; no LAPACK, so the
ahead-of-time extension of :mod:`fixplan.aot` builds it too):

- natural map ``Φ_j(r) = r_j − Proj_{K_μj}(r_j − ρ_j (u_j + μ_j ‖u_t,j‖ e_n))`` with
  ``ρ_j = 1 / W_nn,j``, zero exactly at the solutions (:mod:`fixplan.engine.newton`'s docstring);
- generalized Jacobian ``blockdiag(I − P'_j) + blockdiag(ρ_j P'_j B_j) W`` from
  :func:`jacobian_blocks`, regularized as ``J + λ I`` (Levenberg: ``λ`` ÷10 after a full step,
  ×10 after a failed line search; rank-deficient ``W`` makes ``J`` singular where contacts stick);
- Armijo backtracking on ``½‖Φ‖²``;
- where Newton stalls (on a plate in the same corner it stopped at 8e-3), proximal point rounds
  on ``W + σD`` as :func:`fixplan.engine.newton.run_prox` (6 rounds to 5e-10 there);
- the iterate kept is the one with the lowest FCLib residual (:func:`fclib_error_rows`, the
  residual NSGS stops on), so a polish never makes a step worse.

The time step calls it only when NSGS reached its sweep cap; ``tests/engine/test_polish.py``
checks it against the sparse solver and finite differences.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fixplan.engine.local import project_cone_into
from fixplan.engine.residual import fclib_error_rows

ARMIJO = 1e-4
"""Armijo constant ``σ`` of the line search."""
MIN_STEP = 2.0**-12
"""Shortest line-search step."""
LAMBDA_START = 1e-10
"""Initial regularization of ``J + λ I`` (the map has unit scale per contact)."""
LAMBDA_MAX = 1e4
"""Above this the iteration is stalled."""


@njit(cache=True, error_model="numpy")
def jacobian_blocks(mu, offsets, dims, rho, r, u, A, C):
    """Blocks ``A_j = I − P'_j`` and ``C_j = ρ_j P'_j B_j`` (padded ``(n_c, 4, 4)``) at ``r``.

    One block per entry of ``offsets``; ``P'_j`` is the derivative of the cone projection at
    ``x_j = r_j − ρ_j (u_j + μ_j‖u_t,j‖ e_n)`` (``I`` inside the cone, ``0`` in its polar, the
    closed form of :mod:`fixplan.engine.newton`'s docstring on the boundary region) and
    ``B_j = I + μ_j e_n ĝ_jᵀ`` with ``ĝ_j = (0, u_t,j / ‖u_t,j‖)``.
    """
    x = np.empty(4)
    g = np.zeros(4)
    P = np.zeros((4, 4))
    for j in range(offsets.shape[0]):
        o = offsets[j]
        d = dims[j]
        m = mu[j]
        ut = 0.0
        for a in range(1, d):
            ut += u[o + a] * u[o + a]
        ut = math.sqrt(ut)
        for a in range(d):
            x[a] = r[o + a] - rho[j] * u[o + a]
            g[a] = u[o + a] / ut if (a > 0 and ut > 0.0) else 0.0
        x[0] -= rho[j] * m * ut
        xn = x[0]
        t = 0.0
        for a in range(1, d):
            t += x[a] * x[a]
        t = math.sqrt(t)
        for a in range(d):
            for b in range(d):
                P[a, b] = 0.0
        if m * t <= -xn:
            pass  # polar cone: P' = 0
        elif t <= m * xn and m > 0.0:
            for a in range(d):
                P[a, a] = 1.0  # inside the cone: P' = I
        else:
            s = 1.0 / (1.0 + m * m)
            pn = (xn + m * t) * s
            P[0, 0] = s
            for a in range(1, d):
                e_a = x[a] / t if t > 0.0 else 0.0
                P[0, a] = m * e_a * s
                P[a, 0] = m * e_a * s
                for b in range(1, d):
                    e_b = x[b] / t if t > 0.0 else 0.0
                    ident = 1.0 if a == b else 0.0
                    P[a, b] = m * m * e_a * e_b * s
                    if t > 0.0:
                        P[a, b] += (m * pn / t) * (ident - e_a * e_b)
        for a in range(d):
            for b in range(d):
                A[j, a, b] = (1.0 if a == b else 0.0) - P[a, b]
                # (P B)_ab = P_ab + P_a0 μ g_b   (B = I + μ e_n gᵀ)
                C[j, a, b] = rho[j] * (P[a, b] + P[a, 0] * m * g[b])
    return 0


@njit(cache=True, error_model="numpy")
def natural_map_rows(mu, offsets, dims, rho, r, u, phi, x, p):
    """``Φ_ρ(r)`` into ``phi`` from ``u = W r + q`` already computed (one contact per entry of ``offsets``).

    ``x`` and ``p`` are scratch vectors of length 4. Returns ``‖Φ_ρ(r)‖₂``. Shared by the sparse
    iteration of :mod:`fixplan.engine.newton` and the dense polish here.
    """
    total = 0.0
    for j in range(offsets.shape[0]):
        o, d = offsets[j], dims[j]
        ut = 0.0
        for a in range(1, d):
            ut += u[o + a] * u[o + a]
        ut = math.sqrt(ut)
        for a in range(d):
            x[a] = r[o + a] - rho[j] * u[o + a]
        x[0] -= rho[j] * mu[j] * ut
        project_cone_into(x[:d], mu[j], p[:d])
        for a in range(d):
            v = r[o + a] - p[a]
            phi[o + a] = v
            total += v * v
    return math.sqrt(total)


@njit(cache=True)
def _dense_u(W, q, r, m, u):
    """``u = W r + q`` on the leading ``m`` rows."""
    for a in range(m):
        acc = q[a]
        for b in range(m):
            acc += W[a, b] * r[b]
        u[a] = acc


@njit(cache=True)
def _natural_map_dense(W, q, mu, offsets, sizes, nc, m, rho, r, u, phi, x, p):
    """``u = W r + q`` and ``Φ_ρ(r)`` into ``u``, ``phi`` (leading ``m`` rows); returns ``‖Φ‖₂``."""
    _dense_u(W, q, r, m, u)
    return natural_map_rows(mu[:nc], offsets[:nc], sizes[:nc], rho, r, u, phi, x, p)


@njit(cache=True)
def _lu_solve(M, b, n):
    """Solve ``M[:n, :n] z = b[:n]`` in place (``M`` overwritten, ``z`` into ``b``); False if singular."""
    for col in range(n):
        piv = col
        big = abs(M[col, col])
        for row in range(col + 1, n):
            if abs(M[row, col]) > big:
                big = abs(M[row, col])
                piv = row
        if not (big > 0.0) or not math.isfinite(big):
            return False
        if piv != col:
            for c in range(n):
                tmp = M[col, c]
                M[col, c] = M[piv, c]
                M[piv, c] = tmp
            tmp = b[col]
            b[col] = b[piv]
            b[piv] = tmp
        inv = 1.0 / M[col, col]
        for row in range(col + 1, n):
            f = M[row, col] * inv
            if f != 0.0:
                for c in range(col + 1, n):
                    M[row, c] -= f * M[col, c]
                b[row] -= f * b[col]
    for row in range(n - 1, -1, -1):
        acc = b[row]
        for c in range(row + 1, n):
            acc -= M[row, c] * b[c]
        b[row] = acc / M[row, row]
    return True


@njit(cache=True)
def _residual(W, q, mu, offsets, sizes, nc, m, r, u, x, pr):
    """FCLib residual of ``r`` on ``u = W r + q`` (``u`` written)."""
    _dense_u(W, q, r, m, u)
    return fclib_error_rows(q, mu, offsets, sizes, nc, m, r, u, x, pr)


@njit(cache=True)
def _newton(W, q, mu, offsets, sizes, nc, m, r, tol, max_steps):
    """Newton steps on ``u = W r + q`` from ``r``; ``r`` becomes the best iterate. Returns ``(error, steps)``."""
    x = np.empty(4)
    pr = np.empty(4)
    rho = np.empty(nc)
    wsum, wcount = 0.0, 0
    for j in range(nc):
        if W[offsets[j], offsets[j]] > 0.0:
            wsum += W[offsets[j], offsets[j]]
            wcount += 1
    fallback = wsum / wcount if wcount > 0 else 1.0
    for j in range(nc):
        wnn = W[offsets[j], offsets[j]]
        rho[j] = 1.0 / (wnn if wnn > 0.0 else fallback)
    cur = r[:m].copy()
    u = np.empty(m)
    phi = np.empty(m)
    trial = np.empty(m)
    trial_u = np.empty(m)
    trial_phi = np.empty(m)
    d = np.empty(m)
    Jm = np.empty((m, m))
    A = np.zeros((nc, 4, 4))
    C = np.zeros((nc, 4, 4))
    norm = _natural_map_dense(W, q, mu, offsets, sizes, nc, m, rho, cur, u, phi, x, pr)
    best = fclib_error_rows(q, mu, offsets, sizes, nc, m, cur, u, x, pr)
    if not (math.isfinite(norm) and math.isfinite(best)) or best <= tol:
        return best, 0
    lam = LAMBDA_START
    steps = 0
    while steps < max_steps:
        steps += 1
        jacobian_blocks(mu[:nc], offsets[:nc], sizes[:nc], rho, cur, u, A, C)
        for j in range(nc):
            o, dj = offsets[j], sizes[j]
            for a in range(dj):
                row = o + a
                for c in range(m):
                    acc = 0.0
                    for b in range(dj):
                        acc += C[j, a, b] * W[o + b, c]
                    Jm[row, c] = acc
                for b in range(dj):
                    Jm[row, o + b] += A[j, a, b]
        for a in range(m):
            Jm[a, a] += lam
            d[a] = -phi[a]
        accepted = False
        step = 1.0
        n_trial = norm
        if _lu_solve(Jm, d, m):
            while step >= MIN_STEP:
                for a in range(m):
                    trial[a] = cur[a] + step * d[a]
                n_trial = _natural_map_dense(W, q, mu, offsets, sizes, nc, m, rho, trial, trial_u, trial_phi, x, pr)
                if math.isfinite(n_trial) and n_trial * n_trial <= (1.0 - 2.0 * ARMIJO * step) * norm * norm:
                    accepted = True
                    break
                step *= 0.5
        if accepted:
            for a in range(m):
                cur[a] = trial[a]
                u[a] = trial_u[a]
                phi[a] = trial_phi[a]
            norm = n_trial
            if step == 1.0:
                lam = max(lam * 0.1, 1e-14)
            err = fclib_error_rows(q, mu, offsets, sizes, nc, m, cur, u, x, pr)
            if err < best:
                best = err
                for a in range(m):
                    r[a] = cur[a]
            if best <= tol:
                break
        else:
            lam = max(lam * 10.0, 1e-6)
            if lam > LAMBDA_MAX:
                break
    return best, steps


@njit(cache=True)
def newton_polish(W, q, mu, offsets, sizes, nc, m, P, tol, max_steps):
    """Nonsmooth Newton, then proximal rounds, from ``P`` on ``u = W P + q`` (leading ``nc`` contacts, ``m`` rows).

    First Newton on the problem itself (:func:`_newton`); where it stalls (a singular ``J`` whose
    regularized steps stop descending), proximal point rounds as
    :func:`fixplan.engine.newton.run_prox`: Newton on the well-conditioned ``W + σD``,
    ``q − σD r_k`` (``D`` the diagonal of ``W``), whose solution is the next ``r_{k+1}``, ``σ``
    ×0.3 after a converged round and ×3 after a failed one. ``P`` is overwritten by the iterate
    with the lowest FCLib residual on the original problem (the start if none improved it).
    Returns ``(error, Newton steps in all, converged)``; ``max_steps`` caps the Newton steps of
    each stage and the proximal rounds. Standard cones only (soft-finger spin rows already
    scaled, as the sweep sees them).
    """
    if m == 0:
        return 0.0, 0, True
    x = np.empty(4)
    pr = np.empty(4)
    u = np.empty(m)
    r = P[:m].copy()
    r0 = P[:m].copy()
    best = _residual(W, q, mu, offsets, sizes, nc, m, r, u, x, pr)
    if not math.isfinite(best):
        return best, 0, False
    if best <= tol:
        return best, 0, True
    err, steps = _newton(W, q, mu, offsets, sizes, nc, m, r, tol, max_steps)
    if err < best:
        best = err
        for a in range(m):
            P[a] = r[a]
    if best <= tol:
        return best, steps, True
    # proximal rounds from the start (not from Newton's iterate: on a wedged corner Newton can
    # creep toward a near-solution with large internal impulses, residual 2.5e-6, where the
    # rounds stay; from the start they reach 1e-9)
    for a in range(m):
        r[a] = r0[a]
    Ws = W[:m, :m].copy()
    qs = np.empty(m)
    D = np.empty(m)
    dsum, dcount = 0.0, 0
    for a in range(m):
        if W[a, a] > 0.0:
            dsum += W[a, a]
            dcount += 1
    for a in range(m):
        D[a] = W[a, a] if W[a, a] > 0.0 else (dsum / dcount if dcount > 0 else 1.0)
    sigma = 1.0
    inner_tol = max(0.1 * tol, 1e-16)
    for _ in range(max_steps):
        for a in range(m):
            Ws[a, a] = W[a, a] + sigma * D[a]
            qs[a] = q[a] - sigma * D[a] * r[a]
        inner_err, inner_steps = _newton(Ws, qs, mu, offsets, sizes, nc, m, r, inner_tol, max_steps)
        steps += inner_steps
        err = _residual(W, q, mu, offsets, sizes, nc, m, r, u, x, pr)
        if not math.isfinite(err):
            break
        if err < best:
            best = err
            for a in range(m):
                P[a] = r[a]
            if best <= tol:
                return best, steps, True
        sigma = sigma * 0.3 if inner_err <= inner_tol else sigma * 3.0
        sigma = min(max(sigma, 1e-10), 1e6)
    return best, steps, best <= tol
