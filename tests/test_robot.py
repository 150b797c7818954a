"""The arm that carries the part: kinematics, torques against closed forms and finite differences, the plan check.

The URDFs are the repository's own: ``problems/robots/arm6.urdf`` (a UR5's kinematics, masses and
limits) and ``tests/data/robots/planar2.urdf`` (two massless links of 0.4 m and 0.3 m turning in
a vertical plane, efforts 20 and 8 N·m), whose torques have a closed form.
"""

from __future__ import annotations

import math
import re
import shutil
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from conftest import PROBLEMS, ROBOT_DATA_MISSING, ROOT, run_cli

import fixplan
from fixplan.model import RobotSpec
from fixplan.robot import Arm, check_plan
from fixplan.robot.check import plan_knots
from fixplan.spatial import Pose, log_so3

ARM6 = PROBLEMS / "robots" / "arm6.urdf"
PLANAR2 = ROOT / "tests" / "data" / "robots" / "planar2.urdf"
FIXTURE = PROBLEMS / "box-3-2-1-arm6.toml"
G = np.array([0.0, 0.0, -9.81])


def _arm(path: Path, base: Pose | None = None, tool: str | None = None) -> Arm:
    spec = RobotSpec(path.name, path, base or Pose.identity(3), Pose.identity(3), tool)
    return Arm(spec, G)


@cache
def _solved():
    fx = fixplan.load(FIXTURE)
    return fx, fixplan.solve(fx)


# -- kinematics --------------------------------------------------------------------------------------
def test_ik_reaches_a_pose_forward_kinematics_made(rng: np.random.Generator) -> None:
    """Targets from random joint values, then IK from another start: FK of its answer is the target to 1e-9."""
    base = Pose.from_rpy_deg([0.3, -0.2, 0.1], [5.0, -10.0, 30.0])
    arm = _arm(ARM6, base, "tool0")
    for _ in range(10):
        q_true = rng.uniform(-2.0, 2.0, arm.nq)
        R, p = arm.tool_pose(q_true)
        q, err = arm.ik(R, p, q_true + rng.normal(scale=0.2, size=arm.nq))
        R2, p2 = arm.tool_pose(q)
        assert err <= 1e-9
        assert np.linalg.norm(p2 - p) <= 1e-9
        assert np.linalg.norm(log_so3(R2.T @ R)) <= 1e-9


def test_the_world_jacobian_is_the_derivative_of_the_tool_pose(rng: np.random.Generator) -> None:
    base = Pose.from_rpy_deg([0.1, 0.2, 0.0], [0.0, 20.0, -45.0])
    arm = _arm(ARM6, base, "tool0")
    q = rng.uniform(-2.0, 2.0, arm.nq)
    J = arm.jacobian_world(q)
    eps = 1e-6
    R0, _ = arm.tool_pose(q)
    for i in range(arm.nq):
        dq = np.zeros(arm.nq)
        dq[i] = eps
        Rp, pp = arm.tool_pose(q + dq)
        Rm, pm = arm.tool_pose(q - dq)
        v = (pp - pm) / (2 * eps)
        w = (log_so3(Rp @ R0.T) - log_so3(Rm @ R0.T)) / (2 * eps)
        np.testing.assert_allclose(J[:3, i], v, atol=1e-7)
        np.testing.assert_allclose(J[3:, i], w, atol=1e-7)


# -- torques -----------------------------------------------------------------------------------------
def test_gravity_torques_are_the_gradient_of_the_potential_energy(rng: np.random.Generator) -> None:
    base = Pose.from_rpy_deg([0.0, 0.0, 0.0], [10.0, 0.0, 0.0])  # a tilted base: gravity in other axes
    arm = _arm(ARM6, base, "tool0")
    q = rng.uniform(-2.0, 2.0, arm.nq)
    tau = arm.torques(q, np.zeros(arm.nq), np.zeros(arm.nq), np.zeros(6))
    eps = 1e-6
    fd = np.array(
        [(arm.potential_energy(q + eps * e) - arm.potential_energy(q - eps * e)) / (2 * eps) for e in np.eye(arm.nq)]
    )
    np.testing.assert_allclose(tau, fd, atol=1e-6)
    np.testing.assert_allclose(tau, arm.gravity_torques(q), atol=1e-12)


def test_the_push_torques_do_the_push_s_virtual_work(rng: np.random.Generator) -> None:
    """τ_push·δq = w·δx: the joints that push the part with w do its work along any small motion."""
    arm = _arm(ARM6, Pose.identity(3), "tool0")
    q = rng.uniform(-2.0, 2.0, arm.nq)
    w = rng.normal(size=6) * np.array([30.0, 30.0, 30.0, 2.0, 2.0, 2.0])
    zero = np.zeros(arm.nq)
    tau_push = arm.torques(q, zero, zero, w) - arm.torques(q, zero, zero, np.zeros(6))
    R0, p0 = arm.tool_pose(q)
    eps = 1e-6
    for i in range(arm.nq):
        dq = np.zeros(arm.nq)
        dq[i] = eps
        Rp, pp = arm.tool_pose(q + dq)
        Rm, pm = arm.tool_pose(q - dq)
        dx = np.concatenate([(pp - pm) / (2 * eps), (log_so3(Rp @ R0.T) - log_so3(Rm @ R0.T)) / (2 * eps)])
        assert tau_push[i] == pytest.approx(w @ dx, abs=1e-6)


def test_inertial_torques_are_the_mass_matrix_times_the_acceleration(rng: np.random.Generator) -> None:
    import pinocchio as pin

    arm = _arm(ARM6, Pose.identity(3), "tool0")
    q = rng.uniform(-2.0, 2.0, arm.nq)
    a = rng.normal(size=arm.nq)
    zero = np.zeros(arm.nq)
    M = pin.crba(arm.model, arm.model.createData(), q)
    M = np.triu(M) + np.triu(M, 1).T
    tau = arm.torques(q, zero, a, np.zeros(6)) - arm.torques(q, zero, zero, np.zeros(6))
    np.testing.assert_allclose(tau, M @ a, atol=1e-10)


def _planar_closed_form(q1: float, q2: float, F: float) -> tuple[float, float]:
    """|τ| of the shoulder and elbow holding a downward push F at the tip (massless links 0.4, 0.3 m)."""
    return abs(F * (0.4 * math.cos(q1) + 0.3 * math.cos(q1 + q2))), abs(F * 0.3 * math.cos(q1 + q2))


def test_a_planar_arm_s_torques_equal_the_closed_form(rng: np.random.Generator) -> None:
    arm = _arm(PLANAR2, Pose.identity(3), "tool")
    zero = np.zeros(2)
    for _ in range(20):
        q = rng.uniform(-1.5, 1.5, 2)
        F = float(rng.uniform(1.0, 50.0))
        tau = arm.torques(q, zero, zero, np.array([0.0, 0.0, -F, 0.0, 0.0, 0.0]))
        t1, t2 = _planar_closed_form(float(q[0]), float(q[1]), F)
        assert abs(tau[0]) == pytest.approx(t1, abs=1e-7)
        assert abs(tau[1]) == pytest.approx(t2, abs=1e-7)


def test_the_shoulder_saturates_where_the_closed_form_says() -> None:
    """40 N down at the tip, elbow straight: the shoulder's 20 N·m binds at 0.7 cos q1 = 0.5, q1 = acos(5/7)."""
    arm = _arm(PLANAR2, Pose.identity(3), "tool")
    w = np.array([0.0, 0.0, -40.0, 0.0, 0.0, 0.0])
    zero = np.zeros(2)

    def ratio(q1: float) -> float:
        return float(abs(arm.torques(np.array([q1, 0.0]), zero, zero, w)[0]) / arm.effort_Nm[0])

    lo, hi = 0.0, 1.5  # saturated when horizontal, not when raised
    assert ratio(lo) > 1.0 > ratio(hi)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ratio(mid) > 1.0 else (lo, mid)
    assert lo == pytest.approx(math.acos(5.0 / 7.0), abs=1e-9)


# -- the plan check ----------------------------------------------------------------------------------
@pytest.mark.slow
def test_every_knot_s_joints_put_the_part_at_its_pose() -> None:
    fx, result = _solved()
    assert result.status == "planned", result.reason
    report = result.robot
    assert report is not None and report.feasible and report.reachable
    knots = plan_knots(fx, result.plan)
    assert len(report.knots) == len(knots) >= 2
    arm = Arm(fx.robot, fx.gravity)
    for k, (_, pose, _, _) in zip(report.knots, knots, strict=True):
        got = arm.part_pose_of(k.q)
        assert np.linalg.norm(got.p_world - pose.p_world) <= 1e-9
        assert np.linalg.norm(log_so3(got.R_world_body.T @ pose.R_world_body)) <= 1e-9
        assert np.all(k.q >= arm.lower) and np.all(k.q <= arm.upper)
    # one continuous joint path, and the times increase
    Q = np.array([k.q for k in report.knots])
    assert np.max(np.abs(np.diff(Q, axis=0))) <= 0.5
    assert all(b.time_s >= a.time_s for a, b in zip(report.knots, report.knots[1:], strict=False))
    assert 0.0 < report.max_torque_ratio < 1.0
    assert report.min_clearance_m is not None and report.min_clearance_m > 0.0
    data = result.plan.to_json()["robot"]
    assert data["reachable"] is True and len(data["knots"]) == len(knots)
    assert set(data) >= {
        "reachable",
        "knots",
        "max_torque_ratio",
        "joint_limit_margin_rad",
        "min_clearance_m",
        "reason",
    }


def _copy_with(tmp_path: Path, base: str | None = None, urdf_edit: tuple[str, str] | None = None) -> Path:
    (tmp_path / "robots").mkdir()
    text = ARM6.read_text()
    if urdf_edit is not None:
        assert urdf_edit[0] in text
        text = text.replace(*urdf_edit)
    (tmp_path / "robots" / "arm6.urdf").write_text(text)
    fixture = FIXTURE.read_text()
    if base is not None:
        old = "base = { position = [0.1, 0.55, -0.01], rpy_deg = [0.0, 0.0, -90.0] }"
        assert old in fixture
        fixture = fixture.replace(old, base)
    path = tmp_path / "fixture.toml"
    path.write_text(fixture)
    return path


@pytest.mark.slow
def test_a_base_out_of_reach_is_infeasible_naming_the_knot(tmp_path: Path) -> None:
    fx0, result = _solved()
    path = _copy_with(tmp_path, base="base = { position = [2.5, 0.0, 0.0], rpy_deg = [0.0, 0.0, 180.0] }")
    fx = fixplan.load(path)
    report = check_plan(fx, result.plan)
    assert not report.reachable and not report.feasible
    assert report.worst_knot == 0
    assert report.reason.startswith("knot 0 (") and "out of reach" in report.reason


@pytest.mark.slow
def test_a_weak_shoulder_saturates_naming_the_joint(tmp_path: Path) -> None:
    """The shoulder lift holds the arm's own weight: 150 N·m is ample, 5 N·m is not."""
    _, result = _solved()
    weak = '<limit lower="-6.2832" upper="6.2832" effort="5.0" velocity="3.15"/>\n  </joint>\n  <link name="upper_arm_link">'
    strong = '<limit lower="-6.2832" upper="6.2832" effort="150.0" velocity="3.15"/>\n  </joint>\n  <link name="upper_arm_link">'
    path = _copy_with(tmp_path, urdf_edit=(strong, weak))
    fx = fixplan.load(path)
    report = check_plan(fx, result.plan)
    assert report.reachable and not report.feasible
    assert report.worst_joint == "shoulder_lift_joint" and report.max_torque_ratio > 1.0
    assert "shoulder_lift_joint needs" in report.reason and "effort limit 5 N·m" in report.reason


# -- bad input ---------------------------------------------------------------------------------------
def _fixture_with_robot(tmp_path: Path, robot: str, *, dimension: int = 3) -> Path:
    src = (PROBLEMS / "box-3-2-1.toml").read_text() if dimension == 3 else (PROBLEMS / "disk-2d.toml").read_text()
    path = tmp_path / "f.toml"
    path.write_text(src + "\n" + robot)
    return path


@pytest.mark.parametrize(
    ("robot", "expected"),
    [
        ('[robot]\nurdf = "missing.urdf"\nbase = { position = [0, 0, 0] }\ngrasp = { position = [0, 0, 0] }',
         "robot.urdf: "),
        ('[robot]\nurdf = "../outside.urdf"\nbase = { position = [0, 0, 0] }\ngrasp = { position = [0, 0, 0] }',
         "outside the fixture file's folder"),
        ('[robot]\nurdf = "arm6.urdf"\nbase = { position = [0, 0, 0] }\ngrasp = { position = [0, 0, 0] }\ntool_frame = "nope"',
         "robot.tool_frame: tool_frame 'nope' is not a frame"),
        ('[robot]\nurdf = "arm6.urdf"\ngrasp = { position = [0, 0, 0] }', "robot.base: missing"),
        ('[robot]\nurdf = "arm6.urdf"\nbase = { position = [0, 0, 0] }\ngrasp = { position = [0, 0, 0] }\nrepeatability = -1',
         "robot.repeatability"),
    ],
)  # fmt: skip
def test_a_bad_robot_is_one_line_and_exit_2(tmp_path: Path, robot: str, expected: str) -> None:
    shutil.copy(ARM6, tmp_path / "arm6.urdf")
    (tmp_path / "not-a-urdf.urdf").write_text("<robot")
    path = _fixture_with_robot(tmp_path, robot)
    proc = run_cli("validate", str(path))
    code, err = proc.returncode, proc.stderr
    assert code == 2
    assert expected in err, err
    assert "Traceback" not in err


def test_a_robot_in_2d_is_refused(tmp_path: Path) -> None:
    path = _fixture_with_robot(
        tmp_path,
        '[robot]\nurdf = "arm6.urdf"\nbase = { position = [0, 0] }\ngrasp = { position = [0, 0] }',
        dimension=2,
    )
    proc = run_cli("validate", str(path))
    code, err = proc.returncode, proc.stderr
    assert code == 2 and "3D only" in err


def test_a_named_robot_needs_the_extra_or_loads(tmp_path: Path) -> None:
    path = _fixture_with_robot(
        tmp_path, '[robot]\nurdf = "panda"\nbase = { position = [0.6, 0, 0] }\ngrasp = { position = [0, 0, 0] }'
    )
    proc = run_cli("validate", str(path))
    code, err = proc.returncode, proc.stderr
    try:
        import example_robot_data  # noqa: F401
    except ImportError:
        assert code == 2 and "pip install fixplan[robots]" in err
    else:
        assert code == 0, err


def test_robust_samples_the_robot_s_repeatability(tmp_path: Path) -> None:
    """Without --pose-sigma, `robust` takes the arm's repeatability as the part's pose noise."""
    from fixplan.cli.planning import _pose_sigma

    shutil.copytree(PROBLEMS / "robots", tmp_path / "robots")
    text = FIXTURE.read_text().replace('tool_frame = "tool0"', 'tool_frame = "tool0"\nrepeatability = 2e-4')
    path = tmp_path / "f.toml"
    path.write_text(text)
    fx = fixplan.load(path)
    assert fx.robot is not None and fx.robot.repeatability_m == 2e-4
    assert _pose_sigma(None, fx) == "0.0002,1"
    assert _pose_sigma("3e-3,2", fx) == "3e-3,2"  # given on the command line: as given
    assert _pose_sigma(None, fixplan.load(FIXTURE)) == "1e-3,1"  # no repeatability: the default


def test_the_hand_limits_cut_to_the_arm_are_never_beyond_its_joints(tmp_path: Path, rng: np.random.Generator) -> None:
    """A 60 N·m shoulder cannot push 40 N anywhere: the limits shrink, and no push within them overloads a joint."""
    from fixplan.planner.solve import _with_arm_limits
    from fixplan.robot.check import first_configuration

    weak = '<limit lower="-6.2832" upper="6.2832" effort="60.0" velocity="3.15"/>\n  </joint>\n  <link name="upper_arm_link">'
    strong = '<limit lower="-6.2832" upper="6.2832" effort="150.0" velocity="3.15"/>\n  </joint>\n  <link name="upper_arm_link">'
    fx = fixplan.load(_copy_with(tmp_path, urdf_edit=(strong, weak)))
    cut, limits = _with_arm_limits(fx)
    assert limits is not None and 0.0 < limits.scale < 1.0 and limits.joint == "shoulder_lift_joint"
    F, T = cut.manipulator.max_force_N, cut.manipulator.max_torque_Nm
    assert F == pytest.approx(40.0 * limits.scale) and T == pytest.approx(2.0 * limits.scale)
    arm = Arm(fx.robot, fx.gravity)
    q = first_configuration(arm, fx, fx.start)[0]
    for pose in (fx.start, fx.goal_pose):
        q = arm.ik(*arm.tool_target(pose), q)[0]
        R, p = arm.tool_target(pose)
        zero = np.zeros(arm.nq)
        for _ in range(500):
            f = rng.normal(size=3)
            m = rng.normal(size=3)
            f *= F / np.linalg.norm(f)
            m *= T / np.linalg.norm(m)  # on the limits' spheres, about the body origin
            w_tool = np.concatenate([f, m + np.cross(f, p - pose.p_world)])
            assert np.all(np.abs(arm.torques(q, zero, zero, w_tool)) <= arm.effort_Nm + 1e-9)
    # the arm of the library is strong enough: the fixture's own limits stay
    same, full = _with_arm_limits(fixplan.load(FIXTURE))
    assert full is not None and full.scale == 1.0 and same.manipulator.max_force_N == 40.0


def test_the_stick_figure_ends_at_the_tool(rng: np.random.Generator) -> None:
    arm = _arm(ARM6, Pose.from_rpy_deg([0.2, 0.1, 0.0], [0.0, 0.0, 60.0]), "tool0")
    for _ in range(5):
        q = rng.uniform(-2.0, 2.0, arm.nq)
        P = arm.skeleton_world(q)
        assert P.shape == (arm.nq + 2, 3)
        np.testing.assert_allclose(P[0], arm.p_world_root, atol=1e-15)
        np.testing.assert_allclose(P[-1], arm.tool_pose(q)[1], atol=1e-12)


@pytest.mark.slow
def test_view_draws_the_arm_holding_the_part(tmp_path: Path) -> None:
    """`view --plan` draws the arm (a stick figure through its joints) in the replay's frames."""
    import json
    import re

    plan = tmp_path / "plan.json"
    page = tmp_path / "scene.html"
    run_cli("solve", str(FIXTURE), "--out", str(plan), check_rc=0)
    run_cli("view", str(FIXTURE), "--plan", str(plan), "--out", str(page), check_rc=0)
    html = page.read_text()
    assert html.count('"name":"robot (joints)"') >= 10  # the first frame's trace and every frame's
    data = json.loads(plan.read_text())
    assert data["robot"]["feasible"] is True and re.search(r"reachable through \d+ knots", data["robot"]["reason"])


# -- the wrench search inside the arm's own set of pushes ------------------------------------------------
def _box_fixture(max_force_N: float, max_torque_Nm: float):
    from dataclasses import replace

    from fixplan.model import Manipulator

    fx = fixplan.load(PROBLEMS / "box-3-2-1.toml")
    return replace(fx, manipulator=Manipulator(max_force_N, max_torque_Nm))


def _planar_box(q: tuple[float, float], at: np.ndarray):
    """planar2 at ``q`` with its tool at ``at``, and its joint-torque box there."""
    arm = _arm(PLANAR2, Pose.identity(3), "tool")
    _, p0 = arm.tool_pose(np.array(q))
    arm = _arm(PLANAR2, Pose(np.eye(3), at - p0), "tool")
    box = arm.torque_box(np.array(q), "the test's pose")
    np.testing.assert_allclose(box.point_world, at, atol=1e-12)
    return arm, box


def test_a_lift_in_free_motion_refuses_where_the_planar_closed_form_says() -> None:
    """planar2 horizontal, tool at the box's centre: lifting it with a needs F = m (g + a), the elbow carries 0.3 F.

    Every contact opens, so the push is determined; the elbow's 8 N·m binds before the shoulder's 20
    (0.3 F = 8 before 0.7 F = 20): a* = 8 / (0.3 m) − g, to 1e-6 relative on either side.
    """
    from fixplan.jamming import search_wrench

    fx = _box_fixture(1000.0, 100.0)
    c = np.array([0.10, 0.05, 0.025])
    _, box = _planar_box((0.0, 0.0), c)
    m, g = 2.0, 9.81
    a_star = min(20.0 / 0.7, 8.0 / 0.3) / m - g
    below = search_wrench(fx, [0, 0, a_star * (1 - 1e-6), 0, 0, 0], ["B1", "B2", "B3"], hand_sets=[box])
    above = search_wrench(fx, [0, 0, a_star * (1 + 1e-6), 0, 0, 0], ["B1", "B2", "B3"], hand_sets=[box])
    assert below.found and below.arm_joint == "elbow"
    assert below.arm_torque_ratio == pytest.approx(1.0, abs=2e-6)
    assert below.wrench is not None and below.wrench[2] == pytest.approx(m * (g + a_star), rel=2e-6)
    assert not above.found and above.binding == ["arm"] and "joint elbow" in above.reason
    assert above.arm_torque_ratio is not None and above.arm_torque_ratio > 1.0
    # without the arm the hand's 1000 N lift it
    assert search_wrench(fx, [0, 0, a_star * (1 + 1e-6), 0, 0, 0], ["B1", "B2", "B3"]).found


def _joint_torques_by_hand(w: np.ndarray, tool_minus_shoulder: np.ndarray, elbow_lever: np.ndarray) -> np.ndarray:
    """τ_i = a · (M + r_i × F) with the joint axis a = −y: the planar arm's torques written out."""
    a = np.array([0.0, -1.0, 0.0])
    F, M = w[:3], w[3:]
    return np.array([a @ (M + np.cross(tool_minus_shoulder, F)), a @ (M + np.cross(elbow_lever, F))])


def test_the_zonotope_accepts_a_push_its_inscribed_ball_refuses() -> None:
    """planar2 upright over the box: a vertical push costs its joints nothing, a push along x 0.7 and 0.3 N·m per N.

    Sliding the box up its side wall (S1, S2) at 4 m/s² needs ‖F‖ ≥ m (g + a) = 27.62 N. The ball of
    pushes inscribed in the arm's zonotope (exertable_scale: 0.3 F + T ≤ 8 at the elbow, 100 N and
    10 N·m scaled by 8 / 40 = 0.2: 20 N) refuses it; the zonotope itself accepts it, and the push
    found keeps both joints within their efforts by the torques written out by hand.
    """
    from fixplan.jamming import search_wrench

    c = np.array([0.10, 0.05, 0.025])
    arm, box = _planar_box((math.pi / 2, 0.0), c)
    s, joint = arm.exertable_scale(np.array([math.pi / 2, 0.0]), 0.0, 100.0, 10.0)
    assert s == pytest.approx(8.0 / (0.3 * 100.0 + 10.0), abs=1e-9) and arm.joint_names[joint] == "elbow"
    motion = [0.0, 0.0, 4.0, 0.0, 0.0, 0.0]
    ball = search_wrench(_box_fixture(100.0 * s, 10.0 * s), motion, ["S1", "S2"])
    assert not ball.found and "too weak" in ball.reason
    assert ball.needed_force_N is not None and ball.needed_force_N >= 2.0 * (9.81 + 4.0) * (1 - 1e-6)
    zono = search_wrench(_box_fixture(100.0, 10.0), motion, ["S1", "S2"], hand_sets=[box])
    assert zono.found, zono.reason
    assert zono.wrench is not None and np.linalg.norm(zono.wrench[:3]) > 100.0 * s
    # the wrench is about the body origin (the centre, where the tool is): torques by hand
    tau = _joint_torques_by_hand(zono.wrench, np.array([0.0, 0.0, 0.7]), np.array([0.0, 0.0, 0.3]))
    assert abs(tau[0]) <= 20.0 * (1 + 1e-6) and abs(tau[1]) <= 8.0 * (1 + 1e-6)
    np.testing.assert_allclose(np.abs(tau), np.abs(box.torques(zono.wrench, c)), atol=1e-9)
    assert zono.arm_torque_ratio is not None and zono.arm_torque_ratio <= 1.0 + 1e-6


def test_the_zonotope_refuses_a_push_the_hand_allows_naming_the_joint() -> None:
    """planar2 horizontal: the same slide up the wall needs 0.7 m (g + a) ≥ 20 N·m of the shoulder at 4 m/s²."""
    from fixplan.jamming import search_wrench

    c = np.array([0.10, 0.05, 0.025])
    _, box = _planar_box((0.0, 0.0), c)
    motion = [0.0, 0.0, 4.0, 0.0, 0.0, 0.0]
    fx = _box_fixture(100.0, 10.0)
    assert search_wrench(fx, motion, ["S1", "S2"]).found
    res = search_wrench(fx, motion, ["S1", "S2"], hand_sets=[box])
    assert not res.found and res.binding == ["arm"]
    assert "the arm cannot exert the push" in res.reason and "at the test's pose" in res.reason
    assert res.arm_joint in ("shoulder", "elbow") and res.arm_torque_ratio is not None and res.arm_torque_ratio > 1.0


def test_a_torque_box_is_the_arm_s_torques_as_linear_rows(rng: np.random.Generator) -> None:
    """A w ≤ b ⇔ every joint within its effort, for wrenches about any point (arm6, random poses and pushes)."""
    from fixplan.jamming.hand_set import torque_rows

    arm = _arm(ARM6, Pose.from_rpy_deg([0.1, 0.2, 0.0], [0.0, 0.0, 30.0]), "tool0")
    zero = np.zeros(arm.nq)
    for _ in range(20):
        q = rng.uniform(-2.0, 2.0, arm.nq)
        box = arm.torque_box(q)
        about = rng.normal(size=3)
        A, b = torque_rows([box], about, 0.9)
        w = rng.normal(size=6) * np.array([200.0, 200.0, 200.0, 40.0, 40.0, 40.0])
        w_tool = np.concatenate([w[:3], w[3:] + np.cross(about - box.point_world, w[:3])])
        tau = arm.torques(q, zero, zero, w_tool)
        np.testing.assert_allclose(box.torques(w, about), tau, atol=1e-9)
        assert bool(np.all(A @ w <= b)) == bool(np.all(np.abs(tau) <= 0.9 * arm.effort_Nm))


@pytest.mark.slow
def test_the_planner_s_pushes_stay_inside_the_arm_at_both_knots_of_each_segment(tmp_path: Path) -> None:
    """A 31.5 N·m shoulder (its own weight takes most of it): without the arm's boxes the last transition's
    pushes need 1.03 times its effort; with them every push of the plan is within every joint at both knots."""
    from dataclasses import replace

    from fixplan.jamming.hand_set import worst_joint
    from fixplan.planner.segments import segment_wrenches
    from fixplan.robot.exertable import knot_boxes

    _, result = _solved()
    strong = '<limit lower="-6.2832" upper="6.2832" effort="150.0" velocity="3.15"/>\n  </joint>\n  <link name="upper_arm_link">'
    fx = fixplan.load(_copy_with(tmp_path, urdf_edit=(strong, strong.replace("150.0", "31.5"))))
    worst = {True: 0.0, False: 0.0}
    for tr in result.transitions:
        boxes = knot_boxes(fx, tr.poses)
        assert all(b is not None for b in boxes)
        for with_arm in (True, False):
            w, _, found, reasons = segment_wrenches(
                fx if with_arm else replace(fx, robot=None), tr.poses, tr.established, tr.kind, 1.0,
                friction_margin=0.1,
            )  # fmt: skip
            assert found.all(), reasons
            for k in range(len(w)):
                ratio, _, _ = worst_joint([boxes[k], boxes[k + 1]], w[k], tr.poses[k].p_world)
                worst[with_arm] = max(worst[with_arm], ratio)
    assert worst[False] > 1.0
    assert worst[True] <= 1.0 + 1e-6


@pytest.mark.slow
def test_the_executor_pushes_within_the_arm_where_its_inscribed_ball_is_empty(tmp_path: Path) -> None:
    """A 31.5 N·m shoulder: the arm's own weight loads it with 40.3 N·m at the start (τ_g by RNEA), so no push
    near zero is exertable and the ball of pushes inscribed in its set is empty (scale 0: a hand cut to it
    moves nothing). The set itself holds the pushes that press the part down (the part pushes the tool up:
    ∂τ_shoulder/∂F_z = −0.478 m, so at least (40.3 − 31.5) / 0.478 = 18.5 N down): solve plans and verifies,
    the executor searching every push within the box at the part's pose, and at every traced tick of the
    simulated load the push commanded, and the one the coupling put on the part, load every joint within
    its effort (joints by inverse kinematics at the traced pose, torques by pinocchio)."""
    from fixplan.planner.solve import _with_arm_limits
    from fixplan.robot.check import first_configuration

    strong = '<limit lower="-6.2832" upper="6.2832" effort="150.0" velocity="3.15"/>\n  </joint>\n  <link name="upper_arm_link">'
    fx = fixplan.load(_copy_with(tmp_path, urdf_edit=(strong, strong.replace("150.0", "31.5"))))
    arm = Arm(fx.robot, fx.gravity)
    q = first_configuration(arm, fx, fx.start)[0]
    i = arm.joint_names.index("shoulder_lift_joint")
    assert abs(arm.gravity_torques(q)[i]) == pytest.approx(40.34, abs=0.01) and arm.effort_Nm[i] == 31.5
    assert arm.jacobian_world(q)[2, i] == pytest.approx(-0.478, abs=1e-3)
    limits = _with_arm_limits(fx)[1]
    assert limits is not None and limits.scale == 0.0 and limits.joint == "shoulder_lift_joint"
    result = fixplan.solve(fx)
    assert result.status == "planned", result.reason
    v = result.verification
    ex = v.execution
    assert ex.arm_unreached_solves == 0
    # the box binds: beyond the 80 % headroom, within the efforts
    assert ex.max_arm_torque_ratio is not None and 0.8 < ex.max_arm_torque_ratio <= 1.0 + 1e-9
    zero = np.zeros(arm.nq)
    worst = {"command": 0.0, "coupling": 0.0}
    for k, pose in enumerate(v.trace.poses):
        R, p = arm.tool_target(pose)
        q, err = arm.ik(R, p, q)
        assert err <= 1e-6
        for name, W in (("command", v.trace.command_wrench), ("coupling", v.trace.coupling_wrench)):
            f, m = W[k][:3], W[k][3:]  # about the body origin, world axes
            tau = arm.torques(q, zero, zero, np.concatenate([f, m + np.cross(f, p - pose.p_world)]))
            worst[name] = max(worst[name], float(np.max(np.abs(tau) / arm.effort_Nm)))
    assert len(v.trace.poses) > 50
    assert worst["command"] <= 1.0 + 1e-6 and worst["coupling"] <= 1.0 + 1e-3, worst
    assert result.robot is not None and result.robot.feasible and result.robot.max_torque_ratio <= 1.0


# -- the links along the simulated load ----------------------------------------------------------------
def _with_post(fx, center: np.ndarray, half_m: float):
    from dataclasses import replace

    from fixplan.model import Obstacle

    post = Obstacle("post", "box", np.eye(3), center, np.full(3, half_m), 0.5)
    return replace(fx, obstacles=(*fx.obstacles, post))


def _link_center(fx, q: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    """The world centre and axis of a link's collision cylinder at ``q``."""
    import pinocchio as pin

    from fixplan.robot.exertable import arm_at_start

    arm, _ = arm_at_start(fx)
    geom = arm.loaded.collision
    gdata = geom.createData()
    pin.updateGeometryPlacements(arm.model, arm.data, geom, gdata, q)
    M = gdata.oMg[[o.name for o in geom.geometryObjects].index(name)]
    return arm.p_world_root + arm.R_world_root @ M.translation, arm.R_world_root @ M.rotation[:, 2]


@pytest.mark.parametrize("direction", [(1.0, 0.0, 0.0), (0.0, -1.0, 0.0)])
def test_a_link_is_found_where_it_enters_a_post_at_the_time_the_motion_says(direction: tuple[float, ...]) -> None:
    """The part slides at v = 0.1 m/s; a 1 cm post stands δ = 3 cm beside the flange's cylinder (r = 35 mm).

    The flange moves with the part, so it touches the post at t* = δ / v = 0.3 s: the first sample
    (every 10 ms) that penetrates is the first at or after t*, v t − δ deep, and it is the flange's link.
    """
    from fixplan.robot.clearance import along_trajectory
    from fixplan.robot.exertable import arm_at_start

    fx = fixplan.load(FIXTURE)
    _, q0 = arm_at_start(fx)
    assert q0 is not None
    c, axis = _link_center(fx, q0, "wrist_3_link_0")
    assert abs(axis[2]) == pytest.approx(1.0, abs=1e-6)  # upright: its side faces the post
    u, delta, h, v = np.array(direction), 0.03, 0.005, 0.1
    fx_post = _with_post(fx, c + (0.035 + delta + h) * u, h)
    samples = [(k * 1e-3, Pose(fx.start.R_world_body, fx.start.p_world + v * k * 1e-3 * u)) for k in range(600)]
    clear = along_trajectory(fx, samples, 0.01)
    assert clear is not None and clear.first_hit is None and clear.least is not None
    assert clear.least.distance_m > 0.0 and clear.samples == 61 and clear.unreached == 0  # every 10 ms and the last
    hit = along_trajectory(fx_post, samples, 0.01)
    assert hit is not None and hit.first_hit is not None and hit.first_hit_time_s is not None
    t_star = delta / v
    assert t_star - 1e-9 <= hit.first_hit_time_s <= t_star + 0.01 + 1e-9
    assert hit.first_hit.link == "link wrist_3_link_0" and hit.first_hit.other == "obstacle post"
    assert -hit.first_hit.distance_m == pytest.approx(v * hit.first_hit_time_s - delta, abs=1e-5)


@pytest.mark.slow
def test_the_verification_fails_naming_the_link_and_the_time() -> None:
    """A post around the forearm (away from the part): the links' check fails, naming the link and the time.

    (Run without the policy and re-plans ``solve`` gives the executor, the load itself may also stray.)
    """
    from fixplan.locating import start_state
    from fixplan.planner.solve import plan_steps
    from fixplan.planner.verify import verify
    from fixplan.robot.exertable import arm_at_start

    fx, result = _solved()
    ok = result.verification
    assert ok is not None and ok.passed
    links = ok.extras["robot_links"]
    assert links["first_hit"] is None and links["min_clearance_m"] > 0.0 and links["samples"] >= 10
    _, q0 = arm_at_start(fx)
    c, _ = _link_center(fx, q0, "forearm_link_0")
    bad = _with_post(fx, c, 0.03)
    out = verify(bad, start_state(fx), plan_steps(result.transitions))  # solve's defaults: the haptic profile
    assert not out.passed and "robot links" in out.failed_checks
    assert re.search(r"at t = 0\.0\d\d s link \w+ of the arm hits obstacle post \(\S+ m deep\)", out.reason), out.reason
    assert out.extras["robot_links"]["first_hit"]["other"] == "obstacle post"


# -- the arm in `haptic` -----------------------------------------------------------------------------
@pytest.mark.slow
def test_the_arm_follows_a_recorded_load_to_1e_6() -> None:
    """The simulated haptic load's trace (the part driven by the device through the coupling), frame by frame:
    warm-started IK puts the part, through the grasp, where the trace has it."""
    from fixplan.robot.follow import ArmFollower

    fx, result = _solved()
    trace = result.verification.trace
    assert trace is not None and len(trace.poses) >= 10
    follower = ArmFollower(fx)
    Q = []
    for pose in trace.poses:
        q = follower.follow(pose)
        assert follower.reached and q is not None
        got = follower.arm.part_pose_of(q)
        assert np.linalg.norm(got.p_world - pose.p_world) <= 1e-6
        assert np.linalg.norm(log_so3(got.R_world_body.T @ pose.R_world_body)) <= 1e-6
        Q.append(q.copy())
    assert np.max(np.abs(np.diff(np.array(Q), axis=0))) <= 0.5  # one branch: no flip between frames


def test_haptic_draws_the_arm_holding_the_part() -> None:
    """The live scene's stick figure ends at the tool, which is at the simulated part's pose through the grasp."""
    from fixplan.interactive.app import HapticApp
    from fixplan.interactive.session import HapticSession

    fx = fixplan.load(FIXTURE)
    s = HapticSession(fx, None, realtime=False, synchronous=True, duration_s=1.0, guidance=False)
    app = HapticApp(s, port=0)
    app.start()
    app._stop.set()  # the test draws itself, between ticks
    app._thread.join()
    app.always_draw = True
    try:
        assert app.arm is not None
        s._warm_up()
        for _ in range(50):
            s.tick(0.0)
        app.draw()
        pose = s.snapshot.pose
        segments = np.asarray(app.arm_lines.points)
        assert segments.shape == (app.arm.arm.nq + 1, 2, 3)
        _, p_tool = app.arm.arm.tool_target(pose)
        np.testing.assert_allclose(segments[-1, 1], p_tool, atol=1e-6)
        np.testing.assert_allclose(segments[0, 0], fx.robot.base.p_world, atol=1e-12)
    finally:
        app.stop()


# -- the Panda and the UR5 of example-robot-data (the optional extra fixplan[robots]) -------------------
@pytest.mark.slow
@pytest.mark.skipif(ROBOT_DATA_MISSING is not None, reason=str(ROBOT_DATA_MISSING))
@pytest.mark.parametrize(
    ("name", "joint", "low", "top"),
    [("box-3-2-1-panda.toml", "panda_joint5", 0.0, 0.5), ("box-3-2-1-ur5.toml", "wrist_1_joint", 0.9, 1.0)],
)
def test_the_default_box_loaded_by_a_robot_of_example_robot_data(name: str, joint: str, low: float, top: float) -> None:
    """problems/: planned and verified, every knot's joints put the part at its pose to 1e-9, and the most
    loaded joint (the one each file names) carries the torque the report says, in [low, top) of its limit.

    The UR5 carries the part's weight in its approach from free space 1.42 m from its tool: the moment
    about wrist_1's horizontal axis is at most 19.62 N × 1.42 m = 27.9 N·m against its 28 N·m."""
    path = PROBLEMS / name
    fx = fixplan.load(path)
    result = fixplan.solve(fx)
    assert result.status == "planned", result.reason
    report = result.robot
    assert report is not None and report.feasible and report.worst_joint == joint
    arm = Arm(fx.robot, fx.gravity)
    for k, (_, pose, _, _) in zip(report.knots, plan_knots(fx, result.plan), strict=True):
        got = arm.part_pose_of(k.q)
        assert np.linalg.norm(got.p_world - pose.p_world) <= 1e-9
        assert np.linalg.norm(log_so3(got.R_world_body.T @ pose.R_world_body)) <= 1e-9
    i = arm.joint_names.index(joint)
    worst = max(abs(float(k.torque_Nm[i])) for k in report.knots) / arm.effort_Nm[i]
    assert report.max_torque_ratio == pytest.approx(worst, rel=1e-12) and low <= worst < top
    if name == "box-3-2-1-ur5.toml":
        g = float(np.linalg.norm(fx.gravity))
        lever = float(np.linalg.norm(fx.robot.grasp.p_world[:2]))
        assert worst * arm.effort_Nm[i] <= fx.workpiece.mass_kg * g * lever
    links = result.verification.extras["robot_links"]
    assert links["first_hit"] is None and links["min_clearance_m"] > 0.0
    # the executor kept every push within the arm's joints too
    assert result.verification.execution.max_arm_torque_ratio <= 1.0 + 1e-9
