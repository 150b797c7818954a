"""Verification: run a plan through the simulated haptic loop and check what really happened.

The operator model follows the plan: along each transition the device reference is the planned
workpiece pose, led by ``w_plan / K`` so that the coupling transmits the planned wrench, and the
operator pushes the handle with the feedforward ``w_plan + b ẋ_ref`` plus PD tracking. The
engine runs at the coupling rate (1 kHz). A plan passes when

- the observed contact-state sequence (sets of locators pressed for at least ``dwell_s``)
  matches the planned one;
- the workpiece never stalls where the plan expects motion;
- at the end every locator touches (gaps ≤ ``final_gap_m``);
- penetration stays below ``max_penetration_m``.

A failure says where (transition, time) and why.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import SolverError
from fixplan.fixture import Fixture
from fixplan.haptics import DeviceSpecs, HapticLoop, LoopRecord, SimulatedDevice, VirtualCoupling
from fixplan.pose import Pose, log_so3
from fixplan.simulator import Simulator

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class VerificationTrace:
    """What the simulated load looked like, sampled every ``every_s`` (and at the last tick).

    ``coupling_wrench`` is the wrench the virtual coupling applied to the workpiece (device
    coordinates: force and moment about the body origin, world axes); ``felt_wrench`` is what the
    device displayed to the user (saturated). Contact forces are on the workpiece, world axes.
    """

    every_s: float
    names: tuple[str, ...]  # locators, in file order
    time_s: FloatArray  # (T,)
    poses: tuple[Pose, ...]  # (T,)
    gaps_m: FloatArray  # (T, n)
    normal_forces_N: FloatArray  # (T, n)
    forces_world_N: FloatArray  # (T, n, d)
    coupling_wrench: FloatArray  # (T, ndof)
    felt_wrench: FloatArray  # (T, ndof)
    pressed: tuple[tuple[str, ...], ...]  # locators pushing on the part at each sample

    def to_json(self) -> dict[str, Any]:
        def rows(a: FloatArray) -> list[list[float]]:
            return [[float(x) for x in r] for r in a]

        return {
            "every_s": self.every_s,
            "names": list(self.names),
            "time_s": [float(t) for t in self.time_s],
            "poses": [p.to_json() for p in self.poses],
            "gaps_m": {n: [float(x) for x in self.gaps_m[:, i]] for i, n in enumerate(self.names)},
            "normal_forces_N": {n: [float(x) for x in self.normal_forces_N[:, i]] for i, n in enumerate(self.names)},
            "forces_world_N": {n: rows(self.forces_world_N[:, i]) for i, n in enumerate(self.names)},
            "coupling_wrench": rows(self.coupling_wrench),
            "felt_wrench": rows(self.felt_wrench),
            "pressed": [list(s) for s in self.pressed],
        }


def trace_from_record(rec: LoopRecord, names: Sequence[str], every: int) -> VerificationTrace:
    """Collect the loop's sampled trace (``HapticLoop.run(..., trace_every=every)``) into arrays."""
    ticks = [k for k, _, _, _ in rec.trace]
    return VerificationTrace(
        every_s=every * rec.period_s,
        names=tuple(names),
        time_s=np.array([t for _, t, _, _ in rec.trace]),
        poses=tuple(p for _, _, p, _ in rec.trace),
        gaps_m=np.array([[c.gap_m for c in cs] for _, _, _, cs in rec.trace]),
        normal_forces_N=np.array([[c.normal_force_N for c in cs] for _, _, _, cs in rec.trace]),
        forces_world_N=np.array([[c.force_world for c in cs] for _, _, _, cs in rec.trace]),
        coupling_wrench=np.array([rec.coupling_wrench[k] for k in ticks]),
        felt_wrench=np.array([rec.felt_wrench[k] for k in ticks]),
        pressed=tuple(rec.active_contacts[k] for k in ticks),
    )


@dataclass
class Verification:
    """The outcome of running a plan through the haptic loop."""

    passed: bool
    reason: str
    final_pose: Pose
    max_penetration_m: float
    deadline_misses: int
    tick_mean_us: float
    tick_max_us: float
    observed_sequence: list[tuple[str, ...]]
    final_gaps_m: dict[str, float]
    duration_s: float
    felt_force_max_N: float
    unconverged_steps: int = 0
    max_solver_error: float = 0.0
    trace: VerificationTrace | None = None
    extras: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "passed": self.passed,
            "reason": self.reason,
            "final_pose": self.final_pose.to_json(),
            "max_penetration": self.max_penetration_m,
            "deadline_misses": self.deadline_misses,
            "tick_mean_us": self.tick_mean_us,
            "tick_max_us": self.tick_max_us,
            "observed_sequence": [list(s) for s in self.observed_sequence],
            "final_gaps": self.final_gaps_m,
            "duration_s": self.duration_s,
            "felt_force_max": self.felt_force_max_N,
            "unconverged_steps": self.unconverged_steps,
            "max_solver_error": self.max_solver_error,
            "trace": None if self.trace is None else self.trace.to_json(),
        }


def pose_coordinates(pose: Pose, R0: FloatArray) -> FloatArray:
    """Device coordinates of a workpiece pose: body origin (+ rotation vector of R R0ᵀ in 3D)."""
    if pose.dimension == 3:
        return np.concatenate([pose.p_world, log_so3(pose.R_world_body @ R0.T)])
    return np.array([pose.p_world[0], pose.p_world[1], pose.angle_rad])


def _phase(ends: FloatArray, t: float) -> str:
    i = int(np.searchsorted(ends, t, side="right"))
    return f"transition {i + 1}" if i < len(ends) else "settling after the last transition"


def compress_states(samples: Sequence[tuple[float, frozenset[str]]], dwell_s: float) -> list[tuple[str, ...]]:
    """The sequence of contact states held for at least ``dwell_s`` (chatter removed)."""
    out: list[tuple[str, ...]] = []
    i = 0
    n = len(samples)
    while i < n:
        t0, s = samples[i]
        j = i
        while j + 1 < n and samples[j + 1][1] == s:
            j += 1
        t1 = samples[j][0]
        key = tuple(sorted(s))
        if t1 - t0 >= dwell_s - 1e-12 and key and (not out or out[-1] != key):
            out.append(key)
        i = j + 1
    return out


def verify(
    fixture: Fixture,
    sequence: Sequence[Sequence[str]],
    knots: Sequence[Sequence[Pose]],
    wrenches: Sequence[FloatArray],
    durations_s: Sequence[float],
    *,
    settle_s: float = 0.3,
    dwell_s: float = 0.01,
    final_gap_m: float = 1e-4,
    max_penetration_m: float = 1e-5,
    stall_speed: float = 1e-5,
    stall_s: float = 0.1,
    trace_every_s: float = 0.01,
    max_sweeps: int = 40,
) -> Verification:
    """Run the plan through the loop: per transition the knot poses, the wrench per segment (or one), a duration."""
    # a real-time loop bounds its work: a haptic-grade residual and at most ``max_sweeps`` NSGS
    # sweeps per tick (≈ 7 µs a sweep with five or six sliding contacts: 40 sweeps stay within
    # 0.3 ms of the 1 ms period). Steps that stop at the cap are counted, and the worst residual
    # reached is reported: NSGS stalls near 1e-4 on some sliding contact sets, and 100 sweeps
    # (1.3 ms, a missed deadline) only took it from 2e-4 to 7e-5 on the default box.
    sim = Simulator(fixture, tolerance=1e-6, max_iterations=max_sweeps)
    R0 = fixture.start.R_world_body.copy()
    ndof = 6 if fixture.dimension == 3 else 3
    x0 = pose_coordinates(fixture.start, R0)
    # the device is sized to the limits the plan was made for (the manipulator's, or the wrench
    # search's defaults): a plan may push as hard as those allow, and a weaker device would let
    # the operator overpower its motors and spin the handle away
    wp = fixture.workpiece
    g = float(np.linalg.norm(fixture.gravity)) or 9.81
    F_max = fixture.manipulator.max_force_N if math.isfinite(fixture.manipulator.max_force_N) else 5.0 * wp.mass_kg * g
    T_max = (
        fixture.manipulator.max_torque_Nm
        if math.isfinite(fixture.manipulator.max_torque_Nm)
        else F_max * wp.shape.bounding_radius
    )
    specs = DeviceSpecs(
        max_force_N=1.05 * F_max,
        max_torque_Nm=1.05 * T_max,
        max_stiffness_N_per_m=5000.0,
        max_damping_Ns_per_m=50.0,
        workspace_radius_m=0.5,
        physical_damping_Ns_per_m=8.0,
    )
    dev = SimulatedDevice(ndof, mass_kg=0.2, inertia_kgm2=2e-4, specs=specs, x0=x0)
    b = dev.specs.physical_damping_Ns_per_m
    coupling = VirtualCoupling(2000.0, 2.0, 40.0, 0.02, sim.dt, device_damping=b, device_damping_rot=b * 1e-2)
    loop = HapticLoop(sim, dev, coupling)
    K = np.concatenate([np.full(fixture.dimension, coupling.K_lin), np.full(ndof - fixture.dimension, coupling.K_rot)])
    # the reference: knot coordinates spread evenly over each transition, then a settling phase
    times: list[float] = [0.0]
    refs: list[FloatArray] = [x0]
    pushes: list[FloatArray] = []
    t = 0.0
    seg_pushes: list[FloatArray] = []  # the feedforward for each reference segment
    for poses, w, T in zip(knots, wrenches, durations_s, strict=True):
        coords = [pose_coordinates(p, R0) for p in poses]
        W = np.atleast_2d(np.asarray(w, dtype=float))
        for k, c in enumerate(coords[1:], 1):
            times.append(t + T * k / (len(coords) - 1))
            refs.append(c)
            seg_pushes.append(W[min(k - 1, W.shape[0] - 1)])
        pushes.append(W[-1])
        t += T
    ends = np.cumsum(durations_s)
    total = t + settle_s
    times_arr = np.array(times)
    refs_arr = np.array(refs)
    final_push = pushes[-1] if pushes else np.zeros(ndof)

    def reference(tt: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        if tt >= times_arr[-1]:
            return refs_arr[-1], np.zeros(ndof), final_push
        k = int(np.searchsorted(times_arr, tt, side="right")) - 1
        push = seg_pushes[k]
        dt = times_arr[k + 1] - times_arr[k]
        s = (tt - times_arr[k]) / dt
        x = (1 - s) * refs_arr[k] + s * refs_arr[k + 1]
        v = (refs_arr[k + 1] - refs_arr[k]) / dt
        return x, v, push

    # operator PD gains per coordinate, scaled by the handle's mass and inertia so both have the
    # same natural frequency (≈ 45 rad/s) and damping ratio (≈ 1) at the 1 kHz tick
    d = fixture.dimension
    m_dev, i_dev = 0.2, 2e-4
    kp = np.concatenate([np.full(d, 400.0), np.full(ndof - d, 400.0 * i_dev / m_dev)])
    kd = np.concatenate([np.full(d, 18.0), np.full(ndof - d, 18.0 * i_dev / m_dev)])
    damping = np.concatenate([np.full(d, b), np.full(ndof - d, b * 1e-2)])

    def operator(tt: float, device: SimulatedDevice) -> FloatArray:
        x_ref, v_ref, push = reference(tt)
        lead = push / K
        return push + damping * v_ref + kp * (x_ref + lead - device.position()) + kd * (v_ref - device.velocity())

    try:
        trace_every = max(int(round(trace_every_s / sim.dt)), 1) if trace_every_s > 0 else 0
        rec = loop.run(total, operator, trace_every=trace_every)
    except SolverError as exc:
        return Verification(
            passed=False,
            reason=f"the simulated load diverged at t = {sim.time_s:.3f} s ({_phase(ends, sim.time_s)}): {exc}",
            final_pose=sim.pose,
            max_penetration_m=sim.max_penetration_m,
            deadline_misses=0,
            tick_mean_us=0.0,
            tick_max_us=0.0,
            observed_sequence=[],
            final_gaps_m={},
            duration_s=sim.time_s,
            felt_force_max_N=0.0,
        )
    # observed contact states: locators pressed (positive normal force) at each tick
    samples: list[tuple[float, frozenset[str]]] = []
    for tt, active in zip(rec.time_s, rec.active_contacts, strict=True):
        samples.append((tt, frozenset(active)))
    observed = compress_states(samples, dwell_s)
    planned = [tuple(sorted(s)) for s in sequence]
    gaps = {c.name: float(c.gap_m) for c in sim.contacts()}
    pen = sim.max_penetration_m
    reasons = []
    if planned and observed != planned:
        k = next(
            (i for i, (a, b) in enumerate(zip(observed, planned, strict=False)) if a != b),
            min(len(observed), len(planned)),
        )
        seen = observed[k] if k < len(observed) else "nothing more"
        want = planned[k] if k < len(planned) else "nothing more"
        reasons.append(f"the contact states leave the plan at step {k + 1}: observed {seen}, planned {want}")
    far = {n: g for n, g in gaps.items() if abs(g) > final_gap_m}
    if far:
        reasons.append(
            "at the end "
            + ", ".join(f"{n} is {g:.3g} m away" for n, g in far.items())
            + f" (expected ≤ {final_gap_m:g} m)"
        )
    if pen > max_penetration_m:
        reasons.append(f"penetration reached {pen:.3g} m (expected ≤ {max_penetration_m:g} m)")
    # stall: no progress for stall_s while the plan expects motion
    pos = np.array(rec.workpiece_position)
    speed = np.linalg.norm(np.diff(pos, axis=0), axis=1) / sim.dt if len(pos) > 1 else np.zeros(0)
    run_len = int(math.ceil(stall_s / sim.dt))
    # a stall: stopped for stall_s while the current transition's target is not yet pressed
    # (arriving early, or in a slightly different orientation, and waiting is not a stall)
    targets = [sorted(set(b) - set(a)) for a, b in zip(planned, planned[1:], strict=False)]
    end_positions = [np.asarray(poses[-1].p_world) for poses in knots]
    still = 0
    for k, sp in enumerate(speed):
        tt = rec.time_s[k]
        i = int(np.searchsorted(ends, tt, side="right"))
        if i >= len(end_positions):
            break
        target = targets[i] if i < len(targets) else []
        reached = bool(target) and all(n in rec.active_contacts[k + 1] for n in target)
        away = float(np.linalg.norm(pos[k + 1] - end_positions[i]))
        still = still + 1 if (sp < stall_speed and not reached) else 0
        if still >= run_len:
            reasons.append(
                f"the workpiece stalled at t = {tt:.3f} s in transition {i + 1}, {away * 1e3:.2f} mm from where it should end"
                + (f", before touching {', '.join(target)}" if target else "")
            )
            break
    felt = max((float(np.linalg.norm(f[: fixture.dimension])) for f in rec.felt_wrench), default=0.0)
    return Verification(
        passed=not reasons,
        reason="; ".join(reasons) if reasons else "every check passed",
        final_pose=sim.pose,
        max_penetration_m=pen,
        deadline_misses=rec.deadline_misses,
        tick_mean_us=rec.mean_compute_s * 1e6,
        tick_max_us=rec.max_compute_s * 1e6,
        observed_sequence=observed,
        final_gaps_m=gaps,
        duration_s=total,
        felt_force_max_N=felt,
        unconverged_steps=rec.unconverged_steps,
        max_solver_error=rec.max_solver_error,
        trace=trace_from_record(rec, sim.names, trace_every) if rec.trace else None,
    )
