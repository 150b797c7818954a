"""``fixplan solve``: plan the loading of a full fixture, then verify the plan in the haptic loop.

1. The start state is the set of locators touching at the start pose.
2. The coarse search (:mod:`.coarse`) adds one locator per transition, pricing each with a fine
   plan (:mod:`.fine`: CasADi path + non-jamming wrench per segment); the cost is the
   mass-weighted path length plus a penalty on thin margins.
3. Unless ``verify=False``, the chosen plan is run through the simulated haptic loop
   (:mod:`.verify`): contact states, stalls, final gaps and penetration are checked.

Transition durations for the verification are ``T = 0.15 s + 2 √(L / a)`` for a path of length
``L`` at the planned acceleration ``a`` (accelerate half-way, decelerate half-way).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, cast

import numpy as np

from fixplan.errors import InputError
from fixplan.locating import contact_set, solve_goal
from fixplan.model import Fixture, require_full
from fixplan.planner.coarse import Attempt, CoarsePlan, search
from fixplan.planner.execute import ExecutionSettings, Step, TransitionKind
from fixplan.planner.fine import IPOPT_PATH_FOUND, LADDER, Transition, default_kind, plan_transition
from fixplan.planner.plan import Plan, PlannedTransition, TriedTransition
from fixplan.planner.segments import segment_wrenches
from fixplan.planner.verify import Verification, verify
from fixplan.settings import DEFAULT
from fixplan.spatial import Pose

ROBUST_GRID = DEFAULT.planner.robust_grid
# Gaps kept at the other locators along a fine path [m], tried in turn when IPOPT finds no path:
# a fixed 1 mm is an angle on a part whose locators sit close together (two side locators 11 mm
# apart on a 44 mm face hold a part touching one of them ≥ 5° away from the other; the next
# transition can then not touch the end locator without closing that gap): the smaller
# clearance still keeps the path clear of every locator, with less room for the executor.
CLEARANCES_M = DEFAULT.planner.clearances_m  # fixplan.settings.PlannerSettings.clearances_m


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
    friction_robustness: list[float] = field(default_factory=list)  # per transition: largest δ of ROBUST_GRID

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
            transitions.append(
                PlannedTransition(
                    from_state=tuple(tr.established),
                    to_state=tuple(sorted([*tr.established, tr.target])),
                    added=tr.target,
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
                )
            )
        infeasible = self.status == "infeasible"
        return Plan(
            status=self.status,
            reason=self.reason,
            sequence=tuple(tuple(s) for s in self.sequence),
            transitions=tuple(transitions),
            tried=tuple(
                TriedTransition(tuple(a.established), a.target, a.success, a.reason, a.stage) for a in self.attempts
            ),
            proven=self.proven,
            certificate=tuple(
                TriedTransition(tuple(a.established), a.target, False, a.reason) for a in self.certificate
            )
            if infeasible
            else (),
            verification=self.verification,
            timings=dict(self.timings),
        )

    def to_json(self) -> dict[str, Any]:
        return self.plan.to_json()


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
        )
        for tr in transitions
    ]


def friction_robustness(
    fixture: Fixture,
    tr: Transition,
    acceleration_mps2: float,
    margin_N: float | None,
    grid: Sequence[float] = ROBUST_GRID,
) -> float:
    """The largest δ of ``grid`` for which the first segment's push survives friction ``μ(1 ± δ)``.

    The push must move the part as planned within the hand's limits; 0 when only the nominal μ
    allows it, ``inf`` for a transition from no contact (nothing to slip).
    """
    if not tr.established or len(tr.poses) < 2:
        return float("inf")
    best = 0.0
    for delta in grid:
        _, _, found, _ = segment_wrenches(
            fixture, tr.poses[:2], tuple(tr.established), tr.kind, acceleration_mps2,
            friction_margin=delta, margin_N=margin_N,
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
        acceleration_mps2: float = 1.0,
        friction_margin: float = 0.1,
        margin_N: float | None = None,
        progress: Callable[[Attempt], None] | None = None,
    ):
        self.fixture = fixture
        self.names = [loc.name for loc in fixture.locators]
        self.knots = knots
        self.acceleration_mps2 = acceleration_mps2
        self.friction_margin = friction_margin
        self.margin_N = margin_N
        self.progress = progress
        self.fine_time_s = 0.0
        self.prechecks = 0  # cheap checks run before fine plans, and how many failed
        self.precheck_failures = 0

    def plan_from(self, pose: Pose, state: frozenset[str], order: Sequence[str] | None = None) -> CoarsePlan:
        """The cheapest monotone sequence from ``state`` at ``pose`` to every locator."""
        cache: dict[tuple[tuple[str, ...], str], Transition] = {}

        def evaluate(pose_: Pose, state_: frozenset[str], target: str) -> Transition:
            key = (tuple(sorted(state_)), target)
            if key not in cache:
                t = time.perf_counter()
                for clearance in CLEARANCES_M:
                    last = clearance == CLEARANCES_M[-1]  # the ladder and the diagnosis at the last only
                    tr = plan_transition(
                        self.fixture, pose_, sorted(state_), target, knots=self.knots,
                        acceleration_mps2=self.acceleration_mps2, friction_margin=self.friction_margin,
                        margin_N=self.margin_N, clearance_m=clearance, ladder=LADDER if last else LADDER[:1],
                        diagnose=last,
                    )  # fmt: skip
                    if tr.ipopt_status in IPOPT_PATH_FOUND:
                        break  # a path: its wrenches decide, not the clearance
                cache[key] = tr
                self.fine_time_s += time.perf_counter() - t
            return cache[key]

        return search(
            state, self.names, pose, evaluate, order=order, progress=self.progress,
            estimate=self.estimate, precheck=self.precheck,
        )  # fmt: skip

    def estimate(self, pose: Pose, state: frozenset[str], target: str) -> tuple[float, Pose] | None:
        """A cheap guess of a transition for the lazy search: (mass-weighted length [m], end pose).

        The least-``M``-norm step that closes the target's gap keeping the established contacts,
        to first order. No IPOPT, no cone program.
        """
        fx = self.fixture
        est = sorted(state)
        cs = contact_set(fx, pose, [*est, target])
        gap = float(cs.contacts[-1].gap_m)
        rows = cs.G[: len(est)] if est else np.zeros((0, fx.ndof))
        A = np.vstack([rows, cs.G[-1:]])
        b = np.zeros(A.shape[0])
        b[-1] = -max(gap, 0.0)
        step = cs.M_inv @ A.T @ np.linalg.pinv(A @ cs.M_inv @ A.T, rcond=DEFAULT.numerics.rcond) @ b
        if not np.all(np.isfinite(step)):
            return None
        length = float(np.sqrt(max(float(step @ cs.mass_matrix @ step), 0.0) / fx.workpiece.mass_kg))
        return length, pose.retract(step, fx.workpiece.com_body)

    def precheck(self, pose: Pose, state: frozenset[str], target: str) -> str | None:
        """A cheap necessary check before a transition's fine plan (one cone program, no IPOPT).

        Is there a non-jamming push, within the hand's limits, for the first segment of the
        :meth:`estimate` step at ``pose``? None when there is (or nothing to check: no kept contact),
        else the search's reason. The fine plan may still find another way (its path bends), so
        the lazy search only tries such a transition later; it never drops it.
        """
        if not state:
            return None
        guess = self.estimate(pose, state, target)
        if guess is None:
            return None
        est = tuple(sorted(state))
        self.prechecks += 1
        _, _, found, reasons = segment_wrenches(
            self.fixture, [pose, guess[1]], est, default_kind(self.fixture.dimension, len(est)),
            self.acceleration_mps2, friction_margin=self.friction_margin, margin_N=self.margin_N,
        )  # fmt: skip
        if found[0]:
            return None
        self.precheck_failures += 1
        return reasons[0] if reasons else "no non-jamming push for the first step"

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
                fx.workpiece, [fx.locator(n) for n in sorted(state)], pose, tol_m=DEFAULT.planner.settle_tol_m
            )
            if not settled.converged:
                return f"no pose near the observed one keeps {{{', '.join(sorted(state))}}} touching"
            start = settled.pose
        try:
            coarse = self.plan_from(start, state)
        except InputError as exc:
            return str(exc)
        return plan_steps(coarse.transitions) if coarse.found else coarse.reason


def solve(
    fixture: Fixture,
    *,
    order: Sequence[str] | None = None,
    run_verification: bool = True,
    acceleration_mps2: float = 1.0,
    margin_N: float | None = None,
    friction_margin: float = 0.1,
    knots: int = 10,
    progress: Callable[[Attempt], None] | None = None,
    verify_options: dict[str, Any] | None = None,
) -> PlanResult:
    """Plan (and by default verify) the loading of ``fixture``.

    ``acceleration_mps2`` is the acceleration each push asks for, ``margin_N`` the least normal
    force on the kept contacts (default: the part's weight) and ``friction_margin`` the δ the
    pushes are robust to (friction anywhere in ``μ(1 ± δ)``); the executor uses the same values.
    ``knots`` per transition: 10 by default — on the default box the exact gaps between knots
    stay within 1e-17 m at 10 as at 20 (``benchmarks/bench_planner.py``) for half the time.
    ``verify_options`` are passed to :func:`~fixplan.planner.verify.verify` (e.g. ``max_sweeps``,
    ``noise``).
    """
    vopts = dict(verify_options or {})
    require_full(fixture, "planning")
    if order is not None:
        _check_order(fixture, order)
    t0 = time.perf_counter()
    names = [loc.name for loc in fixture.locators]
    touching = contact_set(fixture, "start")
    start_state = frozenset(c.name for c in touching.contacts if c.kind == "locator")
    settings = vopts.pop("settings", None) or ExecutionSettings(
        accel_mps2=acceleration_mps2, friction_margin=friction_margin, margin_N=margin_N
    )
    planner = Planner(fixture, knots=knots, acceleration_mps2=acceleration_mps2, friction_margin=friction_margin,
                      margin_N=margin_N, progress=progress)  # fmt: skip
    replan = planner.replan
    if start_state == frozenset(names):
        # already located: nothing to plan; verification checks that the part stays there
        verification = (
            verify(fixture, start_state, [], settings=settings, replan=replan, **vopts) if run_verification else None
        )
        timings = {"plan_s": 0.0, "fine_s": 0.0, "total_s": time.perf_counter() - t0}
        status, reason = _status(verification, "already located at the start pose: every locator touches")
        return PlanResult(status, reason, [tuple(sorted(names))], [], [], verification, [], timings)
    coarse = planner.plan_from(fixture.start, start_state, order)
    t_plan = time.perf_counter() - t0
    timings = {"plan_s": t_plan, "fine_s": planner.fine_time_s}
    if not coarse.found:
        timings["total_s"] = time.perf_counter() - t0
        return PlanResult("infeasible", coarse.reason, [], [], coarse.attempts, None, [], timings)
    transitions = list(coarse.transitions)
    durations = [_duration(tr, acceleration_mps2) for tr in transitions]
    robustness = [friction_robustness(fixture, tr, acceleration_mps2, margin_N) for tr in transitions]
    verification = None
    if run_verification:
        t1 = time.perf_counter()
        verification = verify(fixture, start_state, plan_steps(transitions), settings=settings, replan=replan, **vopts)
        timings["verify_s"] = time.perf_counter() - t1
    timings["total_s"] = time.perf_counter() - t0
    status, reason = _status(verification, "")
    return PlanResult(
        status, reason, coarse.sequence, transitions, coarse.attempts, verification, durations, timings, robustness
    )


def _status(verification: Verification | None, note: str) -> tuple[PlanStatus, str]:
    """``planned`` only when the loop confirmed the plan; else ``unverified`` with where and why."""
    if verification is None:
        return "unverified", "verification skipped (--no-verify): the sequence was not run in the haptic loop"
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
        raise InputError(f"--order names unknown locators: {', '.join(extra)} (known: {', '.join(names)})")
    if len(set(order)) != len(order):
        raise InputError(f"--order repeats a locator: {','.join(order)}")
