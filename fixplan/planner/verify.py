"""Verification: run a plan through the simulated haptic loop and check what really happened.

The plan is executed as a contact-state feedback policy (:class:`~fixplan.planner.execute.Executor`):
at the control rate the executor observes the pressed locators and the pose, and re-solves the
non-jamming wrench for the motion the current transition expects. The operator model makes the
virtual coupling transmit that wrench: it holds the device handle ``w / K`` ahead of the
workpiece (feedforward ``w + b ẋ`` plus PD on the handle). The engine runs at the coupling rate
(1 kHz). A plan passes when

- the executor reaches the goal state (every locator pressed, at rest) — re-plans on the way
  (after a lost or unplanned contact) are allowed, counted and reported;
- at the end every locator touches (gaps ≤ ``final_gap_m``);
- penetration stays below ``max_penetration_m``;
- the contact solver's largest residual over the ticks stays below the profile's
  ``verification.max_solver_error`` (a tick's solve may stop at the sweep cap, but a load
  simulated with forces the solver did not find proves nothing: the check names how many steps
  did not converge and the largest residual);
- the push on the part stays within the manipulator's limits (averaged over 10 ms, 5 % slack
  for the coupling's transients);
- with a ``[robot]``, no link of the arm penetrates the fixture or the part along the simulated
  load: a post-pass over the loop's trace (the part's pose every ``trace_every_s``), one sample
  every ``robot.clearance_every_s`` at most, the joints by inverse kinematics from sample to
  sample, coal on the URDF's collision geometry (:func:`link_clearance`). The failure names the
  link, what it hits and when; ``extras["robot_links"]`` carries the least clearance and when.

The executor's push at every tick (what the hand is asked for) is measured against the headroom
its searches keep (``settings.search.limit_fraction`` of the limits):
``peak_force_fraction``, ``peak_torque_fraction`` and ``ticks_above_fraction``; the trace carries
it as ``command_wrench``.

A failure says where (transition, time) and why; divergence (non-finite state, a speed beyond
what the push can cause) stops the run with that reason.

The tick timing (``tick_mean_us``, ``tick_max_us``, ``deadline_misses``) includes the executor's
command, and so any re-plan it runs from inside a tick: simulated time stands still while it
runs, and that tick misses its deadline. ``planner_wall_time_in_loop_s`` is the wall time of
those re-plans together.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fixplan.contact_state import format_state
from fixplan.engine.simulator import Simulator
from fixplan.errors import SolverError
from fixplan.haptics import SimulatedDevice
from fixplan.haptics.coordinates import coordinates_from_pose
from fixplan.haptics.loop import LoopRecord
from fixplan.haptics.rig import haptic_rig
from fixplan.kinematics import mass_matrix
from fixplan.model import Fixture
from fixplan.planner.execute import (
    Avoid,
    ExecutionNoise,
    Executor,
    Replan,
    Step,
    mass_speed,
)
from fixplan.planner.fine import twist_from_pose
from fixplan.planner.plan_types import Timeline, Verification
from fixplan.planner.policy import Policy
from fixplan.settings import HAPTIC, Settings, VerificationSettings
from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]


def final_gap_check(gaps: dict[str, float], final_gap_m: float, checks: list[str], reasons: list[str]) -> None:
    """The check "final gap": every named gap at the end within ``final_gap_m`` (appended when not)."""
    far = {n: g for n, g in gaps.items() if abs(g) > final_gap_m}
    if far:
        checks.append("final gap")
        reasons.append(
            "at the end "
            + ", ".join(f"{n} is {g:.3g} m away" for n, g in far.items())
            + f" (expected ≤ {final_gap_m:g} m)"
        )


def loop_checks(
    rec: LoopRecord,
    sim: Simulator,
    max_penetration_m: float,
    vs: VerificationSettings,
    F_max: float,
    T_max: float,
    limit_slack: float,
    checks: list[str],
    reasons: list[str],
) -> tuple[float, float]:
    """The loop's own checks, appended in this order: "penetration", "solver", "limits".

    Returns the largest push force [N] and moment [N·m] on the part, averaged over
    ``vs.limit_window_s`` (the limits check compares them with the manipulator's limits).
    """
    d = sim.dimension
    ndof = 6 if d == 3 else 3
    pen = sim.max_penetration_m
    if pen > max_penetration_m:
        checks.append("penetration")
        reasons.append(f"penetration reached {pen:.3g} m (expected ≤ {max_penetration_m:g} m)")
    # a load simulated with contact forces the solver did not find proves nothing: the steps that
    # stopped at the sweep cap are allowed while their residual stays small
    worst = rec.max_solver_error
    if worst is not None and worst > vs.max_solver_error:
        checks.append("solver")
        reasons.append(
            f"the contact solver did not converge in {rec.unconverged_steps} of {len(rec.compute_s)} steps "
            f"(largest residual {worst:.2g}, expected ≤ {vs.max_solver_error:g})"
        )
    # the push on the part, averaged over 10 ms, against the manipulator's limits
    W = np.array(rec.coupling_wrench) if rec.coupling_wrench else np.zeros((1, ndof))
    win = max(int(round(vs.limit_window_s / sim.dt)), 1)
    if W.shape[0] >= win:
        kernel = np.ones(win) / win
        Wf = np.array([np.convolve(W[:, j], kernel, mode="valid") for j in range(ndof)]).T
    else:
        Wf = W
    push_F = float(np.max(np.linalg.norm(Wf[:, :d], axis=1)))
    push_T = float(np.max(np.linalg.norm(Wf[:, d:], axis=1)))
    if push_F > (1 + limit_slack) * F_max or push_T > (1 + limit_slack) * T_max:
        checks.append("limits")
        reasons.append(
            f"the push on the part exceeded the manipulator's limits: ‖F‖ up to {push_F:.3g} N (max_force {F_max:.3g} N), "
            f"‖T‖ up to {push_T:.3g} N·m (max_torque {T_max:.3g} N·m), averaged over {vs.limit_window_s * 1e3:g} ms"
        )
    return push_F, push_T


def verify(
    fixture: Fixture,
    start_state: frozenset[str],
    steps: Sequence[Step],
    *,
    settings: Settings = HAPTIC,
    noise: ExecutionNoise | None = None,
    replan: Replan | None = None,
    time_limit_s: float | None = None,
    final_gap_m: float | None = None,
    max_penetration_m: float | None = None,
    limit_slack: float | None = None,
    trace_every_s: float | None = None,
    max_sweeps: int | None = None,
    policy: Policy | None = None,
    avoid: Avoid | None = None,
) -> Verification:
    """Execute the plan (``steps`` from ``start_state``) in the haptic loop and check the outcome.

    ``settings`` (default: the ``haptic`` profile, :mod:`fixplan.settings`) give the engine, the
    rig, the thresholds, how the executor pushes (``settings.execution``) and what its wrench
    searches keep to (``search``, ``witness``, ``numerics``); ``final_gap_m``, ``max_penetration_m``, ``limit_slack``,
    ``trace_every_s`` and ``max_sweeps`` override single ones. ``policy`` (:mod:`.policy`) is
    what the executor consults when it observes a state the plan does not expect, before it
    re-plans.
    """
    vs = settings.verification
    final_gap_m = vs.final_gap_m if final_gap_m is None else final_gap_m
    max_penetration_m = vs.max_penetration_m if max_penetration_m is None else max_penetration_m
    limit_slack = vs.limit_slack if limit_slack is None else limit_slack
    trace_every_s = vs.trace_every_s if trace_every_s is None else trace_every_s
    # a real-time loop bounds its work: a haptic-grade residual and at most ``max_sweeps`` NSGS
    # sweeps per tick (the profile's engine). Steps that stop at the cap are counted, and the
    # worst residual reached is reported.
    sim = Simulator(fixture, max_iterations=max_sweeps, settings=settings.engine)
    R0 = fixture.start.R_world_body.copy()
    x0 = coordinates_from_pose(fixture.start, R0)
    # every re-plan the executor runs from inside a tick is timed: its wall time is the loop's
    # (the tick that waits for it misses its deadline), and the verification reports the sum
    planner_s = [0.0]
    timed_replan = None if replan is None else _timed(replan, planner_s)
    executor = Executor(
        fixture,
        start_state,
        steps,
        settings.execution,
        replan=timed_replan,
        noise=noise,
        tick_s=sim.dt,
        policy=policy,
        avoid=avoid,
        profile=settings,
    )
    F_max, T_max = executor.F_max, executor.T_max
    rig = haptic_rig(fixture, sim, x0, F_max, T_max, settings.haptic)
    if not start_state:
        # a part starting in free space is already carried: the hand holds it against gravity
        # from the first tick (the handle displaced w / K ahead), instead of letting it drop
        # until the coupling's spring catches up (a 2 kg box fell 12 mm before it did)
        w0 = executor.carry_wrench(fixture.start)
        rig = haptic_rig(fixture, sim, x0 + w0 / rig.K, F_max, T_max, settings.haptic)
        executor.preload(w0)
    else:
        press = executor.arm_start_push(fixture.start, start_state)
        if press is not None:
            # an arm that cannot hold itself without pushing: it presses the part from the first tick
            rig = haptic_rig(fixture, sim, x0 + press / rig.K, F_max, T_max, settings.haptic)
            executor.preload(press)
    loop = rig.loop
    d = fixture.dimension
    threshold = executor.threshold_N
    contact_gap_m, hold_gap_m = executor.settings.contact_gap_m, executor.settings.contact_hold_gap_m

    commands: list[FloatArray] = []  # the executor's push, every tick (what the hand is asked for)

    def operator(tt: float, device: SimulatedDevice) -> FloatArray:
        pressed = frozenset(sim.in_contact(threshold, contact_gap_m, executor.observed_state, hold_gap_m))
        w = executor.command(tt, sim.pose, sim.twist, pressed)
        commands.append(np.array(w, dtype=float))
        return rig.operator_wrench(w, device)

    if time_limit_s is None:
        # generous: every transition at the slowest speed the executor keeps, plus settling
        nominal = sum(_path_length(fixture, st) for st in steps) / executor.settings.speed_mps
        time_limit_s = min(vs.time_factor * nominal + vs.time_base_s + vs.time_per_step_s * len(steps), vs.time_max_s)
    trace_every = max(int(round(trace_every_s / sim.dt)), 1) if trace_every_s > 0 else 0
    base_limit_s = time_limit_s
    counts = executor.log.counts

    def finished() -> bool:
        # every new plan taken on the way gets time of its own (within the profile's ceiling)
        if executor.done:
            return True
        new_plans = counts["replans"] + counts["policy_switches"] + counts["dead_ends"]
        return sim.time_s >= min(base_limit_s + vs.time_per_replan_s * new_plans, ceiling_s)

    ceiling_s = max(base_limit_s, vs.time_max_s)
    try:
        rec = loop.run(ceiling_s, operator, trace_every=trace_every, until=finished)
    except SolverError as exc:
        why = f"the simulated load diverged at t = {sim.time_s:.3f} s (transition {executor.index + 1}): {exc}"
        executor._fail(sim.time_s, why, "diverged")
        return Verification(
            passed=False,
            reason=why,
            failed_checks=["executor"],
            final_pose=sim.pose,
            max_penetration_m=sim.max_penetration_m,
            deadline_misses=None,
            tick_mean_us=None,
            tick_max_us=None,
            observed_sequence=list(executor.log.observed),
            final_gaps_m=dict(zip(sim.names, map(float, sim.gaps_m()), strict=True)),  # the state was kept
            duration_s=sim.time_s,
            felt_force_max_N=None,
            execution=executor.log,
            saturated_ticks=loop.saturated_ticks,
            planner_wall_time_in_loop_s=planner_s[0],
            **headroom(commands, d, F_max, T_max, executor.limit_fraction, settings.search.binding_rel),
        )
    log = executor.log
    if log.outcome == "running":
        executor._fail(
            sim.time_s,
            f"timed out after {sim.time_s:.2f} s in transition {executor.index + 1} "
            f"({format_state(executor.states[min(executor.index, len(executor.states) - 1)])}"
            + (f" + {executor.steps[executor.index].target}" if executor.index < len(executor.steps) else "")
            + ")",
            "timeout",
        )
    gaps = {c.name: float(c.gap_m) for c in sim.contacts()}
    reasons = []
    checks = []
    if log.outcome != "reached":
        reasons.append(log.reason)
        checks.append("executor")
    final_gap_check(gaps, final_gap_m, checks, reasons)
    push_F, push_T = loop_checks(rec, sim, max_penetration_m, vs, F_max, T_max, limit_slack, checks, reasons)
    extras: dict[str, Any] = {}
    if fixture.robot is not None:
        links = link_clearance(fixture, rec.trace, settings.robot.clearance_every_s)
        if links is not None:
            extras["robot_links"] = links.to_json()
            if links.first_hit is not None:
                hit = links.first_hit
                checks.append("robot links")
                reasons.append(
                    f"at t = {links.first_hit_time_s:.3f} s {hit.link} of the arm hits {hit.other} "
                    f"({-hit.distance_m:.3g} m deep)"
                )
    measures = loop_measures(rec, sim, trace_every)
    if measures["trace"] is not None and len(commands) == len(rec.coupling_wrench):
        # the executor's push at the trace's ticks, beside the coupling's
        ticks = [k for k, _, _, _ in rec.trace]
        measures["trace"] = replace(measures["trace"], command_wrench=np.array([commands[k] for k in ticks]))
    return Verification(
        passed=not reasons,
        reason="; ".join(reasons) if reasons else "every check passed",
        failed_checks=checks,
        **measures,
        **headroom(commands, d, F_max, T_max, executor.limit_fraction, settings.search.binding_rel),
        observed_sequence=list(log.observed),
        final_gaps_m=gaps,
        execution=log,
        max_push_force_N=push_F,
        max_push_torque_Nm=push_T,
        saturated_ticks=loop.saturated_ticks,
        planner_wall_time_in_loop_s=planner_s[0],
        extras=extras,
    )


def link_clearance(fixture: Fixture, trace: Sequence[tuple[Any, ...]], every_s: float) -> Any:
    """The arm's links along a loop's trace (``(tick, time [s], pose, ...)`` samples), or None.

    :func:`fixplan.robot.clearance.along_trajectory` on the trace's poses, one every ``every_s``
    at most; None without a trace or without collision geometry.
    """
    if not trace:
        return None
    from fixplan.robot.clearance import along_trajectory

    return along_trajectory(fixture, [(float(t), pose) for _, t, pose, *_ in trace], every_s)


def headroom(
    commands: Sequence[FloatArray], d: int, F_max: float, T_max: float, fraction: float, binding_rel: float
) -> dict[str, Any]:
    """The :class:`Verification` fields of the hand's headroom, from the executor's push at every tick.

    ``peak_force_fraction`` = max ‖F‖ / ``F_max``, ``peak_torque_fraction`` = max ‖T‖ / ``T_max``
    (the moment about the body origin, as the limit bounds it), and ``ticks_above_fraction``: the
    ticks where either exceeds ``fraction`` by more than the search's binding tolerance
    ``binding_rel`` (the caller's ``settings.search``).
    """
    if not commands:
        return {"limit_fraction": fraction, "peak_force_fraction": None, "peak_torque_fraction": None,
                "ticks_above_fraction": 0}  # fmt: skip
    W = np.asarray(commands, dtype=float)
    f = np.linalg.norm(W[:, :d], axis=1) / F_max
    t = np.linalg.norm(W[:, d:], axis=1) / T_max
    above = fraction * (1.0 + binding_rel)
    return {
        "limit_fraction": fraction,
        "peak_force_fraction": float(f.max()),
        "peak_torque_fraction": float(t.max()),
        "ticks_above_fraction": int(np.count_nonzero((f > above) | (t > above))),
    }


def _timed(replan: Replan, total_s: list[float]) -> Replan:
    """``replan`` that adds its wall time [s] to ``total_s[0]``."""

    def timed(pose: Pose, state: frozenset[str]) -> list[Step] | str:
        t0 = time.perf_counter()
        try:
            return replan(pose, state)
        finally:
            total_s[0] += time.perf_counter() - t0

    return timed


def loop_measures(rec: Any, sim: Any, trace_every: int) -> dict[str, Any]:
    """The :class:`Verification` fields a finished loop run measured.

    Final pose, penetration, timing, felt force, solver quality and the trace; ``rec`` is the
    loop's record, ``sim`` its simulator.
    """
    d = sim.pose.p_world.shape[0]
    return {
        "final_pose": sim.pose,
        "max_penetration_m": sim.max_penetration_m,
        "deadline_misses": rec.deadline_misses,
        "tick_mean_us": None if rec.mean_compute_s is None else rec.mean_compute_s * 1e6,  # None: no tick ran
        "tick_max_us": None if rec.max_compute_s is None else rec.max_compute_s * 1e6,
        "duration_s": sim.time_s,
        "felt_force_max_N": max((float(np.linalg.norm(f[:d])) for f in rec.felt_wrench), default=None),
        "unconverged_steps": rec.unconverged_steps,
        "max_solver_error": rec.max_solver_error,
        "trace": Timeline.from_record(rec, sim.names, trace_every) if rec.trace else None,
    }


def _path_length(fixture: Fixture, step: Step) -> float:
    """Mass-weighted length of a step's guide path [m] (at least 1 cm)."""
    wp = fixture.workpiece
    total = 0.0
    for a, b in zip(step.path[:-1], step.path[1:], strict=True):
        M = mass_matrix(wp.mass_kg, wp.inertia_body, a.R_world_body)
        total += mass_speed(twist_from_pose(a, b, wp.com_body), M, wp.mass_kg)
    return max(total, 0.01)
