"""A pin insertion's policy: from every state the run can observe, what to do next, and how it recovers.

The staged insertion (:mod:`.insertion`) is one sequence of states: nothing engaged, the pins
engaged in their order, every pin engaged, seated (every rest pressed; a bore: on its bottom).
The run observes the state every tick (the engaged pins and bores from the pose, the pressed rests
from the engine's forces). With the part's pose in the hand off by more than the play it also
meets states the plan does not hold (a pin engaged before the one the plan expects, a pin lost as
the part levers about another) and stages that stall (a hole's chamfer caught on a pin, the part
wedged tilted on two pins). The policy (:func:`insertion_policy`, built with the plan) says, for
every observable state — which pins and bores are engaged, and with all of them engaged whether
the part is seated:

- **what to do** (:class:`PinPolicyEntry`): the stage to run from there (an insertion, the
  seating, holding) and the planned state it leads to. A state further along than the plan's
  current one goes on from there; one the plan does not hold (pins engaged out of order) runs the
  stage of the latest planned state it contains, and goes on to the first planned state that
  contains it;
- **how to recover** when that stage stalls (no progress along the axis for ``stall_s``) or a pin
  the run had engaged is lost: back off along the axis to the end of an earlier stage
  (:attr:`InsertionPolicy.backoff_heights_m`: the lowest at least ``backoff_min_m`` above the
  part at the first back-off, one higher at every further one, the staging pose at most),
  re-centre the guide on where the engaged holes are (:func:`recentre`), and run on down from
  there with the entry of the state observed at the top.

Within a budget: at most ``retries`` back-offs and re-entries, and ``time_s`` seconds from the
first; the run's time limit grows by at most ``time_s``. Then the run fails naming the pin that
did not go in, the stage and by how much it missed, and how many retries it spent. A run that
never stalls never consults it: its answer is the plan's.

**Re-centring** uses what the pose says once a pin is past both chamfers in its hole (its tip at
least ``c_hole + c_pin`` deep; a bore: the part past the bore's chamfer): the pin is then within
the play of the hole's axis, so the hole's place is the pin's to within the play. The guide's
line is moved by the round pin's (or bore's) offset from where the plan put its hole, and turned
about it by the diamond pin's offset along its lands (the direction the diamond locates); with
only the diamond seen, moved by its offset. With no pin past its chamfers the guide stays.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from fixplan.contact_state import State
from fixplan.settings import InsertionSettings
from fixplan.spatial import Pose, exp_so3

if TYPE_CHECKING:
    from fixplan.locating import Insert
    from fixplan.model import Fixture

FloatArray = NDArray[np.float64]
Action = Literal["insert", "seat", "hold"]
ACTIONS: tuple[str, ...] = ("insert", "seat", "hold")
MAX_ENUMERATED = 6  # inserts beyond this: the plan's own states only (2ⁿ subsets)


@dataclass(frozen=True)
class PinPolicyEntry:
    """What the run does in one observable state of a pin insertion.

    Attributes
    ----------
    engaged : tuple of str
        The pins and bores engaged (sorted); the rests pressed do not matter, except for
    seated : bool
        the goal: every pin and bore engaged, every rest pressed (a bore on its bottom): hold.
    transition : int or None
        The stage to run from here (an index into the plan's transitions; None: hold).
    action : {"insert", "seat", "hold"}
        The stage's kind.
    next : tuple of str
        The planned state it leads to (sorted).
    """

    engaged: tuple[str, ...]
    seated: bool
    transition: int | None
    action: Action
    next: tuple[str, ...]

    def to_json(self) -> dict[str, Any]:
        return {
            "engaged": list(self.engaged),
            "seated": self.seated,
            "transition": self.transition,
            "action": self.action,
            "next": list(self.next),
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> PinPolicyEntry:
        t = data.get("transition")
        return cls(
            tuple(sorted(str(x) for x in data["engaged"])),
            bool(data["seated"]),
            None if t is None else int(t),
            data["action"],
            tuple(sorted(str(x) for x in data["next"])),
        )


@dataclass(frozen=True)
class InsertionPolicy:
    """The recovery of a staged insertion: an entry per observable state, the back-off heights and the budget.

    Attributes
    ----------
    entries : tuple of PinPolicyEntry
        One per observable state (module text).
    backoff_heights_m : tuple of float
        The heights above the located pose (along the axis) of the stages' ends a back-off rises
        to, ascending: the insertions' ends, then the staging pose.
    retries : int
        Back-offs and re-entries at most.
    time_s : float
        Seconds of recovery at most (from the first back-off); the run's time limit grows by this.
    backoff_min_m : float
        A back-off rises at least this far.
    """

    entries: tuple[PinPolicyEntry, ...]
    backoff_heights_m: tuple[float, ...]
    retries: int
    time_s: float
    backoff_min_m: float
    _index: dict[tuple[tuple[str, ...], bool], PinPolicyEntry] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        for e in self.entries:
            self._index[(e.engaged, e.seated)] = e

    def entry(self, engaged: State, seated: bool) -> PinPolicyEntry | None:
        """The entry of the state with ``engaged`` pins and bores (``seated``: and every rest pressed)."""
        return self._index.get((tuple(sorted(engaged)), seated))

    def backoff_height(self, height_m: float, escalation: int) -> float:
        """The height a back-off from ``height_m`` rises to: the lowest stage end ``backoff_min_m`` above it, ``escalation`` ends higher."""
        above = [h for h in self.backoff_heights_m if h >= height_m + self.backoff_min_m]
        if not above:
            return max(self.backoff_heights_m[-1], height_m + self.backoff_min_m)
        return above[min(escalation, len(above) - 1)]

    def to_json(self) -> dict[str, Any]:
        return {
            "retries": self.retries,
            "time_s": self.time_s,
            "backoff_min_m": self.backoff_min_m,
            "backoff_heights_m": [float(h) for h in self.backoff_heights_m],
            "entries": [e.to_json() for e in self.entries],
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> InsertionPolicy:
        return cls(
            tuple(PinPolicyEntry.from_json(e) for e in data["entries"]),
            tuple(float(h) for h in data["backoff_heights_m"]),
            int(data["retries"]),
            float(data["time_s"]),
            float(data["backoff_min_m"]),
        )


def insertion_policy(
    fixture: Fixture, states: list[State], kinds: list[str], ends_m: list[float], settings: InsertionSettings
) -> InsertionPolicy:
    """The policy of a staged insertion found on ``fixture``: an entry per observable state (module text).

    ``states``: the plan's, from the start; ``kinds``: each transition's stage (``free``, ``insert``,
    ``seat``); ``ends_m``: the height above the located pose each stage but the seating ends at.
    """
    from fixplan.locating import inserts

    names = [i.name for i in inserts(fixture)]
    goal = states[-1]
    entries: list[PinPolicyEntry] = []
    subsets: list[frozenset[str]]
    if len(names) <= MAX_ENUMERATED:
        subsets = [frozenset(c) for k in range(len(names) + 1) for c in itertools.combinations(names, k)]
    else:
        subsets = sorted({frozenset(s & set(names)) for s in states}, key=len)
    first = 1 if kinds and kinds[0] == "free" else 0  # the stages after the approach
    for engaged in subsets:
        # the latest planned state it holds (after the approach), and the first planned state holding it
        i = max((k for k in range(first, len(states) - 1) if states[k] <= engaged), default=None)
        if i is None:
            continue
        j = min(k for k in range(i + 1, len(states)) if states[k] >= engaged)
        kind = kinds[i]
        entries.append(
            PinPolicyEntry(tuple(sorted(engaged)), False, i, "seat" if kind == "seat" else "insert",
                           tuple(sorted(states[j])))
        )  # fmt: skip
    entries.append(PinPolicyEntry(tuple(sorted(set(names))), True, None, "hold", tuple(sorted(goal))))
    heights = sorted({float(h) for h in ends_m})
    return InsertionPolicy(
        tuple(entries), tuple(h for h in heights if h > 0.0), settings.retries, settings.recovery_time_s,
        settings.backoff_min_m,
    )  # fmt: skip


# -- re-centring the guide -------------------------------------------------------------------------------
def deep_m(fixture: Fixture, ins: Insert) -> float:
    """How far past its mouth an insert's tip must be for its side to be in the bore: both chamfers (a bore: its own)."""
    if ins.kind == "bore":
        return next(b for b in fixture.bores if b.name == ins.name).chamfer_m
    pin = next(p for p in fixture.pins if p.name == ins.name)
    return fixture.workpiece.hole(ins.hole).chamfer_m + pin.chamfer_m


def _bore_start_body(fixture: Fixture, pose: Pose, ins: Insert, depth_m: float) -> FloatArray:
    """The part's point (body frame) on the insert's axis where its bore begins, with the tip ``depth_m`` past the mouth.

    A pin: the point of its hole's axis at the chamfer's end (fixed in the part). A bore: the
    point of the part's own axis at the bore's chamfer's end now (the part is the peg).
    """
    from fixplan.locating import peg_body

    wp = fixture.workpiece
    if ins.kind != "bore":
        hole = wp.hole(ins.hole)
        return np.asarray(hole.p_body, dtype=float) - hole.chamfer_m * np.asarray(hole.axis_body, dtype=float)
    bore = next(b for b in fixture.bores if b.name == ins.name)
    peg = peg_body(wp, pose, bore)
    x = peg.base_world + (peg.length_m - (depth_m - bore.chamfer_m)) * peg.axis_world
    return pose.R_world_body.T @ (x - pose.p_world)


class Recentring:
    """Where the engaged holes were seen, past both chamfers: the offsets the guide is re-centred on (module text).

    ``world``'s pins and bores (their chamfers, which lead) with the plan's located pose ``goal``
    and axis ``u``: each insert's place is its hole's axis where the bore begins, at ``goal``
    (a bore: the part's axis there), normal to ``u``.
    """

    def __init__(self, world: Fixture, goal: Pose, u: FloatArray, inserts: list[Insert]):
        self.world, self.goal, self.u, self.inserts = world, goal, u, inserts
        self.offsets_m: dict[str, FloatArray] = {}  # insert -> its hole's lateral offset from its place
        self.places_m: dict[str, FloatArray] = {}
        for i in inserts:
            b = _bore_start_body(world, goal, i, _goal_depth(world, goal, i))
            self.places_m[i.name] = self._lateral(goal.point_world_from_body(b))

    def _lateral(self, x: FloatArray) -> FloatArray:
        return x - float(x @ self.u) * self.u

    def observe(self, pose: Pose, ins: Insert, depth_m: float) -> None:
        """Record ``ins``'s hole at ``pose`` if its tip is ``depth_m`` past the mouth, past both chamfers."""
        if depth_m < deep_m(self.world, ins):
            return
        b = _bore_start_body(self.world, pose, ins, depth_m)
        self.offsets_m[ins.name] = self._lateral(pose.point_world_from_body(b) - self.goal.point_world_from_body(b))

    def guide(self) -> tuple[Pose, str]:
        """The plan's located pose re-centred on the offsets seen, and what it did (one line).

        The round pin (or bore) fixes where the part is, the diamond pin along its lands how it is
        turned about the round one: the guide moves by the round pin's offset when it was seen, and
        turns about its place by the diamond's offset along its lands, less that move.
        """
        seen = [i for i in self.inserts if i.name in self.offsets_m]
        if not seen:
            return self.goal, "no pin seen past its chamfers: the guide stays"
        rounds = [i for i in self.inserts if i.land_direction_world is None]
        base = rounds[0] if rounds else seen[0]
        t = self.offsets_m.get(base.name, np.zeros(3))
        pivot = self.places_m[base.name]
        theta = 0.0
        for i in seen:
            if i is base or i.land_direction_world is None:
                continue
            along = float(np.cross(self.u, self.places_m[i.name] - pivot) @ i.land_direction_world)
            if along != 0.0:
                theta = float((self.offsets_m[i.name] - t) @ i.land_direction_world) / along
        R = exp_so3(theta * self.u)
        G = self.goal
        moved = f"moved {np.linalg.norm(t) * 1e3:.3g} mm by {base.name}'s hole" if base.name in self.offsets_m else ""
        turned = f"turned {np.degrees(theta):.3g}° about {base.name}" if theta else ""
        what = "the guide " + ", ".join(x for x in (moved, turned) if x) if moved or turned else "the guide stays"
        return Pose(R @ G.R_world_body, pivot + R @ (G.p_world - pivot) + t), "re-centred: " + what


def _goal_depth(world: Fixture, goal: Pose, ins: Insert) -> float:
    from fixplan.locating import engagement

    return engagement(world, goal, ins).depth_m


__all__ = ["ACTIONS", "InsertionPolicy", "PinPolicyEntry", "Recentring", "deep_m", "insertion_policy"]
