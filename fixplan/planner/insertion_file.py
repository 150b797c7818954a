"""A staged insertion in a plan file: what ``solve`` writes for pins and bores, and what ``verify`` re-runs.

A plan for a fixture with pins or bores (:mod:`.insertion`) is written like any other
(``sequence``, ``transitions`` with their knot poses and pushes) plus the ``insertion`` key
(:func:`insertion_json`): the insertion axis, the located pose the guide ends at, each
transition's stage (``free``: the approach to the staging pose, ``insert``, ``seat``), the
seating push and the policy (:mod:`.insertion_policy`: what the run does from every observable
state and how it recovers; a file written before it has none, and re-runs without recovery, as
``solve`` verified it then). :func:`check_insertion_claims` checks those claims against the fixture (the plan
must be the staged insertion of *this* fixture: its axis and located pose, its states from the
start to every pin engaged and every rest pressed), and :func:`insertion_plan_of` reads the plan
back as the :class:`~.insertion.InsertionPlan` that :func:`~.insertion.verify_insertion` runs in
the haptic loop (``fixplan verify PLAN``): the guide and the pushes are the file's; the axis and
the located pose, checked to agree with the file's, are the fixture's.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fixplan.contact_state import format_state
from fixplan.errors import InputError
from fixplan.locating import engagement, insertion_axis, inserts, located_pose, seated
from fixplan.planner.insertion import InsertionPlan, Stage, goal_state, started_in, with_seating
from fixplan.planner.insertion_policy import InsertionPolicy
from fixplan.planner.plan_types import Plan, Verification, pose_from_json
from fixplan.settings import HAPTIC, Settings
from fixplan.spatial import shift_wrench

if TYPE_CHECKING:
    from fixplan.model import Fixture

FloatArray = NDArray[np.float64]

APPROACH = "staging"  # the approach's ``added`` in the file: a pose target, no contact closes


def insertion_json(plan: InsertionPlan) -> dict[str, Any] | None:
    """The plan file's ``insertion`` key; None when there is no plan to re-run (no seating push)."""
    if not plan.ok or plan.seat_wrench is None:
        return None
    out: dict[str, Any] = {
        "axis": [float(x) for x in plan.axis_world],
        "goal": plan.goal.to_json(),
        "stages": [st.kind for st in plan.stages],
        "seat_wrench": [float(x) for x in plan.seat_wrench],
    }
    if plan.policy is not None:
        out["policy"] = plan.policy.to_json()
    return out


def _state(s: Iterable[str]) -> str:
    return format_state(s, empty="{}")


def _stages_expected(n: int, started_in: bool = False) -> list[str]:
    """The stages of a staged insertion of ``n`` transitions: the approach, the insertions, the seating.

    ``started_in``: the part starts with its pins in their holes (:func:`~.insertion.started_in`):
    no approach.
    """
    if not n:
        return []
    return [*([] if started_in else ["free"]), *["insert"] * (n - (1 if started_in else 2)), "seat"]


def check_insertion_claims(plan: Plan, fixture: Fixture, source: str, *, tolerance: tuple[float, float]) -> None:
    """Refuse a solved plan for ``fixture`` (with pins or bores) that is not its staged insertion.

    - ``insertion`` is there, its ``axis`` the fixture's insertion axis and its ``goal`` the
      located pose (else the plan is for another fixture), one ``stages`` entry per transition:
      ``free``, then ``insert`` per engagement, then ``seat`` (no ``free`` for a part that starts
      with its pins in past the chamfers);
    - ``sequence`` starts in the state the part starts in (``{}``: nothing engaged; every pin
      engaged for a part that starts in; a plan without
      transitions claims the part starts located, which the fixture must confirm) and ends with
      every pin engaged and every rest pressed (a bore: engaged and on its bottom); the approach
      (``added``: ``staging``) changes no state, every other transition closes its ``added``;
    - every transition has its guide (at least two knot poses) and its planned push (its
      ``wrench``: the largest caps the hand's push along the axis); the last knot pose is the
      located pose.

    Poses agree within ``tolerance`` (metres, radians; :func:`~.plan.check_plan_claims` passes its
    start tolerances), axes within its angle. The pushes' limits and the knots' continuity are
    :func:`~.plan.check_plan_claims`'. Raises :class:`InputError` naming the key and what was expected.
    """
    tol_m, tol_rad = tolerance
    data = plan.extras.get("insertion")
    if not isinstance(data, dict):
        raise InputError(
            f"{source}: insertion: missing (expected the staged insertion 'fixplan solve --out' writes for a "
            f"fixture with pins or bores; solve {fixture.source} again)"
        )
    u = insertion_axis(fixture)
    axis = np.asarray(data["axis"], dtype=float)
    turn = math.acos(min(max(float(axis @ u) / float(np.linalg.norm(axis)), -1.0), 1.0))
    if turn > tol_rad:
        raise InputError(
            f"{source}: the plan is for another fixture: its insertion axis ({', '.join(f'{x:.4g}' for x in axis)}) "
            f"is {math.degrees(turn):.3g}° from {fixture.source}'s ({', '.join(f'{x:.4g}' for x in u)})"
        )
    G = located_pose(fixture)
    goal = pose_from_json(data["goal"], fixture.dimension, f"{source}: insertion.goal")
    dp, dr = goal.distance_to(G)
    if dp > tol_m or dr > tol_rad:
        raise InputError(
            f"{source}: the plan is for another fixture: its located pose is {dp:.3g} m, {math.degrees(dr):.3g}° "
            f"from {fixture.source}'s (expected ≤ {tol_m:g} m, {math.degrees(tol_rad):.2g}°)"
        )
    n = len(plan.transitions)
    stages = list(data["stages"])
    inside = started_in(fixture)
    if stages != _stages_expected(n, inside):
        raise InputError(
            f"{source}: insertion.stages: got {stages} (expected {_stages_expected(n, inside)}: the approach, one "
            f"insertion per engagement, the seating; one per transition)"
        )
    goal_set = goal_state(fixture)
    start = (frozenset(i.name for i in inserts(fixture)) if inside else frozenset()) if n else goal_set
    if not n:
        S = fixture.start
        located = all(engagement(fixture, S, i).engaged for i in inserts(fixture)) and seated(fixture, S)
        if not located:
            raise InputError(
                f"{source}: transitions: got [] (expected the insertion: the part does not start located in "
                f"{fixture.source}, every pin in its hole and every rest touching)"
            )
    seq = [frozenset(s) for s in plan.sequence]
    if len(seq) != n + 1:
        raise InputError(f"{source}: sequence: got {len(seq)} states (expected {n + 1}, one more than the transitions)")
    if seq[0] != start:
        raise InputError(
            f"{source}: sequence[0]: got {_state(seq[0])} (expected the state the part starts in, {_state(start)})"
        )
    if seq[-1] != goal_set:
        raise InputError(
            f"{source}: sequence[{n}]: got {_state(seq[-1])} (expected every pin engaged and every rest pressed, "
            f"{_state(goal_set)}: a plan loads the part)"
        )
    for i, (tr, kind) in enumerate(zip(plan.transitions, stages, strict=True)):
        where = f"{source}: transitions[{i}]"
        if frozenset(tr.from_state) != seq[i]:
            raise InputError(f"{where}.from: got {_state(tr.from_state)} (expected sequence[{i}], {_state(seq[i])})")
        if len(tr.poses) < 2:
            raise InputError(
                f"{where}.poses: got {len(tr.poses)} (expected the guide's poses, at least its start and end)"
            )
        if tr.wrench is None:
            raise InputError(
                f"{where}.wrench: got null (expected the stage's planned push; its largest caps the hand's)"
            )
        if kind == "free":
            if tr.added_names != (APPROACH,) or seq[i + 1] != seq[i]:
                raise InputError(
                    f"{where}: the approach (insertion.stages[{i}]: free): got {tr.added_label} to "
                    f"{_state(seq[i + 1])} (expected added '{APPROACH}', the state unchanged)"
                )
            continue
        added = set(tr.added_names)
        if not added or added & seq[i] or seq[i + 1] != seq[i] | added or frozenset(tr.to_state) != seq[i + 1]:
            raise InputError(
                f"{where}: {_state(tr.from_state)} + {tr.added_label} → {_state(tr.to_state)} (expected "
                f"sequence[{i + 1}], {_state(seq[i + 1])}, from 'from' plus 'added')"
            )
    if n:
        end = plan.transitions[-1].poses[-1]
        dp, dr = end.distance_to(G)
        if dp > tol_m or dr > tol_rad:
            raise InputError(
                f"{source}: transitions[{n - 1}].poses[-1]: {dp:.3g} m, {math.degrees(dr):.3g}° from the located pose "
                f"(expected the seating to end there, within {tol_m:g} m)"
            )
    if data.get("policy") is not None:
        check_policy_claims(data["policy"], fixture, seq, stages, source)


def check_policy_claims(data: dict[str, Any], fixture: Fixture, seq: list[frozenset[str]], stages: list[str],
                        source: str) -> None:  # fmt: skip
    """Refuse an ``insertion.policy`` that is not one of this plan (:mod:`.insertion_policy`).

    Each entry's ``engaged`` names the fixture's pins and bores, once per (``engaged``,
    ``seated``); ``seated`` (``hold``, no ``transition``) only with all of them; any other entry
    runs a transition after the approach whose stage is its ``action`` (``insert`` or ``seat``),
    from a planned state it holds, and leads to a planned state holding it (``next``).
    """
    names = {i.name for i in inserts(fixture)}
    seen: set[tuple[tuple[str, ...], bool]] = set()
    for k, e in enumerate(data["entries"]):
        where = f"{source}: insertion.policy.entries[{k}]"
        engaged = frozenset(e["engaged"])
        if not engaged <= names:
            raise InputError(
                f"{where}.engaged: got {_state(engaged)} (expected pins and bores of {fixture.source}: {_state(names)})"
            )
        key = (tuple(sorted(engaged)), bool(e["seated"]))
        if key in seen:
            raise InputError(f"{where}: {_state(engaged)} twice (expected one entry per observable state)")
        seen.add(key)
        t, action, nxt = e["transition"], e["action"], frozenset(e["next"])
        if e["seated"] or action == "hold":
            if not (e["seated"] and action == "hold" and t is None and engaged == names and nxt == seq[-1]):
                raise InputError(
                    f"{where}: got seated {e['seated']}, action {action}, transition {t} (expected the goal's "
                    f"entry: every pin and bore engaged, seated true, action hold, transition null, next {_state(seq[-1])})"
                )
            continue
        first = 1 if stages and stages[0] == "free" else 0  # the transitions after the approach
        if t is None or not first <= t < len(stages) or stages[t] != action or not seq[t] <= engaged:
            raise InputError(
                f"{where}.transition: got {t} with action {action} (expected a transition after the approach whose "
                f"stage is the action, from a planned state {_state(engaged)} holds)"
            )
        if nxt not in seq[t + 1 :] or not engaged <= nxt:
            raise InputError(
                f"{where}.next: got {_state(nxt)} (expected a planned state after transition {t} that holds "
                f"{_state(engaged)})"
            )


def insertion_plan_of(plan: Plan, fixture: Fixture, settings: Settings = HAPTIC) -> InsertionPlan:
    """The :class:`~.insertion.InsertionPlan` a plan file holds (its claims checked: :func:`check_insertion_claims`).

    The stages are the file's transitions (their knot poses, their mean planned push), the seating
    push is the file's; the axis and the located pose are the fixture's, and so are the stops, the
    turn into them and the seating push's parts across the axis (:func:`~.insertion.with_seating`,
    with ``settings``' insertion numbers, as ``solve`` found them).
    """
    data = plan.extras["insertion"]
    G = located_pose(fixture)
    stages = []
    for tr, kind in zip(plan.transitions, data["stages"], strict=True):
        free = kind == "free"
        wrench = np.asarray(tr.wrench, dtype=float)  # every stage has one (check_insertion_claims)
        stages.append(
            Stage(
                "" if free else str(tr.added), () if free else tuple(tr.together), kind, list(tr.poses), wrench, (),
                plan.reason,
            )
        )  # fmt: skip
    seat = np.asarray(data["seat_wrench"], dtype=float)
    com = G.point_world_from_body(fixture.workpiece.com_body)
    policy = data.get("policy")
    out = InsertionPlan(
        ok=True,
        reason=plan.reason,
        axis_world=insertion_axis(fixture),
        goal=G,
        stages=stages,
        seat_wrench=seat,
        seat_wrench_com=shift_wrench(seat, G.p_world, com),
        start_state=frozenset(plan.sequence[0]) if plan.sequence else frozenset(),
        policy=None if policy is None else InsertionPolicy.from_json(policy),
    )
    with_seating(out, fixture, settings.insertion)
    return out


def verify_insertion_file(fixture: Fixture, plan: Plan, settings: Settings = HAPTIC) -> Verification:
    """``fixplan verify PLAN`` for a fixture with pins or bores: the file's insertion in the haptic loop, as ``solve`` ran it."""
    from fixplan.planner.insertion import verify_insertion

    return verify_insertion(fixture, insertion_plan_of(plan, fixture, settings), settings=settings)


__all__ = [
    "APPROACH",
    "check_insertion_claims",
    "check_policy_claims",
    "insertion_json",
    "insertion_plan_of",
    "verify_insertion_file",
]
