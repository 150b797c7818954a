"""Compiled contact detection: the closed-form point queries of :mod:`fixplan.geometry.shapes`.

The engine's hot loop cannot call Python shape objects, so each shape is encoded as a kind code
and a parameter array, and :func:`project` answers the same question as
:meth:`fixplan.geometry.Shape.project` (signed distance, closest point, outward normal) in the
body frame. ``tests/engine/test_detect.py`` checks the two agree on random points.

Codes and parameters (``params``; ``verts``/``edge_normals`` only for polygons):

- ``BOX`` (box or rectangle): half extents (3 or 2 numbers);
- ``BALL`` (sphere or disk): radius;
- ``CYLINDER``: radius, half length (axis = body z);
- ``POLYGON``: vertices (n × 2, counter-clockwise) and outward edge normals (n × 2).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fixplan.geometry import Box, Cylinder, Disk, Polygon, Rectangle, Shape, Sphere

BOX, BALL, CYLINDER, POLYGON = 0, 1, 2, 3


def encode(shape: Shape) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """``(kind, params, verts, edge_normals)`` for the compiled queries."""
    empty = np.zeros((0, 2))
    if isinstance(shape, Box | Rectangle):
        return BOX, np.asarray(shape.half, dtype=float), empty, empty
    if isinstance(shape, Sphere | Disk):
        return BALL, np.array([shape.radius]), empty, empty
    if isinstance(shape, Cylinder):
        return CYLINDER, np.array([shape.radius, shape.length / 2.0]), empty, empty
    if isinstance(shape, Polygon):
        V = shape.array
        E = np.roll(V, -1, axis=0) - V
        N = np.stack([E[:, 1], -E[:, 0]], axis=1) / np.linalg.norm(E, axis=1)[:, None]
        return POLYGON, np.array([shape.bounding_radius]), np.ascontiguousarray(V), np.ascontiguousarray(N)
    raise TypeError(f"no compiled query for {type(shape).__name__}")  # pragma: no cover


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
