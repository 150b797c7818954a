"""The compiled mesh queries (:mod:`fixplan.geometry._mesh_kernels`) answer what the Python reference answers.

``Mesh.contacts`` runs the compiled kernel on the mesh's own AABB tree; ``Mesh.contacts_reference``
is the earlier Python path (coal's BVH for the candidates, Ericson's regions in Python, the
pseudo-normal sign in numpy). On seeded random points around a curved non-convex part (a torus),
a finely split box (ties on shared edges and vertices) and an L-bracket (two contacts in the
concave corner), both give the same contacts, in the same order, to 1e-12. The tree itself holds
every triangle once, and every box holds what is below it.
"""

from __future__ import annotations

import numpy as np
import pytest

from fixplan.geometry import Mesh
from fixplan.geometry.cells import box_cells, cell_surface, l_bracket_cells
from fixplan.geometry.shapes import Projection

TOL = 1e-12


def torus(major: int = 40, minor: int = 24, R: float = 0.05, r: float = 0.015) -> Mesh:
    """A closed torus about z: ``2 · major · minor`` triangles, curved and not convex."""
    u = 2.0 * np.pi * np.arange(major) / major
    v = 2.0 * np.pi * np.arange(minor) / minor
    U, W = np.meshgrid(u, v, indexing="ij")
    V = np.stack([(R + r * np.cos(W)) * np.cos(U), (R + r * np.cos(W)) * np.sin(U), r * np.sin(W)], axis=-1)
    idx = np.arange(major * minor).reshape(major, minor)
    a, b = idx, np.roll(idx, -1, axis=0)
    c, d = np.roll(b, -1, axis=1), np.roll(a, -1, axis=1)
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return Mesh(V.reshape(-1, 3), F)


def assert_same_contacts(got: list[Projection], want: list[Projection]) -> float:
    """The same number of contacts, each with the same distance, point and normal to :data:`TOL`; the worst error."""
    assert len(got) == len(want)
    worst = 0.0
    for g, w in zip(got, want, strict=True):
        err = max(
            abs(g.distance - w.distance),
            float(np.abs(g.point_body - w.point_body).max()),
            float(np.abs(g.normal_body - w.normal_body).max()),
        )
        assert err <= TOL, (g, w)
        worst = max(worst, err)
    return worst


def test_torus_random_points_match_the_reference(rng: np.random.Generator) -> None:
    mesh = torus()
    assert mesh.volume_m3 > 0.0
    points = rng.uniform(-0.075, 0.075, size=(300, 3)) * np.array([1.0, 1.0, 0.35])
    for p in points:
        assert_same_contacts(mesh.contacts(p), mesh.contacts_reference(p))
        assert_same_contacts([mesh.project(p)], mesh.contacts_reference(p, band_m=0.0))


def test_near_surface_points_with_a_wide_band_match_the_reference(rng: np.random.Generator) -> None:
    """Tips 1 mm inside to 5 mm outside the surface, and a band of 1 mm (several local minima)."""
    mesh = torus()
    tri = mesh.vertices[mesh.faces]
    k = rng.integers(0, tri.shape[0], size=200)
    w = rng.dirichlet(np.ones(3), size=200)
    on_surface = np.einsum("ij,ijk->ik", w, tri[k])
    points = on_surface + rng.uniform(-0.001, 0.005, size=(200, 1)) * mesh.face_normals[k]
    for p in points:
        for band in (None, 0.0, 1e-3):
            assert_same_contacts(mesh.contacts(p, band), mesh.contacts_reference(p, band))


def test_split_box_ties_on_edges_and_vertices_match_the_reference() -> None:
    """A grid of points that project onto shared edges and vertices (ties broken by triangle index)."""
    size = (0.2, 0.1, 0.05)
    mesh = Mesh(*cell_surface(*box_cells(size, 8)))
    axes = [np.linspace(-0.6 * s, 0.6 * s, 9) for s in size]
    for p in np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3):
        got = mesh.contacts(p)
        assert_same_contacts(got, mesh.contacts_reference(p))
        # and the primitive box's closed form: the distance to the box (outside) or its faces (inside)
        half = np.array(size) / 2.0
        outside = np.linalg.norm(np.maximum(np.abs(p) - half, 0.0))
        expected = outside if outside > 0.0 else -float((half - np.abs(p)).min())
        assert got[0].distance == pytest.approx(expected, abs=TOL)


def test_a_tip_in_the_l_corner_gets_both_faces_and_matches_the_reference(rng: np.random.Generator) -> None:
    mesh = Mesh(*cell_surface(*l_bracket_cells(0.1, 0.04, 0.06, 0.01)))
    corner = mesh.contacts(np.array([0.013, 0.02, 0.013]))
    assert [round(c.distance, 15) for c in corner] == [0.003, 0.003]
    assert sorted(tuple(np.round(c.normal_body, 15)) for c in corner) == [(0.0, 0.0, 1.0), (1.0, 0.0, 0.0)]
    for p in rng.uniform(-0.01, 0.11, size=(300, 3)):
        assert_same_contacts(mesh.contacts(p), mesh.contacts_reference(p))


def test_a_compiled_caller_gets_the_same_contacts_from_the_query_arrays(rng: np.random.Generator) -> None:
    """The engine's way in: the kernel on :attr:`Mesh.query_arrays` (as a numba step would call it)."""
    from fixplan.geometry import _mesh_kernels

    mesh = Mesh(*cell_surface(*l_bracket_cells(0.1, 0.04, 0.06, 0.01)))
    for p in rng.uniform(-0.01, 0.11, size=(50, 3)):
        out = np.zeros((8, 7))
        n = _mesh_kernels.contacts(*p.tolist(), 1e-6, mesh.same_point_m, *mesh.query_arrays, out)
        want = mesh.contacts(p)
        assert n == len(want)
        for row, w in zip(out[:n], want, strict=True):
            assert row[0] == w.distance and np.array_equal(row[1:4], w.point_body)
            assert np.array_equal(row[4:7], w.normal_body)


def test_more_contacts_than_the_first_buffer_holds() -> None:
    """The centre of a 12-triangle cube with a band of 1 m: one contact per face (6 > the 4 rows first tried)."""
    mesh = Mesh(*cell_surface(*box_cells((0.1, 0.1, 0.1), 1)))
    got = mesh.contacts(np.zeros(3), band_m=1.0)
    assert len(got) == 6
    assert all(c.distance == pytest.approx(-0.05, abs=TOL) for c in got)
    normals = sorted(tuple(np.round(c.normal_body, 12)) for c in got)
    assert normals == sorted(tuple(float(x) for x in s * e) for e in np.eye(3) for s in (1.0, -1.0))
    assert_same_contacts(got, mesh.contacts_reference(np.zeros(3), band_m=1.0))


def test_the_tree_holds_every_triangle_once_and_boxes_hold_their_children() -> None:
    mesh = torus()
    tri, _, _, _, _, _, boxes, nodes, order = mesh._kernel_arrays
    m = tri.shape[0]
    assert sorted(order.tolist()) == list(range(m))
    leaves = nodes[nodes[:, 3] > 0]
    assert leaves[:, 3].sum() == m and leaves[:, 3].max() <= mesh.settings.tree_leaf_triangles
    starts = np.sort(leaves[:, 2])
    assert starts.tolist() == np.cumsum(np.r_[0, leaves[np.argsort(leaves[:, 2]), 3][:-1]]).tolist()
    corners = tri.reshape(m, 3, 3)
    for k in range(nodes.shape[0]):
        left, right, start, count = nodes[k]
        lo, hi = boxes[k, :3], boxes[k, 3:]
        if count > 0:
            inside = corners[order[start : start + count]]
            assert np.all(inside.min(axis=(0, 1)) >= lo) and np.all(inside.max(axis=(0, 1)) <= hi)
        else:
            for child in (left, right):
                assert np.all(boxes[child, :3] >= lo) and np.all(boxes[child, 3:] <= hi)


def test_a_point_that_is_not_finite_is_refused() -> None:
    from fixplan.geometry.mesh import MeshError

    mesh = torus(8, 6)
    for bad in ([np.nan, 0.0, 0.0], [0.0, np.inf, 0.0]):
        with pytest.raises(MeshError, match="finite point"):
            mesh.contacts(np.array(bad))
    with pytest.raises(MeshError, match="band"):
        mesh.contacts(np.zeros(3), band_m=-1.0)
