"""The plan and its timeline: exact JSON round trips, strict JSON, and the knot timeline's closed form."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from conftest import PROBLEMS

import fixplan
from fixplan.errors import InputError
from fixplan.planner.plan import (
    Plan,
    PlannedTransition,
    Timeline,
    Verification,
    knot_timeline,
    plan_for_fixture,
    read_plan,
)
from fixplan.planner.solve import solve


def _strict(token: str) -> None:
    raise ValueError(f"non-standard JSON constant {token}")


def through_file(obj: dict) -> dict:
    """``obj`` written as strict JSON and parsed back (what a plan file holds)."""
    return json.loads(json.dumps(obj, allow_nan=False), parse_constant=_strict)


@pytest.fixture(scope="module")
def plate():
    return fixplan.load(PROBLEMS / "naive-order-jams.toml")


@pytest.fixture(scope="module")
def plate_result(jams_plan):
    """A 2D plan with a roll and a slide, verified in the haptic loop (``plate``'s)."""
    result = jams_plan
    assert result.ok and result.transitions, result.reason
    return result


@pytest.fixture(scope="module")
def box():
    return fixplan.load(PROBLEMS / "gen-box-321-s2026-000.toml")


@pytest.fixture(scope="module")
def box_unverified(box):
    """A 3D plan of three slides, not verified."""
    result = solve(box, run_verification=False)
    assert result.transitions
    return result


@pytest.fixture(scope="module")
def infeasible():
    result = solve(fixplan.load(PROBLEMS / "box-weak-hand.toml"))
    assert result.status == "infeasible" and result.certificate
    return result


@pytest.mark.parametrize("which", ["plate_result", "box_unverified", "infeasible"])
def test_a_solved_plan_round_trips_exactly(which, request):
    result = request.getfixturevalue(which)
    written = through_file(result.to_json())
    plan = Plan.from_json(written)
    assert plan.to_json() == written  # file → plan → file: the same JSON, to the last bit
    assert plan == result.plan  # and the same plan as the solver's
    again = Plan.from_json(through_file(plan.to_json()))
    assert again == plan and again.to_json() == written
    for tr_read, tr_solved in zip(plan.transitions, result.plan.transitions, strict=True):
        for p, q in zip(tr_read.poses, tr_solved.poses, strict=True):
            np.testing.assert_allclose(p.R_world_body, q.R_world_body, atol=1e-15)
            np.testing.assert_array_equal(p.p_world, q.p_world)


def test_a_verification_round_trips_exactly(plate_result, plate):
    v = plate_result.verification
    assert v is not None and v.trace is not None
    written = through_file(v.to_json())
    read = Verification.from_json(written, dimension=plate.dimension)
    assert read == v and read.to_json() == written
    # the timeline's arrays come back bit for bit
    t, r = v.trace, read.trace
    for name in ("time_s", "gaps_m", "normal_forces_N", "forces_world_N", "coupling_wrench", "felt_wrench"):
        np.testing.assert_array_equal(getattr(r, name), getattr(t, name))
    assert r.pressed == t.pressed and r.names == t.names and r.every_s == t.every_s
    assert Timeline.from_json(through_file(t.to_json())) == t
    # the executor's counts and events too
    assert read.execution is not None and read.execution.to_json() == v.execution.to_json()


def test_undefined_numbers_are_null(box_unverified):
    # a transition from no contact has nothing to press and nothing to slip (robustness inf)
    result = replace(box_unverified, friction_robustness=[math.inf] + box_unverified.friction_robustness[1:])
    first = replace(result.plan.transitions[0], margin_N=None, wrench=None)
    diverged = Verification(
        passed=False, reason="diverged", final_pose=None, max_penetration_m=1e-6, deadline_misses=None,
        tick_mean_us=None, tick_max_us=None, observed_sequence=[], final_gaps_m={}, duration_s=0.5,
        felt_force_max_N=None,
    )  # fmt: skip
    plan = replace(result.plan, transitions=(first, *result.plan.transitions[1:]), verification=diverged)
    data = json.loads(json.dumps(plan.to_json(), allow_nan=False), parse_constant=_strict)
    tr = data["transitions"][0]
    assert tr["friction_robustness"] is None and tr["margin"] is None and tr["wrench"] is None
    v = data["verification"]
    assert v["deadline_misses"] is None and v["tick_mean_us"] is None and v["final_pose"] is None
    assert data["proven"] is None  # proven is only said of an infeasible plan
    back = Plan.from_json(data)
    assert back == plan and back.transitions[0].margin_N is None and back.verification.deadline_misses is None


def test_the_plan_json_keys_are_the_cli_contract(box_unverified):
    data = box_unverified.to_json()
    assert list(data) == [
        "status", "reason", "sequence", "transitions", "tried", "proven", "certificate", "verification", "policy",
        "coverage", "timings",
    ]  # fmt: skip
    assert list(data["transitions"][0]) == [
        "from", "to", "added", "motion", "wrench", "margin", "friction_robustness", "time_s", "path_length_m",
        "max_constraint_violation_m", "solve_time_s", "poses", "peak_force_fraction", "peak_torque_fraction",
    ]  # fmt: skip


def test_knot_timeline_spreads_the_knots_evenly_and_touches_at_each_end(box_unverified, box):
    plan = box_unverified.plan
    tl = knot_timeline(plan, box)
    knots = [len(tr.poses) for tr in plan.transitions]
    assert len(tl) == sum(knots) - (len(knots) - 1)  # a transition starts where the one before ended
    ends = np.cumsum(plan.durations_s)
    k = 0
    for i, tr in enumerate(plan.transitions):
        n = len(tr.poses)
        t0 = 0.0 if i == 0 else ends[i - 1]
        times = tl.time_s[k : k + n] if i == 0 else tl.time_s[k - 1 : k - 1 + n]
        np.testing.assert_allclose(times, t0 + tr.time_s * np.arange(n) / (n - 1), rtol=0, atol=1e-12)
        last = k + n - 1 if i == 0 else k + n - 2
        # the added locator touches at the transition's last knot, and is pressed there
        assert tl.gaps_m[last, tl.names.index(tr.added)] == pytest.approx(0.0, abs=1e-6)
        assert tr.added in tl.pressed[last] and tr.added not in tl.pressed[last - 1]
        np.testing.assert_array_equal(tl.coupling_wrench[last], tr.wrench)
        k = last + 1
    assert tl.time_s[-1] == pytest.approx(math.fsum(plan.durations_s))


def test_a_plan_is_read_for_its_fixture_only(box_unverified, box, plate, tmp_path):
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(box_unverified.to_json()))
    assert read_plan(path, box) == box_unverified.plan
    with pytest.raises(InputError, match="another fixture: it names locators"):
        read_plan(path, plate)
    with pytest.raises(InputError, match="not a fixplan plan"):
        plan_for_fixture([1, 2], box, "x.json")
    bad = box_unverified.to_json()
    bad["transitions"][1]["wrench"] = [1.0, 2.0]
    with pytest.raises(InputError, match=r"transitions\[1\]\.wrench: got 2 numbers \(expected 6\)"):
        plan_for_fixture(through_file(bad), box, "x.json")


def test_a_transition_from_a_file_keeps_keys_it_does_not_model():
    obj = {
        "from": ["B1"],
        "to": ["B1", "B2"],
        "added": "B2",
        "motion": "slide",
        "wrench": [0.0, 0.0, 1.0],
        "time_s": 0.5,
        "poses": [{"position": [0.0, 0.1], "angle_deg": 3.0}],
        "pushes": {"time_s": [0.0], "wrench": [[0.0, 0.0, 1.0]]},
    }
    tr = PlannedTransition.from_json(obj)
    assert tr.extras == {"pushes": obj["pushes"]} and tr.margin_N is None
    back = tr.to_json()
    assert back["pushes"] == obj["pushes"] and back["poses"] == obj["poses"] and back["margin"] is None
