"""``fixplan solve``: plan the loading of a full fixture, then verify the plan in the haptic loop.

1. The start state is the set of locators touching at the start pose.
2. The coarse search (:mod:`.coarse`) adds one locator per transition (a group of them where
   geometry closes them at the same instant: :func:`~.fine.closing_group`), pricing each with a fine
   plan (:mod:`.fine`: CasADi path + non-jamming wrench per segment); the cost is the
   mass-weighted path length plus a penalty on thin margins.
3. Unless ``verify=False``, the chosen plan is run through the simulated haptic loop
   (:mod:`.verify`): contact states, stalls, final gaps and penetration are checked.

Transition durations for the verification are ``T = 0.15 s + 2 √(L / a)`` for a path of length
``L`` at the planned acceleration ``a`` (accelerate half-way, decelerate half-way).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, cast

import numpy as np

from fixplan.contact_state import format_state
from fixplan.errors import InputError, SolverError
from fixplan.locating import contact_set, solve_goal
from fixplan.locating import start_state as locating_start_state
from fixplan.model import Fixture, require_full
from fixplan.planner.approach import Approach, plan_approach
from fixplan.planner.coarse import Attempt, CoarsePlan, search
from fixplan.planner.execute import Step, TransitionKind
from fixplan.planner.fine import (
    IPOPT_PATH_FOUND,
    LADDER,
    GoalRows,
    Transition,
    closing_group,
    default_kind,
    goal_rows,
    plan_transition,
    with_wrenches,
)
from fixplan.planner.plan_types import Plan, PlannedTransition, TriedTransition
from fixplan.planner.policy import Policy, build_policy
from fixplan.planner.policy_job import PendingPolicy
from fixplan.planner.segments import segment_wrenches
from fixplan.planner.spare import SpareCore
from fixplan.planner.verify import Verification, verify
from fixplan.settings import DEFAULT, HAPTIC, Settings
from fixplan.spatial import Pose

PlanStatus = Literal["planned", "unverified", "infeasible"]


@dataclass
class PlanResult:
    """A plan (or the reason there is none), its verification and timings."""

    status: PlanStatus  # "planned" (verified) | "unverified" | "infeasible"
    reason: str
    sequence: list[tuple[str, ...]]
    transitions: list[Transition]
    attempts: list[Attempt]
    verification: Verification | None
    durations_s: list[float]
    timings: dict[str, float] = field(default_factory=dict)
    friction_robustness: list[float] = field(default_factory=list)  # per transition: largest δ of planner.robust_grid
    policy: Policy | None = None  # the next transition from every contact state (planner/policy.py)
    # the hand's force [N] and torque [N·m] limits the pushes were planned within (the search's,
    # with its defaults when the file has none); None: not known
    hand_limits: tuple[float, float] | None = None
    robot: Any = None  # fixplan.robot.RobotReport: the fixture's [robot] along the plan (None: no robot)
    # pins or bores: the staged insertion (planner.insertion.InsertionPlan); its plan file's ``insertion`` key
    insertion: Any = None

    @property
    def ok(self) -> bool:
        return self.status == "planned"

    @property
    def certificate(self) -> list[Attempt]:
        """For ``infeasible``: the failed transitions that the wrench search certifies.

        Each proves that no push within the hand's limits moves the part as needed (``too weak``,
        or every such push jams).
        """
        return [a for a in self.attempts if not a.success and a.stage == "fine" and _wrench_certificate(a.reason)]

    @property
    def proven(self) -> bool | None:
        """Whether an ``infeasible`` result is proven (``None`` for other statuses).

        Proven: every blocking transition is certified by its wrench search, none is only a path
        the NLP did not find.
        """
        if self.status != "infeasible":
            return None
        failed = [a for a in self.attempts if not a.success and a.stage == "fine"]
        return bool(failed) and all(_wrench_certificate(a.reason) for a in failed)

    @property
    def plan(self) -> Plan:
        """The plan as :class:`~fixplan.planner.plan.Plan` (what ``fixplan solve --out`` writes)."""
        transitions = []
        robust: list[float | None] = list(self.friction_robustness) or [None] * len(self.transitions)
        for tr, T, rob in zip(self.transitions, self.durations_s, robust, strict=True):
            rows = tr.wrenches[np.isfinite(tr.wrenches).all(axis=1)] if len(tr.wrenches) else tr.wrenches
            margins = tr.margins_N[np.isfinite(tr.margins_N)]
            peak_F, peak_T = _peak_fractions(rows, self.hand_limits)
            transitions.append(
                PlannedTransition(
                    from_state=tuple(tr.established),
                    to_state=tuple(sorted([*tr.established, *tr.added])),
                    added=tr.target,
                    together=tuple(tr.together),
                    motion=tr.kind if tr.established else "free",
                    wrench=rows.mean(axis=0) if len(rows) else None,
                    # the least normal force on the kept contacts; None from no contact (nothing to press)
                    margin_N=float(np.min(margins)) if len(margins) else None,
                    friction_robustness=None if rob is None or not math.isfinite(rob) else float(rob),
                    time_s=T,
                    path_length_m=float(tr.cost),
                    max_constraint_violation_m=float(tr.max_constraint_violation_m),
                    solve_time_s=float(tr.solve_time_s),
                    poses=tuple(tr.poses),
                    segment_wrenches=np.atleast_2d(np.asarray(tr.wrenches, dtype=float)),
                    kind=tr.kind,
                    peak_force_fraction=peak_F,
                    peak_torque_fraction=peak_T,
                )
            )
        infeasible = self.status == "infeasible"
        return Plan(
            status=self.status,
            reason=self.reason,
            sequence=tuple(tuple(s) for s in self.sequence),
            transitions=tuple(transitions),
            tried=tuple(
                TriedTransition(tuple(a.established), a.target, a.success, a.reason, a.stage, a.together)
                for a in self.attempts
            ),
            proven=self.proven,
            certificate=tuple(
                TriedTransition(tuple(a.established), a.target, False, a.reason, together=a.together)
                for a in self.certificate
            )
            if infeasible
            else (),
            verification=self.verification,
            timings=dict(self.timings),
            policy=self.policy,
            extras=self._extras(),
        )

    def _extras(self) -> dict[str, Any]:
        """The plan's keys beyond a plan of locators': ``robot``; with pins or bores, ``insertion`` (what verify re-runs)."""
        extras: dict[str, Any] = {} if self.robot is None else {"robot": self.robot.to_json()}
        if self.insertion is not None:
            from fixplan.planner.insertion_file import insertion_json

            written = insertion_json(self.insertion)
            if written is not None:
                extras["insertion"] = written
        return extras

    def to_json(self) -> dict[str, Any]:
        return self.plan.to_json()


def _peak_fractions(rows: np.ndarray, limits: tuple[float, float] | None) -> tuple[float | None, float | None]:
    """The largest planned ‖F‖ / max_force and ‖T‖ / max_torque over a transition's segment pushes."""
    if limits is None or not len(rows):
        return None, None
    d = 3 if rows.shape[1] == 6 else 2
    F_max, T_max = limits
    return (
        float(np.max(np.linalg.norm(rows[:, :d], axis=1))) / F_max,
        float(np.max(np.linalg.norm(rows[:, d:], axis=1))) / T_max,
    )


def _wrench_certificate(reason: str) -> bool:
    """A transition's failure that the wrench search proves (not the path NLP's failure)."""
    return "too weak" in reason or "jams" in reason


def _duration(tr: Transition, acceleration_mps2: float) -> float:
    length = float(tr.cost) if math.isfinite(tr.cost) else 0.0
    return 0.15 + 2.0 * math.sqrt(max(length, 0.0) / acceleration_mps2)


def plan_steps(transitions: Sequence[Transition]) -> list[Step]:
    """The executor's policy from the fine plans: target, motion and guide path per transition."""
    return [
        Step(
            tuple(tr.established),
            tr.target,
            cast(TransitionKind, tr.kind) if tr.established else "free",
            tuple(tr.poses),
            tuple(tr.together),
        )
        for tr in transitions
    ]


def friction_robustness(
    fixture: Fixture,
    tr: Transition,
    acceleration_mps2: float,
    margin_N: float | None,
    grid: Sequence[float] | None = None,
    settings: Settings = DEFAULT,
) -> float:
    """The largest δ of ``grid`` for which the first segment's push survives friction ``μ(1 ± δ)``.

    ``grid`` defaults to ``settings.planner.robust_grid``; the pushes are searched with ``settings``
    (:func:`solve` passes its own).

    The push must move the part as planned within the hand's limits; 0 when only the nominal μ
    allows it, ``inf`` for a transition from no contact (nothing to slip).
    """
    if not tr.established or len(tr.poses) < 2:
        return float("inf")
    best = 0.0
    for delta in settings.planner.robust_grid if grid is None else grid:
        _, _, found, _ = segment_wrenches(
            fixture, tr.poses[:2], tuple(tr.established), tr.kind, acceleration_mps2,
            friction_margin=delta, margin_N=margin_N, settings=settings,
        )  # fmt: skip
        if not found[0]:
            break
        best = delta
    return best


class Planner:
    """Coarse search with fine plans from any (pose, contact state); also the executor's re-planner."""

    def __init__(
        self,
        fixture: Fixture,
        *,
        knots: int = 10,
        settings: Settings = DEFAULT,
        progress: Callable[[Attempt], None] | None = None,
    ):
        """The planner of ``fixture``.

        ``settings`` give its thresholds (``planner``, ``policy``), the pushes' acceleration, normal-force
        margin and friction margin (``execution``: ``accel_mps2``, ``margin_N``,
        ``friction_margin``; the executor's own) and what the pushes' searches keep to (``search``,
        ``witness``, ``numerics``).
        """
        self.fixture = fixture
        self.names = [loc.name for loc in fixture.locators]
        self.knots = knots
        self.settings = settings
        ex = settings.execution
        self.acceleration_mps2 = ex.accel_mps2
        self.friction_margin = ex.friction_margin
        self.margin_N = ex.margin_N
        self.progress = progress
        self.fine_time_s = 0.0
        self.prechecks = 0  # cheap checks run before fine plans, and how many failed
        self.precheck_failures = 0
        # transitions set aside because their simulated load failed: (state, target) → why
        self.set_aside: dict[tuple[frozenset[str], str], str] = {}
        # fine plans by (state, target, start pose): a search after a transition was set aside
        # reuses every fine plan that starts where an earlier one did
        self._cache: dict[tuple[tuple[str, ...], str, bytes, bool], Transition] = {}
        # guesses and prechecks by (state, target, pose): pure functions of them, asked again by
        # every round of the lazy search, by its second pass and by every search after a set-aside
        self._guesses: dict[tuple[tuple[str, ...], str, bytes], tuple[float, Pose, str] | None] = {}
        self._prechecked: dict[tuple[tuple[str, ...], str, bytes], str | None] = {}
        # the policy's representative poses and checked pushes (see policy.build_policy)
        self.policy_memo: dict[tuple[Any, ...], Any] = {}
        self.full_ladder = False  # the fine planner's whole ladder of formulations (second pass)
        # the rank test of closing_group, on the goal's normal rows (built once; None: no goal)
        self._rows: GoalRows | None = goal_rows(fixture)
        self._groups: dict[tuple[frozenset[str], str], tuple[str, ...]] = {}

    def avoid(self, state: frozenset[str], target: str, why: str) -> None:
        """Set the transition ``state → target`` aside for the plans to come (the executor saw it fail)."""
        self.set_aside[(frozenset(state), target)] = why

    def group(self, state: frozenset[str], target: str) -> tuple[str, ...]:
        """The locators that touch at the same instant as ``target`` from ``state`` (sorted, with it).

        :func:`~fixplan.planner.fine.closing_group` on the goal's normal rows: ``(target,)`` unless
        the layout is redundant there (two end locators that the seated base moves alike).
        """
        key = (frozenset(state), target)
        if key not in self._groups:
            self._groups[key] = (
                (target,) if self._rows is None else closing_group(self.fixture, sorted(state), target, self._rows)
            )
        return self._groups[key]

    def plan_from(self, pose: Pose, state: frozenset[str], order: Sequence[str] | None = None) -> CoarsePlan:
        """The cheapest monotone sequence from ``state`` at ``pose`` to every locator.

        The fine plans and the confirmations the search will likely ask for next run ahead on the
        second core (:class:`~fixplan.planner.spare.SpareCore`): the same answers, sooner.
        """
        cache = self._cache
        spare = SpareCore(self._spare_job)
        upcoming: list[tuple[Pose, frozenset[str], str, Any]] = []

        def evaluate(pose_: Pose, state_: frozenset[str], target: str) -> Transition:
            key = (tuple(sorted(state_)), target, _pose_key(pose_), self.full_ladder)
            # set aside first: a transition the executor saw fail must not come back from the cache
            # (a re-plan from free space reached the same state at the same pose, took the cached
            # transition, met the same wrong face and was lifted off again, six times in 17 s)
            why = self.set_aside.get((frozenset(state_), target))
            if why is not None:
                return _set_aside(self.fixture, pose_, state_, target, why)
            plain = cache.get((*key[:3], False))
            if plain is not None and plain.success:
                return plain  # the second pass keeps what the plain program found
            if key not in cache:
                t = time.perf_counter()
                found, tr = spare.take(("fine", key))
                if not found:
                    self._offer_sibling(spare, pose_, state_, target)
                    tr = self._fine(pose_, state_, target, self.full_ladder)
                cache[key] = tr
                self.fine_time_s += time.perf_counter() - t
            return cache[key]

        def confirm(pose_: Pose, state_: frozenset[str], target: str, tr: Transition) -> Transition:
            """The pushes along a priced path (only for the transitions of a chosen sequence)."""
            key = (tuple(sorted(state_)), target, _pose_key(pose_), self.full_ladder)
            t = time.perf_counter()
            found, done = spare.take(("confirm", key))
            if not found:
                # the next transition of the sequence on the second core meanwhile
                later = [u for u in upcoming if u[3] is not tr and not getattr(u[3], "wrenches_checked", True)]
                if later:
                    p_, s_, t_, tr_ = later[0]
                    k_ = (tuple(sorted(s_)), t_, _pose_key(p_), self.full_ladder)
                    spare.offer(("confirm", k_), ("confirm", p_, s_, t_, tr_))
                done = self._confirm(tr)
            if upcoming and upcoming[0][3] is tr:
                upcoming.pop(0)
            self.fine_time_s += time.perf_counter() - t
            for k in (key, (*key[:3], not self.full_ladder)):
                if cache.get(k) is tr:
                    cache[k] = done
            return done

        def upcoming_set(todo: Sequence[tuple[Pose, frozenset[str], str, Any]]) -> None:
            upcoming[:] = list(todo)

        # first the plain program for every transition; only when no sequence is found that way,
        # the whole ladder (other guesses, the other kind, a waypoint, ...) and the diagnosis of
        # what blocks each transition that still fails
        self.full_ladder = False
        try:
            first = search(
                state, self.names, pose, evaluate, order=order, progress=self.progress,
                estimate=self.estimate, precheck=self.precheck, group=self.group, confirm=confirm,
                upcoming=upcoming_set, settings=self.settings.planner,
            )  # fmt: skip
            if first.found:
                return first
            self.full_ladder = True
            try:
                second = search(
                    state, self.names, pose, evaluate, order=order, progress=self.progress,
                    estimate=self.estimate, precheck=self.precheck, group=self.group, confirm=confirm,
                    upcoming=upcoming_set, settings=self.settings.planner,
                )  # fmt: skip
            finally:
                self.full_ladder = False
        finally:
            spare.close()
        second.attempts = [*first.attempts, *(a for a in second.attempts if a not in first.attempts)]
        return second

    def _fine(self, pose: Pose, state: frozenset[str], target: str, full_ladder: bool) -> Transition:
        """The fine plan of ``state → target`` from ``pose``, priced by its path (no pushes yet)."""
        # the kind of motion whose first-order step closes the target (rolling on two contacts
        # in 3D leaves one rotation, which often cannot)
        g = self.guess(pose, state, target) if state else None
        kind = None if g is None else g[2]
        if full_ladder and kind == default_kind(self.fixture.dimension, len(state)):
            kind = None  # the ladder may then try the other kind too
        clearances_m = self.settings.planner.clearances_m
        for i, clearance in enumerate(clearances_m):
            # the ladder of formulations and the diagnosis at the last clearance, and only in the
            # second pass (a failing transition costs 2-9 s with them)
            last = i == len(clearances_m) - 1
            full = full_ladder and last
            tr = plan_transition(
                self.fixture, pose, sorted(state), target, knots=self.knots,
                acceleration_mps2=self.acceleration_mps2, friction_margin=self.friction_margin,
                margin_N=self.margin_N, clearance_m=clearance, kind=kind, settings=self.settings.planner,
                profile=self.settings, ladder=LADDER if full else LADDER[:1], diagnose=full,
                together=[n for n in self.group(state, target) if n != target],
                wrenches=False,
            )  # fmt: skip
            if last or tr.ipopt_status in IPOPT_PATH_FOUND:
                return tr  # a path: its wrenches decide, not the clearance
        raise SolverError("no clearance to plan a transition at (settings planner.clearances_m is empty)")

    def _confirm(self, tr: Transition) -> Transition:
        """A priced transition with the pushes along its path searched."""
        return with_wrenches(
            self.fixture, tr, acceleration_mps2=self.acceleration_mps2, friction_margin=self.friction_margin,
            margin_N=self.margin_N, plain=LADDER[0].name, settings=self.settings,
        )  # fmt: skip

    def _spare_job(self, job: tuple[Any, ...]) -> Transition:
        """A job of :meth:`plan_from`'s second core (run in its child)."""
        if job[0] == "fine":
            return self._fine(*job[1:])
        return self._confirm(job[4])

    def _offer_sibling(self, spare: SpareCore, pose: Pose, state: frozenset[str], target: str) -> None:
        """Start the second core on the likeliest next fine plan: another target from ``state`` at ``pose``.

        The lazy search asks for a sibling next when this transition turns out dearer than its
        estimate; the cheapest estimate among the targets it may ask for (one per closing group)
        comes first. Nothing when the core is busy or absent.
        """
        if not spare.active:
            return
        est, pk = tuple(sorted(state)), _pose_key(pose)
        options = []
        for other in self.names:
            if other in state or other == target or min(self.group(state, other)) != other:
                continue
            key = (est, other, pk, self.full_ladder)
            plain = self._cache.get((*key[:3], False))
            if key in self._cache or (plain is not None and plain.success):
                continue
            if (frozenset(state), other) in self.set_aside or spare.pending(("fine", key)):
                continue
            guess = self.estimate(pose, state, other)
            if guess is not None:
                options.append((guess[0], other, key))
        if options:
            _, other, key = min(options)
            spare.offer(("fine", key), ("fine", pose, state, other, self.full_ladder))

    def guess(self, pose: Pose, state: frozenset[str], target: str) -> tuple[float, Pose, str] | None:
        """A cheap guess of a transition: (mass-weighted length [m], end pose, kind of motion).

        The least-``M``-norm step that closes the target's gap keeping the established contacts,
        to first order, in the fine planner's kind of motion (rolling keeps every row of the kept
        contacts, sliding their normal rows); the other kind when that one cannot close the gap.
        No IPOPT, no cone program. Remembered per (state, target, pose).
        """
        from fixplan.planner.policy import gap_closing_step, motion_kinds

        key = (tuple(sorted(state)), target, _pose_key(pose))
        if key in self._guesses:
            return self._guesses[key]
        found: tuple[float, Pose, str] | None = None
        for kind in motion_kinds(self.fixture.dimension, len(state)):
            step = gap_closing_step(self.fixture, pose, state, target, kind, self.settings.planner)
            if step is not None:
                found = (step[0], step[1], kind)
                break
        self._guesses[key] = found
        return found

    def estimate(self, pose: Pose, state: frozenset[str], target: str) -> tuple[float, Pose] | None:
        """The lazy search's estimate: :meth:`guess` without its kind."""
        g = self.guess(pose, state, target)
        return None if g is None else (g[0], g[1])

    def precheck(self, pose: Pose, state: frozenset[str], target: str) -> str | None:
        """A cheap necessary check before a transition's fine plan (one cone program, no IPOPT).

        Is there a non-jamming push, within the hand's limits, for the first segment of the
        :meth:`guess` step at ``pose``, in the guess's kind of motion? None when there is (or
        nothing to check: no kept contact), else the search's reason. The fine plan may still find
        another way (its path bends), so the lazy search only tries such a transition later; it
        never drops it. Remembered per (state, target, pose).
        """
        if not state:
            return None
        guess = self.guess(pose, state, target)
        if guess is None:
            return None
        est = tuple(sorted(state))
        key = (est, target, _pose_key(pose))
        if key in self._prechecked:
            return self._prechecked[key]
        self.prechecks += 1
        _, _, found, reasons = segment_wrenches(
            self.fixture, [pose, guess[1]], est, guess[2],
            self.acceleration_mps2, friction_margin=self.friction_margin, margin_N=self.margin_N,
            settings=self.settings,
        )  # fmt: skip
        why = None
        if not found[0]:
            self.precheck_failures += 1
            why = reasons[0] if reasons else "no non-jamming push for the first step"
        self._prechecked[key] = why
        return why

    def replan(self, pose: Pose, state: frozenset[str]) -> list[Step] | str:
        """The executor's guard: a new policy from the observed state, or why there is none."""
        if state == frozenset(self.names):
            return []
        fx = self.fixture
        # the observed contacts touch within the sensor's tolerance; the planner wants them exact:
        # the nearest pose (least-squares steps) where they do
        start = pose
        if state:  # a part touching nothing (knocked free) is planned from where it is
            settled = solve_goal(
                fx.workpiece, [fx.locator(n) for n in sorted(state)], pose, tol_m=self.settings.planner.settle_tol_m
            )
            if not settled.converged:
                return f"no pose near the observed one keeps {format_state(state, empty='{}')} touching"
            start = settled.pose
        # a part knocked free (or lifted off a locator it pressed on the wrong face) is first carried
        # to the staging pose, as a free start is: its first contacts are then the planned ones
        approach = None
        if not state and fx.goal_pose is not None:
            from dataclasses import replace

            approach = plan_approach(replace(fx, start=pose), self.settings.policy)
            if approach is not None:
                start = approach.staging
        try:
            coarse = self.plan_from(start, state)
        except InputError as exc:
            return str(exc)
        if not coarse.found:
            return coarse.reason
        transitions = list(coarse.transitions)
        if approach is not None and transitions:
            transitions[0] = with_approach(fx, transitions[0], approach)
        return plan_steps(transitions)


def with_approach(fixture: Fixture, tr: Transition, approach: Approach) -> Transition:
    """The first (free) transition with the approach path from the start in front of it.

    The approach's segments are free flight carrying the part: the push holds it against gravity.
    """
    from dataclasses import replace

    from fixplan.jamming.push import free_wrench

    extra = len(approach.poses) - 1
    mid = approach.poses[len(approach.poses) // 2]
    M = contact_set(fixture, mid, []).mass_matrix
    _, hold, _ = free_wrench(fixture, mid, np.zeros(fixture.ndof), M)
    wrenches = np.vstack([np.tile(hold, (extra, 1)), tr.wrenches]) if len(tr.wrenches) else tr.wrenches
    return replace(
        tr,
        poses=[*approach.poses[:-1], *tr.poses],
        wrenches=wrenches,
        margins_N=np.concatenate([np.full(extra, np.nan), tr.margins_N]),
        found=np.concatenate([np.ones(extra, dtype=bool), tr.found]),
        segment_reasons=["free approach to the staging pose"] * extra + list(tr.segment_reasons),
        cost=float(tr.cost) + approach.length_m,
        reason=f"approach to the staging pose ({'via a waypoint, ' if approach.via_waypoint else ''}"
        f"least gap {approach.least_gap_m:.3g} m), then {tr.reason}",
    )


def _pose_key(pose: Pose) -> bytes:
    return pose.p_world.tobytes() + np.asarray(pose.R_world_body).tobytes()


def _set_aside(fixture: Fixture, pose: Pose, state: frozenset[str], target: str, why: str) -> Transition:
    """A transition the search must not take again: its simulated load failed."""
    K, nv = 1, fixture.ndof
    est = tuple(sorted(state))
    return Transition(
        est, target, default_kind(fixture.dimension, len(est)), [pose], np.full((K, nv), np.nan), np.full(K, np.nan),
        False, f"set aside: the simulated load of a plan through it failed ({why})", 0.0, 0.0, "not run",
    )  # fmt: skip


def failed_transition(transitions: Sequence[Transition], observed: Sequence[Sequence[str]]) -> int:
    """The index of the first planned transition whose end state the simulated load never reached."""
    seen = {frozenset(s) for s in observed}
    for i, tr in enumerate(transitions):
        if frozenset(tr.established) | set(tr.added) not in seen:
            return i
    return len(transitions) - 1


def solve(
    fixture: Fixture,
    *,
    order: Sequence[str] | None = None,
    run_verification: bool = True,
    settings: Settings = HAPTIC,
    knots: int = 10,
    progress: Callable[[Attempt], None] | None = None,
    verify_options: dict[str, Any] | None = None,
) -> PlanResult:
    """Plan (and by default verify) the loading of ``fixture``.

    ``settings`` (default: the ``haptic`` profile, whose planning thresholds are the default
    ones: the verification runs the haptic loop) give the planner's thresholds and, in
    ``settings.execution``, the acceleration each push asks for (``accel_mps2``), the least normal
    force on the kept contacts (``margin_N``; default: the part's weight) and the δ the pushes are
    robust to (``friction_margin``: friction anywhere in ``μ(1 ± δ)``); the executor uses the same.
    ``knots`` per transition: 10 by default — on the default box the exact gaps between knots
    stay within 1e-17 m at 10 as at 20 (``benchmarks/bench_planner.py``) for half the time.
    ``verify_options`` are passed to :func:`~fixplan.planner.verify.verify` (e.g. ``max_sweeps``,
    ``noise``).
    """
    vopts = dict(verify_options or {})
    if fixture.has_pins:  # pins and bores: the staged insertion (planner/insertion.py)
        return solve_insertion(fixture, run_verification=run_verification, settings=settings, verify_options=vopts)
    require_full(fixture, "planning")
    arm_limits = None
    if fixture.robot is not None:
        # the hand's limits stay the fixture's: every push is searched within the arm's own set,
        # its joint-torque box at the pose (the fine planner at both knots of each segment, the
        # executor at the part's pose every solve). The ball of pushes inscribed in that set at the
        # start and goal is only reported (robot.hand_limits): cutting the limits to it refused
        # pushes the arm exerts (an arm whose weight alone loads a joint beyond its effort has an
        # empty ball, yet carries the part by pressing it down)
        arm_limits = _with_arm_limits(fixture)[1]
    if order is not None:
        _check_order(fixture, order)
    t0 = time.perf_counter()
    names = [loc.name for loc in fixture.locators]
    start_state = locating_start_state(fixture)
    acceleration_mps2, margin_N = settings.execution.accel_mps2, settings.execution.margin_N
    planner = Planner(fixture, knots=knots, settings=settings, progress=progress)
    replan = planner.replan
    if start_state == frozenset(names):
        # already located: nothing to plan; verification checks that the part stays there
        verification = (
            verify(fixture, start_state, [], settings=settings, replan=replan, **vopts) if run_verification else None
        )
        timings = {"plan_s": 0.0, "fine_s": 0.0, "total_s": time.perf_counter() - t0}
        status, reason = _status(verification, "already located at the start pose: every locator touches")
        return PlanResult(status, reason, [tuple(sorted(names))], [], [], verification, [], timings)
    approach = plan_approach(fixture, settings.policy) if not start_state and fixture.goal_pose is not None else None
    begin = approach.staging if approach is not None else fixture.start
    coarse = planner.plan_from(begin, start_state, order)
    t_plan = time.perf_counter() - t0
    timings = {"plan_s": t_plan, "fine_s": planner.fine_time_s}
    if not coarse.found:
        timings["total_s"] = time.perf_counter() - t0
        return PlanResult("infeasible", coarse.reason, [], [], coarse.attempts, None, [], timings)
    attempts = list(coarse.attempts)
    first: PlanResult | None = None
    budget = max(settings.policy.max_verifications, 1) if run_verification else 1
    for round_ in range(budget):
        transitions = list(coarse.transitions)
        if approach is not None and transitions:
            transitions[0] = with_approach(fixture, transitions[0], approach)
        durations = [_duration(tr, acceleration_mps2) for tr in transitions]
        robustness = [
            friction_robustness(fixture, tr, acceleration_mps2, margin_N, settings.planner.robust_grid, settings)
            for tr in transitions
        ]
        # the policy is built on the second core while the simulated load runs (policy_job's text)
        pending = PendingPolicy(
            functools.partial(_policy_and_memo, fixture, planner, start_state, transitions),
            fork=None if run_verification else False,
            in_child=functools.partial(setattr, planner, "progress", None),
        )
        verification = None
        if run_verification:
            t1 = time.perf_counter()
            verification = verify(
                fixture, start_state, plan_steps(transitions), settings=settings, replan=replan,
                policy=pending,  # type: ignore[arg-type]
                avoid=planner.avoid, **vopts,
            )  # fmt: skip
            timings["verify_s"] = timings.get("verify_s", 0.0) + time.perf_counter() - t1
        policy = pending.result()
        if pending.started_in_child:
            planner.policy_memo.update(pending.memo)  # the child's memo, for a rebuild after a set-aside
        timings["policy_s"] = timings.get("policy_s", 0.0) + policy.build_time_s
        status, reason = _status(verification, "")
        if round_:
            reason = (
                reason + "; " if reason else ""
            ) + f"sequence {round_ + 1} tried after the simulated load of the first failed"
        result = PlanResult(
            status, reason, coarse.sequence, transitions, attempts, verification, durations, timings, robustness, policy
        )
        if first is None:
            first = result
        if status != "unverified" or verification is None or order is not None or round_ + 1 >= budget:
            break
        # the simulated load failed: set the transition where it failed aside, try the next-best sequence
        i = failed_transition(transitions, verification.observed_sequence)
        tr = transitions[i]
        planner.set_aside[(frozenset(tr.established), tr.target)] = verification.reason
        coarse = planner.plan_from(begin, start_state, order)
        attempts += [a for a in coarse.attempts if a not in attempts]
        if not coarse.found:
            break
    if first is not None and not result.ok and result is not first:
        # no other sequence verified either: report the first (best) one's failure
        result = first
        result.reason += "; the next-best sequences failed too"
    result.attempts = attempts
    result.hand_limits = _hand_limits(fixture)
    if fixture.robot is not None and result.transitions:
        _check_robot(fixture, result, timings, arm_limits)
    timings["fine_s"] = planner.fine_time_s
    timings["total_s"] = time.perf_counter() - t0
    result.timings = timings
    return result


def solve_insertion(
    fixture: Fixture,
    *,
    run_verification: bool = True,
    settings: Settings = HAPTIC,
    verify_options: dict[str, Any] | None = None,
) -> PlanResult:
    """Plan (and by default verify) the insertion of a part onto its pins or into its bore (:mod:`.insertion`).

    ``infeasible`` with the reason (the pin named) when no staged plan exists; ``planned`` when the
    haptic loop confirms it, else ``unverified`` with where and why.
    """
    from fixplan.planner.insertion import plan_insertion, transitions_of, verify_insertion

    t0 = time.perf_counter()
    vopts = {k: v for k, v in (verify_options or {}).items() if k in ("noise", "max_sweeps", "final_gap_m",
                                                                      "max_penetration_m", "trace_every_s")}  # fmt: skip
    plan = plan_insertion(fixture, settings)
    timings = {"plan_s": plan.plan_s, "fine_s": 0.0}
    hand = _hand_limits(fixture)
    if not plan.ok:
        timings["total_s"] = time.perf_counter() - t0
        return PlanResult("infeasible", plan.reason, [], [], [], None, [], timings, hand_limits=hand, insertion=plan)
    transitions = transitions_of(fixture, plan)
    durations = [_duration(tr, 1.0) for tr in transitions]  # the guide at the default 1 m/s² (the run servos it)
    verification = None
    if run_verification:
        t1 = time.perf_counter()
        verification = verify_insertion(fixture, plan, settings=settings, **vopts)
        timings["verify_s"] = time.perf_counter() - t1
    status, reason = _status(verification, plan.reason)
    if status == "planned":
        reason = plan.reason
        ex = verification.execution if verification is not None else None
        retries = ex.counts["retries"] if ex is not None else 0
        if retries:  # the run stalled and recovered by its policy (planner/insertion_policy.py)
            reason += f"; verified after {retries} retr{'ies' if retries != 1 else 'y'} by the insertion's policy"
    timings["total_s"] = time.perf_counter() - t0
    sequence = [tuple(sorted(s)) for s in plan.states]
    return PlanResult(status, reason, sequence, transitions, [], verification, durations, timings,
                      [math.inf] * len(transitions), hand_limits=hand, insertion=plan)  # fmt: skip


def _with_arm_limits(fixture: Fixture) -> tuple[Fixture, Any]:
    """The fixture with its hand limits cut to the ball of pushes its arm exerts at the start and goal.

    (:func:`fixplan.robot.check.arm_hand_limits`.) :func:`solve` reports the cut (``robot.hand_limits``)
    and plans with the fixture's own limits and the arm's joint-torque boxes.
    """
    from dataclasses import replace

    from fixplan.model import Manipulator
    from fixplan.robot.check import arm_hand_limits

    F_max, T_max, _ = fixture.hand_limits()
    limits = arm_hand_limits(fixture, F_max, T_max)
    if limits is None or limits.scale >= 1.0:
        return fixture, limits
    return replace(fixture, manipulator=Manipulator(limits.max_force_N, limits.max_torque_Nm)), limits


def _check_robot(fixture: Fixture, result: PlanResult, timings: dict[str, float], arm_limits: Any = None) -> None:
    """The fixture's arm along the plan (:func:`fixplan.robot.check_plan`): infeasible when it cannot carry it out."""
    from fixplan.robot import check_plan

    t = time.perf_counter()
    report = check_plan(fixture, result.plan)
    report.hand_limits = arm_limits
    timings["robot_s"] = time.perf_counter() - t
    result.robot = report
    if not report.feasible and result.status != "infeasible":
        result.status = "infeasible"
        result.reason = f"the robot cannot carry the plan out: {report.reason}"


def _policy_and_memo(
    fixture: Fixture, planner: Planner, start_state: frozenset[str], transitions: Sequence[Transition]
) -> tuple[Policy, dict[Any, Any]]:
    """The policy of the plan and the planner's memo after it (what a forked build sends back)."""
    return build_policy(fixture, planner, start_state, transitions), planner.policy_memo


def _hand_limits(fixture: Fixture) -> tuple[float, float]:

    F_max, T_max, _ = fixture.hand_limits()
    return F_max, T_max


def _status(verification: Verification | None, note: str) -> tuple[PlanStatus, str]:
    """``planned`` only when the loop confirmed the plan; else ``unverified`` with where and why."""
    if verification is None:
        return (
            "unverified",
            "verification skipped (solve.run_verification=False): the sequence was not run in the haptic loop",
        )
    if verification.passed:
        ex = verification.execution
        replans = ex.counts["replans"] if ex is not None else 0
        extra = f"; verified after {replans} re-plan{'s' if replans != 1 else ''}" if replans else ""
        return "planned", (note + extra).lstrip("; ")
    return "unverified", f"verification failed: {verification.reason}"


def _check_order(fixture: Fixture, order: Sequence[str]) -> None:
    names = [loc.name for loc in fixture.locators]
    extra = [n for n in order if n not in names]
    if extra:
        raise InputError(f"solve.order names unknown locators: {', '.join(extra)} (known: {', '.join(names)})")
    if len(set(order)) != len(order):
        raise InputError(f"solve.order repeats a locator: {','.join(order)}")
