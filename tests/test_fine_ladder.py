"""The fine planner's ladder of formulations, from any contact state, and its no-path diagnosis.

Run as a script for the start-state study's success rates with the plain program alone (the
planner before the ladder) and with the whole ladder:
``PYTHONPATH=$PWD python tests/test_fine_ladder.py``.
"""

from __future__ import annotations

import zlib

import numpy as np
import pytest
from conftest import ROOT

import fixplan
from fixplan.fixture import default_fixture_path
from fixplan.locating import locator_contact, solve_goal
from fixplan.planner.features import feature_at
from fixplan.planner.fine import IPOPT_PATH_FOUND, LADDER, closing_together, plan_transition
from fixplan.settings import DEFAULT
from fixplan.spatial import Pose

CLEARANCES_M = DEFAULT.planner.clearances_m
STUDY_FILES = [
    "default",
    "gen-box-321-s2026-000.toml",
    "gen-box-321-s2026-001.toml",
    "gen-box-321-s2026-002.toml",
    "gen-box-321-s2026-003.toml",
    "gen-plate-2d-s2026-000.toml",
    "gen-plate-2d-s2026-001.toml",
]


def gaps(fixture, pose):
    return {loc.name: locator_contact(fixture.workpiece, pose, loc).gap_m for loc in fixture.locators}


def assert_exact_gaps(fixture, tr, established, target, clearance):
    """At every knot: established |gap| ≤ touch, others ≥ clearance (or their start gap), target monotone to 0."""
    touch = fixture.tolerances.touch_m
    names = [loc.name for loc in fixture.locators]
    others = [n for n in names if n not in established and n != target]
    g0 = gaps(fixture, tr.poses[0])
    prev = g0[target]
    for pose in tr.poses[1:]:
        g = gaps(fixture, pose)
        for n in established:
            assert abs(g[n]) <= touch, (n, g[n])
        for n in others:
            assert g[n] >= min(clearance, g0[n]) - touch, (n, g[n])
        assert -touch <= g[target] <= prev + touch
        prev = g[target]
    assert abs(gaps(fixture, tr.poses[-1])[target]) <= touch


def plan_like_the_planner(fixture, pose, established, target, ladder=LADDER, diagnose=True):
    """Planner.evaluate's loop: each clearance in turn (the plain program, the ladder at the last)."""
    tr = None
    for clearance in CLEARANCES_M:
        last = clearance == CLEARANCES_M[-1]
        tr = plan_transition(
            fixture, pose, established, target, knots=10, friction_margin=0.1, clearance_m=clearance,
            ladder=ladder if last else ladder[:1], diagnose=diagnose and last,
        )  # fmt: skip
        if tr.ipopt_status in IPOPT_PATH_FOUND and tr.formulation != "":
            break
    return tr, clearance


def random_start_states(fixture, rng, count, sizes=(2, 5), sigma_m=8e-3, sigma_deg=8.0, min_gap_m=2e-4):
    """``count`` poses where a random subset of ``sizes`` locators touch exactly (on their goal faces).

    Each is :func:`solve_goal` for the subset from the goal pose perturbed by normal noise
    (``sigma_m`` per axis, ``sigma_deg`` per rotation axis); a draw is kept when it converges, every
    touched locator lies on the feature it touches at the goal, and every other locator is at least
    ``min_gap_m`` away (no penetration, no accidental touch).
    """
    wp = fixture.workpiece
    names = [loc.name for loc in fixture.locators]
    goal = fixture.goal
    d, nv = fixture.dimension, fixture.ndof
    out = []
    for _ in range(200 * count):
        if len(out) == count:
            break
        k = int(rng.integers(sizes[0], min(sizes[1], len(names) - 1) + 1))
        subset = sorted(str(n) for n in rng.choice(names, size=k, replace=False))
        twist = np.concatenate([rng.normal(0.0, sigma_m, d), rng.normal(0.0, np.radians(sigma_deg), nv - d)])
        guess = goal.retract(twist, wp.com_body)
        res = solve_goal(wp, [fixture.locator(n) for n in subset], guess, tol_m=1e-12)
        if not res.converged:
            continue
        pose = res.pose
        if any(
            feature_at(fixture, fixture.locator(n), pose).label != feature_at(fixture, fixture.locator(n), goal).label
            for n in subset
        ):
            continue
        g = gaps(fixture, pose)
        if all(g[n] >= min_gap_m for n in names if n not in subset):
            out.append((pose, subset))
    return out


def study(files, states_per_file, seed=20, ladder=LADDER):
    """(transitions, paths found, successes, rows) over every remaining target of each start state."""
    rows = []
    for name in files:
        fx = fixplan.load(default_fixture_path() if name == "default" else ROOT / "problems" / name)
        rng = np.random.default_rng([seed, zlib.crc32(name.encode())])  # the same states in any list of files
        sizes = (2, 5) if fx.dimension == 3 else (1, 2)
        for pose, subset in random_start_states(fx, rng, states_per_file, sizes=sizes):
            for target in [loc.name for loc in fx.locators if loc.name not in subset]:
                tr, clearance = plan_like_the_planner(fx, pose, subset, target, ladder=ladder, diagnose=False)
                path = tr.ipopt_status in IPOPT_PATH_FOUND and tr.max_constraint_violation_m <= fx.tolerances.touch_m
                rows.append((name, tuple(subset), target, path, tr.success, tr.formulation, clearance, tr.reason))
    return len(rows), sum(r[3] for r in rows), sum(r[4] for r in rows), rows


if __name__ == "__main__":
    import sys
    import time

    n_states = int(sys.argv[1]) if len(sys.argv) > 1 else 6
    files = STUDY_FILES if len(sys.argv) <= 2 else sys.argv[2:]
    for label, ladder in (("plain program (before)", LADDER[:1]), ("ladder (after)", LADDER)):
        t0 = time.perf_counter()
        n, paths, ok, rows = study(files, n_states, ladder=ladder)
        print(
            f"{label}: {n} transitions from {n_states * len(files)} start states: paths {paths}/{n}, successes {ok}/{n} ({time.perf_counter() - t0:.0f} s)"
        )
        used = {}
        for r in rows:
            used[r[5]] = used.get(r[5], 0) + 1
        print("   formulations:", used)
        for r in rows:
            if not r[3]:
                print("   no path:", r[0], r[1], "->", r[2], ":", r[7][:240])


# ---------------------------------------------------------------------------------------------
# Tests
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def default():
    return fixplan.load(default_fixture_path())


def yawed_about(point_world, angle_rad, pose):
    """``pose`` turned by ``angle_rad`` about the vertical axis through ``point_world``."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return Pose(R @ pose.R_world_body, point_world + R @ (pose.p_world - point_world))


def test_pivot_about_s1_onto_s2_from_five_contacts(default):
    """The box on its base touching E1 and S1, yawed 0.03 rad about S1's contact: S2's gap is the
    yaw times the 0.12 m between the side locators, ≈ 3.6 mm. Keeping the five contacts leaves one
    motion (the pivot about S1 sliding along E1 and the base), and it closes S2 at the goal."""
    est = ["B1", "B2", "B3", "E1", "S1"]
    guess = yawed_about(np.array([0.04, 0.0, 0.025]), 0.03, default.goal)
    pose = solve_goal(default.workpiece, [default.locator(n) for n in est], guess, tol_m=1e-12).pose
    g0 = gaps(default, pose)
    assert g0["S2"] == pytest.approx(0.12 * np.sin(0.03), rel=0.05)
    tr, clearance = plan_like_the_planner(default, pose, est, "S2")
    assert tr.success, tr.reason
    assert tr.kind == "slide" and tr.formulation == "default"
    assert_exact_gaps(default, tr, est, "S2", clearance)
    end = tr.poses[-1]
    dp, ang = end.distance_to(default.goal)
    assert dp <= 1e-6 and ang <= 1e-5  # five kept contacts + S2: the located pose


def test_tipped_box_names_the_kept_contact_on_the_wrong_face(default):
    """`fixplan robust --samples 16 --seed 11`, samples 8 and 15: the push toward E1 tips the box
    (about 17° about x and y) until B2 touches its -y face, not its base face. From there no
    transition that keeps B1, B2, B3, S1 touching closes S2: the elastic re-solve relaxes B2's
    kept contact by ~15 mm, and the reason says so and that B2 sits on the wrong face."""
    from fixplan.spatial import exp_so3

    est = ["B1", "B2", "B3", "S1"]
    guess = Pose(exp_so3(np.radians([17.39, 16.65, 7.10])), np.array([0.1096, 0.0612, 0.0174]))
    pose = solve_goal(default.workpiece, [default.locator(n) for n in est], guess, tol_m=1e-12).pose
    assert feature_at(default, default.locator("B2"), pose).label == "-y"
    assert gaps(default, pose)["S2"] > 0.01
    tr = plan_transition(default, pose, est, "S2", knots=10, clearance_m=CLEARANCES_M[-1])
    assert not tr.success and tr.formulation == ""
    assert "S2 cannot close while B2 stays touching its -y face" in tr.reason
    assert "B2's kept contact constraint" in tr.reason
    assert "B2 touches face -y here, -z at the goal" in tr.reason


@pytest.mark.parametrize("name", ["gen-plate-2d-s2026-000.toml", "gen-plate-2d-s2026-002.toml"])
@pytest.mark.parametrize("tilt_deg", [5.0, 10.0, 15.0])
def test_tilted_plate_on_one_base_locator_plans_to_the_others(name, tilt_deg):
    """A generated plate slid 20 mm away from S and turned by 5–15° about its contact with B1
    (resting on B1 alone, B2 and S clear): rolling on B1 reaches B2 and reaches S."""
    fx = fixplan.load(ROOT / "problems" / name)
    b1 = fx.locator("B1")
    slid = Pose(fx.goal.R_world_body, fx.goal.p_world + np.array([0.02, 0.0]))
    pivot = b1.p_world + np.array([0.02, b1.radius_m])
    th = np.radians(tilt_deg)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    guess = Pose(R @ slid.R_world_body, pivot + R @ (slid.p_world - pivot))
    pose = solve_goal(fx.workpiece, [b1], guess, tol_m=1e-12).pose
    g0 = gaps(fx, pose)
    assert abs(g0["B1"]) <= 1e-12 and g0["B2"] > 2e-3 and g0["S"] > 2e-3
    for target in ("B2", "S"):
        tr, clearance = plan_like_the_planner(fx, pose, ["B1"], target)
        assert tr.success, tr.reason
        assert_exact_gaps(fx, tr, ["B1"], target, clearance)


def test_box_touching_two_locators_plans_to_each_other_one(default):
    """The default box on B1 and B3 only, tilted about their line so that B2 lifts (and the sides
    clear): every other locator is reached from there with the exact gaps of the plan."""
    est = ["B1", "B3"]
    b1, b3 = default.locator("B1").p_world, default.locator("B3").p_world
    axis = (b3 - b1) / np.linalg.norm(b3 - b1)
    from fixplan.spatial import exp_so3

    R = exp_so3(-axis * np.radians(4.0))
    pivot = b1 + np.array([0.0, 0.0, 0.005])
    shifted = Pose(default.goal.R_world_body, default.goal.p_world + np.array([0.008, 0.008, 0.0]))
    guess = Pose(R @ shifted.R_world_body, pivot + R @ (shifted.p_world - pivot))
    pose = solve_goal(default.workpiece, [default.locator(n) for n in est], guess, tol_m=1e-12).pose
    g0 = gaps(default, pose)
    assert all(g0[n] > 1e-3 for n in ("B2", "S1", "S2", "E1")), g0
    for target in ("B2", "S1", "S2", "E1"):
        tr, clearance = plan_like_the_planner(default, pose, est, target)
        assert tr.ipopt_status in IPOPT_PATH_FOUND and tr.formulation, tr.reason
        assert_exact_gaps(default, tr, est, target, clearance)


def test_random_start_states_all_find_a_path():
    """20 seeded start states on generated boxes and plates (a random subset of 2–5 locators
    touching, 1–2 on a plate, the goal perturbed by 8 mm and 8°), every remaining target tried as
    the planner does: the ladder finds a path with exact gaps for every one. The plain program
    alone (``ladder=LADDER[:1]``) misses some of them; run this file as a script for the figures."""
    files = [
        "gen-box-321-s2026-002.toml",
        "gen-box-321-s2026-003.toml",
        "gen-plate-2d-s2026-000.toml",
        "gen-plate-2d-s2026-001.toml",
    ]
    n, paths, _, rows = study(files, 5)
    assert len({(r[0], r[1]) for r in rows}) >= 18 and n >= 20  # (two draws may share a subset)
    missing = [r[:3] + (r[7],) for r in rows if not r[3]]
    assert paths == n, missing


def test_blocking_clearance_is_named():
    """Generated box-321 seed 101 fixture 25: two side locators 11 mm apart. Touching S2 with S1
    held 1 mm away turns the part ≈ 5.2°, and from there E1 cannot close unless S1 comes closer
    than 1 mm (the 0.1 mm clearance plans it): the elastic re-solve relaxes S1's clearance."""
    from fixplan.fixture import loads
    from fixplan.generate import generate_one

    g = generate_one("box-321", 101, 25)
    fx = loads(g.toml_text, source=g.name)
    base = ["B1", "B2", "B3"]
    first = plan_transition(fx, fx.start, base, "S2", knots=10)
    assert first.success
    strict = plan_transition(fx, first.poses[-1], [*base, "S2"], "E1", knots=10, clearance_m=1e-3)
    assert not strict.success
    assert "E1 cannot close while {B1, B2, B3, S2} stay touching and S1 stays ≥ 1 mm away" in strict.reason
    assert "S1's clearance constraint" in strict.reason


def collinear_base():
    """The default box with B3 moved onto the line B1-B2, halfway: (0.10, 0.015, -0.005)."""
    from fixplan.fixture import loads

    text = default_fixture_path().read_text()
    old = "position = [0.10, 0.085, -0.005]"
    assert old in text
    return loads(text.replace(old, "position = [0.10, 0.015, -0.005]"))


def test_closing_together_finds_the_collinear_base_locator():
    """B3 halfway between B1 and B2 on one line: their normal rows satisfy G_B3 = (G_B1 + G_B2)/2,
    so with B1 kept G_B2 = 2 G_B3 − G_B1: B3 closes together with B2 at half its rate (ratio 2),
    and every locator's rows have rank 5 at the goal. With B1 and B2 kept, B3 cannot move at all
    (its row is in their span): no locator closes together with it."""
    fx = collinear_base()
    (c,) = closing_together(fx, ["B1"], "B2")
    assert c.locator == "B3" and c.ratio == pytest.approx(2.0, rel=1e-9) and c.rank == 5
    assert closing_together(fx, ["B1", "B2"], "B3") == []
    assert closing_together(fixplan.load(default_fixture_path()), ["B1"], "B2") == []


def test_redundant_pair_is_named():
    """The collinear base, tilted 3° about y through B1 (B2 and B3 lifted, 2:1): rolling on B1
    cannot touch B2 without touching B3 too, and the reason says why instead of blaming IPOPT."""
    from fixplan.spatial import exp_so3

    fx = collinear_base()
    pivot = fx.locator("B1").p_world + np.array([0.0, 0.0, 0.005])
    R = exp_so3(np.array([0.0, -np.radians(3.0), 0.0]))
    shifted = Pose(fx.goal.R_world_body, fx.goal.p_world + np.array([0.01, 0.01, 0.0]))
    guess = Pose(R @ shifted.R_world_body, pivot + R @ (shifted.p_world - pivot))
    pose = solve_goal(fx.workpiece, [fx.locator("B1")], guess, tol_m=1e-12).pose
    g0 = gaps(fx, pose)
    assert g0["B2"] == pytest.approx(2.0 * g0["B3"], rel=0.05) and g0["B3"] > 1e-3
    tr = plan_transition(fx, pose, ["B1"], "B2", knots=10, clearance_m=CLEARANCES_M[-1])
    assert not tr.success
    assert tr.reason.startswith("B3 closes together with B2 (rank 5 at the goal)"), tr.reason


@pytest.mark.parametrize("half", [(0.1, 0.05, 0.025), (0.1, 0.05)])
def test_surface_feature_is_the_exact_distance_across_edges(half):
    """The whole-surface feature of a box (rectangle) gives Shape.project's distance and closest
    point for points outside beside a face, an edge or a corner, and its normal is the distance's
    gradient (central differences, h = 1e-7): a kept contact can follow it round an edge."""
    from types import SimpleNamespace

    import casadi as ca

    from fixplan.geometry import Box, Rectangle
    from fixplan.planner.features import surface_feature

    size = tuple(2 * h for h in half)
    shape = Box(size) if len(half) == 3 else Rectangle(size)
    feature = surface_feature(SimpleNamespace(workpiece=SimpleNamespace(shape=shape)))
    assert feature is not None and feature.kind == "box"
    rng = np.random.default_rng(3)
    h = np.array(half)
    for _ in range(40):
        q = rng.uniform(-1.0, 1.0, h.shape[0]) * (h + 0.02)
        proj = shape.project(q)
        if proj.distance <= 1e-4:
            continue  # inside or on the surface: a kept contact's tip centre is never there
        assert float(feature.distance(ca, ca.DM(q))) == pytest.approx(proj.distance, abs=1e-12)
        x = np.asarray(ca.evalf(feature.point_at(ca, ca.DM(q)))).ravel()
        np.testing.assert_allclose(x, proj.point_body, atol=1e-12)
        n = np.asarray(ca.evalf(feature.normal_at(ca, ca.DM(q)))).ravel()
        fd = [
            (float(feature.distance(ca, ca.DM(q + e))) - float(feature.distance(ca, ca.DM(q - e)))) / 2e-7
            for e in 1e-7 * np.eye(h.shape[0])
        ]
        np.testing.assert_allclose(n, fd, atol=1e-6)


def test_a_ladder_that_does_not_apply_is_an_input_error(default):
    """Sliding instead of rolling needs a default roll: on the base (three contacts) it never applies."""
    from fixplan.errors import InputError
    from fixplan.planner.fine import Formulation

    with pytest.raises(InputError, match="no formulation of the ladder applies"):
        plan_transition(default, default.start, ["B1", "B2", "B3"], "S1", ladder=[Formulation("x", other_kind=True)])
