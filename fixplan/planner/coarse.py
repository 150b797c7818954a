"""The coarse plan: a search over contact states, one locator more per transition (Section IV).

States are the sets of touched locators. From the state at the start pose, every transition adds
one locator (contacts increase monotonically) until all are touched — a lattice of at most 2ⁿ
states. Where geometry makes several locators touch at the same instant (a redundant layout: two
end locators one above the other, whose gaps any motion keeping the base seated changes alike),
the transition adds that *group* at once: ``group(state, target)`` names it (the fine planner's
rank test, :func:`~fixplan.planner.fine.closing_group`), the edge is named by the group's first
locator and leads to ``state ∪ group``, and no edge adds one of them alone. Each transition is
priced by a fine plan (``evaluate``): its cost, or a failure with the reason. Dijkstra's algorithm over the lattice finds the cheapest complete sequence; a fixed
``order`` restricts the search to that one sequence. The result records every transition that
was tried and why each failed, so a user can see why an order was not chosen.

A node's pose is the end pose of the cheapest transition that reached it (the state is settled
then), so later transitions start where the part really is.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from fixplan.contact_state import State, format_state
from fixplan.errors import InputError
from fixplan.settings import DEFAULT, PlannerSettings
from fixplan.spatial import Pose


class TransitionResult(Protocol):
    """What the coarse search needs from a fine plan."""

    @property
    def success(self) -> bool: ...

    @property
    def reason(self) -> str: ...

    @property
    def cost(self) -> float: ...

    @property
    def end_pose(self) -> Pose: ...


Evaluate = Callable[[Pose, State, str], TransitionResult]
# a cheap guess of a transition: (cost, end pose), or None when it is clearly impossible
Estimate = Callable[[Pose, State, str], "tuple[float, Pose] | None"]
# a cheap necessary check of a transition from the pose it would start at, before its fine plan:
# None when it passes, else why not (e.g. no non-jamming push at the first poses of the guess)
Precheck = Callable[[Pose, State, str], "str | None"]
# completes a priced transition whose fine plan stopped at the path (its wrenches searched only now,
# once its sequence is the chosen one): (pose, state, target, result) -> the completed result
Confirm = Callable[[Pose, State, str, Any], TransitionResult]
# the transitions a search is about to confirm, in order: (start pose, state, target, priced result)
Upcoming = Callable[[Sequence[tuple[Pose, State, str, Any]]], None]
# the locators a transition adds with ``target`` (sorted, ``target`` among them): ``(target,)`` unless
# geometry closes others at the same instant
Group = Callable[[State, str], "tuple[str, ...]"]


@dataclass(frozen=True)
class Attempt:
    """One transition the search priced."""

    established: tuple[str, ...]
    target: str
    success: bool
    cost: float
    reason: str
    # "fine": its fine plan was run; "precheck": only the cheap check before it, which failed (the
    # transition was then tried after the others, and appears again if it was fine-planned);
    # "path": its fine path was found, the pushes along it are searched only if its sequence is chosen
    stage: str = "fine"
    together: tuple[str, ...] = ()  # the locators added with the target (closing together with it)
    # where the hand is too weak: the least factor one of its limits must grow by (None otherwise)
    needed_scale: float | None = None

    @property
    def added(self) -> tuple[str, ...]:
        return (self.target, *self.together)


@dataclass
class CoarsePlan:
    """The chosen sequence of states, the fine plans along it, and everything that was tried."""

    found: bool
    sequence: list[tuple[str, ...]]  # states from the first contact to all locators, one (group) more each step
    transitions: list[Any]  # the fine plans along the sequence
    cost: float
    attempts: list[Attempt] = field(default_factory=list)
    reason: str = ""


def _key(state: State) -> tuple[str, ...]:
    return tuple(sorted(state))


def _single(state: State, target: str) -> tuple[str, ...]:
    return (target,)


def _together(group: Group, state: State, target: str) -> tuple[str, ...]:
    """The locators added with ``target`` (not ``target`` itself)."""
    return tuple(n for n in group(state, target) if n != target)


def _leads(group: Group, state: State, goal: State) -> list[str]:
    """The targets out of ``state``: each locator not touched yet, one per group (its first)."""
    return [t for t in sorted(goal - state) if min(group(state, t)) == t]


def search(
    start_state: State,
    all_locators: Sequence[str],
    start_pose: Pose,
    evaluate: Evaluate,
    *,
    order: Sequence[str] | None = None,
    progress: Callable[[Attempt], None] | None = None,
    estimate: Estimate | None = None,
    precheck: Precheck | None = None,
    group: Group | None = None,
    confirm: Confirm | None = None,
    upcoming: Upcoming | None = None,
    settings: PlannerSettings = DEFAULT.planner,
) -> CoarsePlan:
    """Cheapest monotone sequence of contact states from ``start_state`` to all locators.

    With ``estimate`` the search is *lazy* (LazySP): Dijkstra runs on estimated costs, only the
    transitions on the current best sequence are fine-planned (``evaluate``), in order, and the
    search repeats with what was learned until the best sequence is made of evaluated
    transitions only. Without it every transition out of a settled state is evaluated.

    ``precheck`` (lazy search only) is run on a transition of the best sequence before its fine
    plan; one that fails it is not dropped but made ``settings.precheck_penalty`` times dearer, so the
    search first tries the sequences that pass and still fine-plans this one when they all fail.

    ``group`` names the locators a transition adds with its target (default: the target alone);
    a fixed ``order`` must then name a group's locators one after the other.

    ``confirm`` (lazy search only): ``evaluate`` may price a transition by its path alone (a
    result with ``wrenches_checked`` False); once a sequence made of priced transitions is the
    best one, ``confirm`` completes each of them in order (the pushes along the path), and a
    failure sends the search on as any failed transition does. The pushes of transitions priced
    and then left are never searched. ``upcoming`` is told, before each such round of
    confirmations, which transitions it will confirm (a caller may start on the later ones on
    another core).
    """
    grp = group or _single
    if estimate is not None and order is None:
        return _lazy_search(
            start_state, all_locators, start_pose, evaluate, estimate, progress, precheck, grp, confirm, upcoming,
            settings,
        )  # fmt: skip
    goal: State = frozenset(all_locators)
    unknown = start_state - goal
    if unknown:
        raise InputError(f"start state names unknown locators: {', '.join(sorted(unknown))}")
    if order is not None:
        order = list(order)
        missing = goal - start_state - set(order)
        extra = [n for n in order if n not in goal]
        if extra:
            raise InputError(
                f"solve.order names unknown locators: {', '.join(extra)} (known: {', '.join(all_locators)})"
            )
        if len(set(order)) != len(order):
            raise InputError(f"solve.order repeats a locator: {','.join(order)}")
        already = [n for n in order if n in start_state]
        if already:
            raise InputError(f"solve.order names locators already touching at the start: {', '.join(already)}")
        if missing:
            raise InputError(
                f"solve.order leaves out {', '.join(sorted(missing))} (expected every locator not touching at the start)"
            )
    attempts: list[Attempt] = []

    def evaluated(state: State, target: str, pose: Pose) -> tuple[float, Pose, Any] | None:
        result = evaluate(pose, state, target)
        if confirm is not None and not getattr(result, "wrenches_checked", True):
            result = confirm(pose, state, target, result)  # every transition out of a settled state counts
        _record(attempts, progress, state, target, result, _together(grp, state, target))
        return (float(result.cost), result.end_pose, result) if result.success else None

    def candidates(state: State) -> list[str]:
        if order is not None:
            i = len(state) - len(start_state)
            t = order[i]
            together = grp(state, t)
            if set(together) != set(order[i : i + len(together)]):
                # geometry closes these at the same instant: the order must name them together
                why = (
                    f"{', '.join(together)} close together from {format_state(state, empty='{}')} "
                    f"(a redundant layout): solve.order must name them one after the other"
                )
                _log(attempts, progress, Attempt(_key(state), t, False, float("inf"), why))
                return []
            return [t]
        return _leads(grp, state, goal)

    path = _dijkstra(start_state, goal, start_pose, evaluated, candidates, grp)
    if path is None:
        return CoarsePlan(False, [], [], float("inf"), attempts, _no_sequence(attempts))
    transitions = [result for _, _, result in path]
    return _plan(start_state, path, transitions, attempts, grp)


def _record(
    attempts: list[Attempt],
    progress: Callable[[Attempt], None] | None,
    state: State,
    target: str,
    result: Any,
    together: tuple[str, ...] = (),
) -> None:
    _log(
        attempts,
        progress,
        Attempt(
            _key(state), target, bool(result.success), float(result.cost) if result.success else float("inf"),
            result.reason, "fine" if getattr(result, "wrenches_checked", True) else "path", together,
            getattr(result, "needed_scale", None),
        ),
    )  # fmt: skip


def _log(attempts: list[Attempt], progress: Callable[[Attempt], None] | None, attempt: Attempt) -> None:
    attempts.append(attempt)
    if progress is not None:
        progress(attempt)


def _no_sequence(attempts: list[Attempt]) -> str:
    """Why no sequence: the least demanding failure where the hand is too weak, else the last one.

    A transition the hand is too weak for carries the least factor its limits must grow by
    (:attr:`Attempt.needed_scale`); of those that failed, the one needing the least is the one a
    stronger hand would unlock first, and its reason names the force or torque it needs and the
    limit that binds.
    """
    failures = [a for a in attempts if not a.success and a.stage == "fine"]
    reason = "no sequence of transitions reaches every locator"
    if not failures:
        return reason
    weak = [a for a in failures if a.needed_scale is not None]
    if weak:
        least = min(weak, key=lambda a: a.needed_scale)  # type: ignore[arg-type, return-value]
        what = "{" + ", ".join(least.added) + "}" if least.together else least.target
        return (
            reason + f"; of the failed transitions the least demanding is: adding {what} to "
            f"{{{', '.join(least.established)}}} fails: {least.reason}"
        )
    last = failures[-1]
    what = "{" + ", ".join(last.added) + "}" if last.together else last.target
    return reason + f"; e.g. adding {what} to {{{', '.join(last.established)}}} fails: {last.reason}"


Weight = Callable[[State, str, Pose], "tuple[float, Pose, Any] | None"]


def _dijkstra(
    start_state: State,
    goal: State,
    start_pose: Pose,
    weight: Weight,
    candidates: Callable[[State], list[str]],
    group: Group = _single,
) -> list[tuple[State, str, Any]] | None:
    """Cheapest path through the lattice: ``(state, target, payload)`` per transition, or None.

    ``weight(state, target, pose)`` gives a transition's cost, end pose and payload (None: no
    such transition); a state's pose is the end pose of the cheapest transition that reached it.
    A transition leads to ``state ∪ group(state, target)``. Ties are broken by the sorted state
    names (deterministic).
    """
    best: dict[State, float] = {start_state: 0.0}
    came_from: dict[State, tuple[State, str, Any]] = {}
    pose_at: dict[State, Pose] = {start_state: start_pose}
    counter = itertools.count()
    queue: list[tuple[float, int, tuple[str, ...], State]] = [(0.0, next(counter), _key(start_state), start_state)]
    settled: set[State] = set()
    while queue:
        cost, _, _, state = heapq.heappop(queue)
        if state in settled:
            continue
        settled.add(state)
        if state == goal:
            break
        for target in candidates(state):
            w = weight(state, target, pose_at[state])
            if w is None:
                continue
            nxt = state | {target} | set(group(state, target))
            if nxt not in settled and cost + w[0] < best.get(nxt, float("inf")):
                best[nxt] = cost + w[0]
                came_from[nxt] = (state, target, w[2])
                pose_at[nxt] = w[1]
                heapq.heappush(queue, (cost + w[0], next(counter), _key(nxt), nxt))
    if goal not in settled:
        return None
    path = []
    node = goal
    while node != start_state:
        prev, target, payload = came_from[node]
        path.append((prev, target, payload))
        node = prev
    path.reverse()
    return path


def _plan(
    start_state: State,
    path: list[tuple[State, str, Any]],
    transitions: list[Any],
    attempts: list[Attempt],
    group: Group = _single,
) -> CoarsePlan:
    states = [start_state] + [s | {t} | set(group(s, t)) for s, t, _ in path]
    sequence = [_key(s) for s in states if s]  # the free state is not part of the sequence
    return CoarsePlan(True, sequence, transitions, float(sum(float(t.cost) for t in transitions)), attempts, "")


def _lazy_search(
    start_state: State,
    all_locators: Sequence[str],
    start_pose: Pose,
    evaluate: Evaluate,
    estimate: Estimate,
    progress: Callable[[Attempt], None] | None,
    precheck: Precheck | None = None,
    group: Group = _single,
    confirm: Confirm | None = None,
    upcoming: Upcoming | None = None,
    settings: PlannerSettings = DEFAULT.planner,
) -> CoarsePlan:
    """LazySP over the lattice: fine-plan only the transitions on the current best sequence."""
    goal: State = frozenset(all_locators)
    unknown = start_state - goal
    if unknown:
        raise InputError(f"start state names unknown locators: {', '.join(sorted(unknown))}")
    attempts: list[Attempt] = []
    done: dict[tuple[State, str], Any] = {}  # evaluated transitions
    guessed: dict[tuple[State, str], tuple[float, Pose] | None] = {}
    prechecked: set[tuple[State, str]] = set()
    suspect: set[tuple[State, str]] = set()  # transitions whose cheap check failed

    def weight(state: State, target: str, pose: Pose) -> tuple[float, Pose, Any] | None:
        key = (state, target)
        if key in done:
            r = done[key]
            return (float(r.cost), r.end_pose, None) if r.success else None
        if key not in guessed:
            guessed[key] = estimate(pose, state, target)
        g = guessed[key]
        return None if g is None else (g[0], g[1], None)

    def cost_of(path: list[tuple[State, str, Any]]) -> float:
        """The path's cost: evaluated costs where known, estimates elsewhere (inf: a failed transition)."""
        total, pose = 0.0, start_pose
        for state, target, _ in path:
            w = weight(state, target, pose)
            if w is None:
                return float("inf")
            total, pose = total + w[0], w[1]
        return total

    def best() -> tuple[list[tuple[State, str, Any]] | None, float]:
        path = _dijkstra(start_state, goal, start_pose, weight, lambda state: _leads(group, state, goal), group)
        return path, (float("inf") if path is None else cost_of(path))

    slack = settings.lazy_slack
    # each round evaluates or prechecks at least one transition (at most n·2ⁿ⁻¹ of each)
    for _ in range(4 * 2 ** len(goal) + len(goal) * 2 ** len(goal)):
        # Dijkstra on evaluated costs where known, estimates elsewhere
        path, _ = best()
        if path is None:
            return CoarsePlan(False, [], [], float("inf"), attempts, _no_sequence(attempts))
        # evaluate the path's transitions in order, from where the part really is
        pose = start_pose
        complete = True
        for state, target, _ in path:
            key = (state, target)
            if key not in done:
                if precheck is not None and key not in prechecked:
                    prechecked.add(key)
                    guess = guessed.get(key)
                    why = None if guess is None else precheck(pose, state, target)
                    if guess is not None and why is not None:
                        suspect.add(key)
                        # the cheap check fails: try the other sequences first, this one later
                        guessed[key] = (
                            max(settings.precheck_penalty * guess[0], guess[0] + settings.precheck_floor),
                            guess[1],
                        )
                        _log(
                            attempts, progress,
                            Attempt(_key(state), target, False, float("inf"), why, "precheck",
                                    _together(group, state, target)),
                        )  # fmt: skip
                        complete = False
                        break
                result = evaluate(pose, state, target)
                if confirm is not None and key in suspect and not getattr(result, "wrenches_checked", True):
                    # its cheap check failed: the pushes along the path are likely to fail too, so
                    # they are searched now rather than after the sequences that build on it
                    result = confirm(pose, state, target, result)
                done[key] = result
                _record(attempts, progress, state, target, result, _together(group, state, target))
                guess = guessed.get(key)
                if not result.success:
                    complete = False
                    break
                if guess is not None and float(result.cost) > slack * guess[0] + DEFAULT.numerics.zero_rel:
                    # dearer than guessed: go on with this sequence only while it stays the best one
                    # now, counting the fine costs learned so far (within lazy_slack); re-ranking at
                    # every dearer transition fine-planned most of the lattice from near the goal,
                    # where every estimate is a few millimetres (60 fine plans for one free-start
                    # box, 31 now). Scaling the estimates by the learned ratio of fine cost to
                    # estimate halved that again but accepted dearer sequences: a narrow generated
                    # box (box-321 seed 101, 026) then slid to E1 first and tipped off its base
                    _, b = best()
                    if cost_of(path) > slack * b + DEFAULT.numerics.zero_rel:
                        complete = False
                        break
            pose = done[key].end_pose
        if complete and confirm is not None:
            # the best sequence is priced: complete its transitions (the pushes along each path)
            if upcoming is not None:
                todo, pose = [], start_pose
                for state, target, _ in path:
                    if not getattr(done[(state, target)], "wrenches_checked", True):
                        todo.append((pose, state, target, done[(state, target)]))
                    pose = done[(state, target)].end_pose
                upcoming(todo)
            pose = start_pose
            for state, target, _ in path:
                key = (state, target)
                if not getattr(done[key], "wrenches_checked", True):
                    done[key] = confirm(pose, state, target, done[key])
                    _record(attempts, progress, state, target, done[key], _together(group, state, target))
                    if not done[key].success:
                        complete = False
                        break
                pose = done[key].end_pose
        if complete:
            return _plan(start_state, path, [done[(s, t)] for s, t, _ in path], attempts, group)
    return CoarsePlan(False, [], [], float("inf"), attempts, "the lazy search did not settle (too many rounds)")
