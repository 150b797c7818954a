"""Several contacts per locator on a mesh part: detection, classification, the engine, planning.

A spherical tip resting in the L-bracket's concave corner touches the wall's inner face and the
base's top: two contacts, whose normals are the faces' own. Hand-derived verdicts: with μ = 0 and
no gravity a push whose line passes through the tip's centre, along ``(a, 0, b)`` with ``a, b ≥ 0``,
is held by the two normal forces ``a`` and ``b`` (both normals pass through the tip's centre, so
there is no moment); with the nearest contact alone it is not. The engine: a box written as a
mesh resting on three tips under gravity keeps still and its tips carry the statically
determinate closed-form loads. The box as a 12-triangle STL plans as the primitive box does.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import PROBLEMS

from fixplan.cli import main
from fixplan.engine.simulator import Simulator
from fixplan.errors import InputError
from fixplan.fixture import load
from fixplan.geometry.cells import box_cells, cell_surface
from fixplan.geometry.mesh import stl_bytes
from fixplan.jamming import Classifier, classify, search_wrench
from fixplan.locating import contact_set
from fixplan.planner.solve import solve

MESHES = PROBLEMS / "meshes"
CORNER_M = np.array([0.013, 0.02, 0.013])  # E1's centre in the L's concave corner (wall x = 0.01, base top z = 0.01)


def corner_fixture(folder: Path, *, only_e1: bool = False) -> Path:
    """``l-bracket.toml`` with E1 moved into the concave corner; ``only_e1``: E1 alone, no gravity, μ = 0."""
    text = (MESHES / "l-bracket.toml").read_text(encoding="utf-8")
    text = text.replace("position = [0.013, 0.02, 0.035]", "position = [0.013, 0.02, 0.013]")
    if only_e1:
        head = text[: text.index("[[locator]]")].replace("dimension = 3", "dimension = 3\ngravity = [0.0, 0.0, 0.0]")
        text = head + '[[locator]]\nname = "E1"\nposition = [0.013, 0.02, 0.013]\nradius = 0.003\nfriction = 0.0\n'
    (folder / "l-bracket.stl").write_bytes((MESHES / "l-bracket.stl").read_bytes())
    path = folder / ("e1.toml" if only_e1 else "corner.toml")
    path.write_text(text, encoding="utf-8")
    return path


def test_a_tip_in_the_corner_gives_two_contacts_with_the_faces_normals(tmp_path: Path) -> None:
    fixture = load(corner_fixture(tmp_path))
    cs = contact_set(fixture, "goal")
    assert cs.several and cs.names == ["B1", "B2", "B3", "S1", "S2", "E1", "E1#2"]
    assert cs.owners[-2:] == ["E1", "E1"]
    assert cs.per_locator()["E1"] == ["E1", "E1#2"]
    wall, base = cs.contacts[-2:]
    # from the tip into the part: the wall's inner face (outward +x) and the base's top (outward +z)
    np.testing.assert_allclose(wall.normal_world, [-1.0, 0.0, 0.0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(base.normal_world, [0.0, 0.0, -1.0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(wall.point_world, [0.01, 0.02, 0.013], rtol=0, atol=1e-12)
    np.testing.assert_allclose(base.point_world, [0.013, 0.02, 0.01], rtol=0, atol=1e-12)
    assert abs(wall.gap_m) <= 1e-12 and abs(base.gap_m) <= 1e-12
    # the two rows of G differ: the corner takes two normal directions (rank 2 from one locator)
    assert np.linalg.matrix_rank(cs.subset(["E1"]).G, tol=1e-9) == 2
    # a convex part keeps one contact per locator, named as before
    box = contact_set(load(PROBLEMS / "box-3-2-1.toml"), "goal")
    assert not box.several and box.names == box.owners


@pytest.mark.parametrize(
    ("force_N", "mode", "normal_N"),
    [
        ((0.3, 0.0, 0.5), "held", (0.3, 0.5)),  # into the corner from both faces: each face takes its part
        ((0.3, 0.0, 0.0), "held", (0.3, 0.0)),  # into the wall only
        ((0.0, 0.0, 0.5), "held", (0.0, 0.5)),  # onto the base only
        ((0.3, 0.0, -0.5), "separates", None),  # pulls the base away from the tip
        ((-0.3, 0.0, 0.5), "separates", None),  # pulls the wall away from the tip
    ],
)
def test_a_push_into_the_corner_is_held_by_both_faces(tmp_path: Path, force_N, mode, normal_N) -> None:
    fixture = load(corner_fixture(tmp_path, only_e1=True))
    F = np.array(force_N)
    wrench = np.concatenate([F, np.cross(CORNER_M, F)])  # its line through the tip's centre
    (result,) = classify(fixture, wrench[None, :], jobs=1)
    assert result.mode == mode
    assert result.locators == {"E1": ["E1", "E1#2"]}
    assert result.to_json()["locators"] == {"E1": ["E1", "E1#2"]}
    if normal_N is not None:
        assert result.contact_forces["E1"][0] == pytest.approx(normal_N[0], abs=1e-7)
        assert result.contact_forces["E1#2"][0] == pytest.approx(normal_N[1], abs=1e-7)
        np.testing.assert_allclose(result.locator_force_world("E1"), -F, rtol=0, atol=1e-7)


def test_the_nearest_contact_alone_cannot_hold_a_push_into_the_corner(tmp_path: Path) -> None:
    fixture = load(corner_fixture(tmp_path, only_e1=True))
    cs = contact_set(fixture, "start")
    nearest = type(cs)(cs.contacts[:1], cs.com_world, cs.mass_matrix, cs.body_origin_world)
    F = np.array([0.3, 0.0, 0.5])
    w = cs.wrench_about_com(np.concatenate([F, np.cross(CORNER_M, F)]))
    assert Classifier(cs, np.zeros(6)).classify(w).mode == "held"
    assert Classifier(nearest, np.zeros(6)).classify(w).mode != "held"


def test_classify_json_lists_a_locator_s_contacts_and_primitives_keep_their_keys(tmp_path: Path, capsys) -> None:
    path = corner_fixture(tmp_path)
    assert main(["classify", str(path), "--wrench", "0,0,0,0,0,0", "--pose", "goal", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    result = out["results"][0] if "results" in out else out
    assert result["locators"]["E1"] == ["E1", "E1#2"]  # every locator's contacts, where one has several
    assert result["locators"]["B1"] == ["B1"]
    assert set(result["contact_forces"]) == {"B1", "B2", "B3", "S1", "S2", "E1", "E1#2"}
    corner = load(path)
    with pytest.raises(InputError, match="into contact E1#2"):  # a lift drives the base's top into E1's tip
        search_wrench(corner, np.array([0.0, 0.0, 0.1, 0.0, 0.0, 0.0]), pose="goal")
    push = search_wrench(corner, np.array([-0.1, 0.0, 0.0, 0.0, 0.0, 0.0]), pose="goal").to_json()
    assert push["locators"]["E1"] == ["E1", "E1#2"]  # backing off the wall: E1 opens, E1#2 slides
    assert main(["classify", str(PROBLEMS / "box-3-2-1.toml"), "--wrench", "0,0,0,0,0,0", "--json"]) == 0
    box = json.loads(capsys.readouterr().out)
    assert "locators" not in json.dumps(box)


# -- the engine ---------------------------------------------------------------------------------------
BOX_M = (0.2, 0.1, 0.05)
TIPS_XY = np.array([[-0.06, -0.03], [0.07, -0.03], [0.0, 0.04]])  # under the box, about its centre
RHO_M = 0.003


def resting_box(folder: Path) -> Path:
    V, F = cell_surface(*box_cells(tuple(1000.0 * s for s in BOX_M), 1))  # type: ignore[arg-type]
    (folder / "box.stl").write_bytes(stl_bytes(V, F))
    tips = "".join(
        f'[[locator]]\nname = "B{i + 1}"\nposition = [{x}, {y}, {-BOX_M[2] / 2 - RHO_M}]\nradius = {RHO_M}\nfriction = 0.5\n'
        for i, (x, y) in enumerate(TIPS_XY)
    )
    text = (
        'format = 1\n[scene]\nname = "mesh box on three tips"\ndimension = 3\n'
        '[workpiece]\nshape = "mesh"\nfile = "box.stl"\nunits = "mm"\nmass = 2.0\n'
        "start = { position = [0.0, 0.0, 0.0] }\n" + tips
    )
    (folder / "rest.toml").write_text(text)
    return folder / "rest.toml"


def test_a_mesh_box_on_three_tips_rests_with_the_closed_form_loads(tmp_path: Path) -> None:
    fixture = load(resting_box(tmp_path))
    sim = Simulator(fixture)
    sim.run(0.3)
    weight = fixture.workpiece.mass_kg * 9.81
    # statically determinate: Σ N = m g, Σ N x = Σ N y = 0 about the centre of mass (the origin)
    A = np.vstack([np.ones(3), TIPS_XY[:, 0], TIPS_XY[:, 1]])
    closed = np.linalg.solve(A, [weight, 0.0, 0.0])
    reports = sim.contacts()
    normal = np.array([r.normal_force_N for r in reports])
    np.testing.assert_allclose(normal, closed, rtol=1e-6)
    total = sum(r.force_world for r in reports)
    np.testing.assert_allclose(total, [0.0, 0.0, weight], rtol=0, atol=1e-6 * weight)
    assert np.abs(sim.twist).max() <= 1e-9  # no drift: it stays at rest
    np.testing.assert_allclose(sim.pose.p_world, 0.0, atol=1e-9)
    assert sim.max_penetration_m <= 1e-9


def test_the_engine_holds_a_push_into_the_corner_with_both_contacts(tmp_path: Path) -> None:
    fixture = load(corner_fixture(tmp_path, only_e1=True))
    F = np.array([0.3, 0.0, 0.5])
    sim = Simulator(fixture)
    sim.run(0.05, np.concatenate([F, np.cross(CORNER_M, F)]))
    (report,) = sim.contacts()
    assert len(report.contacts) == 2
    forces = sorted(c.normal_force_N for c in report.contacts)
    np.testing.assert_allclose(forces, [0.3, 0.5], rtol=1e-6)
    np.testing.assert_allclose(report.force_world, -F, rtol=0, atol=1e-6)
    assert np.abs(sim.twist).max() <= 1e-9
    assert [len(c) for c in (report.to_json()["contacts"][0]["normal"],)] == [3]


# -- planning ------------------------------------------------------------------------------------------
FREE_START = "start = { position = [0.104, 0.054, 0.033], rpy_deg = [0.5, -0.5, 0.5] }"


def test_a_box_as_a_12_triangle_stl_plans_as_the_primitive_box(tmp_path: Path, capsys) -> None:
    text = (PROBLEMS / "box-3-2-1.toml").read_text()
    text = "\n".join(line for line in text.splitlines() if not line.startswith("face = "))
    text = re.sub(r"start = \{[^}]*\}", FREE_START, text, count=1)
    (tmp_path / "box.toml").write_text(text)
    V, F = cell_surface(*box_cells((200.0, 100.0, 50.0), 1))
    (tmp_path / "box12.stl").write_bytes(stl_bytes(V, F))
    mesh_text = text.replace(
        'shape = "box"\nsize = [0.20, 0.10, 0.05]', 'shape = "mesh"\nfile = "box12.stl"\nunits = "mm"'
    )
    assert mesh_text != text
    (tmp_path / "mesh.toml").write_text(mesh_text)
    box = solve(load(tmp_path / "box.toml"))
    plan = tmp_path / "plan.json"
    assert main(["solve", str(tmp_path / "mesh.toml"), "--json", "--out", str(plan)]) == 0
    mesh = json.loads(capsys.readouterr().out)
    assert box.status == mesh["status"] == "planned"
    assert [tuple(s) for s in mesh["sequence"]] == [tuple(s) for s in box.sequence]
    assert mesh["verification"]["passed"]  # run in the engine on the mesh's real surface
    # the plan file verifies again (a part that starts free: the sequence leaves the free state out)
    assert main(["verify", str(plan), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["passed"]


def test_a_haptic_session_loads_a_mesh_part_with_a_locator_in_its_pocket(tmp_path: Path) -> None:
    """The housing (E1 in its pocket) from a start lifted off its locators: the executor drives the device to the goal."""
    from fixplan.interactive.app import _mesh
    from fixplan.interactive.session import HapticSession

    text = (MESHES / "housing.toml").read_text(encoding="utf-8")
    text = re.sub(
        r"start = \{[^}]*\}", "start = { position = [-0.004, 0.004, 0.008], rpy_deg = [0.5, -0.5, 0.5] }", text
    )
    (tmp_path / "housing.obj").write_bytes((MESHES / "housing.obj").read_bytes())
    (tmp_path / "housing.toml").write_text(text, encoding="utf-8")
    fixture = load(tmp_path / "housing.toml")
    V, F = _mesh(fixture)  # what viser draws: the part's own triangles
    np.testing.assert_array_equal(F, fixture.workpiece.shape.faces)
    res = HapticSession(fixture, None, realtime=False, synchronous=True, duration_s=5.0).run()
    assert res.status == "reached", res.reason
    assert set(res.states[-1][1]) == {loc.name for loc in fixture.locators}
    assert max(abs(g) for g in res.final_gaps_m.values()) < 1e-4
    assert res.max_penetration_m < 1e-5


def test_a_locator_in_the_corner_is_planned_and_seated_on_both_faces(tmp_path: Path, capsys) -> None:
    """The L slid in along its base under E1 (4 mm short of the wall, 4 mm off S1 and S2): E1 ends on both faces.

    The fine planner writes E1 as the least of the base's and the wall's planes (the free space of
    the corner), so the path keeps it clear of the wall until the wall arrives; the plan is run in
    the engine, where E1 ends with two loaded contacts.
    """
    path = corner_fixture(tmp_path)
    text = path.read_text(encoding="utf-8")
    text = re.sub(
        r"start = \{[^}]*\}",
        "start = { position = [-0.004, 0.004, 0.0] }\ngoal = { position = [0.0, 0.0, 0.0] }",
        text,
    )
    path.write_text(text, encoding="utf-8")
    plan = tmp_path / "plan.json"
    assert main(["solve", str(path), "--json", "--out", str(plan)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "planned", out["reason"]
    assert out["sequence"][0] == ["B1", "B2", "B3", "E1"]  # E1 starts on the base's top only
    assert out["verification"]["passed"]
    fixture = load(path)
    cs = contact_set(fixture, "goal")
    assert cs.per_locator()["E1"] == ["E1", "E1#2"]
    assert main(["verify", str(plan), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["passed"]


def test_a_mesh_box_on_a_floor_and_one_tip_keeps_the_floor_s_slots_after_the_tips(tmp_path: Path) -> None:
    """The fixture's own collision-only bodies follow a mesh part's contact slots: a box on a floor, one tip beside it.

    The floor carries the whole weight (its four corner points share it), the tip nothing; at rest.
    """
    path = resting_box(tmp_path)
    text = path.read_text()
    text = text[: text.index("[[locator]]")]
    text += '[[locator]]\nname = "S1"\nposition = [0.0, -0.0531, 0.0]\nradius = 0.003\nfriction = 0.3\n'
    text += '[[obstacle]]\nname = "floor"\nshape = "plane"\npoint = [0.0, 0.0, -0.025]\nnormal = [0.0, 0.0, 1.0]\n'
    path.write_text(text)
    fixture = load(path)
    sim = Simulator(fixture)
    sim.run(0.1)
    weight = fixture.workpiece.mass_kg * 9.81
    (floor,) = sim.obstacles()
    np.testing.assert_allclose(floor.force_world, [0.0, 0.0, weight], rtol=0, atol=1e-6 * weight)
    (tip,) = sim.contacts()
    assert tip.normal_force_N == 0.0 and tip.gap_m == pytest.approx(0.0001, abs=1e-9)
    assert np.abs(sim.twist).max() <= 1e-9


def test_a_finely_split_mesh_box_on_a_floor_hands_the_step_only_its_bottom_vertices(tmp_path: Path) -> None:
    """A box split into 30 × 30 squares a face (5402 vertices) on a floor plane.

    Every vertex is a collision point against the floor; handing all of them to the step made its
    arrays grow with their square (a 5·10⁴-triangle part failed to allocate). Only the points that
    can be within the margin go: at rest on the floor, exactly the bottom face's 31² vertices. The
    floor carries the weight, with the box at rest, as the 12-triangle box does.
    """
    n = 30
    V, F = cell_surface(*box_cells(tuple(1000.0 * s for s in BOX_M), n))  # type: ignore[arg-type]
    (tmp_path / "box.stl").write_bytes(stl_bytes(V, F))
    text = (
        'format = 1\n[scene]\nname = "split box on a floor"\ndimension = 3\n'
        '[workpiece]\nshape = "mesh"\nfile = "box.stl"\nunits = "mm"\nmass = 2.0\n'
        "start = { position = [0.0, 0.0, 0.0] }\n"
        '[[locator]]\nname = "S1"\nposition = [0.0, -0.0531, 0.0]\nradius = 0.003\nfriction = 0.3\n'
        '[[obstacle]]\nname = "floor"\nshape = "plane"\npoint = [0.0, 0.0, -0.025]\nnormal = [0.0, 0.0, 1.0]\n'
    )
    (tmp_path / "floor.toml").write_text(text)
    fixture = load(tmp_path / "floor.toml")
    sim = Simulator(fixture)
    assert sim._slots.shape[0] == 6 * n * n + 2
    near = sim._obstacle_points_near(sim.margin_m)
    bottom = np.flatnonzero(np.isclose(sim._slots[:, 2], -BOX_M[2] / 2, rtol=0, atol=1e-12))
    assert bottom.size == (n + 1) ** 2 and np.array_equal(near, bottom)
    sim.run(0.05)
    weight = fixture.workpiece.mass_kg * 9.81
    (floor,) = sim.obstacles()
    np.testing.assert_allclose(floor.force_world, [0.0, 0.0, weight], rtol=0, atol=1e-6 * weight)
    assert np.abs(sim.twist).max() <= 1e-9


def test_the_path_program_keeps_a_split_box_clear_of_a_floor_with_its_eight_corners() -> None:
    """The lowest point of a part over a plane is a vertex of its hull: a box split into 30 × 30
    squares a face (5402 vertices) needs its 8 corners as clearance rows, not every vertex (with
    2.5·10⁴ vertices the path program took minutes to build); equal radii only, few points whole."""
    from fixplan.planner.fine import HULL_MIN_POINTS, _hull_points

    V, _ = cell_surface(*box_cells(BOX_M, 30))
    corners = _hull_points(V, np.zeros(len(V)))
    assert len(V) == 5402 and len(corners) == 8
    assert np.allclose(np.abs(V[corners]), np.array(BOX_M) / 2, rtol=0, atol=1e-15)
    few = V[:HULL_MIN_POINTS]
    assert np.array_equal(_hull_points(few, np.zeros(len(few))), np.arange(len(few)))
    radii = np.linspace(0.0, 1e-3, len(V))
    assert np.array_equal(_hull_points(V, radii), np.arange(len(V)))
