"""Collision-only bodies (a floor, a base plate, the fixture's body) against the workpiece.

A fixed plane or box meets a convex workpiece first at a vertex (box, rectangle, polygon), on a
rim (cylinder) or at the point of a ball nearest to it (sphere, disk). So the workpiece is seen
by an obstacle as a few *collision points* in its body frame, each with a radius: the vertices
(radius 0; a mesh part's too: exact against a plane, against a box only where a vertex of the
part is the deepest point), ``rim_points`` points on each rim of a cylinder (radius 0; the rims' inscribed
polygons, exact where a vertex of them is the lowest point), the centre of a sphere or disk
(radius = its radius: exact against a plane). A collision point at ``x`` (world) with radius
``ρ`` has the gap ``distance(x) − ρ`` to the obstacle, and the obstacle pushes it along the
obstacle's outward normal there.

Obstacle frames: ``R_world_obstacle``, ``o_world``. A plane (2D: a line) has its origin on the
plane and its last axis along the normal, towards the free side; a box (2D: a rectangle) is
centred on its origin with half extents ``half`` along its axes. The compiled twin of
:func:`obstacle_gap` is :func:`fixplan.engine.detect.obstacle_query3` (and ``obstacle_query2``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from fixplan.geometry.mesh import Mesh
from fixplan.geometry.shapes import Box, Cylinder, Disk, Polygon, Rectangle, Shape, Sphere

FloatArray = NDArray[np.float64]

PLANE, BOX = 0, 1  # obstacle kind codes (the engine's too): a plane or line, a box or rectangle


def collision_points(shape: Shape, rim_points: int) -> tuple[FloatArray, FloatArray]:
    """The workpiece's collision points ``(points_body (n, d), radii (n,))`` (module docstring)."""
    if isinstance(shape, Box | Rectangle):
        half = np.asarray(shape.half, dtype=float)
        d = half.shape[0]
        signs = np.array(np.meshgrid(*([[-1.0, 1.0]] * d), indexing="ij")).reshape(d, -1).T
        return signs * half, np.zeros(signs.shape[0])
    if isinstance(shape, Polygon):
        V = shape.array.copy()
        return V, np.zeros(V.shape[0])
    if isinstance(shape, Mesh):  # a polyhedron meets a plane first at a vertex
        V = np.array(shape.vertices)
        return V, np.zeros(V.shape[0])
    if isinstance(shape, Sphere | Disk):
        return np.zeros((1, shape.dimension)), np.array([shape.radius])
    if isinstance(shape, Cylinder):
        phi = 2.0 * np.pi * np.arange(rim_points) / rim_points
        ring = np.stack([shape.radius * np.cos(phi), shape.radius * np.sin(phi)], axis=1)
        h = shape.length / 2.0
        pts = np.concatenate(
            [np.column_stack([ring, np.full(rim_points, -h)]), np.column_stack([ring, np.full(rim_points, h)])]
        )
        return pts, np.zeros(pts.shape[0])
    raise TypeError(f"no collision points for {type(shape).__name__}")  # pragma: no cover


def obstacle_gap(
    kind: int, R_world_obstacle: FloatArray, o_world: FloatArray, half: FloatArray, x_world: FloatArray, radius: float
) -> tuple[float, FloatArray, FloatArray]:
    """Gap of a collision point to an obstacle: ``(gap, normal_world, contact point on the part)``.

    The normal is the obstacle's outward normal (the direction in which it pushes the part).
    """
    R = np.asarray(R_world_obstacle, dtype=float)
    local = R.T @ (np.asarray(x_world, dtype=float) - np.asarray(o_world, dtype=float))
    d = local.shape[0]
    if kind == PLANE:
        dist = float(local[d - 1])
        m = np.zeros(d)
        m[d - 1] = 1.0
    else:
        h = np.asarray(half, dtype=float)
        q = np.abs(local) - h
        outside = np.maximum(q, 0.0)
        n_out = float(np.linalg.norm(outside))
        if n_out > 0.0:
            dist = n_out
            m = np.sign(local) * outside / n_out
        else:
            i = int(np.argmax(q))
            dist = float(q[i])
            m = np.zeros(d)
            m[i] = 1.0 if local[i] >= 0.0 else -1.0
    n = R @ m
    return dist - radius, n, np.asarray(x_world, dtype=float) - radius * n


def polytope_overlap_m(verts_a: FloatArray, axes_a: FloatArray, verts_b: FloatArray, axes_b: FloatArray) -> float:
    """Depth of overlap of two convex polytopes (world vertices, unit face normals): ≤ 0 when they are apart.

    The separating-axis test: the least overlap of the two vertex sets' projections over the face
    normals of both and (3D) the cross products of their edge directions (for boxes, their axes).
    """
    axes = [*axes_a, *axes_b]
    if verts_a.shape[1] == 3:
        for a in axes_a:
            for b in axes_b:
                c = np.cross(a, b)
                if np.linalg.norm(c) > 1e-12:  # parallel axes: no new direction
                    axes.append(c / np.linalg.norm(c))
    depth = np.inf
    for ax in axes:
        pa, pb = verts_a @ ax, verts_b @ ax
        depth = min(depth, float(min(pa.max() - pb.min(), pb.max() - pa.min())))
    return depth


def plane_frame(point: FloatArray, normal: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``(R_world_obstacle, o_world)`` of a plane (2D: a line) through ``point`` with unit ``normal``."""
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    if n.shape[0] == 2:
        return np.column_stack([[n[1], -n[0]], n]), np.asarray(point, dtype=float)
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    t1 = a - (a @ n) * n
    t1 /= np.linalg.norm(t1)
    return np.column_stack([t1, np.cross(n, t1), n]), np.asarray(point, dtype=float)


__all__ = ["BOX", "PLANE", "collision_points", "obstacle_gap", "plane_frame", "polytope_overlap_m"]
