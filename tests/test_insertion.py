"""Planning and verifying the insertion onto pins and into a bore (fixplan/planner/insertion.py).

Closed forms and hand-derived verdicts: the engagement heights (a tip meets its mouth when the part
is the pin's length above the located pose), the engagement order, the seating push, the hole's
axis within the radial play (D − d)/2 of the pin's after the plan, a pin whose hole is out of reach
named in an infeasible plan, and a pose error captured by the chamfers or not.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from conftest import PROBLEMS, run_cli

import fixplan
from fixplan.errors import InputError
from fixplan.locating import axis_offsets_m, engagement, inserts, located_pose
from fixplan.planner.insertion import plan_insertion, shifted_world, verify_insertion
from fixplan.planner.solve import solve

HOUSING = PROBLEMS / "housing-2-pins.toml"
LOAD = PROBLEMS / "housing-2-pins-load.toml"
SHAFT = PROBLEMS / "shaft-into-bore.toml"
G_N = 2.0 * 9.81  # the housing's weight


def _load(path=LOAD):
    return fixplan.load(path)


def test_engagement_depth_and_offset_in_closed_form() -> None:
    """Lifted by h along the pins' axis, a tip is L − h past its mouth; P1's tip stands 0.1 mm off H1's axis."""
    fx = _load()
    G = fx.goal
    u = np.array([0.0, 0.0, 1.0])
    p1, p2 = inserts(fx)
    assert (p1.name, p2.name) == ("P1", "P2")  # the round pin first
    assert p1.play_m == pytest.approx(1e-4, abs=1e-15)  # (D − d)/2 = (10 − 9.8)/2 mm
    assert p1.capture_m == pytest.approx(1e-4 + 5e-4 + 1e-3, abs=1e-15)  # play + both chamfers
    for h in (0.0, 0.004, 0.0115, 0.013):
        e1, e2 = engagement(fx, G.translated(h * u), p1), engagement(fx, G.translated(h * u), p2)
        assert e1.depth_m == pytest.approx(0.012 - h, abs=1e-12)
        assert e2.depth_m == pytest.approx(0.010 - h, abs=1e-12)
        assert e1.offset_m == pytest.approx(1e-4, abs=1e-12) and e2.offset_m == pytest.approx(0.0, abs=1e-12)
        assert e1.engaged is (h < 0.012) and e2.engaged is (h < 0.010)
    # off by more than the capture: not engaged whatever the depth
    far = dataclasses.replace(G, p_world=G.p_world + np.array([0.002, 0.0, 0.0]))
    assert not engagement(fx, far, p1).engaged


def test_the_plan_engages_the_round_pin_then_the_diamond_then_seats() -> None:
    """Heights 12 mm (P1) and 10 mm (P2): P1 first; each insertion ends past both chamfers; the rests close together."""
    plan = plan_insertion(_load())
    assert plan.ok, plan.reason
    assert plan.order == [("P1",), ("P2",)]
    assert plan.heights_m == pytest.approx({"P1": 0.012, "P2": 0.010}, abs=1e-12)
    assert [s.kind for s in plan.stages] == ["free", "insert", "insert", "seat"]
    assert [tuple(sorted(s)) for s in plan.states] == [
        (), (), ("P1",), ("P1", "P2"), ("B1", "B2", "B3", "P1", "P2")
    ]  # fmt: skip
    z = [float(s.poses[-1].p_world[2]) - 0.015 for s in plan.stages]
    # staging 2 mm above P1's tip (12 mm); P1 in by c_h + c_p + 0.5 mm = 2 mm, but only halfway down to P2's
    # height (10 mm) so that P2 is not in yet: 11 mm; P2 in by its 2 mm: 8 mm; seated: 0
    assert z == pytest.approx([0.014, 0.011, 0.008, 0.0], abs=1e-12)
    staging = plan.stages[0].poses[-1]
    np.testing.assert_allclose(staging.R_world_body, np.eye(3), atol=1e-12)  # the start's roll taken out
    # while P2 enters, P1 slides on H1's -x wall (rim and mouth edge): a push without jamming, no wedging
    p2 = plan.stages[2]
    assert set(p2.contacts) == {"P1", "P1#2"} and p2.wedge_force is not None and p2.wedge_force < 1e-9
    assert p2.margin_N == pytest.approx(0.3 * G_N, rel=1e-6)  # pressed toward the seated side by 0.3 m g


def test_the_seating_push_is_hand_derived_and_held() -> None:
    """m g down through the centre, 0.3 m g toward P1's contact (+x: its normals are −x) through that contact.

    P1's rim (−0.045, 0, 0.011) and mouth edge (−0.045, 0, 0.0005) touch: the side push acts at their
    mean (−0.045, 0, 0.00575), lever (−0.045, 0, −0.00925) from the centre (0, 0, 0.015): moment
    (0, −0.00925 · 0.3 m g, 0). Held (as expected.toml's +x case).
    """
    plan = plan_insertion(_load())
    assert plan.ok, plan.reason
    np.testing.assert_allclose(plan.seat_wrench_com, [0.3 * G_N, 0.0, -G_N, 0.0, -0.00925 * 0.3 * G_N, 0.0], atol=1e-9)


def test_equal_pins_engage_together_round_first() -> None:
    """Pins of equal length meet their mouths at the same height: one transition, the round pin its target."""
    text = LOAD.read_text().replace("length = 0.010", "length = 0.012")
    plan = plan_insertion(fixplan.loads(text, source="equal.toml"))
    assert plan.ok, plan.reason
    assert plan.order == [("P1", "P2")]
    assert plan.stages[1].target == "P1" and plan.stages[1].together == ("P2",)


def test_a_pin_whose_hole_is_out_of_reach_is_named() -> None:
    """P2 moved 3 mm off H2 (beyond its 1.6 mm capture): infeasible, saying which pin and by how much."""
    fx = _load()
    p2 = fx.pins[1]
    moved = dataclasses.replace(p2, p_world=p2.p_world + np.array([0.003, 0.0, 0.0]))
    fx = dataclasses.replace(fx, pins=(fx.pins[0], moved))
    r = solve(fx)
    assert r.status == "infeasible" and r.verification is None
    assert (
        r.reason == "P2 cannot enter H2 at the located pose: its hole H2's axis is 3 mm from its tip (capture 1.6 mm)"
    )


def test_pins_that_are_not_parallel_are_refused_in_one_line() -> None:
    fx = _load()
    p2 = fx.pins[1]
    a = np.array([np.sin(0.05), 0.0, np.cos(0.05)])
    fx = dataclasses.replace(fx, pins=(fx.pins[0], dataclasses.replace(p2, axis_world=a)))
    with pytest.raises(InputError) as exc:
        plan_insertion(fx)
    assert "pin.P2.axis: the pins' axes differ" in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.slow
def test_solve_verifies_the_housing_and_the_holes_end_within_the_play() -> None:
    """Verified in the haptic loop: P1, then P2, then the rests; H1's axis (D − d)/2 = 0.1 mm from P1's, H2 on P2's lands."""
    fx = _load()
    r = solve(fx)
    assert r.status == "planned", r.reason
    v = r.verification
    assert v is not None and v.passed
    assert v.observed_sequence == [("P1",), ("P1", "P2"), ("B1", "B2", "B3", "P1", "P2")]
    assert max(abs(v.final_gaps_m[n]) for n in ("B1", "B2", "B3")) <= 1e-4
    assert v.max_penetration_m <= 1e-5
    pose = v.final_pose
    p1, p2 = inserts(fx)
    # seated toward +x: H1's axis lies the play from P1's (its wall touches), within the slack
    assert max(axis_offsets_m(fx, pose, p1)) == pytest.approx(1e-4, abs=2e-6)
    assert max(axis_offsets_m(fx, pose, p2)) <= 1e-4
    assert r.plan.to_json()["status"] == "planned"


@pytest.mark.slow
def test_a_pose_error_beyond_the_play_is_captured_by_the_chamfers() -> None:
    """The pins and rests 0.6 mm off the plan's (six times the play, within the 1.6 mm capture): verified."""
    fx = _load()
    world = shifted_world(fx, np.array([-0.0004, 0.00045, 0.0]), 0.0)
    v = verify_insertion(world, plan_insertion(fx))
    assert v.passed, v.reason
    assert max(axis_offsets_m(world, v.final_pose, inserts(world)[0])) == pytest.approx(1e-4, abs=2e-6)


@pytest.mark.slow
def test_a_pose_error_beyond_the_capture_fails_naming_the_pin() -> None:
    """The fixture 2.5 mm off (beyond play + chamfers): P1 lands on the part's face; the run says so in one line."""
    fx = _load()
    world = shifted_world(fx, np.array([0.0025, 0.0, 0.0]), 0.0)
    v = verify_insertion(world, plan_insertion(fx))
    assert not v.passed
    ex = v.execution
    assert ex is not None and ex.failure_kind in ("stall", "timeout")
    assert "P1 did not enter H1" in ex.reason and "beyond the capture 1.6 mm" in ex.reason
    assert "\n" not in ex.reason


def test_the_shaft_s_located_pose_in_closed_form() -> None:
    """Coaxial with the bore, its end 40 mm down on the bottom: centre (0, 0, −0.04 + 0.05), upright."""
    fx = fixplan.load(SHAFT)
    G = located_pose(fx)
    np.testing.assert_allclose(G.p_world, [0.0, 0.0, 0.01], atol=1e-12)
    np.testing.assert_allclose(G.R_world_body[:, 2], [0.0, 0.0, 1.0], atol=1e-12)
    (b,) = inserts(fx)
    assert b.play_m == pytest.approx(2e-5, abs=1e-15)
    assert engagement(fx, G, b).depth_m == pytest.approx(0.04, abs=1e-12)


@pytest.mark.slow
def test_the_shaft_enters_its_bore_from_a_tilted_start() -> None:
    """Straightened over the bore, inserted, seated on the bottom: coaxial within the 20 µm play."""
    fx = fixplan.load(SHAFT)
    r = solve(fx)
    assert r.status == "planned", r.reason
    v = r.verification
    assert v is not None
    assert v.observed_sequence == [("B1",), ("B1", "B1.bottom")]
    assert abs(v.final_gaps_m["B1.bottom"]) <= 1e-4
    assert v.final_gaps_m["B1.axis_offset"] <= 2e-5 * 1.05


COCKED = PROBLEMS / "shaft-in-bore.toml"


def test_a_shaft_cocked_in_its_bore_is_engaged() -> None:
    """Whitney's two-point contact 10 mm down (shaft-in-bore): the tip's centre is R − r cos θ off the axis, past the
    10 µm play by r (1 − cos θ) = 20 nm, and in; upright, 2 µm past the play (beyond the 1 µm contact tolerance),
    it is not (no chamfer to capture it)."""
    fx = fixplan.load(COCKED)
    (b,) = inserts(fx)
    assert b.capture_m == pytest.approx(1e-5, abs=1e-15)  # play, no chamfers
    theta = math.radians(0.11459140600859763)
    e = engagement(fx, fx.start, b)
    assert e.offset_m == pytest.approx(0.01001 - 0.01 * math.cos(theta), abs=1e-12)
    assert e.offset_m > b.capture_m and e.depth_m == pytest.approx(0.01, abs=1e-9)
    assert e.engaged
    G = located_pose(fx)
    side = dataclasses.replace(G, p_world=G.p_world + np.array([b.capture_m + 2e-6, 0.0, 0.0]))
    assert not engagement(fx, side, b).engaged


def test_a_shaft_cocked_in_its_bore_is_seated_from_where_it_is() -> None:
    """In past the chamfers at the start: no lift out of the bore (its place would be lost), the seating from there.

    On a world whose bore (with the shaft in it) is 30 µm off the plan's, three times the 10 µm play
    (what ``robust`` draws), the guide is re-centred on the bore seen at the start, and the shaft
    straightens and seats: its axis within the play, the bottom reached, the penetration within
    1e-5 m. Before, the plan lifted it out and aimed at the nominal bore: its end landed on the
    sharp mouth 20 µm beyond the play, and the side's overlap counted as the gap (2e-5 m and more).
    """
    fx = fixplan.load(COCKED)
    plan = plan_insertion(fx)
    assert plan.ok, plan.reason
    assert [st.kind for st in plan.stages] == ["seat"] and plan.start_state == {"B1"}
    # a back-off rises to the start: its centre (L/2) cos θ above the tip 10 mm down, the located centre 10 mm up
    theta = math.radians(0.11459140600859763)
    assert plan.policy is not None
    assert plan.policy.backoff_heights_m == pytest.approx([0.05 * math.cos(theta) - 0.02], abs=1e-9)
    world = shifted_world(fx, np.array([3e-5, -1e-5, 0.0]), 0.001, with_start=True)
    v = verify_insertion(world, plan)
    assert v.passed, v.reason
    assert v.final_gaps_m["B1.axis_offset"] <= 1e-5 * 1.05
    assert abs(v.final_gaps_m["B1.bottom"]) <= 1e-4
    assert v.max_penetration_m <= 1e-5
    assert "re-centred: the guide moved" in v.execution.events[0][2]


def test_cli_verify_re_runs_the_seating_of_a_cocked_shaft(tmp_path) -> None:
    """solve --out writes the one-stage plan ([seat] from {B1}); verify PLAN accepts it and re-runs it."""
    out = tmp_path / "plan.json"
    run_cli("solve", COCKED, "--out", out, "--json", check_rc=0)
    doc = json.loads(out.read_text())
    assert doc["insertion"]["stages"] == ["seat"] and doc["sequence"][0] == ["B1"]
    proc = run_cli("verify", out, "--json", check_rc=0)
    doc = json.loads(proc.stdout)
    assert doc["passed"] is True and doc["observed_sequence"] == [["B1"], ["B1", "B1.bottom"]]


SHARP = """
format = 1
[scene]
name = "sharp-bore"
[workpiece]
shape = "cylinder"
radius = 0.01
length = 0.08
mass = 0.3
start = { position = [0.003, -0.002, 0.05], rpy_deg = [6.0, -7.0, 30.0] }
[[bore]]
name = "B1"
position = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
diameter = 0.02002
depth = 0.03
friction = 0.3
"""


def test_the_approach_ends_with_the_leading_end_aimed_into_a_sharp_mouth() -> None:
    """A sharp bore captures only its play (10 µm). Turned 0.9 mrad about its centre at the staging pose (within the
    old 1 mrad and 0.1 mm), the shaft's leading end is θ L/2 = 36 µm off: the insertion does not begin; turned
    about the leading end itself (the end on the axis), it does. Before, both began, the end landing beside the
    mouth when the servo had not caught up."""
    from fixplan.planner.insertion import InsertionRun
    from fixplan.settings import HAPTIC
    from fixplan.spatial import Pose, exp_so3

    fx = fixplan.loads(SHARP)
    plan = plan_insertion(fx)
    staging = plan.stages[0].poses[-1]
    R = exp_so3(np.array([0.9e-3, 0.0, 0.0]))
    end = staging.p_world - 0.04 * staging.R_world_body[:, 2]  # the leading end's centre
    about_centre = Pose(R @ staging.R_world_body, staging.p_world.copy())
    about_end = Pose(R @ staging.R_world_body, end + R @ (staging.p_world - end))
    for pose, begins in ((about_centre, False), (about_end, True)):
        run = InsertionRun(fx, plan, HAPTIC.insertion)
        run.step_time(10.0, pose)
        assert (run.index == 1) is begins


def test_a_located_start_is_held() -> None:
    """housing-2-pins starts at its located pose: nothing to insert; the seating push holds it (verified)."""
    r = solve(fixplan.load(HOUSING))
    assert r.status == "planned", r.reason
    assert r.reason.startswith("already located") and r.transitions == []


def test_cli_solve_takes_pins_but_not_an_order(tmp_path) -> None:
    proc = run_cli("solve", LOAD, "--json", "--no-verify", check_rc=1)  # unverified: exit 1
    doc = json.loads(proc.stdout)
    assert doc["status"] == "unverified"
    assert [t["added"] for t in doc["transitions"]][1:] == ["P1", "P2", ["B1", "B2", "B3"]]
    proc = run_cli("solve", LOAD, "--order", "P1,P2")
    assert proc.returncode == 2 and "--order is not supported with pins" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_cli_solve_reports_the_clearance_pose_range_and_clamps_on_pins() -> None:
    """solve --clamp on the clamped housing: the clearance range and the clamping stage in one answer.

    The round pin P1 (9.8 mm in a 10 mm hole: c1 = 0.1 mm of radial play) is seated on the hole's
    -x wall, so the hole may move 2 c1 = 0.2 mm toward -x and no further; with the diamond P2's
    c2 = 0.1 mm, linearised (clearance.py's closed forms), y moves ±0.1 mm and the part turns about z
    by ±(c1 + c2)/L = ±0.2 mm / 80 mm = ±2.5 mrad. The rests hold z and the tilts.
    """
    proc = run_cli("solve", PROBLEMS / "housing-2-pins-clamped.toml", "--clamp", "--json")
    doc = json.loads(proc.stdout)
    assert doc["status"] == "planned"
    rng = doc["clearance_pose_range"]
    assert rng["pins"] == ["P1", "P2"]
    assert rng["translation_m"]["x"] == pytest.approx([-2e-4, 0.0], abs=1e-9)
    assert rng["translation_m"]["y"] == pytest.approx([-1e-4, 1e-4], abs=1e-9)
    assert rng["rotation_rad"]["z"] == pytest.approx([-2.5e-3, 2.5e-3], abs=1e-9)
    for axis in ("z",):
        assert rng["translation_m"][axis] == pytest.approx([0.0, 0.0], abs=1e-12)
    for axis in ("x", "y"):
        assert rng["rotation_rad"][axis] == pytest.approx([0.0, 0.0], abs=1e-12)
    clamping = doc["clamping"]
    assert clamping["holds"] is True and clamping["order"] == ["K1", "K2"]
    assert clamping["verification"]["passed"] is True


@pytest.mark.slow
def test_a_part_levered_on_its_diamond_pin_stays_out_of_it() -> None:
    """plane-2-pins seed 2031 fixture 0, robust's world 9: the part levers about P2 as it enters.

    P2's tip contact dropped out of the step and the part went 1.86e-5 m into the pin, beyond the
    1e-5 m bound (tests/engine/test_pin_slots.py has the pose, and the other holes of the same
    detection). Now within it, and the part seats.
    """
    from fixplan.generate import generate_one
    from fixplan.robust import RobustSettings, draw_pin_world

    fixture = fixplan.loads(generate_one("plane-2-pins", 2031, 0).toml_text)
    play = max(i.play_m for i in inserts(fixture))
    world, noise, _ = draw_pin_world(fixture, 9, RobustSettings(pose_sigma_m=3.0 * play, pose_sigma_deg=0.1))
    v = verify_insertion(world, plan_insertion(fixture), noise=noise)
    assert v.passed, v.reason
    assert v.max_penetration_m <= 1e-5
