"""The compiled Moreau–Jean time step (docs/math.md [3]–[5], contact laws [8]–[10], NSGS).

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
   started from its current impulse (:func:`slide3_newton`), then the general solver. Where the
   sweeps reach their cap, a nonsmooth Newton polish of the whole step's problem
   (:func:`fixplan.engine.polish.newton_polish`) continues from the sweep's iterate.
5. **Update**: ``ν⁺ = ν_free + M⁻¹ Jᵀ P``; ``c⁺ = c + h v⁺``; ``R⁺ = exp(h ω̂⁺) R``.
6. **Position post-stabilisation** (Cline & Pai): if an active contact penetrates at the new
   pose, the pose alone is moved by the ``M``-smallest displacement ``Δ = M⁻¹ Gᵀ λ`` with
   ``0 ≤ λ ⊥ g + G Δ ≥ 0`` (a small LCP solved by projected Gauss–Seidel), repeated up to three
   times for the nonlinearity. Velocities are not touched, so no kinetic energy is injected
   (Baumgarte-type velocity terms would); the correction only ever pushes out of contact.

Everything here is ``numba.njit(cache=True)``. The pieces live by concept: detection in
:mod:`.detect`, the small dense products in :mod:`.linalg`, rotations, tangents and moment
shifts in :mod:`fixplan._spatial_kernels`, the sweep in
:func:`fixplan.engine.nsgs.nsgs_dense`, its stopping residual in :mod:`.residual`, the exact
one-contact solvers and their closed-form shortcuts in :mod:`.local`. This module is only the
Moreau–Jean step (planar :func:`step2`, spatial :func:`step3_ws`) and the compiled multi-step
loops. ``tests/engine/reference_step.py`` is the plain NumPy version of the same step.

Speed. The 3D step :func:`step3_ws` works in the buffers of :func:`workspace3`,
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

from fixplan._spatial_kernels import exp_so3_into, quat_into, shifted_moment2, shifted_moment3, tangents3
from fixplan.engine.detect import box_query3, obstacle_query2, obstacle_query3, project, query3
from fixplan.engine.encode import BOX
from fixplan.engine.linalg import mm, mm3_into, mtv, mtv3_into, mv, mv3_into
from fixplan.engine.local import WORKSPACE_SIZE, project_cone_into
from fixplan.engine.nsgs import nsgs_dense
from fixplan.engine.polish import newton_polish
from fixplan.engine.status import STATUS_CONVERGED, STATUS_MAX_ITER, STATUS_NONFINITE


@njit(cache=True)
def _normal_bias(q_n, un_old, gap, h, restitution):
    """The normal row's free velocity ``q_n`` with restitution or the open-gap term (step 3 above)."""
    if restitution > 0.0 and un_old < 0.0 and gap + h * un_old <= 0.0:
        return q_n + restitution * un_old  # an impact within this step: Newton's law, u_n⁺ ≥ −e u_n⁻
    if gap > 0.0:
        return q_n + gap / h  # may close, may not overshoot: g + h u_n ≥ 0
    if un_old < 0.0:
        return q_n + restitution * un_old
    return q_n


@njit(cache=True)
def _pgs_lcp(A, b, x, n, iterations):
    """Projected Gauss–Seidel for ``0 ≤ x ⊥ A x + b ≥ 0`` on the leading ``n`` rows (``A`` symmetric PSD, small)."""
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
def solve_staged(W, q, mus, offsets, sizes, nc, m, P, tol, max_iter, polish_after, polish_steps, diag, inv, has_inv, u,
                 scratch):  # fmt: skip
    """The step's contact problem: sweeps, then Newton where they stall, then the rest of the sweeps.

    :func:`~fixplan.engine.nsgs.nsgs_dense` from the warm start ``P`` for at most
    ``polish_after`` sweeps (``≤ 0``: ``max_iter``); if that has not reached ``tol``, the
    nonsmooth Newton polish of :mod:`fixplan.engine.polish` from the sweeps' iterate (kept only
    where it lowers the residual). If the polish does not converge either, the sweeps go on
    from the best iterate up to ``max_iter`` in all, and a last polish follows. Gauss–Seidel
    converges linearly, slowly on a statically indeterminate seat (a box on six point
    locators: 80 sweeps on average, 1500 at worst, for 10⁻⁶); Newton converges quadratically
    near the solution, so a stalled sweep hands over early. Returns
    ``(error, sweeps + Newton steps, converged, failed local solves in the last sweep)``.
    """
    first = max_iter if polish_after <= 0 else min(max_iter, polish_after)
    err, iters, converged, failures = nsgs_dense(
        W, q, mus, offsets, sizes, nc, m, P, tol, first, diag, inv, has_inv, u, scratch
    )
    if converged or not math.isfinite(err):
        return err, iters, converged, failures
    # Gauss–Seidel stalled (two contacts sliding on their cone boundaries in a corner, a
    # hyperstatic seat): nonsmooth Newton from its iterate, kept only where it lowers the residual
    err, extra, converged = newton_polish(W, q, mus, offsets, sizes, nc, m, P, tol, polish_steps)
    iters += extra
    if converged or first >= max_iter or not math.isfinite(err):
        return err, iters, converged, failures
    err, more, converged, failures = nsgs_dense(
        W, q, mus, offsets, sizes, nc, m, P, tol, max_iter - first, diag, inv, has_inv, u, scratch
    )
    iters += more
    if not converged and math.isfinite(err):
        err, extra, converged = newton_polish(W, q, mus, offsets, sizes, nc, m, P, tol, polish_steps)
        iters += extra
    return err, iters, converged, failures


@njit(cache=True)
def step2(theta, p, v, w, mass, Izz, com_b, kind, params, verts, enorm, loc_p, loc_r, mu, obs, slots,
          h, f_ext, tau_ext, restitution, margin, tol, max_iter, polish_after, polish_steps, P_warm, warm_active, bound_m):  # fmt: skip
    """One planar step, ``ν = (vx, vy, ω)``: :func:`step3_ws` with 2-row contacts (allocating its arrays).

    Contacts: the locators, then the collision points ``slots`` against ``obs`` (``mu`` covers both).
    """
    k = mu.shape[0]
    k_loc = loc_p.shape[0]
    cs, sn = math.cos(theta), math.sin(theta)
    R = np.array([[cs, -sn], [sn, cs]])
    c = p + mv(R, com_b)
    gap = np.empty(k)
    n_w = np.zeros((k, 2))
    pt_w = np.zeros((k, 2))
    active = np.zeros(k, dtype=np.bool_)
    point = np.empty(2)
    normal = np.empty(2)
    for i in range(k_loc):
        pb = mtv(R, loc_p[i] - p)
        gap[i] = project(kind, params, verts, enorm, pb, point, normal) - loc_r[i]
        n_w[i] = -mv(R, normal)
        pt_w[i] = p + mv(R, point)
        active[i] = gap[i] <= margin
    for i in range(k_loc, k):  # collision points against obstacles (none: no iteration)
        gap[i], n_w[i, 0], n_w[i, 1], pt_w[i, 0], pt_w[i, 1] = obstacle_query2(obs, slots, i - k_loc, R, p)
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
        un_old = J[o, 0] * nu_old[0] + J[o, 1] * nu_old[1] + J[o, 2] * nu_old[2]  # no BLAS (see linalg)
        q[o] = _normal_bias(q[o], un_old, gap[i], h, restitution)
    P = np.zeros(m)
    for jj in range(nc):
        i = idx[jj]
        if warm_active[i]:
            P[2 * jj] = P_warm[i, 0]
            P[2 * jj + 1] = P_warm[i, 1]
    diag = np.zeros((nc, 4, 4))
    inv = np.zeros((nc, 4, 4))
    has_inv = np.zeros(nc, dtype=np.bool_)
    scratch = np.empty(WORKSPACE_SIZE + 16)
    err, iters, converged, failures = solve_staged(
        W, q, mus, offsets, sizes, nc, m, P, tol, max_iter, polish_after, polish_steps, diag, inv, has_inv, np.empty(m),
        scratch,
    )  # fmt: skip
    dnu = mv(MinvJt, P)
    nu = nu_free + dnu
    u = mv(W, P) + q
    status = STATUS_CONVERGED if converged else STATUS_MAX_ITER
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
            if i >= k_loc:
                g[jj], nn0, nn1, x0, x1 = obstacle_query2(obs, slots, i - k_loc, Rn, p_new)
                nn = np.array([nn0, nn1])
                r = np.array([x0 - c_new[0], x1 - c_new[1]])
            else:
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
        _pgs_lcp(A, g, lam, nc, 200)
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
_SLIP_WARM = 1e-7  # [m/s] slip above which a contact's warm start is extrapolated (the 'sliding' of contacts())


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
def step3_ws(R, p, v, w, mass, Ib, Ib_inv, com_b, kind, params, verts, enorm, loc_p, loc_r, mu, tors, obs, slots,
             h, f_ext, tau_ext, restitution, margin, tol, max_iter, polish_after, polish_steps, P_full, active_full, P_prev, active_prev,
             gap_full, u_full, n_full, bound_m, ws):  # fmt: skip
    """One 3D step on caller-owned buffers (the algorithm of the module docstring, no allocation).

    ``R, p, v, w`` (the state), ``P_full`` and ``active_full`` (the warm start: impulses per
    locator, and which were active) and ``P_prev``, ``active_prev`` (the same one step earlier)
    are updated in place, ``gap_full`` (start-of-step gaps),
    ``u_full`` (contact velocities) and ``n_full`` (normals) are written. After a non-finite
    result only ``gap_full`` is written and the state is kept. ``ws`` is :func:`workspace3`.
    Contacts ``0 … k_loc − 1`` are the locators (``loc_p``), the rest (``mu`` and ``tors`` are
    that much longer) the collision points ``slots`` against the collision-only bodies ``obs``
    (:func:`fixplan.engine.detect.obstacle_query3`): the same contact law, another detection.
    Returns ``(error, iterations, status, failed local solves, penetration)``.
    """
    (gap, n_w, pt_w, active, J, MinvJt, W, q, P, u, idx, offsets, sizes, mus, diag, inv, has_inv,
     V, Ms, scratch, G, MinvGt, A, g, lam, six) = ws  # fmt: skip
    k = mu.shape[0]
    k_loc = loc_p.shape[0]
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
    mv3_into(R, com_b, tmp)
    for a in range(3):
        c[a] = p[a] + tmp[a]
    for i in range(k_loc):
        if kind == BOX:
            res = box_query3(params, R, p, loc_p[i, 0], loc_p[i, 1], loc_p[i, 2])
        else:
            res = query3(kind, params, verts, enorm, R, p, loc_p[i, 0], loc_p[i, 1], loc_p[i, 2], pb, point, normal)
        dist, n_w[i, 0], n_w[i, 1], n_w[i, 2], pt_w[i, 0], pt_w[i, 1], pt_w[i, 2] = res
        gap[i] = dist - loc_r[i]
        active[i] = gap[i] <= margin
    for i in range(k_loc, k):  # collision points against obstacles (none: no iteration)
        res = obstacle_query3(obs, slots, i - k_loc, R, p)
        gap[i], n_w[i, 0], n_w[i, 1], n_w[i, 2], pt_w[i, 0], pt_w[i, 1], pt_w[i, 2] = res
        active[i] = gap[i] <= margin
    # free motion, angular-momentum form
    for a in range(3):
        v_free[a] = v[a] + h * f_ext[a] / mass
    mtv3_into(R, w, tmp)
    mv3_into(Ib, tmp, tmp2)
    mv3_into(R, tmp2, L_free)
    for a in range(3):
        L_free[a] += h * tau_ext[a]
        w_pred[a] = w[a]
    spinning = (w[0] != 0.0 or w[1] != 0.0 or w[2] != 0.0) or (L_free[0] != 0.0 or L_free[1] != 0.0 or L_free[2] != 0.0)
    for a in range(3):
        for b in range(3):
            Rn[a, b] = R[a, b]
    for _ in range(50 if spinning else 0):
        exp_so3_into(h * w_pred[0], h * w_pred[1], h * w_pred[2], Ex)
        mm3_into(Ex, R, Rn)
        mtv3_into(Rn, L_free, tmp)
        mv3_into(Ib_inv, tmp, tmp2)
        mv3_into(Rn, tmp2, w_new)
        dw = 0.0
        nn = 0.0
        for a in range(3):
            dw += (w_new[a] - w_pred[a]) ** 2
            nn += w_new[a] * w_new[a]
            w_pred[a] = w_new[a]
        if math.sqrt(dw) <= 1e-15 * (1.0 + math.sqrt(nn)):
            break
    if spinning:
        exp_so3_into(h * w_pred[0], h * w_pred[1], h * w_pred[2], Ex)
        mm3_into(Ex, R, Rn)
    mm3_into(Rn, Ib_inv, RI)
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
        s0, s1, s2, b0, b1, b2 = tangents3(n0, n1, n2)  # fixplan.spatial.tangent_basis
        for a in range(3):
            if a == 0:
                t0, t1, t2 = n0, n1, n2
            elif a == 1:
                t0, t1, t2 = s0, s1, s2
            else:
                t0, t1, t2 = b0, b1, b2
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
        q[o] = _normal_bias(q[o], un_old, gap[i], h, restitution)
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
    err, iters, converged, failures = solve_staged(
        W, q, mus, offsets, sizes, nc, m, P, tol, max_iter, polish_after, polish_steps, diag, inv, has_inv, u, scratch
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
    status = STATUS_CONVERGED if converged else STATUS_MAX_ITER
    for a in range(3):
        c_new[a] = c[a] + h * v_new[a]
    exp_so3_into(h * w_new[0], h * w_new[1], h * w_new[2], Ex)
    mm3_into(Ex, R, R_new)
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
        mv3_into(R_new, com_b, tmp)
        for a in range(3):
            p_new[a] = c_new[a] - tmp[a]
        worst = 0.0
        for jj in range(nc):
            i = idx[jj]
            if i >= k_loc:
                res = obstacle_query3(obs, slots, i - k_loc, R_new, p_new)
                rho = 0.0
            elif kind == BOX:
                res = box_query3(params, R_new, p_new, loc_p[i, 0], loc_p[i, 1], loc_p[i, 2])
                rho = loc_r[i]
            else:
                res = query3(
                    kind, params, verts, enorm, R_new, p_new, loc_p[i, 0], loc_p[i, 1], loc_p[i, 2], pb, point, normal
                )
                rho = loc_r[i]
            dist, nn0, nn1, nn2, x0, x1, x2 = res
            g[jj] = dist - rho
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
        _pgs_lcp(A, g, lam, nc, 200)
        for a in range(6):
            acc = 0.0
            for jj in range(nc):
                acc += MinvGt[a, jj] * lam[jj]
            six[a] = acc
        for a in range(3):
            c_new[a] += six[a]
        exp_so3_into(six[3], six[4], six[5], Ex)
        mm3_into(Ex, R_new, Rn)
        for a in range(3):
            for b in range(3):
                R_new[a, b] = Rn[a, b]
    # commit
    mv3_into(R_new, com_b, tmp)
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
def _schedule_index(times, t, k):
    """Index of the wrench in force at ``t``: the last ``times[k] ≤ t`` (0 before the first)."""
    while k + 1 < times.shape[0] and times[k + 1] <= t:
        k += 1
    return k


@njit(cache=True)
def run3(n_steps, record_every, first, t_start, R, p, v, w, mass, Ib, Ib_inv, com_b, kind, params, verts, enorm, loc_p,
         loc_r, mu, tors, obs, slots, h, gravity_f, times, wrenches, restitution, margin_m, bound, tol, max_iter, polish_after, polish_steps,
         P, active, P_prev, active_prev, gap, u, n_w):  # fmt: skip
    """``n_steps`` of :func:`step3_ws` under a wrench schedule, compiled end to end.

    ``wrenches[k]`` (force, moment about the body origin; world axes) acts from ``times[k]``
    to ``times[k + 1]`` (a constant wrench: one row); ``gravity_f`` = m g acts at the centre of
    mass. The wrench is evaluated at each step's start time ``t`` (accumulated ``t += h``, as
    :meth:`fixplan.engine.simulator.Simulator.step` does) and its moment re-expressed about the moving
    centre of mass, as :meth:`Simulator.step` does. The state and warm start (``R, p, v, w, P,
    active``) and the last step's ``gap, u, n_w`` are updated in place; returns the samples
    taken every ``record_every`` steps and at the last, preceded by the initial state when
    ``first`` (time, position, quaternion, twist, normal forces, gaps; residual and sweeps per
    recorded step) and ``(t, steps done, status, max penetration,
    worst residual, last residual, last sweeps)``. Contacts as :func:`step3_ws` (locators, then
    collision points against obstacles); the samples hold every one.
    """
    k = mu.shape[0]
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
    r_com = np.zeros(3)
    r = 0
    re = 0
    if first:
        rec_t[0] = t_start
        rec_p[0] = p
        quat_into(R, rec_q[0])
        rec_nu[0, 0:3] = v
        rec_nu[0, 3:6] = w
        for i in range(k):
            rec_fn[0, i] = P[i, 0] / h if active[i] else 0.0
            rec_gap[0, i] = gap[i]
        r = 1
    t = t_start
    max_pen = 0.0
    status = np.int64(STATUS_CONVERGED)  # not a literal: st (int64) is assigned to it below
    worst_err = 0.0
    last_err, last_it = 0.0, 0
    done = 0
    ks = 0
    for s in range(1, n_steps + 1):
        ks = _schedule_index(times, t, ks)
        mv3_into(R, com_b, r_com)  # lever from the body origin to the centre of mass
        F0, F1, F2 = wrenches[ks, 0], wrenches[ks, 1], wrenches[ks, 2]
        f_ext[0] = gravity_f[0] + F0
        f_ext[1] = gravity_f[1] + F1
        f_ext[2] = gravity_f[2] + F2
        # the schedule's wrench is about the body origin; the step wants it about the centre of mass
        tau[0], tau[1], tau[2] = shifted_moment3(
            F0, F1, F2, wrenches[ks, 3], wrenches[ks, 4], wrenches[ks, 5], r_com[0], r_com[1], r_com[2]
        )
        speed = (
            math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            + math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]) * bound
        )
        margin = margin_m + 2.0 * h * speed
        err, iters, st, failures, pen = step3_ws(
            R, p, v, w, mass, Ib, Ib_inv, com_b, kind, params, verts, enorm, loc_p, loc_r, mu, tors, obs, slots,
            h, f_ext, tau, restitution, margin, tol, max_iter, polish_after, polish_steps, P, active, P_prev, active_prev, gap, u, n_w, bound, ws)  # fmt: skip
        if st == STATUS_NONFINITE:
            status = st
            break
        if st == STATUS_MAX_ITER:
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
            quat_into(R, rec_q[r])
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
def step3_into(R, p, v, w, mass, Ib, Ib_inv, com_b, kind, params, verts, enorm, loc_p, loc_r, mu, tors, obs, slots, h, f_ext,
               tau_ext, restitution, margin, tol, max_iter, polish_after, polish_steps, P, active, P_prev, active_prev, gap, u, n_w, bound):  # fmt: skip
    """One :func:`step3_ws` for Python callers (:meth:`Simulator.step`), with its own workspace.

    Same in-place contract and returns as :func:`step3_ws`.
    """
    ws = workspace3(mu.shape[0])
    return step3_ws(R, p, v, w, mass, Ib, Ib_inv, com_b, kind, params, verts, enorm, loc_p, loc_r, mu, tors, obs, slots, h,
                    f_ext, tau_ext, restitution, margin, tol, max_iter, polish_after, polish_steps, P, active, P_prev, active_prev, gap, u, n_w, bound, ws)  # fmt: skip


@njit(cache=True)
def run2(n_steps, record_every, first, t_start, theta, p, v, w, mass, Izz, com_b, kind, params, verts, enorm, loc_p, loc_r,
         mu, obs, slots, h, gravity_f, times, wrenches, restitution, margin_m, bound, tol, max_iter, polish_after, polish_steps, P, active, gap_in):  # fmt: skip
    """``n_steps`` of :func:`step2` under a wrench schedule ``(Fx, Fy, Mz)`` about the body origin.

    The planar counterpart of :func:`run3` (same schedule, margin and recording rules). Returns
    the samples, then ``(θ, p, v, ω, P, active, gap, u, n_w, t, steps done, status, max
    penetration, worst residual, last residual, last sweeps)``.
    """
    k = mu.shape[0]
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
    status = np.int64(STATUS_CONVERGED)  # not a literal: st (int64) is assigned to it below
    worst_err = 0.0
    last_err, last_it = 0.0, 0
    done = 0
    ks = 0
    for s in range(1, n_steps + 1):
        ks = _schedule_index(times, t, ks)
        cs, sn = math.cos(theta), math.sin(theta)
        r0 = cs * com_b[0] - sn * com_b[1]  # lever from the body origin to the centre of mass
        r1 = sn * com_b[0] + cs * com_b[1]
        F0, F1 = wrenches[ks, 0], wrenches[ks, 1]
        f_ext[0] = gravity_f[0] + F0
        f_ext[1] = gravity_f[1] + F1
        tau = shifted_moment2(F0, F1, wrenches[ks, 2], r0, r1)  # about the centre of mass
        speed = math.sqrt(v[0] * v[0] + v[1] * v[1]) + abs(w) * bound
        margin = margin_m + 2.0 * h * speed
        out = step2(theta, p, v, w, mass, Izz, com_b, kind, params, verts, enorm, loc_p, loc_r, mu, obs, slots,
                    h, f_ext, tau, restitution, margin, tol, max_iter, polish_after, polish_steps, P, active, bound)  # fmt: skip
        th2, p2, v2, w2, P2, act2, gap, u2, nw2, _pt, err, iters, st, failures, pen = out
        if st == STATUS_NONFINITE:
            status = st
            break
        if st == STATUS_MAX_ITER:
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
