"""The compiled Moreau–Jean time step (MATH.md [3]–[5], contact laws [8]–[10], NSGS).

One call advances one rigid workpiece among fixed spherical-tip locators by one step ``h``:

1. **Detection** (start of step): every locator's gap, contact point and normal from the
   closed-form shape queries of :mod:`.detect`; a contact is active when its gap is at most
   ``margin``.
2. **Free motion**, angular-momentum form [4]: ``L⁻ = I_w⁻ ω⁻``, ``L_free = L⁻ + h τ_e`` and
   ``ω_free = I_w⁺⁻¹ L_free`` with ``I_w⁺`` at the end-of-step orientation
   ``R⁺ = exp(h ω̂) R``, found by fixed-point iteration. A free body's angular momentum is
   therefore conserved to rounding (the explicit gyroscopic form is not). ``v_free = v + h f_e/m``.
3. **Transfer equations** [5]: ``u = W P + q`` with ``W = J M⁻¹ Jᵀ`` (``M`` with ``I_w⁺``) and
   ``q = J ν_free``, plus, per normal row: Newton restitution ``+ e u_n⁻`` for a contact that
   approaches (``u_n⁻ < 0``) and closes within the step (``e > 0``: an impact, whose O(h·v)
   overlap the post-stabilisation removes); otherwise ``+ g/h`` for a contact still open by
   ``g > 0`` (it may close during the step but not overshoot: ``g + h u_n ≥ 0``).
   Soft-finger spin rows are scaled by ``e_r`` so the 4D ellipsoid is a standard cone.
4. **Nonsmooth Gauss–Seidel** with the exact one-contact solvers of :mod:`.local`, warm
   started from the previous step's impulses, stopped on the FCLib residual (natural map),
   ``max_iter`` only a cap.
5. **Update**: ``ν⁺ = ν_free + M⁻¹ Jᵀ P``; ``c⁺ = c + h v⁺``; ``R⁺ = exp(h ω̂⁺) R``.
6. **Position post-stabilisation** (Cline & Pai): if an active contact penetrates at the new
   pose, the pose alone is moved by the ``M``-smallest displacement ``Δ = M⁻¹ Gᵀ λ`` with
   ``0 ≤ λ ⊥ g + G Δ ≥ 0`` (a small LCP solved by projected Gauss–Seidel), repeated up to three
   times for the nonlinearity. Velocities are not touched, so no kinetic energy is injected
   (Baumgarte-type velocity terms would); the correction only ever pushes out of contact.

Everything here is ``numba.njit(cache=True)``; :mod:`.reference` is the plain NumPy version of
the same step used by the tests.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fixplan.engine.detect import project
from fixplan.engine.local import FAILED, project_cone_into
from fixplan.engine.nsgs import local_solve_into

STATUS_OK, STATUS_NOT_CONVERGED, STATUS_NONFINITE = 0, 1, 2


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


@njit(cache=True, inline="always")
def mmt(A, B):
    """``A @ B.T`` without BLAS."""
    n, k = A.shape
    m = B.shape[0]
    out = np.zeros((n, m))
    for i in range(n):
        for j in range(m):
            acc = 0.0
            for p in range(k):
                acc += A[i, p] * B[j, p]
            out[i, j] = acc
    return out


@njit(cache=True)
def exp_so3(w):
    """Rodrigues' formula, entry by entry (one allocation)."""
    x, y, z = w[0], w[1], w[2]
    th2 = x * x + y * y + z * z
    th = math.sqrt(th2)
    if th < 1e-8:
        a, b = 1.0, 0.5
    else:
        a, b = math.sin(th) / th, (1.0 - math.cos(th)) / th2
    R = np.empty((3, 3))
    R[0, 0] = 1.0 - b * (y * y + z * z)
    R[1, 1] = 1.0 - b * (x * x + z * z)
    R[2, 2] = 1.0 - b * (x * x + y * y)
    R[0, 1] = -a * z + b * x * y
    R[1, 0] = a * z + b * x * y
    R[0, 2] = a * y + b * x * z
    R[2, 0] = -a * y + b * x * z
    R[1, 2] = -a * x + b * y * z
    R[2, 1] = a * x + b * y * z
    return R


@njit(cache=True)
def tangents3(n):
    """Same tangent choice as :func:`fixplan.kinematics.tangent_basis`."""
    if abs(n[0]) < 0.9:
        a0, a1, a2 = 1.0, 0.0, 0.0
    else:
        a0, a1, a2 = 0.0, 1.0, 0.0
    dot = a0 * n[0] + a1 * n[1] + a2 * n[2]
    t1 = np.array([a0 - dot * n[0], a1 - dot * n[1], a2 - dot * n[2]])
    t1 /= math.sqrt(t1[0] ** 2 + t1[1] ** 2 + t1[2] ** 2)
    t2 = np.array([n[1] * t1[2] - n[2] * t1[1], n[2] * t1[0] - n[0] * t1[2], n[0] * t1[1] - n[1] * t1[0]])
    return t1, t2


@njit(cache=True)
def fclib_error_ws(q, mu, offsets, sizes, P, u, x, pr):
    """Siconos/FCLib residual (natural map, ρ = 1), normalised by max(‖q‖, ‖P‖, ‖u‖).

    ``x`` and ``pr`` are caller-owned scratch vectors of length 4 (no allocation per sweep).
    """
    total = 0.0
    for j in range(offsets.shape[0]):
        o, d = offsets[j], sizes[j]
        nt = 0.0
        for a in range(1, d):
            nt += u[o + a] * u[o + a]
        nt = math.sqrt(nt)
        x[0] = P[o] - (u[o] + mu[j] * nt)
        for a in range(1, d):
            x[a] = P[o + a] - u[o + a]
        project_cone_into(x[:d], mu[j], pr[:d])
        for a in range(d):
            diff = P[o + a] - pr[a]
            total += diff * diff
    scale = max(math.sqrt(np.sum(q * q)), max(math.sqrt(np.sum(P * P)), math.sqrt(np.sum(u * u))))
    return math.sqrt(total) / scale if scale > 0.0 else math.sqrt(total)


@njit(cache=True)
def _invert_small(A, out):
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


@njit(cache=True)
def _fast_local(alpha, mu, d, inv, has_inv, P):
    """The open and stick regimes in closed form when they hold clearly; False: use the full solver.

    Open: ``α_n ≥ 0`` gives ``P = 0`` exactly (the local solver's first regime). Stick:
    ``P = −W_jj⁻¹ α`` is accepted only strictly inside the cone (a relative margin of 1e-9), so
    every boundary case still goes to the exact solver.
    """
    if alpha[0] >= 0.0:
        for a in range(d):
            P[a] = 0.0
        return True
    if not has_inv:
        return False
    for a in range(d):
        acc = 0.0
        for b in range(d):
            acc -= inv[a, b] * alpha[b]
        P[a] = acc
    if P[0] <= 0.0:
        return False
    nt = 0.0
    for a in range(1, d):
        nt += P[a] * P[a]
    return math.sqrt(nt) < mu * P[0] * (1.0 - 1e-9)


@njit(cache=True)
def nsgs_dense(W, q, mu, offsets, sizes, P, tol, max_iter):
    """Gauss–Seidel sweeps with exact local solves until the FCLib residual ≤ tol.

    Returns (error, iterations, converged, failed local solves in the last sweep).
    """
    m = q.shape[0]
    nc = offsets.shape[0]
    alpha = np.empty(4)
    Pj = np.empty(4)
    u = np.empty(m)
    xbuf = np.empty(4)
    prbuf = np.empty(4)
    err = math.inf
    failures = 0
    if m == 0:
        return 0.0, 0, True, 0
    diag = np.zeros((nc, 4, 4))
    inv = np.zeros((nc, 4, 4))
    has_inv = np.zeros(nc, dtype=np.bool_)
    for j in range(nc):
        o, d = offsets[j], sizes[j]
        for a in range(d):
            for b in range(d):
                diag[j, a, b] = W[o + a, o + b]
        has_inv[j] = _invert_small(diag[j, :d, :d], inv[j, :d, :d])
    it = 0
    for it in range(1, max_iter + 1):
        failures = 0
        for j in range(nc):
            o, d = offsets[j], sizes[j]
            for a in range(d):
                s = q[o + a]
                for c in range(m):
                    if c < o or c >= o + d:
                        s += W[o + a, c] * P[c]
                alpha[a] = s
            if not _fast_local(alpha, mu[j], d, inv[j], has_inv[j], Pj):
                st, _ = local_solve_into(diag[j, :d, :d], alpha[:d], mu[j], d, Pj[:d])
                if st == FAILED:
                    failures += 1
            for a in range(d):
                P[o + a] = Pj[a]
        for r in range(m):
            s = q[r]
            for c in range(m):
                s += W[r, c] * P[c]
            u[r] = s
        err = fclib_error_ws(q, mu, offsets, sizes, P, u, xbuf, prbuf)
        if not math.isfinite(err):
            return err, it, False, failures
        if err <= tol:
            return err, it, True, failures
    return err, it, False, failures


@njit(cache=True)
def _pgs_lcp(A, b, x, iterations):
    """Projected Gauss–Seidel for 0 ≤ x ⊥ A x + b ≥ 0 (A symmetric PSD, small)."""
    n = b.shape[0]
    for _ in range(iterations):
        change = 0.0
        for i in range(n):
            if A[i, i] <= 0.0:
                continue
            s = b[i]
            for j in range(n):
                s += A[i, j] * x[j]
            new = max(0.0, x[i] - s / A[i, i])
            change = max(change, abs(new - x[i]))
            x[i] = new
        if change <= 1e-16:
            break


@njit(cache=True)
def step3(R, p, v, w, mass, Ib, Ib_inv, com_b, kind, params, verts, enorm, loc_p, loc_r, mu, tors,
          h, f_ext, tau_ext, restitution, margin, tol, max_iter, P_warm, warm_active, bound_m):  # fmt: skip
    """One 3D step. Returns the new state, impulses, diagnostics (see :class:`fixplan.simulator.Simulator`)."""
    k = loc_p.shape[0]
    c = p + mv(R, com_b)
    gap = np.empty(k)
    n_w = np.zeros((k, 3))
    pt_w = np.zeros((k, 3))
    active = np.zeros(k, dtype=np.bool_)
    point = np.empty(3)
    normal = np.empty(3)
    for i in range(k):
        pb = mtv(R, loc_p[i] - p)
        dist = project(kind, params, verts, enorm, pb, point, normal)
        gap[i] = dist - loc_r[i]
        n_w[i] = -mv(R, normal)
        pt_w[i] = p + mv(R, point)
        active[i] = gap[i] <= margin
    # free motion, angular-momentum form
    v_free = v + h * f_ext / mass
    L_free = mv(R, mv(Ib, mtv(R, w))) + h * tau_ext
    w_pred = w.copy()
    Rn = R
    spinning = (w[0] != 0.0 or w[1] != 0.0 or w[2] != 0.0) or (L_free[0] != 0.0 or L_free[1] != 0.0 or L_free[2] != 0.0)
    for _ in range(50 if spinning else 0):
        Rn = mm(exp_so3(h * w_pred), R)
        w_new = mv(Rn, mv(Ib_inv, mtv(Rn, L_free)))
        dw = math.sqrt(np.sum((w_new - w_pred) ** 2))
        w_pred = w_new
        if dw <= 1e-15 * (1.0 + math.sqrt(np.sum(w_new * w_new))):
            break
    if spinning:
        Rn = mm(exp_so3(h * w_pred), R)
    Iinv = mmt(mm(Rn, Ib_inv), Rn)
    # contact rows
    nc = 0
    m = 0
    for i in range(k):
        if active[i]:
            nc += 1
            m += 4 if tors[i] > 0.0 else 3
    idx = np.empty(nc, dtype=np.int64)
    offsets = np.empty(nc, dtype=np.int64)
    sizes = np.empty(nc, dtype=np.int64)
    mus = np.empty(nc)
    J = np.zeros((m, 6))
    row = 0
    j = 0
    for i in range(k):
        if not active[i]:
            continue
        idx[j] = i
        offsets[j] = row
        sizes[j] = 4 if tors[i] > 0.0 else 3
        mus[j] = mu[i]
        n = n_w[i]
        r = pt_w[i] - c
        t1, t2 = tangents3(n)
        for a, t in enumerate((n, t1, t2)):
            J[row + a, 0:3] = t
            J[row + a, 3] = r[1] * t[2] - r[2] * t[1]
            J[row + a, 4] = r[2] * t[0] - r[0] * t[2]
            J[row + a, 5] = r[0] * t[1] - r[1] * t[0]
        if sizes[j] == 4:
            J[row + 3, 3:6] = tors[i] * n
        row += sizes[j]
        j += 1
    nu_free = np.concatenate((v_free, w_pred))
    nu_old = np.concatenate((v, w))
    MinvJt = np.empty((6, m))
    inv_m = 1.0 / mass
    for r_ in range(m):
        for a in range(3):
            MinvJt[a, r_] = J[r_, a] * inv_m
            MinvJt[3 + a, r_] = Iinv[a, 0] * J[r_, 3] + Iinv[a, 1] * J[r_, 4] + Iinv[a, 2] * J[r_, 5]
    W = np.empty((m, m))
    for r_ in range(m):
        for c_ in range(r_, m):
            acc = 0.0
            for a in range(6):
                acc += J[r_, a] * MinvJt[a, c_]
            W[r_, c_] = acc
            W[c_, r_] = acc
    q = mv(J, nu_free)
    for jj in range(nc):
        i = idx[jj]
        o = offsets[jj]
        un_old = np.dot(J[o], nu_old)
        if restitution > 0.0 and un_old < 0.0 and gap[i] + h * un_old <= 0.0:
            q[o] += restitution * un_old  # an impact within this step: Newton's law, u_n⁺ ≥ −e u_n⁻
        elif gap[i] > 0.0:
            q[o] += gap[i] / h  # may close, may not overshoot: g + h u_n ≥ 0
        elif un_old < 0.0:
            q[o] += restitution * un_old
    P = np.zeros(m)
    for jj in range(nc):
        i = idx[jj]
        if warm_active[i]:
            for a in range(sizes[jj]):
                P[offsets[jj] + a] = P_warm[i, a]
    err, iters, converged, failures = nsgs_dense(W, q, mus, offsets, sizes, P, tol, max_iter)
    dnu = mv(MinvJt, P)
    v_new = v_free + dnu[0:3]
    w_new = w_pred + dnu[3:6]
    u = mv(W, P) + q
    status = STATUS_OK if converged else STATUS_NOT_CONVERGED
    if not (np.all(np.isfinite(v_new)) and np.all(np.isfinite(w_new)) and math.isfinite(err)):
        status = STATUS_NONFINITE
        return R, p, v, w, np.zeros((k, 4)), active, gap, np.zeros((k, 4)), n_w, pt_w, err, iters, status, failures, 0.0
    c_new = c + h * v_new
    R_new = mm(exp_so3(h * w_new), R)
    # position post-stabilisation; a body that does not move keeps g + h u_n ≥ 0 exactly
    pen = 0.0
    deepest = 0.0
    for i in range(k):
        if active[i] and -gap[i] > deepest:
            deepest = -gap[i]
    moved = h * (math.sqrt(np.sum(v_new * v_new)) + math.sqrt(np.sum(w_new * w_new)) * bound_m)
    for _ in range(3 if (moved > 1e-12 or deepest > 1e-12) else 0):
        p_new = c_new - mv(R_new, com_b)
        G = np.zeros((nc, 6))
        g = np.zeros(nc)
        worst = 0.0
        for jj in range(nc):
            i = idx[jj]
            pb = mtv(R_new, loc_p[i] - p_new)
            g[jj] = project(kind, params, verts, enorm, pb, point, normal) - loc_r[i]
            nn = -mv(R_new, normal)
            r = p_new + mv(R_new, point) - c_new
            G[jj, 0:3] = nn
            G[jj, 3] = r[1] * nn[2] - r[2] * nn[1]
            G[jj, 4] = r[2] * nn[0] - r[0] * nn[2]
            G[jj, 5] = r[0] * nn[1] - r[1] * nn[0]
            worst = min(worst, g[jj])
        pen = -worst
        if worst >= -1e-12:
            break
        MinvGt = np.empty((6, nc))
        for jj in range(nc):
            MinvGt[0:3, jj] = G[jj, 0:3] / mass
            MinvGt[3:6, jj] = mv(Iinv, G[jj, 3:6])
        A = mm(G, MinvGt)
        lam = np.zeros(nc)
        _pgs_lcp(A, g, lam, 200)
        d = mv(MinvGt, lam)
        c_new = c_new + d[0:3]
        R_new = mm(exp_so3(d[3:6]), R_new)
    p_new = c_new - mv(R_new, com_b)
    P_full = np.zeros((k, 4))
    u_full = np.zeros((k, 4))
    for jj in range(nc):
        i = idx[jj]
        for a in range(sizes[jj]):
            P_full[i, a] = P[offsets[jj] + a]
            u_full[i, a] = u[offsets[jj] + a]
    return (
        R_new,
        p_new,
        v_new,
        w_new,
        P_full,
        active,
        gap,
        u_full,
        n_w,
        pt_w,
        err,
        iters,
        status,
        failures,
        max(pen, deepest, 0.0),
    )


@njit(cache=True)
def step2(theta, p, v, w, mass, Izz, com_b, kind, params, verts, enorm, loc_p, loc_r, mu,
          h, f_ext, tau_ext, restitution, margin, tol, max_iter, P_warm, warm_active, bound_m):  # fmt: skip
    """One planar step (ν = (vx, vy, ω)). Same outputs as :func:`step3` with 2-row contacts."""
    k = loc_p.shape[0]
    cs, sn = math.cos(theta), math.sin(theta)
    R = np.array([[cs, -sn], [sn, cs]])
    c = p + mv(R, com_b)
    gap = np.empty(k)
    n_w = np.zeros((k, 2))
    pt_w = np.zeros((k, 2))
    active = np.zeros(k, dtype=np.bool_)
    point = np.empty(2)
    normal = np.empty(2)
    for i in range(k):
        pb = mtv(R, loc_p[i] - p)
        gap[i] = project(kind, params, verts, enorm, pb, point, normal) - loc_r[i]
        n_w[i] = -mv(R, normal)
        pt_w[i] = p + mv(R, point)
        active[i] = gap[i] <= margin
    v_free = v + h * f_ext / mass
    w_free = w + h * tau_ext / Izz
    nc = 0
    for i in range(k):
        if active[i]:
            nc += 1
    m = 2 * nc
    idx = np.empty(nc, dtype=np.int64)
    offsets = np.empty(nc, dtype=np.int64)
    sizes = np.full(nc, 2, dtype=np.int64)
    mus = np.empty(nc)
    J = np.zeros((m, 3))
    jj = 0
    for i in range(k):
        if not active[i]:
            continue
        idx[jj] = i
        offsets[jj] = 2 * jj
        mus[jj] = mu[i]
        n = n_w[i]
        t = np.array([-n[1], n[0]])
        r = pt_w[i] - c
        J[2 * jj, 0:2] = n
        J[2 * jj, 2] = r[0] * n[1] - r[1] * n[0]
        J[2 * jj + 1, 0:2] = t
        J[2 * jj + 1, 2] = r[0] * t[1] - r[1] * t[0]
        jj += 1
    Minv = np.array([1.0 / mass, 1.0 / mass, 1.0 / Izz])
    MinvJt = np.empty((3, m))
    for r_ in range(m):
        MinvJt[:, r_] = J[r_] * Minv
    W = mm(J, MinvJt)
    nu_free = np.array([v_free[0], v_free[1], w_free])
    nu_old = np.array([v[0], v[1], w])
    q = mv(J, nu_free)
    for jj in range(nc):
        i = idx[jj]
        o = offsets[jj]
        un_old = np.dot(J[o], nu_old)
        if restitution > 0.0 and un_old < 0.0 and gap[i] + h * un_old <= 0.0:
            q[o] += restitution * un_old  # an impact within this step: Newton's law, u_n⁺ ≥ −e u_n⁻
        elif gap[i] > 0.0:
            q[o] += gap[i] / h  # may close, may not overshoot: g + h u_n ≥ 0
        elif un_old < 0.0:
            q[o] += restitution * un_old
    P = np.zeros(m)
    for jj in range(nc):
        i = idx[jj]
        if warm_active[i]:
            P[2 * jj] = P_warm[i, 0]
            P[2 * jj + 1] = P_warm[i, 1]
    err, iters, converged, failures = nsgs_dense(W, q, mus, offsets, sizes, P, tol, max_iter)
    dnu = mv(MinvJt, P)
    nu = nu_free + dnu
    u = mv(W, P) + q
    status = STATUS_OK if converged else STATUS_NOT_CONVERGED
    if not (np.all(np.isfinite(nu)) and math.isfinite(err)):
        return (
            theta,
            p,
            v,
            w,
            np.zeros((k, 4)),
            active,
            gap,
            np.zeros((k, 4)),
            n_w,
            pt_w,
            err,
            iters,
            STATUS_NONFINITE,
            failures,
            0.0,
        )
    v_new = nu[0:2].copy()
    w_new = nu[2]
    c_new = c + h * v_new
    th_new = theta + h * w_new
    pen = 0.0
    deepest = 0.0
    for i in range(k):
        if active[i] and -gap[i] > deepest:
            deepest = -gap[i]
    moved = h * (math.sqrt(np.sum(v_new * v_new)) + abs(w_new) * bound_m)
    for _ in range(3 if (moved > 1e-12 or deepest > 1e-12) else 0):
        cs, sn = math.cos(th_new), math.sin(th_new)
        Rn = np.array([[cs, -sn], [sn, cs]])
        p_new = c_new - mv(Rn, com_b)
        G = np.zeros((nc, 3))
        g = np.zeros(nc)
        worst = 0.0
        for jj in range(nc):
            i = idx[jj]
            pb = mtv(Rn, loc_p[i] - p_new)
            g[jj] = project(kind, params, verts, enorm, pb, point, normal) - loc_r[i]
            nn = -mv(Rn, normal)
            r = p_new + mv(Rn, point) - c_new
            G[jj, 0:2] = nn
            G[jj, 2] = r[0] * nn[1] - r[1] * nn[0]
            worst = min(worst, g[jj])
        pen = -worst
        if worst >= -1e-12:
            break
        MinvGt = np.empty((3, nc))
        for jj in range(nc):
            MinvGt[:, jj] = G[jj] * Minv
        A = mm(G, MinvGt)
        lam = np.zeros(nc)
        _pgs_lcp(A, g, lam, 200)
        d = mv(MinvGt, lam)
        c_new = c_new + d[0:2]
        th_new = th_new + d[2]
    cs, sn = math.cos(th_new), math.sin(th_new)
    p_new = c_new - mv(np.array([[cs, -sn], [sn, cs]]), com_b)
    P_full = np.zeros((k, 4))
    u_full = np.zeros((k, 4))
    for jj in range(nc):
        i = idx[jj]
        P_full[i, 0:2] = P[2 * jj : 2 * jj + 2]
        u_full[i, 0:2] = u[2 * jj : 2 * jj + 2]
    return (
        th_new,
        p_new,
        v_new,
        w_new,
        P_full,
        active,
        gap,
        u_full,
        n_w,
        pt_w,
        err,
        iters,
        status,
        failures,
        max(pen, deepest, 0.0),
    )


@njit(cache=True)
def run3(n_steps, record_every, R, p, v, w, mass, Ib, Ib_inv, com_b, kind, params, verts, enorm, loc_p, loc_r,
         mu, tors, h, f_ext, tau_world, restitution, margin_m, bound, tol, max_iter, P, active):  # fmt: skip
    """``n_steps`` of :func:`step3` under a constant wrench, compiled end to end.

    ``tau_world`` is the applied moment about the body origin; it is re-expressed about the
    moving centre of mass every step. Returns the final state and the recorded samples.
    """
    k = loc_p.shape[0]
    n_rec = n_steps // record_every + 2
    rec_p = np.zeros((n_rec, 3))
    rec_R = np.zeros((n_rec, 3, 3))
    rec_nu = np.zeros((n_rec, 6))
    rec_fn = np.zeros((n_rec, k))
    rec_gap = np.zeros((n_rec, k))
    rec_err = np.zeros(n_rec)
    rec_it = np.zeros(n_rec, dtype=np.int64)
    rec_p[0] = p
    rec_R[0] = R
    rec_nu[0, 0:3] = v
    rec_nu[0, 3:6] = w
    r = 1
    max_pen = 0.0
    status = STATUS_OK
    worst_err = 0.0
    gap = np.zeros(k)
    n_last = np.zeros((k, 3))
    u_last = np.zeros((k, 4))
    last_err, last_it = 0.0, 0
    for s in range(1, n_steps + 1):
        c = p + mv(R, com_b)
        off = p - c
        tau = tau_world + np.array([off[1] * f_ext[2] - off[2] * f_ext[1], off[2] * f_ext[0] - off[0] * f_ext[2],
                                    off[0] * f_ext[1] - off[1] * f_ext[0]])  # fmt: skip
        speed = math.sqrt(np.sum(v * v)) + math.sqrt(np.sum(w * w)) * bound
        margin = margin_m + 2.0 * h * speed
        R2, p2, v2, w2, P2, active2, gap, u, n_w, pt_w, err, iters, st, failures, pen = step3(
            R, p, v, w, mass, Ib, Ib_inv, com_b, kind, params, verts, enorm, loc_p, loc_r, mu, tors,
            h, f_ext, tau, restitution, margin, tol, max_iter, P, active, bound)  # fmt: skip
        if st == STATUS_NONFINITE:
            status = st
            break
        if st == STATUS_NOT_CONVERGED:
            status = st
        R, p, v, w, P, active = R2, p2, v2, w2, P2, active2
        n_last, u_last = n_w, u
        max_pen = max(max_pen, pen)
        worst_err = max(worst_err, err)
        last_err, last_it = err, iters
        if (s % record_every == 0 or s == n_steps) and r < n_rec:
            rec_p[r] = p
            rec_R[r] = R
            rec_nu[r, 0:3] = v
            rec_nu[r, 3:6] = w
            for i in range(k):
                rec_fn[r, i] = P[i, 0] / h if active[i] else 0.0
                rec_gap[r, i] = gap[i]
            rec_err[r] = err
            rec_it[r] = iters
            r += 1
    return (R, p, v, w, P, active, gap, n_last, u_last, rec_p[:r], rec_R[:r], rec_nu[:r], rec_fn[:r], rec_gap[:r],
            rec_err[:r], rec_it[:r], max_pen, worst_err, status, last_err, last_it)  # fmt: skip


@njit(cache=True)
def step3_into(state, mass, Ib, Ib_inv, com_b, kind, params, verts, enorm, loc_p, loc_r, mu, tors, h, f_ext,
               tau_ext, restitution, margin, tol, max_iter, P, active, gap, u, n_w, bound):  # fmt: skip
    """:func:`step3` writing into caller-owned buffers (cheap to call from Python).

    ``state`` is a (4, 3, 3) buffer: ``state[0]`` = R, ``state[1, 0]`` = p, ``state[1, 1]`` = v,
    ``state[1, 2]`` = ω. Returns (error, iterations, status, failures, penetration).
    """
    R = state[0].copy()
    p = state[1, 0].copy()
    v = state[1, 1].copy()
    w = state[1, 2].copy()
    out = step3(R, p, v, w, mass, Ib, Ib_inv, com_b, kind, params, verts, enorm, loc_p, loc_r, mu, tors, h,
                f_ext, tau_ext, restitution, margin, tol, max_iter, P.copy(), active.copy(), bound)  # fmt: skip
    R2, p2, v2, w2, P2, act2, gap2, u2, nw2, _pt, err, iters, status, failures, pen = out
    if status != STATUS_NONFINITE:
        state[0] = R2
        state[1, 0] = p2
        state[1, 1] = v2
        state[1, 2] = w2
        P[:] = P2
        active[:] = act2
        u[:] = u2
        n_w[:] = nw2
    gap[:] = gap2
    return err, iters, status, failures, pen
