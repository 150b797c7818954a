"""Clamping after loading: least clamp forces, the order, the engine's check (``fixplan clamp``).

Every expected number is derived here by hand:

- a part on its base pressed by one clamp above its centre of mass holds a horizontal load
  pulling it away from its other locators up to ``μ (F + m g)`` (the base's friction, the only
  thing resisting it), and not above; a load into a locator is held whatever its size;
- a clamp pushing the part away from a locator leaves that locator unloaded: nothing holds;
- the tall part (problems/clamp-tall-2d.toml, clamp-tall-3d.toml): its high side clamp alone tips
  it, so the top clamp comes first; the moment of the side clamp about the pivot and the weight's
  against it are computed from the geometry;
- the program's least total force against a sweep of one force and bisection on the other.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import PROBLEMS, run_cli

from fixplan.clamping import analyse_clamping
from fixplan.clamping.forces import build_force_program, cases_of, clamp_scene, solve_force_program
from fixplan.clamping.verify import verify_clamping
from fixplan.fixture import default_fixture_path, load, loads

G = 9.81
TALL_2D = PROBLEMS / "clamp-tall-2d.toml"
TALL_3D = PROBLEMS / "clamp-tall-3d.toml"
BOX_CLAMPED = PROBLEMS / "box-3-2-1-clamped.toml"
HOUSING_CLAMPED = PROBLEMS / "housing-2-pins-clamped.toml"

# a low, wide 2D part: 0.2 x 0.05 m, 1 kg, on B1, B2 (mu = 0.4) with E1 on its -x face; a toggle
# clamp of F newtons on the top face above the centre of mass (0.1, 0.025)
PLATE_2D = """
format = 1
[scene]
name = "plate"
dimension = 2
[workpiece]
shape = "rectangle"
size = [0.2, 0.05]
mass = 1.0
start = {{ position = [0.1, 0.025] }}
[[locator]]
name = "B1"
position = [0.05, 0.0]
friction = 0.4
[[locator]]
name = "B2"
position = [0.15, 0.0]
friction = 0.4
[[locator]]
name = "E1"
position = [0.0, 0.025]
friction = 0.4
[[clamp]]
name = "K1"
position = [0.1, 0.05]
direction = [0.0, -1.0]
friction = 0.3
max_force = 100.0
force = {force}
[[load]]
name = "push"
wrench = [{fx}, {fy}, 0.0]
"""


def _plate(force: float, fx: float, fy: float = 0.0):
    return loads(PLATE_2D.format(force=force, fx=fx, fy=fy), source="plate")


def _box_with_top_clamp(force: float, load: list[float], side_friction: float = 0.0):
    """The default box with a toggle clamp of ``force`` above its centre of mass.

    The base's locators keep mu = 0.25; S1, S2 and E1 get ``side_friction``.
    """
    blocks = default_fixture_path().read_text().split("[[locator]]")
    for i, block in enumerate(blocks):
        if any(f'name = "{n}"' in block for n in ("S1", "S2", "E1")):
            blocks[i] = block.replace("friction = 0.25", f"friction = {side_friction}")
    extra = f"""
[[clamp]]
name = "K1"
position = [0.1, 0.05, 0.054]
direction = [0.0, 0.0, -1.0]
radius = 0.004
friction = 0.3
max_force = 500.0
force = {force}

[[load]]
name = "push"
wrench = [{", ".join(str(x) for x in load)}]
"""
    return loads("[[locator]]".join(blocks) + extra, source="box")


# -- closed forms --------------------------------------------------------------------------------
@pytest.mark.parametrize("force", [5.0, 20.0, 60.0])
def test_2d_a_clamped_plate_holds_a_pull_up_to_mu_times_clamp_plus_weight(force: float) -> None:
    limit = 0.4 * (force + 1.0 * G)  # only the base's friction resists a pull away from E1
    below = analyse_clamping(_plate(force, limit * (1 - 1e-4)), preload_N=0.0, verify=False)
    assert below.holds, below.reason
    above = analyse_clamping(_plate(force, limit * (1 + 1e-4)), preload_N=0.0, verify=False)
    assert not above.holds
    assert "load push is not balanced" in above.reason
    assert [x.holds for x in above.loads] == [False]


def test_2d_a_push_into_the_end_locator_is_held_whatever_its_size() -> None:
    result = analyse_clamping(_plate(5.0, -5000.0), preload_N=0.0, verify=False)
    assert result.holds, result.reason


@pytest.mark.parametrize("angle_deg", [0.0, 30.0, 90.0])
def test_3d_a_clamped_box_holds_a_horizontal_pull_up_to_mu_times_clamp_plus_weight(angle_deg: float) -> None:
    """Pulls in the +x+y quadrant leave S1, S2 and E1 (frictionless here): the base's friction alone resists."""
    force = 40.0
    limit = 0.25 * (force + 2.0 * G)
    u = [math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))]
    for scale, held in ((1 - 1e-4, True), (1 + 1e-4, False)):
        p = scale * limit
        fx = _box_with_top_clamp(force, [p * u[0], p * u[1], 0.0, 0.0, 0.0, 0.0])
        result = analyse_clamping(fx, preload_N=0.0, verify=False)
        assert result.holds is held, (scale, result.reason)


def test_3d_side_locators_with_friction_can_wedge_a_little_above_the_base_alone() -> None:
    """With friction at S1 and S2 a rigid part can be wedged against them: a pull along +x just above
    μ (F + m g) is balanced (S1, S2 pressed by the base's friction in -y, their friction adding to the
    base's in -x: a second-order loss for a first-order gain). The program says so, as the mechanics does.
    """
    force = 40.0
    limit = 0.25 * (force + 2.0 * G)
    fx = _box_with_top_clamp(force, [1.01 * limit, 0.0, 0.0, 0.0, 0.0, 0.0], side_friction=0.25)
    assert analyse_clamping(fx, preload_N=0.0, verify=False).holds


def test_a_clamp_pushing_the_part_away_from_a_locator_never_holds() -> None:
    """A clamp on the -x face pushing +x (away from E1) instead of K3 on the +x face: nothing presses the part onto E1.

    And as a toggle clamp of 400 N beside K3 (at most 300 N): K3 cannot press the part back.
    """
    extra = """
[[clamp]]
name = "K9"
position = [-0.004, 0.09, 0.04]
direction = [1.0, 0.0, 0.0]
radius = 0.004
friction = 0.3
max_force = 500.0
"""
    text = BOX_CLAMPED.read_text()
    without_k3 = text[: text.index('[[clamp]]\nname = "K3"')] + text[text.index("[[load]]") :]
    result = analyse_clamping(loads(without_k3 + extra, source="box"), verify=False)
    assert not result.holds
    assert result.reason.endswith("at best E1 keeps 0 N"), result.reason
    toggle = loads(text + extra.replace("max_force = 500.0", "max_force = 500.0\nforce = 400.0"), source="box")
    result = analyse_clamping(toggle, verify=False)
    assert not result.holds and result.reason.startswith(
        "the clamped part (gravity alone, seated by normal forces) is not balanced"
    )
    # 2D: the plate's clamp pushing up from below its base, between B1 and B2, lifts the part
    fx2 = loads(
        PLATE_2D.format(force=10.0, fx=0.0, fy=0.0).replace(
            "position = [0.1, 0.05]\ndirection = [0.0, -1.0]", "position = [0.1, 0.0]\ndirection = [0.0, 1.0]"
        ),
        source="plate",
    )
    result = analyse_clamping(fx2, preload_N=0.0, verify=False)
    assert not result.holds and "not balanced" in result.reason


def test_a_clamp_pulling_or_leaning_beyond_its_friction_cone_is_refused_with_the_reason() -> None:
    text = BOX_CLAMPED.read_text()
    pulls = loads(text.replace("direction = [0.0, 0.0, -1.0]", "direction = [0.0, 0.0, 1.0]", 1), source="b")
    result = analyse_clamping(pulls, verify=False)
    assert not result.holds and result.reason.startswith("K1 pulls: its direction points out of the part's surface")
    # 20° off the normal with mu = 0.3 (friction angle 16.7°): its tip would slide
    s, c = math.sin(math.radians(20.0)), math.cos(math.radians(20.0))
    leans = loads(text.replace("direction = [0.0, 0.0, -1.0]", f"direction = [{s}, 0.0, {-c}]", 1), source="b")
    result = analyse_clamping(leans, verify=False)
    assert not result.holds and "K1 pushes 20° from the surface normal" in result.reason
    assert "atan(0.3) = 16.7°" in result.reason


# -- the order -----------------------------------------------------------------------------------
def test_2d_the_tall_part_is_clamped_top_first_and_the_other_order_tips_it() -> None:
    fx = load(TALL_2D)
    result = analyse_clamping(fx, verify=False)
    assert result.holds and result.order == ("K2", "K1")
    refused = analyse_clamping(fx, ["K1", "K2"], verify=False)
    assert not refused.holds
    f1 = result.forces_N["K1"]
    # K1 at (0.04, 0.18) pushing -x, about E1 at (0, 0.02): 0.16 F1; the weight at (0.02, 0.1): 0.02 m g
    expected = (
        f"the order K1, K2 fails: K1 alone lifts B1, B2: tipping moment {0.16 * f1:.3g} N·m about E1 "
        f"against {0.02 * G:.3g} N·m of weight"
    )
    assert refused.reason == expected
    assert 0.16 * f1 > 0.02 * G


def test_3d_the_tall_part_is_clamped_top_first_and_the_other_order_tips_it() -> None:
    fx = load(TALL_3D)
    result = analyse_clamping(fx, verify=False)
    assert result.holds and result.order[0] == "K2", result.order
    refused = analyse_clamping(fx, ["K1", "K2", "K3"], verify=False)
    assert not refused.holds
    assert refused.reason.startswith("the order K1, K2, K3 fails: K1 alone lifts ")
    tip, weight = (float(x) for x in _moments(refused.reason))
    assert tip > weight > 0.0


def _moments(reason: str) -> tuple[str, str]:
    head = reason.split("tipping moment ")[1]
    return head.split(" N·m")[0], head.split("against ")[1].split(" N·m")[0]


def test_every_prefix_of_the_order_found_is_balanced_and_the_search_tries_each_set_once() -> None:
    from fixplan.clamping.order import OrderSearch

    fx = load(TALL_3D)
    scene = clamp_scene(fx)
    result = analyse_clamping(fx, verify=False)
    search = OrderSearch(scene, result.forces_N)
    for i in range(1, len(result.order) + 1):
        assert search.check(result.order[:i]).holds
    order, failure = search.search()
    assert order == result.order and failure is None
    assert search.programs <= 2 ** len(scene.clamps) - 1


# -- the program against a sweep -----------------------------------------------------------------
def _feasible(scene, cases, forces: dict[str, float]) -> bool:
    return solve_force_program(scene, build_force_program(scene, cases, 1.0, given=forces)).found


def _least_second(scene, cases, first: str, f1: float, second: str, top: float, fixed: dict[str, float]) -> float:
    """The least force of ``second`` with ``first`` at ``f1`` (the feasible set is an interval): bisection."""
    if not _feasible(scene, cases, {first: f1, second: top, **fixed}):
        return math.inf
    lo, hi = 0.0, top
    if _feasible(scene, cases, {first: f1, second: 0.0, **fixed}):
        return 0.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if _feasible(scene, cases, {first: f1, second: mid, **fixed}) else (mid, hi)
    return hi


@pytest.mark.parametrize(
    ("path", "first", "second", "fixed", "grid"),
    [
        (TALL_2D, "K1", "K2", (), np.linspace(0.0, 12.0, 49)),
        (BOX_CLAMPED, "K1", "K3", ("K2",), np.linspace(0.0, 30.0, 31)),
    ],
    ids=["2d-tall", "3d-box"],
)
def test_the_least_total_force_matches_a_sweep(path, first, second, fixed, grid) -> None:
    fx = load(path)
    scene = clamp_scene(fx)
    cases = cases_of(scene)
    best = solve_force_program(scene, build_force_program(scene, cases, 1.0))
    assert best.found
    held = {k: best.forces_N[k] for k in fixed}
    top = fx.clamps[[k.name for k in fx.clamps].index(second)].max_force_N

    def total(f1: float) -> float:
        return f1 + _least_second(scene, cases, first, f1, second, top, held)

    coarse = [(total(float(f1)), float(f1)) for f1 in grid]
    step = float(grid[1] - grid[0])
    around = min(coarse)[1]
    fine = np.linspace(max(around - step, 0.0), around + step, 81)  # a second sweep around the best point
    swept = min(min(coarse)[0], *(total(float(f1)) for f1 in fine))
    program = best.forces_N[first] + best.forces_N[second]
    assert program <= swept + 1e-6  # the program is never beaten by a point of the sweep
    # ... and the sweep comes within its fine step times the total's slope, (1 + dF2/dF1): on the
    # tall part K2 (lever 0.015 m about the tipping point) answers K1 (lever 0.16 m) at about 11 to 1
    assert swept <= program + 12.0 * float(fine[1] - fine[0])


# -- the engine -----------------------------------------------------------------------------------
@pytest.mark.parametrize("path", [TALL_2D, TALL_3D, BOX_CLAMPED, HOUSING_CLAMPED], ids=lambda p: p.stem)
def test_the_engine_keeps_the_clamped_part_still(path) -> None:
    result = analyse_clamping(load(path))
    v = result.verification
    assert v is not None and v.passed, v
    assert v.max_displacement_m <= 1e-9 and v.max_gap_m <= 1e-9
    assert result.holds


@pytest.mark.parametrize(("scale", "moves"), [(0.9, False), (1.1, True)])
def test_the_engine_slides_the_plate_above_mu_times_clamp_plus_weight_and_not_below(scale, moves) -> None:
    """The closed form again, in the engine: the plate stays below the limit and slides off E1 above it."""
    force = 20.0
    fx = _plate(force, scale * 0.4 * (force + G))
    scene = clamp_scene(fx)
    v = verify_clamping(fx, ("K1",), {"K1": force}, {c.name: c.point_world for c in scene.clamps})
    assert (v.max_displacement_m > 1e-6) is moves, v
    assert v.passed is not moves


# -- a part on pins -------------------------------------------------------------------------------
def _frictionless_housing(loads_toml: str):
    """problems/housing-2-pins-clamped.toml with every rest and pin frictionless and the given loads."""
    import re

    text = re.sub(r"friction = 0\.(25|2)\n", "friction = 0.0\n", HOUSING_CLAMPED.read_text())
    return loads(text[: text.index("[[load]]")] + loads_toml, source="housing")


def test_the_round_pin_touching_at_the_located_pose_is_a_contact_and_the_clear_diamond_pin_is_not() -> None:
    scene = clamp_scene(load(HOUSING_CLAMPED))
    assert scene.owners == ("B1", "B2", "B3", "P1")  # P2 is 0.1 mm clear on both lands
    assert [c.name for c in scene.cs.contacts if c.owner == "P1"] == ["P1", "P1#2"]
    for c in scene.cs.contacts[3:]:
        assert np.allclose(c.normal_world, [-1.0, 0.0, 0.0], atol=1e-12)  # radial: the hole's -x wall on P1


def test_pins_closed_form_least_forces_of_the_frictionless_housing() -> None:
    """Frictionless rests and pins, preload 1 N, loads pull-x (12 N along -x) and lift (25 N up).

    pull-x: only K2 (+x) and P1 (-x, ≥ 1 N) take x forces: K2 = 12 + 1 = 13 N.
    lift: the rests carry T = F1 + m g - 25; K2 presses P1 with 13 N at best at its rim, 0.004 m below
    c, a moment about y the rests take as N_B3 - (N_B1 + N_B2) = 0.004 x 13 / 0.05 = 1.04 N; with
    N_B1 = N_B2 = 1 N: T = 4 + 1.04, F1 = 25 - 19.62 + 5.04 = 10.42 N.
    """
    fx = _frictionless_housing(
        '[[load]]\nname = "pull-x"\nwrench = [-12.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n\n'
        '[[load]]\nname = "lift"\nwrench = [0.0, 0.0, 25.0, 0.0, 0.0, 0.0]\n'
    )
    result = analyse_clamping(fx)
    assert result.holds, result.reason
    assert result.forces_N["K2"] == pytest.approx(13.0, abs=1e-6)
    assert result.forces_N["K1"] == pytest.approx(25.0 - 2.0 * G + 4.0 + 0.004 * 13.0 / 0.05, abs=1e-6)
    v = result.verification
    assert v is not None and v.passed and v.max_displacement_m <= 1e-9
    assert v.locator_forces_N["P1"]["engine_N"] == pytest.approx(13.0, abs=1e-5)  # K2's push, no friction to share it


def test_pins_a_load_only_the_clear_diamond_pin_could_take_is_not_held() -> None:
    """Frictionless, a 2 N load along +y: no counted contact has a y normal (P2 is 0.1 mm away)."""
    fx = _frictionless_housing('[[load]]\nname = "mill-y"\nwrench = [0.0, 2.0, 0.0, 0.0, 0.0, 0.0]\n')
    result = analyse_clamping(fx, verify=False)
    assert not result.holds
    assert result.reason == "load mill-y is not balanced by the locators with any clamp forces up to max_force"


def test_the_cli_clamps_a_part_on_pins() -> None:
    proc = run_cli("clamp", HOUSING_CLAMPED, "--json", check_rc=0)
    out = json.loads(proc.stdout)
    assert out["holds"] is True and out["order"] == ["K1", "K2"]
    assert set(out["verification"]["locator_forces_N"]) == {"B1", "B2", "B3", "P1"}


# -- the command line -----------------------------------------------------------------------------
def test_cli_json_has_the_documented_keys() -> None:
    proc = run_cli("clamp", TALL_2D, "--json", check_rc=0)
    out = json.loads(proc.stdout)
    assert {"holds", "order", "forces_N", "loads", "verification", "reason"} <= set(out)
    assert out["holds"] is True and out["order"] == ["K2", "K1"]
    assert set(out["forces_N"]) == {"K1", "K2"}
    assert [set(x) >= {"name", "holds", "min_locator_force_N"} for x in out["loads"]] == [True]
    assert {"passed", "max_displacement_m"} <= set(out["verification"])


def test_cli_exit_1_with_the_reason_and_2_on_bad_input() -> None:
    proc = run_cli("clamp", TALL_2D, "--order", "K1,K2", "--no-verify", check_rc=1)
    assert "K1 alone lifts B1, B2: tipping moment" in proc.stdout
    for args, words in (
        (("--order", "K1"), "--order misses K2"),
        (("--order", "K1,K1"), "names a clamp twice"),
        (("--order", "K1,K7"), "unknown clamp 'K7'"),
        (("--preload", "-1"), "--preload is -1"),
    ):
        proc = run_cli("clamp", TALL_2D, *args, check_rc=2)
        assert words in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    proc = run_cli("clamp", check_rc=2)
    assert "no [[clamp]] entries" in proc.stderr


# -- the problem library's hand-derived clamping verdicts -------------------------------------------
def _clamp_entries() -> list[dict]:
    import tomllib

    return tomllib.loads((PROBLEMS / "expected.toml").read_text())["clamp"]


@pytest.mark.parametrize("entry", _clamp_entries(), ids=lambda e: e["file"])
def test_clamping_matches_the_hand_derived_verdict(entry: dict) -> None:
    fx = load(PROBLEMS / entry["file"])
    result = analyse_clamping(fx, verify=False)
    assert result.holds is entry["holds"], result.reason
    if "order" in entry:
        assert list(result.order) == entry["order"]
    if "refused_order" in entry:
        refused = analyse_clamping(fx, entry["refused_order"], verify=False)
        assert not refused.holds
        assert entry["because"] in refused.reason, refused.reason


# -- the scene view --------------------------------------------------------------------------------
def test_view_draws_each_clamp_pushing_onto_the_part_with_its_force() -> None:
    from fixplan.present.replay import rest_replay
    from fixplan.present.scene import CLAMP_ARROW_MAX_NORMALS, NORMAL_FRACTION, scene_figure, scene_info

    fx = load(TALL_2D)
    forces = analyse_clamping(fx, verify=False).forces_N
    fig = scene_figure(fx, rest_replay(fx), clamp_forces_N=forces)
    info = scene_info(fig)
    tips = fig.data[info.traces["clamps"]]
    assert list(tips.text) == [f"K1 {forces['K1']:.3g} N", f"K2 {forces['K2']:.3g} N"]
    shafts = fig.data[info.traces["clamp forces"]]
    x, y = np.array(shafts.x, dtype=float), np.array(shafts.y, dtype=float)  # (start, end, None) per clamp
    normal = NORMAL_FRACTION * fx.workpiece.shape.bounding_radius
    for i, k in enumerate(fx.clamps):
        start, end = np.array([x[3 * i], y[3 * i]]), np.array([x[3 * i + 1], y[3 * i + 1]])
        assert np.allclose(end, k.p_world + k.radius_m * k.direction_world, atol=1e-6)  # it ends on the part
        along = end - start
        assert np.allclose(along / np.linalg.norm(along), k.direction_world, atol=1e-6)  # along its direction
        expected = min(max(forces[k.name] * info.force_scale_m_per_N, 0.25 * normal), CLAMP_ARROW_MAX_NORMALS * normal)
        assert np.linalg.norm(along) == pytest.approx(expected, rel=1e-5)


# -- solve --clamp ---------------------------------------------------------------------------------
def test_solve_clamp_continues_the_loading_plan_with_the_clamping_stage(tmp_path) -> None:
    from fixplan.plan_schema import validate_plan_document

    plan = tmp_path / "plan.json"
    proc = run_cli("solve", TALL_2D, "--clamp", "--json", "--out", plan, check_rc=0)
    out = json.loads(proc.stdout)
    assert out["status"] == "planned"
    clamping = out["clamping"]
    assert clamping["holds"] is True and clamping["order"] == ["K2", "K1"]
    assert clamping["verification"]["passed"] is True
    assert json.loads(plan.read_text())["clamping"] == clamping
    assert validate_plan_document(json.loads(plan.read_text()), 2) == []  # the plan file's schema takes it
    run_cli("verify", plan, check_rc=0)  # and verify replays the loading as before
    proc = run_cli("solve", PROBLEMS / "box-3-2-1.toml", "--clamp", check_rc=2)
    assert "--clamp: no [[clamp]] entries" in proc.stderr


def test_engine_forces_beside_the_programs_and_a_preload_check_would_refuse_a_clamping_that_holds() -> None:
    """The measurement behind not checking the preload in the engine (docs/fixture-format.md).

    The program's ``clamped`` case is seated by normal forces alone, so its forces are the closed
    form: K1 above c, K2 and K3 through c's height and x: the base carries m g + K1 at 1/4, 1/4,
    1/2; S1 = S2 = K2/2; E1 = K3. The engine keeps the part within 1e-9 m while a locator the
    program gave ≥ 1 N ends below half of it (friction elsewhere carries its share).
    """
    result = analyse_clamping(load(BOX_CLAMPED))
    v = result.verification
    assert v is not None and v.passed
    f = result.forces_N
    program = {name: x["program_N"] for name, x in v.locator_forces_N.items()}
    t = 2.0 * G + f["K1"]
    expected = {"B1": t / 4, "B2": t / 4, "B3": t / 2, "S1": f["K2"] / 2, "S2": f["K2"] / 2, "E1": f["K3"]}
    assert program == pytest.approx(expected, abs=1e-6)
    engine = {name: x["engine_N"] for name, x in v.locator_forces_N.items()}
    assert min(engine.values()) < 0.5 * result.preload_N <= min(program.values()) + 1e-6
    assert v.max_displacement_m <= 1e-9 and v.max_gap_m <= 1e-9
