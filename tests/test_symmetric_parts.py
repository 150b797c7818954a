"""Parts with a continuous symmetry: located, and planned, up to the motion that maps them onto themselves.

``problems/cylinder-5.toml``: a cylinder (R = 0.04 m, L = 0.12 m) in two 90° V-blocks plus an end
stop E1. Every V normal passes through the axis and E1's is parallel to it, so no locator resists
the spin about the axis (rank G = 5 of 6), and nothing else is free. Closed forms (file header):
the V contacts sit at ``y = ∓a``, ``z = z0`` (``a = 0.028284271247``, ``z0 = 0.021715728753``), so
the axis runs along x at ``y = 0``, height ``z0 + √(R² − a²) = 0.05`` m; E1 at ``x = −0.06`` on the
−z end face puts the centre at ``x = −0.06 + L/2 = 0``. The spin is whatever the start's is.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import PROBLEMS, run_cli

from fixplan import twins
from fixplan.fixture import load, loads
from fixplan.geometry import Box, Cylinder, Disk, Sphere
from fixplan.locating import contact_set, free_motions_at, with_goal
from fixplan.model import nearest_symmetric_pose, symmetry_axes_body
from fixplan.planner.solve import solve
from fixplan.spatial import Pose, exp_so3, log_so3, matrix_from_rpy, rot2, rpy_from_matrix

CYLINDER_5 = PROBLEMS / "cylinder-5.toml"
R_M, L_M = 0.04, 0.12
A_M, Z0_M = 0.028284271247, 0.021715728753  # a V contact's |y| and height (the file's locators)
CENTRE = np.array([-0.06 + L_M / 2.0, 0.0, Z0_M + math.sqrt(R_M**2 - A_M**2)])  # (0, 0, 0.05)
AXIS_ALONG_X = matrix_from_rpy(np.radians([0.0, 90.0, 0.0]))  # body z (the axis) along world +x
EXACT = 1e-9  # [m], [rad]
FINAL_GAP_M = 1e-4  # the verification's own threshold (tests/test_plans.py)


def _spun(theta_deg: float) -> np.ndarray:
    """The cylinder lying along world x, turned by ``theta_deg`` about its own axis."""
    return AXIS_ALONG_X @ exp_so3(math.radians(theta_deg) * np.array([0.0, 0.0, 1.0]))


def _with_start(text: str, position: list[float], R: np.ndarray) -> str:
    rpy = ", ".join(f"{x:.15g}" for x in np.degrees(rpy_from_matrix(R)))
    pos = ", ".join(f"{x:.15g}" for x in position)
    lines = [
        f"start = {{ position = [{pos}], rpy_deg = [{rpy}] }}" if ln.startswith("start = ") else ln
        for ln in text.splitlines()
    ]
    return "\n".join(lines) + "\n"


def _spin_deg(a: Pose, b: Pose) -> float:
    """The turn from ``a`` to ``b`` about the part's own axis (body z) [deg]."""
    return math.degrees(float(log_so3(a.R_world_body.T @ b.R_world_body)[2]))


# a start 10 mm off the end stop along the axis, spun 30° about it: resting in the V, E1 open
SHIFTED = _with_start(CYLINDER_5.read_text(), [0.01, 0.0, 0.05], _spun(30.0))


# -- located up to the spin ------------------------------------------------------------------------
def test_cylinder_5_is_located_up_to_its_spin():
    fx = load(CYLINDER_5)
    assert fx.is_full and len(fx.locators) == 5 and not fx.unlocated
    np.testing.assert_allclose(np.abs(fx.free_motions), [[0, 0, 0, 0, 0, 1]], atol=EXACT)
    # the null space of G at the goal is the spin about the axis (world x), nothing else
    null = free_motions_at(fx, fx.goal)
    assert null.shape == (1, 6)
    np.testing.assert_allclose(np.abs(null[0]), [0, 0, 0, 1, 0, 0], atol=EXACT)
    np.testing.assert_allclose(np.abs(fx.free_motions_world(fx.goal)), np.abs(null), atol=EXACT)
    G = contact_set(fx, "goal", [loc.name for loc in fx.locators]).G
    assert np.linalg.matrix_rank(G, tol=1e-9) == 5
    np.testing.assert_allclose(G @ fx.free_motions_world(fx.goal)[0], 0.0, atol=EXACT)
    # the start is located (every locator touches): the goal is the start, centre from the V geometry
    np.testing.assert_allclose(fx.goal.p_world, CENTRE, atol=EXACT)
    np.testing.assert_allclose(fx.goal.R_world_body, fx.start.R_world_body, atol=EXACT)


@pytest.mark.parametrize("theta_deg", [0.0, 30.0, -75.0, 170.0])
def test_the_goal_keeps_the_start_spin(theta_deg):
    fx = loads(_with_start(CYLINDER_5.read_text(), [0.01, 0.0, 0.05], _spun(theta_deg)), source="spun")
    assert fx.is_full and fx.goal_starts == 1
    np.testing.assert_allclose(fx.goal.p_world, CENTRE, atol=EXACT)
    np.testing.assert_allclose(fx.goal.R_world_body, _spun(theta_deg), atol=EXACT)
    assert _spin_deg(fx.start, fx.goal) == pytest.approx(0.0, abs=1e-7)


def test_a_turned_start_keeps_its_spin_about_the_located_axis():
    """Start yawed 3° and lifted 6 mm: the goal's axis lies along x; its spin is the nearest to the start's."""
    R = exp_so3(math.radians(3.0) * np.array([0.0, 0.0, 1.0])) @ _spun(40.0)
    fx = loads(_with_start(CYLINDER_5.read_text(), [0.01, 0.0, 0.056], R), source="yawed")
    goal = fx.goal
    np.testing.assert_allclose(goal.p_world, CENTRE, atol=1e-8)
    np.testing.assert_allclose(goal.R_world_body[:, 2], [1.0, 0.0, 0.0], atol=1e-8)  # the axis
    # nearest in the family: no turn about the axis brings the goal closer to the start
    angle = np.linalg.norm(log_so3(fx.start.R_world_body.T @ goal.R_world_body))
    grid = [
        np.linalg.norm(log_so3(fx.start.R_world_body.T @ goal.R_world_body @ exp_so3(np.array([0, 0, t]))))
        for t in np.radians(np.arange(-180.0, 180.0, 0.25))
    ]
    assert angle <= min(grid) + 1e-12
    assert math.degrees(angle) == pytest.approx(3.0, abs=1e-3)  # only the yaw is undone


def test_nearest_symmetric_pose_against_a_search():
    rng = np.random.default_rng(0)
    for _ in range(20):
        pose = Pose(exp_so3(rng.standard_normal(3)), rng.standard_normal(3))
        near = Pose(exp_so3(rng.standard_normal(3)), rng.standard_normal(3))
        best = nearest_symmetric_pose(Cylinder(0.04, 0.12), pose, near)
        # in the family (a turn about body z), at the body origin, and nearest of the family
        turn = log_so3(pose.R_world_body.T @ best.R_world_body)
        np.testing.assert_allclose(turn[:2], 0.0, atol=1e-12)
        np.testing.assert_array_equal(best.p_world, pose.p_world)
        angle = np.linalg.norm(log_so3(near.R_world_body.T @ best.R_world_body))
        grid = [
            np.linalg.norm(log_so3(near.R_world_body.T @ pose.R_world_body @ exp_so3(np.array([0, 0, t]))))
            for t in np.linspace(-np.pi, np.pi, 2001)
        ]
        assert angle <= min(grid) + 1e-12
    pose = Pose(exp_so3([0.3, -0.2, 1.0]), [1.0, 2.0, 3.0])
    near = Pose(exp_so3([-1.0, 0.5, 0.1]), [0.0, 0.0, 0.0])
    np.testing.assert_allclose(nearest_symmetric_pose(Sphere(0.1), pose, near).R_world_body, near.R_world_body)
    assert nearest_symmetric_pose(Box((0.1, 0.2, 0.3)), pose, near) is pose  # a box has no continuous symmetry
    assert nearest_symmetric_pose(Disk(0.05), Pose(rot2(1.0), [0, 0]), Pose(rot2(-2.0), [1, 1])).angle_rad == (
        pytest.approx(-2.0)
    )
    assert [len(symmetry_axes_body(s)) for s in (Cylinder(1, 1), Sphere(1), Disk(1), Box((1, 1, 1)))] == [1, 3, 1, 0]


def test_validate_reports_the_goal_and_the_free_spin():
    proc = run_cli("validate", CYLINDER_5, "--verbose", check_rc=0)
    assert "goal computed, spin free" in proc.stdout
    assert "goal (computed): position [0, 0, 0.05] m" in proc.stdout
    assert "free at the goal: the spin about the cylinder's axis" in proc.stdout
    assert "the locators determine the pose up to the part's symmetry" in proc.stdout
    assert "do not determine" not in proc.stdout + proc.stderr


# -- other free motions are refused, named -----------------------------------------------------------
def _without(text: str, name: str) -> str:
    head, _, tail = text.partition(f'[[locator]]\nname = "{name}"\n')
    rest = tail.split("[[locator]]", 1)
    return head + ("[[locator]]" + rest[1] if len(rest) > 1 else "")


def test_a_cylinder_on_four_locators_is_refused_naming_what_is_free(tmp_path):
    """The V-blocks alone: the spin and the slide along the axis (world x) are free."""
    text = _without(CYLINDER_5.read_text(), "E1")
    fx = loads(text, source="cylinder-4")
    assert len(fx.locators) == 4 and not fx.is_full and fx.goal_pose is None
    assert fx.unlocated == "the spin about the cylinder's axis, translation along x"
    path = tmp_path / "cylinder-4.toml"
    path.write_text(text)
    proc = run_cli("solve", path, "--no-verify")
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.strip() == (
        f"fixplan: planning needs a full fixture (6 locators in 3D, or 5 that leave only the cylinder's symmetry "
        f"free); {path} has 4: its locators leave free the spin about the cylinder's axis, translation along x"
    )


def test_a_cylinder_with_a_v_block_missing_is_refused_naming_the_tilt():
    """L2, R2 and E1 only: besides the spin, the part can tilt about the axis point above the V-block left (x = 0.04)."""
    fx = loads(_without(_without(CYLINDER_5.read_text(), "L1"), "R1"), source="cylinder-3")
    assert not fx.is_full
    assert fx.unlocated == (
        "the spin about the cylinder's axis, rotation about any axis through (0.04, 0, 0.05) m normal to x"
    )


def test_a_box_on_five_locators_names_its_free_rotation():
    """box-3-2-1 without S2: the box can yaw about the vertical line where S1's and E1's normals cross (S1.x, E1.y)."""
    text = (PROBLEMS / "box-3-2-1.toml").read_text()
    fx = loads(_without(text, "S2"), source="box-5")
    assert not fx.is_full and fx.free_motions_body is None
    s1, e1 = fx.locator("S1").p_world, fx.locator("E1").p_world
    assert fx.unlocated.startswith("rotation about an axis along z through (")
    through = [float(x) for x in fx.unlocated.split("through (")[1].split(")")[0].split(",")]
    assert through[:2] == pytest.approx([s1[0], e1[1]], abs=1e-9)


def test_with_goal_locates_a_hand_built_model_up_to_its_spin():
    fx = load(CYLINDER_5)
    bare = dataclasses.replace(
        fx, start=Pose(_spun(-50.0), [0.02, 0.0, 0.05]), free_motions_body=None, goal_pose=None, goal_starts=0
    )
    located = with_goal(bare)
    assert located.is_full and located.free_motions_body is not None
    np.testing.assert_allclose(located.goal.p_world, CENTRE, atol=EXACT)
    np.testing.assert_allclose(located.goal.R_world_body, _spun(-50.0), atol=EXACT)


# -- planned with the spin free ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def shifted_plan():
    fx = loads(SHIFTED, source="cylinder-5-shifted")
    return fx, solve(fx)


@pytest.mark.slow
def test_cylinder_5_plans_and_verifies_with_its_spin_free(shifted_plan):
    fx, r = shifted_plan
    assert r.status == "planned", r.reason
    assert [tuple(s) for s in r.sequence] == [("L1", "L2", "R1", "R2"), ("E1", "L1", "L2", "R1", "R2")]
    v = r.verification
    assert v is not None and v.passed, v.reason
    assert sorted(v.final_gaps_m) == ["E1", "L1", "L2", "R1", "R2"]
    assert max(abs(g) for g in v.final_gaps_m.values()) <= FINAL_GAP_M
    # at the goal modulo the spin: centre and axis as located; the push left the spin alone
    final = v.final_pose
    dp, dang = final.distance_to(fx.goal_near(final))
    assert dp <= FINAL_GAP_M and dang <= 1e-3
    assert abs(_spin_deg(fx.start, final)) <= 0.1


@pytest.mark.slow
def test_a_rotated_world_twin_gets_the_same_plan(shifted_plan):
    fx, r = shifted_plan
    Rw = twins.random_rotation(np.random.default_rng([20, 5]), 3)
    twin = loads(twins.rotated_fixture_text(SHIFTED, Rw), source="cylinder-5-rotated")
    assert twin.is_full and twin.free_motions_body is not None
    # the located pose turns with the world, the start's spin carried over in both
    np.testing.assert_allclose(twin.goal.R_world_body, Rw @ fx.goal.R_world_body, atol=1e-8)
    np.testing.assert_allclose(twin.goal.p_world, Rw @ fx.goal.p_world, atol=1e-8)
    rt = solve(twin)
    assert (rt.status, [tuple(sorted(s)) for s in rt.sequence]) == (r.status, [tuple(sorted(s)) for s in r.sequence])


def test_the_located_start_needs_no_plan():
    r = solve(load(CYLINDER_5), run_verification=False)
    assert r.status == "unverified" and [tuple(s) for s in r.sequence] == [("E1", "L1", "L2", "R1", "R2")]


# a ball in a three-point seat, normals 45° from vertical through the centre: rank G = 3, every
# turn about the centre free. Seated: centre above the seat's middle at z = 0.038787 + R cos 45° = 0.06.
SPHERE_3 = """format = 1
[scene]
name = "sphere-3"
dimension = 3
gravity = [0.0, 0.0, -9.81]
[workpiece]
shape = "sphere"
radius = 0.03
mass = 0.5
start = { position = [0.004, 0.0, 0.068], rpy_deg = [10.0, 20.0, 30.0] }
[[locator]]
name = "A"
position = [0.021213203, 0.0, 0.038786797]
radius = 0.0
friction = 0.3
[[locator]]
name = "B"
position = [-0.010606602, 0.018371173, 0.038786797]
radius = 0.0
friction = 0.3
[[locator]]
name = "C"
position = [-0.010606602, -0.018371173, 0.038786797]
radius = 0.0
friction = 0.3
"""


@pytest.mark.slow
def test_a_sphere_on_three_locators_is_located_and_planned_up_to_its_turns():
    fx = loads(SPHERE_3, source="sphere-3")
    assert fx.is_full and fx.free_motions.shape == (3, 6)
    np.testing.assert_allclose(fx.goal.p_world, [0.0, 0.0, 0.021213203 + 0.038786797], atol=1e-8)
    np.testing.assert_allclose(fx.goal.R_world_body, fx.start.R_world_body, atol=EXACT)  # every turn kept
    r = solve(fx)
    assert r.status == "planned", r.reason
    assert [len(s) for s in r.sequence] == [1, 2, 3]  # from free space, one locator at a time
    v = r.verification
    assert v is not None and max(abs(g) for g in v.final_gaps_m.values()) <= FINAL_GAP_M
    assert np.linalg.norm(v.final_pose.p_world - fx.goal.p_world) <= FINAL_GAP_M
