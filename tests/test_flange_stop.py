"""A flange onto one round pin with a rotational stop (``problems/flange-1-pin-stop.toml``).

Three rests, a round pin P1 in the plate's central through hole (radial play c = 0.1 mm, the part
seated toward +x) and a stop S1 on the +y face at x = 0.03 m, which takes the turn about the pin's
axis. The descent along the axis closes the rests but not S1 (its normal, −y, lies across the
axis): the seating must press it. Closed forms, at the located pose (c = body origin = centre of
mass, m g = 11.772 N):

- the seating push is ``seat_press`` m g down through c, ``seat_side`` m g along +x through P1's
  contacts' mean (−0.006, 0, 0.00575) and ``seat_side`` m g along +y through S1's contact
  (0.03, 0.05, 0.01), each balanced by what it presses (``problems/expected.toml``);
- S1's gap opens at ``n·(z × (p − c_P1)) = −(0.03 + 0.0001)`` m per radian of turn about +z, so
  the descent turns by ``1 mm / 0.0301 m`` clockwise;
- at the end P1 touches its hole (the hole's axis the play c from the pin's) on the seated side,
  within the pin's friction angle ``atan μ_P1``: the side push, through P1's contact, is what holds
  the hole there while the rests are lightly loaded, and P1's friction what lets it stop short of
  the exact side.

The verification from the tilted start fails on the old seating push (the run reached the rests
57 µm off S1 and stalled there until its retries ran out).
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import PROBLEMS

import fixplan
from fixplan.cli import main
from fixplan.locating import (
    axis_offsets_m,
    engagement,
    insertion_axis,
    inserts,
    located_pose,
    locator_gaps,
    seat_at,
)
from fixplan.settings import HAPTIC
from fixplan.spatial import log_so3

FLANGE = PROBLEMS / "flange-1-pin-stop.toml"
MG = 1.2 * 9.81
PLAY_M = 0.5 * (0.012 - 0.0118)
MU_PIN = 0.2
GAP_M = HAPTIC.execution.contact_gap_m  # a contact this close counts as touching


def _mirrored(tmp_path: Path) -> Path:
    """The flange mirrored in y (its rests and pin are symmetric): S1 on the −y face, the start mirrored."""
    text = FLANGE.read_text()
    for a, b in (
        ("[0.03, 0.05, 0.01]", "[0.03, -0.05, 0.01]"),
        (
            "position = [0.003, -0.004, 0.045], rpy_deg = [2.0, -1.5, -4.0]",
            "position = [0.003, 0.004, 0.045], rpy_deg = [-2.0, -1.5, 4.0]",
        ),
    ):
        assert text.count(a) == 1, a
        text = text.replace(a, b)
    out = tmp_path / "flange-mirrored.toml"
    out.write_text(text)
    return out


def test_s1_is_a_stop_and_the_seating_push_presses_it_through_its_contact() -> None:
    from fixplan.planner.insertion import seat_push

    fx = fixplan.load(FLANGE)
    G, u = located_pose(fx), insertion_axis(fx)
    seat = seat_at(fx, G, u)
    assert seat.stop_names == ("S1",)
    w, w_com, held = seat_push(fx, G, u, HAPTIC.insertion)
    assert held is None
    s = 0.3 * MG
    expected = [s, s, -MG, 0.0, -0.00425 * s, 0.03 * s]  # about c = the body origin (module text)
    np.testing.assert_allclose(w, expected, atol=1e-9)
    np.testing.assert_allclose(w_com, expected, atol=1e-9)


def test_the_part_goes_down_turned_away_from_the_stop_by_the_closed_form_angle() -> None:
    from fixplan.planner.insertion import plan_insertion, seat_turn

    fx = fixplan.load(FLANGE)
    G, u = located_pose(fx), insertion_axis(fx)
    turn = seat_turn(fx, G, u, HAPTIC.insertion)
    assert turn is not None and turn.pin == "P1"
    np.testing.assert_allclose(turn.axis_world, [0.0, 0.0, 1.0])  # counter-clockwise presses S1
    assert turn.angle_rad == pytest.approx(0.001 / 0.0301, rel=1e-12)
    gaps = dict(
        zip([loc.name for loc in fx.locators], locator_gaps(fx.workpiece, turn.descent, fx.locators), strict=True)
    )
    # S1 opens by the clearance (to first order: the face turns by 0.033 rad, the second order is
    # 0.0583 m · θ²/2 = 32 µm at most), the rests stay touching, P1 keeps its play
    assert gaps["S1"] == pytest.approx(0.001, abs=4e-5)
    assert max(abs(gaps[n]) for n in ("B1", "B2", "B3")) <= 1e-12
    assert max(axis_offsets_m(fx, turn.descent, inserts(fx)[0])) == pytest.approx(PLAY_M, abs=1e-12)
    # no turn where two pins fix it
    housing = fixplan.load(PROBLEMS / "housing-2-pins.toml")
    assert seat_turn(housing, located_pose(housing), insertion_axis(housing), HAPTIC.insertion) is None
    plan = plan_insertion(fx, HAPTIC)
    assert plan.ok, plan.reason
    assert plan.stages[-1].poses[-2].distance_to(turn.descent) == pytest.approx((0.0, 0.0), abs=1e-15)


def _assert_located(fx: fixplan.Fixture, result) -> None:  # result: PlanResult
    assert result.status == "planned", result.reason
    v = result.verification
    assert v is not None and v.passed, v.reason if v else None
    assert [list(s) for s in v.observed_sequence][-1] == ["B1", "B2", "B3", "P1", "S1"]
    # every rest and the stop closed
    pose = v.final_pose
    gaps = locator_gaps(fx.workpiece, pose, fx.locators)
    assert np.max(np.abs(gaps)) <= GAP_M, dict(zip([loc.name for loc in fx.locators], gaps, strict=True))
    # P1 touches its hole: the hole's axis the play from the pin's, on the seated side within atan μ
    u = insertion_axis(fx)
    side = seat_at(fx, located_pose(fx), u).side_world
    ins = inserts(fx)[0]
    assert max(axis_offsets_m(fx, pose, ins)) == pytest.approx(PLAY_M, abs=GAP_M)
    hole = pose.point_world_from_body(fx.workpiece.hole("H1").p_body)
    pin = next(p for p in fx.pins if p.name == "P1").p_world
    r = hole - pin
    r -= float(r @ u) * u
    assert float(np.linalg.norm(r)) == pytest.approx(PLAY_M, abs=GAP_M)
    angle = math.acos(min(float(r @ side) / float(np.linalg.norm(r)), 1.0))
    assert angle <= math.atan(MU_PIN), f"{math.degrees(angle):.3g}° from the seated side"


def test_the_flange_from_a_tilted_start_is_planned_verified_and_located() -> None:
    """Fails on the old seating push: the run stalled 57 µm off S1 (S1 never pressed)."""
    fx = fixplan.load(FLANGE)
    # the start: turned about every axis, off the pin (nothing engaged)
    assert np.all(np.abs(log_so3(fx.start.R_world_body @ fx.goal_pose.R_world_body.T)) > 0.01)
    assert not any(engagement(fx, fx.start, i).engaged for i in inserts(fx))
    result = fixplan.solve(fx)
    _assert_located(fx, result)
    assert [list(s) for s in result.sequence] == [[], [], ["P1"], ["B1", "B2", "B3", "P1", "S1"]]


def test_the_mirrored_flange_turns_the_other_way_and_is_located(tmp_path: Path) -> None:
    from fixplan.planner.insertion import seat_turn

    fx = fixplan.load(_mirrored(tmp_path))
    turn = seat_turn(fx, located_pose(fx), insertion_axis(fx), HAPTIC.insertion)
    assert turn is not None
    np.testing.assert_allclose(turn.axis_world, [0.0, 0.0, -1.0])
    _assert_located(fx, fixplan.solve(fx))


def test_verify_reruns_the_flange_plan_file_as_solve_did(capsys, tmp_path: Path) -> None:
    fixture = tmp_path / "fx" / FLANGE.name
    fixture.parent.mkdir()
    shutil.copyfile(FLANGE, fixture)
    plan = tmp_path / "plan.json"
    capsys.readouterr()
    assert main(["solve", str(fixture), "--out", str(plan)]) == 0
    data = json.loads(plan.read_text())
    # the turn is the fixture's (recomputed when read), not a key of the file
    assert set(data["insertion"]) == {"axis", "goal", "stages", "seat_wrench", "policy"}
    capsys.readouterr()
    assert main(["verify", str(plan), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["passed"] is True
    for name, gap in data["verification"]["final_gaps"].items():
        assert doc["final_gaps"][name] == pytest.approx(gap, abs=1e-9), name


def test_the_approach_moves_sideways_clear_of_the_pin_and_the_stop_then_comes_down() -> None:
    """From the tilted start the straight move would bring the tilted bottom within reach of P1's tip.

    The clear level: P1's tip (0.012 m) and S1's top (0.01 m), max 0.012 m, plus lead_m (0.002 m).
    Every knot before the staging pose keeps the part's lowest corner above it, turned as the guide or
    still as at the start; the last leg is straight down the axis, turned as the staging pose.
    """
    from fixplan.planner.insertion import plan_insertion

    fx = fixplan.load(FLANGE)
    plan = plan_insertion(fx, HAPTIC)
    guide = plan.stages[0].poses
    staging = guide[-1]
    clear = 0.012 + HAPTIC.insertion.lead_m
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * fx.workpiece.shape.half

    def lowest(R: np.ndarray, p: np.ndarray) -> float:
        return float(np.min((corners @ R.T + p)[:, 2]))

    assert lowest(staging.R_world_body, staging.p_world) == pytest.approx(clear, abs=1e-12)
    above = guide[-5]  # the knot over the staging pose: the last leg's four steps down
    np.testing.assert_allclose(above.p_world[:2], staging.p_world[:2], atol=1e-12)
    np.testing.assert_allclose(above.R_world_body, staging.R_world_body, atol=1e-12)
    for pose in guide[:-4]:
        assert min(lowest(pose.R_world_body, pose.p_world), lowest(fx.start.R_world_body, pose.p_world)) >= clear - 1e-9
