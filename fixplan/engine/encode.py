"""Shapes as the compiled engine reads them: a kind code and parameter arrays.

The engine's hot loop cannot call Python shape objects, so :func:`encode` turns each shape into
a kind code and a parameter array, answered by :mod:`.detect`'s closed-form queries. A module
without numba, so that :class:`~fixplan.engine.simulator.Simulator` can encode a shape when its
kernels come from :mod:`fixplan.aot`'s extension.

Codes and parameters (``params``; ``verts``/``edge_normals`` only for polygons):

- ``BOX`` (box or rectangle): half extents (3 or 2 numbers);
- ``BALL`` (sphere or disk): radius;
- ``CYLINDER``: radius, half length (axis = body z);
- ``POLYGON``: vertices (n × 2, counter-clockwise) and outward edge normals (n × 2);
- ``MESH``: no parameters. The step's shape queries never see a mesh part: its locators' contacts
  are detected each step by the compiled mesh step, which hands them to the step as slots
  (:mod:`.mesh_slots`, :mod:`._mesh_slot_kernels`).

Collision-only bodies (:func:`encode_obstacles`): one row per obstacle, ``[kind, origin (d),
R_world_obstacle row-major (d²), half extents (d)]`` (kind 0: plane or line, 1: box or
rectangle; a plane's half extents are unused), and one row per collision point of the part
against one obstacle, ``[point (d, body frame), radius, obstacle row]``
(:mod:`fixplan.geometry.collision`). No obstacle: arrays with no rows, of the same rank and width.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from fixplan.geometry import Box, Cylinder, Disk, Polygon, Rectangle, Shape, Sphere
from fixplan.geometry.collision import BOX as OBSTACLE_BOX
from fixplan.geometry.collision import PLANE as OBSTACLE_PLANE
from fixplan.geometry.collision import collision_points

if TYPE_CHECKING:
    from fixplan.model import Fixture

BOX, BALL, CYLINDER, POLYGON, MESH = 0, 1, 2, 3, 4


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
    if shape.name == "mesh":  # never queried by the kernels: its contacts come as slots (.mesh_slots)
        return MESH, np.zeros(3), empty, empty
    raise TypeError(f"no compiled query for {type(shape).__name__}")  # pragma: no cover


def encode_obstacles(fixture: Fixture, rim_points: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(obs, slots, mu)``: the fixture's collision-only bodies, the part's collision points against each, their μ."""
    d = fixture.dimension
    obs = np.zeros((len(fixture.obstacles), 1 + 2 * d + d * d))
    for j, ob in enumerate(fixture.obstacles):
        half = ob.half_m if ob.half_m.size == d else np.zeros(d)
        code = OBSTACLE_PLANE if ob.is_plane else OBSTACLE_BOX
        obs[j] = np.concatenate([[code], ob.o_world, np.asarray(ob.R_world_obstacle).reshape(-1), half])
    if not fixture.obstacles:
        return obs, np.zeros((0, d + 2)), np.zeros(0)
    pts, radii = collision_points(fixture.workpiece.shape, rim_points)
    n = pts.shape[0]
    slots = np.concatenate([np.column_stack([pts, radii, np.full(n, float(j))]) for j in range(len(fixture.obstacles))])
    mu = np.repeat([ob.friction for ob in fixture.obstacles], n)
    return np.ascontiguousarray(obs), np.ascontiguousarray(slots), mu
