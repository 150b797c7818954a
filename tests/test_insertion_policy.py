"""A pin insertion's policy and its recovery (fixplan/planner/insertion_policy.py, the run in insertion.py).

The policy of the housing loaded from above in closed form (an entry per observable state, the
back-off heights from the engagement heights); a run that stalls, levered and wedged on both pins,
backs off, re-centres on the holes it saw and seats the part, counting the retry; with no budget
the same run fails naming the pin, the stage and the miss; a plan file carries the policy, ``verify``
checks it against the plan and still re-runs a file written before it (without recovery).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from conftest import PROBLEMS

import fixplan
from fixplan.cli import main
from fixplan.generate import generate_one
from fixplan.locating import inserts
from fixplan.planner.insertion import plan_insertion, verify_insertion
from fixplan.planner.insertion_policy import InsertionPolicy
from fixplan.robust import RobustSettings, draw_pin_world
from fixplan.settings import HAPTIC, InsertionSettings

LOAD = PROBLEMS / "housing-2-pins-load.toml"  # from above: approach, P1 (12 mm), P2 (10 mm), seat


def test_the_housing_s_policy_in_closed_form() -> None:
    """Every subset of {P1, P2} engaged, and seated; back-offs to the insertions' ends and the staging pose.

    P1 engages 12 mm above the located pose, P2 at 10 mm, each with 1.5 mm of chamfers: P1's
    insertion ends at max(12 − 1.5 − 0.5, (12 + 10)/2) = 11 mm, P2's at max(10 − 2, 5) = 8 mm; the
    staging pose is 2 mm above P1's tip, 14 mm. P2 engaged first (not in the plan) runs P1's
    insertion and goes on to {P1, P2}.
    """
    plan = plan_insertion(fixplan.load(LOAD))
    policy = plan.policy
    assert policy is not None
    assert policy.backoff_heights_m == pytest.approx((0.008, 0.011, 0.014), abs=1e-12)
    rows = {(e.engaged, e.seated): (e.transition, e.action, e.next) for e in policy.entries}
    goal = ("B1", "B2", "B3", "P1", "P2")
    assert rows == {
        ((), False): (1, "insert", ("P1",)),
        (("P1",), False): (2, "insert", ("P1", "P2")),
        (("P2",), False): (1, "insert", ("P1", "P2")),
        (("P1", "P2"), False): (3, "seat", goal),
        (("P1", "P2"), True): (None, "hold", goal),
    }
    # the first back-off rises to the lowest end 1 mm above the part, each further one an end higher
    assert policy.backoff_height(0.0095, 0) == pytest.approx(0.011)
    assert policy.backoff_height(0.0095, 1) == pytest.approx(0.014)
    assert policy.backoff_height(0.0095, 5) == pytest.approx(0.014)
    assert InsertionPolicy.from_json(json.loads(json.dumps(policy.to_json()))) == policy


def test_the_guide_re_centred_on_both_holes_is_the_world_s_located_pose() -> None:
    """Pins 0.4 mm and 0.3 mm off and turned 0.2°: the holes seen past their chamfers at the world's located pose give it back.

    The round pin's hole moves the guide by the shift; the diamond's offset along its lands, less
    that, over its lever about the round pin turns it: the guide is the world's located pose to
    within the play times the turn (0.1 mm × 3.5 mrad), far below a micrometre.
    """
    import math

    import numpy as np

    from fixplan.locating import engagement
    from fixplan.planner.insertion import shifted_world
    from fixplan.planner.insertion_policy import Recentring

    fixture = fixplan.load(LOAD)
    plan = plan_insertion(fixture)
    world = shifted_world(fixture, np.array([0.0004, -0.0003, 0.0]), math.radians(0.2))
    here = world.goal
    rc = Recentring(world, plan.goal, plan.axis_world, inserts(world))
    assert rc.guide()[1] == "no pin seen past its chamfers: the guide stays"
    for i in inserts(world):
        rc.observe(here, i, engagement(world, here, i).depth_m)
    guide, what = rc.guide()
    dp, dr = guide.distance_to(here)
    assert dp < 1e-6 and dr < 1e-6, (dp, dr)
    assert what == "re-centred: the guide moved 0.5 mm by P1's hole, turned 0.2° about P1"


@pytest.fixture(scope="module")
def levered():
    """plane-2-pins seed 2031 fixture 0 in robust's world 10: pins 0.31 mm and 0.13° off the plan's.

    The diamond pin P2 engages first with its hole off across its lands; its lands' ends ride the
    chamfer and lever the part 3° about P2; P1 enters tilted and the part wedges on both pins,
    29.3 mm above the located pose, in the seating.
    """
    fx = generate_one("plane-2-pins", 2031, 0)
    fixture = fixplan.loads(fx.toml_text)
    play = max(i.play_m for i in inserts(fixture))
    settings = RobustSettings(samples=20, seed=0, pose_sigma_m=3.0 * play, pose_sigma_deg=0.1)
    world, noise, _ = draw_pin_world(fixture, 10, settings)
    return fixture, world, noise


def test_a_wedged_run_backs_off_recentres_and_seats(levered) -> None:
    """One retry: back off to P2's insertion's end, the guide re-centred on the holes seen; P1 enters, the part seats."""
    fixture, world, noise = levered
    v = verify_insertion(world, plan_insertion(fixture), noise=noise)
    assert v.passed, v.reason
    ex = v.execution
    assert ex is not None and ex.counts["retries"] == 1 and ex.counts["stalls"] == 1
    (retry,) = [m for _, kind, m in ex.events if kind == "retry"]
    assert "stuck in transition 4 (the seating)" in retry and "P1 wedged in H1" in retry
    assert "back off to 36.7 mm above the located pose" in retry and "re-centred: the guide turned 0.18" in retry
    assert "° about P1" in retry  # P2 (the diamond) seen past its chamfers: its offset along its lands turns the guide
    assert v.max_penetration_m <= 1e-5
    assert ex.observed[-1] == ("B1", "B2", "B3", "P1", "P2")


def test_with_no_budget_the_run_fails_naming_the_pin_the_stage_and_the_miss(levered) -> None:
    """``retries = 0``: the same run fails in one line: P1 wedged in H1 in the seating, by how much, no retry left."""
    fixture, world, noise = levered
    settings = HAPTIC.with_(insertion=InsertionSettings(retries=0))
    v = verify_insertion(world, plan_insertion(fixture, settings), settings=settings, noise=noise)
    assert not v.passed
    ex = v.execution
    assert ex is not None and ex.failure_kind == "stall" and ex.counts["retries"] == 0
    assert "stuck in transition 4 (the seating)" in ex.reason
    assert "P1 wedged in H1: the hole's axis 0.2" in ex.reason and "mm off the pin's (play 0.0792 mm)" in ex.reason
    assert ex.reason.endswith("; 0 retries spent (the policy's budget)") and "\n" not in ex.reason


def test_a_plan_without_a_policy_fails_where_the_policy_recovers(levered) -> None:
    """The same plan with its policy taken away (a plan file written before it): the stage's stall is the end."""
    fixture, world, noise = levered
    plan = plan_insertion(fixture)
    plan.policy = None
    v = verify_insertion(world, plan, noise=noise)
    assert not v.passed and v.execution is not None and v.execution.failure_kind == "stall"
    assert "retries spent" not in v.reason


# -- the plan file ---------------------------------------------------------------------------------------
def _run(capsys, *args: object) -> tuple[int, str, str]:
    capsys.readouterr()
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def _solved(capsys, tmp_path: Path) -> tuple[Path, dict]:
    fixture = tmp_path / "fx" / LOAD.name
    fixture.parent.mkdir(exist_ok=True)
    shutil.copyfile(LOAD, fixture)
    plan = tmp_path / "load.json"
    rc, _, err = _run(capsys, "solve", fixture, "--out", plan)
    assert rc == 0, err
    return plan, json.loads(plan.read_text())


def test_solve_writes_the_policy_and_verify_takes_old_and_new_files(capsys, tmp_path) -> None:
    plan, data = _solved(capsys, tmp_path)
    policy = data["insertion"]["policy"]
    assert policy == plan_insertion(fixplan.load(LOAD)).policy.to_json()  # type: ignore[union-attr]
    rc, out, err = _run(capsys, "verify", plan, "--json")
    assert rc == 0 and json.loads(out)["passed"], err
    old = tmp_path / "old.json"  # a file written before the policy: no key, no recovery, still re-run
    del data["insertion"]["policy"]
    old.write_text(json.dumps(data))
    rc, out, err = _run(capsys, "verify", old, "--json")
    assert rc == 0 and json.loads(out)["passed"], err


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        (lambda e: e[1].update(engaged=["P7"]), "insertion.policy.entries[1].engaged: got {P7} (expected pins and bores"),
        (lambda e: e[1].update(transition=0), "insertion.policy.entries[1].transition: got 0 with action insert"),
        (lambda e: e[1].update(action="seat"), "insertion.policy.entries[1].transition: got 2 with action seat"),
        (lambda e: e[2].update(next=["P1"]), "insertion.policy.entries[2].next: got {P1} (expected a planned state"),
        (lambda e: e.append(dict(e[0])), "insertion.policy.entries[5]: {} twice (expected one entry per observable"),
        (lambda e: e[4].update(transition=3), "insertion.policy.entries[4]: got seated True, action hold, transition 3"),
    ],
)  # fmt: skip
def test_a_policy_that_is_not_the_plan_s_is_refused_in_one_line(capsys, tmp_path, edit, words) -> None:
    plan, data = _solved(capsys, tmp_path)
    edit(data["insertion"]["policy"]["entries"])
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(data))
    rc, out, err = _run(capsys, "verify", bad)
    assert rc == 2 and out == "", err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in err, err


def test_the_policy_s_format_is_checked_with_its_key_path(capsys, tmp_path) -> None:
    plan, data = _solved(capsys, tmp_path)
    data["insertion"]["policy"]["backoff_heights_m"] = [0.011, 0.008]
    data["insertion"]["policy"]["retries"] = -1
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(data))
    rc, _, err = _run(capsys, "verify", bad)
    assert rc == 2
    assert "insertion.policy.retries: got the number -1 (expected a non-negative integer)" in err


def test_robust_counts_the_insertion_policy_retries_per_world(levered) -> None:
    """``fixplan robust``'s outcome of that world says it took one retry (its JSON lists them)."""
    from fixplan.robust import run_sample

    fixture, _, _ = levered
    play = max(i.play_m for i in inserts(fixture))
    settings = RobustSettings(samples=20, seed=0, pose_sigma_m=3.0 * play, pose_sigma_deg=0.1)
    outcome = run_sample(10, fixture, frozenset(), [], settings)
    assert outcome["passed"] and outcome["retries"] == 1 and outcome["replans"] == 0
