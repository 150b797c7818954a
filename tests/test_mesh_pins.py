"""Pins in the holes of a mesh (CAD) part: the holes analytic, the rests on the triangles, every command.

The mesh twin of a bundled housing is the same box written as a triangle mesh with trimesh (an OBJ
at 17 digits, so that the twin's faces are the box's to the last bit; a binary STL would round them
to float32, 3.4e-10 m at 15 mm) beside the same ``[[workpiece.hole]]``s, rests and pins. The
engine then detects the rests on the 12 triangles and the pins in the holes in closed form (the
mesh's triangles are never tested against a pin), so the twin must answer as the primitive:

- one step from the same state, at poses where the pins touch their walls, the mouths or each
  other's chamfers: the same contacts, gaps, forces and the same pose after the step (1e-12);
- frictionless rests and pins, a push of 10 N along +x through the centre of mass, toward P1's
  contact (normals −x): at rest, P1's normal forces sum to the push and the rests' to m g (the
  closed form of ``problems/expected.toml``'s +x case), on the twin and on a mesh whose bores are
  modelled (a square through channel at H1, a blind pocket at H2: blind by the loader's probe);
- the compiled mesh step with pins follows its Python reference step for step (1e-12);
- ``solve`` (the staged insertion, verified in the haptic loop), ``verify PLAN``, ``robust``,
  ``view`` and the haptic session give the twin the primitive's status, stages, observed states,
  final gaps and final pose (within 1e-9 m and 1e-9 rad: the NSGS residual, not the geometry).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import trimesh
from conftest import PROBLEMS, run_cli

import fixplan
from fixplan.engine.simulator import Simulator
from fixplan.geometry.cells import cell_surface
from fixplan.settings import DEFAULT
from fixplan.spatial import Pose, exp_so3

HOUSING = PROBLEMS / "housing-2-pins.toml"
LOAD = PROBLEMS / "housing-2-pins-load.toml"
CLAMPED = PROBLEMS / "housing-2-pins-clamped.toml"
TOL = 1e-12
POSE_TOL_M = 1e-9  # the twin's final pose and gaps against the primitive's after a whole haptic run
G_N = 2.0 * 9.81  # the housing's weight


def mesh_twin(source: Path, folder: Path, *, frictionless: bool = False) -> Path:
    """``source`` with its box written as a triangle mesh (trimesh, OBJ at 17 digits) beside it; holes, rests and pins unchanged."""
    text = source.read_text(encoding="utf-8")
    box = re.search(r'shape = "box"\nsize = \[(.*?)\]', text)
    assert box is not None
    size = [float(x) for x in box.group(1).split(",")]
    mesh = trimesh.creation.box(extents=size)
    obj = trimesh.exchange.obj.export_obj(mesh, digits=17, include_normals=False, include_texture=False)
    (folder / "housing.obj").write_text(obj, encoding="utf-8")
    text = text.replace(box.group(0), 'shape = "mesh"\nfile = "housing.obj"')
    if frictionless:
        text = re.sub(r"friction = [0-9.]+", "friction = 0.0", text)
    path = folder / f"mesh-{source.name}"
    path.write_text(text, encoding="utf-8")
    return path


def bored_twin(folder: Path, *, frictionless: bool = False) -> Path:
    """The housing as a mesh whose bores are modelled: a 12 mm square through channel at H1, a 20 mm deep pocket at H2."""
    xs = np.array([-0.06, -0.046, -0.034, 0.034, 0.046, 0.06])
    ys = np.array([-0.04, -0.006, 0.006, 0.04])
    zs = np.array([-0.015, 0.005, 0.015])
    filled = np.ones((5, 3, 2), dtype=bool)
    filled[1, 1, :] = False  # H1's channel, through
    filled[3, 1, 0] = False  # H2's pocket, from the bottom face up to z = 0.005 (20 mm)
    V, F = cell_surface(xs, ys, zs, filled)
    obj = trimesh.exchange.obj.export_obj(trimesh.Trimesh(V, F, process=False), digits=17, include_normals=False)
    (folder / "bored.obj").write_text(obj, encoding="utf-8")
    text = mesh_twin(HOUSING, folder, frictionless=frictionless).read_text(encoding="utf-8")
    text = text.replace('file = "housing.obj"', 'file = "bored.obj"')
    h2 = "position = [0.04, 0.0, -0.015]\naxis = [0.0, 0.0, -1.0]\ndiameter = 0.010\ndepth = 0.03"
    assert h2 in text
    text = text.replace(h2, h2.replace("depth = 0.03", "depth = 0.02"))
    path = folder / "bored.toml"
    path.write_text(text, encoding="utf-8")
    return path


def assert_same_contacts(a: Simulator, b: Simulator, tol_N: float) -> float:
    """The same per-name and per-contact reports (gaps to 1e-12 m, forces to ``tol_N``); the largest pin force."""
    most = 0.0
    for x, y in zip(a.contacts(), b.contacts(), strict=True):
        assert (x.name, x.mode) == (y.name, y.mode)
        assert abs(x.gap_m - y.gap_m) <= TOL and abs(x.normal_force_N - y.normal_force_N) <= tol_N
        np.testing.assert_allclose(x.force_world, y.force_world, rtol=0, atol=tol_N)
        assert len(x.contacts) == len(y.contacts)
        for s, t in zip(x.contacts, y.contacts, strict=True):
            assert abs(s.gap_m - t.gap_m) <= TOL and abs(s.normal_force_N - t.normal_force_N) <= tol_N
            np.testing.assert_allclose(s.normal_world, t.normal_world, rtol=0, atol=TOL)
        if x.name.startswith("P"):
            most = max(most, x.normal_force_N)
    return most


# -- the engine ------------------------------------------------------------------------------------
def test_pin_forces_on_the_mesh_twin_equal_the_primitives_at_a_few_poses(tmp_path: Path) -> None:
    """One step from rest at the located pose, lifted onto the pins' sides, yawed onto P2's lands, and with P1's
    tip on H1's mouth chamfer: each pin's contacts (rim, mouth, tip) and forces equal, and the pose after the step."""
    box, mesh = fixplan.load(HOUSING), fixplan.load(mesh_twin(HOUSING, tmp_path))
    sb, sm = Simulator(box), Simulator(mesh)
    G = box.goal
    up = np.array([0.0, 0.0, 1.0])
    poses = {
        "located": G,
        "on the pins' sides": G.translated(0.005 * up),
        "yawed onto P2's lands": Pose(
            exp_so3(np.array([0.0, 0.0, 0.004])) @ G.R_world_body, G.p_world + np.array([5e-5, 0.0, 0.006])
        ),  # fmt: skip
        "P1's tip on H1's chamfer": G.translated(np.array([1.3e-3, 0.0, 0.0118])),  # 45° on 45°: gap 0
    }
    wrench = np.array([10.0, 0.0, -5.0, 0.0, 0.0, 0.05])  # toward P1's contact, down, a little yaw
    loaded = {}
    for label, pose in poses.items():
        for sim in (sb, sm):
            sim.set_state(pose)
            sim.step(wrench)
        loaded[label] = assert_same_contacts(sb, sm, TOL / sb.dt)
        np.testing.assert_allclose(sm.pose.p_world, sb.pose.p_world, rtol=0, atol=TOL)
        np.testing.assert_allclose(sm.pose.R_world_body, sb.pose.R_world_body, rtol=0, atol=TOL)
        np.testing.assert_allclose(sm.twist, sb.twist, rtol=0, atol=TOL)
    assert min(loaded.values()) > 1.0, loaded  # every pose loads a pin (the comparison is not of zeros)
    last = {r.name: r for r in sm.contacts()}  # the last pose: P1's tip chamfer on the mouth chamfer
    assert last["P1"].normal_force_N > 1.0


@pytest.mark.parametrize("part", ["twin", "modelled bores"])
def test_frictionless_p1_takes_the_whole_push_on_a_mesh_part(tmp_path: Path, part: str) -> None:
    """μ = 0 everywhere, 10 N along +x through the centre of mass: at rest, ΣN(P1) = 10 N and ΣN(rests) = m g.

    With no friction only P1's normals (−x) take an x force, and only the rests' (+z) the weight:
    the closed form holds whatever the split between P1's rim and mouth edge. The same on the mesh
    twin and on a mesh whose bores are modelled (its triangles around the pins are never tested).
    """
    path = (
        mesh_twin(HOUSING, tmp_path, frictionless=True) if part == "twin" else bored_twin(tmp_path, frictionless=True)
    )
    fx = fixplan.load(path)
    sim = Simulator(fx)
    c = fx.goal.point_world_from_body(fx.workpiece.com_body)
    F = np.array([10.0, 0.0, 0.0])
    sim.run(0.3, np.concatenate([F, np.cross(c - fx.goal.p_world, F)]))
    assert np.abs(sim.twist).max() <= 1e-9  # at rest
    reports = {r.name: r for r in sim.contacts()}
    assert reports["P1"].normal_force_N == pytest.approx(10.0, abs=1e-6)
    np.testing.assert_allclose(reports["P1"].force_world, [-10.0, 0.0, 0.0], atol=1e-6)
    assert sum(reports[n].normal_force_N for n in ("B1", "B2", "B3")) == pytest.approx(G_N, abs=1e-6)
    assert reports["P2"].normal_force_N == 0.0 and reports["P2"].gap_m == pytest.approx(1e-4, abs=1e-9)


def test_a_mesh_that_models_a_blind_bore_gives_a_blind_hole(tmp_path: Path) -> None:
    """H1's channel goes through the part, H2's pocket stops 20 mm up: the loader's probe past each bottom says which."""
    fx = fixplan.load(bored_twin(tmp_path))
    assert {h.name: h.through for h in fx.workpiece.holes} == {"H1": True, "H2": False}
    twin = fixplan.load(mesh_twin(HOUSING, tmp_path))
    assert all(h.through for h in twin.workpiece.holes)  # a mesh without bores: through, as the box's
    # the probe's length is a setting, and a blind hole's bottom in plain material is blind whatever it is
    assert DEFAULT.mesh.hole_probe_m > 0.0
    text = mesh_twin(HOUSING, tmp_path).read_text(encoding="utf-8").replace("depth = 0.03", "depth = 0.02", 1)
    (tmp_path / "blind.toml").write_text(text, encoding="utf-8")
    assert [h.through for h in fixplan.load(tmp_path / "blind.toml").workpiece.holes] == [False, True]


def _sync(a: Simulator, b: Simulator) -> None:
    """``a`` (compiled) takes ``b``'s (the Python reference's) state and warm starts, the pins' too (as tests/test_mesh_slot_kernels.py)."""
    from test_mesh_slot_kernels import sync

    sync(a, b)
    stepper, pins = a._mesh_stepper, b._pin_last
    assert stepper is not None and pins is not None
    for j, key in enumerate(pins.keys):
        old = b._pin_state[key]
        stepper.pin_state[j, :12], stepper.pin_state[j, 16:18], stepper.pin_state[j, 18:21] = old[:12], old[12:14], key
    stepper.pin_count[0] = len(pins.keys)


def test_the_compiled_mesh_step_with_pins_follows_the_python_step(tmp_path: Path) -> None:
    """150 steps from 6 mm above the seat, yawed onto P2's lands, pushed onto P1 and down onto the rests: each step
    from the same state gives the same state and reports (1e-12), while the pins and then the rests take the load."""
    fx = fixplan.load(mesh_twin(HOUSING, tmp_path))
    compiled, reference = Simulator(fx), Simulator(fx)
    reference._mesh_reference = True
    G = fx.goal
    start = Pose(exp_so3(np.array([0.0, 0.0, 0.004])) @ G.R_world_body, G.p_world + np.array([5e-5, 0.0, 0.006]))
    for sim in (compiled, reference):
        sim.set_state(start)
    wrench = np.array([10.0, 0.0, -5.0, 0.0, 0.0, 0.3])
    most: dict[str, float] = {}
    for s in range(150):
        ia, ib = compiled.step(wrench), reference.step(wrench)
        assert abs(ia.error - ib.error) <= TOL and ia.converged == ib.converged
        for x, y in ((compiled._R, reference._R), (compiled._p, reference._p), (compiled._v, reference._v),
                     (compiled._w, reference._w), (compiled._P, reference._P), (compiled._u, reference._u),
                     (compiled._gap, reference._gap), (compiled._nw, reference._nw)):  # fmt: skip
            np.testing.assert_allclose(x, y, rtol=0, atol=TOL)
        assert np.array_equal(compiled._active, reference._active)
        if s % 10 == 0 or s == 149:
            assert_same_contacts(compiled, reference, TOL / compiled.dt)
            for r in compiled.contacts():
                most[r.name] = max(most.get(r.name, 0.0), r.normal_force_N)
        _sync(compiled, reference)
    assert min(most.values()) > 0.1, most  # both pins and every rest were loaded along the way
    for sim in (compiled, reference):  # a new state: no warm start in either
        sim.set_state(fx.goal)
        sim.step(wrench)
    np.testing.assert_allclose(compiled._P, reference._P, rtol=0, atol=TOL)


# -- the commands ----------------------------------------------------------------------------------
@pytest.mark.slow
def test_solve_on_the_mesh_twin_is_the_primitives_solve(tmp_path: Path) -> None:
    """The staged insertion of housing-2-pins-load: same status, stages, observed states; final pose and gaps within 1e-9."""
    from fixplan.planner.solve import solve

    box, mesh = solve(fixplan.load(LOAD)), solve(fixplan.load(mesh_twin(LOAD, tmp_path)))
    assert box.status == mesh.status == "planned", mesh.reason
    assert [t.added for t in mesh.transitions] == [t.added for t in box.transitions]
    vb, vm = box.verification, mesh.verification
    assert vb is not None and vm is not None and vm.passed, vm.reason
    assert vm.observed_sequence == vb.observed_sequence == [("P1",), ("P1", "P2"), ("B1", "B2", "B3", "P1", "P2")]
    dp, dang = vm.final_pose.distance_to(vb.final_pose)
    assert dp <= POSE_TOL_M and dang <= POSE_TOL_M
    assert vm.final_gaps_m.keys() == vb.final_gaps_m.keys()
    for name, gap in vb.final_gaps_m.items():
        assert vm.final_gaps_m[name] == pytest.approx(gap, abs=POSE_TOL_M), name
    assert vm.final_gaps_m["P1.axis_offset"] == pytest.approx(1e-4, abs=2e-6)  # seated against P1: the play
    located = solve(fixplan.load(mesh_twin(HOUSING, tmp_path)))  # starts located: nothing to insert
    assert located.status == "planned" and located.reason.startswith("already located")


@pytest.mark.slow
def test_verify_robust_view_and_clamp_take_the_mesh_twin(tmp_path: Path) -> None:
    """``solve --out``, ``verify PLAN``, ``robust``, ``view --plan`` and ``clamp`` on mesh twins: the primitive's answers."""
    path = mesh_twin(LOAD, tmp_path)
    plan = tmp_path / "plan.json"
    run_cli("validate", path, check_rc=0)
    run_cli("solve", path, "--out", plan, check_rc=0)
    doc = json.loads(run_cli("verify", plan, "--json", check_rc=0).stdout)
    assert doc["passed"] and doc["observed_sequence"] == [["P1"], ["P1", "P2"], ["B1", "B2", "B3", "P1", "P2"]]
    robust = json.loads(run_cli("robust", path, "--samples", "3", "--json", check_rc=0).stdout)
    assert robust["succeeded"] == robust["samples"] == 3
    html = tmp_path / "scene.html"
    run_cli("view", path, "--plan", plan, "--out", html, check_rc=0)
    assert '"name":"P1"' in html.read_text(encoding="utf-8").replace(" ", "")
    clamps = [
        json.loads(run_cli("clamp", p, "--json", check_rc=0).stdout) for p in (CLAMPED, mesh_twin(CLAMPED, tmp_path))
    ]
    assert clamps[0]["holds"] and clamps[1]["holds"]
    for name, force in clamps[0]["forces_N"].items():
        assert clamps[1]["forces_N"][name] == pytest.approx(force, abs=1e-6)


@pytest.mark.slow
def test_haptic_session_inserts_the_mesh_twin_as_the_primitive(tmp_path: Path) -> None:
    """Guided from above the pins: the same states at the same ticks, the goal reached, the same final gaps and pose."""
    from fixplan.interactive.session import HapticSession

    runs = []
    for path in (LOAD, mesh_twin(LOAD, tmp_path)):
        fx = fixplan.load(path)
        result = HapticSession(fx, None, realtime=False, synchronous=True, until_goal=True, duration_s=8.0).run()
        assert result.reached, result.reason
        runs.append(result)
    box, mesh = runs
    assert mesh.states == box.states
    for name, gap in box.final_gaps_m.items():
        assert mesh.final_gaps_m[name] == pytest.approx(gap, abs=POSE_TOL_M), name
    dp, dang = mesh.trace.poses[-1].distance_to(box.trace.poses[-1])
    assert dp <= POSE_TOL_M and dang <= POSE_TOL_M


def test_a_bore_with_a_mesh_part_is_refused_in_one_line(tmp_path: Path) -> None:
    """The one piece a mesh part cannot take: a [[bore]] needs a cylindrical part (the part is the bore's peg)."""
    path = mesh_twin(HOUSING, tmp_path)
    bore = (
        '\n[[bore]]\nname = "K9"\nposition = [0.0, 0.0, -0.1]\naxis = [0.0, 0.0, 1.0]\ndiameter = 0.2\ndepth = 0.04\n'
    )
    path.write_text(path.read_text(encoding="utf-8") + bore + "friction = 0.3\n", encoding="utf-8")
    for command in ("validate", "simulate"):
        proc = run_cli(command, path, check_rc=2)
        lines = (proc.stdout + proc.stderr).strip().splitlines()
        assert lines == [
            f"{path}: bore.K9: a bore takes a cylindrical part (expected workpiece.shape = 'cylinder', got 'mesh')"
        ]


# -- a pin's tip on the face around its hole -------------------------------------------------------
def test_the_face_around_a_mesh_parts_hole_is_the_boxs(tmp_path: Path) -> None:
    """The coplanar triangles around each mouth make the box's bottom face, to the bit, with the bores modelled or not;
    a face whose outline is no rectangle (an L) gives none, as a curved one."""
    from fixplan.geometry import Box
    from fixplan.geometry.pins import mouth_face

    def faces(path: Path) -> list[tuple[list[float], list[float], list[float], tuple[float, float]] | None]:
        fx = fixplan.load(path)
        out = []
        for hole in fx.workpiece.holes:
            f = mouth_face(fx.workpiece.shape, hole.p_body, hole.axis_body, fx.tolerances.touch_m, 0.01)
            out.append(None if f is None else (f.centre.tolist(), f.normal.tolist(), f.e1.tolist(), f.half_m))
        return out

    box = faces(HOUSING)
    assert box[0] == ([0.0, 0.0, -0.015], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0], (0.06, 0.04))
    assert faces(mesh_twin(HOUSING, tmp_path)) == box
    assert faces(bored_twin(tmp_path)) == box  # the channel's and the pocket's openings inside the rectangle
    # an L-shaped bottom face: the corner x > 0.034, y > 0.006 cut away through the whole height
    xs, ys, zs = np.array([-0.06, 0.034, 0.06]), np.array([-0.04, 0.006, 0.04]), np.array([-0.015, 0.015])
    filled = np.ones((2, 2, 1), dtype=bool)
    filled[1, 1, 0] = False
    from fixplan.geometry.mesh import Mesh

    L = Mesh(*cell_surface(xs, ys, zs, filled))
    mouth, down = np.array([-0.04, 0.0, -0.015]), np.array([0.0, 0.0, -1.0])
    assert mouth_face(L, mouth, down, 1e-9, 0.01) is None
    assert mouth_face(Box((0.12, 0.08, 0.03)), mouth, down, 1e-9, 0.01) is not None


def _lowered_beside(path: Path) -> Simulator:
    """The housing 1 mm above its pins' tips, 12 mm across them along x (beyond the 1.6 mm capture), at rest."""
    fixture = fixplan.load(path)
    sim = Simulator(fixture)
    goal = fixture.goal
    sim.set_state(Pose(goal.R_world_body, goal.p_world + np.array([0.012, 0.0, 0.013])))
    return sim


def test_a_mesh_part_lowered_beside_its_pins_rests_on_their_tips_as_the_box(tmp_path: Path) -> None:
    """Pushed down 20 N for 0.5 s: the twin's tips on its face are the box's, step for step, and it comes to rest on
    them at the tips' height (12 mm above the located pose) with no penetration.

    Each step: the same contacts with the same gaps and normals (1e-9), the same net force of the pins on
    the part (1e-9 N) and the same pose and twist after it. (Not each contact's force: a tip lying flat
    on the face touches at 4 coplanar points, statically indeterminate, and the two engines' NSGS
    split the same net wrench differently among them, by up to 8e-3 N.) Before the mesh part had its
    face, the tips passed its surface: the twin fell 5.3 mm through them (the engine's penetration 12 mm).
    """
    sb, sm = _lowered_beside(HOUSING), _lowered_beside(mesh_twin(HOUSING, tmp_path))
    push = np.array([0.0, 0.0, -20.0, 0.0, 0.0, 0.0])
    loaded = 0.0
    for _ in range(500):
        sb.step(push)
        sm.step(push)
        net_b, net_m = np.zeros(3), np.zeros(3)
        for name in ("P1", "P2"):
            b = next(r for r in sb.contacts() if r.name == name)
            m = next(r for r in sm.contacts() if r.name == name)
            assert len(b.contacts) == len(m.contacts)
            for s, t in zip(b.contacts, m.contacts, strict=True):
                assert abs(s.gap_m - t.gap_m) <= POSE_TOL_M
                np.testing.assert_allclose(t.normal_world, s.normal_world, rtol=0, atol=POSE_TOL_M)
            net_b, net_m = net_b + b.force_world, net_m + m.force_world
        np.testing.assert_allclose(net_m, net_b, rtol=0, atol=POSE_TOL_M)
        np.testing.assert_allclose(sm.pose.p_world, sb.pose.p_world, rtol=0, atol=POSE_TOL_M)
        np.testing.assert_allclose(sm.twist, sb.twist, rtol=0, atol=POSE_TOL_M)
        loaded = max(loaded, float(net_m[2]))
    assert loaded > 10.0  # the tips carry the part: the comparison is not of zeros
    goal_z = fixplan.load(HOUSING).goal.p_world[2]
    for sim in (sb, sm):
        assert sim.pose.p_world[2] == pytest.approx(goal_z + 0.012, abs=1e-9)
        np.testing.assert_allclose(sim.pose.p_world[:2], [0.012, 0.0], atol=1e-9)
        assert sim.max_penetration_m < 1e-9
    np.testing.assert_allclose(sm.pose.R_world_body, sb.pose.R_world_body, rtol=0, atol=POSE_TOL_M)
    reports = {r.name: r for r in sm.contacts()}
    assert reports["P1"].force_world[2] + reports["P2"].force_world[2] == pytest.approx(2.0 * 9.81 + 20.0, rel=1e-6)


def test_a_bored_mesh_part_beside_its_pins_is_held_by_its_face(tmp_path: Path) -> None:
    """The mesh with its bores modelled (its own mass properties): held on the tips too, the penetration within 1e-9 m."""
    sim = _lowered_beside(bored_twin(tmp_path))
    sim.run(0.5, np.array([0.0, 0.0, -20.0, 0.0, 0.0, 0.0]))
    assert sim.pose.p_world[2] == pytest.approx(0.015 + 0.012, abs=1e-9)
    assert sim.max_penetration_m < 1e-9
    assert np.linalg.norm(sim.twist) < 1e-7
