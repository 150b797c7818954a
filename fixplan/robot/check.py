"""Can this arm, at this base, carry the plan out? The plan's knots through the arm.

For every knot of the plan (each transition's poses, the shared end and start counted once) the
part's pose gives the tool's (``X · grasp``); inverse kinematics gives ``q`` (the first knot from
several starts, each later one from the knot before, so the joint path is continuous); the knot
times are the transitions' planned durations spread evenly over their segments; ``q̇`` and
``q̈`` are the finite differences of ``q`` over those times. The push at a knot is its segment's
planned wrench (the transition's mean where the segments are not known, the part's weight held
where no push is planned). Then ``τ = RNEA(q, q̇, q̈) + Jᵀ w`` (:meth:`Arm.torques`).

The report answers, in this order of blame: a knot out of reach (which knot, how far the tool
stays from its target, which joint is held at a limit); a jump of the joint path (an elbow or
wrist flip between two knots); a joint beyond its effort limit (which knot, which joint, the
torque against the limit); a link that hits the fixture or the part (:mod:`.clearance`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fixplan.model import Fixture
from fixplan.robot.arm import Arm
from fixplan.settings import DEFAULT, RobotSettings
from fixplan.spatial import Pose, shift_wrench_by

if TYPE_CHECKING:
    from fixplan.planner.plan import Plan

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RobotKnot:
    """One knot: its time, the joints, the part's pose, the tool's pose error and the torques."""

    time_s: float
    q: FloatArray
    part_pose: Pose
    transition: int  # 1-based; 0 for the plan's very first pose
    ik_error: float
    torque_Nm: FloatArray
    wrench: FloatArray  # the hand's push on the part at the tool origin, world axes [N, N·m]

    def to_json(self) -> dict[str, Any]:
        return {
            "time_s": self.time_s,
            "q": [float(x) for x in self.q],
            "part_pose": self.part_pose.to_json(),
            "transition": self.transition,
            "torque_Nm": [float(x) for x in self.torque_Nm],
        }


@dataclass
class RobotReport:
    """What the arm makes of a plan (see the module docstring); ``feasible`` when it carries it out."""

    robot: str
    joints: tuple[str, ...]
    reachable: bool
    knots: list[RobotKnot]
    max_torque_ratio: float
    max_velocity_ratio: float
    joint_limit_margin_rad: float
    min_clearance_m: float | None
    reason: str
    worst_joint: str | None = None
    worst_knot: int | None = None
    notes: list[str] = field(default_factory=list)
    hand_limits: ArmLimits | None = (
        None  # the ball of pushes inscribed in the arm's set at start and goal (solve sets it)
    )

    @property
    def feasible(self) -> bool:
        clear = self.min_clearance_m is None or self.min_clearance_m >= 0.0
        return self.reachable and self.max_torque_ratio <= 1.0 and clear

    def to_json(self) -> dict[str, Any]:
        return {
            "robot": self.robot,
            "joints": list(self.joints),
            "reachable": self.reachable,
            "feasible": self.feasible,
            "knots": [k.to_json() for k in self.knots],
            "max_torque_ratio": _finite(self.max_torque_ratio),
            "max_velocity_ratio": _finite(self.max_velocity_ratio),
            "joint_limit_margin_rad": _finite(self.joint_limit_margin_rad),
            "min_clearance_m": None if self.min_clearance_m is None else _finite(self.min_clearance_m),
            "worst_joint": self.worst_joint,
            "worst_knot": self.worst_knot,
            "reason": self.reason,
            "notes": list(self.notes),
            "hand_limits": None if self.hand_limits is None else self.hand_limits.to_json(),
        }


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def plan_knots(fixture: Fixture, plan: Plan) -> list[tuple[float, Pose, FloatArray, int]]:
    """``(time [s], part pose, push about the body origin (world axes), transition)`` at every knot of ``plan``."""
    wp = fixture.workpiece
    out: list[tuple[float, Pose, FloatArray, int]] = []
    t0 = 0.0
    for i, tr in enumerate(plan.transitions, start=1):
        poses = list(tr.poses)
        if len(poses) < 2:
            continue
        segments = len(poses) - 1
        dt = float(tr.time_s) / segments if tr.time_s and math.isfinite(tr.time_s) else 0.0
        seg = tr.segment_wrenches
        for k, pose in enumerate(poses):
            if out and k == 0:
                continue  # the end of the transition before
            if seg is not None and len(seg) and np.all(np.isfinite(seg[min(k, len(seg) - 1)])):
                w = np.asarray(seg[min(k, len(seg) - 1)], dtype=float)
            elif tr.wrench is not None and np.all(np.isfinite(tr.wrench)):
                w = np.asarray(tr.wrench, dtype=float)
            else:
                # no planned push: the hand holds the part's weight (about the body origin)
                f = -wp.mass_kg * np.asarray(fixture.gravity, dtype=float)
                com = pose.point_world_from_body(wp.com_body)
                w = shift_wrench_by(np.concatenate([f, np.zeros(3)]), pose.p_world - com)
            out.append((t0 + k * dt, pose, w, i))
        t0 += dt * segments
    if out:
        first = out[0]
        out[0] = (first[0], first[1], first[2], 0)
    return out


def check_plan(fixture: Fixture, plan: Plan, settings: RobotSettings = DEFAULT.robot) -> RobotReport:
    """The arm of ``fixture.robot`` along ``plan``'s knots (see the module docstring)."""
    if fixture.robot is None:
        raise ValueError("the fixture has no [robot]")
    arm = Arm(fixture.robot, fixture.gravity, settings)
    knots = plan_knots(fixture, plan)
    name = arm.loaded.source
    if not knots:
        return RobotReport(name, arm.joint_names, True, [], 0.0, 0.0, math.inf, None, "the plan has no knot to carry")
    from fixplan.robot.clearance import least_clearance

    qs: list[FloatArray] = []
    errors: list[float] = []
    for j, (_, pose, _, _) in enumerate(knots):
        R, p = arm.tool_target(pose)
        if j == 0:
            # the first knot's branch: the first reaching one clear of the fixture and the part
            q, err = first_configuration(arm, fixture, pose)
        else:
            q, err = arm.ik(R, p, qs[-1])
        qs.append(q)
        errors.append(err)
    times = np.array([k[0] for k in knots])
    Q = np.array(qs)
    V, A = _derivatives(times, Q)
    report_knots: list[RobotKnot] = []
    ratios = np.zeros((len(knots), arm.nq))
    for j, ((t, pose, w_body, tr), q) in enumerate(zip(knots, qs, strict=True)):
        R, p = arm.tool_target(pose)
        w_tool = shift_wrench_by(w_body, p - pose.p_world)  # about the tool frame's origin
        tau = arm.torques(q, V[j], A[j], w_tool)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratios[j] = np.where(arm.effort_Nm > 0, np.abs(tau) / arm.effort_Nm, 0.0)
        report_knots.append(RobotKnot(float(t), q, pose, tr, errors[j], tau, w_tool))
    with np.errstate(divide="ignore", invalid="ignore"):
        vel = np.where(arm.velocity_limit > 0, np.abs(V) / arm.velocity_limit, 0.0)
    margin = min(arm.limit_margin(q) for q in qs)
    worst = np.unravel_index(int(np.argmax(ratios)), ratios.shape)
    ratio = float(ratios[worst])
    report = RobotReport(
        name, arm.joint_names, True, report_knots, ratio, float(np.max(vel)) if vel.size else 0.0, margin, None, "",
        worst_joint=arm.joint_names[worst[1]], worst_knot=int(worst[0]),
    )  # fmt: skip
    if arm.loaded.collision_note:
        report.notes.append(arm.loaded.collision_note)
    far = [j for j, e in enumerate(errors) if e > settings.reach_tol_m]
    if far:
        j = far[0]
        report.reachable = False
        report.worst_knot = j
        held = _held_joints(arm, qs[j])
        report.reason = (
            f"knot {j} ({_where(knots[j])}) is out of reach: the tool stays {errors[j]:.3g} (m and rad) from its "
            f"target" + (f"; {held} at its limit" if held else "") + f" (base at {_xyz(arm.p_world_root)})"
        )
        return report
    steps = np.max(np.abs(np.diff(Q, axis=0)), axis=1) if len(qs) > 1 else np.zeros(0)
    if steps.size and float(np.max(steps)) > settings.max_step_rad:
        j = int(np.argmax(steps))
        joint = int(np.argmax(np.abs(Q[j + 1] - Q[j])))
        report.reachable = False
        report.worst_knot, report.worst_joint = j + 1, arm.joint_names[joint]
        report.reason = (
            f"knot {j + 1} ({_where(knots[j + 1])}): joint {arm.joint_names[joint]} jumps {steps[j]:.3g} rad from the "
            f"knot before (the arm would flip between knots; expected at most {settings.max_step_rad:g} rad)"
        )
        return report
    clearance = least_clearance(arm, fixture, [(k[1], q) for k, q in zip(knots, qs, strict=True)])
    if clearance is not None:
        report.min_clearance_m = clearance.distance_m
    if ratio > 1.0:
        j, joint = int(worst[0]), int(worst[1])
        report.reason = (
            f"knot {j} ({_where(knots[j])}): joint {arm.joint_names[joint]} needs {abs(report_knots[j].torque_Nm[joint]):.3g} "
            f"N·m against its effort limit {arm.effort_Nm[joint]:.3g} N·m"
        )
    elif clearance is not None and clearance.distance_m < 0.0:
        report.worst_knot = clearance.knot
        report.reason = (
            f"knot {clearance.knot} ({_where(knots[clearance.knot])}): {clearance.link} hits {clearance.other} "
            f"({-clearance.distance_m:.3g} m deep)"
        )
    else:
        report.reason = (
            f"reachable through {len(knots)} knots; the most loaded joint is {report.worst_joint} at "
            f"{100.0 * ratio:.0f} % of its effort limit"
        )
    return report


@dataclass(frozen=True)
class ArmLimits:
    """The hand's limits the arm can honour at the part's start and goal: ``s ×`` the fixture's."""

    max_force_N: float
    max_torque_Nm: float
    scale: float  # ≤ 1: the factor applied to the fixture's hand limits
    joint: str | None  # the joint that binds (None: none does)
    where: str  # "start" or "goal"

    def to_json(self) -> dict[str, Any]:
        return {
            "max_force_N": self.max_force_N,
            "max_torque_Nm": self.max_torque_Nm,
            "scale": self.scale,
            "joint": self.joint,
            "where": self.where,
        }


def first_configuration(arm: Arm, fixture: Fixture, pose: Pose) -> tuple[FloatArray, float]:
    """``(q, error)``: the first reaching branch at ``pose`` whose links clear the fixture and the part."""
    from fixplan.robot.clearance import least_clearance

    R, p = arm.tool_target(pose)
    candidates = arm.ik_starts(R, p)
    for q_c, err_c in candidates:
        if err_c > arm.settings.reach_tol_m:
            break
        c = least_clearance(arm, fixture, [(pose, q_c)])
        if c is None or c.distance_m >= 0.0:
            return q_c, err_c
    return candidates[0]


def arm_hand_limits(fixture: Fixture, force_N: float, torque_Nm: float) -> ArmLimits | None:
    """The hand limits ``(F, T)`` scaled to what the arm exerts at the start and goal poses (None: no robot).

    The ball of pushes the arm can exert there (:meth:`Arm.exertable_scale`), inscribed in its
    set: what a hand with only force and torque limits could be given. :func:`~fixplan.solve`
    reports it; its searches use the arm's set itself (:meth:`Arm.torque_box`). A pose the arm cannot reach leaves the limits as they are (the plan
    check then refuses the plan, naming the knot).
    """
    if fixture.robot is None:
        return None
    arm = Arm(fixture.robot, fixture.gravity)
    best = ArmLimits(force_N, torque_Nm, 1.0, None, "start")
    poses = [("start", fixture.start)] + ([("goal", fixture.goal_pose)] if fixture.goal_pose is not None else [])
    q_prev: FloatArray | None = None
    for where, pose in poses:
        if q_prev is None:
            q, err = first_configuration(arm, fixture, pose)
        else:
            R, p = arm.tool_target(pose)
            q, err = arm.ik(R, p, q_prev)
        if err > arm.settings.reach_tol_m:
            continue
        q_prev = q
        R, p = arm.tool_target(pose)
        s, joint = arm.exertable_scale(q, float(np.linalg.norm(p - pose.p_world)), force_N, torque_Nm)
        if s < best.scale:
            name = arm.joint_names[joint] if joint >= 0 else None
            best = ArmLimits(s * force_N, s * torque_Nm, s, name, where)
    return best


def _derivatives(times: FloatArray, Q: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``q̇`` and ``q̈`` at the knots: finite differences over the knot times (zero where time stands still)."""
    n = len(times)
    if n < 3 or not np.all(np.diff(times) > 0):
        return np.zeros_like(Q), np.zeros_like(Q)
    V = np.gradient(Q, times, axis=0)
    A = np.gradient(V, times, axis=0)
    return V, A


def _held_joints(arm: Arm, q: FloatArray) -> str:
    at = [arm.joint_names[i] for i in range(arm.nq) if min(q[i] - arm.lower[i], arm.upper[i] - q[i]) <= 0.0]
    return ", ".join(at)


def _where(knot: tuple[float, Pose, FloatArray, int]) -> str:
    t, pose, _, tr = knot
    return f"t = {t:.3g} s, transition {tr}, part at {_xyz(pose.p_world)}"


def _xyz(p: FloatArray) -> str:
    return "(" + ", ".join(f"{float(x):.3g}" for x in p) + ") m"


__all__ = [
    "ArmLimits",
    "RobotKnot",
    "RobotReport",
    "arm_hand_limits",
    "check_plan",
    "first_configuration",
    "plan_knots",
]
