"""What the scene page replays: a plan's timeline, or the start pose at rest.

:func:`read_plan` reads the JSON written by ``fixplan solve --out`` (or ``fixplan haptic
--record``) for a fixture and makes a :class:`Replay` of it (:func:`plan_replay`): the
verification trace when present (the simulated motion sampled every 10 ms, with the contact
forces), else the planned knot poses. :func:`rest_replay` is the scene without a plan: the start
pose with the contact forces that hold the part at rest under gravity
(:func:`fixplan.jamming.rest.rest_forces`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import FixplanError

if TYPE_CHECKING:
    from fixplan.model import Fixture
    from fixplan.planner.plan import Plan, Timeline
    from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Replay:
    """What the page shows: a :class:`~fixplan.planner.plan.Timeline` with where it comes from.

    Attributes
    ----------
    source : {"trace", "plan", "rest"}
        The simulated verification trace, the planned knot poses, or the start pose at rest.
    timeline : Timeline
        Poses over time, with the pressed locators, the contact forces on the workpiece (world
        axes [N]; None: not known) and the hand's push (``coupling_wrench``: force, moment about
        the body origin, world axes; None: not known).
    note : str
        One line for the title (what is shown, status).
    extra_forces : tuple of (point_world, force_world_N)
        Forces at explicit ``[[contact]]`` entries (rest only), drawn like locator forces.
    policy : tuple of str
        The plan's policy, one line per contact state (``{B1, B2} → +S1 (slide)``), and its
        coverage first; empty without one.
    """

    source: str
    timeline: Timeline
    note: str
    extra_forces: tuple[tuple[FloatArray, FloatArray], ...] = ()
    policy: tuple[str, ...] = ()

    def __len__(self) -> int:
        return len(self.timeline)

    @property
    def time_s(self) -> FloatArray:
        return self.timeline.time_s

    @property
    def poses(self) -> tuple[Pose, ...]:
        return self.timeline.poses

    @property
    def pressed(self) -> tuple[tuple[str, ...], ...]:
        return self.timeline.pressed

    @property
    def forces_world_N(self) -> FloatArray | None:
        return self.timeline.forces_world_N

    @property
    def push_wrench(self) -> FloatArray | None:
        return self.timeline.coupling_wrench


def read_plan(path: Path, fixture: Fixture) -> Replay:
    """Read a plan JSON (``fixplan solve --out``), check it belongs to ``fixture``, and replay it.

    Raises
    ------
    InputError
        The file is unreadable, not JSON, not a fixplan plan, malformed, or for another fixture
        (other locator names, another dimension, or another start pose).
    """
    from fixplan.planner.plan import read_plan as read

    return plan_replay(read(Path(path), fixture), fixture, str(path))


def replay_from_plan(data: Any, fixture: Fixture, source: str = "plan") -> Replay:
    """The replay of a plan file's JSON object (see :func:`read_plan`)."""
    from fixplan.planner.plan import plan_for_fixture

    return plan_replay(plan_for_fixture(data, fixture, source), fixture, source)


def policy_lines(plan: Plan) -> tuple[str, ...]:
    """The plan's policy as lines: its coverage, then one line per state (fewest contacts first)."""
    if plan.policy is None:
        return ()
    cov = plan.policy.coverage
    head = (
        f"policy: {cov.get('states_planned')} of {cov.get('states_reachable')} reachable contact states "
        "have a next transition with a non-jamming push"
    )
    rows = []
    for e in plan.policy.to_json():
        state = "{" + ", ".join(e["state"]) + "}" if e["state"] else "free"
        mark = "" if e["checked"] else " (no push found)"
        added = "{" + ", ".join([e["target"], *e["together"]]) + "}" if e.get("together") else e["target"]
        rows.append(f"{state} → +{added} ({e['motion']}, {e['source']}){mark}")
    return (head, *rows)


def plan_replay(plan: Plan, fixture: Fixture, source: str = "plan") -> Replay:
    """The replay of a plan: its verification trace when there is one, else its knot poses."""
    return replace(_plan_replay(plan, fixture, source), policy=policy_lines(plan))


def _plan_replay(plan: Plan, fixture: Fixture, source: str = "plan") -> Replay:
    from fixplan.planner.plan import STATUS_WORDS, knot_timeline

    v = plan.verification
    if v is not None and v.trace is not None:
        verdict = "passed" if v.passed else f"FAILED: {v.reason}"
        what = "haptic session" if plan.extras.get("source") == "haptic session" else "simulated verification"
        note = f"{what} ({verdict}), {len(v.trace)} samples, {v.trace.time_s[-1]:.2f} s"
        trace = _locator_columns(v.trace, fixture)
        if trace is not v.trace:
            note += "; the pins' and bores' forces are not drawn"
        return Replay("trace", trace, note)
    if plan.transitions:
        knots = knot_timeline(plan, fixture, source)
        note = (
            f"planned knot poses ({len(knots)} knots, {sum(plan.durations_s):.2f} s; no verification trace, "
            "so no contact forces)"
        )
        return Replay("plan", knots, note)
    words = STATUS_WORDS.get(plan.status, f"plan {plan.status}")
    note = f"{words}{': ' + plan.reason if plan.reason else ''} (nothing to replay)"
    return Replay("plan", _at_rest(fixture), note)


def _locator_columns(trace: Timeline, fixture: Fixture) -> Timeline:
    """``trace`` with the locators' columns only (the scene draws a force at each locator's tip).

    A trace of a fixture with pins or bores has a column per pin and bore too (their summed
    contact forces, with no point to draw them at): those are left out. Unchanged otherwise.
    """
    names = tuple(loc.name for loc in fixture.locators)
    if trace.names == names or not set(names) <= set(trace.names):
        return trace
    cols = [trace.names.index(n) for n in names]

    def pick(a: FloatArray | None) -> FloatArray | None:
        return None if a is None else a[:, cols]

    return replace(
        trace,
        names=names,
        gaps_m=pick(trace.gaps_m),
        normal_forces_N=pick(trace.normal_forces_N),
        forces_world_N=pick(trace.forces_world_N),
    )


def _at_rest(fixture: Fixture, forces_world_N: FloatArray | None = None) -> Timeline:
    """One sample at the start pose with the locators touching there."""
    from fixplan.locating import locator_contact
    from fixplan.planner.plan import Timeline

    tol = fixture.tolerances.touch_m
    pose = fixture.start
    touching = tuple(loc.name for loc in fixture.locators if locator_contact(fixture.workpiece, pose, loc).gap_m <= tol)
    names = tuple(loc.name for loc in fixture.locators)
    return Timeline(names, np.zeros(1), (pose,), (touching,), forces_world_N=forces_world_N)


def rest_replay(fixture: Fixture, *, forces: bool = True) -> Replay:
    """The start pose at rest: the locators touching there, and (``forces``) the contact forces under gravity.

    The forces are :func:`~fixplan.jamming.rest.rest_forces`: drawn when the part is ``held`` or
    ``jammed`` at rest, else the note says what gravity alone does.
    """
    replay = Replay("rest", _at_rest(fixture), "start pose")
    if not forces:
        return replay
    from fixplan.jamming.rest import rest_forces

    try:
        rest = rest_forces(fixture)
    except FixplanError as exc:
        return replace(replay, note=f"start pose (no rest forces: {exc})")
    if rest is None:
        return replace(replay, note="start pose (no contacts: nothing holds the part)")
    if rest.forces_world_N is None:
        return replace(replay, note=f"start pose (under gravity alone the part {rest.mode}: no rest forces)")
    return Replay(
        "rest",
        _at_rest(fixture, rest.forces_world_N[None]),
        f"start pose at rest under gravity ({rest.mode})",
        rest.extra_forces,
    )
