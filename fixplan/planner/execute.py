"""Executing a plan as a contact-state feedback policy (the paper's state-based scheme).

A plan is a sequence of recognisable contact states ``S_0 ⊂ S_1 ⊂ … ⊂ S_n`` (sets of pressed
locators) and, per transition ``S_i → S_{i+1}``, a :class:`Step`: the target locator, the
motion on the established contacts (``roll``, ``slide`` or ``free``) and a guide path (the fine
plan's knot poses). The :class:`Executor` does not replay that path. At the control rate it

1. observes the *contact state* — the locators whose normal force exceeds a threshold, as a
   force sensor at each locator would report it, or whose gap is within ``contact_gap_m`` (a
   locator that friction leaves unloaded is still in contact), debounced over ``dwell_s`` — and
   the pose;
2. finds the current transition from the pressed set (advancing, or skipping ahead when a later
   planned state is reached directly);
3. chooses the desired motion at the *current* pose: toward the guide path a little ahead of
   the nearest knot, or (near its end) the least-``M``-norm motion that closes the target's
   gap, in both cases projected onto the motions that keep the established contacts
   (normal rows for sliding, all rows for rolling);
4. regulates speed along that motion (cruise at ``speed_mps``, slow down near the target) and
   re-solves the non-jamming wrench (:func:`~fixplan.jamming.search.search_wrench`, least
   effort, friction robust to ``±friction_margin``) at the current pose; the wrench is held
   between solves. With a ``[robot]`` every push is sought within the arm's own set at the
   current pose, its joint-torque box ``|τ_g(q) + J(q)ᵀ w| ≤ τ_max`` (the joints ``q`` followed
   by inverse kinematics from solve to solve, :class:`~fixplan.robot.follow.ArmFollower`), as
   the plan's searches are at its knots: not a ball of pushes inscribed in it.

Guards, each counted and reported in :class:`ExecutionLog`:

- **lost contact** (an established locator seen in contact is no longer) or **unplanned contact** (a
  pressed set that is not in the plan): re-plan from the observed state and pose (the
  ``replan`` callback: a coarse search from there);
- **stall** (at rest while the current transition expects motion): the push is re-searched
  with a larger acceleration and friction margin, then along the direct gap-closing motion; a
  stall that no wrench within the hand's limits breaks ends the run with the search's reason;
- **divergence**: a non-finite state, a speed beyond what the push can cause, or the part far
  from the fixture ends the run with that reason.

The same policy guides a person at a haptic device: :meth:`Executor.guidance` is the next
target and the suggested push.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from fixplan.contact_state import Debounce, State, format_state
from fixplan.errors import InputError
from fixplan.locating import contact_set, locator_contact
from fixplan.planner.fine import twist_from_pose
from fixplan.settings import DEFAULT, ExecutionNoise, ExecutionSettings, Settings
from fixplan.spatial import Pose, shift_twist, shift_wrench

if TYPE_CHECKING:
    from fixplan.jamming.hand_set import TorqueBox
    from fixplan.model import Fixture
    from fixplan.planner.policy import Policy

FloatArray = NDArray[np.float64]

FAILURE_KINDS = ("lost contact", "unplanned contact", "replan failed", "stall", "diverged", "timeout")


TransitionKind = Literal["roll", "slide", "free"]  # how a transition moves the part
Outcome = Literal["running", "reached", "failed"]  # an execution so far


@dataclass(frozen=True)
class Step:
    """The policy of one transition: press ``target`` while keeping ``established`` pressed."""

    established: tuple[str, ...]
    target: str
    kind: TransitionKind
    path: tuple[Pose, ...]  # guide poses, the first near where the transition starts, the last where target touches
    together: tuple[str, ...] = ()  # locators closing at the same instant (a redundant layout): pressed too

    @property
    def added(self) -> tuple[str, ...]:
        """The target and the locators closing together with it: the step is done when all touch."""
        return (self.target, *self.together)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"established": list(self.established), "target": self.target, "kind": self.kind}
        if self.together:
            out["together"] = list(self.together)
        return out


@dataclass
class ExecutionLog:
    """What the executor did and saw."""

    events: list[tuple[float, str, str]] = field(default_factory=list)  # (time, kind, message)
    counts: dict[str, int] = field(
        default_factory=lambda: {
            "solves": 0,
            "failed_solves": 0,
            "replans": 0,
            "lost_contact": 0,
            "unplanned_contact": 0,
            "stalls": 0,
            "retries": 0,
            "skipped_states": 0,
            "recovered": 0,
            "policy_switches": 0,
            "wrong_face": 0,
            "dead_ends": 0,
            "loops": 0,
        }
    )
    observed: list[tuple[str, ...]] = field(default_factory=list)  # debounced pressed sets, in order
    outcome: Outcome = "running"
    reason: str = ""
    # why it failed, one of FAILURE_KINDS (None while running or when reached)
    failure_kind: str | None = None
    transition_at_end: int = 0
    max_command_force_N: float = 0.0
    max_command_torque_Nm: float = 0.0
    # wrench solves that used more than the headroom (limit_fraction of the hand's limits): no
    # non-jamming push inside it, or none inside pressing the kept contacts by the weight
    beyond_fraction_solves: int = 0
    # with a [robot]: the most loaded joint's |τ| / τ_max under the pushes commanded (None: no arm), and
    # the solves at a pose the arm does not reach (searched without its box)
    max_arm_torque_ratio: float | None = None
    arm_unreached_solves: int = 0

    def event(self, t: float, kind: str, message: str) -> None:
        self.events.append((t, kind, message))

    def to_json(self) -> dict[str, Any]:
        return {
            "outcome": self.outcome,
            "reason": self.reason,
            "failure_kind": self.failure_kind,
            "counts": dict(self.counts),
            "events": [{"time_s": t, "kind": k, "message": m} for t, k, m in self.events],
            "max_command_force_N": self.max_command_force_N,
            "max_command_torque_Nm": self.max_command_torque_Nm,
            "beyond_fraction_solves": self.beyond_fraction_solves,
            "max_arm_torque_ratio": self.max_arm_torque_ratio,
            "arm_unreached_solves": self.arm_unreached_solves,
        }


Replan = Callable[[Pose, State], "list[Step] | str"]
# sets a transition (established state, target) aside for the re-plans to come, with the reason
Avoid = Callable[[State, str, str], None]


def braking_speed(settings: ExecutionSettings, left_m: float, *, free: bool) -> float:
    """The speed [m/s] from which the part stops just as it covers ``left_m``, braking as the settings say.

    Every transition brakes at ``brake_mps2``. Free flight (nothing kept, nothing to jam) brakes
    at ``free_brake_mps2`` until ``soft_approach_m`` is left, then as gently: the speed at the
    target, and over its last ``soft_approach_m``, is that of any transition. A free start
    5-80 mm away spent most of its simulated load in the gentle profile (0.5-2.8 s of 1-3.3 s).
    """
    a, d = settings.brake_mps2, settings.soft_approach_m
    if not free or left_m <= d or settings.free_brake_mps2 <= a:
        return math.sqrt(2.0 * a * left_m)
    return math.sqrt(2.0 * a * d + 2.0 * settings.free_brake_mps2 * (left_m - d))


def mass_speed(nu: FloatArray, M: FloatArray, m: float) -> float:
    """The mass-weighted size ``√(νᵀ M ν / m)`` of a twist (or twist rate) of the centre of mass."""
    return float(math.sqrt(max(float(nu @ M @ nu), 0.0) / m))


def origin_motion(com_rate: FloatArray, com_world: FloatArray, origin_world: FloatArray) -> FloatArray:
    """A twist (rate) of the centre of mass re-expressed at the body origin."""
    return shift_twist(com_rate, com_world, origin_world)


def project_keeping(
    nu: FloatArray, A: FloatArray | None, M_inv: FloatArray, rcond: float = DEFAULT.numerics.rcond
) -> FloatArray:
    """The ``M``-orthogonal projection of ``nu`` onto ``{ν : A ν = 0}`` (``rcond``: the pseudo-inverse's cut-off)."""
    if A is None or A.shape[0] == 0:
        return nu
    return nu - M_inv @ A.T @ np.linalg.pinv(A @ M_inv @ A.T, rcond=rcond) @ (A @ nu)


@dataclass(frozen=True)
class DivergenceGuard:
    """Where a simulated load has left the fixture: the one definition the executor and the haptic session use.

    The part never needs to leave the fixture's neighbourhood: beyond ``far_m`` (``reach_factor`` ×
    (the farthest locator, pin or bore from the start position + the part's bounding radius)) of where it
    started, or faster than ``v_limit_mps`` (``speed_limit_factor`` × the cruise speed, and at
    least 1 m/s: a speed no push of the plan causes), the load has diverged (the part fell off the
    locators, or the simulation blew up).
    """

    home_world: FloatArray  # the part's start position [m]
    far_m: float
    v_limit_mps: float

    @classmethod
    def for_fixture(
        cls, fixture: Fixture, settings: ExecutionSettings | None = None, *, accel_mps2: float | None = None
    ) -> DivergenceGuard:
        """The guard of ``fixture``'s neighbourhood.

        ``accel_mps2``: the largest acceleration the push can cause (a person's push is not the
        plan's cruise): the speed limit is then at least ``√(2 a far_m)``, what that acceleration
        reaches over the whole neighbourhood.
        """
        s = settings or ExecutionSettings()
        home = np.array(fixture.start.p_world, dtype=float)
        # the fixture's elements: its locators, pins and bores (a shaft's bore alone: no locator at all)
        points = [loc.p_world for loc in fixture.locators] + [p.p_world for p in fixture.pins]
        points += [b.p_world for b in fixture.bores]
        offsets = np.asarray(points, dtype=float).reshape(len(points), home.shape[0]) - home
        reach = float(np.max(np.linalg.norm(offsets, axis=1), initial=0.0))
        far_m = s.reach_factor * (reach + fixture.workpiece.shape.bounding_radius)
        v_limit = max(s.speed_limit_factor * s.speed_mps, 1.0)
        if accel_mps2 is not None:
            v_limit = max(v_limit, math.sqrt(2.0 * accel_mps2 * far_m))
        return cls(home, far_m, v_limit)

    def check(self, pose: Pose, speed_mps: float) -> str | None:
        """None while the part is near the fixture at a speed a push can cause; else why not, in words."""
        p = np.asarray(pose.p_world, dtype=float)
        if not (np.all(np.isfinite(p)) and math.isfinite(speed_mps)):
            return "the state is not finite"
        away = float(np.linalg.norm(p - self.home_world))
        if away > self.far_m:
            return f"the part is {away:.3g} m from where it started (limit {self.far_m:.3g} m)"
        if speed_mps > self.v_limit_mps:
            return f"speed {speed_mps:.3g} m/s, beyond what the push can cause (limit {self.v_limit_mps:.3g} m/s)"
        return None


class Executor:
    """The plan as a feedback policy; :meth:`command` is called once per tick with the observed state."""

    def __init__(
        self,
        fixture: Fixture,
        start_state: State,
        steps: Sequence[Step],
        settings: ExecutionSettings | None = None,
        *,
        replan: Replan | None = None,
        noise: ExecutionNoise | None = None,
        tick_s: float = 1e-3,
        policy: Policy | None = None,
        avoid: Avoid | None = None,
        profile: Settings = DEFAULT,
    ):
        """The executor of ``steps`` from ``start_state`` on ``fixture``.

        ``settings`` say how it pushes (default: ``profile.execution``); ``profile`` (default: the
        ``default`` profile, :mod:`fixplan.settings`) gives the rest of what it uses at run time:
        every wrench search runs with it (``search``, ``witness``, ``numerics``), its headroom is
        ``profile.search.limit_fraction`` and its projections cut off at ``profile.numerics.rcond``.
        :func:`fixplan.planner.verify.verify` passes its own ``settings`` here.
        """
        self.fixture = fixture
        self.policy = policy
        self.avoid = avoid
        self.profile = profile
        self.rcond = profile.numerics.rcond
        self.settings = s = profile.execution if settings is None else settings
        self.noise = noise or ExecutionNoise()
        self.rng = np.random.default_rng(self.noise.seed)
        self.replan = replan
        self.tick_s = tick_s
        wp = fixture.workpiece
        self.mass = wp.mass_kg
        self.weight_N = fixture.weight_N
        self.threshold_N = max(s.press_fraction * self.weight_N, 1e-6)
        self.names = tuple(loc.name for loc in fixture.locators)
        self.goal_state: State = frozenset(self.names)
        self.ndof = fixture.ndof
        self.log = ExecutionLog()
        self._set_plan(start_state, list(steps))
        self.every = max(int(round(1.0 / (s.control_rate_hz * tick_s))), 1)
        self.wrench = np.zeros(self.ndof)  # held command (about the body origin, world axes)
        self._applied = np.zeros(self.ndof)
        self._target = np.zeros(self.ndof)  # the policy's push before smoothing
        self._tick = 0
        self._debounced = Debounce(s.dwell_s)  # the observed contact state (None: nothing seen yet)
        self._still_since: float | None = None
        self._retry = 0
        self._use_direct = False
        self._last_reason = ""
        self._settled_since: float | None = None
        self._hold: FloatArray | None = None
        self._seen: set[str] = set()  # locators observed in contact at least once
        self._policy_failed: set[State] = set()  # states whose transition stalled and were re-planned from
        self._path_cache: dict[int, tuple[Step, list[float], int]] = {}  # the guide's lengths, nearest knot
        self._progress: tuple[int, float, float] | None = None  # (transition, least target gap [m], since [s])
        self._arrived = False  # the current target touches: holding until the state is confirmed
        self._recover_until: float | None = None  # pressing a lost contact back until then
        self._recover_why = ""
        self._pressed_back_for = -1  # the transition in which a failed re-plan last pressed the part back
        self._left_plan_in: tuple[State, str] | None = None  # (established, target) of the step a contact was lost in
        # contacts lost in each transition (established, target): a transition that keeps losing
        # one is a loop (settings.max_losses), set aside and planned around
        self._losses: dict[tuple[State, str], int] = {}
        self._looping: set[tuple[State, str]] = set()  # transitions set aside as loops in this load
        self._dead_ends = 0  # dead-end states left by lifting the part off (settings.dead_end_releases)
        self._prev_solve: tuple[float, FloatArray] | None = None  # (time, twist) at the last solve
        self._delay_ticks = int(round(self.noise.latency_s / tick_s))
        self._history: deque[tuple[Pose, FloatArray, State]] = deque(maxlen=self._delay_ticks + 1)

        self.F_max, self.T_max, _ = fixture.hand_limits()
        # headroom: pushes are sought within this fraction of the limits first (the search's own)
        self.limit_fraction = profile.search.limit_fraction
        self.guard = DivergenceGuard.for_fixture(fixture, s)
        self.v_limit = self.guard.v_limit_mps
        self._far_m = self.guard.far_m
        self._goal_normals = _goal_normals_body(fixture)
        self._release: tuple[str, float] | None = None  # (why, since): lifting the part off a wrong face
        self._beyond_noted = -1  # the transition in which a push beyond the headroom was last reported
        self._arm = None  # the arm that carries the part, followed from solve to solve (a [robot] in 3D)
        if fixture.robot is not None and fixture.dimension == 3:
            from fixplan.robot.follow import ArmFollower

            self._arm = ArmFollower(fixture)
            self.log.max_arm_torque_ratio = 0.0
        self._box: TorqueBox | None = None  # the arm's box at the last solve's pose
        self._box_about = np.zeros(3)  # that pose's body origin, the point the pushes are about
        self._box_binds = False  # the last push searched within the box loaded a joint near the headroom

    # -- plan bookkeeping ----------------------------------------------------------------------
    def _set_plan(self, start_state: State, steps: list[Step]) -> None:
        self.steps = steps
        self.states: list[State] = [start_state]
        for st in steps:
            self.states.append(frozenset(st.established) | set(st.added))
        self.index = 0  # current transition (== len(steps): holding at the goal)
        self._hold = None
        self._arrived = False
        self._recover_until = None

    @property
    def done(self) -> bool:
        return self.log.outcome != "running"

    def guidance(self) -> dict[str, Any]:
        """The next target and the suggested push (for a person at a device, or a display)."""
        step = self.steps[self.index] if self.index < len(self.steps) else None
        return {
            "transition": self.index + 1 if step else None,
            "target": step.target if step else None,
            "motion": step.kind if step else "hold",
            "wrench": [float(x) for x in self.wrench],
        }

    def _fail(self, t: float, reason: str, kind: str) -> None:
        if not self.done:
            self.log.outcome = "failed"
            self.log.reason = reason
            self.log.failure_kind = kind
            self.log.transition_at_end = self.index + 1
            self.log.event(t, "failed", reason)

    # -- observation ---------------------------------------------------------------------------
    @property
    def _observed(self) -> State | None:
        """The debounced contact state (None: nothing seen yet)."""
        return self._debounced.observed

    @property
    def observed_state(self) -> State:
        """The debounced contact state (empty until one is accepted).

        Its contacts are the ones the sensing holds within ``contact_hold_gap_m`` (a graze shorter
        than the dwell is never held).
        """
        return self._debounced.observed or frozenset()

    def _observe(self, t: float, pressed: State) -> bool:
        """Debounce the pressed set; True when a new state has just been accepted."""
        if not self._debounced.observe(t, pressed):
            return False
        self._seen |= pressed
        key = tuple(sorted(pressed))
        if key and (not self.log.observed or self.log.observed[-1] != key):
            self.log.observed.append(key)
        return True

    def _on_new_state(self, t: float, pose: Pose) -> None:
        P = self._observed
        if P is None:
            return
        if self._release is not None:
            return  # lifting the part off: contacts come and go until it is free
        if self._check_faces(t, pose, P):
            return
        later = [j for j in range(self.index + 1, len(self.states)) if self.states[j] == P]
        if later:
            j = later[0]
            if j > self.index + 1:
                self.log.counts["skipped_states"] += j - self.index - 1
                self.log.event(t, "skipped", f"reached {format_state(P)} directly")
            self.index = j
            self._retry, self._use_direct, self._still_since, self._arrived = 0, False, None, False
            if self._recover_until is not None:
                self._recover_until = None
                self.log.counts["recovered"] += 1
            self.log.event(t, "state", f"reached {format_state(P)}")
            return
        current = self.states[self.index]
        if P == current:
            if self._recover_until is not None:
                self._recover_until = None
                self.log.counts["recovered"] += 1
                self.log.event(t, "recovered", f"back in {format_state(P)}")
            return
        if self._recover_until is not None and t < self._recover_until:
            # pressing the part back: only the state it left (or a later planned one) ends the
            # press early; anything else in between is the part settling under the press
            return
        # a locator can only be lost once it has been seen in contact (at the start the push that
        # presses the part into its touching locators is still building up in the coupling)
        lost = sorted((current - P) & self._seen)
        if not lost and P < current:
            return
        if lost:
            self.log.counts["lost_contact"] += 1
            why = f"lost contact with {', '.join(lost)} in transition {self.index + 1}"
            if self.index < len(self.steps):
                step = self.steps[self.index]
                self._left_plan_in = key = (frozenset(step.established), step.target)
                self._losses[key] = n = self._losses.get(key, 0) + 1
                if n >= self.settings.max_losses:
                    # the same transition lost a contact again and again: pressing back and the
                    # policy lead the part into it once more (a box lost B2 and S2 24 times in
                    # its last slide until the time ran out). Set it aside and plan around it.
                    self._looping.add(key)
                    loop = f"{why}: {format_state(key[0])} + {key[1]} lost a contact {n} times, a loop"
                    if self.avoid is not None:
                        self.avoid(key[0], key[1], loop)
                    self._recover_until = None
                    self.log.counts["loops"] += 1
                    self.log.event(t, "guard", loop + "; set aside, re-planning around it")
                    self._replan(t, pose, P, loop, "lost contact")
                    return
            added = set(self.steps[self.index].added) if self.index < len(self.steps) else set()
            if self._recover_until is None and (P - current) <= added:
                # first press the part back into what it left (a part that rocks off a contact
                # on impact settles back): re-plan only if that does not restore the state
                self._recover_until = t + self.settings.recover_s
                self._recover_why = why
                self.wrench = self.hold_wrench(pose, sorted(current | P))
                self._target = self._with_noise(self.wrench)
                self.log.event(t, "guard", why + ": pressing the part back into it")
                return
        else:
            self.log.counts["unplanned_contact"] += 1
            why = f"unplanned contact state {format_state(P)} in transition {self.index + 1} (planned {format_state(self.states[self.index + 1]) if self.index + 1 < len(self.states) else 'the goal'})"
        self._recover_until = None
        self.log.event(t, "guard", why)
        if self._follow_policy(t, P, why, pose):
            return
        self._replan(t, pose, P, why, "lost contact" if lost else "unplanned contact")

    def _follow_policy(self, t: float, state: State, why: str, pose: Pose) -> bool:
        """Take the policy's transitions from ``state`` (no planner call); False when it has none.

        A state the policy already led into and that stalled is not taken again from the policy:
        the re-planner gets it (a fine plan from the pose the part is in).
        """
        if self.policy is None or state in self._policy_failed:
            return False
        chain = self.policy.chain_from(self.fixture, state, pose, self.goal_state, self.profile)
        if not chain:
            return False
        if any((frozenset(st.established), st.target) in self._looping for st in chain):
            return False  # it leads through a transition that looped here: the re-planner plans around it
        self.log.counts["policy_switches"] += 1
        self._set_plan(state, chain)
        self._retry, self._use_direct, self._still_since = 0, False, None
        seq = " → ".join(format_state(s) for s in self.states)
        self.log.event(t, "policy", f"{why}: the policy's transitions from {format_state(state)}: {seq}")
        return True

    def _replan(self, t: float, pose: Pose, state: State, why: str, kind_of_guard: str) -> None:
        if self.replan is None:
            self._fail(t, f"{why}; no re-planning available", "replan failed")
            return
        if self.log.counts["replans"] >= self.settings.max_replans:
            self._fail(t, f"{why}; gave up after {self.settings.max_replans} re-plans", kind_of_guard)
            return
        self.log.counts["replans"] += 1
        result = self.replan(pose, state)
        if isinstance(result, str):
            current = self.states[self.index]
            if self._pressed_back_for != self.index and state != current and self.index < len(self.steps):
                # no plan from where the part ended up: press it back into the state it left (and
                # what it touches now) for longer, once per transition, then look again
                self._pressed_back_for = self.index
                press_s = 3.0 * self.settings.recover_s
                self._recover_until = t + press_s
                self._recover_why = f"{why}; re-planning from {format_state(state)} failed: {result}"
                self.wrench = self.hold_wrench(pose, sorted(current | state))
                self._target = self._with_noise(self.wrench)
                self.log.event(
                    t,
                    "guard",
                    f"re-planning from {format_state(state)} failed: pressing the part back into {format_state(current | state)} for {press_s:g} s",
                )
                return
            if self._leave_dead_end(t, state, f"{why}; re-planning from {format_state(state)} failed: {result}"):
                return
            self._fail(t, f"{why}; re-planning from {format_state(state)} failed: {result}", "replan failed")
            return
        self._set_plan(state, result)
        self._retry, self._use_direct, self._still_since = 0, False, None
        seq = " → ".join(format_state(s) for s in self.states)
        self.log.event(t, "replan", f"re-planned from {format_state(state)}: {seq}")

    def _leave_dead_end(self, t: float, state: State, why: str) -> bool:
        """Lift the part off a state no plan leads on from, then approach again; True if it does.

        The part lost a contact on its way and settled where every way on jams (a 3-2-1 box that
        lost S1 while S2 closed: from {B1, B2, B3, E1, S2} the turn about S2 that closes S1 wedges
        between S2 and E1). Pressing back did not restore the plan, and the monotone planner adds
        contacts only: the way out is back through free space. The transition the contact was
        lost in is set aside first, so the new plan does not lead the part the same way again.
        """
        s = self.settings
        if not state or self._dead_ends >= s.dead_end_releases or self.replan is None or self._release is not None:
            return False
        self._dead_ends += 1
        self.log.counts["dead_ends"] += 1
        culprit = self._left_plan_in
        if culprit is None and self.index < len(self.steps):
            step = self.steps[self.index]
            culprit = (frozenset(step.established), step.target)
        aside = ""
        if culprit is not None and self.avoid is not None:
            self.avoid(culprit[0], culprit[1], why)
            aside = f", {format_state(culprit[0])} + {culprit[1]} set aside"
        self.log.event(t, "guard", f"{why}: a dead end; lifting the part off, then approaching again{aside}")
        self._release = (why, t)
        self._recover_until = None
        return True

    # -- the command ---------------------------------------------------------------------------
    def command(self, t: float, pose: Pose, twist: FloatArray, pressed: State) -> FloatArray:
        """The wrench the operator applies now (about the body origin, world axes).

        The policy's push, smoothed with a first-order lag of ``smoothing_s``: force and moment
        change together, as one push, instead of arriving through the coupling at different
        rates (a tall part tipped when a sideways push arrived before its counter-moment).
        """
        self._command(t, pose, twist, pressed)
        tau = self.settings.smoothing_s
        alpha = 1.0 if tau <= 0 else min(self.tick_s / tau, 1.0)
        self._applied = self._applied + alpha * (self._target - self._applied)
        return self._applied

    def _command(self, t: float, pose: Pose, twist: FloatArray, pressed: State) -> FloatArray:
        """One tick of the policy: updates the target push ``_target``."""
        twist = np.asarray(twist, dtype=float)
        if self._delay_ticks:
            # the operator reacts to what it saw latency_s ago (or the oldest observation it has)
            self._history.append((pose, twist, pressed))
            pose, twist, pressed = self._history[0]
        tick = self._tick
        self._tick += 1
        if self.done:
            return self._applied
        if not (np.all(np.isfinite(twist)) and np.all(np.isfinite(pose.p_world))):
            self._fail(t, f"the simulated load diverged at t = {t:.3f} s: the state is not finite", "diverged")
            return self._applied
        M = self._mass_matrix(pose)
        speed = mass_speed(twist, M, self.mass)
        why = self.guard.check(pose, speed)
        if why is not None:
            self._fail(
                t, f"the simulated load diverged at t = {t:.3f} s (transition {self.index + 1}): {why}", "diverged"
            )
            return self._applied
        if self._observe(t, pressed):
            self._on_new_state(t, pose)
            if self.done:
                return self._applied
        if self._release is None and tick % self.every == 0 and self._observed:
            # a part may also roll onto another face while its pressed set stays the same
            self._check_faces(t, pose, self._observed)
        if self._release is not None:
            if tick % self.every == 0:
                self._lift(t, pose, twist, M)
            return self._applied
        at_goal = self.index >= len(self.steps)
        # at rest with everything pressed: done
        if at_goal and self._observed == self.goal_state and speed < self.settings.stall_speed_mps * 10:
            if self._settled_since is None:
                self._settled_since = t
            elif t - self._settled_since >= self.settings.settle_s:
                self.log.outcome = "reached"
                self.log.reason = "every locator pressed, at rest"
                self.log.transition_at_end = len(self.steps)
                self.log.event(t, "reached", "every locator pressed, at rest")
        else:
            self._settled_since = None
        if not at_goal and self._recover_until is None and tick % self.every == 0:
            # at the control rate: a stall is judged over stall_s (0.12 s) or progress_s, and the
            # target's exact gap at every tick was a tenth of the executor's time
            self._check_stall(t, pose, speed)
            if self.done:
                return self._applied
        if self._recover_until is not None:
            if t >= self._recover_until:
                # pressing did not restore the state: re-plan from what is observed
                self._recover_until = None
                P = self._observed if self._observed is not None else frozenset()
                self.log.event(t, "guard", f"{self._recover_why}; not restored by pressing")
                if not self._follow_policy(t, P, self._recover_why, pose):
                    self._replan(t, pose, P, self._recover_why, "lost contact")
                if self.done:
                    return self._applied
            else:
                return self._applied
        if not at_goal:
            # the target touched: stop driving at once and press into the new state's contacts
            # (the push that brought the part here would carry it on, or tip it back)
            step = self.steps[self.index]
            arrived = set(step.added) <= pressed and set(step.established) <= pressed
            if arrived and not self._arrived:
                self._arrived = True
                self.wrench = self.hold_wrench(pose, [*step.established, *step.added])
                self._target = self._with_noise(self.wrench)
                return self._applied
            if not arrived:
                self._arrived = False
        if tick % self.every == 0:
            if self._arrived and not at_goal:
                pass  # hold until the new state is confirmed (dwell), then the next transition
            elif at_goal:
                if self._hold is None:
                    self._hold = self.hold_wrench(pose)
                    self.log.event(t, "hold", "every planned state reached: pressing the part into every locator")
                self.wrench = self._hold
            else:
                self._solve(t, pose, twist, M)
            self._target = self._with_noise(self.wrench)
        return self._applied

    def wrong_faces(self, pose: Pose, pressed: State) -> list[tuple[str, str]]:
        """Pressed locators that press another face of the part than at the goal, with that face.

        A locator's contact normal in the part's frame is compared with its normal at the goal
        (cosine below ``wrong_face_cos``): a side tip under the base, a base tip against a side
        face. No plan from such a state reaches the goal without first leaving it ("B2 cannot
        close while B2 stays touching its -y face"). Shapes without named faces: none.
        """
        if not self._goal_normals:
            return []
        shape = self.fixture.workpiece.shape
        out = []
        for loc in self.fixture.locators:
            n_goal = self._goal_normals.get(loc.name)
            if n_goal is None or loc.name not in pressed:
                continue
            proj = shape.project(pose.point_body_from_world(loc.p_world))
            if float(np.asarray(proj.normal_body) @ n_goal) < self.settings.wrong_face_cos:
                face = shape.face_of(proj.point_body)
                out.append((loc.name, f"face {face!r}" if face else "another face"))
        return out

    def _check_faces(self, t: float, pose: Pose, pressed: State) -> bool:
        """Start lifting the part off when it presses a locator on the wrong face; True if it does."""
        if self._release is not None or self.replan is None:
            return False
        wrong = self.wrong_faces(pose, pressed)
        if not wrong:
            return False
        where = ", ".join(f"{n} presses {f}" for n, f in wrong)
        why = f"{where}, not the face it touches at the goal (transition {self.index + 1})"
        self.log.counts["wrong_face"] += 1
        self.log.event(t, "guard", f"{why}: lifting the part off, then approaching again")
        if self.avoid is not None and self.index < len(self.steps):
            # the re-plan from free space must not lead the part the same way onto the wrong face
            # (it chose the same sequence again and the part met the same face until the time ran
            # out: six lifts in 12 s on a generated box)
            step = self.steps[self.index]
            self.avoid(frozenset(step.established), step.target, why)
        self._release = (why, t)
        self._recover_until = None
        return True

    def _lift(self, t: float, pose: Pose, twist: FloatArray, M: FloatArray) -> None:
        """Carry the part straight off every locator it touches, then re-plan from free space.

        The hand carries the part (free flight, the whole twist controlled) along the sum of the
        near locators' contact normals (or against gravity when they cancel) at the cruise speed,
        keeping its orientation, until every locator is ``release_gap_m`` away; the re-plan then
        starts with the approach from free space (:meth:`Planner.replan` of an empty state).
        """
        from fixplan.jamming.push import free_wrench
        from fixplan.locating import locator_gaps

        s = self.settings
        why, since = self._release  # type: ignore[misc]  # only called while releasing
        fx = self.fixture
        wp = fx.workpiece
        d = fx.dimension
        gaps = locator_gaps(wp, pose, fx.locators)
        if float(np.min(gaps)) >= s.release_gap_m:
            self._release = None
            self.log.event(t, "released", f"every locator at least {s.release_gap_m:g} m away")
            self._debounced.observed = frozenset()
            self._replan(t, pose, frozenset(), why, "unplanned contact")
            return
        if t - since > s.release_s:
            self._fail(t, f"{why}; could not lift the part off it within {s.release_s:g} s", "stall")
            return
        push = np.zeros(d)
        for loc, g in zip(fx.locators, gaps, strict=True):
            if g < s.release_gap_m:
                push += locator_contact(wp, pose, loc).normal_world
        up = -np.asarray(fx.gravity, dtype=float)
        up = up / (np.linalg.norm(up) or 1.0)
        if float(np.linalg.norm(push)) < 0.5:
            push = push + up
        direction = push / float(np.linalg.norm(push))
        twist_ahead = twist + self._measured_accel(t, twist) * self._lag_s
        desired = np.concatenate([direction * s.speed_mps, np.zeros(self.ndof - d)])
        a_com = self._carry_accel((desired - twist_ahead) / s.speed_time_s, M, s.accel_mps2)
        self.log.counts["solves"] += 1
        ok, w, reason = free_wrench(fx, pose, a_com, M, self._arm_boxes(t, pose))
        if ok:
            self._accept(w)
        else:
            self._reject(t, reason)
        self._target = self._with_noise(self.wrench)

    def _carry_accel(self, a_com: FloatArray, M: FloatArray, cap_mps2: float) -> FloatArray:
        """The acceleration a carrying hand asks: translation capped at ``cap_mps2``, turning by the hand's torque.

        The translation is what the plan's speed profile bounds; the turning is the hand's
        grip: a part that arrives spinning (5–10 rad/s after it slipped off a locator) is
        stopped with up to ``carry_torque_fraction`` of the hand's torque limit. Capping both
        together by ``cap_mps2`` left a 2 kg box 0.12 N·m against its spin, and it tumbled on.
        """
        d = self.fixture.dimension
        lin, ang = a_com[:d], a_com[d:]
        n_lin = float(np.linalg.norm(lin))
        if n_lin > cap_mps2:
            lin = lin * (cap_mps2 / n_lin)
        torque = M[d:, d:] @ ang
        T = float(np.linalg.norm(torque))
        T_cap = self.settings.carry_torque_fraction * self.T_max
        if T > T_cap:
            ang = ang * (T_cap / T)
        # headroom: the carrying force m a − m g within limit_fraction of max_force where holding
        # the part still is (the largest share s of the acceleration that keeps it there; ‖m s a − m g‖
        # is convex in s, so bisection from the hold finds it)
        m = float(M[0, 0])
        g_lin = np.asarray(self.fixture.gravity_wrench()[:d], dtype=float)
        F_cap = self.limit_fraction * self.F_max
        if float(np.linalg.norm(m * lin - g_lin)) > F_cap >= float(np.linalg.norm(g_lin)):
            lo, hi = 0.0, 1.0
            for _ in range(40):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if float(np.linalg.norm(m * mid * lin - g_lin)) <= F_cap else (lo, mid)
            lin = lin * lo
        return np.concatenate([lin, ang])

    def carry_wrench(self, pose: Pose) -> FloatArray:
        """The push that holds the part still in free space at ``pose`` (gravity's opposite, about the body origin)."""
        from fixplan.jamming.push import free_wrench

        return free_wrench(self.fixture, pose, np.zeros(self.ndof), self._mass_matrix(pose))[1]

    def arm_start_push(self, pose: Pose, pressed: State) -> FloatArray | None:
        """The hold push (:meth:`hold_wrench`) on ``pressed`` where the arm cannot hold itself at ``pose`` without pushing.

        None without an arm, or where its joints carry its own weight within their efforts (no
        push, ``|τ_g| ≤ τ_max``). An arm whose weight alone is beyond a joint's effort holds the
        part pressed into its contacts from the first tick, instead of starting from no push.
        """
        boxes = self._arm_boxes(None, pose)
        if not boxes or not pressed or float(np.max(boxes[0].ratios(np.zeros(6), pose.p_world))) <= 1.0:
            return None
        return self.hold_wrench(pose, sorted(pressed))

    def preload(self, w: FloatArray) -> None:
        """Start with ``w`` already applied (a part that is carried when the run begins)."""
        self.wrench = np.asarray(w, dtype=float).copy()
        self._target = self.wrench.copy()
        self._applied = self.wrench.copy()

    def hold_wrench(self, pose: Pose, names: Sequence[str] | None = None) -> FloatArray:
        """A push that keeps every locator (or ``names``) pressed at ``pose`` (about the body origin, world axes).

        The contact forces that carry gravity (least squares, ≥ 0) plus ``hold_fraction`` of the
        weight pressed into every locator: ``w = r − τ Σ_i G_iᵀ``, with ``r`` the part of gravity
        the locators cannot carry; τ is reduced until the push is within ``limit_fraction`` of the
        hand's limits (the headroom every push keeps where it can). With a ``[robot]`` the push is
        also kept within ``limit_fraction`` of the joints' efforts at ``pose`` (its torque box): τ
        is reduced, or raised while within the hand's limits (pressing the part down can carry an
        arm's own weight), and where no τ does it the push that loads the joints least is taken.
        """
        from fixplan.nnls import nnls

        fx = self.fixture
        cs = contact_set(fx, pose, list(self.names if names is None else names))
        G = cs.G  # (k, n): unit normal wrenches about the centre of mass
        w_g = fx.gravity_wrench()
        f, _ = nnls(G.T, -w_g)
        r = -w_g - G.T @ f
        tau = self.settings.hold_fraction * self.weight_N
        com = cs.com_world
        d = fx.dimension
        F_cap, T_cap = self.limit_fraction * self.F_max, self.limit_fraction * self.T_max
        boxes = self._arm_boxes(None, pose)
        taus = [tau * 0.7**k for k in range(30)]
        if boxes:
            taus += [tau / 0.7**k for k in range(1, 30)]
        best: tuple[float, FloatArray] | None = None
        for tau_k in taus:
            w_o = shift_wrench(r - tau_k * G.sum(axis=0), com, pose.p_world)
            if np.linalg.norm(w_o[:d]) > F_cap or np.linalg.norm(w_o[d:]) > T_cap:
                continue
            ratio = float(np.max(boxes[0].ratios(w_o, pose.p_world))) if boxes else 0.0
            if ratio <= self.limit_fraction:
                best = (ratio, w_o)
                break
            if best is None or ratio < best[0]:
                best = (ratio, w_o)
        if best is None:  # none within the hand's limits: the least pressing
            return shift_wrench(r - taus[29] * G.sum(axis=0), com, pose.p_world)
        if boxes and self.log.max_arm_torque_ratio is not None:
            self.log.max_arm_torque_ratio = max(self.log.max_arm_torque_ratio, best[0])
        return best[1]

    def _with_noise(self, w: FloatArray) -> FloatArray:
        if self.noise.force_noise <= 0:
            return w.copy()
        return w * (1.0 + self.noise.force_noise * self.rng.standard_normal(w.shape[0]))

    def _mass_matrix(self, pose: Pose) -> FloatArray:
        from fixplan.kinematics import mass_matrix

        wp = self.fixture.workpiece
        return mass_matrix(wp.mass_kg, wp.inertia_body, pose.R_world_body)

    def _check_stall(self, t: float, pose: Pose, speed: float) -> None:
        """Two guards on the current transition: at rest, or moving without closing the target's gap.

        No progress — the target's gap not ``progress_m`` smaller than its least value so far for
        ``progress_s`` — is a stall too: a part rocking on a kept contact, or sliding along it
        without coming nearer, has speed but goes nowhere (a plate slid for 7 s with its side
        locator 30 mm away until the time ran out).
        """
        s = self.settings
        step = self.steps[self.index]
        gap = float(locator_contact(self.fixture.workpiece, pose, self.fixture.locator(step.target)).gap_m)
        if self._progress is None or self._progress[0] != self.index or gap < self._progress[1] - s.progress_m:
            self._progress = (self.index, gap, t)
        elif t - self._progress[2] >= s.progress_s:
            self._progress = (self.index, gap, t)
            self._stalled(
                t, pose, f"no progress in transition {self.index + 1}: {step.target}'s gap stays at {gap:.3g} m"
            )
            return
        if speed >= s.stall_speed_mps:
            self._still_since = None
            return
        if self._still_since is None:
            self._still_since = t
            return
        if t - self._still_since < s.stall_s:
            return
        self._still_since = None
        self._stalled(t, pose, f"at rest in transition {self.index + 1} before {step.target} touches")

    def _stalled(self, t: float, pose: Pose, what: str) -> None:
        """A stall: re-search the push, then go along the direct motion, then re-plan from here, then fail."""
        s = self.settings
        self.log.counts["stalls"] += 1
        step = self.steps[self.index]
        state = self.states[self.index]
        guided = len(step.path) >= 2
        if (
            (self._retry >= s.max_retries or not guided)
            and self.replan is not None
            and state not in self._policy_failed
        ):
            # the transition (the plan's from where the part was then, after the re-searches; the
            # policy's at once: it was planned at a representative pose, not where the part is)
            # does not move the part from where it is now: a fine plan from here is the last resort
            self._policy_failed.add(state)
            why = f"{what}: {format_state(state)} + {step.target} stalled after {self._retry} re-searches"
            self.log.event(t, "guard", why)
            self._replan(t, pose, state, why, "stall")
            return
        if self._retry >= s.max_retries:
            self._fail(
                t,
                f"stalled in transition {self.index + 1} ({format_state(self.states[self.index])} + {step.target}) at t = {t:.3f} s "
                f"after {self._retry} re-searches ({what}): "
                + (
                    self._last_reason or f"it stays at rest under pushes found to move it ({self._verdict(pose, step)})"
                ),
                "stall",
            )
            return
        self._retry += 1
        self.log.counts["retries"] += 1
        if self._retry >= 2:
            self._use_direct = True
        self.log.event(
            t,
            "stall",
            f"{what} ({self._verdict(pose, step)}): "
            f"re-search #{self._retry}"
            + (" along the direct gap-closing motion" if self._use_direct else " with a larger push"),
        )

    def _verdict(self, pose: Pose, step: Step) -> str:
        """What the held push does to the part at rest here (the classifier's mode and margin)."""
        from fixplan.jamming import classify

        names = [n for n in step.established] or None
        try:
            c = classify(self.fixture, self._applied, names, pose=pose, jobs=1)[0]
        except Exception as exc:  # noqa: BLE001 - a report, never a reason to stop
            return f"push not classified: {exc}"
        margin = (
            ""
            if c.balance_residual is None or not math.isfinite(c.balance_residual)
            else f", margin {c.balance_residual:.3g}"
        )
        return f"the held push: {c.mode}{margin}"

    def direction(self, pose: Pose, step: Step) -> tuple[FloatArray, float]:
        """Unit (mass-weighted) desired twist of the centre of mass and the distance left [m]."""
        fx = self.fixture
        wp = fx.workpiece
        names = [*step.established, step.target]
        cs = contact_set(fx, pose, names).nearest_of(step.target)  # kept contacts, then the target's nearest
        M, M_inv = cs.mass_matrix, cs.M_inv
        n_est = len(cs) - 1 if step.established else 0
        if n_est:
            est_cs_rows = cs.J[: int(sum(c.size for c in cs.contacts[:n_est]))] if step.kind == "roll" else cs.G[:n_est]
        else:
            est_cs_rows = None
        target = cs.contacts[-1]
        gap = max(float(target.gap_m), 0.0)
        # the direct motion: the least M-norm one that closes the target's gap (to first order)
        A = cs.G[-1:] if est_cs_rows is None else np.vstack([est_cs_rows, cs.G[-1:]])
        b = np.zeros(A.shape[0])
        b[-1] = -max(gap, 1e-4)
        direct = M_inv @ A.T @ np.linalg.pinv(A @ M_inv @ A.T, rcond=self.rcond) @ b
        left = gap
        nu = direct
        if not self._use_direct and len(step.path) >= 2:
            n_path = len(step.path)
            cache = self._path_cache.get(id(step))
            if cache is None or cache[0] is not step:
                # the guide's segment lengths, once per step (in the metric where it starts)
                seg_all = [
                    mass_speed(twist_from_pose(a, b_, wp.com_body), M, wp.mass_kg)
                    for a, b_ in zip(step.path[:-1], step.path[1:], strict=True)
                ]
                cache = (step, seg_all, 0)
            # the nearest knot: searched near the last one, the whole guide when it lies at the window's edge
            lo, hi = max(cache[2] - 3, 0), min(cache[2] + 7, n_path)
            twists: dict[int, FloatArray] = {}

            def near(lo_: int, hi_: int) -> int:
                for k in range(lo_, hi_):
                    if k not in twists:
                        twists[k] = twist_from_pose(pose, step.path[k], wp.com_body)
                return min(range(lo_, hi_), key=lambda k: (mass_speed(twists[k], M, wp.mass_kg), k))

            j = near(lo, hi)
            if (j == lo and lo > 0) or (j == hi - 1 and hi < n_path):
                j = near(0, n_path)
            self._path_cache = {id(step): (step, cache[1], j)}
            ahead = min(j + 1, n_path - 1)
            if ahead not in twists:
                twists[ahead] = twist_from_pose(pose, step.path[ahead], wp.com_body)
            left_path = mass_speed(twists[ahead], M, wp.mass_kg) + float(sum(cache[1][ahead:]))
            if est_cs_rows is None and ahead < len(step.path) - 2:
                # free flight along the guide (the approach from free space may first take the
                # part back, away from the target): follow it, nothing to keep, until its last
                # segment leads onto the target
                size = mass_speed(twists[ahead], M, wp.mass_kg)
                if size > 1e-15:
                    return twists[ahead] / size, max(left_path, gap)
            if left_path > max(2.0 * gap, 1e-3) or ahead < len(step.path) - 1:
                to = project_keeping(twists[ahead], est_cs_rows, M_inv, self.rcond)
                # blend in the gap-closing motion so the path leads onto the target
                nu = to + 0.5 * direct * (mass_speed(to, M, wp.mass_kg) / max(mass_speed(direct, M, wp.mass_kg), 1e-15))
                left = max(left_path, gap)
        elif len(step.path) < 2 and fx.goal_pose is not None:
            # no guide (a policy's transition planned at a representative pose): close the gap while
            # turning toward the goal — the motions that keep the contacts and leave the target's
            # gap alone, toward the located pose, at most as fast as the closing motion (closing
            # the gap greedily rolled a tilted box on one base locator further from the goal)
            keep_target = cs.G[-1:] if est_cs_rows is None else np.vstack([est_cs_rows, cs.G[-1:]])
            # (the located pose nearest this one: a part's free spin is not turned back)
            toward = project_keeping(
                twist_from_pose(pose, fx.goal_near(pose), wp.com_body), keep_target, M_inv, self.rcond
            )
            size_t, size_d = mass_speed(toward, M, wp.mass_kg), mass_speed(direct, M, wp.mass_kg)
            if size_t > 1e-15:
                nu = direct + toward * min(1.0, size_d / size_t)
        nu = project_keeping(nu, est_cs_rows, M_inv, self.rcond)
        if nu is not direct and float(cs.G[-1] @ nu) >= 0.0:
            # the guide leads away from the target (the part is off the path, e.g. a perturbed
            # world rolls it along another curve, and the knot ahead lies behind it on the
            # constraint surface): a transition's motion closes its target's gap, so go direct.
            # Following the guide here rocked a plate back and forth on one locator for 4.5 s
            nu = project_keeping(direct, est_cs_rows, M_inv, self.rcond)
        size = mass_speed(nu, M, wp.mass_kg)
        if size <= 1e-15:
            return np.zeros(self.ndof), left
        return nu / size, left

    def _solve(self, t: float, pose: Pose, twist: FloatArray, M: FloatArray) -> None:
        from fixplan.jamming.push import free_wrench

        s = self.settings
        step = self.steps[self.index]
        try:
            nu_hat, left = self.direction(pose, step)
        except (InputError, np.linalg.LinAlgError) as exc:
            self._last_reason = str(exc)
            return
        if not np.any(nu_hat):
            self._last_reason = "no motion keeps the established contacts and closes the target's gap"
            return
        boost = 1.0 + self._retry
        # the speed the part will have when this push acts: the push reaches it one control
        # period plus the smoothing later, and it keeps accelerating as measured until then
        # (without this the loop overshot the cruise speed by the lag × the acceleration: a heavy
        # box reached 69 mm/s against 40 and its impact on the last locator tipped it)
        twist_ahead = twist + self._measured_accel(t, twist) * self._lag_s
        v_along = float(twist_ahead @ M @ nu_hat) / self.mass
        # cruise, then brake at brake_mps2 so that contact is made at about min_speed_mps
        # free flight (nothing to keep, nothing to jam) cruises faster; both brake alike toward the target
        cruise = s.speed_mps if step.established else max(s.free_speed_mps, s.speed_mps)
        v_des = max(s.min_speed_mps, min(cruise, braking_speed(s, max(left, 0.0), free=not step.established)))
        # below the desired speed: speed up; up to 1.5× it: coast (the least push that keeps the
        # motion); beyond: brake (a dead band, so the loop does not chatter between push and brake)
        if v_along <= v_des:
            a_raw = (v_des - v_along) / s.speed_time_s
        elif v_along <= 1.5 * v_des:
            a_raw = 0.0
        else:
            a_raw = (1.5 * v_des - v_along) / s.speed_time_s
        a_cmd = float(np.clip(a_raw, -s.accel_mps2, s.accel_mps2))
        floor = s.min_accel_fraction * s.accel_mps2 * boost
        # sliding too fast: friction brakes the part when the push only presses the kept contacts
        brake = (
            float(np.clip(-a_cmd / (0.5 * s.accel_mps2), 0.0, 1.0))
            if step.kind == "slide" and step.established
            else 0.0
        )
        wp = self.fixture.workpiece
        com = pose.point_world_from_body(wp.com_body)
        if step.kind == "slide" and step.established:
            # the part itself too fast, whatever the direction asked: its approach to the target
            # (what the impact unloads other contacts with) or its speed. A push toward a turn the
            # base's friction resists leaves the speed along the asked motion low while the part
            # translates ever faster (a tall box met its end locator at 6 cm/s: B1 lifted)
            a_slow = self._slowdown(pose, twist, twist_ahead, M, step)
            if a_slow is not None and self._brake(t, pose, twist, a_slow, com, step):
                return
        if brake > 0.0 and self._brake(t, pose, twist, nu_hat * a_cmd, com, step):
            return
        if step.kind != "roll" or not step.established:
            a_cmd = max(a_cmd, floor)  # sliding and free motion: never command a jamming push
        elif abs(a_cmd) < floor:
            a_cmd = math.copysign(floor, a_cmd if a_cmd != 0 else 1.0)
        a_cmd *= boost if a_cmd > 0 else 1.0
        a_com = nu_hat * a_cmd
        self.log.counts["solves"] += 1
        if not step.established:
            # free flight: the hand controls the whole twist, not only its part along the motion
            # (a part that fell off a contact kept falling while the push only set its speed
            # toward the target: 1 m/s within 0.7 s); the velocity error is closed in speed_time_s
            a_com = self._carry_accel((nu_hat * v_des - twist_ahead) / s.speed_time_s, M, s.accel_mps2 * boost)
            ok, w, why = free_wrench(self.fixture, pose, a_com, M, self._arm_boxes(t, pose))
            if ok:
                self._accept(w)
            else:
                self._reject(t, why)
            return
        motion = origin_motion(a_com, com, pose.p_world)
        # friction opposes the slip the part has (plus what this push adds before the next
        # solve), not the acceleration asked for: a part turning while it slides would otherwise
        # get a push computed for friction pointing elsewhere, and leave a kept contact
        slip = origin_motion(twist + a_com / s.control_rate_hz, com, pose.p_world)
        try:
            res = self._search(
                t,
                pose,
                motion,
                list(step.established),
                objective="effort",
                min_margin_N=s.margin_N,
                friction_margin=s.friction_margin * boost,
                max_accel_factor=s.max_accel_factor,
                slip_twist=slip,
                confirm=False,  # the loop watches the motion it causes: no classifier check at 200 Hz
            )
        except InputError as exc:
            self._reject(t, str(exc))
            return
        if res.found and res.wrench is not None:
            self._note_fraction(t, res)
            w = np.asarray(res.wrench, dtype=float)
            if brake > 0.0:
                w = (1.0 - brake) * w + brake * self.hold_wrench(pose, step.established)
            self._accept(w)
        else:
            self._reject(t, res.reason)

    @property
    def _lag_s(self) -> float:
        """How long after an observation a new push acts on the part: a control period plus the smoothing."""
        return 1.0 / self.settings.control_rate_hz + self.settings.smoothing_s

    def _measured_accel(self, t: float, twist: FloatArray) -> FloatArray:
        """The twist's rate between the last two solves (zero at the first, after a gap, or at rest)."""
        prev, self._prev_solve = self._prev_solve, (t, twist.copy())
        if prev is None:
            return np.zeros_like(twist)
        dt = t - prev[0]
        if not (0.0 < dt <= 2.5 / self.settings.control_rate_hz):
            return np.zeros_like(twist)
        return (twist - prev[1]) / dt

    def _slowdown(
        self, pose: Pose, twist: FloatArray, twist_ahead: FloatArray, M: FloatArray, step: Step
    ) -> FloatArray | None:
        """The deceleration of the part's own motion when it is too fast, else None.

        Too fast: the target's gap closes, or the part moves (its mass-weighted speed, i.e. its
        kinetic energy), faster than 1.5 × the braking profile ``√(2 a_b g)`` capped at the cruise
        speed (``g``: the gap left after the distance covered before a new push acts, one control
        period plus the push's smoothing; never below ``min_speed_mps``); both speeds as they will
        be when the push acts (``twist_ahead``: the measured acceleration continued). A pivot
        about a nearby locator closes the gap slowly while the part turns fast: bounded by the
        closing rate alone it met its target with far more energy, and the impact pivoted it off
        the locator it turned about (side locators 11 mm apart: six re-plans). The deceleration
        opposes the twist and brings the speed back within the limit in about ``speed_time_s``,
        keeping the established contacts.
        """
        s = self.settings
        speed = mass_speed(twist, M, self.mass)
        if speed <= s.min_speed_mps:
            return None
        target = contact_set(self.fixture, pose, [step.target])
        gap = max(float(target.contacts[0].gap_m), 0.0)
        closing = -float(target.G[0] @ twist)  # m/s at which the target's gap closes
        closing_ahead = -float(target.G[0] @ twist_ahead)
        allowed = max(s.min_speed_mps, math.sqrt(2.0 * s.brake_mps2 * max(gap - max(closing, 0.0) * self._lag_s, 0.0)))
        ratio = max(closing_ahead, mass_speed(twist_ahead, M, self.mass)) / (1.5 * min(allowed, s.speed_mps))
        if ratio <= 1.0:
            return None
        a = min(speed * (1.0 - 1.0 / ratio) / s.speed_time_s, s.accel_mps2)
        # against the twist, on the motions that keep the established contacts (the twist's
        # normal part is numerical noise: left in, it reads as a push that lifts the part off)
        est = contact_set(self.fixture, pose, list(step.established))
        back = project_keeping(-np.asarray(twist, dtype=float), est.G, est.M_inv, self.rcond)
        size = mass_speed(back, M, self.mass)
        return None if size <= 1e-15 else back * (a / size)

    def _brake(self, t: float, pose: Pose, twist: FloatArray, a_com: FloatArray, com: FloatArray, step: Step) -> bool:
        """Slow a sliding part down with a push that balances what sliding friction does to it.

        Friction keeps acting while the part slides, with its moment about the centre of mass (a
        tall part sliding on its base is tipped by it); the static hold push has no such moment,
        and blending toward it let tall boxes tip off a base locator as they braked. The push is
        the dynamics of the deceleration ``a_com`` with friction against the slip, without the
        not-jamming constraint (held at rest is what braking aims at). False when none is found.
        """
        s = self.settings
        self.log.counts["solves"] += 1
        try:
            res = self._search(
                t,
                pose,
                origin_motion(a_com, com, pose.p_world),
                list(step.established),
                objective="effort",
                min_margin_N=s.margin_N,
                friction_margin=0.0,
                max_accel_factor=s.max_accel_factor,
                slip_twist=origin_motion(np.asarray(twist, dtype=float), com, pose.p_world),
                certify=False,
                confirm=False,
            )
        except InputError:
            return False
        if not (res.found and res.wrench is not None):
            return False
        self._note_fraction(t, res)
        self._accept(np.asarray(res.wrench, dtype=float))
        return True

    def _note_fraction(self, t: float, res: Any) -> None:
        """Count a push found beyond the headroom, and say so once per transition."""
        if res.within_fraction is not False:
            return
        self.log.beyond_fraction_solves += 1
        if self._beyond_noted != self.index:
            self._beyond_noted = self.index
            why = (
                f"within {self.limit_fraction:.0%} of the hand's limits the kept contacts are pressed by less than the weight"
                if "less than the weight" in res.reason
                else f"no non-jamming push within {self.limit_fraction:.0%} of the hand's limits"
            )
            self.log.event(
                t,
                "limits",
                f"transition {self.index + 1}: {why} here; using {res.force_fraction:.0%} of max_force and"
                f" {res.torque_fraction:.0%} of max_torque",
            )

    def _search(self, t: float, pose: Pose, motion: FloatArray, contacts: list[str], **options: Any) -> Any:
        """:func:`~fixplan.jamming.search.search_wrench` at ``pose``, within the arm's joint-torque box there.

        The box's rows cost a solve about a quarter more (2.8 against 2.3 ms on box-3-2-1-arm6,
        ``benchmarks/bench_robot.py``; following the arm and building its box 0.2 ms): while
        the last push left the joints inside the headroom, the push is first sought without them,
        and kept when it is inside too (where the arm does not bind, the same push); otherwise,
        and from then on while the box binds, it is sought within the box.
        """
        from fixplan.jamming.search import search_wrench

        boxes = self._arm_boxes(t, pose)
        if boxes and not self._box_binds:
            res = search_wrench(self.fixture, motion, contacts, pose=pose, settings=self.profile, **options)
            if res.found and res.wrench is not None:
                ratio = float(np.max(boxes[0].ratios(res.wrench, pose.p_world)))
                if ratio <= self.limit_fraction:
                    return res
            self._box_binds = True
        res = search_wrench(
            self.fixture, motion, contacts, pose=pose, hand_sets=boxes, settings=self.profile, **options
        )
        if boxes and res.found and res.arm_torque_ratio is not None:
            self._box_binds = res.arm_torque_ratio >= self.settings.box_binds_fraction * self.limit_fraction
        return res

    def _arm_boxes(self, t: float | None, pose: Pose) -> tuple[TorqueBox, ...]:
        """The arm's joint-torque box at ``pose`` for the search (none without an arm, or where it does not reach)."""
        self._box = None
        if self._arm is None:
            return ()
        self._box = self._arm.torque_box(pose, "the part's pose" + ("" if t is None else f" at t = {t:.3f} s"))
        self._box_about = pose.p_world
        if self._box is None:
            self.log.arm_unreached_solves += 1
            return ()
        return (self._box,)

    def _accept(self, w: FloatArray) -> None:
        self.wrench = np.asarray(w, dtype=float).copy()
        if self._box is not None and self.log.max_arm_torque_ratio is not None:
            ratio = float(np.max(self._box.ratios(self.wrench, self._box_about)))
            self.log.max_arm_torque_ratio = max(self.log.max_arm_torque_ratio, ratio)
        d = self.fixture.dimension
        self.log.max_command_force_N = max(self.log.max_command_force_N, float(np.linalg.norm(w[:d])))
        self.log.max_command_torque_Nm = max(self.log.max_command_torque_Nm, float(np.linalg.norm(w[d:])))
        self._last_reason = ""

    def _reject(self, t: float, reason: str) -> None:
        self.log.counts["failed_solves"] += 1
        self._last_reason = reason


def _goal_normals_body(fixture: Fixture) -> dict[str, FloatArray]:
    """Each locator's contact normal at the goal, in the part's frame (flat-faced parts only, else empty).

    A round part's normal turns with the part about its axis (a cylinder turned 60° in its
    V-block is still located): only boxes, rectangles and polygons have faces to be wrong about.
    """
    from fixplan.geometry import Box, Polygon, Rectangle

    shape = fixture.workpiece.shape
    goal = fixture.goal_pose
    if goal is None or not isinstance(shape, Box | Rectangle | Polygon):
        return {}
    return {
        loc.name: np.asarray(shape.project(goal.point_body_from_world(loc.p_world)).normal_body, dtype=float)
        for loc in fixture.locators
    }


__all__ = [
    "FAILURE_KINDS",
    "ExecutionLog",
    "ExecutionNoise",
    "ExecutionSettings",
    "Executor",
    "Step",
    "mass_speed",
    "origin_motion",
    "project_keeping",
]
