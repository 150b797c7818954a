"""Plain NumPy reference of the compiled step (:mod:`fixplan.engine.step`): a test oracle.

Written from the high-level pieces — the shape classes, :class:`fixplan.kinematics.Contact`
Jacobians, NumPy linear algebra and a Python Gauss–Seidel loop — rather than from the kernels,
so that agreement between the two checks detection, Jacobian assembly, the Delassus operator,
the sweep and the integration. Only the one-contact solvers are shared (they are tested on
their own). Same algorithm, same order of operations; slow.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from fixplan.engine import problem as contact_problem
from fixplan.engine.local import solve_cone, solve_coulomb_2d
from fixplan.engine.problem import build_problem
from fixplan.geometry.collision import BOX, PLANE, collision_points, obstacle_gap
from fixplan.kinematics import Contact
from fixplan.locating import locator_contact
from fixplan.model import Fixture
from fixplan.settings import DEFAULT
from fixplan.spatial import Pose, exp_so3, rot2


def fclib_error(W, q, mu, offsets, sizes, P):
    """The FCLib residual of the dense problem (rows already scaled: a spin row is a standard cone row)."""
    if len(sizes) == 0:
        return 0.0
    return contact_problem.fclib_error(build_problem(W, q, mu, np.asarray(sizes), torsion_radius=1.0), P)


def obstacle_contacts(fixture: Fixture, pose: Pose) -> list[SimpleNamespace]:
    """The part's collision points against each [[obstacle]] (in the engine's order: per obstacle, per point)."""
    pts, radii = collision_points(fixture.workpiece.shape, DEFAULT.engine.rim_points)
    out = []
    for ob in fixture.obstacles:
        kind = PLANE if ob.is_plane else BOX
        for j, (b, rho) in enumerate(zip(pts, radii, strict=True)):
            gap, n, x = obstacle_gap(
                kind, ob.R_world_obstacle, ob.o_world, ob.half_m, pose.point_world_from_body(b), rho
            )
            out.append(SimpleNamespace(name=f"{ob.name}#{j}", point_world=x, normal_world=n, friction=ob.friction,
                                       torsion_m=0.0, gap_m=gap))  # fmt: skip
    return out


def reference_step(fixture: Fixture, pose: Pose, twist: np.ndarray, P_warm: np.ndarray, warm_active: np.ndarray,
                   f_ext: np.ndarray, tau_ext, h: float, restitution: float, margin: float, tol: float,
                   max_iter: int):  # fmt: skip
    """One step; returns (pose, twist, P_full (k×4), active, error, iterations).

    Contacts: the locators, then the part's collision points against each obstacle (as the engine).
    """
    wp = fixture.workpiece
    d = fixture.dimension
    R, p = pose.R_world_body, pose.p_world
    c = p + R @ wp.com_body
    contacts = [locator_contact(wp, pose, loc) for loc in fixture.locators] + obstacle_contacts(fixture, pose)
    active = np.array([ct.gap_m <= margin for ct in contacts])
    v, w = twist[:d], twist[d:]
    m = wp.mass_kg
    v_free = v + h * f_ext / m
    if d == 3:
        Ib, Ib_inv = wp.inertia_body, np.linalg.inv(wp.inertia_body)
        L_free = R @ Ib @ R.T @ w + h * tau_ext
        w_pred = w.copy()
        for _ in range(50):
            Rn = exp_so3(h * w_pred) @ R
            w_new = Rn @ Ib_inv @ Rn.T @ L_free
            done = np.linalg.norm(w_new - w_pred) <= 1e-15 * (1 + np.linalg.norm(w_new))
            w_pred = w_new
            if done:
                break
        Rn = exp_so3(h * w_pred) @ R
        M_inv = np.zeros((6, 6))
        M_inv[:3, :3] = np.eye(3) / m
        M_inv[3:, 3:] = Rn @ Ib_inv @ Rn.T
    else:
        Izz = float(wp.inertia_body[0, 0])
        w_pred = w + h * np.atleast_1d(tau_ext) / Izz
        M_inv = np.diag([1 / m, 1 / m, 1 / Izz])
    rows, sizes, mus, idx = [], [], [], []
    for i, ct in enumerate(contacts):
        if not active[i]:
            continue
        Ji = Contact(ct.name, ct.point_world, ct.normal_world, ct.friction, ct.torsion_m, ct.gap_m).jacobian(c)
        if Ji.shape[0] == 4:
            Ji[3] *= ct.torsion_m  # scaled spin row: the ellipsoid becomes a standard cone
        rows.append(Ji)
        sizes.append(Ji.shape[0])
        mus.append(ct.friction)
        idx.append(i)
    nu_free = np.concatenate([v_free, w_pred])
    J = np.vstack(rows) if rows else np.zeros((0, len(nu_free)))
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(int) if sizes else np.zeros(0, int)
    W = J @ M_inv @ J.T
    q = J @ nu_free
    for o, i in zip(offsets, idx, strict=True):
        g = contacts[i].gap_m
        un = J[o] @ twist
        if restitution > 0 and un < 0 and g + h * un <= 0:
            q[o] += restitution * un
        elif g > 0:
            q[o] += g / h
        elif un < 0:
            q[o] += restitution * un
    P = np.zeros(J.shape[0])
    for o, s, i in zip(offsets, sizes, idx, strict=True):
        if warm_active[i]:
            P[o : o + s] = P_warm[i, :s]
    err, it = np.inf, 0
    for it in range(1, max_iter + 1):  # noqa: B007 - the count is returned
        for o, s, mu in zip(offsets, sizes, mus, strict=True):
            alpha = q[o : o + s] + W[o : o + s] @ P - W[o : o + s, o : o + s] @ P[o : o + s]
            Wjj = np.ascontiguousarray(W[o : o + s, o : o + s])
            Pj = solve_coulomb_2d(Wjj, alpha, mu)[0] if s == 2 else solve_cone(Wjj, alpha, mu)[0]
            P[o : o + s] = Pj
        err = fclib_error(W, q, mus, offsets, sizes, P)
        if err <= tol:
            break
    nu = nu_free + M_inv @ J.T @ P
    c_new = c + h * nu[:d]
    if d == 3:
        R_new = exp_so3(h * nu[3:]) @ R
    else:
        R_new = rot2(h * nu[2]) @ R
    P_full = np.zeros((len(contacts), 4))
    for o, s, i in zip(offsets, sizes, idx, strict=True):
        P_full[i, :s] = P[o : o + s]
    return Pose(R_new, c_new - R_new @ wp.com_body), nu, P_full, active, err, it
