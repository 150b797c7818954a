"""The fine plan of one transition: exact gaps along the path, closed-form end poses, wrenches, failures.

Closed forms used (derived in each test's docstring): a point-locator pivot keeps the touched body
point fixed in the world, so the end pose of a roll is known from the contact's body coordinates.
"""

import json
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import ROOT

import fixplan
from fixplan.errors import InputError
from fixplan.fixture import default_fixture_path
from fixplan.locating import locator_contact
from fixplan.planner.features import feature_at
from fixplan.planner.fine import Transition, plan_transition
from fixplan.spatial import Pose

TOUCH = 1e-6  # [m]


def gaps(fixture, pose):
    return {loc.name: locator_contact(fixture.workpiece, pose, loc).gap_m for loc in fixture.locators}


def assert_plan_geometry(fixture, tr, established, target, clearance):
    """Exact numpy gaps at every knot: established touch, target closes monotonically to 0, others clear."""
    others = [loc.name for loc in fixture.locators if loc.name not in established and loc.name != target]
    prev = np.inf
    for pose in tr.poses:
        g = gaps(fixture, pose)
        for n in established:
            assert abs(g[n]) <= TOUCH, (n, g[n])
        for n in others:
            assert g[n] >= clearance - TOUCH, (n, g[n])
        assert g[target] >= -TOUCH and g[target] <= prev + TOUCH
        prev = g[target]
    assert abs(gaps(fixture, tr.poses[-1])[target]) <= TOUCH
    assert tr.max_constraint_violation_m <= TOUCH


@pytest.fixture(scope="module")
def default():
    return fixplan.load(default_fixture_path())


@pytest.fixture(scope="module")
def default_s1(default):
    return plan_transition(default, default.start, ["B1", "B2", "B3"], "S1")


def test_default_slides_on_the_base_to_touch_s1(default, default_s1):
    tr = default_s1
    assert tr.success, tr.reason
    assert tr.kind == "slide" and tr.ipopt_status == "Solve_Succeeded"
    assert len(tr.poses) == 21 and tr.poses[0].distance_to(default.start) == (0.0, 0.0)
    assert_plan_geometry(default, tr, ["B1", "B2", "B3"], "S1", 1e-3)
    # Sliding on the -z face keeps the box flat: z of the centre and roll/pitch stay at the start's.
    for pose in tr.poses:
        assert abs(pose.p_world[2] - 0.025) <= TOUCH
        assert abs(pose.R_world_body[2, 2] - 1.0) <= 1e-9
    # Wrenches: found for every segment, within the manipulator's limits, base contacts pressed.
    assert tr.found.all() and tr.wrenches.shape == (20, 6) and np.isfinite(tr.wrenches).all()
    assert np.all(np.linalg.norm(tr.wrenches[:, :3], axis=1) <= 40.0 * (1 + 1e-6))
    assert np.all(np.linalg.norm(tr.wrenches[:, 3:], axis=1) <= 2.0 * (1 + 1e-6))
    assert np.all(tr.margins > 0.0)
    assert tr.solve_time_s < 10.0 and tr.cost > 0.0
    doc = json.loads(json.dumps(tr.to_json()))
    assert (
        doc["kind"] == "slide" and len(doc["poses"]) == 21 and set(doc["poses"][0]) == {"position", "quaternion_wxyz"}
    )


def test_warm_start_reproduces_the_plan(default, default_s1):
    again = plan_transition(default, default.start, ["B1", "B2", "B3"], "S1", knots=10, warm_start=default_s1)
    assert again.success, again.reason
    dp, ang = again.poses[-1].distance_to(default_s1.poses[-1])
    assert dp <= 1e-6 and ang <= 1e-5
    assert again.ipopt_iterations <= default_s1.ipopt_iterations


def rect_touching_b1(angle_deg=5.0, contact_x_body=-0.07):
    """rect-3 turned by +5° and resting on B1 (0.05, 0) at body point (−0.07, −0.05); B2, S1 clear."""
    th = np.radians(angle_deg)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    p = np.array([0.05, 0.0]) - R @ np.array([contact_x_body, -0.05])
    text = (ROOT / "problems" / "rect-3.toml").read_text()
    old = "start = { position = [0.10, 0.05], angle_deg = 0.0 }"
    assert old in text
    return fixplan.loads(
        text.replace(old, f"start = {{ position = [{p[0]:.17g}, {p[1]:.17g}], angle_deg = {angle_deg} }}")
    )


def test_rect_rolls_on_b1_to_b2_then_slides_to_s1():
    """Rolling on the point B1 is a pivot: the body point (−0.07, −0.05) stays at B1, so the roll
    ends at angle 0 with the centre at B1 + (0.07, 0.05) = (0.12, 0.05). Sliding on B1, B2 then
    moves the part 2 cm in −x to the located pose (0.10, 0.05)."""
    fx = rect_touching_b1()
    g0 = gaps(fx, fx.start)
    assert abs(g0["B1"]) <= 1e-12 and g0["B2"] > 5e-3 and g0["S1"] > 5e-3
    roll = plan_transition(fx, fx.start, ["B1"], "B2")
    assert roll.success, roll.reason
    assert roll.kind == "roll"
    assert_plan_geometry(fx, roll, ["B1"], "B2", 1e-3)
    b1 = fx.locator("B1").p_world
    for pose in roll.poses:
        np.testing.assert_allclose(pose.point_body_from_world(b1), [-0.07, -0.05], atol=1e-6)
    np.testing.assert_allclose(roll.poses[-1].p_world, [0.12, 0.05], atol=1e-6)
    assert abs(roll.poses[-1].angle_rad) <= 1e-6
    assert roll.max_slip_m <= 1e-6 and roll.found.all()
    assert set(json.loads(json.dumps(roll.to_json()))["poses"][-1]) == {"position", "angle_deg"}

    slide = plan_transition(fx, roll.end_pose, ["B1", "B2"], "S1")
    assert slide.success, slide.reason
    assert slide.kind == "slide"
    assert_plan_geometry(fx, slide, ["B1", "B2"], "S1", 1e-3)
    np.testing.assert_allclose(slide.poses[-1].p_world, [0.10, 0.05], atol=1e-6)


def test_tilted_box_rolls_about_b1_b2_onto_b3():
    """box-tilted-start rests on B1, B2 at body points (−0.075, −0.04, −0.025), (0.045, −0.04, −0.025):
    rolling keeps both fixed, i.e. a pivot about the B1-B2 line, which lands flat on B3 with the
    centre at B1 − (−0.075, −0.04, −0.025) = (0.115, 0.06, 0.025)."""
    fx = fixplan.load(ROOT / "problems" / "box-tilted-start.toml")
    tr = plan_transition(fx, fx.start, ["B1", "B2"], "B3")
    assert tr.success, tr.reason
    assert tr.kind == "roll"
    assert_plan_geometry(fx, tr, ["B1", "B2"], "B3", 1e-3)
    np.testing.assert_allclose(tr.poses[-1].p_world, [0.115, 0.06, 0.025], atol=1e-6)
    np.testing.assert_allclose(tr.poses[-1].R_world_body, np.eye(3), atol=1e-6)
    assert tr.max_slip_m <= 1e-6 and tr.found.all()


def test_rolling_on_b1_b2_cannot_reach_s1():
    """The only rolling motion on two point contacts is the pivot about their line (along x); it
    turns the -y face onto S1 and S2 at once, so the program is infeasible and says so, naming the
    constraint that gives way in the elastic re-solve (S2's clearance). Left to choose, the ladder
    slides instead."""
    fx = fixplan.load(ROOT / "problems" / "box-tilted-start.toml")
    tr = plan_transition(fx, fx.start, ["B1", "B2"], "S1", knots=8, kind="roll")
    assert not tr.success and tr.kind == "roll" and tr.formulation == ""
    assert tr.ipopt_status == "Infeasible_Problem_Detected"
    assert "no path" in tr.reason and "S1" in tr.reason
    assert "slide instead of roll" not in tr.reason  # the caller chose to roll: the ladder keeps it
    # the pivot about the B1-B2 line (along x) turns the -y face onto S1 and S2 alike: S2 closes too
    assert "S1 cannot close while {B1, B2} stay touching and S2 stays ≥ 1 mm away" in tr.reason
    assert "S2's clearance constraint" in tr.reason
    free = plan_transition(fx, fx.start, ["B1", "B2"], "S1", knots=8)
    assert free.success, free.reason
    assert free.kind == "slide" and free.formulation == "slide instead of roll"
    assert_plan_geometry(fx, free, ["B1", "B2"], "S1", 1e-3)
    assert free.to_json()["formulation"] == "slide instead of roll"


def test_weak_manipulator_fails_with_its_reason(default):
    """Sliding the 2 kg box on μ = 0.25 needs at least μ m g ≈ 4.9 N of push: 0.5 N cannot."""
    text = default_fixture_path().read_text()
    assert "max_force = 40.0" in text
    weak = fixplan.loads(text.replace("max_force = 40.0", "max_force = 0.5"))
    tr = plan_transition(weak, weak.start, ["B1", "B2", "B3"], "S1", knots=6)
    assert not tr.success
    # every segment fails; the reason quotes the most demanding one (what the transition needs)
    assert "too weak" in tr.reason and "segment " in tr.reason
    quoted = float(tr.reason.split("the push needs ")[1].split(" N")[0])
    assert tr.needed_scale == pytest.approx(quoted / 0.5, rel=1e-3) and quoted > 0.25 * 2 * 9.81 / np.hypot(1, 0.25)
    assert not tr.found.any() and np.isnan(tr.wrenches).all()
    assert tr.max_constraint_violation_m <= TOUCH  # the path itself is fine
    assert tr.cost == float("inf")


def test_bad_questions_are_input_errors(default):
    with pytest.raises(InputError, match="already established"):
        plan_transition(default, default.start, ["B1", "B2", "B3"], "B1")
    with pytest.raises(InputError, match="must touch at the start"):
        plan_transition(default, default.start, ["B1", "S1"], "S2")
    with pytest.raises(InputError, match="unknown locator"):
        plan_transition(default, default.start, ["B1"], "X9")


@pytest.mark.parametrize(
    ("shape", "point_body"),
    [
        ("box", [0.03, -0.01, -0.04]),  # below the -z face
        ("cylinder", [0.05, 0.02, 0.01]),  # beside the lateral surface
        ("cylinder", [0.01, -0.01, 0.07]),  # above the +z end
        ("sphere", [0.03, 0.04, -0.02]),
        ("polygon", [0.05, -0.02]),  # below the bottom edge
        ("disk", [-0.03, 0.05]),
    ],
)
def test_closed_form_gap_matches_the_exact_distance(shape, point_body, rng):
    """The CasADi feature distance equals Shape.project's where the closest point is on the feature."""
    import casadi as ca

    from fixplan.geometry import Box, Cylinder, Disk, Polygon, Sphere

    shapes = {
        "box": Box((0.2, 0.1, 0.05)),
        "cylinder": Cylinder(0.03, 0.1),
        "sphere": Sphere(0.04),
        "polygon": Polygon(((0.0, 0.0), (0.12, 0.0), (0.1, 0.06), (0.02, 0.08))),
        "disk": Disk(0.04),
    }
    s = shapes[shape]
    fx = SimpleNamespace(workpiece=SimpleNamespace(shape=s))
    pose = Pose.identity(s.dimension)
    q0 = np.asarray(point_body, dtype=float)
    feature = feature_at(fx, SimpleNamespace(p_world=q0), pose)
    for q in q0 + 1e-3 * rng.standard_normal((5, q0.shape[0])):
        closed = float(feature.distance(ca, ca.DM(q)))
        proj = s.project(q)
        assert closed == pytest.approx(proj.distance, abs=1e-12)
        np.testing.assert_allclose(
            np.asarray(ca.evalf(feature.point_at(ca, ca.DM(q)))).ravel(), proj.point_body, atol=1e-12
        )


def test_transition_is_frozen(default_s1):
    assert isinstance(default_s1, Transition)
    with pytest.raises(AttributeError):
        default_s1.success = False  # type: ignore[misc]


def _plane_gap(feature, q_body, locator):
    return float(feature.normal @ q_body) - feature.offset - locator.radius_m


def test_clearance_features_are_lower_bounds_that_keep_a_turned_part_clear(default):
    """Face planes of a convex part are lower bounds of the true gap; the planes kept for a clear
    locator must also *separate* it at the start. On 300 seeded poses of the default box (turned up
    to 30° about z, shifted up to 3 cm) every locator with a positive true gap gets planes whose
    larger gap is positive and at most the true gap, and their smooth maximum lies within
    s log 2 below that. The goal's face alone has a negative plane gap for some of them (a side
    locator beside the end face of a turned box), which let a planned path run the part's corner
    into the locator."""
    from fixplan.planner.features import clearance_features, smooth_max
    from fixplan.settings import DEFAULT

    SMOOTH_MAX_M = DEFAULT.planner.smooth_max_m

    rng = np.random.default_rng(11)
    goal = default.goal
    negative_goal_face = 0
    for _ in range(300):
        yaw = rng.uniform(-30, 30)
        shift = np.r_[rng.uniform(-0.03, 0.03, 2), 0.0]
        pose = Pose.from_rpy_deg(goal.p_world + shift, [0.0, 0.0, yaw])
        for loc in default.locators:
            true_gap = locator_contact(default.workpiece, pose, loc).gap_m
            if true_gap <= 1e-9:
                continue
            q = pose.point_body_from_world(loc.p_world)
            goal_face = feature_at(default, loc, goal)
            negative_goal_face += _plane_gap(goal_face, q, loc) < 0
            feats = clearance_features(default, loc, pose, goal_face)
            assert feats[0] is goal_face and len(feats) <= 2
            gaps_m = [_plane_gap(f, q, loc) for f in feats]
            assert 0.0 < max(gaps_m) <= true_gap + 1e-12, (yaw, shift, loc.name)
            if len(feats) == 2:
                sm = float(smooth_max(np, gaps_m[0], gaps_m[1]))
                assert max(gaps_m) - SMOOTH_MAX_M * np.log(2) - 1e-15 <= sm <= max(gaps_m) + 1e-15
    assert negative_goal_face > 0  # the case the second plane exists for does occur


def test_close_side_locators_need_the_smaller_clearance():
    """Two side locators 11 mm apart: touching one with the other kept 1 mm away turns the part
    by atan(1/11) ≈ 5.2°, and from there no path touches the end locator keeping that gap; the
    planner's second clearance (0.1 mm) finds one (generated box-321 seed 101, fixture 25)."""
    import math

    from fixplan.fixture import loads
    from fixplan.generate import generate_one
    from fixplan.planner.solve import Planner
    from fixplan.settings import DEFAULT

    CLEARANCES_M = DEFAULT.planner.clearances_m

    g = generate_one("box-321", 101, 25)
    fx = loads(g.toml_text, source=g.name)
    base = ["B1", "B2", "B3"]
    first = plan_transition(fx, fx.start, base, "S2", knots=10)
    assert first.success
    end = first.poses[-1]
    gap_s1 = locator_contact(fx.workpiece, end, fx.locator("S1")).gap_m
    assert gap_s1 == pytest.approx(CLEARANCES_M[0], abs=1e-6)  # the clearance is what stops the turn
    spacing = float(np.linalg.norm(fx.locator("S1").p_world[:2] - fx.locator("S2").p_world[:2]))
    yaw = math.degrees(math.atan2(end.R_world_body[1, 0], end.R_world_body[0, 0]))
    assert abs(yaw) == pytest.approx(math.degrees(math.atan(CLEARANCES_M[0] / spacing)), abs=0.3)
    strict = plan_transition(fx, end, [*base, "S2"], "E1", knots=10, clearance_m=CLEARANCES_M[0])
    assert not strict.success and strict.ipopt_status == "Infeasible_Problem_Detected"
    relaxed = plan_transition(fx, end, [*base, "S2"], "E1", knots=10, clearance_m=CLEARANCES_M[1])
    assert relaxed.success
    others = [locator_contact(fx.workpiece, p, fx.locator("S1")).gap_m for p in relaxed.poses[1:]]
    assert min(others) >= CLEARANCES_M[1] - 1e-7
    plan = Planner(fx).plan_from(fx.start, frozenset(base))
    assert plan.found, plan.reason


def test_other_locators_are_held_against_the_model_start_gap():
    """A turned box touching S2 with S1 0.35 mm away beside its goal face: S1's model gap (the
    smooth maximum of two planes) starts below the exact one, the NLP holds S1 at the model's
    start value, and the exact check asks no more than that (it asked the exact start gap and
    rejected sound paths by 3–28 µm: generated box-321 seed 303, fixture 3)."""
    from fixplan.fixture import loads
    from fixplan.generate import generate_one
    from fixplan.locating import solve_goal

    g = generate_one("box-321", 303, 3)
    fx = loads(g.toml_text, source=g.name)
    est = ["B1", "B2", "B3", "S2"]
    near = Pose.from_rpy_deg([0.0221337, 0.0945951, 0.1536], [0.0, 0.0, 3.2085])
    pose = solve_goal(fx.workpiece, [fx.locator(n) for n in est], near, tol_m=1e-10).pose
    s1 = fx.locator("S1")
    gap0 = locator_contact(fx.workpiece, pose, s1).gap_m
    assert 1e-4 < gap0 < 1e-3  # closer than the clearance: held at its start gap
    tr = plan_transition(fx, pose, est, "E1", knots=10)
    assert tr.success, tr.reason
    assert tr.max_constraint_violation_m <= fx.tolerances.touch_m
    gaps = [locator_contact(fx.workpiece, p, s1).gap_m for p in tr.poses[1:]]
    assert min(gaps) >= gap0 - 1e-4  # the model's lower bound is within the smooth max's width
    assert min(gaps) < gap0 - fx.tolerances.touch_m  # the path uses that room: the exact start gap was the wrong bound
