"""The compiled twin of :mod:`.mesh_slots`: a mesh part's whole step, detection included, in one call.

:func:`mesh_step3` does in numba what :meth:`fixplan.engine.simulator.Simulator._step_mesh_reference`
does in Python, with the same arithmetic (``tests/test_mesh_slot_kernels.py`` pins the two
together, 1e-12, on a box and an L-bracket):

1. every locator's contacts on the mesh (:func:`fixplan.geometry._mesh_kernels.contacts_near`:
   :func:`~fixplan.geometry._mesh_kernels.contacts`' answer to the bit, from the triangles
   remembered near the tip's last full query while the tip stays within a radius of it; band =
   the step's margin; after the nearest, a face seen from behind is no contact), each made a
   plane slot as :func:`fixplan.engine.mesh_slots.mesh_slots` makes it (plane through the tip's
   point nearest the part, frame of :func:`fixplan.geometry.collision.plane_frame`), with the
   locator's μ and, for a soft finger, its torsion arm (a spin row); then every pin's contacts
   with its ``[[workpiece.hole]]`` within the margin, in closed form
   (:func:`fixplan.engine._pin_slot_kernels.pin_slots`: the hole is analytic, the mesh's own
   triangles are never tested against a pin), each a plane slot with the pin's μ;
2. the fixture's collision points that may be within the margin of their obstacle
   (:meth:`Simulator._obstacle_points_near`'s lower bound, point by point), found through an
   AABB tree of the points (:func:`fixplan.geometry._mesh_kernels.build_tree` on degenerate
   triangles): a node is skipped when a lower bound of every gap in it, less ``slack``, is beyond
   the margin, so the same points are found as by testing each one;
3. the warm start of each slot from the last step's slot of the same ``(locator, rank)`` (a
   pin's: of the same ``(pin, kind, ordinal)``), of each collision point from its own row;
4. the Moreau–Jean step (:func:`fixplan.engine.step.step3_ws`);
5. the results written back: each slot's state (the next warm start and the reports), the
   collision points' rows (only those handed over in this step or the last are touched: a part
   of 5·10⁴ triangles has 2.5·10⁴ of them per obstacle), each locator's row (its contacts
   together: the least gap, any active, the summed normal impulse, the nearest's normal) and each
   pin's row (as :meth:`fixplan.engine.simulator.Simulator._step_pins` writes it for a primitive
   part: its least gap over all its contacts, any active, the summed normal impulse, the normal of
   the slot at that least gap).

The state a caller keeps between steps (:class:`fixplan.engine.mesh_slots.MeshStepper` allocates it):

- ``slot_state (C, 18)``: per slot ``[P (4), P_prev (4), u (4), n_world (3), gap, active, active_prev]``;
- ``loc_slots (k_loc, 2)``: each locator's first slot and slot count (count 0: no warm start);
- ``near (2 n_points + 1,)``: the count of collision points handed over in the last step (−1: none
  yet, every row is reset at the next step), then their rows, then room for this step's;
- ``cache_q (k_loc, 5)``, ``cache_ids (k_loc, C)``: each locator's last full query point (body
  frame), count (−1: none) and reach, then the triangles remembered there, with ``radius``;
- ``pin_state (C_pin, 21)``, ``pin_count (1,)``: per pin slot of the last step ``slot_state``'s 18
  columns and its key ``(pin, kind, ordinal)``, and how many there were (``C_pin``: every contact
  the closed forms can give, :data:`fixplan.engine.pin_slots.MAX_CONTACTS` a pin).

The simulator's named rows are the locators' (``k_loc``), then the pins' (``k_pin``); the
fixture's collision points follow them (row ``k_loc + k_pin + q``). Without pins the pins' arrays
are empty and the step is the one without them, to the bit.

Every function is ``numba.njit(cache=True)``; :data:`fixplan.aot.EXPORTS` lists
:func:`mesh_step3`, the one called from Python.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fixplan.engine._pin_slot_kernels import pin_slots
from fixplan.engine.step import step3_ws, workspace3
from fixplan.geometry._mesh_kernels import STACK, contacts_near

MESH = 4  # fixplan.engine.encode.MESH: the step never queries the part itself (every contact is a slot)
STATE = 18  # columns of slot_state (module docstring)
PIN_STATE = STATE + 3  # columns of pin_state: slot_state's, then the key (pin, kind, ordinal)


@njit(cache=True)
def plane_row(x0, x1, x2, m0, m1, m2, gap, row):
    """``row (16)``: the plane obstacle through ``x − gap·m`` with normal ``m`` (:func:`~fixplan.geometry.collision.plane_frame`)."""
    o0, o1, o2 = x0 - gap * m0, x1 - gap * m1, x2 - gap * m2
    nrm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    n0, n1, n2 = m0 / nrm, m1 / nrm, m2 / nrm
    a0, a1, a2 = abs(n0), abs(n1), abs(n2)
    axis = 0  # the first axis of least |n| (numpy's argmin)
    if a1 < a0:
        axis = 1
        if a2 < a1:
            axis = 2
    elif a2 < a0:
        axis = 2
    na = n0 if axis == 0 else (n1 if axis == 1 else n2)
    t0, t1, t2 = -na * n0, -na * n1, -na * n2
    if axis == 0:
        t0 += 1.0
    elif axis == 1:
        t1 += 1.0
    else:
        t2 += 1.0
    tn = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    t0, t1, t2 = t0 / tn, t1 / tn, t2 / tn
    b0, b1, b2 = n1 * t2 - n2 * t1, n2 * t0 - n0 * t2, n0 * t1 - n1 * t0
    row[0] = 0.0  # a plane
    row[1], row[2], row[3] = o0, o1, o2
    row[4], row[5], row[6] = t0, b0, n0  # R_world_plane = [t1, n × t1, n], row-major
    row[7], row[8], row[9] = t1, b1, n1
    row[10], row[11], row[12] = t2, b2, n2
    row[13], row[14], row[15] = 0.0, 0.0, 0.0


@njit(cache=True)
def point_lower(pts, q, M, c, kind, half_norm):
    """Simulator._obstacle_points_near's lower bound of collision point ``q``'s gap (``local = M x + c``)."""
    x0, x1, x2 = pts[q, 0], pts[q, 1], pts[q, 2]
    l2 = x0 * M[2, 0] + x1 * M[2, 1] + x2 * M[2, 2] + c[2]
    if kind == 0:  # a plane: the point's height over it
        return l2 - pts[q, 3]
    l0 = x0 * M[0, 0] + x1 * M[0, 1] + x2 * M[0, 2] + c[0]
    l1 = x0 * M[1, 0] + x1 * M[1, 1] + x2 * M[1, 2] + c[1]
    return math.sqrt(l0 * l0 + l1 * l1 + l2 * l2) - half_norm - pts[q, 3]


@njit(cache=True)
def _node_lower(box, M, c, kind, half_norm, rho_max):
    """A lower bound of :func:`point_lower` over every point in the box ``(lo xyz, hi xyz)``."""
    if kind == 0:
        acc = c[2]
        for a in range(3):
            acc += M[2, a] * (box[a] if M[2, a] >= 0.0 else box[3 + a])
        return acc - rho_max
    # a box obstacle: the distance from its centre (in body coordinates, −Mᵀc) to the node's box
    total = 0.0
    for a in range(3):
        y = -(M[0, a] * c[0] + M[1, a] * c[1] + M[2, a] * c[2])
        if y < box[a]:
            total += (box[a] - y) ** 2
        elif y > box[3 + a]:
            total += (y - box[3 + a]) ** 2
    return math.sqrt(total) - half_norm - rho_max


@njit(cache=True)
def points_near(R, p, obs, pts, boxes, nodes, order, rho_max, margin, slack, found):
    """The collision points whose gap may be within ``margin`` (ascending rows) into ``found``; their count.

    ``pts (n, 6)``: ``[x_body (3), radius, obstacle row, μ]``; the tree ``boxes, nodes, order`` is
    :func:`~fixplan.geometry._mesh_kernels.build_tree`'s of the points, ``rho_max`` their largest
    radius. ``found`` holds ``n`` rows.
    """
    if pts.shape[0] == 0:
        return 0
    M = np.empty((3, 3))
    c = np.empty(3)
    stack = np.empty(STACK, dtype=np.int64)
    count = 0
    for j in range(obs.shape[0]):
        for a in range(3):
            for b in range(3):
                acc = 0.0
                for t in range(3):
                    acc += obs[j, 4 + 3 * t + a] * R[t, b]
                M[a, b] = acc
            acc = 0.0
            for t in range(3):
                acc += obs[j, 4 + 3 * t + a] * (p[t] - obs[j, 1 + t])
            c[a] = acc
        kind = int(obs[j, 0])
        half_norm = math.sqrt(obs[j, 13] ** 2 + obs[j, 14] ** 2 + obs[j, 15] ** 2)
        stack[0] = 0
        depth = 1
        while depth > 0:
            depth -= 1
            node = stack[depth]
            if _node_lower(boxes[node], M, c, kind, half_norm, rho_max) - slack > margin:
                continue
            if nodes[node, 3] == 0:
                stack[depth] = nodes[node, 0]
                stack[depth + 1] = nodes[node, 1]
                depth += 2
                continue
            start = nodes[node, 2]
            for k in range(start, start + nodes[node, 3]):
                q = order[k]
                if int(pts[q, 4]) == j and point_lower(pts, q, M, c, kind, half_norm) <= margin:
                    found[count] = q
                    count += 1
    found[:count].sort()
    return count


@njit(cache=True)
def _grow_f(a, rows):
    b = np.empty((rows,) + a.shape[1:])
    b[: a.shape[0]] = a
    return b


@njit(cache=True)
def _grow_i(a, rows):
    b = np.empty(rows, dtype=np.int64)
    b[: a.shape[0]] = a
    return b


@njit(cache=True)
def locator_slots(R, p, tri, face_normals, edge_normals, vertex_normals, faces, around, boxes, nodes, order, same, loc,
                  band, radius, cache_q, cache_ids):  # fmt: skip
    """Every locator's contacts within ``band`` of its nearest, as plane slots (:func:`fixplan.engine.mesh_slots.mesh_slots`).

    ``radius``, ``cache_q (k_loc, 5)``, ``cache_ids (k_loc, C)``: each locator's remembered
    triangles (:func:`fixplan.geometry._mesh_kernels.contacts_near`: the same answer as a full query).

    Returns ``(n, locator (≥n,), rank (≥n,), x_body (≥n, 3), obstacle rows (≥n, 16), gap (≥n,))``:
    the leading ``n`` rows, locator by locator, nearest first.
    """
    k_loc = loc.shape[0]
    cap = 2 * k_loc + 8
    s_loc = np.empty(cap, dtype=np.int64)
    s_rank = np.empty(cap, dtype=np.int64)
    s_x = np.empty((cap, 3))
    s_obs = np.empty((cap, 16))
    s_gap = np.empty(cap)
    out = np.empty((8, 7))
    m = cache_ids.shape[1]
    scratch_ids, scratch_dist, scratch_pts = np.empty(m, dtype=np.int64), np.empty(m), np.empty((m, 4))
    n = 0
    for i in range(k_loc):
        d0, d1, d2 = loc[i, 0] - p[0], loc[i, 1] - p[1], loc[i, 2] - p[2]
        b0 = R[0, 0] * d0 + R[1, 0] * d1 + R[2, 0] * d2
        b1 = R[0, 1] * d0 + R[1, 1] * d1 + R[2, 1] * d2
        b2 = R[0, 2] * d0 + R[1, 2] * d1 + R[2, 2] * d2
        found = contacts_near(b0, b1, b2, band, same, tri, face_normals, edge_normals, vertex_normals, faces, around,
                              boxes, nodes, order, out, radius, cache_q[i], cache_ids[i], scratch_ids, scratch_dist,
                              scratch_pts)  # fmt: skip
        while found < 0:  # too few rows: again with room for all
            out = np.empty((2 * out.shape[0] - found, 7))
            found = contacts_near(b0, b1, b2, band, same, tri, face_normals, edge_normals, vertex_normals, faces,
                                  around, boxes, nodes, order, out, radius, cache_q[i], cache_ids[i], scratch_ids,
                                  scratch_dist, scratch_pts)  # fmt: skip
        rank = 0
        for r in range(found):
            if r > 0 and not out[r, 0] > 0.0:  # a face seen from behind is no contact
                continue
            if n == cap:
                cap *= 2
                s_loc, s_rank, s_gap = _grow_i(s_loc, cap), _grow_i(s_rank, cap), _grow_f(s_gap, cap)
                s_x, s_obs = _grow_f(s_x, cap), _grow_f(s_obs, cap)
            xb0, xb1, xb2 = out[r, 1], out[r, 2], out[r, 3]
            nb0, nb1, nb2 = out[r, 4], out[r, 5], out[r, 6]
            # from the locator into the part, and the contact point, world axes
            m0 = -(R[0, 0] * nb0 + R[0, 1] * nb1 + R[0, 2] * nb2)
            m1 = -(R[1, 0] * nb0 + R[1, 1] * nb1 + R[1, 2] * nb2)
            m2 = -(R[2, 0] * nb0 + R[2, 1] * nb1 + R[2, 2] * nb2)
            x0 = p[0] + (R[0, 0] * xb0 + R[0, 1] * xb1 + R[0, 2] * xb2)
            x1 = p[1] + (R[1, 0] * xb0 + R[1, 1] * xb1 + R[1, 2] * xb2)
            x2 = p[2] + (R[2, 0] * xb0 + R[2, 1] * xb1 + R[2, 2] * xb2)
            gap = out[r, 0] - loc[i, 3]
            plane_row(x0, x1, x2, m0, m1, m2, gap, s_obs[n])
            s_loc[n], s_rank[n], s_gap[n] = i, rank, gap
            s_x[n, 0], s_x[n, 1], s_x[n, 2] = xb0, xb1, xb2
            rank += 1
            n += 1
    return n, s_loc, s_rank, s_x, s_obs, s_gap


@njit(cache=True)
def mesh_step3(R, p, v, w, mass, Ib, Ib_inv, com_b,
               tri, face_normals, edge_normals, vertex_normals, faces, around, boxes, nodes, order, same,
               loc, obs_fix, pts_fix, pt_boxes, pt_nodes, pt_order, rho_max,
               pins, holes_body, pin_mu, rim_samples, newton_steps, golden_steps, coaxial_rel, face_points, arc_inset,
               h, f_ext, tau_ext, restitution, margin, tol, max_iter, polish_after, polish_steps, bound,
               P_full, active_full, P_prev_full, active_prev_full, gap_full, u_full, n_full,
               slot_state, loc_slots, near, radius, cache_q, cache_ids, pin_state, pin_count):  # fmt: skip
    """One 3D step of a mesh part (the module docstring's five parts); the state arrays updated in place.

    ``loc (k_loc, 6)``: each locator's ``[p_world (3), radius, μ, torsion arm]`` (a soft finger's
    torsion arm gives each of its slots a spin row, as it gives a primitive part's contact one).
    ``obs_fix``, ``pts_fix``: the
    fixture's collision-only bodies and collision points (``[x_body (3), radius, obstacle row, μ]``,
    with the AABB tree of :func:`points_near` and their largest radius ``rho_max``),
    whose rows follow the locators' and the pins' in ``P_full`` … ``n_full`` (the simulator's arrays).
    ``pins (k_pin, 14)``, ``holes_body (k_pin, 10, 22 or 53)`` … ``arc_inset``: the pins and their holes as
    :func:`fixplan.engine._pin_slot_kernels.pin_slots` reads them
    (:attr:`fixplan.engine.pin_slots.PinGeometry.kernel_inputs`; a mesh part has no bore), ``pin_mu``
    each pin's μ; ``pin_state``, ``pin_count``: the pins' slots' state (module docstring), as many
    rows as the closed forms can give contacts. Without pins they are empty, the pins' scratch is
    never allocated, and the step is the one without them.
    Returns ``(error, iterations, status, failed local solves, penetration, slots)``; when the
    locators' slots are more than ``slot_state`` holds, ``slots`` is minus their number and nothing
    was changed (call again with room for them).
    """
    k_loc = loc.shape[0]
    k_pin = pins.shape[0]
    k_named = k_loc + k_pin  # the collision points' rows follow the locators' and the pins'
    # 1. every locator's contacts, as plane slots; every pin's, in closed form
    n, s_loc, s_rank, s_x, s_obs, s_gap = locator_slots(
        R, p, tri, face_normals, edge_normals, vertex_normals, faces, around, boxes, nodes, order, same, loc, margin,
        radius, cache_q, cache_ids,
    )  # fmt: skip
    if n > slot_state.shape[0]:
        return 0.0, 0, 0, 0, 0.0, -n
    m = 0
    last = 0
    # the pins' scratch: allocated only with pins (without: zero-row views of the step's own arrays, never read)
    pin_obs, pin_slot_rows, pin_meta, pin_normals = obs_fix[:0], slot_state[:0], slot_state[:0], n_full[:0]
    pin_least = gap_full[:0]
    if k_pin > 0:
        rows = pin_state.shape[0]
        pin_obs, pin_slot_rows, pin_meta = np.empty((rows, 16)), np.empty((rows, 5)), np.empty((rows, 4))
        pin_normals, pin_least = np.empty((rows, 3)), np.empty(k_pin)
        m = pin_slots(pins, holes_body, np.zeros((0, 10)), np.zeros(2), R, p, rim_samples, newton_steps, golden_steps,
                      coaxial_rel, face_points, arc_inset, margin, np.empty((rows, 13)), pin_obs, pin_slot_rows, pin_meta,
                      pin_normals, pin_least)  # fmt: skip
        last = pin_count[0]
    nm = n + m
    # 2. the fixture's collision points that may be within the margin
    n_pts = pts_fix.shape[0]
    near_now = near[1 + n_pts :]  # scratch (a new array of 2.5·10⁴ rows would be mapped and unmapped each step)
    n_near = points_near(R, p, obs_fix, pts_fix, pt_boxes, pt_nodes, pt_order, rho_max, margin, same, near_now)
    # 3. the step's arrays: the locators' slots, the pins', then the collision points; warm starts
    k = nm + n_near
    n_obs = obs_fix.shape[0]
    obs = np.empty((nm + n_obs, 16))
    slots = np.empty((k, 5))
    mu = np.empty(k)
    tors = np.zeros(k)
    P = np.zeros((k, 4))
    P_prev = np.zeros((k, 4))
    u = np.zeros((k, 4))
    act = np.zeros(k, dtype=np.bool_)
    act_prev = np.zeros(k, dtype=np.bool_)
    for j in range(n):
        i = s_loc[j]
        obs[j] = s_obs[j]
        slots[j, 0], slots[j, 1], slots[j, 2], slots[j, 3], slots[j, 4] = s_x[j, 0], s_x[j, 1], s_x[j, 2], 0.0, j
        mu[j] = loc[i, 4]
        tors[j] = loc[i, 5]
        if s_rank[j] < loc_slots[i, 1]:  # the same (locator, rank) in the last step
            o = loc_slots[i, 0] + s_rank[j]
            for a in range(4):
                P[j, a] = slot_state[o, a]
                P_prev[j, a] = slot_state[o, 4 + a]
                u[j, a] = slot_state[o, 8 + a]
            act[j] = slot_state[o, 16] != 0.0
            act_prev[j] = slot_state[o, 17] != 0.0
    for jj in range(m):
        j = n + jj
        obs[j] = pin_obs[jj]
        for a in range(4):
            slots[j, a] = pin_slot_rows[jj, a]
        slots[j, 4] = j
        mu[j] = pin_mu[int(pin_meta[jj, 0])]
        for o in range(last):  # the same (pin, kind, ordinal) in the last step: few, a search is enough
            if (pin_state[o, STATE] == pin_meta[jj, 0] and pin_state[o, STATE + 1] == pin_meta[jj, 1]
                    and pin_state[o, STATE + 2] == pin_meta[jj, 2]):  # fmt: skip
                for a in range(4):
                    P[j, a] = pin_state[o, a]
                    P_prev[j, a] = pin_state[o, 4 + a]
                    u[j, a] = pin_state[o, 8 + a]
                act[j] = pin_state[o, 16] != 0.0
                act_prev[j] = pin_state[o, 17] != 0.0
                break
    for j in range(n_obs):
        obs[nm + j] = obs_fix[j]
    for jj in range(n_near):
        q = near_now[jj]
        j = nm + jj
        row = k_named + q
        for a in range(4):
            slots[j, a] = pts_fix[q, a]
        slots[j, 4] = pts_fix[q, 4] + nm  # the fixture's obstacles follow the slots' planes
        mu[j] = pts_fix[q, 5]
        for a in range(4):
            P[j, a] = P_full[row, a]
            P_prev[j, a] = P_prev_full[row, a]
            u[j, a] = u_full[row, a]
        act[j] = active_full[row]
        act_prev[j] = active_prev_full[row]
    gap = np.zeros(k)
    n_w = np.zeros((k, 3))
    # 4. the step (the part itself is never queried: no locator rows of its own)
    err, iters, status, failures, pen = step3_ws(
        R, p, v, w, mass, Ib, Ib_inv, com_b, MESH, np.zeros(3), np.zeros((0, 2)), np.zeros((0, 2)),
        np.zeros((0, 3)), np.zeros(0), mu, tors, obs, slots, h, f_ext, tau_ext, restitution, margin, tol, max_iter,
        polish_after, polish_steps, P, act, P_prev, act_prev, gap, u, n_w, bound, workspace3(k),
    )  # fmt: skip
    # 5. written back: the slots' state, the pins' slots' state, the collision points' rows, the named rows
    for j in range(n):
        for a in range(4):
            slot_state[j, a] = P[j, a]
            slot_state[j, 4 + a] = P_prev[j, a]
            slot_state[j, 8 + a] = u[j, a]
        for a in range(3):
            slot_state[j, 12 + a] = n_w[j, a]
        slot_state[j, 15] = gap[j]
        slot_state[j, 16] = 1.0 if act[j] else 0.0
        slot_state[j, 17] = 1.0 if act_prev[j] else 0.0
    for jj in range(m):  # the same columns, then the key
        j = n + jj
        for a in range(4):
            pin_state[jj, a] = P[j, a]
            pin_state[jj, 4 + a] = P_prev[j, a]
            pin_state[jj, 8 + a] = u[j, a]
        for a in range(3):
            pin_state[jj, 12 + a] = n_w[j, a]
            pin_state[jj, STATE + a] = pin_meta[jj, a]
        pin_state[jj, 15] = gap[j]
        pin_state[jj, 16] = 1.0 if act[j] else 0.0
        pin_state[jj, 17] = 1.0 if act_prev[j] else 0.0
    if k_pin > 0:
        pin_count[0] = m
    if near[0] < 0:  # the first step since the state was set: every row
        for q in range(n_pts):
            _open_row(k_named + q, P_full, active_full, P_prev_full, active_prev_full, gap_full, u_full)
    else:
        for jj in range(near[0]):
            _open_row(k_named + near[1 + jj], P_full, active_full, P_prev_full, active_prev_full, gap_full, u_full)
    for jj in range(n_near):
        q = near_now[jj]
        j = nm + jj
        row = k_named + q
        for a in range(4):
            P_full[row, a] = P[j, a]
            P_prev_full[row, a] = P_prev[j, a]
            u_full[row, a] = u[j, a]
        active_full[row] = act[j]
        active_prev_full[row] = act_prev[j]
        gap_full[row] = gap[j]
        for a in range(3):
            n_full[row, a] = n_w[j, a]
        near[1 + jj] = q
    near[0] = n_near
    j = 0
    for i in range(k_loc):
        loc_slots[i, 0] = j
        first = j
        any_on = False
        least = math.inf
        total = 0.0
        while j < n and s_loc[j] == i:
            least = min(least, gap[j])
            if act[j]:
                any_on = True
                total += P[j, 0]
            j += 1
        loc_slots[i, 1] = j - first
        if j == first:  # every locator has a nearest contact
            continue
        active_full[i] = any_on
        gap_full[i] = least
        P_full[i, 0] = total
        P_full[i, 1], P_full[i, 2], P_full[i, 3] = 0.0, 0.0, 0.0
        for a in range(3):
            n_full[i, a] = n_w[first, a]
        for a in range(4):
            u_full[i, a] = u[first, a]
    # each pin's row: its least gap over all its contacts (the closed forms'), any active, the summed
    # normal impulse, the normal and velocity of its slot at that gap (Simulator._step_pins' rows)
    for o in range(k_pin):
        r = k_loc + o
        _open_row(r, P_full, active_full, P_prev_full, active_prev_full, gap_full, u_full)
        gap_full[r] = pin_least[o]
    for jj in range(m):
        j = n + jj
        r = k_loc + int(pin_meta[jj, 0])
        if act[j]:
            active_full[r] = True
            P_full[r, 0] += P[j, 0]
        if gap[j] <= gap_full[r]:
            gap_full[r] = gap[j]
            for a in range(3):
                n_full[r, a] = n_w[j, a]
            for a in range(4):
                u_full[r, a] = u[j, a]
    return err, iters, status, failures, pen, n


@njit(cache=True)
def _open_row(row, P_full, active_full, P_prev_full, active_prev_full, gap_full, u_full):
    """A collision point not handed to the step: open, no impulse, its gap beyond the margin."""
    for a in range(4):
        P_full[row, a] = 0.0
        P_prev_full[row, a] = 0.0
        u_full[row, a] = 0.0
    active_full[row] = False
    active_prev_full[row] = False
    gap_full[row] = math.inf
