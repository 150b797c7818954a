"""Compiled contact detection: the closed-form point queries of :mod:`fixplan.geometry.shapes`.

The engine's hot loop cannot call Python shape objects, so each shape is encoded as a kind code
and a parameter array (:func:`fixplan.engine.encode.encode`), and :func:`project` answers the
same question as :meth:`fixplan.geometry.Shape.project` (signed distance, closest point, outward normal) in the
body frame (codes and parameters: :mod:`fixplan.engine.encode`). ``tests/engine/test_detect.py``
checks the two agree on random points.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fixplan.engine.encode import BALL, BOX, CYLINDER


@njit(cache=True)
def _box(p, half, point, normal):
    d = p.shape[0]
    out2 = 0.0
    scale = 0.0
    kmax = 0
    qmax = -1e300
    for i in range(d):
        q = abs(p[i]) - half[i]
        if q > 0.0:
            out2 += q * q
        if half[i] > scale:
            scale = half[i]
        if q > qmax:
            qmax = q
            kmax = i
    n_out = math.sqrt(out2)
    if n_out > 1e-12 * scale:
        for i in range(d):
            s = 1.0 if p[i] >= 0.0 else -1.0
            q = abs(p[i]) - half[i]
            point[i] = min(max(p[i], -half[i]), half[i])
            normal[i] = s * q / n_out if q > 0.0 else 0.0
        return n_out
    for i in range(d):
        point[i] = p[i]
        normal[i] = 0.0
    s = 1.0 if p[kmax] >= 0.0 else -1.0
    point[kmax] = s * half[kmax]
    normal[kmax] = s
    return qmax


@njit(cache=True)
def project(kind, params, verts, edge_normals, p, point, normal):
    """Signed distance of body-frame point ``p``; fills the closest point and outward normal."""
    d = p.shape[0]
    if kind == BOX:
        return _box(p, params, point, normal)
    if kind == BALL:
        rho = math.sqrt(np.sum(p * p))
        for i in range(d):
            normal[i] = 0.0
        if rho > 1e-15:
            for i in range(d):
                normal[i] = p[i] / rho
        else:
            normal[d - 1] = 1.0
        for i in range(d):
            point[i] = params[0] * normal[i]
        return rho - params[0]
    if kind == CYLINDER:
        rho = math.hypot(p[0], p[1])
        rx, ry = 1.0, 0.0
        if rho > 1e-15:
            rx, ry = p[0] / rho, p[1] / rho
        q2 = np.array([rho, p[2]])
        pt2 = np.empty(2)
        n2 = np.empty(2)
        dist = _box(q2, params, pt2, n2)
        point[0] = pt2[0] * rx
        point[1] = pt2[0] * ry
        point[2] = pt2[1]
        nx, ny, nz = n2[0] * rx, n2[0] * ry, n2[1]
        nn = math.sqrt(nx * nx + ny * ny + nz * nz)
        normal[0], normal[1], normal[2] = nx / nn, ny / nn, nz / nn
        return dist
    # POLYGON
    nv = verts.shape[0]
    kbest = 0
    best = -1e300
    for k in range(nv):
        s = (p[0] - verts[k, 0]) * edge_normals[k, 0] + (p[1] - verts[k, 1]) * edge_normals[k, 1]
        if s > best:
            best = s
            kbest = k
    if best <= 0.0:
        point[0] = p[0] - best * edge_normals[kbest, 0]
        point[1] = p[1] - best * edge_normals[kbest, 1]
        normal[0] = edge_normals[kbest, 0]
        normal[1] = edge_normals[kbest, 1]
        return best
    dmin = 1e300
    cx, cy, tk = 0.0, 0.0, 0.0
    kmin = 0
    for k in range(nv):
        k2 = (k + 1) % nv
        ex, ey = verts[k2, 0] - verts[k, 0], verts[k2, 1] - verts[k, 1]
        t = ((p[0] - verts[k, 0]) * ex + (p[1] - verts[k, 1]) * ey) / (ex * ex + ey * ey)
        t = min(max(t, 0.0), 1.0)
        qx, qy = verts[k, 0] + t * ex, verts[k, 1] + t * ey
        dd = math.hypot(p[0] - qx, p[1] - qy)
        if dd < dmin:
            dmin, cx, cy, kmin, tk = dd, qx, qy, k, t
    point[0], point[1] = cx, cy
    scale = params[0]
    if dmin > 1e-12 * scale and 0.0 < tk < 1.0:
        normal[0], normal[1] = edge_normals[kmin, 0], edge_normals[kmin, 1]
    elif dmin > 1e-12 * scale:
        normal[0], normal[1] = (p[0] - cx) / dmin, (p[1] - cy) / dmin
    else:
        normal[0], normal[1] = edge_normals[kbest, 0], edge_normals[kbest, 1]
    return dmin


# Scalar 3D queries for the allocation-free step: a numba helper that merely *contains* a call to
# the general :func:`project` costs about 0.2 µs per call even when that branch never runs, so the
# caller picks the box-only scalar path and keeps the general call for the other shapes.


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
    """``Rᵀ (q − p)``: the world point ``q`` in body coordinates (same sums as :func:`fixplan.engine.linalg.mtv`)."""
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
def box_query3(half, R, p, q0, q1, q2):
    """Gap data of the world point ``q`` against a box at ``(R, p)``: ``(distance, n, x)``, world axes.

    Kept apart from :func:`query3`: a helper that merely contains the call to the general
    :func:`~fixplan.engine.detect.project` cost 15× more per call (measured 1.2 against 0.08 µs
    for six locators), so the caller chooses.
    """
    b0, b1, b2 = _frame3(R, p, q0, q1, q2)
    dist, x0, x1, x2, m0, m1, m2 = _box3(b0, b1, b2, half[0], half[1], half[2])
    return _to_world3(R, p, dist, x0, x1, x2, m0, m1, m2)


@njit(cache=True)
def query3(kind, params, verts, enorm, R, p, q0, q1, q2, pb, point, normal):
    """:func:`box_query3` for any shape (``pb, point, normal``: scratch 3-vectors)."""
    pb[0], pb[1], pb[2] = _frame3(R, p, q0, q1, q2)
    dist = project(kind, params, verts, enorm, pb, point, normal)
    return _to_world3(R, p, dist, point[0], point[1], point[2], normal[0], normal[1], normal[2])


# Collision-only bodies ([[obstacle]], :mod:`fixplan.geometry.collision`): a collision point of the
# part (``slots`` row: body point, radius, obstacle index) against a fixed plane or box (``obs``
# row: kind, origin, rotation row-major, half extents). The compiled twin of
# :func:`fixplan.geometry.collision.obstacle_gap`; ``tests/engine/test_obstacles.py`` pins them.


@njit(cache=True)
def obstacle_query3(obs, slots, j, R, p):
    """Collision point ``j`` against its obstacle at the body pose ``(R, p)``: ``(gap, n, x)``, world axes.

    ``n`` is the obstacle's outward normal (it pushes the part along it), ``x`` the contact point
    on the part.
    """
    b0, b1, b2, rho = slots[j, 0], slots[j, 1], slots[j, 2], slots[j, 3]
    o = int(slots[j, 4])
    x0 = p[0] + (R[0, 0] * b0 + R[0, 1] * b1 + R[0, 2] * b2)
    x1 = p[1] + (R[1, 0] * b0 + R[1, 1] * b1 + R[1, 2] * b2)
    x2 = p[2] + (R[2, 0] * b0 + R[2, 1] * b1 + R[2, 2] * b2)
    d0, d1, d2 = x0 - obs[o, 1], x1 - obs[o, 2], x2 - obs[o, 3]
    l0 = obs[o, 4] * d0 + obs[o, 7] * d1 + obs[o, 10] * d2
    l1 = obs[o, 5] * d0 + obs[o, 8] * d1 + obs[o, 11] * d2
    l2 = obs[o, 6] * d0 + obs[o, 9] * d1 + obs[o, 12] * d2
    if obs[o, 0] == 0.0:  # a plane: its local z is the signed distance
        dist, m0, m1, m2 = l2, 0.0, 0.0, 1.0
    else:
        dist, _x0, _x1, _x2, m0, m1, m2 = _box3(l0, l1, l2, obs[o, 13], obs[o, 14], obs[o, 15])
    n0 = obs[o, 4] * m0 + obs[o, 5] * m1 + obs[o, 6] * m2
    n1 = obs[o, 7] * m0 + obs[o, 8] * m1 + obs[o, 9] * m2
    n2 = obs[o, 10] * m0 + obs[o, 11] * m1 + obs[o, 12] * m2
    return dist - rho, n0, n1, n2, x0 - rho * n0, x1 - rho * n1, x2 - rho * n2


@njit(cache=True)
def obstacle_query2(obs, slots, j, R, p):
    """:func:`obstacle_query3` in the plane: ``(gap, n0, n1, x0, x1)``."""
    b0, b1, rho = slots[j, 0], slots[j, 1], slots[j, 2]
    o = int(slots[j, 3])
    x0 = p[0] + (R[0, 0] * b0 + R[0, 1] * b1)
    x1 = p[1] + (R[1, 0] * b0 + R[1, 1] * b1)
    d0, d1 = x0 - obs[o, 1], x1 - obs[o, 2]
    l0 = obs[o, 3] * d0 + obs[o, 5] * d1
    l1 = obs[o, 4] * d0 + obs[o, 6] * d1
    if obs[o, 0] == 0.0:  # a line: its local y is the signed distance
        dist, m0, m1 = l1, 0.0, 1.0
    else:
        h0, h1 = obs[o, 7], obs[o, 8]
        q0, q1 = abs(l0) - h0, abs(l1) - h1
        s0 = 1.0 if l0 >= 0.0 else -1.0
        s1 = 1.0 if l1 >= 0.0 else -1.0
        e0, e1 = max(q0, 0.0), max(q1, 0.0)
        n_out = math.sqrt(e0 * e0 + e1 * e1)
        if n_out > 0.0:
            dist, m0, m1 = n_out, s0 * e0 / n_out, s1 * e1 / n_out
        elif q0 >= q1:
            dist, m0, m1 = q0, s0, 0.0
        else:
            dist, m0, m1 = q1, 0.0, s1
    n0 = obs[o, 3] * m0 + obs[o, 4] * m1
    n1 = obs[o, 5] * m0 + obs[o, 6] * m1
    return dist - rho, n0, n1, x0 - rho * n0, x1 - rho * n1
