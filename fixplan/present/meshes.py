"""Meshes and outlines of the shapes, pins, holes and bores, and the drawing positions of the locators, for the scene views.

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
    from fixplan.model import Bore, Fixture, Hole, Pin
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


def contact_anchors(fixture: Fixture, pose: Pose) -> tuple[FloatArray, FloatArray]:
    """Per name of the simulator (locators, then pins and bores): where its force is drawn, and its normal.

    A locator's tip (:func:`locator_tips`); a pin's or bore's nearest contact at ``pose`` (its point
    on the part, its normal into the part).
    """
    from fixplan.locating import insert_contacts

    tips, normals = locator_tips(fixture, pose)
    d = fixture.dimension
    extra_p, extra_n = [], []
    wp = fixture.workpiece
    per_owner = [insert_contacts(wp, pose, p) for p in fixture.pins]
    per_owner += [insert_contacts(wp, pose, b) for b in fixture.bores]
    for found in per_owner:
        if found:
            c = min(found, key=lambda c: c.gap_m)
            extra_p.append(c.point_world)
            extra_n.append(c.normal_world)
        else:  # no contact possible (the pin out of its hole): drawn at the origin, no normal
            extra_p.append(np.zeros(d))
            extra_n.append(np.zeros(d))
    if not extra_p:
        return tips, normals
    return np.vstack([tips, np.reshape(extra_p, (-1, d))]), np.vstack([normals, np.reshape(extra_n, (-1, d))])


def revolution_mesh(
    profile: Sequence[tuple[float, float]],
    origin: FloatArray,
    axis: FloatArray,
    e1: FloatArray,
    segments: int = 32,
    half_width: float | None = None,
) -> tuple[FloatArray, IntArray]:
    """A surface of revolution about ``axis`` through ``origin``: one ring per profile point ``(t, ρ)``.

    A point ``(t, ρ)`` at angle φ is ``origin + t axis + ρ (cos φ e1 + sin φ e2)``, ``e2 = axis × e1``;
    a ring of radius 0 is one vertex (a pole). ``half_width``: the section clipped to ``|y| ≤ half_width``
    along ``e2`` (a diamond pin's relief: flats, the lands left round about ``±e1``).
    """
    axis = np.asarray(axis, dtype=float)
    e1 = np.asarray(e1, dtype=float)
    e2 = np.cross(axis, e1)
    a = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    V: list[FloatArray] = []
    rings: list[list[int]] = []
    for t, rho in profile:
        centre = np.asarray(origin, dtype=float) + t * axis
        if rho <= 0.0:
            rings.append([len(V)] * segments)
            V.append(centre)
            continue
        x, y = rho * np.cos(a), rho * np.sin(a)
        if half_width is not None:
            y = np.clip(y, -half_width, half_width)
        rings.append(list(range(len(V), len(V) + segments)))
        V.extend(centre + np.outer(x, e1) + np.outer(y, e2))
    F = []
    for r0, r1 in zip(rings[:-1], rings[1:], strict=True):
        for k in range(segments):
            j = (k + 1) % segments
            for tri in ((r0[k], r0[j], r1[j]), (r0[k], r1[j], r1[k])):
                if len(set(tri)) == 3:  # a pole's fan: no degenerate triangles
                    F.append(tri)
    return np.array(V, dtype=float).reshape(-1, 3), np.array(F, dtype=np.int64).reshape(-1, 3)


def _normal_to(axis: FloatArray, prefer: FloatArray | None = None) -> FloatArray:
    """A unit vector normal to ``axis`` (along ``prefer``'s part normal to it when given)."""
    v = prefer if prefer is not None else np.eye(3)[int(np.argmin(np.abs(axis)))]
    v = np.asarray(v, dtype=float) - float(np.dot(v, axis)) * axis
    return v / np.linalg.norm(v)


def pin_mesh(pin: Pin, segments: int = 32) -> tuple[FloatArray, IntArray]:
    """A ``[[pin]]`` in the world frame: its side, tip chamfer and faces; a diamond pin with its relief's flats."""
    r, L, c = 0.5 * pin.diameter_m, pin.length_m, pin.chamfer_m
    profile = [(0.0, 0.0), (0.0, r), (L - c, r)] + ([(L, r - c)] if c > 0.0 else []) + [(L, 0.0)]
    axis = np.asarray(pin.axis_world, dtype=float)
    diamond = pin.land_direction_world is not None
    e1 = _normal_to(axis, pin.land_direction_world if diamond else None)
    return revolution_mesh(profile, pin.p_world, axis, e1, segments, 0.5 * pin.land_width_m if diamond else None)


def _bore_profile(radius: float, depth: float, chamfer: float, closed: bool) -> list[tuple[float, float]]:
    """A hole's wall going down from its mouth (``t`` = −depth): the mouth's chamfer, the wall, the bottom."""
    out = [(0.0, radius + chamfer)] + ([(-chamfer, radius)] if chamfer > 0.0 else []) + [(-depth, radius)]
    return out + ([(-depth, 0.0)] if closed else [])


def hole_mesh(hole: Hole, segments: int = 32) -> tuple[FloatArray, IntArray]:
    """A ``[[workpiece.hole]]``'s wall (and a blind hole's bottom) in the body frame: drawn with the part."""
    axis = np.asarray(hole.axis_body, dtype=float)
    profile = _bore_profile(0.5 * hole.diameter_m, hole.depth_m, hole.chamfer_m, not hole.through)
    return revolution_mesh(profile, hole.p_body, axis, _normal_to(axis), segments)


def bore_mesh(bore: Bore, segments: int = 32) -> tuple[FloatArray, IntArray]:
    """A ``[[bore]]``'s wall and bottom in the world frame."""
    axis = np.asarray(bore.axis_world, dtype=float)
    profile = _bore_profile(0.5 * bore.diameter_m, bore.depth_m, bore.chamfer_m, True)
    return revolution_mesh(profile, bore.p_world, axis, _normal_to(axis), segments)


def merge_meshes(*meshes: tuple[FloatArray, IntArray]) -> tuple[FloatArray, IntArray]:
    """One mesh of several: vertices stacked, each mesh's triangles shifted by the vertices before it."""
    V = [np.asarray(m[0], dtype=float).reshape(-1, 3) for m in meshes]
    offsets = np.cumsum([0] + [len(v) for v in V[:-1]])
    F = [np.asarray(m[1], dtype=np.int64).reshape(-1, 3) + o for m, o in zip(meshes, offsets, strict=True)]
    return np.vstack(V) if V else np.zeros((0, 3)), np.vstack(F) if F else np.zeros((0, 3), dtype=np.int64)


def part_mesh(fixture: Fixture) -> tuple[FloatArray, IntArray]:
    """The workpiece's mesh (body frame) with its holes' walls (3D): what moves with the part."""
    wp = fixture.workpiece
    return merge_meshes(shape_mesh(wp.shape), *(hole_mesh(h) for h in wp.holes))


def fixture_meshes(fixture: Fixture) -> dict[str, tuple[FloatArray, IntArray]]:
    """The fixture's pins and bores by name, in the world frame (3D; empty without them)."""
    out = {pin.name: pin_mesh(pin) for pin in fixture.pins}
    out.update({bore.name: bore_mesh(bore) for bore in fixture.bores})
    return out


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
