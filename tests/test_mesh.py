"""Mesh parts: mass properties, exact gaps and normals, several contacts in a concave corner, bad meshes.

Closed forms: a box's and an extruded L's volume, centre of mass and inertia (sums of boxes with
the parallel-axis theorem), and the primitive :class:`~fixplan.geometry.Box`'s projection (its
face, edge and corner regions) for the same box as a mesh.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from fixplan.cli import main
from fixplan.errors import FixtureError
from fixplan.fixture import load
from fixplan.geometry import Box, Mesh
from fixplan.geometry.cells import box_cells, cell_surface, l_bracket_cells
from fixplan.geometry.mesh import MeshError, closest_on_triangles, mass_properties, parse_mesh, stl_bytes
from fixplan.geometry.step import step_available
from fixplan.limits import MAX_MESH_BYTES, MAX_MESH_TRIANGLES

SIZE = (0.2, 0.1, 0.05)


def box_mesh(n: int = 1, size: tuple[float, float, float] = SIZE) -> Mesh:
    V, F = cell_surface(*box_cells(size, n))
    return parse_mesh(stl_bytes(V, F, ascii=True), "stl")


# -- mass properties -----------------------------------------------------------------------------
def test_box_mass_properties_match_the_closed_form() -> None:
    a, b, c = SIZE
    for n in (1, 5):
        V, F = cell_surface(*box_cells(SIZE, n))
        volume, com, unit = mass_properties(V, F)
        assert volume == pytest.approx(a * b * c, rel=1e-12)
        assert np.abs(com).max() <= 1e-12 * a
        closed = a * b * c / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
        np.testing.assert_allclose(unit, closed, rtol=1e-12, atol=1e-12 * np.abs(closed).max())


def test_extruded_l_mass_properties_match_the_closed_form() -> None:
    # L: base 0.1 × 0.01 (x, z) and wall 0.01 × 0.05 above it at x in [0, 0.01]; 0.04 along y
    L, W, H, T = 0.1, 0.04, 0.06, 0.01
    V, F = cell_surface(*l_bracket_cells(L, W, H, T))
    volume, com, unit = mass_properties(V, F)
    boxes = [((0.0, 0.0, 0.0), (L, W, T)), ((0.0, 0.0, T), (T, W, H - T))]  # (corner, size)
    vols = [s[0] * s[1] * s[2] for _, s in boxes]
    centres = [np.array(o) + np.array(s) / 2.0 for o, s in boxes]
    v_total = sum(vols)
    c_total = sum(v * c for v, c in zip(vols, centres, strict=True)) / v_total
    closed = np.zeros((3, 3))
    for v, (_, s), c in zip(vols, boxes, centres, strict=True):
        r = c - c_total
        own = v / 12.0 * np.diag([s[1] ** 2 + s[2] ** 2, s[0] ** 2 + s[2] ** 2, s[0] ** 2 + s[1] ** 2])
        closed += own + v * (r @ r * np.eye(3) - np.outer(r, r))
    assert volume == pytest.approx(v_total, rel=1e-12)
    np.testing.assert_allclose(com, c_total, rtol=1e-12)
    np.testing.assert_allclose(unit, closed, rtol=1e-12, atol=1e-12 * np.abs(closed).max())
    assert abs(unit[0, 2]) > 1e-3 * abs(unit[0, 0])  # the L has a product of inertia: it was checked


# -- exact geometry ------------------------------------------------------------------------------
def test_closest_point_regions_of_one_triangle() -> None:
    a, b, c = np.array([[0.0, 0, 0]]), np.array([[1.0, 0, 0]]), np.array([[0.0, 1, 0]])
    cases = [  # point, closest, region (Ericson: 0 face, 1-3 vertices a b c, 4-6 edges ab bc ca)
        ((0.2, 0.2, 0.5), (0.2, 0.2, 0.0), 0),
        ((-1.0, -1.0, 0.3), (0.0, 0.0, 0.0), 1),
        ((2.0, -0.5, 0.0), (1.0, 0.0, 0.0), 2),
        ((-0.5, 2.0, 0.0), (0.0, 1.0, 0.0), 3),
        ((0.5, -1.0, 1.0), (0.5, 0.0, 0.0), 4),
        ((1.0, 1.0, -1.0), (0.5, 0.5, 0.0), 5),
        ((-1.0, 0.5, 0.0), (0.0, 0.5, 0.0), 6),
    ]
    for p, closest, region in cases:
        point, reg = closest_on_triangles(np.array(p), a, b, c)
        np.testing.assert_allclose(point[0], closest, atol=1e-15)
        assert reg[0] == region


@pytest.mark.parametrize("n", [1, 4])
def test_gaps_points_and_normals_match_the_primitive_box(n: int) -> None:
    """Faces, edges and corners, inside and outside: the mesh's projection is the box's to 1e-12."""
    mesh, box = box_mesh(n), Box(SIZE)
    rng = np.random.default_rng(23)
    half = np.array(SIZE) / 2.0
    points = [rng.uniform(-1.6, 1.6, 3) * half for _ in range(300)]  # every region outside, and inside
    points += [rng.uniform(-0.9, 0.9, 3) * half for _ in range(100)]
    inside = outside = 0
    for p in points:
        q, r = mesh.project(p), box.project(p)
        assert q.distance == pytest.approx(r.distance, abs=1e-12)
        np.testing.assert_allclose(q.point_body, r.point_body, atol=1e-12)
        np.testing.assert_allclose(q.normal_body, r.normal_body, atol=1e-12)
        inside += q.distance < 0
        outside += q.distance > 0
    assert inside >= 100 and outside >= 200


def test_edge_and_corner_points_are_exact_with_their_closed_forms() -> None:
    mesh = box_mesh(3)
    a, b, c = np.array(SIZE) / 2.0
    p_edge = np.array([a + 0.03, b + 0.04, 0.01])  # beyond the +x+y edge: distance 0.05 along (3, 4, 0)/5
    q = mesh.project(p_edge)
    assert q.distance == pytest.approx(0.05, abs=1e-12)
    np.testing.assert_allclose(q.normal_body, [0.6, 0.8, 0.0], atol=1e-12)
    p_corner = np.array([a + 0.02, -b - 0.02, c + 0.01])
    q = mesh.project(p_corner)
    assert q.distance == pytest.approx(0.03, abs=1e-12)
    np.testing.assert_allclose(q.normal_body, np.array([2.0, -2.0, 1.0]) / 3.0, atol=1e-12)
    np.testing.assert_allclose(q.point_body, [a, -b, c], atol=1e-12)


def test_a_tip_in_the_l_corner_touches_two_faces() -> None:
    L, W, H, T = 0.1, 0.04, 0.06, 0.01
    V, F = cell_surface(*l_bracket_cells(L, W, H, T))
    mesh = parse_mesh(stl_bytes(V, F, ascii=True), "stl")
    rho = 0.004
    centre = np.array([T + rho, W / 2.0, T + rho])  # a ball of radius rho resting in the concave corner
    contacts = mesh.contacts(centre)
    assert len(contacts) == 2
    normals = sorted(tuple(np.round(c.normal_body, 12)) for c in contacts)
    assert normals == [(0.0, 0.0, 1.0), (1.0, 0.0, 0.0)]
    for c in contacts:
        assert c.distance == pytest.approx(rho, abs=1e-12)
    # off the bisector one face is nearer: one contact within the band, the other 1 mm farther
    assert len(mesh.contacts(centre + np.array([0.001, 0.0, 0.0]))) == 1
    assert len(mesh.contacts(centre + np.array([0.001, 0.0, 0.0]), band_m=0.002)) == 2
    # over the convex corner of the wall's top: one contact (the edge), not two faces
    top = np.array([T + 0.003, W / 2.0, H + 0.004])
    assert len(mesh.contacts(top)) == 1
    assert mesh.project(top).distance == pytest.approx(0.005, abs=1e-12)


# -- bad meshes ------------------------------------------------------------------------------------
FIXTURE = """format = 1
[scene]
name = "mesh"
[workpiece]
shape = "mesh"
file = "{file}"
units = "{units}"
mass = 1.0
start = {{ position = [0.1, 0.05, 0.025] }}
[[locator]]
name = "B1"
position = [0.05, 0.03, -0.001]
friction = 0.3
"""


def write_fixture(folder: Path, file: str, data: bytes | None, units: str = "m") -> Path:
    if data is not None:
        (folder / file).write_bytes(data)
    path = folder / "f.toml"
    text = FIXTURE.format(file=file, units=units)
    if file.endswith(".step"):  # a STEP file states its own unit
        text = text.replace(f'units = "{units}"\n', "")
    path.write_text(text)
    return path


def mesh_issue(path: Path) -> str:
    with pytest.raises(FixtureError) as info:
        load(path)
    (issue,) = info.value.issues
    assert issue.key == "workpiece.file"
    return issue.message


def box_stl(**kw: bool) -> bytes:
    V, F = cell_surface(*box_cells(SIZE, 1))
    return stl_bytes(V, F, **kw)


def test_a_closed_box_loads_in_every_unit(tmp_path: Path) -> None:
    V, F = cell_surface(*box_cells((200.0, 100.0, 50.0), 1))
    path = write_fixture(tmp_path, "box.stl", stl_bytes(V, F), units="mm")
    mesh = load(path).workpiece.shape
    assert isinstance(mesh, Mesh)
    assert mesh.volume_m3 == pytest.approx(0.001, rel=1e-12)
    V, F = cell_surface(*box_cells((200.0 / 25.4, 100.0 / 25.4, 50.0 / 25.4), 1))
    path = write_fixture(tmp_path, "box.stl", stl_bytes(V, F, ascii=True), units="in")
    assert load(path).workpiece.shape.volume_m3 == pytest.approx(0.001, rel=1e-12)  # type: ignore[attr-defined]


def test_obj_and_ply_give_the_same_part(tmp_path: Path) -> None:
    import trimesh

    V, F = cell_surface(*l_bracket_cells(0.1, 0.04, 0.06, 0.01))
    reference = mass_properties(V, F)
    for suffix in ("obj", "ply"):
        data = trimesh.Trimesh(V, F, process=False).export(file_type=suffix)
        raw = data if isinstance(data, bytes) else data.encode()
        mesh = load(write_fixture(tmp_path, f"l.{suffix}", raw)).workpiece.shape
        # trimesh writes OBJ with 8 decimals and PLY in float32: the part to those digits
        assert mesh.volume_m3 == pytest.approx(reference[0], rel=1e-6)  # type: ignore[attr-defined]


def _open_box() -> bytes:
    V, F = cell_surface(*box_cells(SIZE, 1))
    return stl_bytes(V, F[:-1])


def _edge_of_three() -> bytes:
    # a box and a fin: one extra triangle pair hung on an edge -> that edge has four triangles
    V, F = cell_surface(*box_cells(SIZE, 1))
    a, b = V[F[0, 0]], V[F[0, 1]]
    fin = np.array([a, b, (a + b) / 2.0 + [0.0, 0.0, 0.3]])
    V2 = np.vstack([V, fin[2:]])
    i, j = F[0, 0], F[0, 1]
    k = V.shape[0]
    return stl_bytes(V2, np.vstack([F, [[i, j, k], [j, i, k]]]))


def _bowtie() -> bytes:
    V, F = cell_surface(*box_cells(SIZE, 1))
    return stl_bytes(np.vstack([V, V + np.array(SIZE)]), np.vstack([F, F + V.shape[0]]))


def _overlapping() -> bytes:
    V, F = cell_surface(*box_cells(SIZE, 1))
    return stl_bytes(np.vstack([V, V + 0.01]), np.vstack([F, F + V.shape[0]]))


def _degenerate() -> bytes:
    tri = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])
    return stl_bytes(tri, np.array([[0, 1, 2]]), ascii=True)


BAD = [
    ("open.stl", _open_box, "open: 3 edge(s) belong to one triangle only"),
    ("fin.stl", _edge_of_three, "non-manifold: 1 edge(s) shared by more than two triangles"),
    ("bowtie.stl", _bowtie, "non-manifold: 1 vertex(es) where separate sheets meet at a point"),
    ("overlap.stl", _overlapping, "self-intersecting: triangles"),
    ("flat.stl", _degenerate, "only degenerate triangles"),
    ("empty.stl", lambda: b"", "no triangles"),
    ("words.stl", lambda: b"this is not a mesh\n" * 10, "no triangles: not a STL mesh"),
    ("nan.obj", lambda: b"v 0 0 0\nv 1 0 0\nv nan 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n", "non-finite"),
    (
        "part.step",
        lambda: b"ISO-10303-21;",
        "is not a readable STEP file"
        if step_available()
        else "is a STEP file: reading STEP needs the optional CAD extra",
    ),
    ("part.iges", lambda: b"x", "has the suffix '.iges' (expected a mesh file: .stl, .obj, .ply; or .step, .stp with"),
    ("missing.stl", None, "cannot read: no such file"),
]


@pytest.mark.parametrize(("file", "make", "message"), BAD, ids=[b[0] for b in BAD])
def test_bad_meshes_are_refused_naming_workpiece_file(tmp_path: Path, file: str, make, message: str) -> None:
    path = write_fixture(tmp_path, file, None if make is None else make())
    assert message in mesh_issue(path)


def test_paths_a_directory_a_fifo_and_outside_the_folder(tmp_path: Path) -> None:
    (tmp_path / "dir.stl").mkdir()
    assert "is a directory" in mesh_issue(write_fixture(tmp_path, "dir.stl", None))
    os.mkfifo(tmp_path / "pipe.stl")
    assert "is not a regular file but a named pipe" in mesh_issue(write_fixture(tmp_path, "pipe.stl", None))
    inner = tmp_path / "inner"
    inner.mkdir()
    (tmp_path / "box.stl").write_bytes(box_stl())
    assert "outside the fixture file's folder" in mesh_issue(write_fixture(inner, "../box.stl", None))
    assert "absolute path" in mesh_issue(write_fixture(inner, str(tmp_path / "box.stl"), None))
    (inner / "link.stl").symlink_to(tmp_path / "box.stl")
    assert "outside the fixture file's folder" in mesh_issue(write_fixture(inner, "link.stl", None))
    (inner / "parts").mkdir()
    (inner / "parts" / "box.stl").write_bytes(box_stl())
    assert isinstance(load(write_fixture(inner, "parts/box.stl", None)).workpiece.shape, Mesh)  # a subfolder is fine


def test_a_header_declaring_ten_million_triangles_is_refused_before_reading(tmp_path: Path) -> None:
    header = b"\0" * 80 + np.uint32(10_000_000).tobytes()
    path = write_fixture(tmp_path, "huge.stl", header + b"\0" * 50)  # the rest is not there
    assert (
        f"declares 10000000 triangles in its binary STL header (expected at most {MAX_MESH_TRIANGLES})"
        in mesh_issue(path)
    )
    with open(tmp_path / "sparse.stl", "wb") as fh:  # the whole file's size, as a sparse file
        fh.write(header)
        fh.truncate(84 + 50 * 10_000_000)
    assert f"larger than the limit of {MAX_MESH_BYTES} bytes" in mesh_issue(write_fixture(tmp_path, "sparse.stl", None))


def test_orientation_is_repaired_and_validate_verbose_says_so(tmp_path: Path, capsys) -> None:
    V, F = cell_surface(*box_cells((200.0, 100.0, 50.0), 1))
    F = F.copy()
    F[3] = F[3][::-1]  # one triangle wound the other way
    folder = tmp_path
    (folder / "box.stl").write_bytes(stl_bytes(V, F))
    text = (Path(__file__).resolve().parents[1] / "problems" / "box-3-2-1.toml").read_text()
    text = text.replace('shape = "box"\nsize = [0.20, 0.10, 0.05]', 'shape = "mesh"\nfile = "box.stl"\nunits = "mm"')
    text = "\n".join(line for line in text.splitlines() if not line.startswith("face = "))
    (folder / "f.toml").write_text(text)
    assert main(["validate", "--verbose", str(folder / "f.toml")]) == 0
    out = capsys.readouterr().out
    assert "mesh: 12 triangles, 8 vertices, volume 0.001 m³" in out
    assert "mesh: repaired inconsistent triangle orientation" in out
    assert "goal (computed): position [0.1, 0.05, 0.025] m, rpy [0, 0, 0] deg" in out


def test_the_engine_commands_take_a_mesh_part(tmp_path: Path, capsys) -> None:
    """The box of box-3-2-1 as a mesh rests on its locators in the engine and is drawn from its triangles."""
    (tmp_path / "box.stl").write_bytes(box_stl())
    text = (Path(__file__).resolve().parents[1] / "problems" / "box-3-2-1.toml").read_text()
    text = text.replace('shape = "box"\nsize = [0.20, 0.10, 0.05]', 'shape = "mesh"\nfile = "box.stl"')
    text = "\n".join(line for line in text.splitlines() if not line.startswith("face = "))
    (tmp_path / "f.toml").write_text(text)
    assert main(["simulate", str(tmp_path / "f.toml"), "--duration", "0.05", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert max(abs(x) for x in out["velocity"]["linear"] + out["velocity"]["angular"]) <= 1e-9  # located: at rest
    assert [c["name"] for c in out["contacts"]] == ["B1", "B2", "B3", "S1", "S2", "E1"]
    assert main(["view", str(tmp_path / "f.toml"), "--out", str(tmp_path / "scene.html")]) == 0
    page = (tmp_path / "scene.html").read_text()
    assert "mesh3d" in page.lower()


def test_parse_mesh_reports_what_it_is_given() -> None:
    with pytest.raises(MeshError, match="no triangles"):
        parse_mesh(b"solid x\nendsolid x\n", "stl")
