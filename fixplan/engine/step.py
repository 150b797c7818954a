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
   started from the previous step's impulses (in 3D, a contact that slid in the last step from
   the linear extrapolation of its last two impulses, projected on its cone), stopped on the
   FCLib residual (natural map), ``max_iter`` only a cap. A 3D contact tries the closed-form
   open and strict-stick regimes, then the sliding regime by Newton on the slip direction
   started from its current impulse (:func:`slide3_newton`), then the general solver.
5. **Update**: ``ν⁺ = ν_free + M⁻¹ Jᵀ P``; ``c⁺ = c + h v⁺``; ``R⁺ = exp(h ω̂⁺) R``.
6. **Position post-stabilisation** (Cline & Pai): if an active contact penetrates at the new
   pose, the pose alone is moved by the ``M``-smallest displacement ``Δ = M⁻¹ Gᵀ λ`` with
   ``0 ≤ λ ⊥ g + G Δ ≥ 0`` (a small LCP solved by projected Gauss–Seidel), repeated up to three
   times for the nonlinearity. Velocities are not touched, so no kinetic energy is injected
   (Baumgarte-type velocity terms would); the correction only ever pushes out of contact.

Everything here is ``numba.njit(cache=True)``; :mod:`.reference` is the plain NumPy version of
the same step used by the tests.

Speed (issue 11 §2). The 3D step :func:`step3_ws` works in the buffers of :func:`workspace3`,
allocated once per run by :func:`run3` (the compiled multi-step loop under a constant or
piecewise-constant wrench) or per call by :func:`step3_into` (Python's :meth:`Simulator.step`);
it allocates nothing. Measured on the six-locator box before this layout: 10 µs per step, of
which 3.7 µs detection, nearly all of it small-array allocation (~0.1 µs each). The code on the
per-contact paths takes and returns scalars: a numba helper that merely *contains* a call to a
general routine (the shape query :func:`~fixplan.engine.detect.project`, a cone projection on
array views) cost about 0.2 µs per call even when that branch never ran, so the caller picks the
box-only or 3D-only scalar path and keeps the general call for the other shapes and dimensions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fixplan.engine.detect import BOX, project
from fixplan.engine.local import FAILED, WORKSPACE_SIZE, project_cone_into
from fixplan.engine.nsgs import local_solve_into, local_solve_ws

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
    _pgs_lcp_n(A, b, x, b.shape[0], iterations)


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


# ---------------------------------------------------------------------------------------------
# 3D: one allocation-free step on a caller-owned workspace, and the compiled multi-step loop
# ---------------------------------------------------------------------------------------------
_SLIDE_NEWTON_ITER = 16
_SLIP_WARM = 1e-7  # [m/s] slip above which a contact's warm start is extrapolated (the 'sliding' of contacts())


@njit(cache=True)
def slide3_newton(A, alpha, mu, P):
    """The sliding regime of a 3D contact by Newton on the slip direction, started from ``P``'s.

    Sliding means ``u_n = 0``, ``P_t = −μ P_n s`` and ``u_t = g s`` with ``g > 0`` for a unit
    ``s = (cos θ, sin θ)``. For a given ``s`` the first condition gives
    ``P_n = −α_n / (W_nn − μ W_nt·s)``, so the law is the scalar equation
    ``f(θ) = u_t × s = 0`` (with ``g = u_t·s > 0``), and ``f'(θ) = (du_t/dθ) × s + g`` exactly.
    Newton's step ``δ = f/f'`` turns ``s`` by ``atan δ`` (``s ← (s − δ s⊥)/√(1 + δ²)``: no
    trigonometry; still quadratic). Started from the previous sweep's (or step's) slip direction
    it converges in 2–3 steps, a fraction of the general root find of :mod:`.local`. The result is
    accepted only when the last step is below 1e-14 rad, ``D``, ``P_n`` and the slip ``g`` are
    clearly positive (``g > 1e-9‖α‖``, so a contact at the stick/slide boundary goes to the
    general solver) and everything is finite; otherwise ``False`` and the caller uses the general
    solver. No cone is linearized: the root is of the exact law.
    """
    an = alpha[0]
    if not (an < 0.0) or not (mu > 1e-17):
        return False
    a = A[0, 0]
    b0 = A[0, 1]
    b1 = A[0, 2]
    c0 = A[1, 0]
    c1 = A[2, 0]
    C00 = A[1, 1]
    C01 = A[1, 2]
    C10 = A[2, 1]
    C11 = A[2, 2]
    a1 = alpha[1]
    a2 = alpha[2]
    s0, s1 = -P[1], -P[2]  # u_t opposes P_t
    ns = math.sqrt(s0 * s0 + s1 * s1)
    if not (ns > 0.0) or not math.isfinite(ns):
        s0, s1 = a1, a2
        ns = math.sqrt(s0 * s0 + s1 * s1)
        if not (ns > 0.0) or not math.isfinite(ns):
            return False
    s0 /= ns
    s1 /= ns
    scale = abs(an) + abs(a1) + abs(a2)
    for _ in range(_SLIDE_NEWTON_ITER):
        D = a - mu * (b0 * s0 + b1 * s1)
        if not (D > 0.0):
            return False
        Pn = -an / D
        k0 = c0 - mu * (C00 * s0 + C01 * s1)
        k1 = c1 - mu * (C10 * s0 + C11 * s1)
        ut0 = k0 * Pn + a1
        ut1 = k1 * Pn + a2
        f = ut0 * s1 - ut1 * s0
        g = ut0 * s0 + ut1 * s1
        dPn = -an * mu * (b1 * s0 - b0 * s1) / (D * D)
        dut0 = k0 * dPn - mu * Pn * (C01 * s0 - C00 * s1)
        dut1 = k1 * dPn - mu * Pn * (C11 * s0 - C10 * s1)
        df = dut0 * s1 - dut1 * s0 + g
        if not (df > 0.0) or not math.isfinite(df):
            return False
        delta = f / df
        if abs(delta) <= 1e-14:
            if not (g > 1e-9 * scale) or not (Pn > 0.0) or not math.isfinite(Pn):
                return False
            P[0] = Pn
            P[1] = -mu * Pn * s0
            P[2] = -mu * Pn * s1
            return True
        r = 1.0 / math.sqrt(1.0 + delta * delta)
        s0, s1 = (s0 + delta * s1) * r, (s1 - delta * s0) * r
    return False


@njit(cache=True)
def workspace3(k):
    """Scratch arrays for :func:`step3_ws` with ``k`` locators (allocated once per run)."""
    m = 4 * k
    return (
        np.zeros(k),  # 0: gaps at the start of the step
        np.zeros((k, 3)),  # 1: contact normals (world)
        np.zeros((k, 3)),  # 2: contact points (world)
        np.zeros(k, dtype=np.bool_),  # 3: active contacts
        np.zeros((m, 6)),  # 4: J
        np.zeros((6, m)),  # 5: M⁻¹Jᵀ
        np.zeros((m, m)),  # 6: W
        np.zeros(m),  # 7: q
        np.zeros(m),  # 8: P (active rows)
        np.zeros(m),  # 9: u (active rows)
        np.zeros(k, dtype=np.int64),  # 10: locator of each active contact
        np.zeros(k, dtype=np.int64),  # 11: row offsets
        np.zeros(k, dtype=np.int64),  # 12: row counts
        np.zeros(k),  # 13: μ of each active contact
        np.zeros((k, 4, 4)),  # 14: diagonal blocks
        np.zeros((k, 4, 4)),  # 15: their inverses
        np.zeros(k, dtype=np.bool_),  # 16: block invertible
        np.zeros((12, 3)),  # 17: 3-vectors
        np.zeros((6, 3, 3)),  # 18: 3×3 matrices
        np.zeros(WORKSPACE_SIZE + 16),  # 19: local solver scratch, α, P_j, cone scratch
        np.zeros((k, 6)),  # 20: G (post-stabilisation)
        np.zeros((6, k)),  # 21: M⁻¹Gᵀ
        np.zeros((k, k)),  # 22: G M⁻¹ Gᵀ
        np.zeros(k),  # 23: gaps at the new pose
        np.zeros(k),  # 24: λ
        np.zeros(6),  # 25: 6-vector
    )


@njit(cache=True)
def _exp_so3_into(x, y, z, R):
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
def _mm3_into(A, B, out):
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
def _mv3_into(A, x, out):
    for i in range(3):
        acc = 0.0
        for j in range(3):
            acc += A[i, j] * x[j]
        out[i] = acc


@njit(cache=True)
def _mtv3_into(A, x, out):
    for j in range(3):
        out[j] = 0.0
    for i in range(3):
        xi = x[i]
        for j in range(3):
            out[j] += A[i, j] * xi


@njit(cache=True)
def _pgs_lcp_n(A, b, x, n, iterations):
    """:func:`_pgs_lcp` on the leading ``n`` rows of caller-owned buffers."""
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
def _fclib_error_n(q, mu, offsets, sizes, nc, m, P, u, x, pr):
    """:func:`fclib_error_ws` on the leading ``nc`` contacts / ``m`` rows of workspace buffers."""
    total = 0.0
    for j in range(nc):
        o, d = offsets[j], sizes[j]
        nt = 0.0
        for a in range(1, d):
            nt += u[o + a] * u[o + a]
        nt = math.sqrt(nt)
        x[0] = P[o] - (u[o] + mu[j] * nt)
        for a in range(1, d):
            x[a] = P[o + a] - u[o + a]
        if d == 3:
            # project_cone_into's arithmetic in scalars for the usual range of ‖x_t‖²
            x0, x1, x2 = x[0], x[1], x[2]
            st = x1 * x1 + x2 * x2
            if 1e-290 < st < 1e290 and math.isfinite(x0):
                m_ = mu[j]
                xt = math.sqrt(st)
                if m_ * xt <= -x0:
                    p0, p1, p2 = 0.0, 0.0, 0.0
                elif xt <= m_ * x0:
                    p0, p1, p2 = x0, x1, x2
                else:
                    p0 = (x0 + m_ * xt) / (1.0 + m_ * m_)
                    f = m_ * p0 / xt
                    p1, p2 = f * x1, f * x2
                d0, d1, d2 = P[o] - p0, P[o + 1] - p1, P[o + 2] - p2
                total += d0 * d0
                total += d1 * d1
                total += d2 * d2
                continue
        project_cone_into(x[:d], mu[j], pr[:d])
        for a in range(d):
            diff = P[o + a] - pr[a]
            total += diff * diff
    sq = 0.0
    sp = 0.0
    su = 0.0
    for r in range(m):
        sq += q[r] * q[r]
        sp += P[r] * P[r]
        su += u[r] * u[r]
    scale = max(math.sqrt(sq), max(math.sqrt(sp), math.sqrt(su)))
    return math.sqrt(total) / scale if scale > 0.0 else math.sqrt(total)


@njit(cache=True)
def nsgs_ws(W, q, mu, offsets, sizes, nc, m, P, tol, max_iter, diag, inv, has_inv, u, scratch):
    """:func:`nsgs_dense` on workspace buffers (leading ``nc`` contacts, ``m`` rows): no allocation.

    A 3D contact whose closed-form open/stick test fails first tries :func:`slide3_newton` from
    its current impulse, then the general exact solver of :mod:`.local`.
    """
    err = math.inf
    failures = 0
    if m == 0:
        return 0.0, 0, True, 0
    ws = scratch[0:WORKSPACE_SIZE]
    alpha = scratch[WORKSPACE_SIZE : WORKSPACE_SIZE + 4]
    Pj = scratch[WORKSPACE_SIZE + 4 : WORKSPACE_SIZE + 8]
    xbuf = scratch[WORKSPACE_SIZE + 8 : WORKSPACE_SIZE + 12]
    prbuf = scratch[WORKSPACE_SIZE + 12 : WORKSPACE_SIZE + 16]
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
            if d == 3:
                # the 3D contact in scalars: α (same summation order as below), then the
                # closed-form open and strict-stick regimes of _fast_local
                s0, s1, s2 = q[o], q[o + 1], q[o + 2]
                for c in range(o):
                    pc = P[c]
                    s0 += W[o, c] * pc
                    s1 += W[o + 1, c] * pc
                    s2 += W[o + 2, c] * pc
                for c in range(o + 3, m):
                    pc = P[c]
                    s0 += W[o, c] * pc
                    s1 += W[o + 1, c] * pc
                    s2 += W[o + 2, c] * pc
                if s0 >= 0.0:
                    P[o] = 0.0
                    P[o + 1] = 0.0
                    P[o + 2] = 0.0
                    continue
                if has_inv[j]:
                    iv = inv[j]
                    x0 = -iv[0, 0] * s0 - iv[0, 1] * s1 - iv[0, 2] * s2
                    x1 = -iv[1, 0] * s0 - iv[1, 1] * s1 - iv[1, 2] * s2
                    x2 = -iv[2, 0] * s0 - iv[2, 1] * s1 - iv[2, 2] * s2
                    if x0 > 0.0 and math.sqrt(x1 * x1 + x2 * x2) < mu[j] * x0 * (1.0 - 1e-9):
                        P[o] = x0
                        P[o + 1] = x1
                        P[o + 2] = x2
                        continue
                alpha[0] = s0
                alpha[1] = s1
                alpha[2] = s2
                Pj[0] = P[o]
                Pj[1] = P[o + 1]
                Pj[2] = P[o + 2]
                if not slide3_newton(diag[j, :3, :3], alpha[:3], mu[j], Pj[:3]):
                    st, _ = local_solve_ws(diag[j, :3, :3], alpha[:3], mu[j], 3, Pj[:3], ws)
                    if st == FAILED:
                        failures += 1
                P[o] = Pj[0]
                P[o + 1] = Pj[1]
                P[o + 2] = Pj[2]
                continue
            for a in range(d):
                s = q[o + a]
                for c in range(m):
                    if c < o or c >= o + d:
                        s += W[o + a, c] * P[c]
                alpha[a] = s
            if not _fast_local(alpha, mu[j], d, inv[j], has_inv[j], Pj):
                for a in range(d):
                    Pj[a] = P[o + a]
                if not (d == 3 and slide3_newton(diag[j, :3, :3], alpha[:3], mu[j], Pj[:3])):
                    st, _ = local_solve_ws(diag[j, :d, :d], alpha[:d], mu[j], d, Pj[:d], ws)
                    if st == FAILED:
                        failures += 1
            for a in range(d):
                P[o + a] = Pj[a]
        for r in range(m):
            s = q[r]
            for c in range(m):
                s += W[r, c] * P[c]
            u[r] = s
        err = _fclib_error_n(q, mu, offsets, sizes, nc, m, P, u, xbuf, prbuf)
        if not math.isfinite(err):
            return err, it, False, failures
        if err <= tol:
            return err, it, True, failures
    return err, it, False, failures


@njit(cache=True)
def _box3(p0, p1, p2, h0, h1, h2):
    """:func:`fixplan.engine.detect.project` for a 3D box in scalars (same arithmetic, no arrays).

    Returns ``(distance, point, normal)`` as 7 numbers (body frame).
    """
    q0 = abs(p0) - h0
    q1 = abs(p1) - h1
    q2 = abs(p2) - h2
    out2 = 0.0
    if q0 > 0.0:
        out2 += q0 * q0
    if q1 > 0.0:
        out2 += q1 * q1
    if q2 > 0.0:
        out2 += q2 * q2
    scale = max(h0, max(h1, h2))
    n_out = math.sqrt(out2)
    s0 = 1.0 if p0 >= 0.0 else -1.0
    s1 = 1.0 if p1 >= 0.0 else -1.0
    s2 = 1.0 if p2 >= 0.0 else -1.0
    if n_out > 1e-12 * scale:
        return (
            n_out,
            min(max(p0, -h0), h0),
            min(max(p1, -h1), h1),
            min(max(p2, -h2), h2),
            s0 * q0 / n_out if q0 > 0.0 else 0.0,
            s1 * q1 / n_out if q1 > 0.0 else 0.0,
            s2 * q2 / n_out if q2 > 0.0 else 0.0,
        )
    # inside (or on the surface): the face of the largest q (the first one on ties)
    if q0 >= q1 and q0 >= q2:
        return q0, s0 * h0, p1, p2, s0, 0.0, 0.0
    if q1 >= q2:
        return q1, p0, s1 * h1, p2, 0.0, s1, 0.0
    return q2, p0, p1, s2 * h2, 0.0, 0.0, s2


@njit(cache=True)
def _frame3(R, p, q0, q1, q2):
    """``Rᵀ (q − p)``: the world point ``q`` in body coordinates (same sums as :func:`mtv`)."""
    d0 = q0 - p[0]
    d1 = q1 - p[1]
    d2 = q2 - p[2]
    return (
        R[0, 0] * d0 + R[1, 0] * d1 + R[2, 0] * d2,
        R[0, 1] * d0 + R[1, 1] * d1 + R[2, 1] * d2,
        R[0, 2] * d0 + R[1, 2] * d1 + R[2, 2] * d2,
    )


@njit(cache=True)
def _to_world3(R, p, dist, x0, x1, x2, m0, m1, m2):
    """``(distance, n, x)`` in world axes from the body-frame point and outward normal.

    ``n = −R·normal`` (the contact normal, into the workpiece), ``x = p + R·point``.
    """
    return (
        dist,
        -(R[0, 0] * m0 + R[0, 1] * m1 + R[0, 2] * m2),
        -(R[1, 0] * m0 + R[1, 1] * m1 + R[1, 2] * m2),
        -(R[2, 0] * m0 + R[2, 1] * m1 + R[2, 2] * m2),
        p[0] + (R[0, 0] * x0 + R[0, 1] * x1 + R[0, 2] * x2),
        p[1] + (R[1, 0] * x0 + R[1, 1] * x1 + R[1, 2] * x2),
        p[2] + (R[2, 0] * x0 + R[2, 1] * x1 + R[2, 2] * x2),
    )


@njit(cache=True)
def _box_query3(half, R, p, q0, q1, q2):
    """Gap data of the world point ``q`` against a box at ``(R, p)``: ``(distance, n, x)``, world axes.

    Kept apart from :func:`_query3`: a helper that merely contains the call to the general
    :func:`~fixplan.engine.detect.project` cost 15× more per call (measured 1.2 against 0.08 µs
    for six locators), so the caller chooses.
    """
    b0, b1, b2 = _frame3(R, p, q0, q1, q2)
    dist, x0, x1, x2, m0, m1, m2 = _box3(b0, b1, b2, half[0], half[1], half[2])
    return _to_world3(R, p, dist, x0, x1, x2, m0, m1, m2)


@njit(cache=True)
def _query3(kind, params, verts, enorm, R, p, q0, q1, q2, pb, point, normal):
    """:func:`_box_query3` for any shape (``pb, point, normal``: scratch 3-vectors)."""
    pb[0], pb[1], pb[2] = _frame3(R, p, q0, q1, q2)
    dist = project(kind, params, verts, enorm, pb, point, normal)
    return _to_world3(R, p, dist, point[0], point[1], point[2], normal[0], normal[1], normal[2])


@njit(cache=True)
def step3_ws(R, p, v, w, mass, Ib, Ib_inv, com_b, kind, params, verts, enorm, loc_p, loc_r, mu, tors,
             h, f_ext, tau_ext, restitution, margin, tol, max_iter, P_full, active_full, P_prev, active_prev,
             gap_full, u_full, n_full, bound_m, ws):  # fmt: skip
    """One 3D step on caller-owned buffers (the algorithm of the module docstring, no allocation).

    ``R, p, v, w`` (the state), ``P_full`` and ``active_full`` (the warm start: impulses per
    locator, and which were active) and ``P_prev``, ``active_prev`` (the same one step earlier)
    are updated in place, ``gap_full`` (start-of-step gaps),
    ``u_full`` (contact velocities) and ``n_full`` (normals) are written. After a non-finite
    result only ``gap_full`` is written and the state is kept. ``ws`` is :func:`workspace3`.
    Returns ``(error, iterations, status, failed local solves, penetration)``.
    """
    (gap, n_w, pt_w, active, J, MinvJt, W, q, P, u, idx, offsets, sizes, mus, diag, inv, has_inv,
     V, Ms, scratch, G, MinvGt, A, g, lam, six) = ws  # fmt: skip
    k = loc_p.shape[0]
    c = V[0]
    pb = V[1]
    point = V[2]
    normal = V[3]
    tmp = V[4]
    tmp2 = V[5]
    v_free = V[6]
    L_free = V[7]
    w_pred = V[8]
    w_new = V[9]
    v_new = V[10]
    c_new = V[11]
    Rn = Ms[0]
    Ex = Ms[1]
    Iinv = Ms[2]
    RI = Ms[3]
    R_new = Ms[4]
    _mv3_into(R, com_b, tmp)
    for a in range(3):
        c[a] = p[a] + tmp[a]
    for i in range(k):
        if kind == BOX:
            res = _box_query3(params, R, p, loc_p[i, 0], loc_p[i, 1], loc_p[i, 2])
        else:
            res = _query3(kind, params, verts, enorm, R, p, loc_p[i, 0], loc_p[i, 1], loc_p[i, 2], pb, point, normal)
        dist, n_w[i, 0], n_w[i, 1], n_w[i, 2], pt_w[i, 0], pt_w[i, 1], pt_w[i, 2] = res
        gap[i] = dist - loc_r[i]
        active[i] = gap[i] <= margin
    # free motion, angular-momentum form
    for a in range(3):
        v_free[a] = v[a] + h * f_ext[a] / mass
    _mtv3_into(R, w, tmp)
    _mv3_into(Ib, tmp, tmp2)
    _mv3_into(R, tmp2, L_free)
    for a in range(3):
        L_free[a] += h * tau_ext[a]
        w_pred[a] = w[a]
    spinning = (w[0] != 0.0 or w[1] != 0.0 or w[2] != 0.0) or (L_free[0] != 0.0 or L_free[1] != 0.0 or L_free[2] != 0.0)
    for a in range(3):
        for b in range(3):
            Rn[a, b] = R[a, b]
    for _ in range(50 if spinning else 0):
        _exp_so3_into(h * w_pred[0], h * w_pred[1], h * w_pred[2], Ex)
        _mm3_into(Ex, R, Rn)
        _mtv3_into(Rn, L_free, tmp)
        _mv3_into(Ib_inv, tmp, tmp2)
        _mv3_into(Rn, tmp2, w_new)
        dw = 0.0
        nn = 0.0
        for a in range(3):
            dw += (w_new[a] - w_pred[a]) ** 2
            nn += w_new[a] * w_new[a]
            w_pred[a] = w_new[a]
        if math.sqrt(dw) <= 1e-15 * (1.0 + math.sqrt(nn)):
            break
    if spinning:
        _exp_so3_into(h * w_pred[0], h * w_pred[1], h * w_pred[2], Ex)
        _mm3_into(Ex, R, Rn)
    _mm3_into(Rn, Ib_inv, RI)
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for t in range(3):
                acc += RI[i, t] * Rn[j, t]
            Iinv[i, j] = acc
    # contact rows
    nc = 0
    m = 0
    for i in range(k):
        if active[i]:
            idx[nc] = i
            offsets[nc] = m
            sizes[nc] = 4 if tors[i] > 0.0 else 3
            mus[nc] = mu[i]
            m += sizes[nc]
            nc += 1
    for jj in range(nc):
        i = idx[jj]
        row = offsets[jj]
        n0, n1, n2 = n_w[i, 0], n_w[i, 1], n_w[i, 2]
        r0, r1, r2 = pt_w[i, 0] - c[0], pt_w[i, 1] - c[1], pt_w[i, 2] - c[2]
        # tangents: the choice of tangents3 / fixplan.kinematics.tangent_basis
        if abs(n0) < 0.9:
            e0, e1, e2 = 1.0, 0.0, 0.0
        else:
            e0, e1, e2 = 0.0, 1.0, 0.0
        dot = e0 * n0 + e1 * n1 + e2 * n2
        s0, s1, s2 = e0 - dot * n0, e1 - dot * n1, e2 - dot * n2
        nrm = math.sqrt(s0**2 + s1**2 + s2**2)
        s0, s1, s2 = s0 / nrm, s1 / nrm, s2 / nrm
        for a in range(3):
            if a == 0:
                t0, t1, t2 = n0, n1, n2
            elif a == 1:
                t0, t1, t2 = s0, s1, s2
            else:
                t0, t1, t2 = n1 * s2 - n2 * s1, n2 * s0 - n0 * s2, n0 * s1 - n1 * s0
            J[row + a, 0] = t0
            J[row + a, 1] = t1
            J[row + a, 2] = t2
            J[row + a, 3] = r1 * t2 - r2 * t1
            J[row + a, 4] = r2 * t0 - r0 * t2
            J[row + a, 5] = r0 * t1 - r1 * t0
        if sizes[jj] == 4:
            J[row + 3, 0] = 0.0
            J[row + 3, 1] = 0.0
            J[row + 3, 2] = 0.0
            J[row + 3, 3] = tors[i] * n0
            J[row + 3, 4] = tors[i] * n1
            J[row + 3, 5] = tors[i] * n2
    inv_m = 1.0 / mass
    for r_ in range(m):
        for a in range(3):
            MinvJt[a, r_] = J[r_, a] * inv_m
            MinvJt[3 + a, r_] = Iinv[a, 0] * J[r_, 3] + Iinv[a, 1] * J[r_, 4] + Iinv[a, 2] * J[r_, 5]
    for r_ in range(m):
        for c_ in range(r_, m):
            acc = 0.0
            for a in range(6):
                acc += J[r_, a] * MinvJt[a, c_]
            W[r_, c_] = acc
            W[c_, r_] = acc
    for r_ in range(m):
        acc = 0.0
        for a in range(3):
            acc += J[r_, a] * v_free[a]
        for a in range(3):
            acc += J[r_, 3 + a] * w_pred[a]
        q[r_] = acc
    for jj in range(nc):
        i = idx[jj]
        o = offsets[jj]
        un_old = 0.0
        for a in range(3):
            un_old += J[o, a] * v[a]
        for a in range(3):
            un_old += J[o, 3 + a] * w[a]
        if restitution > 0.0 and un_old < 0.0 and gap[i] + h * un_old <= 0.0:
            q[o] += restitution * un_old  # an impact within this step: Newton's law, u_n⁺ ≥ −e u_n⁻
        elif gap[i] > 0.0:
            q[o] += gap[i] / h  # may close, may not overshoot: g + h u_n ≥ 0
        elif un_old < 0.0:
            q[o] += restitution * un_old
    for r_ in range(m):
        P[r_] = 0.0
    for jj in range(nc):
        i = idx[jj]
        o, d = offsets[jj], sizes[jj]
        if active_full[i] and active_prev[i] and u_full[i, 1] ** 2 + u_full[i, 2] ** 2 > _SLIP_WARM**2:
            # sliding in the last step and active in the two before: start from the linear
            # extrapolation of its impulse, kept in the cone (a sliding contact's impulse drifts
            # as its lever arm moves; a sticking one keeps its impulse, and extrapolating it
            # would move a statically indeterminate set along its null space)
            for a in range(d):
                P[o + a] = 2.0 * P_full[i, a] - P_prev[i, a]
            project_cone_into(P[o : o + d], mus[jj], P[o : o + d])
        elif active_full[i]:
            for a in range(d):
                P[o + a] = P_full[i, a]
    err, iters, converged, failures = nsgs_ws(
        W, q, mus, offsets, sizes, nc, m, P, tol, max_iter, diag, inv, has_inv, u, scratch
    )
    finite = math.isfinite(err)
    for a in range(6):
        acc = 0.0
        for r_ in range(m):
            acc += MinvJt[a, r_] * P[r_]
        six[a] = acc
    for a in range(3):
        v_new[a] = v_free[a] + six[a]
        w_new[a] = w_pred[a] + six[3 + a]
        finite = finite and math.isfinite(v_new[a]) and math.isfinite(w_new[a])
    for i in range(k):
        gap_full[i] = gap[i]
    if not finite:
        return err, iters, STATUS_NONFINITE, failures, 0.0
    status = STATUS_OK if converged else STATUS_NOT_CONVERGED
    for a in range(3):
        c_new[a] = c[a] + h * v_new[a]
    _exp_so3_into(h * w_new[0], h * w_new[1], h * w_new[2], Ex)
    _mm3_into(Ex, R, R_new)
    # position post-stabilisation; a body that does not move keeps g + h u_n ≥ 0 exactly
    pen = 0.0
    deepest = 0.0
    for i in range(k):
        if active[i] and -gap[i] > deepest:
            deepest = -gap[i]
    sv = 0.0
    sw = 0.0
    for a in range(3):
        sv += v_new[a] * v_new[a]
        sw += w_new[a] * w_new[a]
    moved = h * (math.sqrt(sv) + math.sqrt(sw) * bound_m)
    p_new = tmp2
    for _ in range(3 if (moved > 1e-12 or deepest > 1e-12) else 0):
        _mv3_into(R_new, com_b, tmp)
        for a in range(3):
            p_new[a] = c_new[a] - tmp[a]
        worst = 0.0
        for jj in range(nc):
            i = idx[jj]
            if kind == BOX:
                res = _box_query3(params, R_new, p_new, loc_p[i, 0], loc_p[i, 1], loc_p[i, 2])
            else:
                res = _query3(
                    kind, params, verts, enorm, R_new, p_new, loc_p[i, 0], loc_p[i, 1], loc_p[i, 2], pb, point, normal
                )
            dist, nn0, nn1, nn2, x0, x1, x2 = res
            g[jj] = dist - loc_r[i]
            r0 = x0 - c_new[0]
            r1 = x1 - c_new[1]
            r2 = x2 - c_new[2]
            G[jj, 0] = nn0
            G[jj, 1] = nn1
            G[jj, 2] = nn2
            G[jj, 3] = r1 * nn2 - r2 * nn1
            G[jj, 4] = r2 * nn0 - r0 * nn2
            G[jj, 5] = r0 * nn1 - r1 * nn0
            worst = min(worst, g[jj])
        pen = -worst
        if worst >= -1e-12:
            break
        for jj in range(nc):
            for a in range(3):
                MinvGt[a, jj] = G[jj, a] / mass
            for a in range(3):
                MinvGt[3 + a, jj] = Iinv[a, 0] * G[jj, 3] + Iinv[a, 1] * G[jj, 4] + Iinv[a, 2] * G[jj, 5]
        for i in range(nc):
            for j in range(nc):
                acc = 0.0
                for a in range(6):
                    acc += G[i, a] * MinvGt[a, j]
                A[i, j] = acc
            lam[i] = 0.0
        _pgs_lcp_n(A, g, lam, nc, 200)
        for a in range(6):
            acc = 0.0
            for jj in range(nc):
                acc += MinvGt[a, jj] * lam[jj]
            six[a] = acc
        for a in range(3):
            c_new[a] += six[a]
        _exp_so3_into(six[3], six[4], six[5], Ex)
        _mm3_into(Ex, R_new, Rn)
        for a in range(3):
            for b in range(3):
                R_new[a, b] = Rn[a, b]
    # commit
    _mv3_into(R_new, com_b, tmp)
    for a in range(3):
        p[a] = c_new[a] - tmp[a]
        v[a] = v_new[a]
        w[a] = w_new[a]
        for b in range(3):
            R[a, b] = R_new[a, b]
    for i in range(k):
        active_prev[i] = active_full[i]
        active_full[i] = active[i]
        for a in range(4):
            P_prev[i, a] = P_full[i, a]
            P_full[i, a] = 0.0
            u_full[i, a] = 0.0
        for a in range(3):
            n_full[i, a] = n_w[i, a]
    for jj in range(nc):
        i = idx[jj]
        for a in range(sizes[jj]):
            P_full[i, a] = P[offsets[jj] + a]
            u_full[i, a] = u[offsets[jj] + a]
    return err, iters, status, failures, max(pen, deepest, 0.0)


@njit(cache=True)
def _quat_into(R, out):
    """Unit quaternion ``(w, x, y, z)``, ``w ≥ 0`` (as :func:`fixplan.pose.quaternion_wxyz_from_matrix`)."""
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
def _schedule_index(times, t, k):
    """Index of the wrench in force at ``t``: the last ``times[k] ≤ t`` (0 before the first)."""
    while k + 1 < times.shape[0] and times[k + 1] <= t:
        k += 1
    return k


@njit(cache=True)
def run3(n_steps, record_every, first, t_start, R, p, v, w, mass, Ib, Ib_inv, com_b, kind, params, verts, enorm, loc_p,
         loc_r, mu, tors, h, gravity_f, times, wrenches, restitution, margin_m, bound, tol, max_iter,
         P, active, P_prev, active_prev, gap, u, n_w):  # fmt: skip
    """``n_steps`` of :func:`step3_ws` under a wrench schedule, compiled end to end.

    ``wrenches[k]`` (force, moment about the body origin; world axes) acts from ``times[k]``
    to ``times[k + 1]`` (a constant wrench: one row); ``gravity_f`` = m g acts at the centre of
    mass. The wrench is evaluated at each step's start time ``t`` (accumulated ``t += h``, as
    :meth:`fixplan.simulator.Simulator.step` does) and its moment re-expressed about the moving
    centre of mass, as :meth:`Simulator.step` does. The state and warm start (``R, p, v, w, P,
    active``) and the last step's ``gap, u, n_w`` are updated in place; returns the samples
    taken every ``record_every`` steps and at the last, preceded by the initial state when
    ``first`` (time, position, quaternion, twist, normal forces, gaps; residual and sweeps per
    recorded step) and ``(t, steps done, status, max penetration,
    worst residual, last residual, last sweeps)``.
    """
    k = loc_p.shape[0]
    ws = workspace3(k)
    n_rec = n_steps // record_every + 2
    rec_t = np.zeros(n_rec)
    rec_p = np.zeros((n_rec, 3))
    rec_q = np.zeros((n_rec, 4))
    rec_nu = np.zeros((n_rec, 6))
    rec_fn = np.zeros((n_rec, k))
    rec_gap = np.zeros((n_rec, k))
    rec_err = np.zeros(n_rec)
    rec_it = np.zeros(n_rec, dtype=np.int64)
    f_ext = np.zeros(3)
    tau = np.zeros(3)
    off = np.zeros(3)
    r = 0
    re = 0
    if first:
        rec_t[0] = t_start
        rec_p[0] = p
        _quat_into(R, rec_q[0])
        rec_nu[0, 0:3] = v
        rec_nu[0, 3:6] = w
        for i in range(k):
            rec_fn[0, i] = P[i, 0] / h if active[i] else 0.0
            rec_gap[0, i] = gap[i]
        r = 1
    t = t_start
    max_pen = 0.0
    status = STATUS_OK
    worst_err = 0.0
    last_err, last_it = 0.0, 0
    done = 0
    ks = 0
    for s in range(1, n_steps + 1):
        ks = _schedule_index(times, t, ks)
        _mv3_into(R, com_b, off)
        for a in range(3):
            off[a] = -off[a]  # body origin relative to the centre of mass
        F0, F1, F2 = wrenches[ks, 0], wrenches[ks, 1], wrenches[ks, 2]
        f_ext[0] = gravity_f[0] + F0
        f_ext[1] = gravity_f[1] + F1
        f_ext[2] = gravity_f[2] + F2
        tau[0] = wrenches[ks, 3] + (off[1] * F2 - off[2] * F1)
        tau[1] = wrenches[ks, 4] + (off[2] * F0 - off[0] * F2)
        tau[2] = wrenches[ks, 5] + (off[0] * F1 - off[1] * F0)
        speed = (
            math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            + math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]) * bound
        )
        margin = margin_m + 2.0 * h * speed
        err, iters, st, failures, pen = step3_ws(
            R, p, v, w, mass, Ib, Ib_inv, com_b, kind, params, verts, enorm, loc_p, loc_r, mu, tors,
            h, f_ext, tau, restitution, margin, tol, max_iter, P, active, P_prev, active_prev, gap, u, n_w, bound, ws)  # fmt: skip
        if st == STATUS_NONFINITE:
            status = st
            break
        if st == STATUS_NOT_CONVERGED:
            status = st
        t += h
        done = s
        max_pen = max(max_pen, pen)
        worst_err = max(worst_err, err)
        last_err, last_it = err, iters
        if (s % record_every == 0 or s == n_steps) and r < n_rec:
            rec_t[r] = t
            for a in range(3):  # element by element: no array views in the hot loop
                rec_p[r, a] = p[a]
                rec_nu[r, a] = v[a]
                rec_nu[r, 3 + a] = w[a]
            _quat_into(R, rec_q[r])
            for i in range(k):
                rec_fn[r, i] = P[i, 0] / h if active[i] else 0.0
                rec_gap[r, i] = gap[i]
            rec_err[re] = err
            rec_it[re] = iters
            re += 1
            r += 1
    return (rec_t[:r], rec_p[:r], rec_q[:r], rec_nu[:r], rec_fn[:r], rec_gap[:r], rec_err[:re], rec_it[:re],
            t, done, status, max_pen, worst_err, last_err, last_it)  # fmt: skip


@njit(cache=True)
def step3_into(R, p, v, w, mass, Ib, Ib_inv, com_b, kind, params, verts, enorm, loc_p, loc_r, mu, tors, h, f_ext,
               tau_ext, restitution, margin, tol, max_iter, P, active, P_prev, active_prev, gap, u, n_w, bound):  # fmt: skip
    """One :func:`step3_ws` for Python callers (:meth:`Simulator.step`), with its own workspace.

    Same in-place contract and returns as :func:`step3_ws`.
    """
    ws = workspace3(loc_p.shape[0])
    return step3_ws(R, p, v, w, mass, Ib, Ib_inv, com_b, kind, params, verts, enorm, loc_p, loc_r, mu, tors, h,
                    f_ext, tau_ext, restitution, margin, tol, max_iter, P, active, P_prev, active_prev, gap, u, n_w, bound, ws)  # fmt: skip


@njit(cache=True)
def run2(n_steps, record_every, first, t_start, theta, p, v, w, mass, Izz, com_b, kind, params, verts, enorm, loc_p, loc_r,
         mu, h, gravity_f, times, wrenches, restitution, margin_m, bound, tol, max_iter, P, active, gap_in):  # fmt: skip
    """``n_steps`` of :func:`step2` under a wrench schedule ``(Fx, Fy, Mz)`` about the body origin.

    The planar counterpart of :func:`run3` (same schedule, margin and recording rules). Returns
    the samples, then ``(θ, p, v, ω, P, active, gap, u, n_w, t, steps done, status, max
    penetration, worst residual, last residual, last sweeps)``.
    """
    k = loc_p.shape[0]
    n_rec = n_steps // record_every + 2
    rec_t = np.zeros(n_rec)
    rec_p = np.zeros((n_rec, 2))
    rec_th = np.zeros((n_rec, 1))
    rec_nu = np.zeros((n_rec, 3))
    rec_fn = np.zeros((n_rec, k))
    rec_gap = np.zeros((n_rec, k))
    rec_err = np.zeros(n_rec)
    rec_it = np.zeros(n_rec, dtype=np.int64)
    f_ext = np.zeros(2)
    gap = np.zeros(k)
    u = np.zeros((k, 4))
    n_w = np.zeros((k, 2))
    r = 0
    re = 0
    if first:
        rec_t[0] = t_start
        rec_p[0] = p
        rec_th[0, 0] = theta
        rec_nu[0, 0:2] = v
        rec_nu[0, 2] = w
        for i in range(k):
            rec_fn[0, i] = P[i, 0] / h if active[i] else 0.0
            rec_gap[0, i] = gap_in[i]
        r = 1
    t = t_start
    max_pen = 0.0
    status = STATUS_OK
    worst_err = 0.0
    last_err, last_it = 0.0, 0
    done = 0
    ks = 0
    for s in range(1, n_steps + 1):
        ks = _schedule_index(times, t, ks)
        cs, sn = math.cos(theta), math.sin(theta)
        o0 = -(cs * com_b[0] - sn * com_b[1])
        o1 = -(sn * com_b[0] + cs * com_b[1])
        F0, F1 = wrenches[ks, 0], wrenches[ks, 1]
        f_ext[0] = gravity_f[0] + F0
        f_ext[1] = gravity_f[1] + F1
        tau = wrenches[ks, 2] + o0 * F1 - o1 * F0
        speed = math.sqrt(v[0] * v[0] + v[1] * v[1]) + abs(w) * bound
        margin = margin_m + 2.0 * h * speed
        out = step2(theta, p, v, w, mass, Izz, com_b, kind, params, verts, enorm, loc_p, loc_r, mu,
                    h, f_ext, tau, restitution, margin, tol, max_iter, P, active, bound)  # fmt: skip
        th2, p2, v2, w2, P2, act2, gap, u2, nw2, _pt, err, iters, st, failures, pen = out
        if st == STATUS_NONFINITE:
            status = st
            break
        if st == STATUS_NOT_CONVERGED:
            status = st
        theta, p, v, w, P, active, u, n_w = th2, p2, v2, w2, P2, act2, u2, nw2
        t += h
        done = s
        max_pen = max(max_pen, pen)
        worst_err = max(worst_err, err)
        last_err, last_it = err, iters
        if (s % record_every == 0 or s == n_steps) and r < n_rec:
            rec_t[r] = t
            rec_p[r] = p
            rec_th[r, 0] = theta
            rec_nu[r, 0:2] = v
            rec_nu[r, 2] = w
            for i in range(k):
                rec_fn[r, i] = P[i, 0] / h if active[i] else 0.0
                rec_gap[r, i] = gap[i]
            rec_err[re] = err
            rec_it[re] = iters
            re += 1
            r += 1
    return (rec_t[:r], rec_p[:r], rec_th[:r], rec_nu[:r], rec_fn[:r], rec_gap[:r], rec_err[:re], rec_it[:re],
            theta, p, v, w, P, active, gap, u, n_w, t, done, status, max_pen, worst_err, last_err, last_it)  # fmt: skip
