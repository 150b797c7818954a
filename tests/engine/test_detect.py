"""The compiled detection kernels answer exactly what the shape classes answer."""

import numpy as np
import pytest

from fixplan.engine.detect import project
from fixplan.engine.encode import encode
from fixplan.geometry import Box, Cylinder, Disk, Polygon, Rectangle, Sphere

SHAPES = [
    Box((0.2, 0.1, 0.05)),
    Cylinder(0.04, 0.12),
    Sphere(0.05),
    Rectangle((0.2, 0.1)),
    Disk(0.05),
    Polygon(((0.0, 0.0), (0.2, 0.0), (0.15, 0.1), (0.02, 0.08))),
]


@pytest.mark.parametrize("shape", SHAPES, ids=lambda s: s.name)
def test_compiled_projection_matches_shape(shape, rng):
    kind, params, V, N = encode(shape)
    d = shape.dimension
    pts = rng.normal(size=(300, d)) * shape.bounding_radius
    # points exactly on faces too
    ref_pts = [shape.project(p).point_body for p in pts[:50]]
    for p in list(pts) + ref_pts:
        ref = shape.project(np.asarray(p, dtype=float))
        point, normal = np.empty(d), np.empty(d)
        dist = project(kind, params, V, N, np.asarray(p, dtype=float), point, normal)
        assert dist == pytest.approx(ref.distance, abs=1e-14)
        assert np.allclose(point, ref.point_body, atol=1e-14)
        assert np.allclose(normal, ref.normal_body, atol=1e-12)
