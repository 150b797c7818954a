"""Reading a plan file for a fixture: the same locators, dimension and start pose, and claims it can keep.

``fixplan view --plan`` and ``fixplan verify PLAN`` read a plan file with :func:`read_plan` (or
:func:`plan_for_fixture` on an object): the object is checked against the format, then against
the fixture (:func:`check_names`, :func:`check_starts_at`, :func:`check_plan_claims`) before it
is replayed. :func:`knot_timeline` makes a timeline of a plan's knot poses.

The plan's types (:class:`Plan`, :class:`PlannedTransition`, :class:`TriedTransition`,
:class:`Verification`, :class:`Timeline`) and their JSON form are :mod:`fixplan.planner.plan_types`';
every public name there is importable from here too, as it always was.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fixplan.contact_state import format_state
from fixplan.errors import InputError
from fixplan.planner.plan_types import (
    MAX_ISSUES_SHOWN,
    NOT_A_PLAN,
    STATUS_WORDS,
    Plan,
    PlannedTransition,
    ReadPose,
    Timeline,
    TriedTransition,
    Verification,
    _dimension_of,
    _names,
    _short,
    check_plan_document,
    execution_from_json,
    pose_from_json,
)
from fixplan.spatial import Pose

if TYPE_CHECKING:
    from fixplan.model import Fixture

FloatArray = NDArray[np.float64]

START_TOLERANCE_M = 1e-3  # a plan must start within this of the fixture's start pose ...
START_TOLERANCE_RAD = 1e-2  # ... and this rotation, else it is for another fixture


def _known_names(fixture: Fixture) -> tuple[list[str], list[str]]:
    """What a plan for ``fixture`` may name in its states, and the names of its verification's trace.

    A fixture of locators: its locators, both. With pins or bores (:mod:`.insertion_file`): the
    states also name the pins, the bores and each bore's bottom (``B1.bottom``), and the
    approach's ``staging``; the trace has a column per locator, pin and bore (the engine's).
    """
    locators = [loc.name for loc in fixture.locators]
    if not fixture.has_pins:
        return locators, locators
    from fixplan.planner.insertion import goal_state
    from fixplan.planner.insertion_file import APPROACH

    traced = locators + [p.name for p in fixture.pins] + [b.name for b in fixture.bores]
    return [*goal_state(fixture), APPROACH], traced  # the goal state names every one a state may


def check_names(data: Any, fixture: Fixture, source: str) -> None:
    """Refuse a plan object that names locators the fixture lacks (before parsing its poses)."""
    if not isinstance(data, dict) or not isinstance(data.get("transitions"), list) or "status" not in data:
        raise InputError(f"{source}: {NOT_A_PLAN}")
    known, traced = _known_names(fixture)
    mentioned: list[str] = []
    for i, tr in enumerate(data["transitions"]):
        if not isinstance(tr, dict):
            raise InputError(f"{source}: transitions[{i}]: expected an object, got {_short(tr)}")
        mentioned += [*_names(tr.get("from", []), f"{source}: transitions[{i}].from")]
        if "added" in tr:
            added = tr["added"]
            mentioned += _names(added if isinstance(added, list) else [added], f"{source}: transitions[{i}].added")
        for key in ("to", "lost"):
            if isinstance(tr.get(key), list):
                mentioned += _names(tr[key], f"{source}: transitions[{i}].{key}")
    for i, s in enumerate(data.get("sequence") or []):
        mentioned += _names(s, f"{source}: sequence[{i}]")
    for key in ("tried", "certificate"):
        for i, entry in enumerate(data.get(key) or []):
            if isinstance(entry, dict):
                mentioned += _names(entry.get("from", []), f"{source}: {key}[{i}].from")
                add = entry.get("add", [])
                mentioned += _names(add if isinstance(add, list) else [add], f"{source}: {key}[{i}].add")
    policy = data.get("policy")
    if isinstance(policy, list):
        for i, entry in enumerate(policy):
            if isinstance(entry, dict):
                mentioned += _names(entry.get("state", []), f"{source}: policy[{i}].state")
                if isinstance(entry.get("target"), str):
                    mentioned.append(entry["target"])
                for key in ("next", "together"):
                    if isinstance(entry.get(key), list):
                        mentioned += _names(entry[key], f"{source}: policy[{i}].{key}")
    verification = data.get("verification")
    if isinstance(verification, dict):
        for i, s in enumerate(verification.get("observed_sequence") or []):
            mentioned += _names(s, f"{source}: verification.observed_sequence[{i}]")
        if isinstance(verification.get("final_gaps"), dict):
            # a pin's or bore's gap is its axis offset at the end ("P1.axis_offset"): its name counts
            offsets = {f"{n}.axis_offset": n for n in traced if fixture.has_pins}
            mentioned += [offsets.get(k, k) for k in verification["final_gaps"]]
    trace = verification.get("trace") if isinstance(verification, dict) else None
    if trace is not None:
        if not isinstance(trace, dict):
            raise InputError(f"{source}: verification.trace: expected an object, got {_short(trace)}")
        names = _names(trace.get("names"), f"{source}: verification.trace.names")
        if names != traced:
            missing = [n for n in names if n not in traced] or [n for n in traced if n not in names]
            raise InputError(
                f"{source}: the plan is for another fixture: its trace has locators {', '.join(names)}, "
                f"{fixture.source} has {', '.join(traced)} (differing: {', '.join(missing) or 'order'})"
            )
    unknown = sorted(set(mentioned) - set(known))
    if unknown:
        raise InputError(
            f"{source}: the plan is for another fixture: it names locators {', '.join(unknown)} "
            f"that {fixture.source} does not have (it has {', '.join(traced)})"
        )


def check_starts_at(first: Pose, fixture: Fixture, source: str) -> None:
    """Refuse a plan whose first pose is not the fixture's start pose (within the start tolerances)."""
    dp, dr = first.distance_to(fixture.start)
    if dp > START_TOLERANCE_M or dr > START_TOLERANCE_RAD:
        pos = ", ".join(f"{x:.4g}" for x in first.p_world)
        start = ", ".join(f"{x:.4g}" for x in fixture.start.p_world)
        raise InputError(
            f"{source}: the plan is for another fixture: it starts at ({pos}), {fixture.source} starts at "
            f"({start}) ({dp:.3g} m, {math.degrees(dr):.3g}° away; expected ≤ {START_TOLERANCE_M:g} m, "
            f"{math.degrees(START_TOLERANCE_RAD):.2g}°)"
        )


def plan_for_fixture(data: Any, fixture: Fixture, source: str = "plan") -> Plan:
    """A plan file's object read for ``fixture``: the same locators, dimension and start pose, and claims it can keep.

    Raises
    ------
    InputError
        Not a fixplan plan, malformed (every problem with its key path), for another fixture
        (other locator names, another dimension, or another start pose), or claiming what the
        fixture rules out (:func:`check_plan_claims`).
    """
    try:
        check_plan_document(data, source, fixture.dimension)
    except InputError:
        _check_same_fixture(data, fixture, source)  # "for another fixture" says more than its poses' widths
        raise
    check_names(data, fixture, source)
    plan = Plan.from_json(data, source=source, dimension=fixture.dimension, validated=True)
    trace = plan.verification.trace if plan.verification is not None else None
    if trace is not None:
        check_starts_at(trace.poses[0], fixture, source)
    # a solved plan's knots start at the start pose (a recording's transitions start where the
    # person first pressed a locator: its trace is where it started)
    if plan.transitions and plan.transitions[0].poses and plan.extras.get("source") != "haptic session":
        check_starts_at(plan.transitions[0].poses[0], fixture, source)
    check_plan_claims(plan, fixture, source)
    return plan


def _check_same_fixture(data: Any, fixture: Fixture, source: str) -> None:
    """Raise "the plan is for another fixture" when a malformed plan names other locators or is of the other dimension."""
    try:
        check_names(data, fixture, source)
        poses = [p for tr in data["transitions"] for p in tr.get("poses") or []]
        trace = (data.get("verification") or {}).get("trace")
        poses += trace["poses"][:1] if isinstance(trace, dict) else []
        dims = {_dimension_of(p) for p in poses}
    except InputError as exc:
        if "another fixture" in str(exc):
            raise
        return
    except (TypeError, KeyError, AttributeError, IndexError):  # a malformed plan: its own messages say why
        return
    if dims and dims != {fixture.dimension}:
        raise InputError(
            f"{source}: the plan is for another fixture: its poses are {'/'.join(f'{d}D' for d in sorted(dims))}, "
            f"{fixture.source} is {fixture.dimension}D"
        )


def check_plan_claims(plan: Plan, fixture: Fixture, source: str) -> None:
    """Refuse a plan whose claims ``fixture`` rules out, before it is replayed.

    - every push it names (a transition's mean wrench, a policy's, a recording's pushes) is within
      the hand's limits (``manipulator.max_force``, ``max_torque``; :meth:`~fixplan.model.Fixture.hand_limits`);
    - a solved plan (not infeasible): its sequence starts in the state the part starts in (the
      locators touching at the start pose) and ends with every locator; its transitions are that
      sequence's steps, each closing its ``added`` locators; its knot poses start at the start
      pose, follow on from one transition to the next and stay in the fixture's neighbourhood
      (the executor's divergence bound);
    - a solved plan for a fixture with pins or bores: the staged insertion's states, stages, axis
      and located pose (:func:`~.insertion_file.check_insertion_claims`), its seating push within
      the hand's limits, and the same knots.

    Raises :class:`InputError` naming the key and what was expected.
    """
    from fixplan.settings import DEFAULT

    F_max, T_max, _ = fixture.hand_limits()
    slack = 1.0 + DEFAULT.plan_file.limit_rel
    d = fixture.dimension

    def within_limits(w: FloatArray | None, where: str) -> None:
        if w is None:
            return
        force, torque = float(np.linalg.norm(w[:d])), float(np.linalg.norm(w[d:]))
        if force > F_max * slack or torque > T_max * slack:
            raise InputError(
                f"{source}: {where}: a push of {force:.4g} N, {torque:.4g} N·m (expected within the hand's limits "
                f"{F_max:.4g} N, {T_max:.4g} N·m of {fixture.source})"
            )

    for i, tr in enumerate(plan.transitions):
        within_limits(tr.wrench, f"transitions[{i}].wrench")
        pushes = tr.extras.get("pushes")
        if isinstance(pushes, dict):
            for k, w in enumerate(pushes.get("wrench") or []):
                within_limits(np.asarray(w, dtype=float), f"transitions[{i}].pushes.wrench[{k}]")
    where = plan.extras.get("where")
    if isinstance(where, dict) and where.get("push") is not None:
        within_limits(np.asarray(where["push"], dtype=float), "where.push")
    insertion = plan.extras.get("insertion")
    if isinstance(insertion, dict) and insertion.get("seat_wrench") is not None:
        within_limits(np.asarray(insertion["seat_wrench"], dtype=float), "insertion.seat_wrench")
    if plan.policy is not None:
        for i, entry in enumerate(plan.policy.to_json()):
            w = entry.get("wrench")
            within_limits(None if w is None else np.asarray(w, dtype=float), f"policy[{i}].wrench")
    if plan.extras.get("source") == "haptic session" or plan.status == "infeasible":
        return  # a recording claims what a person did: its replay judges it
    if fixture.has_pins:  # the staged insertion's states and stages, then the knots as for any plan
        from fixplan.planner.insertion_file import check_insertion_claims

        check_insertion_claims(plan, fixture, source, tolerance=(START_TOLERANCE_M, START_TOLERANCE_RAD))
        _check_knots(plan, fixture, source)
        return
    names = frozenset(loc.name for loc in fixture.locators)
    from fixplan.locating import start_state

    start = start_state(fixture)

    def state(s: Iterable[str]) -> str:
        return format_state(s, empty="{}")  # a plan file's messages spell the free state {}

    seq = [frozenset(s) for s in plan.sequence]
    if not start and seq and seq[0] and plan.transitions and not plan.transitions[0].from_state:
        seq = [frozenset(), *seq]  # a part that starts free: solve's sequence leaves out the free state
    if not seq or seq[0] != start:
        got = state(seq[0]) if seq else "[]"
        raise InputError(
            f"{source}: sequence[0]: got {got} (expected the state the part starts in, {state(start)}, "
            f"the locators touching at {fixture.source}'s start pose)"
        )
    if seq[-1] != names:
        raise InputError(
            f"{source}: sequence[{len(seq) - 1}]: got {state(seq[-1])} (expected every locator, {state(names)}: "
            f"a plan loads the part)"
        )
    if len(plan.transitions) != len(seq) - 1:
        raise InputError(
            f"{source}: transitions: got {len(plan.transitions)} (expected {len(seq) - 1}, one per step of the sequence)"
        )
    for i, tr in enumerate(plan.transitions):
        where = f"{source}: transitions[{i}]"
        if tr.added is None:
            raise InputError(f"{where}.added: missing (expected the locator the transition closes)")
        if frozenset(tr.from_state) != seq[i]:
            raise InputError(f"{where}.from: got {state(tr.from_state)} (expected sequence[{i}], {state(seq[i])})")
        after = frozenset(tr.from_state) | set(tr.added_names)
        if after != seq[i + 1] or frozenset(tr.to_state) != after or set(tr.added_names) & set(tr.from_state):
            raise InputError(
                f"{where}: {state(tr.from_state)} + {tr.added_label} → {state(tr.to_state)} (expected sequence[{i + 1}], "
                f"{state(seq[i + 1])}, from 'from' plus 'added')"
            )
    _check_knots(plan, fixture, source)


def _check_knots(plan: Plan, fixture: Fixture, source: str) -> None:
    """Refuse knot poses beyond the fixture's neighbourhood, or a transition that does not start where the last ended."""
    from fixplan.planner.execute import DivergenceGuard

    guard = DivergenceGuard.for_fixture(fixture)
    previous: Pose | None = None
    for i, tr in enumerate(plan.transitions):
        for k, pose in enumerate(tr.poses):
            away = float(np.linalg.norm(pose.p_world - guard.home_world))
            if away > guard.far_m:
                raise InputError(
                    f"{source}: transitions[{i}].poses[{k}].position: {away:.3g} m from the start "
                    f"(expected within {guard.far_m:.3g} m, the fixture's neighbourhood)"
                )
        if tr.poses and previous is not None:
            dp, dr = tr.poses[0].distance_to(previous)
            if dp > START_TOLERANCE_M or dr > START_TOLERANCE_RAD:
                raise InputError(
                    f"{source}: transitions[{i}].poses[0]: {dp:.3g} m, {math.degrees(dr):.3g}° from where "
                    f"transitions[{i - 1}] ends (expected the same pose within {START_TOLERANCE_M:g} m, "
                    f"{math.degrees(START_TOLERANCE_RAD):.2g}°)"
                )
        if tr.poses:
            previous = tr.poses[-1]


def read_plan(path: Path, fixture: Fixture | None = None, *, expected: str | None = None) -> Plan:
    """Read a plan file; with ``fixture``, check that the plan belongs to it (:func:`plan_for_fixture`)."""
    from fixplan.files import read_plan_json

    data = read_plan_json(Path(path), expected=expected or "a plan JSON written by 'fixplan solve --out'")
    if fixture is None:
        return Plan.from_json(data, source=str(path))
    return plan_for_fixture(data, fixture, str(path))


def knot_timeline(plan: Plan, fixture: Fixture, source: str = "plan") -> Timeline:
    """The planned knot poses as a timeline: each transition's knots spread evenly over its duration.

    At a knot the pressed locators are the transition's ``from`` state (its last knot: with the
    added locator), the push is the transition's mean planned wrench, and the gaps are the exact
    locator gaps at the knot.
    """
    from fixplan.locating import locator_gaps

    times: list[float] = []
    poses: list[Pose] = []
    pressed: list[tuple[str, ...]] = []
    pushes: list[FloatArray] = []
    gaps: list[FloatArray] = []
    t0 = 0.0
    for i, tr in enumerate(plan.transitions):
        where = f"{source}: transitions[{i}]"
        if not tr.poses:
            raise InputError(f"{where}.poses: expected the planned knot poses, got []")
        wrench = np.zeros(fixture.ndof) if tr.wrench is None else tr.wrench
        before = tr.from_state
        after = tuple(sorted([*before, *tr.added_names])) if tr.added else before
        n = len(tr.poses)
        for k, pose in enumerate(tr.poses):
            if i > 0 and k == 0:
                continue  # the previous transition ended here
            poses.append(pose)
            times.append(t0 + (tr.time_s * k / (n - 1) if n > 1 else 0.0))
            pressed.append(after if k == n - 1 else before)
            pushes.append(wrench)
            gaps.append(locator_gaps(fixture.workpiece, pose, fixture.locators))
        t0 += tr.time_s
    names = tuple(loc.name for loc in fixture.locators)
    if not poses:
        return Timeline(names, np.zeros(0), (), (), gaps_m=np.zeros((0, len(names))))
    return Timeline(
        names,
        np.array(times),
        tuple(poses),
        tuple(pressed),
        gaps_m=np.array(gaps),
        coupling_wrench=np.array(pushes),
    )


__all__ = [
    "MAX_ISSUES_SHOWN",
    "NOT_A_PLAN",
    "START_TOLERANCE_M",
    "START_TOLERANCE_RAD",
    "STATUS_WORDS",
    "Plan",
    "PlannedTransition",
    "ReadPose",
    "Timeline",
    "TriedTransition",
    "Verification",
    "check_names",
    "check_plan_claims",
    "check_plan_document",
    "check_starts_at",
    "execution_from_json",
    "knot_timeline",
    "plan_for_fixture",
    "pose_from_json",
    "read_plan",
]
