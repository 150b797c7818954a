"""Meshes and outlines of the shapes, and the drawing positions of the locators, for the scene views.

The scene page (:mod:`fixplan.present.scene`) and the live app (:mod:`fixplan.interactive.app`)
draw with these. Vertices are in the body frame unless named ``_world``; :func:`points_world`
moves them by ``T_world_body``. A locator's *tip* is the point of its sphere nearest the
workpiece, ``p + ρ n``, with ``n`` the contact normal at that pose (from the locator into the
workpiece); at contact it is the contact point.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import InputError
from fixplan.geometry.mesh import Mesh
from fixplan.geometry.shapes import Box, Cylinder, Disk, Polygon, Rectangle, Shape, Sphere

if TYPE_CHECKING:
    from fixplan.model import Fixture
    from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def box_mesh(half: Sequence[float]) -> tuple[FloatArray, IntArray]:
    """The 8 corners (body frame) and 12 outward-oriented triangles of a box of half extents ``half``."""
    hx, hy, hz = (float(h) for h in half)
    V = np.array([[sx * hx, sy * hy, sz * hz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    # corner index = 4 i_x + 2 i_y + i_z (i = 0 for −, 1 for +)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]  # -x +x -y +y -z +z
    F = np.array([t for a, b, c, e in quads for t in ((a, b, c), (a, c, e))], dtype=np.int64)
    return V, F


def cylinder_mesh(radius: float, length: float, segments: int = 32) -> tuple[FloatArray, IntArray]:
    """A closed cylinder, axis along body z: two rings of ``segments`` vertices and the two cap centres."""
    a = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.stack([radius * np.cos(a), radius * np.sin(a)], axis=1)
    h = length / 2.0
    V = np.vstack(
        [np.column_stack([ring, np.full(segments, -h)]), np.column_stack([ring, np.full(segments, h)]), [[0, 0, -h]]]
    )
    V = np.vstack([V, [[0.0, 0.0, h]]])
    bottom, top = 2 * segments, 2 * segments + 1
    F = []
    for k in range(segments):
        j = (k + 1) % segments
        F += [(k, j, segments + j), (k, segments + j, segments + k), (bottom, j, k), (top, segments + k, segments + j)]
    return V, np.array(F, dtype=np.int64)


def sphere_mesh(radius: float, rings: int = 12, segments: int = 24) -> tuple[FloatArray, IntArray]:
    """A UV sphere: two poles and ``rings − 1`` rings of ``segments`` vertices."""
    V = [[0.0, 0.0, radius]]
    for i in range(1, rings):
        th = np.pi * i / rings
        for k in range(segments):
            ph = 2.0 * np.pi * k / segments
            V.append([radius * np.sin(th) * np.cos(ph), radius * np.sin(th) * np.sin(ph), radius * np.cos(th)])
    V.append([0.0, 0.0, -radius])
    south = len(V) - 1
    F = []

    def at(i: int, k: int) -> int:
        return 1 + (i - 1) * segments + k % segments

    for k in range(segments):
        F.append((0, at(1, k), at(1, k + 1)))
        F.append((south, at(rings - 1, k + 1), at(rings - 1, k)))
        for i in range(1, rings - 1):
            F += [(at(i, k), at(i + 1, k), at(i + 1, k + 1)), (at(i, k), at(i + 1, k + 1), at(i, k + 1))]
    return np.array(V), np.array(F, dtype=np.int64)


def shape_mesh(shape: Shape) -> tuple[FloatArray, IntArray]:
    """Vertices (body frame) and triangles of a 3D shape."""
    if isinstance(shape, Box):
        return box_mesh(tuple(float(h) for h in shape.half))
    if isinstance(shape, Cylinder):
        return cylinder_mesh(shape.radius, shape.length)
    if isinstance(shape, Sphere):
        return sphere_mesh(shape.radius)
    if isinstance(shape, Mesh):  # the part's own triangles, as loaded (metres, outward winding)
        return np.array(shape.vertices, dtype=float), np.array(shape.faces, dtype=np.int64)
    raise InputError(f"no mesh for a {shape.name} workpiece (expected box, cylinder, sphere or mesh)")


def shape_outline(shape: Shape, segments: int = 64) -> FloatArray:
    """The outline of a 2D shape, counter-clockwise vertices in the body frame (not closed)."""
    if isinstance(shape, Rectangle):
        hx, hy = shape.half
        return np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    if isinstance(shape, Disk):
        a = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
        return shape.radius * np.stack([np.cos(a), np.sin(a)], axis=1)
    if isinstance(shape, Polygon):
        return shape.array.copy()
    raise InputError(f"no outline for a {shape.name} workpiece (expected rectangle, disk or polygon)")


def points_world(pose: Pose, points_body: FloatArray) -> FloatArray:
    """Body-frame points (rows) moved to the world frame by ``T_world_body``."""
    return np.asarray(points_body, dtype=float) @ pose.R_world_body.T + pose.p_world


def locator_tips(fixture: Fixture, pose: Pose) -> tuple[FloatArray, FloatArray]:
    """Per locator (fixture order): the tip ``p + ρ n`` and the contact normal ``n`` at ``pose``."""
    from fixplan.locating import locator_contact

    tips, normals = [], []
    for loc in fixture.locators:
        c = locator_contact(fixture.workpiece, pose, loc)
        tips.append(loc.p_world + loc.radius_m * c.normal_world)
        normals.append(c.normal_world)
    d = fixture.dimension
    return np.array(tips).reshape(-1, d), np.array(normals).reshape(-1, d)
