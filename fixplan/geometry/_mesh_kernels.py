"""The compiled point queries of :class:`fixplan.geometry.mesh.Mesh`: a flat AABB tree and exact contacts.

The same arithmetic as the Python reference in :mod:`fixplan.geometry.mesh`
(:func:`~fixplan.geometry.mesh._closest_scalar`, ``Mesh.contacts_reference``), written on scalars
so that one query allocates almost nothing; ``tests/test_mesh_kernels.py`` pins the two together
on seeded random queries (1e-12, in practice to the bit).

The tree (:func:`build_tree`): a binary tree of axis-aligned boxes in flat arrays, split at the
median centroid along the longest axis of the centroids' box, at most ``leaf_size`` triangles per
leaf. ``boxes[k] = (lo xyz, hi xyz)``; ``nodes[k] = (left, right, start, count)``: a leaf
(``count > 0``) holds the triangles ``order[start : start + count]``; an inner node's children are
``left`` and ``right``.

A query (:func:`contacts`) walks the tree once, depth first, nearer child first, gathering every
triangle within ``best + band + same`` of the point (``best`` the nearest distance so far; a box
farther than that is skipped), sorts them by (distance, triangle index) as the reference sorts
them, and keeps
each local minimum: a closest point on an edge or a vertex counts only when every triangle around
that feature has it as its own closest point; points within ``same`` of one already kept are the
same contact. Signs and normals are those of the reference: the face's own normal in a face, the
angle-weighted pseudo-normal's side on an edge or a vertex.

Every function here is ``numba.njit(cache=True)``; :data:`fixplan.aot.EXPORTS` lists the two
called from Python, which are compiled ahead of time with the others.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# Ericson's regions (the same codes as fixplan.geometry.mesh)
FACE, VERTEX_A, VERTEX_B, VERTEX_C, EDGE_AB, EDGE_BC, EDGE_CA = 0, 1, 2, 3, 4, 5, 6
STACK = 256  # deeper than any median-split tree of at most 2**255 triangles


@njit(cache=True)
def closest_point(px, py, pz, t):
    """``(x, y, z, region)``: the closest point of triangle ``t = (a xyz, b xyz, c xyz)`` to ``p`` (Ericson 5.1.5)."""
    ax, ay, az, bx, by, bz, cx, cy, cz = t[0], t[1], t[2], t[3], t[4], t[5], t[6], t[7], t[8]
    abx, aby, abz, acx, acy, acz = bx - ax, by - ay, bz - az, cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1, d2 = abx * apx + aby * apy + abz * apz, acx * apx + acy * apy + acz * apz
    if d1 <= 0 and d2 <= 0:
        return ax, ay, az, VERTEX_A
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3, d4 = abx * bpx + aby * bpy + abz * bpz, acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0 and d4 <= d3:
        return bx, by, bz, VERTEX_B
    vc = d1 * d4 - d3 * d2
    if vc <= 0 and d1 >= 0 and d3 <= 0:
        v = d1 / (d1 - d3)
        return ax + v * abx, ay + v * aby, az + v * abz, EDGE_AB
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5, d6 = abx * cpx + aby * cpy + abz * cpz, acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0 and d5 <= d6:
        return cx, cy, cz, VERTEX_C
    vb = d5 * d2 - d1 * d6
    if vb <= 0 and d2 >= 0 and d6 <= 0:
        w = d2 / (d2 - d6)
        return ax + w * acx, ay + w * acy, az + w * acz, EDGE_CA
    va = d3 * d6 - d5 * d4
    if va <= 0 and (d4 - d3) >= 0 and (d5 - d6) >= 0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return bx + w * (cx - bx), by + w * (cy - by), bz + w * (cz - bz), EDGE_BC
    nx, ny, nz = aby * acz - abz * acy, abz * acx - abx * acz, abx * acy - aby * acx
    norm = math.sqrt(nx * nx + ny * ny + nz * nz)
    nx, ny, nz = nx / norm, ny / norm, nz / norm
    h = apx * nx + apy * ny + apz * nz
    return px - h * nx, py - h * ny, pz - h * nz, FACE


@njit(cache=True)
def _box_distance2(px, py, pz, box):
    """Squared distance from ``p`` to the box ``(lo xyz, hi xyz)`` (0 inside)."""
    total = 0.0
    if px < box[0]:
        total += (box[0] - px) * (box[0] - px)
    elif px > box[3]:
        total += (px - box[3]) * (px - box[3])
    if py < box[1]:
        total += (box[1] - py) * (box[1] - py)
    elif py > box[4]:
        total += (py - box[4]) * (py - box[4])
    if pz < box[2]:
        total += (box[2] - pz) * (box[2] - pz)
    elif pz > box[5]:
        total += (pz - box[5]) * (pz - box[5])
    return total


@njit(cache=True)
def build_tree(tri, leaf_size, boxes, nodes, order):
    """Fill ``boxes (2m, 6)``, ``nodes (2m, 4)`` and ``order (m,)`` for ``tri (m, 9)``; return the node count.

    The module's docstring says what the arrays hold.
    """
    m = tri.shape[0]
    lo = np.empty((m, 3))
    hi = np.empty((m, 3))
    centre = np.empty((m, 3))
    for i in range(m):
        order[i] = i
        for axis in range(3):
            a, b, c = tri[i, axis], tri[i, 3 + axis], tri[i, 6 + axis]
            lo[i, axis] = min(a, b, c)
            hi[i, axis] = max(a, b, c)
            centre[i, axis] = (lo[i, axis] + hi[i, axis]) * 0.5
    stack = np.empty((STACK, 3), dtype=np.int64)
    stack[0, 0], stack[0, 1], stack[0, 2] = 0, 0, m
    depth = 1
    count = 1
    while depth > 0:
        depth -= 1
        node, start, end = stack[depth, 0], stack[depth, 1], stack[depth, 2]
        c_lo = np.full(3, np.inf)
        c_hi = np.full(3, -np.inf)
        for axis in range(3):
            boxes[node, axis] = np.inf
            boxes[node, 3 + axis] = -np.inf
        for k in range(start, end):
            i = order[k]
            for axis in range(3):
                boxes[node, axis] = min(boxes[node, axis], lo[i, axis])
                boxes[node, 3 + axis] = max(boxes[node, 3 + axis], hi[i, axis])
                c_lo[axis] = min(c_lo[axis], centre[i, axis])
                c_hi[axis] = max(c_hi[axis], centre[i, axis])
        if end - start <= leaf_size:
            nodes[node, 0], nodes[node, 1], nodes[node, 2], nodes[node, 3] = -1, -1, start, end - start
            continue
        axis = int(np.argmax(c_hi - c_lo))
        segment = order[start:end].copy()
        keys = np.empty(end - start)
        for k in range(end - start):
            keys[k] = centre[segment[k], axis]
        sorted_k = np.argsort(keys, kind="mergesort")
        for k in range(end - start):
            order[start + k] = segment[sorted_k[k]]
        middle = (start + end) // 2
        left, right = count, count + 1
        count += 2
        nodes[node, 0], nodes[node, 1], nodes[node, 2], nodes[node, 3] = left, right, start, 0
        stack[depth, 0], stack[depth, 1], stack[depth, 2] = left, start, middle
        stack[depth + 1, 0], stack[depth + 1, 1], stack[depth + 1, 2] = right, middle, end
        depth += 2
    return count


@njit(cache=True)
def _feature_is_shared(px, py, pz, x, y, z, tri_id, region, same, tri, faces, around_start, around):
    """Whether every triangle at the closest feature (an edge or a vertex of ``tri_id``) has ``(x, y, z)`` as its closest point."""
    if region == VERTEX_A or region == VERTEX_B or region == VERTEX_C:
        v0 = faces[tri_id, region - VERTEX_A]
        v1 = -1
    else:
        u = region - EDGE_AB  # slots AB, BC, CA
        v0, v1 = faces[tri_id, u], faces[tri_id, (u + 1) % 3]
    for k in range(around_start[v0], around_start[v0 + 1]):
        f = around[k]
        if f == tri_id:  # (x, y, z) is its own closest point
            continue
        if v1 >= 0 and faces[f, 0] != v1 and faces[f, 1] != v1 and faces[f, 2] != v1:
            continue
        qx, qy, qz, _ = closest_point(px, py, pz, tri[f])
        dx, dy, dz = qx - x, qy - y, qz - z
        if math.sqrt(dx * dx + dy * dy + dz * dz) > same:
            return False
    return True


@njit(cache=True)
def _collect(px, py, pz, reach_extra, tri, boxes, nodes, order):
    """One traversal, nearer child first: every triangle within ``nearest + reach_extra`` of ``p``.

    Returns ``(n, ids, dist, pts, nearest)``: the leading ``n`` rows are triangles with their distance and
    closest point (``x, y, z, region``); every triangle within the final ``nearest + reach_extra``
    is among them (a few farther ones may be too: the reach shrinks as the nearest improves).
    """
    size = 16
    ids = np.empty(size, dtype=np.int64)
    dist = np.empty(size)
    pts = np.empty((size, 4))  # x, y, z, region
    n = 0
    best = np.inf
    reach = np.inf
    slack2 = np.inf  # reach²: the box test; the exact test follows
    stack = np.empty(STACK, dtype=np.int64)
    below = np.empty(STACK)  # each stacked node's box distance² (the test again when it is popped)
    stack[0], below[0] = 0, 0.0
    depth = 1
    while depth > 0:
        depth -= 1
        node = stack[depth]
        if below[depth] > slack2:
            continue
        if nodes[node, 3] == 0:
            left, right = nodes[node, 0], nodes[node, 1]
            dl = _box_distance2(px, py, pz, boxes[left])
            dr = _box_distance2(px, py, pz, boxes[right])
            if dl <= dr:  # the nearer child on top
                if dr <= slack2:
                    stack[depth], below[depth] = right, dr
                    depth += 1
                if dl <= slack2:
                    stack[depth], below[depth] = left, dl
                    depth += 1
            else:
                if dl <= slack2:
                    stack[depth], below[depth] = left, dl
                    depth += 1
                if dr <= slack2:
                    stack[depth], below[depth] = right, dr
                    depth += 1
            continue
        start = nodes[node, 2]
        for k in range(start, start + nodes[node, 3]):
            i = order[k]
            x, y, z, region = closest_point(px, py, pz, tri[i])
            dx, dy, dz = px - x, py - y, pz - z
            d = math.sqrt(dx * dx + dy * dy + dz * dz)
            if d < best:
                best = d
                reach = best + reach_extra
                slack2 = reach * reach
            if d > reach:
                continue
            if n == size:
                size *= 2
                ids2, dist2, pts2 = np.empty(size, dtype=np.int64), np.empty(size), np.empty((size, 4))
                ids2[:n], dist2[:n], pts2[:n] = ids, dist, pts
                ids, dist, pts = ids2, dist2, pts2
            ids[n], dist[n] = i, d
            pts[n, 0], pts[n, 1], pts[n, 2], pts[n, 3] = x, y, z, region
            n += 1
    return n, ids, dist, pts, best


@njit(cache=True)
def _emit(px, py, pz, band, same, tri, face_normals, edge_normals, vertex_normals, faces, around, n, ids, dist, pts,
          out):  # fmt: skip
    """:func:`contacts`' answer from candidate triangles that hold every one within ``nearest + band + same``."""
    n_vertices = vertex_normals.shape[0]
    around_start = around[: n_vertices + 1]
    around_list = around[n_vertices + 1 :]
    nearest = np.inf
    for k in range(n):
        nearest = min(nearest, dist[k])
    limit = nearest + band + same
    # by (distance, triangle index), those within the limit: an insertion sort of a few rows, in place
    kept = 0
    for k in range(n):
        if dist[k] > limit:
            continue
        d, i, x, y, z, code = dist[k], ids[k], pts[k, 0], pts[k, 1], pts[k, 2], pts[k, 3]
        r = kept
        while r > 0 and (dist[r - 1] > d or (dist[r - 1] == d and ids[r - 1] > i)):
            dist[r], ids[r] = dist[r - 1], ids[r - 1]
            pts[r, 0], pts[r, 1], pts[r, 2], pts[r, 3] = pts[r - 1, 0], pts[r - 1, 1], pts[r - 1, 2], pts[r - 1, 3]
            r -= 1
        dist[r], ids[r] = d, i
        pts[r, 0], pts[r, 1], pts[r, 2], pts[r, 3] = x, y, z, code
        kept += 1
    found = 0
    needed = 0
    for k in range(kept):
        x, y, z, d = pts[k, 0], pts[k, 1], pts[k, 2], dist[k]
        region = int(pts[k, 3])
        repeat = False
        for j in range(min(found, out.shape[0])):
            ex, ey, ez = out[j, 1] - x, out[j, 2] - y, out[j, 3] - z
            if math.sqrt(ex * ex + ey * ey + ez * ez) <= same:
                repeat = True
                break
        if repeat:
            continue
        t = ids[k]
        if region != FACE and not _feature_is_shared(
            px, py, pz, x, y, z, t, region, same, tri, faces, around_start, around_list
        ):
            continue
        if found >= out.shape[0]:
            needed = found + 1
            found += 1
            continue
        if region == FACE:
            nx, ny, nz = face_normals[t, 0], face_normals[t, 1], face_normals[t, 2]
            gap = (px - tri[t, 0]) * nx + (py - tri[t, 1]) * ny + (pz - tri[t, 2]) * nz
        else:
            if region == EDGE_AB or region == EDGE_BC or region == EDGE_CA:
                s = 3 * (region - EDGE_AB)
                qx, qy, qz = edge_normals[t, s], edge_normals[t, s + 1], edge_normals[t, s + 2]
            else:
                v = faces[t, region - VERTEX_A]
                qx, qy, qz = vertex_normals[v, 0], vertex_normals[v, 1], vertex_normals[v, 2]
            sign = 1.0 if (px - x) * qx + (py - y) * qy + (pz - z) * qz >= 0.0 else -1.0
            if d > same:
                nx, ny, nz = sign * (px - x) / d, sign * (py - y) / d, sign * (pz - z) / d
            else:
                length = math.sqrt(qx * qx + qy * qy + qz * qz)
                nx, ny, nz = qx / length, qy / length, qz / length
            gap = sign * d
        out[found, 0], out[found, 1], out[found, 2], out[found, 3] = gap, x, y, z
        out[found, 4], out[found, 5], out[found, 6] = nx, ny, nz
        found += 1
        if band == 0.0:
            break
    if needed > 0:
        return -found
    return found


@njit(cache=True)
def contacts(
    px, py, pz, band, same, tri, face_normals, edge_normals, vertex_normals, faces, around, boxes, nodes, order, out
):
    """Every local minimum of the distance from ``p`` within ``band`` of the nearest; the count written into ``out``.

    ``out[k] = (signed distance, point xyz, normal xyz)``, nearest first; ``band == 0``: the
    nearest only. ``around = (offsets (n+1), triangles)`` concatenated: the triangles at each
    vertex. When ``out`` has too few rows, returns minus the number needed (nothing is lost:
    call again with a larger ``out``).
    """
    # every triangle within (nearest + band + same), and the box test with another ``same`` of slack
    n, ids, dist, pts, _ = _collect(px, py, pz, band + 2.0 * same, tri, boxes, nodes, order)
    return _emit(px, py, pz, band, same, tri, face_normals, edge_normals, vertex_normals, faces, around, n, ids, dist,
                 pts, out)  # fmt: skip


@njit(cache=True)
def contacts_near(px, py, pz, band, same, tri, face_normals, edge_normals, vertex_normals, faces, around, boxes, nodes,
                  order, out, radius, cache_q, cache_ids, scratch_ids, scratch_dist, scratch_pts):  # fmt: skip
    """:func:`contacts` for a point that moves a little between calls: the same answer, to the bit.

    ``cache_q = (x, y, z, count, reach)`` and ``cache_ids`` remember, from the last full query at
    ``q₀`` (nearest distance ``d₀``), every triangle within ``d₀ + reach`` of ``q₀`` (``count < 0``:
    nothing remembered); a full query remembers ``reach = band + 2·same + 2·radius``. For ``p`` at
    ``δ = |p − q₀|`` the nearest distance is at most ``d₀ + δ``, and every triangle within
    ``nearest + band + same`` of ``p`` is within ``d₀ + 2δ + band + same`` of ``q₀`` (the distance
    to a triangle is 1-Lipschitz in the point). So while ``2δ + band + same ≤ reach`` the remembered
    triangles hold every one :func:`contacts` would keep, and the same arithmetic on them (closest
    points, the sort by distance and index, the local minima) gives its answer. Otherwise, or when
    they were more than ``cache_ids`` holds, a full query remembers them anew. ``scratch_*``: room
    for as many rows as ``cache_ids`` (the remembered triangles' distances and closest points).
    """
    count = int(cache_q[3])
    ex, ey, ez = px - cache_q[0], py - cache_q[1], pz - cache_q[2]
    if count >= 0 and 2.0 * math.sqrt(ex * ex + ey * ey + ez * ez) + band + same <= cache_q[4]:
        ids, dist, pts = scratch_ids, scratch_dist, scratch_pts
        for k in range(count):
            i = cache_ids[k]
            x, y, z, region = closest_point(px, py, pz, tri[i])
            dx, dy, dz = px - x, py - y, pz - z
            ids[k], dist[k] = i, math.sqrt(dx * dx + dy * dy + dz * dz)
            pts[k, 0], pts[k, 1], pts[k, 2], pts[k, 3] = x, y, z, region
        return _emit(px, py, pz, band, same, tri, face_normals, edge_normals, vertex_normals, faces, around, count,
                     ids, dist, pts, out)  # fmt: skip
    extra = band + 2.0 * same + 2.0 * radius
    n, ids, dist, pts, nearest = _collect(px, py, pz, extra, tri, boxes, nodes, order)
    kept = 0
    for k in range(n):
        if dist[k] <= nearest + extra:
            if kept < cache_ids.shape[0]:
                cache_ids[kept] = ids[k]
            kept += 1
    cache_q[0], cache_q[1], cache_q[2] = px, py, pz
    cache_q[3] = float(kept) if kept <= cache_ids.shape[0] else -1.0
    cache_q[4] = extra
    return _emit(px, py, pz, band, same, tri, face_normals, edge_normals, vertex_normals, faces, around, n, ids, dist,
                 pts, out)  # fmt: skip
