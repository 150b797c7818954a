"""The coarse search on a scripted evaluator: cheapest order, forbidden transitions, fixed orders, reasons."""

from dataclasses import dataclass

import numpy as np
import pytest

from fixplan.errors import InputError
from fixplan.planner.coarse import search
from fixplan.spatial import Pose

START = Pose.identity(3)


@dataclass(frozen=True)
class Fake:
    success: bool
    reason: str
    cost: float
    end_pose: Pose


def scripted(costs, forbidden=()):
    """Cost of adding a locator depends only on (state, target); some transitions jam."""

    def evaluate(pose, state, target):
        key = (tuple(sorted(state)), target)
        if key in forbidden:
            return Fake(False, f"adding {target} jams (margin < 0)", 0.0, pose)
        return Fake(
            True,
            "",
            costs.get(target, 1.0) * (1.0 + 0.1 * len(state)),
            Pose(pose.R_world_body, pose.p_world + np.array([0.0, 0.0, 1.0])),
        )

    return evaluate


def test_cheapest_order_is_found_and_poses_chain():
    """B2 then C costs 1.0·1.1 + 5.0·1.2 = 7.1; C then B2 costs 5.0·1.1 + 1.0·1.2 = 6.7: C first."""
    plan = search(frozenset({"B1"}), ["B1", "B2", "C"], START, scripted({"B2": 1.0, "C": 5.0}))
    assert plan.found
    assert plan.sequence == [("B1",), ("B1", "C"), ("B1", "B2", "C")]
    assert plan.cost == pytest.approx(6.7)
    # each transition started where the previous one ended
    assert plan.transitions[-1].end_pose.p_world[2] == pytest.approx(2.0)


def test_naive_order_jams_and_another_is_found():
    """The cheaper order (C first) jams at its second transition; the planner takes B2 first."""
    forbidden = {(("B1", "C"), "B2")}
    plan = search(frozenset({"B1"}), ["B1", "B2", "C"], START, scripted({"B2": 1.0, "C": 5.0}, forbidden))
    assert plan.found and plan.sequence[1] == ("B1", "B2")
    assert plan.cost == pytest.approx(7.1)
    assert any(
        not a.success and a.target == "B2" and a.established == ("B1", "C") and "jams" in a.reason
        for a in plan.attempts
    )


def test_fixed_order_failure_names_the_transition():
    forbidden = {(("B1", "C"), "B2")}
    plan = search(frozenset({"B1"}), ["B1", "B2", "C"], START, scripted({}, forbidden), order=["C", "B2"])
    assert not plan.found
    assert "adding B2 to {B1, C} fails" in plan.reason and "jams" in plan.reason


def test_bad_orders_are_input_errors():
    ev = scripted({})
    with pytest.raises(InputError, match="leaves out"):
        search(frozenset(), ["A", "B"], START, ev, order=["A"])
    with pytest.raises(InputError, match="unknown"):
        search(frozenset(), ["A", "B"], START, ev, order=["A", "Z"])
    with pytest.raises(InputError, match="already touching"):
        search(frozenset({"A"}), ["A", "B"], START, ev, order=["A", "B"])


def test_lattice_is_searched_deterministically():
    runs = [search(frozenset(), ["A", "B", "C"], START, scripted({"A": 1.0, "B": 1.0, "C": 1.0})) for _ in range(3)]
    assert all(r.sequence == runs[0].sequence for r in runs)
    assert runs[0].sequence[0] == ("A",)


def _exact_estimate(costs):
    """A lazy-search estimate equal to the scripted cost (so only the precheck reorders)."""

    def estimate(pose, state, target):
        return costs.get(target, 1.0) * (1.0 + 0.1 * len(state)), Pose(
            pose.R_world_body, pose.p_world + np.array([0.0, 0.0, 1.0])
        )

    return estimate


def _counting(evaluate):
    calls = []

    def wrapped(pose, state, target):
        calls.append((tuple(sorted(state)), target))
        return evaluate(pose, state, target)

    return wrapped, calls


def test_a_failed_precheck_reorders_the_lazy_search_before_any_fine_plan():
    """C-then-B2 (6.7) is cheapest, but adding B2 to {B1, C} fails its cheap check and would jam.

    With the precheck the search fine-plans B2-then-C (7.1) and never the jamming transition:
    3 fine plans (B1→C is learned first, then B1→B2, B1,B2→C) instead of 4 without it.
    """
    costs = {"B2": 1.0, "C": 5.0}
    jam = (("B1", "C"), "B2")
    for precheck, expected_calls in ((None, 4), (lambda p, s, t: "jams" if (tuple(sorted(s)), t) == jam else None, 3)):
        evaluate, calls = _counting(scripted(costs, forbidden={jam}))
        plan = search(
            frozenset({"B1"}), ["B1", "B2", "C"], START, evaluate,
            estimate=_exact_estimate(costs), precheck=precheck,
        )  # fmt: skip
        assert plan.found and plan.sequence == [("B1",), ("B1", "B2"), ("B1", "B2", "C")]
        assert plan.cost == pytest.approx(7.1)
        assert len(calls) == expected_calls
        assert (jam in calls) == (precheck is None)


def test_a_failed_precheck_never_drops_a_transition():
    """The precheck is a guess: when every other sequence fails, the flagged one is still planned."""
    costs = {"B2": 1.0, "C": 5.0}
    flagged = (("B1", "C"), "B2")
    forbidden = {(("B1",), "B2")}  # B2 first is impossible: only C then B2 remains
    evaluate, calls = _counting(scripted(costs, forbidden=forbidden))
    plan = search(
        frozenset({"B1"}), ["B1", "B2", "C"], START, evaluate,
        estimate=_exact_estimate(costs), precheck=lambda p, s, t: "x" if (tuple(sorted(s)), t) == flagged else None,
    )  # fmt: skip
    assert plan.found and plan.sequence == [("B1",), ("B1", "C"), ("B1", "B2", "C")]
    assert flagged in calls


@dataclass(frozen=True)
class FakePath:
    """A transition priced by its path alone (``wrenches_checked`` False until confirmed)."""

    success: bool
    reason: str
    cost: float
    end_pose: Pose
    wrenches_checked: bool = False


def test_pushes_are_searched_only_along_the_chosen_sequence_and_a_failed_one_reroutes():
    """Paths price every transition; the pushes (``confirm``) run only on the best sequence.

    From {B1} to {B1, B2, C}: C-then-B2 costs 5.0·1.1 + 1.0·1.2 = 6.7, B2-then-C 7.1. With exact
    estimates the search prices C-then-B2's two paths and confirms them; B2-then-C is never
    confirmed. When the pushes of {B1, C} + B2 fail (a jam along its path), the search re-routes
    to B2-then-C (7.1), confirms its two transitions, and never confirms anything else.
    """
    costs = {"B2": 1.0, "C": 5.0}
    for push_fails, sequence, cost, confirmed in (
        (set(), [("B1",), ("B1", "C"), ("B1", "B2", "C")], 6.7, [(("B1",), "C"), (("B1", "C"), "B2")]),
        (
            {(("B1", "C"), "B2")},
            [("B1",), ("B1", "B2"), ("B1", "B2", "C")],
            7.1,
            [(("B1",), "C"), (("B1", "C"), "B2"), (("B1",), "B2"), (("B1", "B2"), "C")],
        ),
    ):
        scripted_eval = scripted(costs)

        def evaluate(pose, state, target, _s=scripted_eval):
            r = _s(pose, state, target)
            return FakePath(r.success, "a path", r.cost, r.end_pose)

        calls = []

        def confirm(pose, state, target, result, _fails=push_fails, _calls=calls):
            key = (tuple(sorted(state)), target)
            _calls.append(key)
            if key in _fails:
                return FakePath(False, "segment 0: every push jams", float("inf"), result.end_pose, True)
            return FakePath(True, "pushes found", result.cost, result.end_pose, True)

        plan = search(
            frozenset({"B1"}), ["B1", "B2", "C"], START, evaluate, estimate=_exact_estimate(costs), confirm=confirm
        )
        assert plan.found and plan.sequence == sequence
        assert plan.cost == pytest.approx(cost)
        assert calls == confirmed
        assert all(t.wrenches_checked and t.success for t in plan.transitions)
        stages = {(a.established, a.target): a.stage for a in plan.attempts}
        assert all(stages[k] == "fine" for k in confirmed)
