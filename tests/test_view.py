"""fixplan view: the scene's geometry, the plan replay, CLI errors, a page that fetches nothing, and the page in a browser.

The browser test (marked ``browser``) opens the page in headless Chromium through Playwright;
``make install`` installs Debian's chromium, so it runs in ``make test`` and skips only where
/usr/bin/chromium is absent.
"""

import copy
import json

import numpy as np
import pytest
from conftest import PROBLEMS, run_cli

import fixplan
from fixplan.errors import InputError
from fixplan.geometry.shapes import Box, Cylinder, Sphere
from fixplan.present.browser import CHROMIUM, open_page
from fixplan.present.meshes import box_mesh, locator_tips, points_world, shape_mesh, sphere_mesh
from fixplan.present.page import external_references, write_scene
from fixplan.present.replay import read_plan, replay_from_plan, rest_replay
from fixplan.present.scene import FORCE_ARROW_FRACTION, MAX_FRAMES, frame_indices, scene_figure, scene_info

fixplan_cli = run_cli


@pytest.fixture(scope="module")
def box():
    return fixplan.load(fixplan.default_fixture_path())


@pytest.fixture(scope="module")
def solved_plan(default_plan, tmp_path_factory):
    """A real plan of the default box with its verification trace, written like 'fixplan solve --out'."""
    result = default_plan
    assert result.ok, result.reason
    path = tmp_path_factory.mktemp("plan") / "plan.json"
    path.write_text(json.dumps(result.to_json()))
    return path


def synthetic_plan(fx, T, rng):
    """A plan JSON whose trace stays at the start pose with random contact forces (T samples)."""
    names = [loc.name for loc in fx.locators]
    d = fx.dimension
    forces = rng.normal(size=(T, len(names), d)) * 10.0
    pose = fx.start.to_json()
    trace = {
        "every_s": 0.01,
        "names": names,
        "time_s": [0.01 * k for k in range(T)],
        "poses": [pose] * T,
        "gaps_m": {n: [0.0] * T for n in names},
        "normal_forces_N": {n: [0.0] * T for n in names},
        "forces_world_N": {n: forces[:, i].tolist() for i, n in enumerate(names)},
        "coupling_wrench": np.zeros((T, fx.ndof)).tolist(),
        "felt_wrench": np.zeros((T, fx.ndof)).tolist(),
        "pressed": [names[:3]] * T,
    }
    # "infeasible": a plan that claims no load (a "planned" one with this trace would claim a
    # load without transitions, which the fixture rules out)
    plan = {
        "status": "infeasible",
        "reason": "",
        "sequence": [names[:3]],
        "transitions": [],
        "tried": [],
        "verification": {"passed": True, "reason": "", "trace": trace},
        "timings": {},
    }
    return plan, forces


def mesh_is_closed_and_outward(V, F):
    edges = {}
    for tri in F:
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            edges[(a, b)] = edges.get((a, b), 0) + 1
    # closed and consistently oriented: every directed edge once, and its reverse once
    assert all(n == 1 and edges.get((b, a)) == 1 for (a, b), n in edges.items())
    # outward: the divergence-theorem volume is positive
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


# -- geometry --------------------------------------------------------------------------------------
def test_box_mesh_at_the_goal_is_the_transformed_corners(box):
    fig = scene_figure(box, rest_replay(box, forces=False))
    info = scene_info(fig)
    ghost = fig.data[info.traces["goal"]]
    shown = np.column_stack([ghost.x, ghost.y, ghost.z])
    half = np.array(box.workpiece.shape.size) / 2
    R, p = box.goal.R_world_body, box.goal.p_world
    corners = np.array([R @ (half * s) + p for s in np.array(np.meshgrid(*[[-1, 1]] * 3)).reshape(3, -1).T])
    assert shown.shape == (8, 3) and len(ghost.i) == 12
    # every transformed corner is a mesh vertex (to the page's 0.1 µm rounding)
    dist = np.linalg.norm(shown[:, None, :] - corners[None, :, :], axis=2)
    assert dist.min(axis=0).max() < 1e-6 and dist.min(axis=1).max() < 1e-6
    # and the goal of the default box is the documented located pose
    assert np.allclose(p, [0.1, 0.05, 0.025], atol=1e-9) and np.allclose(R, np.eye(3), atol=1e-9)


def test_meshes_are_closed_outward_and_on_the_surface():
    V, F = box_mesh([0.1, 0.05, 0.025])
    assert V.shape == (8, 3) and F.shape == (12, 3)
    assert mesh_is_closed_and_outward(V, F) == pytest.approx(0.2 * 0.1 * 0.05)
    cyl = Cylinder(radius=0.03, length=0.1)
    V, F = shape_mesh(cyl)
    vol = mesh_is_closed_and_outward(V, F)
    n = 32  # the inscribed 32-gon prism
    assert vol == pytest.approx(0.5 * n * np.sin(2 * np.pi / n) * 0.03**2 * 0.1)
    assert max(abs(cyl.project(v).distance) for v in V) < 1e-12
    ball = Sphere(radius=0.02)
    V, F = sphere_mesh(ball.radius)
    assert 0.9 * (4 / 3) * np.pi * 0.02**3 < mesh_is_closed_and_outward(V, F) < (4 / 3) * np.pi * 0.02**3
    assert max(abs(ball.project(v).distance) for v in V) < 1e-12
    box = Box(size=(0.2, 0.1, 0.05))
    assert max(abs(box.project(v).distance) for v in shape_mesh(box)[0]) < 1e-12


def test_2d_outline_moves_with_the_pose():
    fx = fixplan.load(PROBLEMS / "rect-3.toml")
    fig = scene_figure(fx, rest_replay(fx, forces=False))
    wp = fig.data[scene_info(fig).traces["workpiece"]]
    shown = np.column_stack([wp.x, wp.y])
    w, h = fx.workpiece.shape.size
    corners = points_world(fx.start, np.array([[-w, -h], [w, -h], [w, h], [-w, h]]) / 2)
    assert np.allclose(shown[:4], corners, atol=1e-7) and np.allclose(shown[4], shown[0])
    assert wp.fill == "toself"


def test_arrows_start_at_the_locator_tips_with_length_proportional_to_the_trace_force(box, rng):
    plan, forces = synthetic_plan(box, 5, rng)
    replay = replay_from_plan(plan, box)
    fig = scene_figure(box, replay)
    info = scene_info(fig)
    assert info.source == "trace" and info.frames == 5
    biggest = np.linalg.norm(forces, axis=2).max()
    assert info.force_scale_m_per_N == pytest.approx(
        FORCE_ARROW_FRACTION * box.workpiece.shape.bounding_radius / biggest
    )
    # the base locators' tips at the start: the locator centre plus its radius along +z (the -z face's inward normal)
    tips, normals = locator_tips(box, box.start)
    for name in ("B1", "B2", "B3"):
        loc = box.locator(name)
        i = [x.name for x in box.locators].index(name)
        assert np.allclose(tips[i], loc.p_world + [0, 0, loc.radius_m], atol=1e-12)
        assert np.allclose(normals[i], [0, 0, 1], atol=1e-12)
    k_forces = info.traces["forces"]
    for frame, f in zip(fig.frames, forces, strict=True):
        arrows = frame.data[frame.traces.index(k_forces)]
        pts = np.array([[np.nan if v is None else v for v in c] for c in (arrows.x, arrows.y, arrows.z)]).T
        starts, ends = pts[0::3], pts[1::3]
        assert np.isnan(pts[2::3]).all()  # segments separated by gaps
        assert np.allclose(starts, tips, atol=2e-7)
        assert np.allclose(ends - starts, info.force_scale_m_per_N * f, atol=2e-7)


def test_long_traces_are_subsampled_keeping_both_ends(box, rng):
    idx = frame_indices(1000, 150)
    assert len(idx) == 150 and idx[0] == 0 and idx[-1] == 999 and np.all(np.diff(idx) > 0)
    assert list(frame_indices(7, 150)) == list(range(7))
    plan, _ = synthetic_plan(box, 400, rng)
    fig = scene_figure(box, replay_from_plan(plan, box))
    assert scene_info(fig).frames == MAX_FRAMES == len(fig.frames) == len(fig.layout.sliders[0].steps)


def test_a_plan_without_trace_replays_its_knot_poses(box, solved_plan):
    plan = json.loads(solved_plan.read_text())
    plan["verification"] = None
    replay = replay_from_plan(plan, box)
    knots = [tr["poses"] for tr in plan["transitions"]]
    assert replay.source == "plan" and replay.forces_world_N is None
    assert len(replay) == sum(len(k) for k in knots) - (len(knots) - 1)
    assert replay.poses[-1].distance_to(box.goal)[0] < 1e-4
    assert replay.pressed[0] == tuple(plan["sequence"][0]) and set(replay.pressed[-1]) == set(plan["sequence"][-1])


def test_rest_scene_shows_the_weight_carried_by_the_base(box):
    replay = rest_replay(box)
    assert replay.source == "rest" and set(replay.pressed[0]) == {"B1", "B2", "B3"}
    total = replay.forces_world_N[0].sum(axis=0)
    assert total == pytest.approx([0.0, 0.0, box.workpiece.mass_kg * 9.81], abs=1e-6)


# -- plan checks -----------------------------------------------------------------------------------
def test_plan_for_another_fixture_is_refused(box, solved_plan, rng):
    with pytest.raises(InputError, match="another fixture: it starts at"):
        read_plan(solved_plan, fixplan.load(PROBLEMS / "box-tilted-start.toml"))
    with pytest.raises(InputError, match="another fixture: its trace has locators"):
        read_plan(solved_plan, fixplan.load(PROBLEMS / "rect-3.toml"))
    plan, _ = synthetic_plan(box, 3, rng)
    bad = copy.deepcopy(plan)
    bad["verification"]["trace"]["poses"][1] = {"position": [0.1, 0.05], "angle_deg": 0.0}
    with pytest.raises(InputError, match="2D pose"):
        replay_from_plan(bad, box)
    bad = copy.deepcopy(plan)
    bad["verification"]["trace"]["forces_world_N"]["B2"] = [[1.0, 2.0]] * 3
    with pytest.raises(InputError, match=r"forces_world_N\.B2\[0\]: got 2 numbers \(expected 3\)"):
        replay_from_plan(bad, box)


def test_cli_errors_are_one_line_and_exit_2(tmp_path, solved_plan):
    bad_json = tmp_path / "bad.json"
    bad_json.write_text("{oops")
    not_plan = tmp_path / "list.json"
    not_plan.write_text("[1, 2]")
    out = tmp_path / "scene.html"
    cases = [
        (["view", "--plan", str(bad_json), "--out", str(out)], "not valid JSON"),
        (["view", "--plan", str(not_plan), "--out", str(out)], "not a fixplan plan"),
        (["view", "--plan", str(tmp_path / "missing.json"), "--out", str(out)], "cannot read"),
        (
            ["view", str(PROBLEMS / "box-tilted-start.toml"), "--plan", str(solved_plan), "--out", str(out)],
            "another fixture",
        ),
        (["view", str(PROBLEMS / "rect-3.toml"), "--plan", str(solved_plan), "--out", str(out)], "another fixture"),
        (["view", "--frames", "1", "--out", str(out)], "--frames"),
    ]
    for args, message in cases:
        proc = fixplan_cli(*args)
        assert proc.returncode == 2, (args, proc.stderr)
        assert proc.stdout == "" and len(proc.stderr.strip().splitlines()) == 1 and message in proc.stderr, proc.stderr
        assert "Traceback" not in proc.stderr
    assert not out.exists()  # nothing written on bad input


def test_cli_writes_the_page_and_never_overwrites_without_force(tmp_path, solved_plan):
    out = tmp_path / "scene.html"
    proc = fixplan_cli("view", "--plan", str(solved_plan), "--out", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    trace = json.loads(solved_plan.read_text())["verification"]["trace"]
    assert summary["source"] == "trace" and summary["frames"] == min(len(trace["time_s"]), MAX_FRAMES)
    assert summary["bytes"] == out.stat().st_size
    before = out.read_bytes()
    again = fixplan_cli("view", "--out", str(out))
    assert again.returncode == 2 and "exists (use --force" in again.stderr and out.read_bytes() == before
    forced = fixplan_cli("view", "--out", str(out), "--force")
    assert forced.returncode == 0 and "still scene" in forced.stdout and out.read_bytes() != before


# -- the page --------------------------------------------------------------------------------------
def test_page_is_self_contained(box, tmp_path, rng):
    plan, _ = synthetic_plan(box, 4, rng)
    path = tmp_path / "scene.html"
    size = write_scene(scene_figure(box, replay_from_plan(plan, box)), path)
    html = path.read_text()
    assert size == len(html.encode()) and size > 3_000_000  # plotly.js (~4.5 MB) is embedded
    assert external_references(html) == []
    assert "<script src=" not in html and "<link " not in html  # every script inline, no stylesheet link
    assert "cdn.plot.ly/plotly" not in html and "ajax/libs/mathjax" not in html  # include_mathjax=False
    # the detector itself catches a CDN script or a protocol-relative stylesheet
    assert external_references('<script src="https://cdn.plot.ly/plotly.min.js"></script>')
    assert external_references("<link rel=stylesheet href='//fonts.example/x.css'>")


@pytest.mark.browser
@pytest.mark.skipif(not CHROMIUM.exists(), reason=f"{CHROMIUM} is absent (make install installs Debian's chromium)")
@pytest.mark.parametrize("case", ["3d-plan", "2d-rest"])
def test_page_renders_in_headless_chromium(case, tmp_path, solved_plan):
    import matplotlib.image

    if case == "3d-plan":
        args = ["--plan", str(solved_plan)]
        trace = json.loads(solved_plan.read_text())["verification"]["trace"]
        frames = min(len(trace["time_s"]), MAX_FRAMES)
    else:
        args = [str(PROBLEMS / "rect-3.toml")]
        frames = 0
    html = tmp_path / "scene.html"
    assert fixplan_cli("view", *args, "--out", str(html)).returncode == 0
    png = tmp_path / "shots" / "scene.png"
    report = open_page(html, png, width=900, height=600)
    assert report.errors == []  # no console errors, no page errors, no fetch attempted
    state = report.state
    assert state["main_svg"] >= 1 and state["traces"] >= 4 and not state["no_webgl_message"]
    assert state["frames"] == state["meta_frames"] == frames
    if case == "3d-plan":
        assert state["is3d"] and state["webgl"] and state["canvases"] >= 1
        assert report.last_frame_shown is True  # the animation ran to the last frame
    # a real picture: tens of KB, many colours, not one flat colour
    assert png.stat().st_size > 20_000
    img = matplotlib.image.imread(png)
    assert img.shape[:2] == (600, 900)
    rgb = img[..., :3].reshape(-1, 3)
    assert rgb.std(axis=0).max() > 0.05
    assert len(np.unique((rgb * 255).round().astype(np.uint8), axis=0)) > 50
