"""An interactive haptic session: a person's device drives the part through the virtual coupling.

The loop (its own thread, one tick per engine step, 1 kHz for the bundled fixtures):

1. read the device handle (:mod:`.handles`: the viser gizmo, the UDP bridge, a SpaceMouse) or,
   in *auto*, the simulated device the planner's executor drives (:func:`~fixplan.haptics.rig.haptic_rig`'s
   operator);
2. the coupling wrench ``w_c = K (x_d − x_w) + B (ẋ_d − ẋ_w)`` on the part, saturated at the
   hand's limits (the gains are ``haptic_rig``'s: scaled to the part, passive for the handle's
   damping; the mouse's stiffness slider scales ``K`` within the passivity bound);
3. the engine steps the part under ``w_c`` and gravity;
4. the device displays the felt wrench ``−w_c`` (saturated at its limits); the bridge's answer
   carries the part's state and the guidance;
5. the contact state (locators pressing or within ``contact_gap_m``, debounced) and the goal
   (every locator in contact, at rest for ``settle_s``) are observed; every ``trace_every`` ticks
   the contacts are sampled for the recording and a :class:`Snapshot` is published for the display.

Steps 2–4 are the rig's :class:`~fixplan.haptics.loop.HapticLoop` tick (the one the verification
runs), which the session holds and calls with the tick's device: the person's handle as read
(:class:`~fixplan.haptics.device.ReadDevice`) or the simulated one.

The guidance (:class:`Guide`: the planner's contact-state executor, re-solving the non-jamming
push at the observed state, and ``classify`` of the push the part receives) runs in a second
thread and never blocks the loop; or, with ``synchronous=True`` (tests, reproducible runs), inside
the loop every ``trace_every`` ticks without a wall clock.
"""

from __future__ import annotations

import gc
import math
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from fixplan.clamping.stage import ClampStage, StageRecord, StageTick
from fixplan.contact_state import Debounce, format_state
from fixplan.engine.simulator import Simulator
from fixplan.errors import InfeasibleError, InputError, SolverError, one_line
from fixplan.haptics import SimulatedDevice
from fixplan.haptics.coordinates import coordinates_from_pose, pose_from_coordinates
from fixplan.haptics.coupling import check_passivity
from fixplan.haptics.device import HapticDevice, ReadDevice, saturate
from fixplan.haptics.rig import haptic_rig
from fixplan.interactive import protocol
from fixplan.interactive.handles import Handle, UdpHandle
from fixplan.jamming.classify import MODES as CLASSIFY_MODES
from fixplan.model import Fixture
from fixplan.settings import DEFAULT, HAPTIC, HapticRigSettings, Settings
from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]

GUIDE_PERIOD_S = 0.02  # the guidance process re-solves the push at most at 50 Hz (each solve takes 5–15 ms)
VERDICT_PERIOD_S = 0.04  # the verdict process classifies the current push at 25 Hz
MODES = (*CLASSIFY_MODES, "free")  # the verdicts, in the protocol's order (it sends the index)
Motion = Literal["free", "slide", "roll", "hold", "plan", "none"]  # what the guidance asks
SessionStatus = Literal["reached", "jammed", "short", "diverged", "error"]


@dataclass(frozen=True)
class Guidance:
    """The planner's advice at one instant, and the verdict of the push the part receives."""

    time_s: float = 0.0
    target: str | None = None  # the next locator to press
    transition: int | None = None
    motion: Motion = "plan"  # "plan": planning
    push: FloatArray | None = None  # suggested non-jamming push on the part (about the body origin, world axes)
    verdict: str | None = None  # classify's mode of the current push (None: not yet known)
    margin: float | None = None
    verdict_push: FloatArray | None = None  # the push that was classified
    verdict_time_s: float | None = None  # session time of that classification
    note: str = ""  # planner status in words


@dataclass(frozen=True)
class LoopStats:
    """Timing of the haptic loop so far."""

    ticks: int
    tick_mean_us: float | None  # None: no tick yet
    tick_p99_us: float | None
    tick_max_us: float | None
    deadline_misses: int  # ticks that ended after their deadline (real time) or computed longer than a period
    late_p99_us: float | None  # how late ticks started, 99th percentile (real time; None: not measured)

    def to_json(self) -> dict[str, Any]:
        return {
            "ticks": self.ticks, "tick_mean_us": self.tick_mean_us, "tick_p99_us": self.tick_p99_us,
            "tick_max_us": self.tick_max_us, "deadline_misses": self.deadline_misses, "late_p99_us": self.late_p99_us,
        }  # fmt: skip


@dataclass(frozen=True)
class Snapshot:
    """What the display shows: the loop's state every ``trace_every`` ticks."""

    time_s: float
    pose: Pose
    twist: FloatArray  # of the centre of mass, world axes
    device_pose: Pose  # the proxy: the device coordinates as a pose of the part
    coupling_wrench: FloatArray  # on the part
    felt_wrench: FloatArray  # displayed on the device
    pressed: tuple[str, ...]
    normal_forces_N: FloatArray  # (n,)
    forces_world_N: FloatArray  # (n, d)
    speed_mps: float
    at_goal: bool
    jammed: bool
    auto: bool
    stats: LoopStats
    guidance: Guidance
    bridge: dict[str, Any] | None
    ended: bool


@dataclass
class Trace:
    """The session sampled every ``every`` ticks (arrays grown as lists)."""

    time_s: list[float] = field(default_factory=list)
    poses: list[Pose] = field(default_factory=list)
    device_x: list[FloatArray] = field(default_factory=list)  # device coordinates
    gaps_m: list[FloatArray] = field(default_factory=list)
    normal_forces_N: list[FloatArray] = field(default_factory=list)
    forces_world_N: list[FloatArray] = field(default_factory=list)
    coupling_wrench: list[FloatArray] = field(default_factory=list)  # mean over the samples' ticks
    felt_wrench: list[FloatArray] = field(default_factory=list)
    pressed: list[tuple[str, ...]] = field(default_factory=list)
    suggested: list[FloatArray | None] = field(default_factory=list)
    verdict: list[str | None] = field(default_factory=list)
    auto: list[bool] = field(default_factory=list)


@dataclass
class SessionResult:
    """How a session ended, with everything the recording needs."""

    status: SessionStatus  # "error": a bug, with where
    reason: str
    where: dict[str, Any]
    duration_s: float
    names: tuple[str, ...]
    every_s: float
    trace: Trace
    states: list[tuple[float, tuple[str, ...]]]  # (time, debounced contact state) as observed, in order
    stats: LoopStats
    bridge: dict[str, Any] | None
    device: str
    max_penetration_m: float
    final_gaps_m: dict[str, float]
    saturated_ticks: int
    felt_equals_coupling_max_N: float  # max |felt + coupling| over the ticks the device did not saturate
    rates: dict[str, float | None] = field(default_factory=dict)  # guidance and verdict updates per second
    clamping: dict[str, Any] | None = None  # the clamping stage played after the goal (``--clamp``), None: not played

    @property
    def reached(self) -> bool:
        return self.status == "reached"


def coupling_cap(fixture: Fixture, rig: HapticRigSettings) -> tuple[float, float, str]:
    """The coupling's force [N] and torque [N·m] caps, and where they come from, in words.

    The ``[manipulator]`` limits when the file gives them; else ``coupling_force_weights`` × the
    part's weight ``m |g|`` and ``coupling_torque_weights`` × ``m |g|`` × its bounding radius.
    """
    wp = fixture.workpiece
    weight_N = fixture.weight_N
    r_m = wp.shape.bounding_radius
    F, T = fixture.manipulator.max_force_N, fixture.manipulator.max_torque_Nm
    notes = []
    if not math.isfinite(F):
        F = rig.coupling_force_weights * weight_N
        notes.append(f"{rig.coupling_force_weights:g} m|g| = {F:.4g} N")
    if not math.isfinite(T):
        T = rig.coupling_torque_weights * weight_N * r_m
        notes.append(f"{rig.coupling_torque_weights:g} m|g| × bounding radius {r_m:.3g} m = {T:.4g} N·m")
    if notes:
        return F, T, f"coupling capped at {F:.4g} N, {T:.4g} N·m (no [manipulator] limits: {'; '.join(notes)})"
    return F, T, f"coupling capped at {F:.4g} N, {T:.4g} N·m (the [manipulator] limits)"


def capped_fixture(fixture: Fixture, F_max: float, T_max: float) -> Fixture:
    """``fixture`` with the hand's limits at the coupling's cap (what the guidance may ask)."""
    from dataclasses import replace

    from fixplan.model import Manipulator

    m = fixture.manipulator
    if m.max_force_N == F_max and m.max_torque_Nm == T_max:
        return fixture
    return replace(fixture, manipulator=Manipulator(max_force_N=F_max, max_torque_Nm=T_max))


class InsertionGuide:
    """A fixture with pins or bores: the staged insertion (:mod:`fixplan.planner.insertion`) as the guide's executor.

    Planned from the pose the part is in (a part partly on its pins is lifted straight out first; one
    in past the chamfers is seated from there),
    run by :class:`~fixplan.planner.insertion.InsertionRun` with the haptic profile: the same calls
    the guide makes of the locators' executor (``command``, ``guidance``, ``done``, ``log``).
    ``delay_s``: how late the operator's push follows the guidance (the run's servo is held to it).
    """

    def __init__(self, fixture: Fixture, pose: Pose, tick_s: float, delay_s: float = 0.0):
        from dataclasses import replace

        from fixplan.planner.insertion import InsertionRun, plan_insertion
        from fixplan.settings import HAPTIC

        here = replace(fixture, start=pose)
        self.plan = plan_insertion(here, settings=HAPTIC)
        if not self.plan.ok:
            raise InfeasibleError(self.plan.reason)
        self.run = InsertionRun(here, self.plan, HAPTIC.insertion, tick_s=tick_s, execution=HAPTIC.execution,
                                delay_s=delay_s)  # fmt: skip
        self.log = self.run.log
        self.steps: list[Any] = []  # no locator steps: the guide's policy note does not apply

    @property
    def done(self) -> bool:
        return self.run.done

    def command(self, t: float, pose: Pose, twist: FloatArray, pressed: frozenset[str]) -> FloatArray:
        self.run.step_time(t, pose)
        return self.run.command(t, pose, twist, tuple(sorted(pressed)))

    def guidance(self) -> dict[str, Any]:
        """The stage under way: what it adds and how the part moves (free approach, sliding on the pins, held)."""
        stages = self.plan.stages
        if self.run.index >= len(stages):
            return {"transition": None, "target": None, "motion": "hold"}
        st = stages[self.run.index]
        motion = "free" if st.kind == "free" else "hold" if st.kind == "seat" else "slide"
        return {"transition": self.run.index + 1, "target": st.target or None, "motion": motion}


class Guide:
    """The planner's executor as guidance, and the jamming verdict of the current push."""

    def __init__(
        self,
        fixture: Fixture,
        start_state: frozenset[str],
        *,
        tick_s: float,
        verdict_every_s: float = 0.0,
        role: str = "both",
        reaction_s: float = 0.0,
    ):
        self.role = role  # "both" | "plan" (the executor only) | "verdict" (classify only)
        self.fixture = fixture
        self.tick_s = tick_s
        # the operator follows the advice this late (their reaction, and this guide's own update period)
        self.reaction_s = reaction_s
        self.delay_s = reaction_s + tick_s if reaction_s > 0.0 else 0.0
        self.verdict_every_s = verdict_every_s
        self.start_state = start_state
        self._planner: Any = None
        self._executor: Any = None
        self._policy: Any = None  # planner/policy.py's Policy once the first plan is made
        self._next_verdict = 0.0
        self._next_replan = 0.0
        self.note = "planning"
        self.verdict: str | None = None
        self.margin: float | None = None
        self.verdict_push: FloatArray | None = None
        self.verdict_time_s: float | None = None
        self.solves = 0
        self.plans = 0

    def _plan(self, pose: Pose, state: frozenset[str], t: float) -> None:
        from fixplan.planner.execute import Executor
        from fixplan.planner.solve import Planner, plan_steps

        if self.fixture.has_pins:  # the staged insertion onto the pins (or into the bore)
            self.plans += 1
            self._executor = InsertionGuide(self.fixture, pose, self.tick_s, self.delay_s)
            self.note = "following the insertion"
            return
        if self._planner is None:
            self._planner = Planner(self.fixture)
        self.plans += 1
        if not self.plans - 1 and pose.distance_to(self.fixture.start)[0] < DEFAULT.planner.same_pose_m:
            coarse = self._planner.plan_from(pose, state)
            steps: Any = plan_steps(coarse.transitions) if coarse.found else coarse.reason
            if coarse.found and self.fixture.goal_pose is not None:
                # the next transition from every contact state: the guidance follows the person's
                # part into states the plan did not expect without waiting for the planner
                from fixplan.planner.policy import build_policy

                self._policy = build_policy(self.fixture, self._planner, state, coarse.transitions)
        else:
            steps = self._planner.replan(pose, state)
        if isinstance(steps, str):
            self._executor = None
            self.note = f"no plan from {format_state(state, empty='{}')}: {steps}"
            self._next_replan = t + 1.0
            return
        self._executor = Executor(
            self.fixture, state, steps, replan=self._planner.replan, tick_s=self.tick_s, policy=self._policy
        )
        self.note = "following the plan" if steps else "every locator touches: hold"

    def update(self, snap: Snapshot, push_now: FloatArray) -> Guidance:
        """One guidance step at the snapshot's state; ``push_now`` is what the part receives."""
        t = snap.time_s
        state = frozenset(snap.pressed)
        if self.role == "verdict":
            self._classify(snap, push_now)
            return Guidance(t, verdict=self.verdict, margin=self.margin, verdict_push=self.verdict_push,
                            verdict_time_s=self.verdict_time_s)  # fmt: skip
        ex = self._executor
        if ex is not None and ex.done and ex.log.outcome == "failed" and t >= self._next_replan:
            self.note = f"re-planning: {ex.log.reason}"
            ex = self._executor = None
        if ex is None and t >= self._next_replan:
            try:
                self._plan(snap.pose, state, t)
            except Exception as exc:  # noqa: BLE001 - guidance must not stop the session
                self._executor = None
                self.note = f"planner failed: {type(exc).__name__}: {exc}"
                self._next_replan = t + 1.0
            ex = self._executor
        push = None
        target = transition = None
        motion: Motion = "none"
        if ex is not None:
            push = np.array(ex.command(t, snap.pose, snap.twist, state), dtype=float)
            self.solves += 1
            g = ex.guidance()
            target, transition, motion = g["target"], g["transition"], g["motion"]
            switched = ex.log.counts.get("policy_switches", 0)
            if switched and ex.steps and ex.index < len(ex.steps):
                here = ex.states[ex.index]
                self.note = (
                    f"following the policy from {format_state(here, empty='{}')}"
                    f" ({switched} switch{'es' if switched != 1 else ''} off the plan)"
                )
            if ex.done and ex.log.outcome == "reached":
                motion = "hold"
        if self.role == "both" and t >= self._next_verdict:
            self._next_verdict = t + self.verdict_every_s
            self._classify(snap, push_now)
        return Guidance(
            t, target, transition, motion, push, self.verdict, self.margin, self.verdict_push, self.verdict_time_s,
            self.note,
        )  # fmt: skip

    def _classify(self, snap: Snapshot, push_now: FloatArray) -> None:
        from fixplan.jamming import classify

        known = set(self.fixture.names)
        names = sorted(n for n in snap.pressed if n in known)  # a bore's "<bore>.bottom" is its own contact's
        self.verdict_push = push_now.copy()
        self.verdict_time_s = snap.time_s
        if not names:
            self.verdict, self.margin = "free", None
            return
        try:
            c = classify(self.fixture, push_now, names, pose=snap.pose, jobs=1)[0]
        except Exception:  # noqa: BLE001 - a verdict is advice; an unclassifiable push is shown as unknown
            self.verdict, self.margin = "indeterminate", None
            return
        self.verdict = c.mode
        self.margin = (
            float(c.balance_residual) if c.balance_residual is not None and math.isfinite(c.balance_residual) else None
        )


def _guide_worker(
    conn: Any, fixture: Fixture, start_state: frozenset[str], tick_s: float, role: str, reaction_s: float = 0.0
) -> None:
    """A guidance process: answers each snapshot with a :class:`Guidance` (see :class:`RemoteGuide`)."""
    import os

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    if role == "verdict":
        # a classification is 1–2 ms, 25 times a second: above the other processes (a browser
        # rendering in software took it down to 5 Hz), below the loop and the display
        real_time_priority(5)
    else:
        # the planner is not a deadline: it asks for a larger share of a busy core than the
        # other users' processes (guide_nice), not for real-time priority (a re-plan computes for seconds)
        try:
            os.nice(HAPTIC.haptic.guide_nice)
        except OSError:
            pass
    guide = Guide(fixture, start_state, tick_s=tick_s, role=role, reaction_s=reaction_s)
    if role == "plan":  # import what the planner needs before the clock starts
        import fixplan.planner.execute
        import fixplan.planner.policy
        import fixplan.planner.solve  # noqa: F401
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return
        if msg is None:
            return
        snap, push_now = msg
        try:
            conn.send(guide.update(snap, push_now))
        except (BrokenPipeError, OSError):
            return


class RemoteGuide:
    """:class:`Guide` in its own process, so that the loop thread never waits for the planner.

    The planner's solvers (CasADi, Clarabel) hold the GIL for milliseconds; in a thread they stalled
    the 1 kHz loop for the length of every solve. :meth:`update` sends the snapshot and waits for the
    answer (the waiting thread releases the GIL).
    """

    def __init__(
        self,
        fixture: Fixture,
        start_state: frozenset[str],
        *,
        tick_s: float,
        role: str = "plan",
        reaction_s: float = 0.0,
    ):
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        self.tick_s = tick_s
        self.role = role
        self.reaction_s = reaction_s
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(
            target=_guide_worker, args=(child, fixture, start_state, tick_s, role, reaction_s), name=f"fixplan-{role}",
            daemon=True,
        )  # fmt: skip
        self._proc.start()
        child.close()
        self.note = "planning"

    def update(self, snap: Snapshot, push_now: FloatArray) -> Guidance:
        self.post(snap, push_now)
        return self.answer()

    def post(self, snap: Snapshot, push_now: FloatArray) -> None:
        """Send a snapshot (its answer is read by :meth:`answer`)."""
        self._conn.send((snap, push_now))

    def answer(self, within_s: float | None = None) -> Guidance:
        """The answer to the last snapshot posted; :class:`InputError` when the process ended or did not answer in time."""
        deadline = None if within_s is None else time.perf_counter() + within_s
        while not self._conn.poll(0.5):
            if not self._proc.is_alive():
                raise InputError("the guidance process ended")
            if deadline is not None and time.perf_counter() > deadline:
                raise InputError(f"the guidance process did not answer within {within_s:g} s")
        out: Guidance = self._conn.recv()
        return out

    def close(self) -> None:
        try:
            self._conn.send(None)
        except (BrokenPipeError, OSError):
            pass
        self._proc.join(timeout=5.0)
        if self._proc.is_alive():
            self._proc.terminate()
            self._proc.join(timeout=2.0)
        self._conn.close()


def real_time_priority(priority: int = 40) -> str:
    """Ask for ``SCHED_FIFO`` for the calling thread (as haptic loops run); what was granted, in words.

    The loop sleeps most of each period, so it takes a small share of a core; the priority keeps
    other processes from delaying its ticks. Without permission (not root, no ``CAP_SYS_NICE``,
    no ``rtprio`` limit) the thread keeps the normal policy.
    """
    import os

    try:
        p = min(priority, os.sched_get_priority_max(os.SCHED_FIFO))
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(p))
    except (AttributeError, OSError, PermissionError) as exc:
        return f"normal (real-time priority refused: {getattr(exc, 'strerror', None) or exc})"
    return f"SCHED_FIFO {p}"


class HapticSession:
    """The interactive loop around one fixture (see the module's docstring)."""

    def __init__(
        self,
        fixture: Fixture,
        handle: Handle | None,
        *,
        until_goal: bool = True,
        duration_s: float | None = None,
        realtime: bool = True,
        synchronous: bool = False,
        guidance: bool = True,
        auto: bool = False,
        trace_every: int = 10,
        clock: str = "wall",
        settle_s: float = 0.2,
        max_sweeps: int | None = None,
        profile: Settings = HAPTIC,
        clamp: bool = False,
        reaction_s: float | None = None,
    ):
        from fixplan.locating import contact_set, inserts, start_state
        from fixplan.model import require_full
        from fixplan.planner.execute import DivergenceGuard, ExecutionSettings

        if not (fixture.bores and not fixture.pins):  # a shaft in a bore: located by the bore alone
            require_full(fixture, "a haptic session")
        if clock not in ("wall", "device"):
            raise InputError(f"HapticSession.clock must be 'wall' or 'device', got {clock!r}")
        if clock == "device" and not isinstance(handle, UdpHandle):
            raise InputError(
                "HapticSession.clock device needs run_session.device udp[:PORT] (the device's poses drive the loop)"
            )
        self.clock = clock
        if clock == "device":
            # one tick per pose, no wall clock: the guidance runs inside the loop (reproducible)
            realtime, synchronous = False, True
            if isinstance(handle, UdpHandle):  # checked above: --clock device is UDP only
                handle.one_per_read = True
        if duration_s is not None and not (duration_s > 0 and math.isfinite(duration_s)):
            raise InputError(f"session duration must be a positive number of seconds, got {duration_s}")
        self.fixture = fixture
        self.handle = handle
        self.rig_settings = profile.haptic
        # how late the operator follows the guidance (its servo is held to it): a device's person or
        # robot (``operator_reaction_s``); the simulated hand of a session without a device reacts at once
        if reaction_s is None:
            reaction_s = profile.haptic.operator_reaction_s if handle is not None else 0.0
        if not (reaction_s >= 0.0 and math.isfinite(reaction_s)):
            raise InputError(f"HapticSession.reaction_s must be a finite number of seconds ≥ 0, got {reaction_s}")
        self.reaction_s = float(reaction_s)
        self.sim = Simulator(fixture, max_iterations=max_sweeps, settings=profile.engine)
        self.names = tuple(self.sim.names)  # the locators, then the pins and bores
        self.period_s = self.sim.dt
        self.dimension = fixture.dimension
        self.ndof = fixture.ndof
        self.R0 = fixture.start.R_world_body.copy()
        self.x0 = coordinates_from_pose(fixture.start, self.R0)
        self.F_max, self.T_max, self.cap_note = coupling_cap(fixture, profile.haptic)
        # the guidance plans within the same cap (a push the coupling cannot deliver is no advice)
        self.guide_fixture = capped_fixture(fixture, self.F_max, self.T_max)
        self.rig = haptic_rig(fixture, self.sim, self.x0, self.F_max, self.T_max, profile.haptic)
        # the loop: coupling, saturation at the hand's limits, engine step, display (one tick's work)
        self.loop = self.rig.loop
        self._read = ReadDevice(self.ndof, self.loop.device.specs)  # a person's device, as the loop sees it
        self._zeros_ndof = np.zeros(self.ndof)  # the push on a person's handle: theirs, not ours
        c = self.rig.loop.coupling
        d = self.dimension
        self.K = self.rig.K.copy()
        self.B = np.concatenate([np.full(d, c.B_lin), np.full(self.ndof - d, c.B_rot)])
        self.device_damping = self.rig.damping.copy()
        specs = self.rig.loop.device.specs
        self.device_limits = (specs.max_force_N, specs.max_torque_Nm)
        self._stiffness_scale = 1.0
        self.stiffness_scale_max = self._passive_scale_max()
        settings = ExecutionSettings()
        wp = fixture.workpiece
        g = fixture.gravity_m_s2
        self.weight_N = fixture.weight_N
        # the executor's guard of the fixture's neighbourhood; a person's push may be the whole cap
        self.guard = DivergenceGuard.for_fixture(fixture, settings, accel_mps2=self.F_max / wp.mass_kg + g)
        self.threshold_N = max(settings.press_fraction * self.weight_N, 1e-6)
        self.contact_gap_m, self.contact_hold_gap_m = settings.contact_gap_m, settings.contact_hold_gap_m
        self.dwell_s = settings.dwell_s
        self.rest_speed_mps = settings.stall_speed_mps * 10
        self.settle_s = settle_s
        self._r_gyr = math.sqrt(float(np.max(np.linalg.eigvalsh(np.atleast_2d(wp.inertia_body)))) / wp.mass_kg)
        self.until_goal = until_goal
        self.duration_s = duration_s
        self.realtime = realtime
        self.synchronous = synchronous
        self.trace_every = max(int(trace_every), 1)
        self.start_state = start_state(fixture, ("locator", "pin", "bore"))
        # the goal: every locator pressed; a pin or bore pressed when it touches at the located pose
        # (its clearance leaves the others free: a diamond pin centred in its hole touches nothing)
        self.goal_names = frozenset(self.names)
        if fixture.has_pins and fixture.is_full:
            seated = {x.owner for x in contact_set(fixture, "goal").contacts}
            tips = self.names[: self.sim.n_tips]
            self.goal_names = frozenset(tips) | frozenset(n for n in self.names[self.sim.n_tips :] if n in seated)
        # a bore: its bottom closed (``"<bore>.bottom"``, as the insertion's states name it) and the shaft's
        # axis within the bore's radial play (:meth:`_bores_seated`), as the insertion's verification asks
        self._bore_inserts = [i for i in inserts(fixture) if i.kind == "bore"]
        self._axis_play_rel = profile.insertion.axis_play_rel
        self.goal_names |= frozenset(f"{b.name}.bottom" for b in fixture.bores)
        self._guidance_on = guidance
        self.guide: Guide | RemoteGuide | None = None
        if guidance and synchronous:
            self.guide = Guide(self.guide_fixture, self.start_state, tick_s=self.trace_every * self.period_s,
                               reaction_s=self.reaction_s)  # fmt: skip
        self._auto = bool(auto) or handle is None
        self._auto_dev = self._auto_device(self.x0, np.zeros(self.ndof))
        self._x_d = self.x0.copy()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._ended = threading.Event()
        self._thread: threading.Thread | None = None
        self._guide_thread: threading.Thread | None = None
        self.verdict_guide: RemoteGuide | None = None  # classify in its own process (real time only)
        self._verdict_thread: threading.Thread | None = None
        self._guidance_lock = threading.Lock()
        self._reset_requested = False
        self.scheduling = "normal"
        self._restart_guide = False
        self._coords: tuple[FloatArray, FloatArray] | None = None
        if isinstance(handle, UdpHandle) and not handle.config:
            handle.config = self.bridge_config()
        self.profile = profile
        self._loop_tolerance = self.sim.tolerance
        self.clamp_stage: ClampStage | None = None
        self.clamp_plan: Any = None
        if clamp:
            self._plan_clamping()
        self._init_state()

    def _plan_clamping(self) -> None:
        """The clamping stage to play once the part is located (``--clamp``): forces and order from the cone programs."""
        from fixplan.clamping import analyse_clamping
        from fixplan.clamping.forces import clamp_scene

        fixture = self.fixture
        if not fixture.clamps:
            raise InputError(
                f"HapticSession.clamp: {fixture.source} has no [[clamp]] entries (expected clamps to play)"
            )
        plan = analyse_clamping(fixture, verify=False, settings=self.profile)
        if not plan.holds:
            raise InfeasibleError(f"HapticSession.clamp: {one_line(plan.reason)}")
        scene = clamp_scene(fixture)
        points = {c.name: c.point_world for c in scene.clamps}
        self.clamp_plan = plan
        self.clamp_watched = scene.owners
        self.clamp_stage = ClampStage(fixture, plan.order, plan.forces_N, points, self.period_s, self.profile)

    # -- state ---------------------------------------------------------------------------------
    def _init_state(self) -> None:
        n = len(self.names)
        self.trace = Trace()
        self.states: list[tuple[float, tuple[str, ...]]] = []
        self.resets = 0
        self._debounced = Debounce(self.dwell_s)  # the observed contact state (None: none accepted yet)
        self._settled_since: float | None = None
        self.goal_reached_at: float | None = None
        self._jammed_since: float | None = None
        self.jammed_where: dict[str, Any] | None = None
        self._stage_k: int | None = None  # the clamping stage's next step (None: not started)
        self.stage_record: StageRecord | None = None
        self.located_at: float | None = None  # when the clamping stage began (the part located)
        self.clamp_phase = ""
        self._compute: list[float] = []
        self._compute_sum = 0.0
        self._compute_max = 0.0
        self._stats_cache: LoopStats | None = None
        self._late: list[float] = []
        self._misses = 0
        self._acc_w = np.zeros(self.ndof)
        self._acc_f = np.zeros(self.ndof)
        self._acc_n = 0
        self._push_recent = np.zeros(self.ndof)
        self.felt_error_max = 0.0
        self.guidance = Guidance()
        self.guide_updates = 0  # guidance answers received
        self._first_guide_s: float | None = None  # session time of the first (after the planner's start-up)
        self._first_verdict_s: float | None = None
        self.verdict_updates = 0  # new classify verdicts among them
        self.status: SessionStatus | None = None
        self.reason = ""
        self._zeros_n = np.zeros(n)
        self.snapshot: Snapshot | None = None
        self._publish(np.zeros(self.ndof), np.zeros(self.ndof), tuple(sorted(self.start_state)), force=True)

    def _auto_device(self, x: FloatArray, v: FloatArray) -> SimulatedDevice:
        """A simulated device for the auto switch, like the loop's, at handle state ``(x, v)``."""
        old = self.rig.loop.device
        dev = SimulatedDevice(
            self.ndof,
            mass_kg=float(old._M[0]),
            inertia_kgm2=float(old._M[-1]),
            specs=old.specs,
            x0=x,
        )
        dev._v = np.array(v, dtype=float)
        dev.open()
        return dev

    def _passive_scale_max(self) -> float:
        """The largest stiffness scale for which the coupling stays passive with the handle's damping."""
        T = self.period_s
        scales = [(b - abs(B)) / (K * T / 2.0) for K, B, b in zip(self.K, self.B, self.device_damping, strict=True)]
        return float(min(scales)) * 0.99

    @property
    def stiffness_scale(self) -> float:
        return self._stiffness_scale

    def set_stiffness_scale(self, scale: float) -> float:
        """Scale the coupling stiffness; refused beyond the passivity bound ``b > K T/2 + |B|``."""
        if not (scale > 0 and math.isfinite(scale)):
            raise InputError(f"stiffness scale must be positive, got {scale}")
        for K, B, b in zip(self.K, self.B, self.device_damping, strict=True):
            check_passivity(K * scale, B, self.period_s, b)
        self._stiffness_scale = float(scale)
        return self._stiffness_scale

    @property
    def auto(self) -> bool:
        return self._auto

    def set_auto(self, on: bool) -> None:
        """Let the planner's executor drive (the simulated device starts where the handle is)."""
        if on and not self._auto:
            x_w, v_w = self.rig.loop.workpiece_coordinates()
            self._auto_dev = self._auto_device(self._x_d.copy(), v_w)
        if not on and self.handle is None:
            return  # no device: auto is the only driver
        self._auto = bool(on)

    def request_reset(self) -> None:
        """Put the part back at its start pose, at rest (done by the loop thread at its next tick)."""
        self._reset_requested = True

    def _reset(self) -> None:
        self.sim.set_state(self.fixture.start, None)
        self._coords = None
        self._auto_dev = self._auto_device(self.x0, np.zeros(self.ndof))
        self._debounced.reset()
        self._settled_since = self._jammed_since = None
        self.goal_reached_at = None
        self._stage_k, self.stage_record, self.located_at, self.clamp_phase = None, None, None, ""
        self.sim.tolerance = self._loop_tolerance
        if isinstance(self.guide, Guide):
            self.guide = Guide(
                self.guide_fixture, self.start_state, tick_s=self.guide.tick_s, reaction_s=self.reaction_s
            )
        elif isinstance(self.guide, RemoteGuide):
            self._restart_guide = True
        # the recording starts afresh from the start pose (what came before is not a way to load the part)
        self.trace = Trace()
        self.states = []
        self.jammed_where = None
        self.resets += 1

    # -- the loop ------------------------------------------------------------------------------
    def _answer(self, felt: FloatArray, x_w: FloatArray, v_w: FloatArray) -> Any:
        g = self.guidance
        flags = (protocol.FLAG_GOAL if self.goal_reached_at is not None else 0) | (
            protocol.FLAG_JAMMED if self._jammed_flag() else 0
        )
        flags |= protocol.FLAG_AUTO if self._auto else 0
        flags |= protocol.FLAG_ENDED if self.status is not None else 0
        target = self.names.index(g.target) if g.target in self.names else -1
        verdict = MODES.index(g.verdict) if g.verdict in MODES else protocol.VERDICT_UNKNOWN
        push = g.push if g.push is not None else np.zeros(self.ndof)
        echo = self.handle.last_pose.seq if isinstance(self.handle, UdpHandle) and self.handle.last_pose else 0
        t_session = self.sim.time_s

        def build(seq: int, t_echo: float) -> protocol.ForcePacket:
            return protocol.ForcePacket(
                seq, echo, t_echo, t_session, flags, felt, x_w, v_w, target, g.transition or 0, verdict,
                float("nan") if g.margin is None else g.margin, push, self.ndof,
            )  # fmt: skip

        return build

    @property
    def _observed(self) -> frozenset[str] | None:
        """The debounced contact state (None: none accepted yet)."""
        return self._debounced.observed

    def _jammed_flag(self) -> bool:
        return self._jammed_since is not None and self.sim.time_s - self._jammed_since >= 0.3

    @property
    def saturated_ticks(self) -> int:
        """Ticks whose coupling wrench was capped at the hand's limits (the loop's count)."""
        return self.loop.saturated_ticks

    def _coordinates(self) -> tuple[FloatArray, FloatArray]:
        """:meth:`coordinates`, computed once per state of the part."""
        if self._coords is None:
            self._coords = self.coordinates()
        return self._coords

    def tick(self, wall_s: float) -> bool:
        """One period of the loop (steps 1–5 of the module's docstring); False when the device clock did not tick."""
        if self._reset_requested:
            self._reset_requested = False
            self._reset()
        sim = self.sim
        reading = None if self.handle is None else self.handle.read(wall_s)
        if self.clock == "device" and not getattr(self.handle, "fresh", False):
            return False  # no new pose (a HELLO, a dropped datagram): the device's clock has not ticked
        hand, scale = True, 1.0
        auto_dev = self._auto_dev  # (set_auto may replace it meanwhile: this tick keeps the one it reads)
        device: HapticDevice
        if self._auto:
            device = auto_dev
            self._x_d = device.position()
        elif reading is None:
            device = self._read  # no device input: the coupling goes limp (the handle is where the part is)
            self._x_d = self._coordinates()[0]
            hand = False
        else:
            device = self._read
            device.read(*reading)
            self._x_d = reading[0]
            scale = self._stiffness_scale
        stage = self._stage_tick()
        external = None
        if stage is not None:
            # the clamping stage: the clamps (and a load) on the part; the hand let go after the ramps
            if not stage.hand:
                hand = False
                if self._stage_k == getattr(self.clamp_stage, "n_hand", -1) and self.stage_record is not None:
                    self.stage_record.located = sim.pose  # the hand lets go: the part must stay where it is now
            external = self.clamp_stage.wrench(stage, sim.pose)  # type: ignore[union-attr]

        def auto_hand() -> FloatArray:  # the simulated hand reacts to this tick: the part moved, the handle felt
            push = self.guidance.push if self.guidance.push is not None else np.zeros(self.ndof)
            return self.rig.operator_wrench(push, auto_dev)

        w_c, felt, _ = self.loop.tick(
            auto_hand if self._auto else self._zeros_ndof,
            external=external,
            hand=hand,
            device=device,
            stiffness_scale=scale,
        )
        self._coords = None
        if stage is not None:
            self._stage_step(stage)
        if not saturate(-w_c, self.dimension, *self.device_limits)[1]:
            self.felt_error_max = max(self.felt_error_max, float(np.max(np.abs(felt + w_c))))
        why = self.guard.check(sim.pose, self._speed())
        if why is not None:  # fell off the locators, or blew up: end now, the recording keeps what led there
            self._end(f"the part left the fixture at t = {sim.time_s:.3f} s (divergence guard): {why}")
        self._push_recent += 0.1 * (w_c - self._push_recent)
        self._acc_w += w_c
        self._acc_f += felt
        self._acc_n += 1
        self._observe(sim.time_s)
        if sim.steps % self.trace_every == 0:
            self._sample(w_c, felt)
            if self.synchronous and self.guide is not None and self.snapshot is not None:
                self._run_guide(self.snapshot)
        if self.duration_s is not None and sim.time_s >= self.duration_s - DEFAULT.numerics.same_time_s:
            self._end(None)
        elif self.clamp_stage is not None and self._stage_k is None and self.goal_reached_at is not None:
            self._start_stage()
        elif self.until_goal and self._goal_done():
            self._end(None)
        if self.handle is not None:  # the answer carries the goal and end flags of this tick
            x_new, v_new = self._coordinates()
            self.handle.display(felt, self._answer(felt, x_new, v_new))
        return True

    # -- the clamping stage (``--clamp``) ---------------------------------------------------------
    def _goal_done(self) -> bool:
        """The goal is reached, and the clamping stage (when asked for) has been played."""
        if self.clamp_stage is None:
            return self.goal_reached_at is not None
        return self._stage_k is not None and self._stage_k >= self.clamp_stage.n_ticks

    def _start_stage(self) -> None:
        """The part is located: the clamping stage starts at this pose (the hand still holds it)."""
        stage = self.clamp_stage
        if stage is None:
            return
        self._stage_k = 0
        self.located_at = self.sim.time_s
        # the stage runs the engine at the fixture's own NSGS tolerance (as `fixplan clamp` verifies it), not the
        # loop's looser one: whether the part stays within 1e-9 m is then the contacts' answer, not the solver's
        self._loop_tolerance = self.sim.tolerance
        self.sim.tolerance = min(self.sim.tolerance, self.fixture.simulation.tolerance)
        # displacements from where the hand lets go (reset then): the hand's coupling may ease the part meanwhile
        self.stage_record = StageRecord.for_stage(stage, self.clamp_watched, self.profile, reference=self.sim.pose)

    def _stage_tick(self) -> StageTick | None:
        """What the clamping stage applies this tick: its schedule, then the clamps held on (None: no stage)."""
        stage, k = self.clamp_stage, self._stage_k
        if stage is None or k is None:
            return None
        if k < stage.n_ticks:
            return stage.at(k)
        return StageTick(False, dict.fromkeys(stage.order, 1.0), np.zeros(self.ndof), "clamped", None)

    def _stage_step(self, tick: StageTick) -> None:
        stage, record, k = self.clamp_stage, self.stage_record, self._stage_k
        if stage is None or record is None or k is None:
            return
        self.clamp_phase = tick.phase
        if k < stage.n_ticks:
            last = self.sim.last
            sample = k % self.trace_every == 0 or k == stage.n_ticks - 1  # the contact reports: sampled
            record.observe(self.sim, tick, 0.0 if last is None else last.error, contacts=sample)
            self._stage_k = k + 1

    def clamping_result(self) -> dict[str, Any] | None:
        """The clamping stage as played: the order and forces, and what the engine did (None: not asked for)."""
        plan, record, stage = self.clamp_plan, self.stage_record, self.clamp_stage
        if plan is None or stage is None:
            return None
        out: dict[str, Any] = {"order": list(plan.order), "forces_N": dict(plan.forces_N), "played": False}
        if record is None or self._stage_k is None:
            out["reason"] = "not played: the part was not located"
            return out
        played = self._stage_k >= stage.n_ticks
        passed, why = record.verdict(self.profile)
        program = plan.clamped_forces_N or {}
        out |= {
            "played": played,
            "passed": played and passed,
            "located_at_s": self.located_at,
            **record.to_json(),
            "locator_forces_N": {
                name: {"engine_N": record.final_forces_N.get(name), "program_N": program.get(name)}
                for name in self.clamp_watched
            },
            "reason": why if played else f"stopped during the stage ({self.clamp_phase})",
        }
        return out

    def coordinates(self) -> tuple[FloatArray, FloatArray]:
        """The part's device coordinates and rates (``HapticLoop.workpiece_coordinates``, compiled in 3D)."""
        return self.loop.workpiece_coordinates(compiled=True)

    def _speed(self) -> float:
        tw = self.sim.twist
        d = self.dimension
        v = float(np.linalg.norm(tw[:d]))
        w = float(np.linalg.norm(tw[d:]))
        return math.hypot(v, w * self._r_gyr)

    def _bottoms(self, pressed: frozenset[str]) -> frozenset[str]:
        """``"<bore>.bottom"`` for each pressed bore whose bottom the shaft's end touches (the insertion's observation)."""
        from fixplan.locating import bottom_gap_m

        tol = self.fixture.tolerances.touch_m + self.contact_gap_m
        pose = self.sim.pose
        return frozenset(
            f"{b.name}.bottom"
            for b in self.fixture.bores
            if b.name in pressed and bottom_gap_m(self.fixture, pose, b) <= tol
        )

    def _bores_seated(self) -> bool:
        """Every bore's shaft with its axis within the bore's radial play (at the mouth and the end), as the verification checks."""
        from fixplan.locating import axis_offsets_m

        pose = self.sim.pose
        return all(
            max(axis_offsets_m(self.fixture, pose, i)) <= i.play_m * (1.0 + self._axis_play_rel)
            for i in self._bore_inserts
        )

    def goal_words(self) -> str:
        """What reaching the goal means for this fixture, for the end's reason."""
        words = "every locator pressed" if self.fixture.locators or self.fixture.pins else ""
        if self.fixture.bores:
            seated = ", ".join(b.name for b in self.fixture.bores)
            words += (" and " if words else "") + f"seated in {seated} (its bottom closed, the axis within the play)"
        return words

    def _observe(self, t: float) -> None:
        held = self._debounced.observed or frozenset()  # the accepted state's contacts stay within the hold gap
        pressed = frozenset(self.sim.in_contact(self.threshold_N, self.contact_gap_m, held, self.contact_hold_gap_m))
        if self._bore_inserts:
            pressed |= self._bottoms(pressed)
        if self._debounced.observe(t, pressed):
            self.states.append((t, tuple(sorted(pressed))))
        at_rest = self._speed() < self.rest_speed_mps
        at_goal = self._observed == self.goal_names and (not self._bore_inserts or self._bores_seated())
        if at_goal and at_rest:
            if self._settled_since is None:
                self._settled_since = t
            elif t - self._settled_since >= self.settle_s and self.goal_reached_at is None:
                self.goal_reached_at = t
        else:
            self._settled_since = None
            if not at_goal:
                self.goal_reached_at = None
        g = self.guidance
        if (
            g.verdict == "jammed"
            and at_rest
            and self._observed != self.goal_names
            and self._push_norm(self._push_recent) > 1e-3 * self.weight_N
        ):
            if self._jammed_since is None:
                self._jammed_since = t
            if self._jammed_flag():
                pose = self.sim.pose
                self.jammed_where = {
                    "time_s": t,
                    "state": sorted(self._observed or ()),
                    "pose": pose.to_json(),
                    "push": [float(x) for x in (g.verdict_push if g.verdict_push is not None else self._push_recent)],
                    "margin": g.margin,
                }
        else:
            self._jammed_since = None

    def _push_norm(self, w: FloatArray) -> float:
        return float(np.linalg.norm(w[: self.dimension]))

    def _sample(self, w_c: FloatArray, felt: FloatArray) -> None:
        sim = self.sim
        reports = sim.contacts()
        tr = self.trace
        n = max(self._acc_n, 1)
        w_mean = self._acc_w / n
        f_mean = self._acc_f / n
        self._acc_w = np.zeros(self.ndof)
        self._acc_f = np.zeros(self.ndof)
        self._acc_n = 0
        pose = sim.pose
        tr.time_s.append(sim.time_s)
        tr.poses.append(pose)
        tr.device_x.append(np.array(self._x_d, dtype=float))
        tr.gaps_m.append(np.array([r.gap_m for r in reports]))
        normals = np.array([r.normal_force_N for r in reports])
        forces = np.array([r.force_world for r in reports]).reshape(len(reports), self.dimension)
        tr.normal_forces_N.append(normals)
        tr.forces_world_N.append(forces)
        tr.coupling_wrench.append(w_mean)
        tr.felt_wrench.append(f_mean)
        # before the first debounced observation: the locators touching at the start
        pressed = tuple(sorted(self._observed if self._observed is not None else self.start_state))
        tr.pressed.append(pressed)
        g = self.guidance
        tr.suggested.append(None if g.push is None else g.push.copy())
        tr.verdict.append(g.verdict)
        tr.auto.append(self._auto)
        self._publish(w_c, felt, pressed, normals=normals, forces=forces)

    def _publish(
        self,
        w_c: FloatArray,
        felt: FloatArray,
        pressed: tuple[str, ...],
        *,
        normals: FloatArray | None = None,
        forces: FloatArray | None = None,
        force: bool = False,
    ) -> None:
        pose = self.sim.pose
        snap = Snapshot(
            time_s=self.sim.time_s,
            pose=pose,
            twist=self.sim.twist,
            device_pose=pose_from_coordinates(np.asarray(self._x_d, dtype=float), self.R0, self.dimension),
            coupling_wrench=np.array(w_c, dtype=float),
            felt_wrench=np.array(felt, dtype=float),
            pressed=pressed,
            normal_forces_N=self._zeros_n if normals is None else normals,
            forces_world_N=np.zeros((len(self.names), self.dimension)) if forces is None else forces,
            speed_mps=self._speed(),
            at_goal=self.goal_reached_at is not None,
            jammed=self._jammed_flag(),
            auto=self._auto,
            stats=self.stats(),
            guidance=self.guidance,
            bridge=self.handle.stats.to_json() if isinstance(self.handle, UdpHandle) else None,
            ended=self.status is not None,
        )
        self.snapshot = snap

    def _run_guide(self, snap: Snapshot, verdict: bool = False, answer_within_s: float | None = None) -> None:
        """One guidance answer merged into :attr:`guidance`: the plan's fields, or (``verdict``) the verdict's.

        ``answer_within_s``: the snapshot was already posted (:meth:`RemoteGuide.post`); wait this
        long for its answer, else go on without that guidance.
        """
        from dataclasses import replace

        guide = self.verdict_guide if verdict else self.guide
        if guide is None:
            return
        try:
            if answer_within_s is not None and isinstance(guide, RemoteGuide):
                new = guide.answer(answer_within_s)
            else:
                new = guide.update(snap, self._push_recent.copy())
        except InputError as exc:  # a guidance process is gone (or never answered): the session goes on without it
            if isinstance(guide, RemoteGuide):
                guide.close()
            with self._guidance_lock:
                if verdict:
                    self.verdict_guide = None
                    self.guidance = replace(self.guidance, verdict=None, margin=None, note=f"no verdict: {exc}")
                else:
                    self.guide = None
                    self.guidance = replace(self.guidance, push=None, target=None, motion="none",
                                            note=f"no guidance: {exc}")  # fmt: skip
            return
        with self._guidance_lock:
            old = self.guidance
            if new.verdict_time_s is not None and new.verdict_time_s != old.verdict_time_s:
                self.verdict_updates += 1
                if self._first_verdict_s is None:
                    self._first_verdict_s = self.sim.time_s
            if verdict:
                merged = replace(old, verdict=new.verdict, margin=new.margin, verdict_push=new.verdict_push,
                                 verdict_time_s=new.verdict_time_s)  # fmt: skip
            else:
                self.guide_updates += 1
                if self._first_guide_s is None:
                    self._first_guide_s = self.sim.time_s
                merged = new if self.verdict_guide is None else replace(
                    new, verdict=old.verdict, margin=old.margin, verdict_push=old.verdict_push,
                    verdict_time_s=old.verdict_time_s,
                )  # fmt: skip
            self.guidance = merged

    def stats(self) -> LoopStats:
        """Tick timing so far: mean and misses over every tick, p99 over the last 2000 (cached for 0.25 s)."""
        n = len(self._compute)
        if not n:
            return LoopStats(0, None, None, None, 0, None)
        cached = self._stats_cache
        if cached is not None and n - cached.ticks < 250 and self.status is None:
            return cached
        recent = np.asarray(self._compute[-2000:]) * 1e6
        late = np.asarray(self._late[-2000:]) * 1e6 if self._late else None  # stepped without a wall clock
        out = LoopStats(
            ticks=n,
            tick_mean_us=float(self._compute_sum / n * 1e6),
            tick_p99_us=float(np.percentile(recent, 99)),
            tick_max_us=float(self._compute_max * 1e6),
            deadline_misses=self._misses,
            late_p99_us=float(np.percentile(late, 99)) if late is not None else None,
        )
        self._stats_cache = out
        return out

    def guidance_rates(self) -> dict[str, float | None]:
        """Guidance answers and new verdicts per second of session time, from the first answer on."""
        if self._first_guide_s is None:
            return {"guidance_hz": 0.0, "verdict_hz": 0.0, "guidance_start_s": None}
        t = max(self.sim.time_s - self._first_guide_s, 1e-9)
        t_v = max(self.sim.time_s - (self._first_verdict_s or self._first_guide_s), 1e-9)
        return {
            "guidance_hz": (self.guide_updates - 1) / t,
            "verdict_hz": max(self.verdict_updates - 1, 0) / t_v,
            "guidance_start_s": self._first_guide_s,  # the planner's start-up (a process, imports, the first plan)
        }

    def final_stats(self) -> LoopStats:
        """Like :meth:`stats`, p99 over every tick."""
        n = len(self._compute)
        if not n:
            return LoopStats(0, None, None, None, 0, None)
        a = np.asarray(self._compute) * 1e6
        late = np.asarray(self._late) * 1e6 if self._late else None  # stepped without a wall clock: not measured
        return LoopStats(n, float(a.mean()), float(np.percentile(a, 99)), float(a.max()), self._misses,
                         float(np.percentile(late, 99)) if late is not None else None)  # fmt: skip

    def _end(self, why: str | None, status: SessionStatus = "diverged") -> None:
        if self.status is not None:
            return
        t = self.sim.time_s
        if why is not None:
            self.status, self.reason = status, why
        elif self.located_at is not None:  # located, then clamped (the stage may unload a locator: still located)
            self.status = "reached"
            self.reason = f"{self.goal_words()}, at rest at t = {self.located_at:.3f} s; then the clamping stage"
        elif self.goal_reached_at is not None:
            self.status = "reached"
            self.reason = f"{self.goal_words()}, at rest at t = {self.goal_reached_at:.3f} s"
        elif self.jammed_where is not None and self._jammed_flag():
            j = self.jammed_where
            self.status = "jammed"
            self.reason = (
                f"jammed at t = {j['time_s']:.3f} s in {{{', '.join(j['state'])}}}: the push "
                f"({', '.join(f'{x:.3g}' for x in j['push'])}) is held by friction (margin {j['margin']})"
            )
        else:
            missing = sorted(self.goal_names - set(self._observed or ()))
            self.status = "short"
            self.reason = (
                f"ended at t = {t:.3f} s short of the goal in {format_state(self._observed or (), empty='{}')}"
                + (f": {', '.join(missing)} not in contact" if missing else ": not yet at rest")
            )
        self._ended.set()

    def _loop(self) -> None:
        T = self.period_s
        if self.realtime:
            self.scheduling = real_time_priority()
        old_interval = sys.getswitchinterval()
        sys.setswitchinterval(
            min(old_interval, self.rig_settings.switch_interval_s)
        )  # the display thread yields the GIL quickly
        gc.collect()
        gc.freeze()  # long-lived objects out of the collector's way: collections stay short
        try:
            if self.clock == "wall" and isinstance(self.handle, UdpHandle):
                self._await_device()  # the wall clock starts with the device's first pose
            next_t = time.perf_counter()
            while not self._stop.is_set() and self.status is None:
                if self.realtime:
                    next_t += T
                    now = time.perf_counter()
                    if next_t - now > self.rig_settings.spin_s:
                        time.sleep(next_t - now - self.rig_settings.wake_early_s)
                    while (now := time.perf_counter()) < next_t:
                        pass
                    if now - next_t > 50 * T:  # fell far behind (the process was stopped): start afresh
                        next_t = now
                    start = now
                else:
                    if self.clock == "device" and not self.handle.wait_readable(0.1):  # type: ignore[union-attr]
                        continue
                    start = time.perf_counter()
                try:
                    if not self.tick(start):
                        continue
                except SolverError as exc:
                    self._end(f"the simulation diverged at t = {self.sim.time_s:.3f} s: {exc}")
                except Exception as exc:  # noqa: BLE001 - a bug: end the session saying so, never hang
                    import traceback

                    where = traceback.extract_tb(exc.__traceback__)[-1]
                    self._end(
                        f"internal error in the haptic loop at t = {self.sim.time_s:.3f} s: {type(exc).__name__}: "
                        f"{exc} ({where.filename}:{where.lineno}; a bug in fixplan)",
                        status="error",
                    )
                end = time.perf_counter()
                self._compute.append(end - start)
                self._compute_sum += end - start
                self._compute_max = max(self._compute_max, end - start)
                if self.realtime:
                    self._late.append(start - next_t)
                    if end - next_t > T:
                        self._misses += 1
                elif end - start > T:
                    self._misses += 1
            if self.status is None:
                self._end(None)
            if self.handle is not None and self.snapshot is not None:  # tell the device it ended, however it did
                x_w, v_w = self.coordinates()
                self.handle.display(self.snapshot.felt_wrench, self._answer(self.snapshot.felt_wrench, x_w, v_w))
            last = self.snapshot
            if last is not None:  # the final state, with the last contact forces, flagged as ended
                self._publish(last.coupling_wrench, last.felt_wrench, last.pressed, normals=last.normal_forces_N,
                              forces=last.forces_world_N)  # fmt: skip
        finally:
            gc.unfreeze()
            sys.setswitchinterval(old_interval)
            self._ended.set()

    def _await_device(self) -> None:
        """Answer HELLOs (with CONFIG) until the device's first pose, or the session is stopped."""
        handle = self.handle
        while not self._stop.is_set() and isinstance(handle, UdpHandle) and handle.last_pose is None:
            handle.wait_readable(0.1)
            handle.read(time.perf_counter())

    def _guide_loop(self, verdict: bool = False) -> None:
        if self.realtime:
            real_time_priority(10)  # it holds the GIL to pickle snapshots: never preempted while it does
        period = VERDICT_PERIOD_S if verdict else GUIDE_PERIOD_S
        last: Snapshot | None = None
        next_t = time.perf_counter()
        while not self._ended.is_set():
            wait = next_t - time.perf_counter()
            if wait > 0 and self._ended.wait(wait):
                return
            next_t = max(next_t + period, time.perf_counter())
            if not verdict and self._restart_guide and isinstance(self.guide, RemoteGuide):
                self._restart_guide = False
                self.guide.close()
                self.guide = RemoteGuide(self.guide_fixture, self.start_state, tick_s=self.guide.tick_s,
                                         reaction_s=self.reaction_s)  # fmt: skip
            snap = self.snapshot
            if snap is None or snap is last:
                time.sleep(0.002)
                continue
            last = snap
            self._run_guide(snap, verdict=verdict)

    def _warm_up(self) -> None:
        """Load the engine's compiled kernels on a scratch copy, so that no tick pays for it."""
        scratch = self.loop.warm_up()  # the coupling and the engine step
        scratch.contacts()
        scratch.in_contact(self.threshold_N, self.contact_gap_m)
        self.coordinates()

    def start(self) -> HapticSession:
        """Start the loop (and the guidance) in their own threads."""
        self._warm_up()
        if self._guidance_on and not self.synchronous and self.guide is None:
            # both processes start now and make their first answer (imports, the first plan and the
            # policy: seconds) before the clock starts: the guidance is never late on the wall clock
            self.guide = RemoteGuide(self.guide_fixture, self.start_state, tick_s=GUIDE_PERIOD_S, role="plan",
                                     reaction_s=self.reaction_s)  # fmt: skip
            self.verdict_guide = RemoteGuide(
                self.guide_fixture, self.start_state, tick_s=GUIDE_PERIOD_S, role="verdict"
            )
            snap = self.snapshot
            if snap is not None:
                for guide in (self.guide, self.verdict_guide):
                    guide.post(snap, self._push_recent.copy())
                self._run_guide(snap, answer_within_s=self.rig_settings.guide_ready_s)
                self._run_guide(snap, verdict=True, answer_within_s=self.rig_settings.guide_ready_s)
        if self.synchronous and self.guide is not None and self.snapshot is not None:
            self._run_guide(self.snapshot)  # plan before the first tick
        self._thread = threading.Thread(target=self._loop, name="fixplan-haptic-loop", daemon=True)
        self._thread.start()
        if self.guide is not None and not self.synchronous:
            self._guide_thread = threading.Thread(target=self._guide_loop, name="fixplan-guidance", daemon=True)
            self._guide_thread.start()
        if self.verdict_guide is not None:
            self._verdict_thread = threading.Thread(
                target=self._guide_loop, kwargs={"verdict": True}, name="fixplan-verdict", daemon=True
            )
            self._verdict_thread.start()
        return self

    def wait(self, timeout_s: float | None = None) -> bool:
        """Block until the session ends (True) or ``timeout_s`` passes (False)."""
        return self._ended.wait(timeout_s)

    def stop(self) -> None:
        """End the session at the next tick (the status says how far it got)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        for thread in (self._guide_thread, self._verdict_thread):
            if thread is not None:
                thread.join(timeout=30.0)
        for guide in (self.guide, self.verdict_guide):
            if isinstance(guide, RemoteGuide):
                guide.close()

    def run(self) -> SessionResult:
        """Start, wait for the end (goal or time), stop, and return the result."""
        self.start()
        try:
            while not self.wait(0.1):
                pass
        finally:
            self.stop()
            if self.handle is not None:
                self.handle.close()
        return self.result()

    def result(self) -> SessionResult:
        if self.status is None:
            self._end(None)
        where: dict[str, Any] = {
            "time_s": self.sim.time_s,
            "state": sorted(self._observed or ()),
            "pose": self.sim.pose.to_json(),
        }
        if self.status == "jammed" and self.jammed_where is not None:
            where = dict(self.jammed_where)
        gaps = {c.name: float(c.gap_m) for c in self.sim.contacts()}
        return SessionResult(
            status=self.status or "error",  # _end above always sets it
            reason=self.reason,
            where=where,
            duration_s=self.sim.time_s,
            names=self.names,
            every_s=self.trace_every * self.period_s,
            trace=self.trace,
            states=list(self.states),
            stats=self.final_stats(),
            bridge=self.handle.stats.to_json() if isinstance(self.handle, UdpHandle) else None,
            device="auto" if self.handle is None else self.handle.kind,
            max_penetration_m=self.sim.max_penetration_m,
            final_gaps_m=gaps,
            saturated_ticks=self.saturated_ticks,
            felt_equals_coupling_max_N=self.felt_error_max,
            rates=self.guidance_rates(),
            clamping=self.clamping_result(),
        )

    def bridge_config(self) -> dict[str, Any]:
        """The CONFIG a UDP device receives after its HELLO."""
        dev = self.rig.loop.device
        return {
            "protocol": 1,
            "ndof": self.ndof,
            "dimension": self.dimension,
            "period_s": self.period_s,
            "K": [float(x) for x in self.K],
            "B": [float(x) for x in self.B],
            "device_damping": [float(x) for x in self.device_damping],
            "device_mass": [float(x) for x in dev._M],
            "operator_kp": [float(x) for x in self.rig.kp],
            "operator_kd": [float(x) for x in self.rig.kd],
            "x0": [float(x) for x in self.x0],
            "F_max_N": self.F_max,
            "T_max_Nm": self.T_max,
            "names": list(self.names),
            "mode_names": list(MODES),
        }
