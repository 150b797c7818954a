"""A policy over contact states: from every state the part can be observed in, the next transition.

The coarse plan (:mod:`.coarse`) is one sequence of contact states from the start state. Under
uncertainty — a part starting in free space, a tilt, friction not as modelled — the part meets
other states: another locator touches first, two close together, a contact is lost. The
paper's coarse plan is a pre-image plan: for every recognisable contact state, the motion that
leads on toward the goal. This module builds it, backward from the goal:

1. **Representative poses.** The pre-image of a state ``S`` (a set of touched locators) near the
   goal is reached by backing the part off the located pose ``X*`` along the motion that keeps
   ``S`` touching and opens every other locator by ``backoff_m``: to first order
   ``G Δ = b`` with ``b_i = 0`` for ``i ∈ S`` and ``b_i = backoff_m`` otherwise (``G`` the
   normal rows at the goal; least ``M``-norm for rank-deficient layouts), then polished so the
   locators of ``S`` touch exactly (:func:`~fixplan.locating.solve_goal`). ``S`` is
   *realisable* when every other locator really is open there (at least ``min_open_fraction``
   of the back-off): a state two locators can only reach together is not one the part is seen in.
2. **Cost-to-go.** Dynamic programming over the lattice of states, largest first:
   ``V(goal) = 0``, ``V(S) = min_t c(S, t) + V(S ∪ {t})`` with ``c`` the planner's cheap estimate
   (the least-``M``-norm step that closes ``t`` keeping ``S``, from ``S``'s representative pose).
3. **The push.** Out of each state the part can be in — the states reachable from the start and
   every state the policy leads to from them — the candidates are checked cheapest first (at most
   ``checks_per_state``): is there a non-jamming push within the hand's limits for the first step
   (one cone program, :func:`~fixplan.planner.segments.segment_wrenches`)? Of those that have one
   within the cost slack of the cheapest (at most ``margin_candidates``), the one with the most
   margin is kept, with its push; a state with none keeps its cheapest candidate, marked
   unchecked (the executor still tries it, and re-plans when it stalls). States the part cannot
   be in keep their cheapest candidate unchecked.
4. **The plan's own states** take the fine plan's transition (its guide path and pushes): the
   policy agrees with the plan wherever the plan goes.

The executor (:mod:`.execute`) consults the policy whenever it observes a state the plan does not
expect, and only re-plans (a coarse search from the observed pose) when the policy has nothing or
its transition stalls. Computing it costs no IPOPT solve: one small least-squares polish and at
most ``checks_per_state`` cone programs per state.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from fixplan.contact_state import State
from fixplan.errors import InputError
from fixplan.locating import contact_set, locator_gaps, solve_goal
from fixplan.planner.segments import carry_factor
from fixplan.settings import DEFAULT, PlannerSettings, PolicySettings, Settings
from fixplan.spatial import Pose

if TYPE_CHECKING:
    from fixplan.model import Fixture
    from fixplan.planner.execute import Step
    from fixplan.planner.fine import Transition

FloatArray = NDArray[np.float64]
Source = Literal["plan", "pre-image"]


@dataclass(frozen=True, eq=False)
class PolicyEntry:
    """What to do in one contact state: touch ``target`` next, with this motion and push.

    Attributes
    ----------
    state : tuple of str
        The touched locators (sorted).
    target : str
        The locator to touch next.
    motion : {"free", "roll", "slide"}
        How the part moves on the kept contacts.
    wrench : (ndof,) array or None
        A non-jamming push for the first step from the representative pose (about the body
        origin, world axes); None when none was found (``checked`` False).
    margin_N : float or None
        The least normal force on the kept contacts under that push [N] (None from no contact).
    cost_to_go_m : float
        Estimated mass-weighted path length from here to every locator [m].
    source : {"plan", "pre-image"}
        ``plan``: the fine plan's transition; ``pre-image``: the backward construction.
    checked : bool
        Whether a non-jamming push was found for it.
    path : tuple of Pose
        Guide poses (the fine plan's knots; empty for pre-image entries: the executor then takes
        the gap-closing motion at the pose the part is in).
    pose : Pose or None
        The representative pose the entry was computed at.
    together : tuple of str
        Locators that close at the same instant as ``target`` (a redundant layout: the plan's
        group transition); ``"together"`` in the file, only when there are any.
    """

    state: tuple[str, ...]
    target: str
    motion: str
    wrench: FloatArray | None
    margin_N: float | None
    cost_to_go_m: float
    source: Source
    checked: bool
    path: tuple[Pose, ...] = field(default=(), repr=False)
    pose: Pose | None = field(default=None, repr=False)
    together: tuple[str, ...] = ()

    @property
    def next_state(self) -> tuple[str, ...]:
        return tuple(sorted([*self.state, self.target, *self.together]))

    def step(self) -> Step:
        """The executor's step for this entry."""
        from fixplan.planner.execute import Step

        return Step(tuple(self.state), self.target, self.motion, tuple(self.path), self.together)  # type: ignore[arg-type]

    def to_json(self) -> dict[str, Any]:
        def num(x: float | None) -> float | None:
            return None if x is None or not math.isfinite(x) else float(x)

        return {
            "state": list(self.state),
            "next": list(self.next_state),
            "target": self.target,
            "motion": self.motion,
            "wrench": None if self.wrench is None else [float(x) for x in self.wrench],
            "margin_N": num(self.margin_N),
            "cost_to_go_m": num(self.cost_to_go_m),
            "source": self.source,
            "checked": self.checked,
        } | ({"together": list(self.together)} if self.together else {})

    @classmethod
    def from_json(cls, obj: Any, where: str = "policy") -> PolicyEntry:
        if not isinstance(obj, dict):
            raise InputError(f"{where}: expected an object, got {type(obj).__name__}")
        state = obj.get("state")
        target = obj.get("target")
        if not isinstance(state, list) or not all(isinstance(n, str) for n in state):
            raise InputError(f"{where}.state: expected a list of locator names")
        if not isinstance(target, str) or target in state:
            raise InputError(f"{where}.target: expected a locator name not in the state, got {target!r}")
        motion = obj.get("motion")
        if motion not in ("free", "roll", "slide"):
            raise InputError(f"{where}.motion: expected free, roll or slide, got {motion!r}")
        w = obj.get("wrench")
        wrench = None
        if w is not None:
            if not isinstance(w, list) or not all(isinstance(x, int | float) for x in w):
                raise InputError(f"{where}.wrench: expected a list of numbers or null")
            wrench = np.asarray(w, dtype=float)
            if not np.all(np.isfinite(wrench)):
                raise InputError(f"{where}.wrench: expected finite numbers")

        def num(key: str) -> float | None:
            x = obj.get(key)
            if x is None:
                return None
            if not isinstance(x, int | float) or not math.isfinite(x):
                raise InputError(f"{where}.{key}: expected a finite number or null, got {x!r}")
            return float(x)

        source = obj.get("source", "pre-image")
        if source not in ("plan", "pre-image"):
            raise InputError(f"{where}.source: expected plan or pre-image, got {source!r}")
        ctg = num("cost_to_go_m")
        together = obj.get("together", [])
        if (
            not isinstance(together, list)
            or not all(isinstance(n, str) for n in together)
            or {target, *state} & set(together)
        ):
            raise InputError(f"{where}.together: expected a list of locator names not in the state nor the target")
        return cls(
            tuple(sorted(state)), target, str(motion), wrench, num("margin_N"),
            float("inf") if ctg is None else ctg, source, bool(obj.get("checked", wrench is not None)),
            together=tuple(together),
        )  # fmt: skip


@dataclass(frozen=True, eq=False)
class Policy:
    """The next transition from every contact state the part can be observed in.

    ``entries`` maps a state to its :class:`PolicyEntry`; ``reachable`` are the states the part can
    be observed in from the start (realisable states that contain the start state, or that one
    lost contact leads to from a planned state); ``unrealisable`` are the states no pose near the
    goal touches without closing another locator too.
    """

    entries: dict[State, PolicyEntry]
    reachable: frozenset[State]
    unrealisable: frozenset[State] = frozenset()
    build_time_s: float = 0.0
    stated_coverage: dict[str, Any] | None = None  # a file's coverage, kept as read

    def entry(self, state: State) -> PolicyEntry | None:
        return self.entries.get(frozenset(state))

    def chain(self, state: State, goal: State) -> list[Step] | None:
        """The steps the policy takes from ``state`` to ``goal`` (None when it has no way there)."""
        steps: list[Step] = []
        s = frozenset(state)
        while s != goal:
            e = self.entries.get(s)
            if e is None:
                return None
            steps.append(e.step())
            s = frozenset(e.next_state)
        return steps

    def chain_from(
        self, fixture: Fixture, state: State, pose: Pose, goal: State, settings: Settings = DEFAULT
    ) -> list[Step] | None:
        """The policy's steps from ``state`` with the part at ``pose``: the first chosen where it is.

        The value of the next states is the policy's cost-to-go; the first step's own cost is the
        gap-closing step from ``pose`` (not from the state's representative pose): of the ways on,
        the one with the least step from here plus cost-to-go from where it leads. A part that
        lost a base locator and tipped up closes that locator again rather than one the
        representative pose found nearer. The plan's own transition keeps its guide path when it
        is the one chosen. The steps are priced with ``settings`` (``policy``, ``planner``: the executor's
        profile).
        """
        from fixplan.planner.execute import Step

        s = frozenset(state)
        if s == goal:
            return []
        later = {
            t: 0.0 if s | {t} == goal else self.entries[s | {t}].cost_to_go_m
            for t in goal - s
            if s | {t} == goal or s | {t} in self.entries
        }
        best: tuple[float, str, str] | None = None
        seen: set[str] = set()
        for cost, t, kind, _, _ in ways_on(fixture, pose, s, later, settings.policy, settings.planner):
            if t in seen:
                continue  # the other kind only when the planner's own cannot close the gap
            seen.add(t)
            if best is None or (cost, t, kind) < best:
                best = (cost, t, kind)
        if best is None:
            return self.chain(s, goal)
        _, t, kind = best
        entry = self.entries.get(s)
        first = (
            entry.step()
            if entry is not None and entry.target == t and (entry.motion == kind or entry.source == "plan")
            else Step(tuple(sorted(s)), t, kind, ())  # type: ignore[arg-type]
        )
        rest = self.chain(s | {t}, goal)
        return None if rest is None else [first, *rest]

    @property
    def coverage(self) -> dict[str, Any]:
        """States with a checked transition / states reachable."""
        if self.stated_coverage is not None:
            return dict(self.stated_coverage)
        planned = sum(1 for s in self.reachable if s in self.entries and self.entries[s].checked)
        n = len(self.reachable)
        return {
            "states_planned": planned,
            "states_reachable": n,
            "fraction": None if n == 0 else planned / n,
            "states_with_an_unchecked_transition": sum(
                1 for s in self.reachable if s in self.entries and not self.entries[s].checked
            ),
            "states_unrealisable": len(self.unrealisable),
        }

    def to_json(self) -> list[dict[str, Any]]:
        return [self.entries[s].to_json() for s in sorted(self.entries, key=lambda s: (len(s), sorted(s)))]

    @classmethod
    def from_json(cls, data: Any, where: str = "policy", coverage: Any = None) -> Policy:
        if coverage is not None and not isinstance(coverage, dict):
            raise InputError(f"{where}: coverage: expected an object, got {type(coverage).__name__}")
        if not isinstance(data, list):
            raise InputError(f"{where}: expected a list of states with their next transition")
        entries: dict[State, PolicyEntry] = {}
        for i, obj in enumerate(data):
            e = PolicyEntry.from_json(obj, f"{where}[{i}]")
            entries[frozenset(e.state)] = e
        return cls(entries, frozenset(entries), stated_coverage=coverage)


# -- building it -----------------------------------------------------------------------------------
def representative_pose(
    fixture: Fixture,
    goal: Pose,
    state: State,
    settings: PolicySettings = DEFAULT.policy,
    planner_settings: PlannerSettings = DEFAULT.planner,
) -> Pose | None:
    """A pose in ``state``'s pre-image near the goal: its locators touch, every other one is open.

    None when no such pose is found (the state's locators cannot touch without another one). The
    state's locators are made to touch within ``planner_settings.settle_tol_m``.
    """
    names = [loc.name for loc in fixture.locators]
    wp = fixture.workpiece
    if frozenset(state) == frozenset(names):
        return goal
    cs = contact_set(fixture, goal, names)
    b = np.array([0.0 if c.owner in state else settings.backoff_m for c in cs.contacts])  # every contact of each
    G = cs.G
    Minv = cs.M_inv
    step = Minv @ G.T @ np.linalg.pinv(G @ Minv @ G.T, rcond=DEFAULT.numerics.rcond) @ b
    if not np.all(np.isfinite(step)):
        return None
    pose = goal.retract(step, wp.com_body)
    if state:
        settled = solve_goal(wp, [fixture.locator(n) for n in sorted(state)], pose, tol_m=planner_settings.settle_tol_m)
        if not settled.converged:
            return None
        pose = settled.pose
    gaps = locator_gaps(wp, pose, fixture.locators)
    open_ = [g for n, g in zip(names, gaps, strict=True) if n not in state]
    if open_ and min(open_) < settings.min_open_fraction * settings.backoff_m:
        return None
    if np.any(gaps < -fixture.tolerances.touch_m):
        return None
    return pose


def gap_closing_step(
    fixture: Fixture, pose: Pose, state: State, target: str, kind: str, settings: PlannerSettings = DEFAULT.planner
) -> tuple[float, Pose] | None:
    """The least-``M``-norm step that closes ``target``'s gap keeping ``state`` (to first order).

    ``kind`` ``slide`` keeps the kept contacts' normal rows, ``roll`` every row (no slip), ``free``
    none. Returns (mass-weighted length [m] times the carry factor of :func:`~fixplan.planner.segments.carry_factor`, end pose), or None when that motion cannot close the
    gap (the target's row is not reachable with the kept rows, e.g. rolling on two contacts in 3D
    leaves one rotation, which may not approach the target). ``settings``: the planner's (its ``carry_cost``).
    """
    wp = fixture.workpiece
    est = sorted(state)
    cs = contact_set(fixture, pose, [*est, target]).nearest_of(target)  # kept contacts, then the target's nearest
    gap = max(float(cs.contacts[-1].gap_m), 0.0)
    if not est or kind == "free":
        kept = np.zeros((0, fixture.ndof))
    elif kind == "roll":
        kept = cs.J[: int(sum(c.size for c in cs.contacts[:-1]))]
    else:
        kept = cs.G[: len(cs) - 1]
    A = np.vstack([kept, cs.G[-1:]])
    b = np.zeros(A.shape[0])
    b[-1] = -gap
    Minv = cs.M_inv
    step = Minv @ A.T @ np.linalg.pinv(A @ Minv @ A.T, rcond=DEFAULT.numerics.rcond) @ b
    if not np.all(np.isfinite(step)):
        return None
    # the target must really close (not a least-squares compromise with the kept rows)
    if gap > 0 and abs(float(cs.G[-1] @ step) + gap) > 0.5 * gap:
        return None
    length = float(np.sqrt(max(float(step @ cs.mass_matrix @ step), 0.0) / wp.mass_kg))
    length *= carry_factor(fixture, pose, est, cs, settings)  # priced as the fine plan prices it
    return length, pose.retract(step, wp.com_body)


def motion_kinds(dimension: int, n_kept: int) -> tuple[str, ...]:
    """The kinds of motion tried out of a state with ``n_kept`` contacts, the fine planner's own first.

    ``free`` from no contact; else the planner's default (:func:`~fixplan.planner.fine.default_kind`)
    and then the other one.
    """
    from fixplan.planner.fine import KINDS, default_kind

    if not n_kept:
        return ("free",)
    first = default_kind(dimension, n_kept)
    return (first, *(k for k in KINDS if k != first))


def ways_on(
    fixture: Fixture,
    pose: Pose,
    state: State,
    later: dict[str, float],
    settings: PolicySettings = DEFAULT.policy,
    planner_settings: PlannerSettings = DEFAULT.planner,
) -> list[tuple[float, str, str, Pose, int]]:
    """The transitions out of ``state`` at ``pose``, priced: ``(cost, target, kind, end pose, rank)``.

    One per target of ``later`` (its cost-to-go [m] from the state it leads to) and kind of
    :func:`motion_kinds` whose first-order step closes the gap (:func:`gap_closing_step`); ``cost``
    is the step's length plus the cost-to-go, the other kind (``rank`` 1) dearer by the back-off.
    In target order, the planner's own kind first. The steps are priced with ``planner_settings``.
    """
    out = []
    for t in sorted(later):
        if not math.isfinite(later[t]):
            continue
        for rank, kind in enumerate(motion_kinds(fixture.dimension, len(state))):
            step = gap_closing_step(fixture, pose, state, t, kind, planner_settings)
            if step is not None:
                out.append((step[0] + later[t] + rank * settings.backoff_m, t, kind, step[1], rank))
    return out


def build_policy(
    fixture: Fixture,
    planner: Any,
    start_state: State,
    transitions: Sequence[Transition] = (),
    *,
    settings: PolicySettings | None = None,
) -> Policy:
    """The policy of ``fixture`` (see the module docstring).

    ``planner`` is a :class:`~fixplan.planner.solve.Planner` (its ``estimate`` prices a transition,
    its options set the push's acceleration, friction margin and least normal force, its
    ``settings`` the planner's thresholds and the pushes' searches; ``settings``, the policy's
    own, default to its ``settings.policy``);
    ``transitions`` the fine plans of the chosen sequence, whose states take the plan's transition.
    A planner with a ``policy_memo`` dictionary keeps there the representative poses and the
    checked pushes, which a rebuild for another plan of the same fixture (after a transition was
    set aside) reuses wherever the inputs are the same.
    """
    t0 = time.perf_counter()
    profile: Settings = planner.settings
    settings = profile.policy if settings is None else settings
    memo = getattr(planner, "policy_memo", None)
    memo = {} if not isinstance(memo, dict) else memo
    names = [loc.name for loc in fixture.locators]
    goal_state: State = frozenset(names)
    goal = fixture.goal
    plan_states = [frozenset(tr.established) for tr in transitions]
    planned_at = {frozenset(tr.established): tr for tr in transitions}

    if len(names) <= settings.max_locators:
        states = [frozenset(c) for r in range(len(names)) for c in itertools.combinations(names, r)]
    else:
        near: set[State] = set()
        for p in plan_states:
            near.add(p)
            near |= {p | {x} for x in goal_state - p}
            near |= {p - {x} for x in p}
        states = sorted(near - {goal_state}, key=len)

    poses: dict[State, Pose | None] = {goal_state: goal}

    def pose_of(s: State) -> Pose | None:
        if s not in poses:
            key = ("pose", s, _pose_bytes(goal), settings)
            if key not in memo:
                memo[key] = representative_pose(fixture, goal, s, settings, profile.planner)
            poses[s] = memo[key]
        return poses[s]

    value: dict[State, float] = {goal_state: 0.0}
    entries: dict[State, PolicyEntry] = {}
    unrealisable: set[State] = set()
    candidates: dict[State, list[tuple[float, str, str, Pose]]] = {}
    # pass 1: cost-to-go over the whole lattice from the estimates alone (no cone program)
    for s in sorted(states, key=lambda s: (-len(s), sorted(s))):
        tr = planned_at.get(s)
        pose = tr.poses[0] if tr is not None else pose_of(s)
        if pose is None:
            unrealisable.add(s)
            continue
        if tr is not None:
            # the plan's own transition: its fine path and pushes
            rows = tr.wrenches[np.isfinite(tr.wrenches).all(axis=1)] if len(tr.wrenches) else tr.wrenches
            margins = tr.margins_N[np.isfinite(tr.margins_N)]
            later = value.get(s | {tr.target} | set(tr.together), 0.0)
            value[s] = float(tr.cost) + later if math.isfinite(float(tr.cost)) else later
            entries[s] = PolicyEntry(
                tuple(sorted(s)), tr.target, tr.kind if s else "free",
                rows.mean(axis=0) if len(rows) else None,
                float(np.min(margins)) if len(margins) else None,
                value[s], "plan", True, tuple(tr.poses), pose, tuple(tr.together),
            )  # fmt: skip
            continue
        to_go = {t: value[s | {t}] for t in goal_state - s if s | {t} in value}
        options = [
            (cost, t, kind, end)
            for cost, t, kind, end, _ in ways_on(fixture, pose, s, to_go, settings, profile.planner)
        ]
        options.sort(key=lambda o: (o[0], o[1], o[2]))
        if not options:
            continue
        candidates[s] = options
        cost, t, kind, _ = options[0]
        value[s] = cost
        # unchecked until pass 2 (a free state has nothing to check: the hand carries the part)
        entries[s] = PolicyEntry(tuple(sorted(s)), t, kind, None, None, cost, "pre-image", not s, (), pose)

    # the states the part can be observed in from the start
    reachable = {
        s
        for s in states
        if s not in unrealisable and (start_state <= s or any(len(p - s) == 1 and s < p for p in plan_states))
    }

    # pass 2: the push of every state the part can be in — the reachable ones and every state the
    # policy leads to from them — checked with one cone program per candidate
    checked: set[State] = set()
    while True:
        need: set[State] = set()
        for s0 in reachable:
            s1: State | None = s0
            while s1 is not None and s1 in entries and s1 not in need:
                need.add(s1)
                s1 = frozenset(entries[s1].next_state)
        todo = sorted((s for s in need - checked if s in candidates and s), key=lambda s: (-len(s), sorted(s)))
        if not todo:
            break
        for s in todo:
            checked.add(s)
            here = entries[s].pose
            if here is not None:
                tried = candidates[s][: max(settings.checks_per_state, 1)]
                key = (
                    "check",
                    s,
                    _pose_bytes(here),
                    tuple((c, t, k, _pose_bytes(e)) for c, t, k, e in tried),
                    settings,
                )
                if key not in memo:
                    memo[key] = _checked_entry(fixture, planner, s, here, candidates[s], settings)
                entries[s] = memo[key]
    return Policy(entries, frozenset(reachable), frozenset(unrealisable), time.perf_counter() - t0)


def _pose_bytes(pose: Pose) -> bytes:
    return pose.p_world.tobytes() + np.asarray(pose.R_world_body).tobytes()


def _checked_entry(
    fixture: Fixture,
    planner: Any,
    s: State,
    pose: Pose,
    options: list[tuple[float, str, str, Pose]],
    settings: PolicySettings,
) -> PolicyEntry:
    """The state's transition with a non-jamming first push (cheapest first).

    Among those within the cost slack, the one with the most margin; the cheapest, unchecked, when
    none has a push.
    """
    from fixplan.planner.segments import segment_wrenches

    found_ones: list[PolicyEntry] = []
    best_cost = options[0][0]
    for cost, t, kind, end in options[: max(settings.checks_per_state, 1)]:
        if found_ones and (
            len(found_ones) >= settings.margin_candidates or cost > planner.settings.planner.cost_slack * best_cost
        ):
            break
        w, m, found, _ = segment_wrenches(
            fixture, [pose, end], tuple(sorted(s)), kind, planner.acceleration_mps2,
            friction_margin=planner.friction_margin, margin_N=planner.margin_N, settings=planner.settings,
        )  # fmt: skip
        if found[0]:
            found_ones.append(
                PolicyEntry(
                    tuple(sorted(s)),
                    t,
                    kind,
                    np.asarray(w[0], dtype=float),
                    float(m[0]) if math.isfinite(float(m[0])) else None,
                    cost,
                    "pre-image",
                    True,
                    (),
                    pose,
                )  # fmt: skip
            )
    if found_ones:
        # several ways on within the cost slack: the one with the most margin (the least normal
        # force on the kept contacts under its push), the cheaper on a tie
        return max(found_ones, key=lambda e: (e.margin_N or 0.0, -e.cost_to_go_m))
    cost, t, kind, _ = options[0]
    return PolicyEntry(tuple(sorted(s)), t, kind, None, None, cost, "pre-image", False, (), pose)


__all__ = [
    "Policy",
    "PolicyEntry",
    "build_policy",
    "gap_closing_step",
    "motion_kinds",
    "representative_pose",
    "ways_on",
]
