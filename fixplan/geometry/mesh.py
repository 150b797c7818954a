"""A triangle-mesh part: a closed, manifold, non-self-intersecting surface and exact point queries.

Reading. :func:`parse_mesh` turns a file's bytes (STL binary or ASCII, OBJ, PLY, parsed by
trimesh from memory, so an OBJ never opens a material file) into a :class:`Mesh` in metres
(``units``: m, mm or in); the body frame is the file's own frame. A bad mesh raises
:class:`MeshError` with one line saying what is wrong. In order:

1. the file parses and has triangles (a point cloud or an empty file has none);
2. every vertex coordinate is finite;
3. duplicate vertices are merged (an STL stores each triangle's corners apart), and degenerate
   triangles (a repeated corner, or a sliver: twice the area ≤ ``degenerate_rel`` · longest
   edge²) are dropped; none left is an error;
4. closed: every edge is shared by exactly two triangles (one: open; more: non-manifold edge);
5. manifold at every vertex: the triangles around a vertex form one fan (two cones touching
   at a tip are refused): the triangle corners at a vertex, joined across shared edges, form
   one connected group;
6. orientation: inconsistent winding is repaired (trimesh's ``fix_normals``), and a surface
   facing inwards is turned outwards (positive volume); both are reported as notes;
7. not self-intersecting: the triangle pairs whose bounding boxes overlap (within a hair) come
   from a uniform grid (:func:`_box_pairs`, numpy); each pair is then tested exactly
   (floating-point orientation determinants): pairs sharing no vertex by segment–triangle
   crossings of their six edges (coplanar pairs in 2D), pairs sharing one vertex by whether the
   line where their planes meet leaves that vertex inside both triangles (coplanar: whether
   their corners' wedges overlap), pairs sharing an edge by whether they fold onto each other
   (coplanar, on one side of the edge). Touching counts as intersecting. Measured here: the whole
   check takes about 0.6 s for 10⁴ triangles and 2 s for 5·10⁴; coal's BVH of the mesh against
   itself found the candidate pairs of 2·10⁴ triangles in 0.9 s, but reading its 2.7·10⁵
   contacts back through Python doubled that, so the grid replaced it.

Queries. :meth:`Mesh.project` and :meth:`Mesh.contacts` are exact on the triangles and compiled
(:mod:`fixplan.geometry._mesh_kernels`, numba, ahead of time with the other kernels): the mesh's
own AABB tree (flat arrays, median splits, built once per mesh) gives every triangle within the
nearest distance plus the band; closest points on those triangles are Ericson's region tests
(Real-Time Collision Detection, section 5.1.5); the sign comes from angle-weighted pseudo-normals
(Bærentzen & Aanæs 2005) of the closest feature: the face's own normal in a face, the sum of the
two faces' normals on an edge, the angle-weighted sum at a vertex. :meth:`Mesh.contacts` returns
every local minimum of the distance within a band: a tip in a concave corner touches two faces.
A query near the surface of a 5·10⁴-triangle part takes about 12 µs from Python
(``benchmarks/run.py --only mesh``). :meth:`Mesh.contacts_reference` is the same query in Python
(coal's BVH gives the nearest triangle, an upper bound of the distance, then every triangle within
that distance, a sphere against the BVH): the tests' reference. coal's own signed distance is
not used (it is not exact when a sphere and the mesh overlap).

Mass properties (:func:`mass_properties`) come from the closed surface by the divergence theorem:
the signed tetrahedra each triangle spans with a reference point.
"""

from __future__ import annotations

import functools
import io
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import FixplanError
from fixplan.geometry.shapes import FloatArray, Projection, Shape
from fixplan.settings import DEFAULT, MeshSettings

IntArray = NDArray[np.int64]

MESH_SUFFIXES = {".stl": "stl", ".obj": "obj", ".ply": "ply"}
UNITS_M = {"m": 1.0, "mm": 1e-3, "in": 0.0254}
STL_HEADER_BYTES = 84  # 80-byte header + uint32 triangle count
STL_TRIANGLE_BYTES = 50

# Ericson's regions of a triangle (a, b, c) where the closest point lies
FACE, VERTEX_A, VERTEX_B, VERTEX_C, EDGE_AB, EDGE_BC, EDGE_CA = range(7)


class MeshError(FixplanError):
    """A mesh file is not a closed, manifold, non-self-intersecting triangle mesh (one-line reason)."""


def declared_stl_triangles(head: bytes, size_bytes: int) -> int | None:
    """The triangle count a binary STL's header declares, or None for a file that is not binary STL.

    A file is taken as binary when its size is the one its count implies, or when its first bytes
    are not all text (an ASCII STL is text; a binary one's free 80-byte header may be text too, but
    then its count's 4 bytes are not): so a count of 10⁷ is refused from 84 bytes, before the rest
    is read.
    """
    if len(head) < STL_HEADER_BYTES:
        return None
    count = int.from_bytes(head[80:84], "little")
    if STL_HEADER_BYTES + STL_TRIANGLE_BYTES * count == size_bytes:
        return count
    text = all(32 <= b < 127 or b in b"\t\r\n" for b in head)
    return None if text else count


def parse_mesh(
    data: bytes,
    file_type: str,
    *,
    units: str = "m",
    settings: MeshSettings = DEFAULT.mesh,
    max_triangles: int | None = None,
) -> Mesh:
    """A checked :class:`Mesh` from a file's bytes; its ``notes`` say what was repaired (module docstring).

    Raises
    ------
    MeshError
        The bytes are not a mesh of ``file_type``, or the mesh is not closed, manifold and free
        of self-intersections, or has no usable triangle.
    """
    vertices, faces = _read_triangles(data, file_type)
    if faces.shape[0] == 0:
        raise MeshError(
            f"no triangles: not a {file_type.upper()} mesh, or an empty one (expected a closed triangle mesh)"
        )
    return mesh_from_triangles(vertices, faces, units=units, settings=settings, max_triangles=max_triangles)


def mesh_from_triangles(
    vertices: FloatArray,
    faces: IntArray,
    *,
    units: str = "m",
    settings: MeshSettings = DEFAULT.mesh,
    max_triangles: int | None = None,
    read_notes: tuple[str, ...] = (),
) -> Mesh:
    """A checked :class:`Mesh` from triangles (a parsed file's, or a tessellated STEP part's): checks 2–7 of the module docstring.

    ``read_notes`` come first in the mesh's ``notes`` (what reading did, e.g. the tessellation).

    Raises
    ------
    MeshError
        The triangles are not a closed, manifold surface free of self-intersections, or none is usable.
    """
    vertices = np.asarray(vertices, dtype=float).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if faces.shape[0] == 0:
        raise MeshError("no triangles (expected a closed triangle mesh)")
    if max_triangles is not None and faces.shape[0] > max_triangles:
        raise MeshError(f"{faces.shape[0]} triangles (expected at most {max_triangles})")
    if not np.all(np.isfinite(vertices)):
        raise MeshError("non-finite vertex coordinates (NaN or infinity; expected finite numbers)")
    used = np.unique(faces)
    if used.size and (used.min() < 0 or used.max() >= vertices.shape[0]):
        raise MeshError("a triangle refers to a vertex that does not exist")
    vertices = vertices * UNITS_M[units]
    notes = list(read_notes)
    vertices, faces = _merge_vertices(vertices, faces)
    faces, dropped = _drop_degenerate(vertices, faces, settings)
    if faces.shape[0] == 0:
        raise MeshError("only degenerate triangles (zero area; expected a closed triangle mesh)")
    if dropped:
        notes.append(f"dropped {dropped} degenerate triangle(s) (zero area)")
    vertices, faces = _compact(vertices, faces)
    _check_closed_manifold(faces)
    faces, flipped = _orient(vertices, faces)
    if flipped:
        notes.append(flipped)
    mesh = Mesh(vertices, faces, settings=settings, notes=tuple(notes))
    pair = mesh.self_intersection()
    if pair is not None:
        i, j = pair
        raise MeshError(
            f"self-intersecting: triangles {i} and {j} cross or touch (expected a surface that meets itself only along shared edges)"
        )
    return mesh


def stl_bytes(vertices: FloatArray, faces: IntArray, *, ascii: bool = False, name: str = "part") -> bytes:
    """An STL file of the triangles: binary (float32 coordinates) or ASCII (every float64 digit, ``repr``)."""
    tri = np.asarray(vertices, dtype=float)[np.asarray(faces)]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(n, axis=1)
    n = n / np.where(length > 0.0, length, 1.0)[:, None]  # a degenerate triangle: normal 0
    if ascii:
        lines = [f"solid {name}"]
        for normal, corners in zip(n, tri, strict=True):
            lines.append("  facet normal " + " ".join(repr(float(x)) for x in normal))
            lines.append("    outer loop")
            lines += ["      vertex " + " ".join(repr(float(x)) for x in c) for c in corners]
            lines += ["    endloop", "  endfacet"]
        lines.append(f"endsolid {name}")
        return ("\n".join(lines) + "\n").encode()
    record = np.zeros(tri.shape[0], dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    record["n"], record["v"] = n, tri
    header = name.encode()[:80].ljust(80, b" ")
    return header + np.uint32(tri.shape[0]).tobytes() + record.tobytes()


# -- reading and cleaning ---------------------------------------------------------------------------
def _read_triangles(data: bytes, file_type: str) -> tuple[FloatArray, IntArray]:
    import trimesh

    try:
        loaded: Any = trimesh.load(io.BytesIO(data), file_type=file_type, process=False, force="mesh")
    except Exception as exc:  # trimesh's parsers raise anything from ValueError to struct.error
        reason = " ".join(str(exc).split())[:120] or type(exc).__name__
        raise MeshError(f"not a readable {file_type.upper()} mesh ({reason})") from None
    vertices = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), dtype=float).reshape(-1, 3)
    faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))), dtype=np.int64)
    if faces.size == 0:
        return vertices, np.zeros((0, 3), dtype=np.int64)
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise MeshError(f"not a triangle mesh (faces of shape {faces.shape})")
    return vertices, faces


def _merge_vertices(vertices: FloatArray, faces: IntArray) -> tuple[FloatArray, IntArray]:
    """Bit-identical vertices merged into one (STL repeats every corner per triangle)."""
    unique, inverse = np.unique(vertices, axis=0, return_inverse=True)
    return unique, inverse.reshape(-1)[faces]


def _drop_degenerate(vertices: FloatArray, faces: IntArray, settings: MeshSettings) -> tuple[IntArray, int]:
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    twice_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    longest2 = np.max([np.einsum("ij,ij->i", e, e) for e in (b - a, c - b, a - c)], axis=0)
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 2] == faces[:, 0])
    bad = repeated | (twice_area <= settings.degenerate_rel * longest2)
    return faces[~bad], int(bad.sum())


def _compact(vertices: FloatArray, faces: IntArray) -> tuple[FloatArray, IntArray]:
    """Vertices no triangle uses are removed."""
    used, inverse = np.unique(faces, return_inverse=True)
    return vertices[used], inverse.reshape(faces.shape)


def _edges(faces: IntArray) -> tuple[IntArray, IntArray, IntArray]:
    """``(edges (k,2) sorted, inverse (m,3): each face slot's edge, counts (k,))``; slots AB, BC, CA."""
    directed = faces[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2)
    low, high = directed.min(axis=1), directed.max(axis=1)
    n = int(faces.max()) + 1
    keys, inverse, counts = np.unique(low * n + high, return_inverse=True, return_counts=True)
    edges = np.stack(np.divmod(keys, n), axis=1)
    return edges, inverse.reshape(-1, 3), counts


def _check_closed_manifold(faces: IntArray) -> None:
    edges, slot_edge, counts = _edges(faces)
    if np.any(counts == 1):
        k = int(np.argmax(counts == 1))
        raise MeshError(
            f"open: {int((counts == 1).sum())} edge(s) belong to one triangle only, e.g. between vertices "
            f"{edges[k, 0]} and {edges[k, 1]} (expected a closed, watertight surface)"
        )
    if np.any(counts > 2):
        k = int(np.argmax(counts > 2))
        raise MeshError(
            f"non-manifold: {int((counts > 2).sum())} edge(s) shared by more than two triangles, e.g. between "
            f"vertices {edges[k, 0]} and {edges[k, 1]} (expected each edge in exactly two)"
        )
    # vertices: the corners (face, vertex) joined across every shared edge form one group per vertex
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    m = faces.shape[0]
    corner = np.arange(3 * m).reshape(m, 3)  # corner id of (face, slot)
    slots = [(0, 1), (1, 2), (2, 0)]
    rows, cols = [], []
    order = np.argsort(slot_edge.reshape(-1), kind="stable")
    pair = order.reshape(-1, 2)  # the two (face, slot) of each edge
    f1, s1 = np.divmod(pair[:, 0], 3)
    f2, s2 = np.divmod(pair[:, 1], 3)
    for end in (0, 1):
        # the vertex at this end of the edge, and its corner in each of the two faces
        v = faces[f1, np.array([slots[s][end] for s in range(3)])[s1]]
        c1 = corner[f1, np.array([slots[s][end] for s in range(3)])[s1]]
        c2 = corner[f2, np.argmax(faces[f2] == v[:, None], axis=1)]
        rows.append(c1)
        cols.append(c2)
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(r.size), (r, c)), shape=(3 * m, 3 * m))
    _, label = connected_components(graph, directed=False)
    groups = np.unique(np.stack([faces.reshape(-1), label], axis=1), axis=0)[:, 0]
    per_vertex = np.bincount(groups)
    if np.any(per_vertex > 1):
        v = int(np.argmax(per_vertex > 1))
        raise MeshError(
            f"non-manifold: {int((per_vertex > 1).sum())} vertex(es) where separate sheets meet at a point, "
            f"e.g. vertex {v} (expected the triangles around each vertex to form one fan)"
        )


def _orient(vertices: FloatArray, faces: IntArray) -> tuple[IntArray, str]:
    """Consistent winding, facing outwards (positive volume); a note when anything was turned.

    Two triangles wound alike traverse their shared edge in opposite directions. A breadth-first
    tree over the triangles (per connected part) fixes each one's flip from its parent's; an
    edge off the tree that still disagrees means a one-sided surface (refused). Each connected
    part with negative volume is then turned over.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, connected_components

    m = faces.shape[0]
    directed = faces[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2)
    _, slot_edge, _ = _edges(faces)
    pair = np.argsort(slot_edge.reshape(-1), kind="stable").reshape(-1, 2)  # closed: two slots per edge
    f1, f2 = pair[:, 0] // 3, pair[:, 1] // 3
    agree = directed[pair[:, 0], 0] != directed[pair[:, 1], 0]  # opposite traversal: wound alike
    graph = coo_matrix((np.ones(f1.size), (f1, f2)), shape=(m, m)).tocsr()
    count, label = connected_components(graph, directed=False)
    flip = np.zeros(m, dtype=bool)
    relation: dict[tuple[int, int], bool] = {}
    for a, b, same in zip(f1.tolist(), f2.tolist(), agree.tolist(), strict=True):
        relation[(a, b)] = relation[(b, a)] = not same
    for part in range(count):
        root = int(np.argmax(label == part))
        order, parent = breadth_first_order(graph, root, directed=False, return_predecessors=True)
        for f in order[1:].tolist():
            flip[f] = flip[parent[f]] ^ relation[(f, int(parent[f]))]
    if np.any((flip[f1] ^ flip[f2]) == agree):
        raise MeshError("one-sided: the triangles cannot be wound consistently (expected the surface of a solid)")
    notes = []
    out = faces.copy()
    if flip.any():
        out[flip] = out[flip][:, ::-1]
        notes.append(
            f"repaired inconsistent triangle orientation ({int(min(flip.sum(), m - flip.sum()))} triangle(s) turned)"
        )
    turned = 0
    for part in range(count):
        sel = label == part
        if mass_properties(vertices, out[sel])[0] < 0.0:
            out[sel] = out[sel][:, ::-1]
            turned += 1
    if turned:
        notes.append("turned the surface outwards (its triangles faced inwards)")
    return out, "; ".join(notes)


# -- mass properties ------------------------------------------------------------------------------
def mass_properties(vertices: FloatArray, faces: IntArray) -> tuple[float, FloatArray, FloatArray]:
    """``(volume [m³], centre of volume (3,), ∫(r·r I − r rᵀ) dV about it (3,3) [m⁵])`` of a closed surface.

    The divergence theorem: the solid is the signed sum of the tetrahedra each triangle spans
    with a reference point (the vertices' mean, for digits); a tetrahedron (0, a, b, c) has
    ``∫ x xᵀ dV = det/120 · (Σ vᵢvᵢᵀ + s sᵀ)``, ``s = a + b + c``, ``det = a·(b × c)``.
    Multiply the last by the density for the inertia about the centre of mass.
    """
    ref = vertices.mean(axis=0)
    a, b, c = (vertices[faces[:, k]] - ref for k in range(3))
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    volume = float(det.sum() / 6.0)
    s = a + b + c
    first = (det[:, None] * s).sum(axis=0) / 24.0  # ∫ x dV
    second = (
        np.einsum("i,ij,ik->jk", det, a, a)
        + np.einsum("i,ij,ik->jk", det, b, b)
        + np.einsum("i,ij,ik->jk", det, c, c)
        + np.einsum("i,ij,ik->jk", det, s, s)
    ) / 120.0
    if volume == 0.0:
        return 0.0, ref, np.zeros((3, 3))
    com = first / volume
    covariance = second - volume * np.outer(com, com)  # about the centre of volume
    inertia = np.trace(covariance) * np.eye(3) - covariance
    return volume, ref + com, (inertia + inertia.T) / 2.0


# -- closest points -------------------------------------------------------------------------------
def closest_on_triangles(p: FloatArray, a: FloatArray, b: FloatArray, c: FloatArray) -> tuple[FloatArray, IntArray]:
    """Closest points of triangles ``(a, b, c)`` (each ``(m, 3)``) to the point ``p``, and their regions.

    Ericson, Real-Time Collision Detection, section 5.1.5: the Voronoi regions of the vertices, then the
    edges, then the face; the region codes are :data:`FACE`, :data:`VERTEX_A` ... :data:`EDGE_CA`.
    In the face the point is the orthogonal projection onto the plane (``p − ((p − a)·n) n``), so a
    point over a face gets it to the digits of the face's plane.
    """
    ab, ac = b - a, c - a
    ap, bp, cp = p - a, p - b, p - c

    def dot(u: FloatArray, v: FloatArray) -> FloatArray:
        return np.einsum("ij,ij->i", u, v)

    d1, d2 = dot(ab, ap), dot(ac, ap)
    d3, d4 = dot(ab, bp), dot(ac, bp)
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    m = a.shape[0]
    region = np.full(m, FACE, dtype=np.int64)
    point = np.empty_like(a)
    todo = np.ones(m, dtype=bool)

    def take(mask: Any, code: int, value: FloatArray) -> None:
        sel = todo & mask
        region[sel] = code
        point[sel] = value[sel]
        todo[sel] = False

    with np.errstate(divide="ignore", invalid="ignore"):
        take((d1 <= 0) & (d2 <= 0), VERTEX_A, a)
        take((d3 >= 0) & (d4 <= d3), VERTEX_B, b)
        take((vc <= 0) & (d1 >= 0) & (d3 <= 0), EDGE_AB, a + (d1 / (d1 - d3))[:, None] * ab)
        take((d6 >= 0) & (d5 <= d6), VERTEX_C, c)
        take((vb <= 0) & (d2 >= 0) & (d6 <= 0), EDGE_CA, a + (d2 / (d2 - d6))[:, None] * ac)
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        take((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), EDGE_BC, b + w[:, None] * (c - b))
    n = np.cross(ab, ac)
    n /= np.linalg.norm(n, axis=1)[:, None]
    point[todo] = p - dot(ap, n)[todo, None] * n[todo]
    return point, region


def _box_pairs(lo: FloatArray, hi: FloatArray, max_entries_per_box: int = 64, min_cell_rel: float = 0.0) -> IntArray:
    """Pairs ``(i, j)``, i < j, of axis-aligned boxes that overlap: a uniform grid, then the exact box test.

    The cell is the boxes' 90th-percentile extent, at least ``min_cell_rel`` times the largest
    (doubled until the boxes cover at most ``max_entries_per_box`` cells each on average); each box is entered in every cell it covers,
    boxes sharing a cell are candidate pairs.
    """
    m = lo.shape[0]
    if m < 2:
        return np.zeros((0, 2), dtype=np.int64)
    extent = (hi - lo).max(axis=1)
    cell = max(float(np.quantile(extent, 0.9)), float(extent.max()) * min_cell_rel, float(np.finfo(float).tiny))
    origin = lo.min(axis=0)
    while True:
        first = np.floor((lo - origin) / cell).astype(np.int64)
        last = np.floor((hi - origin) / cell).astype(np.int64)
        span = last - first + 1
        count = np.prod(span, axis=1)
        if count.sum() <= max_entries_per_box * m or count.max() == 1:
            break
        cell *= 2.0
    box = np.repeat(np.arange(m), count)
    k = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)  # index within the box's cells
    sy, sz = span[box, 1], span[box, 2]
    ix = first[box, 0] + k // (sy * sz)
    iy = first[box, 1] + (k // sz) % sy
    iz = first[box, 2] + k % sz
    dims = last.max(axis=0) + 1
    key = (ix * dims[1] + iy) * dims[2] + iz
    order = np.argsort(key, kind="stable")
    key, box = key[order], box[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    sizes = np.diff(np.r_[starts, key.size])
    end = np.repeat(starts + sizes, sizes)  # one past the last of each entry's group
    partners = end - np.arange(key.size) - 1
    a = np.repeat(np.arange(key.size), partners)
    b = a + 1 + (np.arange(partners.sum()) - np.repeat(np.cumsum(partners) - partners, partners))
    i, j = box[a], box[b]
    i, j = np.minimum(i, j), np.maximum(i, j)
    pair_key = np.sort(i * m + j)
    unique = pair_key[np.r_[True, pair_key[1:] != pair_key[:-1]]]  # (np.unique hashes: slower here)
    i, j = np.divmod(unique, m)
    keep = (i != j) & np.all(lo[i] <= hi[j], axis=1) & np.all(lo[j] <= hi[i], axis=1)
    return np.stack([i[keep], j[keep]], axis=1)


def _closest_scalar(p: tuple[float, float, float], tri: Any) -> tuple[tuple[float, float, float], int]:
    """:func:`closest_on_triangles` for one triangle (3×3 nested lists) in plain floats (fewer calls)."""
    (ax, ay, az), (bx, by, bz), (cx, cy, cz) = tri
    px, py, pz = p
    abx, aby, abz, acx, acy, acz = bx - ax, by - ay, bz - az, cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1, d2 = abx * apx + aby * apy + abz * apz, acx * apx + acy * apy + acz * apz
    if d1 <= 0 and d2 <= 0:
        return (ax, ay, az), VERTEX_A
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3, d4 = abx * bpx + aby * bpy + abz * bpz, acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0 and d4 <= d3:
        return (bx, by, bz), VERTEX_B
    vc = d1 * d4 - d3 * d2
    if vc <= 0 and d1 >= 0 and d3 <= 0:
        v = d1 / (d1 - d3)
        return (ax + v * abx, ay + v * aby, az + v * abz), EDGE_AB
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5, d6 = abx * cpx + aby * cpy + abz * cpz, acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0 and d5 <= d6:
        return (cx, cy, cz), VERTEX_C
    vb = d5 * d2 - d1 * d6
    if vb <= 0 and d2 >= 0 and d6 <= 0:
        w = d2 / (d2 - d6)
        return (ax + w * acx, ay + w * acy, az + w * acz), EDGE_CA
    va = d3 * d6 - d5 * d4
    if va <= 0 and (d4 - d3) >= 0 and (d5 - d6) >= 0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return (bx + w * (cx - bx), by + w * (cy - by), bz + w * (cz - bz)), EDGE_BC
    nx, ny, nz = aby * acz - abz * acy, abz * acx - abx * acz, abx * acy - aby * acx
    norm = math.sqrt(nx * nx + ny * ny + nz * nz)
    nx, ny, nz = nx / norm, ny / norm, nz / norm
    h = apx * nx + apy * ny + apz * nz
    return (px - h * nx, py - h * ny, pz - h * nz), FACE


def _orient3(a: FloatArray, b: FloatArray, c: FloatArray, d: FloatArray) -> FloatArray:
    """``det[b − a, c − a, d − a]`` row by row: > 0 when d is on the side of (a, b, c)'s normal."""
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a)


def _segments_cross_triangles(p: FloatArray, q: FloatArray, a: FloatArray, b: FloatArray, c: FloatArray) -> Any:
    """Segment pq meets triangle abc (closed), row by row, for segments not lying in the plane."""
    o1, o2 = _orient3(a, b, c, p), _orient3(a, b, c, q)
    straddles = (o1 * o2 <= 0.0) & ~((o1 == 0.0) & (o2 == 0.0))
    s1, s2, s3 = _orient3(p, q, a, b), _orient3(p, q, b, c), _orient3(p, q, c, a)
    inside = ((s1 >= 0) & (s2 >= 0) & (s3 >= 0)) | ((s1 <= 0) & (s2 <= 0) & (s3 <= 0))
    return straddles & inside


def _coplanar_overlap(A: FloatArray, B: FloatArray) -> Any:
    """Coplanar triangle pairs ``A``, ``B`` (each ``(k, 3, 3)``) overlap or touch, row by row.

    2D tests in each plane's dominant projection: an edge of one properly crosses an edge of the
    other, or a corner of one lies in the other (closed).
    """
    n = np.cross(A[:, 1] - A[:, 0], A[:, 2] - A[:, 0])
    drop = np.argmax(np.abs(n), axis=1)
    keep = np.array([[1, 2], [0, 2], [0, 1]])[drop]  # (k, 2)
    a2 = np.take_along_axis(A, keep[:, None, :], axis=2)  # (k, 3, 2)
    b2 = np.take_along_axis(B, keep[:, None, :], axis=2)

    def cross2(o: FloatArray, u: FloatArray, v: FloatArray) -> FloatArray:
        return (u[:, 0] - o[:, 0]) * (v[:, 1] - o[:, 1]) - (u[:, 1] - o[:, 1]) * (v[:, 0] - o[:, 0])

    def inside(pt: FloatArray, tri: FloatArray) -> Any:
        s = [cross2(tri[:, i], tri[:, (i + 1) % 3], pt) for i in range(3)]
        return ((s[0] >= 0) & (s[1] >= 0) & (s[2] >= 0)) | ((s[0] <= 0) & (s[1] <= 0) & (s[2] <= 0))

    hit = np.zeros(A.shape[0], dtype=bool)
    for i in range(3):
        p, q = a2[:, i], a2[:, (i + 1) % 3]
        for j in range(3):
            r, t = b2[:, j], b2[:, (j + 1) % 3]
            hit |= (cross2(p, q, r) * cross2(p, q, t) < 0) & (cross2(r, t, p) * cross2(r, t, q) < 0)
        hit |= inside(a2[:, i], b2) | inside(b2[:, i], a2)
    return hit


@functools.cache
def _contacts_kernel() -> Any:
    """The compiled query (ahead of time when built, else numba's JIT; :mod:`fixplan.aot`)."""
    from fixplan import aot

    return aot.kernel("fixplan.geometry._mesh_kernels", "contacts")


# -- the shape ------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Mesh(Shape):
    """A closed triangle mesh in its body frame (the file's frame), metres, outward winding.

    Built by :func:`parse_mesh` (which checks it); the arrays are read-only copies.
    """

    vertices: FloatArray  # (n, 3) [m]
    faces: IntArray  # (m, 3) vertex indices, counter-clockwise seen from outside
    settings: MeshSettings = field(default=DEFAULT.mesh, repr=False)
    notes: tuple[str, ...] = ()  # what loading repaired (validate --verbose prints them)
    dimension = 3
    name = "mesh"

    def __post_init__(self) -> None:
        v = np.array(self.vertices, dtype=float).reshape(-1, 3)
        f = np.array(self.faces, dtype=np.int64).reshape(-1, 3)
        v.setflags(write=False)
        f.setflags(write=False)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)

    def __getstate__(self) -> dict[str, Any]:
        """The defining fields only: the cached arrays and coal's BVH are rebuilt where it is unpickled."""
        return {k: self.__dict__[k] for k in ("vertices", "faces", "settings", "notes")}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)

    # -- derived arrays (computed once) -----------------------------------------------------------
    @functools.cached_property
    def _triangles(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        V, F = self.vertices, self.faces
        return V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]

    @functools.cached_property
    def face_normals(self) -> FloatArray:
        """Outward unit normals of the triangles ``(m, 3)``."""
        a, b, c = self._triangles
        n = np.cross(b - a, c - a)
        return n / np.linalg.norm(n, axis=1)[:, None]

    @functools.cached_property
    def _edge_normals(self) -> FloatArray:
        """Each triangle's three edge pseudo-normals (slots AB, BC, CA): the sum of the two faces' normals."""
        edges, slot_edge, _ = _edges(self.faces)
        total = np.zeros((edges.shape[0], 3))
        for k in range(3):
            np.add.at(total, slot_edge[:, k], self.face_normals)
        return total[slot_edge]  # (m, 3, 3)

    @functools.cached_property
    def _vertex_normals(self) -> FloatArray:
        """Angle-weighted pseudo-normals of the vertices (Bærentzen & Aanæs)."""
        a, b, c = self._triangles
        total = np.zeros_like(self.vertices)
        for k, (p, u, v) in enumerate(((a, b, c), (b, c, a), (c, a, b))):
            e1, e2 = u - p, v - p
            cosine = np.einsum("ij,ij->i", e1, e2) / (np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1))
            angle = np.arccos(np.clip(cosine, -1.0, 1.0))
            np.add.at(total, self.faces[:, k], angle[:, None] * self.face_normals)
        return total

    @functools.cached_property
    def _vertex_faces(self) -> tuple[IntArray, IntArray]:
        """CSR of the triangles around each vertex: ``(offsets (n+1,), faces)``."""
        flat = self.faces.reshape(-1)
        order = np.argsort(flat, kind="stable")
        offsets = np.concatenate([[0], np.cumsum(np.bincount(flat, minlength=self.vertices.shape[0]))])
        return offsets, order // 3

    @functools.cached_property
    def bvh(self) -> Any:
        """The OBBRSS bounding-volume hierarchy of the triangles, built by coal (the broad phase)."""
        import coal

        model = coal.BVHModelOBBRSS()
        model.beginModel(self.faces.shape[0], self.vertices.shape[0])
        model.addVertices(np.ascontiguousarray(self.vertices))
        model.addTriangles(np.ascontiguousarray(self.faces))
        model.endModel()
        return model

    @functools.cached_property
    def _mass(self) -> tuple[float, FloatArray, FloatArray]:
        return mass_properties(self.vertices, self.faces)

    # -- Shape ------------------------------------------------------------------------------------
    @property
    def volume_m3(self) -> float:
        return self._mass[0]

    @property
    def com_body(self) -> FloatArray:
        return self._mass[1].copy()

    def inertia_body(self, mass_kg: float) -> FloatArray:
        volume, _, unit = self._mass
        return mass_kg / volume * unit

    @functools.cached_property
    def bounding_radius(self) -> float:  # type: ignore[override]
        return float(np.linalg.norm(self.vertices, axis=1).max())

    @functools.cached_property
    def _scale_m(self) -> float:
        return float(np.ptp(self.vertices, axis=0).max())

    def project(self, p_body: FloatArray) -> Projection:
        return self.contacts(p_body, band_m=0.0)[0]

    def contacts(self, p_body: FloatArray, band_m: float | None = None) -> list[Projection]:
        """Every local minimum of the distance from ``p_body`` to the surface within ``band_m`` of the nearest.

        Nearest first. One per face, edge or vertex region (a tip over a convex edge: one; a tip
        in a concave corner between two faces: two). ``band_m`` defaults to
        ``MeshSettings.contact_band_m``. Computed by the compiled kernel
        (:func:`fixplan.geometry._mesh_kernels.contacts`) on the mesh's own AABB tree;
        :meth:`contacts_reference` is the same query in Python (coal's BVH for the candidates).
        """
        x, y, z = np.asarray(p_body, dtype=float).reshape(3).tolist()
        band = float(self.settings.contact_band_m if band_m is None else band_m)
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z) and math.isfinite(band) and band >= 0.0):
            raise MeshError(f"a point query needs a finite point and band ≥ 0, got {[x, y, z]} and {band}")
        arrays = self._kernel_arrays
        out = np.empty((4, 7))
        found = _contacts_kernel()(x, y, z, band, self._same_m, *arrays, out)
        while found < 0:  # too few rows: again with room for all
            out = np.empty((2 * out.shape[0] - found, 7))
            found = _contacts_kernel()(x, y, z, band, self._same_m, *arrays, out)
        rows = out[:found]  # this call's own array: the projections' views of it are theirs alone
        return [Projection(float(row[0]), row[1:4], row[4:7]) for row in rows]

    @functools.cached_property
    def _same_m(self) -> float:
        """Two points this close are one [m] (``MeshSettings.same_point_rel`` of the part's size)."""
        return float(self.settings.same_point_rel * self._scale_m)

    @property
    def query_arrays(self) -> tuple[Any, ...]:
        """The arrays a numba kernel passes to :func:`fixplan.geometry._mesh_kernels.contacts` after ``(px, py, pz, band, same)``.

        In order (read-only, C-contiguous, built once per mesh): ``tri (m, 9)`` corners,
        ``face_normals (m, 3)``, ``edge_normals (m, 9)`` (slots AB, BC, CA), ``vertex_normals (n, 3)``,
        ``faces (m, 3)``, ``around`` (vertex → triangles, CSR offsets then indices), and the tree's
        ``boxes (k, 6)``, ``nodes (k, 4)``, ``order (m,)``. ``same`` is :attr:`same_point_m`. A
        compiled caller (the engine's step) queries the part without coming back to Python.
        """
        return self._kernel_arrays

    @property
    def same_point_m(self) -> float:
        """Two closest points this close are one contact [m] (the kernel's ``same`` argument)."""
        return self._same_m

    @functools.cached_property
    def _kernel_arrays(self) -> tuple[Any, ...]:
        """The compiled query's arrays (read-only, C-contiguous): triangles, pseudo-normals, the tree."""
        from fixplan import aot

        m = self.faces.shape[0]
        tri = np.ascontiguousarray(self.vertices[self.faces].reshape(m, 9))
        offsets, around = self._vertex_faces
        boxes, nodes, order = np.empty((2 * m, 6)), np.empty((2 * m, 4), dtype=np.int64), np.empty(m, dtype=np.int64)
        build = aot.kernel("fixplan.geometry._mesh_kernels", "build_tree")
        count = int(build(tri, self.settings.tree_leaf_triangles, boxes, nodes, order))
        arrays = (
            tri,
            np.ascontiguousarray(self.face_normals),
            np.ascontiguousarray(self._edge_normals.reshape(m, 9)),
            np.ascontiguousarray(self._vertex_normals),
            np.ascontiguousarray(self.faces),
            np.concatenate([offsets, around]).astype(np.int64),
            boxes[:count].copy(),
            nodes[:count].copy(),
            order,
        )
        for a in arrays:
            a.setflags(write=False)
        return arrays

    def contacts_reference(self, p_body: FloatArray, band_m: float | None = None) -> list[Projection]:
        """:meth:`contacts` in Python and numpy, coal's BVH for the candidates (the tests' reference)."""
        p = np.asarray(p_body, dtype=float).reshape(3)
        band = self.settings.contact_band_m if band_m is None else band_m
        ids = self._candidates(p, band)
        pt = (float(p[0]), float(p[1]), float(p[2]))
        corners = self._corner_lists
        closest = [_closest_scalar(pt, corners[i]) for i in ids.tolist()]
        points = np.array([c[0] for c in closest])
        regions = [c[1] for c in closest]
        dist = np.sqrt(((p - points) ** 2).sum(axis=1))
        nearest = float(dist.min())
        same = self.settings.same_point_rel * self._scale_m
        found: list[tuple[float, Projection]] = []
        for k in np.argsort(dist, kind="stable").tolist():
            if dist[k] > nearest + band + same:
                break
            if any(float(np.linalg.norm(points[k] - prj.point_body)) <= same for _, prj in found):
                continue
            if regions[k] != FACE and not self._local_minimum(int(ids[k]), regions[k], points[k], ids, points):
                continue
            found.append((float(dist[k]), self._signed(p, int(ids[k]), regions[k], points[k], float(dist[k]))))
            if band == 0.0:
                break
        return [prj for _, prj in found]

    @functools.cached_property
    def _corner_lists(self) -> list[Any]:
        """Each triangle's corners as nested lists of floats (for :func:`_closest_scalar`)."""
        return self.vertices[self.faces].tolist()

    @functools.cached_property
    def _queries(self) -> tuple[Any, ...]:
        """The objects of a coal point query, made once: transforms, requests, the probe sphere."""
        import coal

        request = coal.CollisionRequest()
        request.num_max_contacts = self.faces.shape[0]
        request.enable_contact = False
        probe = coal.Sphere(self.settings.same_point_rel * self._scale_m)
        return coal.Transform3s(), coal.Transform3s(), coal.DistanceRequest(), request, probe

    def _candidates(self, p: FloatArray, band_m: float) -> IntArray:
        """The triangles within (nearest distance + band) of ``p``: coal's BVH, distance then a sphere.

        coal's nearest triangle gives an upper bound of the distance (the exact distance to that
        triangle); every triangle that a ball of that radius (plus the band) touches is a candidate.
        """
        import coal

        here, identity, distance_request, collision_request, probe = self._queries
        here.setTranslation(p)
        result = coal.DistanceResult()
        coal.distance(self.bvh, identity, probe, here, distance_request, result)
        first = int(result.b1) if 0 <= int(result.b1) < self.faces.shape[0] else 0
        point, _ = _closest_scalar((float(p[0]), float(p[1]), float(p[2])), self._corner_lists[first])
        upper = math.dist(point, p.tolist())
        reach = upper + band_m + 2.0 * self.settings.same_point_rel * self._scale_m
        found = coal.CollisionResult()
        coal.collide(self.bvh, identity, coal.Sphere(reach), here, collision_request, found)
        ids = {int(ct.b1) for ct in found.getContacts()}
        ids.add(first)
        return np.fromiter(sorted(ids), dtype=np.int64)

    def _feature_faces(self, tri: int, region: int) -> IntArray:
        """The triangles that share the closest feature (an edge or a vertex) of triangle ``tri``."""
        F = self.faces
        offsets, around = self._vertex_faces
        if region in (VERTEX_A, VERTEX_B, VERTEX_C):
            v = int(F[tri, region - VERTEX_A])
            return around[offsets[v] : offsets[v + 1]]
        u, w = {EDGE_AB: (0, 1), EDGE_BC: (1, 2), EDGE_CA: (2, 0)}[region]
        v0, v1 = int(F[tri, u]), int(F[tri, w])
        fan = around[offsets[v0] : offsets[v0 + 1]]
        return fan[np.any(F[fan] == v1, axis=1)]

    def _local_minimum(self, tri: int, region: int, point: FloatArray, ids: IntArray, points: FloatArray) -> bool:
        """A closest point on an edge or vertex is a local minimum when every triangle there has it as its own."""
        same = self.settings.same_point_rel * self._scale_m
        at = {int(i): k for k, i in enumerate(ids)}
        for f in self._feature_faces(tri, region):
            k = at.get(int(f))
            if k is None or float(np.linalg.norm(points[k] - point)) > same:
                return False
        return True

    def _signed(self, p: FloatArray, tri: int, region: int, point: FloatArray, dist: float) -> Projection:
        """The signed distance and outward normal at a closest point (pseudo-normal sign)."""
        if region == FACE:
            n = self.face_normals[tri]
            return Projection(float((p - self._triangles[0][tri]) @ n), point.copy(), n.copy())
        if region in (VERTEX_A, VERTEX_B, VERTEX_C):
            pseudo = self._vertex_normals[self.faces[tri, region - VERTEX_A]]
        else:
            pseudo = self._edge_normals[tri, {EDGE_AB: 0, EDGE_BC: 1, EDGE_CA: 2}[region]]
        sign = 1.0 if float((p - point) @ pseudo) >= 0.0 else -1.0
        if dist > self.settings.same_point_rel * self._scale_m:
            normal = sign * (p - point) / dist
        else:
            normal = pseudo / np.linalg.norm(pseudo)
        return Projection(sign * dist, point.copy(), normal)

    # -- checks -----------------------------------------------------------------------------------
    def self_intersection(self) -> tuple[int, int] | None:
        """A pair of triangles that cross or touch other than along shared edges and vertices, or None.

        The candidate pairs are those whose bounding boxes overlap (within a hair), found on a
        uniform grid (:func:`_box_pairs`); each is then tested exactly (module docstring).
        """
        F, V = self.faces, self.vertices
        tri = V[F]
        pad = self.settings.same_point_rel * self._scale_m
        pairs = _box_pairs(tri.min(axis=1) - pad, tri.max(axis=1) + pad, min_cell_rel=self.settings.grid_cell_min_rel)
        if pairs.size == 0:
            return None
        fa, fb = F[pairs[:, 0]], F[pairs[:, 1]]
        shared = (fa[:, :, None] == fb[:, None, :]).sum(axis=(1, 2))
        for count, test in ((0, self._cross_apart), (1, self._cross_at_vertex), (2, self._fold_at_edge)):
            sel = pairs[shared == count]
            if sel.size:
                hit = test(sel, V, F)
                if hit.any():
                    i, j = sel[int(np.argmax(hit))]
                    return int(i), int(j)
        return None

    def _coplanar(self, A: FloatArray, B: FloatArray) -> Any:
        tol = self.settings.coplanar_rel * self._scale_m**3
        return np.all([np.abs(_orient3(A[:, 0], A[:, 1], A[:, 2], B[:, k])) <= tol for k in range(3)], axis=0)

    def _cross_apart(self, pairs: IntArray, V: FloatArray, F: IntArray) -> Any:
        A, B = V[F[pairs[:, 0]]], V[F[pairs[:, 1]]]  # (k, 3, 3)
        hit = np.zeros(pairs.shape[0], dtype=bool)
        for X, Y in ((A, B), (B, A)):
            for i in range(3):
                hit |= _segments_cross_triangles(X[:, i], X[:, (i + 1) % 3], Y[:, 0], Y[:, 1], Y[:, 2])
        flat = self._coplanar(A, B) & ~hit
        if flat.any():
            hit[flat] = _coplanar_overlap(A[flat], B[flat])
        return hit

    def _cross_at_vertex(self, pairs: IntArray, V: FloatArray, F: IntArray) -> Any:
        """Two triangles sharing vertex v meet beyond it when a direction from v lies in both wedges.

        Not coplanar: the line where their planes meet, both ways from v. Coplanar: an edge of
        one strictly inside the other's wedge.
        """
        fa, fb = F[pairs[:, 0]], F[pairs[:, 1]]
        rows = np.arange(pairs.shape[0])
        ia = np.argmax(np.any(fa[:, :, None] == fb[:, None, :], axis=2), axis=1)
        ib = np.argmax(np.any(fb[:, :, None] == fa[:, None, :], axis=2), axis=1)
        v = V[fa[rows, ia]]
        ea = [V[fa[rows, (ia + s) % 3]] - v for s in (1, 2)]
        eb = [V[fb[rows, (ib + s) % 3]] - v for s in (1, 2)]
        na, nb = np.cross(ea[0], ea[1]), np.cross(eb[0], eb[1])
        tol = self.settings.wedge_rel

        def dot(u: FloatArray, w: FloatArray) -> FloatArray:
            return np.einsum("ij,ij->i", u, w)

        def lowest(d: FloatArray, e: list[FloatArray], n: FloatArray) -> FloatArray:
            """The smaller of d's coordinates along the wedge's edges (d in the wedge's plane)."""
            den = dot(np.cross(e[0], e[1]), n)
            return np.minimum(dot(np.cross(d, e[1]), n), dot(np.cross(e[0], d), n)) / den

        line = np.cross(na, nb)
        size = np.linalg.norm(line, axis=1)
        flat = size <= self.settings.coplanar_rel * np.linalg.norm(na, axis=1) * np.linalg.norm(nb, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            d = line / np.where(flat, 1.0, size)[:, None]
            hit = np.zeros(pairs.shape[0], dtype=bool)
            for sign in (1.0, -1.0):
                hit |= ~flat & (lowest(sign * d, ea, na) >= -tol) & (lowest(sign * d, eb, nb) >= -tol)
            for e, other, n in ((eb, ea, na), (ea, eb, nb)):
                for x in e:
                    unit = x / np.linalg.norm(x, axis=1)[:, None]
                    hit |= flat & (lowest(unit, other, n) > tol)
        return hit

    def _fold_at_edge(self, pairs: IntArray, V: FloatArray, F: IntArray) -> Any:
        """Two triangles sharing an edge overlap when coplanar with their third corners on one side."""
        fa, fb = F[pairs[:, 0]], F[pairs[:, 1]]
        rows = np.arange(pairs.shape[0])
        ia = np.argmin(np.any(fa[:, :, None] == fb[:, None, :], axis=2), axis=1)  # A's corner not in B
        ib = np.argmin(np.any(fb[:, :, None] == fa[:, None, :], axis=2), axis=1)
        p, q = V[fa[rows, (ia + 1) % 3]], V[fa[rows, (ia + 2) % 3]]
        ni, nj = np.cross(q - p, V[fa[rows, ia]] - p), np.cross(q - p, V[fb[rows, ib]] - p)
        lin = np.linalg.norm(np.cross(ni, nj), axis=1)
        flat = lin <= self.settings.coplanar_rel * np.linalg.norm(ni, axis=1) * np.linalg.norm(nj, axis=1)
        return flat & (np.einsum("ij,ij->i", ni, nj) > 0.0)


__all__ = [
    "MESH_SUFFIXES",
    "UNITS_M",
    "Mesh",
    "MeshError",
    "closest_on_triangles",
    "declared_stl_triangles",
    "mass_properties",
    "mesh_from_triangles",
    "parse_mesh",
    "stl_bytes",
]
