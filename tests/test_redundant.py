"""Redundant layouts: locators that geometry closes at the same instant are one transition.

Two hand-derived fixtures (``tests/data``; each file's comment block derives its normal rows):

- ``redundant-ends-box.toml``: the default 3-2-1 box with two end locators E1, E2 on the −x face
  at the same (x, y), 26 mm apart in height. Normal rows ``[n; r × n]`` at the goal (r from the
  centre of mass (0.10, 0.05, 0.025) to the tip centre, n = +x): E1 ``[1,0,0; 0,−0.013,0]``, E2
  ``[1,0,0; 0,0.013,0]``; B1, B2 (same y = 0.015, x = 0.035 and 0.165, n = +z):
  ``[0,0,1; −0.035, ±0.065, 0]``. So ``G_E2 − G_E1 = [0,0,0; 0,0.026,0] = −0.2 (G_B2 − G_B1)``:
  seven rows of rank 6. With B1 and B2 kept, ``G_E1 = G_E2 + 0.2 (G_B2 − G_B1)`` — E1's row is
  E2's plus kept rows with coefficient +1 on E2, so every motion keeping B1 and B2 changes both
  end gaps alike (pitch is held, and the two tips differ only in height on a face that stays
  vertical): E1 and E2 close together, ratio 1.
- ``redundant-sides-plate.toml``: rect-3 with two side locators S1 (0, 0.03), S2 (0, 0.07) on
  the −x edge line. Rows (2D ``r × n = r_x n_y − r_y n_x``): B1 ``[0,1,−0.05]``, B2
  ``[0,1,0.05]``, S1 ``[1,0,0.02]``, S2 ``[1,0,−0.02]``: four rows of rank 3.
  ``G_S1 = G_S2 + 0.4 (G_B2 − G_B1)``: with {B1, B2} kept S1 and S2 close together (ratio 1);
  ``G_B2 = G_B1 + 2.5 (G_S1 − G_S2)``: with {B1, S2} kept B2 closes together with S1 (ratio 2.5);
  with {B1, S1} kept the coefficient of S2 is −2.5 (closing B2 opens S2): not together.

Before the coarse lattice had group edges, both fixtures were ``infeasible`` ("E2 closes together
with E1 (rank 6 at the goal): no path ..."): every single-locator transition into a state holding
one of a pair without the other has no path.
"""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
from conftest import ROOT

import fixplan
from fixplan.fixture import loads
from fixplan.locating import locator_contact
from fixplan.planner.coarse import search
from fixplan.planner.execute import Step
from fixplan.planner.fine import LADDER, closing_group, closing_together, dependent_kept, goal_rows, plan_transition
from fixplan.planner.plan import Plan, PlannedTransition, TriedTransition
from fixplan.planner.policy import PolicyEntry
from fixplan.spatial import Pose

DATA = ROOT / "tests" / "data"
BOX = DATA / "redundant-ends-box.toml"
PLATE = DATA / "redundant-sides-plate.toml"
BASE_SIDES = ["B1", "B2", "B3", "S1", "S2"]


def gaps(fx, pose):
    return {loc.name: float(locator_contact(fx.workpiece, pose, loc).gap_m) for loc in fx.locators}


# -- the rank test on the hand-derived rows --------------------------------------------------------
def test_box_rows_and_groups_are_the_hand_derived_ones():
    fx = fixplan.load(BOX)
    rows = goal_rows(fx)
    assert rows is not None and rows.rank == 6 and len(rows.names) == 7
    assert rows.row("E1") == pytest.approx([1, 0, 0, 0, -0.013, 0], abs=1e-12)
    assert rows.row("E2") == pytest.approx([1, 0, 0, 0, 0.013, 0], abs=1e-12)
    assert rows.row("E2") - rows.row("E1") == pytest.approx(-0.2 * (rows.row("B2") - rows.row("B1")), abs=1e-12)
    (c,) = closing_together(fx, BASE_SIDES, "E1")
    assert c.locator == "E2" and c.ratio == pytest.approx(1.0, rel=1e-9) and c.rank == 6
    for kept in (BASE_SIDES, ["B1", "B2"], ["B1", "B2", "B3"], ["B1", "B2", "S2"]):
        assert closing_group(fx, kept, "E1", rows) == ("E1", "E2")
        assert closing_group(fx, kept, "E2", rows) == ("E1", "E2")
    # B1 and B3 do not hold the pitch (their line is diagonal): the ends close one at a time, as free
    for kept in ([], ["B1"], ["B1", "B3"], ["S1", "S2"]):
        assert closing_group(fx, kept, "E1", rows) == ("E1",)
    # the independent locators close alone from any state
    for r in range(0, 6):
        for kept in itertools.combinations(BASE_SIDES, r):
            for t in set(BASE_SIDES) - set(kept):
                assert closing_group(fx, kept, t, rows) == (t,)
    # after the pair, E2's row repeats the kept rows'
    assert dependent_kept(fx, ["B1", "B2", "B3", "E1", "E2", "S1"]) == ("E2",)
    assert dependent_kept(fx, BASE_SIDES) == ()


def test_plate_rows_and_groups_are_the_hand_derived_ones():
    fx = fixplan.load(PLATE)
    rows = goal_rows(fx)
    assert rows is not None and rows.rank == 3 and len(rows.names) == 4
    expect = {"B1": [0, 1, -0.05], "B2": [0, 1, 0.05], "S1": [1, 0, 0.02], "S2": [1, 0, -0.02]}
    for n, g in expect.items():
        assert rows.row(n) == pytest.approx(g, abs=1e-12)
    (c,) = closing_together(fx, ["B1", "B2"], "S1")
    assert (c.locator, c.ratio) == ("S2", pytest.approx(1.0, rel=1e-9))
    (c,) = closing_together(fx, ["B1", "S2"], "B2")
    assert (c.locator, c.ratio) == ("S1", pytest.approx(2.5, rel=1e-9))
    assert closing_group(fx, ["B1", "B2"], "S2", rows) == ("S1", "S2")
    assert closing_group(fx, ["B1", "S2"], "B2", rows) == ("B2", "S1")
    assert closing_group(fx, ["B1", "S1"], "B2", rows) == ("B2",)  # coefficient −2.5: not together
    assert closing_group(fx, ["B1"], "S1", rows) == ("S1",)
    assert closing_group(fx, [], "B2", rows) == ("B2",)
    assert dependent_kept(fx, ["B1", "B2", "S1", "S2"]) == ("S2",)


@pytest.mark.parametrize("twin", ["rotated", "mirrored"])
def test_twins_have_the_same_groups(twin):
    """A rigid motion or reflection of the world changes no gap: the same pairs close together."""
    from fixplan.spatial import exp_so3
    from fixplan.twins import mirrored_fixture_text, rotated_fixture_text

    for path, n in ((BOX, 3), (PLATE, 2)):
        text = path.read_text()
        if twin == "rotated":
            R = exp_so3(np.array([0.3, -0.5, 0.9])) if n == 3 else np.array([[0.6, -0.8], [0.8, 0.6]])
            tw = loads(rotated_fixture_text(text, R), source=f"rotated {path.name}")
        else:
            tw = loads(mirrored_fixture_text(text, [0.0, 1.0, 0.0][:n] if n == 3 else [0.0, 1.0]), source="m")
        fx = fixplan.load(path)
        rows, trows = goal_rows(fx), goal_rows(tw)
        assert trows is not None and rows is not None and trows.rank == rows.rank
        names = [loc.name for loc in fx.locators]
        for r in range(len(names)):
            for kept in itertools.combinations(names, r):
                for t in set(names) - set(kept):
                    assert closing_group(tw, kept, t, trows) == closing_group(fx, kept, t, rows), (path.name, kept, t)


def test_generated_layouts_have_no_groups():
    """Generated 3-2-1 boxes (seed 101) and plates (seed 202): independent rows, so no transition
    of their lattices adds a group and no kept contact is dependent — the search and the path
    programs are those of before (solving the 20 gave the same status and sequence before and after)."""
    from fixplan.generate import generate_one

    for family, seed in (("box-321", 101), ("plate-2d", 202)):
        for i in range(10):
            g = generate_one(family, seed, i)
            fx = loads(g.toml_text, source=g.name)
            rows = goal_rows(fx)
            names = [loc.name for loc in fx.locators]
            assert rows is not None and rows.rank == len(names) == fx.ndof
            for r in range(len(names)):
                for kept in itertools.combinations(names, r):
                    assert dependent_kept(fx, kept, rows) == ()
                    for t in set(names) - set(kept):
                        assert closing_group(fx, kept, t, rows) == (t,)


# -- the coarse lattice ----------------------------------------------------------------------------
class _Fake:
    def __init__(self, pose):
        self.success, self.reason, self.cost, self.end_pose = True, "", 1.0, pose


def test_lattice_adds_a_group_in_one_transition():
    """A, B free; C and D close together once A is kept: the sequences go A → {C, D} as one step,
    and no transition adds C or D alone from a state holding A."""
    start = Pose.identity(3)
    tried = []

    def evaluate(pose, state, target):
        tried.append((tuple(sorted(state)), target))
        return _Fake(pose)

    def group(state, target):
        return ("C", "D") if "A" in state and target in ("C", "D") else (target,)

    plan = search(frozenset({"A"}), ["A", "B", "C", "D"], start, evaluate, group=group)
    assert plan.found
    assert all(len(b) - len(a) in (1, 2) for a, b in itertools.pairwise(plan.sequence))
    assert ("A", "C", "D") in plan.sequence or ("A", "B", "C", "D") == plan.sequence[-1]
    assert all(t != "D" for s, t in tried if "A" in s)  # D only through its group's first name, C
    jumps = [(a, b) for a, b in itertools.pairwise(plan.sequence) if len(b) - len(a) == 2]
    assert jumps and set(jumps[0][1]) - set(jumps[0][0]) == {"C", "D"}
    # with a fixed order the pair must be named one after the other
    bad = search(frozenset({"A"}), ["A", "B", "C", "D"], start, evaluate, order=["C", "B", "D"], group=group)
    assert not bad.found and "C, D close together" in bad.attempts[-1].reason
    # the reason names the argument (solve.order); the command line prints its flag there
    assert "solve.order must name them one after the other" in bad.attempts[-1].reason
    good = search(frozenset({"A"}), ["A", "B", "C", "D"], start, evaluate, order=["C", "D", "B"], group=group)
    assert good.found and good.sequence == [("A",), ("A", "C", "D"), ("A", "B", "C", "D")]


# -- the fine plan of a group ------------------------------------------------------------------------
def test_fine_plan_closes_the_pair_together():
    """From the goal slid 8 mm along +x (base and sides touching, both ends 8 mm open): with E2
    planned together the path closes both, their gaps equal at every knot (the face stays vertical);
    alone, E1 has no path and the reason names E2 and the rank."""
    fx = fixplan.load(BOX)
    goal = fx.goal
    pose = Pose(goal.R_world_body, goal.p_world + np.array([0.008, 0.0, 0.0]))
    g0 = gaps(fx, pose)
    assert g0["E1"] == pytest.approx(0.008, abs=1e-12) and g0["E2"] == pytest.approx(0.008, abs=1e-12)
    tr = plan_transition(fx, pose, BASE_SIDES, "E1", knots=10, friction_margin=0.1, together=["E2"])
    assert tr.success, tr.reason
    assert tr.added == ("E1", "E2") and "to touch {E1, E2}" in tr.reason
    touch = fx.tolerances.touch_m
    for p in tr.poses:
        g = gaps(fx, p)
        assert g["E1"] == pytest.approx(g["E2"], abs=1e-9)
        assert all(abs(g[n]) <= touch for n in BASE_SIDES)
    end = gaps(fx, tr.end_pose)
    assert abs(end["E1"]) <= touch and abs(end["E2"]) <= touch
    alone = plan_transition(fx, pose, BASE_SIDES, "E1", knots=10, ladder=LADDER[:1], clearance_m=1e-4)
    assert not alone.success
    assert alone.reason.startswith("E2 closes together with E1 (rank 6 at the goal)"), alone.reason


def test_after_the_pair_a_transition_keeps_both_without_overconstraining():
    """{B1, B2, B3, E1, E2, S1} + S2: six kept gap equalities on six dof were one too many
    (IPOPT: Not_Enough_Degrees_Of_Freedom); E2's repeats E1's and the base's, so it is kept as
    gap ≥ 0 and both ends still touch at every knot."""
    from fixplan.locating import solve_goal
    from fixplan.spatial import exp_so3

    fx = fixplan.load(BOX)
    kept = ["B1", "B2", "B3", "E1", "E2", "S1"]
    goal = fx.goal
    R = exp_so3(np.array([0.0, 0.0, np.radians(2.0)]))
    pivot = fx.locator("S1").p_world
    guess = Pose(R @ goal.R_world_body, pivot + R @ (goal.p_world - pivot))
    pose = solve_goal(fx.workpiece, [fx.locator(n) for n in kept], guess, tol_m=1e-12).pose
    assert gaps(fx, pose)["S2"] > 2e-3
    tr = plan_transition(fx, pose, kept, "S2", knots=10, friction_margin=0.1, ladder=LADDER[:1])
    assert tr.success, tr.reason
    touch = fx.tolerances.touch_m
    for p in tr.poses:
        g = gaps(fx, p)
        assert abs(g["E1"]) <= touch and abs(g["E2"]) <= touch


# -- the plan's representation -------------------------------------------------------------------------
def test_group_transition_json_round_trip():
    tr = PlannedTransition(
        from_state=tuple(BASE_SIDES), to_state=("B1", "B2", "B3", "E1", "E2", "S1", "S2"), added="E1",
        motion="slide", wrench=None, margin_N=None, friction_robustness=None, time_s=0.3, path_length_m=0.01,
        max_constraint_violation_m=0.0, solve_time_s=0.1, poses=(), together=("E2",),
    )  # fmt: skip
    obj = tr.to_json()
    assert obj["added"] == ["E1", "E2"] and tr.added_label == "{E1,E2}"
    back = PlannedTransition.from_json(json.loads(json.dumps(obj)))
    assert back.added == "E1" and back.together == ("E2",) and back == tr
    # without "to", the group fills the end state
    obj.pop("to")
    assert PlannedTransition.from_json(obj).to_state == ("B1", "B2", "B3", "E1", "E2", "S1", "S2")
    single = PlannedTransition.from_json({"from": ["B1"], "added": "B2", "motion": "roll"})
    assert single.to_json()["added"] == "B2" and single.together == ()
    tried = TriedTransition(tuple(BASE_SIDES), "E1", True, "", together=("E2",))
    assert tried.to_json()["add"] == ["E1", "E2"]
    assert TriedTransition.from_json(tried.to_json()) == tried
    entry = PolicyEntry(tuple(BASE_SIDES), "E1", "slide", None, None, 0.0, "plan", True, together=("E2",))
    assert entry.next_state == ("B1", "B2", "B3", "E1", "E2", "S1", "S2")
    again = PolicyEntry.from_json(entry.to_json())
    assert again.together == ("E2",) and again.step().added == ("E1", "E2")


def test_executor_waits_for_the_whole_group():
    """The executor's planned states hold the whole group, so touching E1 alone is not arrival."""
    from fixplan.planner.execute import Executor

    fx = fixplan.load(BOX)
    steps = [Step(tuple(BASE_SIDES), "E1", "slide", (), ("E2",))]
    ex = Executor(fx, frozenset(BASE_SIDES), steps)
    assert ex.states[-1] == frozenset([*BASE_SIDES, "E1", "E2"])
    assert steps[0].to_json()["together"] == ["E2"]


# -- fixplan solve on the two fixtures -----------------------------------------------------------------
@pytest.fixture(scope="module")
def plate_plan():
    from fixplan.planner.solve import solve

    return solve(fixplan.load(PLATE))


@pytest.fixture(scope="module")
def box_plan():
    from fixplan.planner.solve import solve

    return solve(fixplan.load(BOX))


def test_plate_is_planned_with_a_pair_transition(plate_plan):
    assert plate_plan.status == "planned", plate_plan.reason
    payload = plate_plan.to_json()
    added = [t["added"] for t in payload["transitions"]]
    pairs = [a for a in added if isinstance(a, list)]
    assert pairs in ([["S1", "S2"]], [["B2", "S1"]]), added
    assert payload["sequence"][-1] == ["B1", "B2", "S1", "S2"]
    # every step adds one locator or the group, and the round trip keeps the group
    plan = Plan.from_json(json.loads(json.dumps(payload)))
    assert [t.added_names for t in plan.transitions] == [tuple(a if isinstance(a, list) else [a]) for a in added]
    assert set(plate_plan.verification.observed_sequence[-1]) == {"B1", "B2", "S1", "S2"}


def test_box_is_planned_with_the_end_pair_in_one_transition(box_plan):
    assert box_plan.status == "planned", box_plan.reason
    payload = box_plan.to_json()
    added = [t["added"] for t in payload["transitions"]]
    (pair,) = [t for t in payload["transitions"] if isinstance(t["added"], list)]
    assert pair["added"] == ["E1", "E2"] and {"B1", "B2", "B3"} <= set(pair["from"])
    assert sorted(a for a in added if isinstance(a, str)) == ["S1", "S2"]
    # no state of the sequence holds one end locator without the other
    assert all(("E1" in s) == ("E2" in s) for s in payload["sequence"])


def test_plate_plan_file_reruns_with_its_group(plate_plan, tmp_path, capsys):
    """``fixplan verify PLAN``: the file's ``"added": ["S1", "S2"]`` becomes one executor step
    that waits for both, and the re-run reaches the goal (exit 0)."""
    from fixplan.cli import main

    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plate_plan.to_json()))
    assert main(["verify", str(path), "--fixture", str(PLATE)]) == 0, capsys.readouterr().err
