"""Collision-only bodies ([[obstacle]]): a floor or a base plate that catches the part, never locates it.

Closed forms: a block resting on a plane carries its weight ``m g`` on it; on a plane tilted by
θ with μ < tan θ it slides with ``a = g (sin θ − μ cos θ)``. Invariants: the part never goes
through a floor; obstacles never enter contact states, the goal or ``G``.
"""

import math
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import fixplan
from fixplan.engine.detect import obstacle_query2, obstacle_query3
from fixplan.engine.simulator import Simulator
from fixplan.errors import FixtureError
from fixplan.geometry import Box, Cylinder, Rectangle, Sphere
from fixplan.geometry.collision import BOX, PLANE, collision_points, obstacle_gap, plane_frame
from fixplan.spatial import Pose, matrix_from_rpy

G = 9.81


def block_on_plane(theta_deg=0.0, mu=0.3, extra="", obstacle=None):
    """A 0.2×0.1×0.05 box of 2 kg lying flat on a plane tilted by θ about y (gravity −z).

    The fixture's one locator is far away (a file needs one); the plane passes through the origin
    with normal ``(−sin θ, 0, cos θ)``, the box rests on it, its −z face flat.
    """
    th = math.radians(theta_deg)
    n = (-math.sin(th), 0.0, math.cos(th))
    c = [0.025 * v for v in n]
    ob = obstacle or (
        f'[[obstacle]]\nname = "floor"\nshape = "plane"\npoint = [0.0, 0.0, 0.0]\n'
        f"normal = [{n[0]:.17g}, {n[1]:.17g}, {n[2]:.17g}]\nfriction = {mu}\n"
    )
    return fixplan.loads(
        textwrap.dedent(
            f"""
            format = 1
            [scene]
            name = "block-on-plane"
            [workpiece]
            shape = "box"
            size = [0.2, 0.1, 0.05]
            mass = 2.0
            start = {{ position = [{c[0]:.17g}, {c[1]:.17g}, {c[2]:.17g}], rpy_deg = [0.0, {-theta_deg:.17g}, 0.0] }}
            [simulation]
            tolerance = 1e-10
            [[locator]]
            name = "far"
            position = [5.0, 5.0, 5.0]
            friction = 0.3
            """
        )
        + ob
        + extra
    )


def lowest_vertex_z(pose: Pose, half) -> float:
    pts, _ = collision_points(Box(tuple(2 * np.asarray(half))), 0)
    return float(min(pose.point_world_from_body(p)[2] for p in pts))


# -- the compiled queries are the NumPy reference ------------------------------------------------


def test_compiled_obstacle_queries_match_the_reference(rng):
    """obstacle_query3 / obstacle_query2 give the gap, normal and contact point of obstacle_gap (1e-12)."""
    for d, query in ((3, obstacle_query3), (2, obstacle_query2)):
        for _ in range(200):
            kind = int(rng.integers(0, 2))
            if d == 3:
                R_o = matrix_from_rpy(rng.uniform(-math.pi, math.pi, 3))
                R_b = matrix_from_rpy(rng.uniform(-math.pi, math.pi, 3))
            else:
                a, b = rng.uniform(-math.pi, math.pi, 2)
                R_o = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
                R_b = np.array([[math.cos(b), -math.sin(b)], [math.sin(b), math.cos(b)]])
            o, half, p = rng.normal(size=d), rng.uniform(0.1, 1.0, d), rng.normal(size=d)
            b, rho = rng.normal(size=d), float(rng.uniform(0.0, 0.2))
            obs = np.concatenate([[kind], o, R_o.reshape(-1), half])[None, :]
            slots = np.concatenate([b, [rho, 0.0]])[None, :]
            got = query(obs, slots, 0, R_b, p)
            gap, n, x = obstacle_gap(kind, R_o, o, half, R_b @ b + p, rho)
            assert got[0] == pytest.approx(gap, abs=1e-12)
            assert np.allclose(got[1 : 1 + d], n, atol=1e-12) and np.allclose(got[1 + d :], x, atol=1e-12)


def test_collision_points_of_each_shape():
    """Box: its 8 corners; cylinder: 2 rims of n points on its radius; sphere: its centre with its radius."""
    pts, r = collision_points(Box((0.2, 0.1, 0.05)), 16)
    assert pts.shape == (8, 3) and np.allclose(np.abs(pts), [0.1, 0.05, 0.025]) and not r.any()
    pts, r = collision_points(Cylinder(0.03, 0.1), 16)
    assert pts.shape == (32, 3) and np.allclose(np.hypot(pts[:, 0], pts[:, 1]), 0.03)
    assert set(np.round(pts[:, 2], 12)) == {-0.05, 0.05}
    pts, r = collision_points(Sphere(0.04), 16)
    assert np.allclose(pts, 0.0) and r.tolist() == [0.04]
    pts, _ = collision_points(Rectangle((0.2, 0.1)), 16)
    assert pts.shape == (4, 2)
    # a plane's frame: last axis the unit normal, right-handed
    R, o = plane_frame(np.zeros(3), np.array([0.0, 3.0, 4.0]))
    assert np.allclose(R[:, 2], [0.0, 0.6, 0.8]) and np.linalg.det(R) == pytest.approx(1.0)
    R2, _ = plane_frame(np.zeros(2), np.array([0.0, 2.0]))
    assert np.allclose(R2[:, 1], [0.0, 1.0]) and np.linalg.det(R2) == pytest.approx(1.0)
    # a point 1 m above a plane through the origin, a ball of radius 0.25 there
    assert obstacle_gap(PLANE, R, o, np.zeros(3), np.array([0.0, 0.6, 0.8]), 0.25)[0] == pytest.approx(0.75)
    assert obstacle_gap(BOX, np.eye(3), np.zeros(3), np.ones(3), np.array([0.0, 0.0, 0.5]), 0.0)[0] == pytest.approx(
        -0.5
    )


# -- closed forms --------------------------------------------------------------------------------


def test_block_resting_on_a_plane_carries_its_weight():
    """On a horizontal plane: the plane pushes m g = 19.62 N up, no friction; the block does not move."""
    fx = block_on_plane(0.0)
    sim = Simulator(fx)
    p0 = sim.pose.p_world.copy()
    sim.run(0.5)
    f = sim.obstacle_force_world()
    assert f == pytest.approx([0.0, 0.0, 2.0 * G], abs=1e-6)
    assert np.linalg.norm(sim.pose.p_world - p0) <= 1e-9
    assert abs(sim.obstacle_gap_m()) <= 1e-9


@pytest.mark.parametrize(("theta_deg", "mu"), [(30.0, 0.3), (20.0, 0.1)])
def test_block_slides_down_a_tilted_plane_with_the_closed_form_acceleration(theta_deg, mu):
    """μ < tan θ: v(t) = g (sin θ − μ cos θ) t down the slope (1e-6 relative), N = m g cos θ, flat on the plane."""
    th = math.radians(theta_deg)
    fx = block_on_plane(theta_deg, mu)
    sim = Simulator(fx)
    traj = sim.run(0.3, record_every=10)
    down = -np.array([math.cos(th), 0.0, math.sin(th)])
    a = G * (math.sin(th) - mu * math.cos(th))
    for t, nu in zip(traj.time_s[1:], traj.velocity[1:], strict=True):
        assert nu[:3] @ down == pytest.approx(a * t, rel=1e-6)
        assert np.linalg.norm(nu[3:]) <= 1e-8  # it slides flat, no tipping
    n = np.array([-math.sin(th), 0.0, math.cos(th)])
    f = sim.obstacle_force_world()
    assert f @ n == pytest.approx(2.0 * G * math.cos(th), rel=1e-6)
    assert f @ down == pytest.approx(-mu * 2.0 * G * math.cos(th), rel=1e-6)
    assert sim.obstacle_gap_m() >= -1e-9


def test_block_sticks_on_a_plane_tilted_below_the_friction_angle():
    """θ = 20°, μ = 0.5 > tan 20°: it stays put (≤ 1e-8 m in 1 s)."""
    sim = Simulator(block_on_plane(20.0, 0.5))
    p0 = sim.pose.p_world.copy()
    sim.run(1.0)
    assert np.linalg.norm(sim.pose.p_world - p0) <= 1e-8


def test_rectangle_resting_on_a_line_in_2d():
    """2D: a 1 kg rectangle on the line y = 0 carries m g; shoved sideways (5 N, μ = 0.2) it slides at (5 − μ m g)/m."""
    fx = fixplan.loads(
        textwrap.dedent(
            """
            format = 1
            [scene]
            name = "plate-on-line"
            dimension = 2
            [workpiece]
            shape = "rectangle"
            size = [0.2, 0.1]
            mass = 1.0
            start = { position = [0.0, 0.05] }
            [simulation]
            tolerance = 1e-10
            [[locator]]
            name = "far"
            position = [5.0, 5.0]
            friction = 0.3
            [[obstacle]]
            name = "floor"
            shape = "line"
            point = [0.0, 0.0]
            normal = [0.0, 1.0]
            friction = 0.2
            """
        )
    )
    sim = Simulator(fx)
    sim.run(0.2)
    assert sim.obstacle_force_world() == pytest.approx([0.0, G], abs=1e-6)
    traj = sim.run(0.2, np.array([5.0, 0.0, 0.0]), record_every=20)
    a = 5.0 - 0.2 * G
    for t, nu in zip(traj.time_s[1:] - 0.2, traj.velocity[1:], strict=True):
        assert nu[0] == pytest.approx(a * t, rel=1e-6)
    assert sim.obstacle_gap_m() >= -1e-9


def test_cylinder_lands_on_a_base_plate_box():
    """A cylinder dropped 5 mm onto a box plate comes to rest on it: the plate carries m g, its rim no deeper than 1e-6 m."""
    fx = fixplan.loads(
        textwrap.dedent(
            """
            format = 1
            [scene]
            name = "cyl-on-plate"
            [workpiece]
            shape = "cylinder"
            radius = 0.03
            length = 0.1
            mass = 1.0
            start = { position = [0.0, 0.0, 0.055] }
            [[locator]]
            name = "far"
            position = [5.0, 5.0, 5.0]
            friction = 0.3
            [[obstacle]]
            name = "plate"
            shape = "box"
            size = [0.3, 0.3, 0.02]
            pose = { position = [0.0, 0.0, -0.01] }
            """
        )
    )
    sim = Simulator(fx)
    traj = sim.run(0.5, record_every=10)
    assert sim.obstacle_force_world()[2] == pytest.approx(G, rel=1e-4)
    assert sim.pose.p_world[2] == pytest.approx(0.05, abs=1e-6)
    assert traj.max_penetration_m <= 1e-6


# -- the report: the default fixture has a floor --------------------------------------------------


def test_pushed_off_its_locators_the_default_box_lands_on_the_floor():
    """fixplan simulate --wrench 6,0,0,0,0,0 (1 s): the box slid off its locators to z = −2.34 m before the
    floor; now no corner goes below the floor by more than the engine's penetration (1e-6 m) at any sample,
    and it ends lying on it, pushed along x against the floor's friction."""
    fx = fixplan.load(fixplan.default_fixture_path())
    (floor,) = fx.obstacles
    z_floor = float(floor.o_world[2])
    assert z_floor == pytest.approx(-0.01) and floor.is_plane
    sim = Simulator(fx)
    traj = sim.run(1.0, np.array([6.0, 0.0, 0.0, 0.0, 0.0, 0.0]), record_every=5)
    half = np.asarray(fx.workpiece.shape.half)
    lowest = min(lowest_vertex_z(Pose(_rot(q), p), half) for p, q in zip(traj.position, traj.orientation, strict=True))
    assert lowest >= z_floor - 1e-6
    assert traj.max_penetration_m <= 1e-6
    assert sim.pose.p_world[2] == pytest.approx(z_floor + 0.025, abs=1e-6)  # flat on the floor at the end
    assert sim.pose.p_world[0] > 0.3  # it did slide off the base locators
    # the obstacle is no locator: reports, traces and contact states name the six locators only
    names = tuple(loc.name for loc in fx.locators)
    assert traj.names == list(names) and traj.gap.shape[1] == 6 and traj.normal_force.shape[1] == 6
    assert [c.name for c in sim.contacts()] == list(names)
    assert set(sim.in_contact(1e-9, 1e-4)) <= set(names) and set(sim.pressed()) <= set(names)
    assert sim.obstacle_force_world()[2] == pytest.approx(2.0 * G, rel=1e-3)


def test_simulate_cli_keeps_the_default_box_above_its_floor():
    """The reported command line: the box ends on the floor (z = −0.01 + 0.025), not 2.34 m below it."""
    out = subprocess.run(
        [sys.executable, "-m", "fixplan.cli", "simulate", "--wrench", "6,0,0,0,0,0", "--duration", "1", "--json"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0, out.stderr
    import json

    data = json.loads(out.stdout)
    assert data["pose"]["position"][2] == pytest.approx(0.015, abs=1e-6)
    assert [c["name"] for c in data["contacts"]] == ["B1", "B2", "B3", "S1", "S2", "E1"]
    (floor,) = data["obstacles"]
    assert floor["name"] == "floor" and abs(floor["gap"]) <= 1e-6
    assert floor["force"][2] == pytest.approx(2.0 * G, rel=1e-3)


def _rot(q):
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def test_obstacles_never_locate():
    """The floor changes neither the goal pose nor the contact set's G (rank 6) nor the locators."""
    from fixplan.locating import contact_set

    with_floor = fixplan.load(fixplan.default_fixture_path())
    text = fixplan.default_fixture_path().read_text()
    bare = fixplan.loads(text.split("[[obstacle]]")[0] + "[manipulator]" + text.split("[manipulator]")[1])
    assert not bare.obstacles and with_floor.obstacles
    assert np.array_equal(with_floor.goal.p_world, bare.goal.p_world)
    assert np.array_equal(with_floor.goal.R_world_body, bare.goal.R_world_body)
    cs_a, cs_b = contact_set(with_floor, with_floor.goal), contact_set(bare, bare.goal)
    assert np.array_equal(cs_a.G, cs_b.G) and np.linalg.matrix_rank(cs_a.G) == 6
    assert with_floor.names == bare.names


# -- the file ------------------------------------------------------------------------------------

BASE = textwrap.dedent(
    """
    format = 1
    [scene]
    name = "t"
    [workpiece]
    shape = "box"
    size = [0.2, 0.1, 0.05]
    mass = 2.0
    start = { position = [0.1, 0.05, 0.025] }
    [[locator]]
    name = "B1"
    position = [0.05, 0.03, -0.001]
    radius = 0.001
    friction = 0.3
    """
)

ERRORS = [
    ('shape = "mesh"', "obstacle.o.shape", "mesh obstacles come later"),
    ('shape = "cone"', "obstacle.o.shape", "expected one of: plane, box"),
    ('shape = "line"\npoint = [0.0, 0.0]\nnormal = [0.0, 1.0]', "obstacle.o.shape", "expected one of: plane, box"),
    ('shape = "plane"\npoint = [0.0, 0.0, -0.01]', "obstacle.o.normal", "missing (expected 3 numbers)"),
    ('shape = "plane"\npoint = [0.0, 0.0, -0.01]\nnormal = [0.0, 0.0, 0.0]', "obstacle.o.normal", "zero vector"),
    ('shape = "plane"\npoint = [0.0, 0.0]\nnormal = [0.0, 0.0, 1.0]', "obstacle.o.point", "expected 3 for a 3D scene"),
    (
        'shape = "plane"\npoint = [0, 0, -0.01]\nnormal = [0, 0, 1]\nsize = [1, 1, 1]',
        "obstacle.o.size",
        "not a key of a plane",
    ),
    ('shape = "plane"\npoint = [0, 0, -0.01]\nnormal = [0, 0, 1]\nfriction = -1', "obstacle.o.friction", "≥ 0"),
    ('shape = "plane"\npoint = [0, 0, -0.01]\nnormal = [0, 0, 1]\ncolour = 1', "obstacle.o.colour", "unknown key"),
    ('shape = "box"\nsize = [1, 1, 0.01]', "obstacle.o.pose", "missing (expected a table)"),
    ('shape = "box"\nsize = [1, 1]\npose = { position = [0, 0, -1] }', "obstacle.o.size", "expected 3 for a 3D scene"),
    (
        'shape = "box"\nsize = [1, 1, 0.1]\npose = { position = [0, 0, -1], rpy = [0, 0, 0] }',
        "obstacle.o.pose.rpy",
        "unknown key",
    ),
    # the part at its start pose (and, for a full fixture, its located pose) clear of the body
    (
        'shape = "plane"\npoint = [0, 0, 0.01]\nnormal = [0, 0, 1]',
        "obstacle.o",
        "inside this collision-only body by 0.01 m",
    ),
    # a plate through the middle of the part, no corner of either inside the other
    (
        'shape = "box"\nsize = [0.4, 0.4, 0.01]\npose = { position = [0.1, 0.05, 0.02] }',
        "obstacle.o",
        "start pose is inside",
    ),
]


@pytest.mark.parametrize(("body", "key", "message"), ERRORS)
def test_malformed_obstacles_are_refused_with_their_key(body, key, message, tmp_path):
    path = tmp_path / "f.toml"
    path.write_text(BASE + f'[[obstacle]]\nname = "o"\n{body}\n')
    with pytest.raises(FixtureError) as info:
        fixplan.load(path)
    lines = str(info.value).splitlines()
    assert any(line.startswith(f"{path}: {key}: ") and message in line for line in lines), lines


def test_an_obstacle_through_the_located_pose_is_refused(tmp_path):
    """The default box with its floor raised 2 mm above its located bottom face (z = 0): refused at the goal."""
    text = fixplan.default_fixture_path().read_text().replace("point = [0.0, 0.0, -0.01]", "point = [0.0, 0.0, 0.002]")
    # the start pose rests on the base tips too, so move the start up out of the way first
    text = text.replace("position = [0.115, 0.06, 0.025]", "position = [0.115, 0.06, 0.03]")
    path = tmp_path / "raised.toml"
    path.write_text(text)
    out = subprocess.run(
        [sys.executable, "-m", "fixplan.cli", "validate", str(path)], capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 2 and "Traceback" not in out.stderr
    lines = out.stderr.strip().splitlines()
    assert lines == [
        f"{path}: obstacle.floor: the part at its located pose is inside this collision-only body by 0.002 m "
        "(expected it clear: an obstacle never locates, so it must lie beyond the part where the locators hold it)"
    ]


def test_obstacles_round_trip_through_a_rotated_twin():
    """A rotated world carries its floor: the twin loads, its floor is the turned one, the goal clear of it."""
    from fixplan.twins import rotated_fixture_text

    R = matrix_from_rpy(np.radians([20.0, -35.0, 50.0]))
    text = fixplan.default_fixture_path().read_text()
    twin = fixplan.loads(rotated_fixture_text(text, R))
    (floor,) = twin.obstacles
    assert np.allclose(floor.R_world_obstacle[:, 2], R @ [0.0, 0.0, 1.0])
    assert np.allclose(floor.o_world @ floor.R_world_obstacle[:, 2], -0.01)


# -- the planner -----------------------------------------------------------------------------------

WALLED = textwrap.dedent(
    """
    format = 1
    [scene]
    name = "walled"
    dimension = 2
    gravity = [0.0, 0.0]
    [workpiece]
    shape = "rectangle"
    size = [0.2, 0.1]
    mass = 1.0
    start = { position = [0.5, 0.05], angle_deg = 10.0 }
    [[locator]]
    name = "T"
    position = [-0.002, 0.05]
    radius = 0.001
    friction = 0.3
    """
)


def test_fine_paths_never_cross_a_plane_obstacle():
    """The only way to the target locator crosses the line x = 0.3: with that line as an obstacle there is no
    path; without it the same transition plans. A floor under the path (y = −0.05, clear) changes nothing, and
    every knot keeps the part's corners above it."""
    from fixplan.planner.fine import plan_transition

    bare = fixplan.loads(WALLED)
    free = plan_transition(bare, bare.start, (), "T", diagnose=False)
    assert free.success
    wall = '[[obstacle]]\nname = "wall"\nshape = "line"\npoint = [0.3, 0.0]\nnormal = [1.0, 0.0]\n'
    walled = fixplan.loads(WALLED + wall)
    blocked = plan_transition(walled, walled.start, (), "T", diagnose=False)
    assert not blocked.success
    floor = '[[obstacle]]\nname = "floor"\nshape = "line"\npoint = [0.0, -0.05]\nnormal = [0.0, 1.0]\n'
    floored = fixplan.loads(WALLED + floor)
    tr = plan_transition(floored, floored.start, (), "T", diagnose=False)
    assert tr.success
    corners, _ = collision_points(Rectangle((0.2, 0.1)), 0)
    assert min(float(min((p.R_world_body @ corners.T)[1] + p.p_world[1])) for p in tr.poses) >= -0.05 - 1e-9


@pytest.mark.parametrize("family", ["box-321", "plate-2d", "box-321-free", "plate-2d-free"])
def test_generate_floor_adds_only_a_floor_under_the_same_draw(family):
    """--floor: the same file plus one [[obstacle]] plane normal to gravity, 10 mm (0.1 mm steps) below the
    part's lowest point at its start and goal; the goal pose and the locators are unchanged."""
    from fixplan.generate import generate_one

    plain = generate_one(family, 2026, 1)
    floored = generate_one(family, 2026, 1, floor=True)
    head, tail = floored.toml_text.split("\n[[obstacle]]\n")
    assert head == plain.toml_text and floored.params == plain.params
    a, b = fixplan.loads(plain.toml_text), fixplan.loads(floored.toml_text)
    (floor,) = b.obstacles
    d = b.dimension
    assert floor.is_plane and np.allclose(floor.R_world_obstacle[:, -1], np.eye(d)[d - 1])
    assert np.allclose(a.goal.p_world, b.goal.p_world) and a.names == b.names
    pts, _ = collision_points(b.workpiece.shape, 0)
    low = min(float(pose.point_world_from_body(p)[d - 1]) for pose in (b.start, b.goal) for p in pts)
    assert low - 0.0101 <= floor.o_world[d - 1] <= low - 0.01


def test_the_approach_from_free_space_keeps_clear_of_the_floor():
    """A free start with a floor (generate --floor): the approach exists as without the floor, and no pose of it
    puts a corner below the floor; with the floor raised between the start and the staging pose (the start above
    it, the staging pose in it) there is no approach."""
    from fixplan.generate import generate_one
    from fixplan.planner.approach import _obstacle_gaps, plan_approach

    gen = generate_one("box-321-free", 2026, 0, floor=True)
    fx = fixplan.loads(gen.toml_text)
    plain = plan_approach(fixplan.loads(gen.toml_text.split("\n[[obstacle]]\n")[0]))
    with_floor = plan_approach(fx)
    assert plain is not None and with_floor is not None
    assert len(with_floor.poses) == len(plain.poses)
    assert min(float(_obstacle_gaps(fx, p).min()) for p in with_floor.poses) >= 0.0
    # the floor 12.5 mm higher: the start is still above it (1.8 mm), the staging pose 0.5 mm into it
    from dataclasses import replace

    (floor,) = fx.obstacles
    raised = replace(fx, obstacles=(replace(floor, o_world=floor.o_world + [0.0, 0.0, 0.0125]),))
    assert _obstacle_gaps(raised, raised.start)[0] > 0.0 > _obstacle_gaps(raised, with_floor.staging)[0]
    assert plan_approach(raised) is None
