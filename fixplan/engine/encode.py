"""Shapes as the compiled engine reads them: a kind code and parameter arrays.

The engine's hot loop cannot call Python shape objects, so :func:`encode` turns each shape into
a kind code and a parameter array, answered by :mod:`.detect`'s closed-form queries. A module
without numba, so that :class:`~fixplan.engine.simulator.Simulator` can encode a shape when its
kernels come from :mod:`fixplan.aot`'s extension.

Codes and parameters (``params``; ``verts``/``edge_normals`` only for polygons):

- ``BOX`` (box or rectangle): half extents (3 or 2 numbers);
- ``BALL`` (sphere or disk): radius;
- ``CYLINDER``: radius, half length (axis = body z);
- ``POLYGON``: vertices (n × 2, counter-clockwise) and outward edge normals (n × 2).
"""

from __future__ import annotations

import numpy as np

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
