"""Pins, holes and bores drawn (``view``, ``haptic``) and the haptic session with pins and bores.

The meshes are checked against closed forms: a polygonal pin of n sides is a prism and a frustum
whose volumes are exact (``A(ρ) = (n/2) ρ² sin(2π/n)``), a diamond pin's section is clipped to its
lands' width, every mesh is closed where it should be (each edge in two triangles).
"""

from __future__ import annotations

import json
import math
from collections import Counter

import numpy as np
import pytest
from conftest import PROBLEMS, run_cli

import fixplan
from fixplan.present.meshes import bore_mesh, contact_anchors, hole_mesh, part_mesh, pin_mesh, shape_mesh

HOUSING = PROBLEMS / "housing-2-pins.toml"
SHAFT = PROBLEMS / "shaft-in-bore.toml"


def _volume(V: np.ndarray, F: np.ndarray) -> float:
    """The signed volume of a closed triangle mesh (divergence theorem)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def _edge_uses(F: np.ndarray) -> Counter[tuple[int, int]]:
    return Counter(tuple(sorted((int(t[i]), int(t[(i + 1) % 3])))) for t in F for i in range(3))


def test_round_pin_mesh_is_a_closed_prism_and_frustum() -> None:
    """P1 (d = 9.8 mm, L = 12 mm, 1 mm chamfer), 32 sides: volume A(r)(L − c) + c/3 (A(r) + A(r−c) + √(A(r) A(r−c)))."""
    pin = fixplan.load(HOUSING).pins[0]
    V, F = pin_mesh(pin, segments=32)
    assert set(_edge_uses(F).values()) == {2}  # closed: every edge between two triangles
    r, L, c, n = 0.0049, 0.012, 0.001, 32

    def area(rho: float) -> float:
        return 0.5 * n * rho * rho * math.sin(2.0 * math.pi / n)

    a1, a2 = area(r), area(r - c)
    expected = a1 * (L - c) + c / 3.0 * (a1 + a2 + math.sqrt(a1 * a2))
    assert _volume(V, F) == pytest.approx(expected, rel=1e-12)  # outward winding: positive
    axial = (V - pin.p_world) @ pin.axis_world
    assert axial.min() == pytest.approx(0.0, abs=1e-15) and axial.max() == pytest.approx(L, abs=1e-15)


def test_diamond_pin_mesh_keeps_its_lands_only() -> None:
    """P2's section is clipped to |y| ≤ w/2 across its land direction (±y: clipped along x), round on its lands."""
    pin = fixplan.load(HOUSING).pins[1]
    V, _F = pin_mesh(pin, segments=64)
    rel = V - pin.p_world
    land = np.asarray(pin.land_direction_world)
    across = np.cross(pin.axis_world, land)
    assert np.abs(rel @ across).max() <= 0.5 * pin.land_width_m + 1e-15
    radial = np.hypot(rel @ land, rel @ across)
    assert radial.max() == pytest.approx(0.5 * pin.diameter_m, rel=1e-12)  # the lands' crest


def test_hole_and_bore_meshes_follow_their_profiles() -> None:
    """A through hole: an open tube (its two rims used once); a bore: closed at its bottom, open at its mouth."""
    fx = fixplan.load(HOUSING)
    V, F = hole_mesh(fx.workpiece.holes[0])
    uses = _edge_uses(F)
    assert sum(1 for k in uses.values() if k == 1) == 2 * 32  # the mouth's and the exit's rims
    depth = (fx.workpiece.holes[0].p_body - V) @ fx.workpiece.holes[0].axis_body
    assert depth.min() == pytest.approx(0.0, abs=1e-15) and depth.max() == pytest.approx(0.03, abs=1e-15)
    bore = fixplan.load(SHAFT).bores[0]
    V, F = bore_mesh(bore)
    uses = _edge_uses(F)
    assert sum(1 for k in uses.values() if k == 1) == 32  # the mouth's rim only
    radial = np.linalg.norm(np.cross(V - bore.p_world, bore.axis_world), axis=1)
    assert radial.max() == pytest.approx(0.5 * bore.diameter_m, rel=1e-12)
    # the part is drawn with its holes: the shape's vertices, then the holes'
    Vp, _Fp = part_mesh(fx)
    assert len(Vp) == len(shape_mesh(fx.workpiece.shape)[0]) + 2 * len(hole_mesh(fx.workpiece.holes[0])[0])


def test_view_draws_the_pins(tmp_path) -> None:
    out = tmp_path / "scene.html"
    proc = run_cli("view", HOUSING, "--out", out, "--json", check_rc=0)
    assert json.loads(proc.stdout)["html"] == str(out)
    from fixplan.present.replay import rest_replay
    from fixplan.present.scene import scene_figure

    fx = fixplan.load(HOUSING)
    fig = scene_figure(fx, rest_replay(fx))
    names = [t.name for t in fig.data]
    assert "P1" in names and "P2" in names
    html = out.read_text()
    assert '"name":"P1"' in html.replace(" ", "") and '"name":"P2"' in html.replace(" ", "")


def test_contact_anchors_put_a_pin_at_its_nearest_contact() -> None:
    """Seated toward +x, P1 touches H1's −x wall at its rim (z = 0.011) and the mouth's edge (z = 0.0005), normal −x.

    Both gaps are 0 (a generator line): the anchor is either end.
    """
    fx = fixplan.load(HOUSING)
    points, normals = contact_anchors(fx, fx.goal)
    assert points.shape == (5, 3)  # B1 B2 B3, then P1 P2
    np.testing.assert_allclose(points[3, :2], [-0.045, 0.0], atol=1e-12)
    assert min(abs(points[3, 2] - 0.011), abs(points[3, 2] - 0.0005)) < 1e-12
    np.testing.assert_allclose(normals[3], [-1.0, 0.0, 0.0], atol=1e-12)


def test_haptic_session_with_pins_reaches_the_goal() -> None:
    """At its located pose the housing is at the goal: every rest and P1 pressed; P2, centred in its play, is not needed."""
    from fixplan.interactive.session import HapticSession

    fx = fixplan.load(HOUSING)
    s = HapticSession(fx, None, realtime=False, synchronous=True, until_goal=True, duration_s=1.0, guidance=False)
    assert s.names == ("B1", "B2", "B3", "P1", "P2")
    assert s.goal_names == frozenset({"B1", "B2", "B3", "P1"})
    result = s.run()
    assert result.reached, result.reason
    assert result.final_gaps_m["P2"] == pytest.approx(1e-4, abs=1e-9)
    assert result.max_penetration_m < 1e-9


def test_haptic_session_guides_the_part_onto_its_pins() -> None:
    """With guidance, a housing that starts above its pins is carried, inserted and seated by the staged
    insertion (the guide ran the locators' executor before and stopped at 0.1 s on the first pin's name):
    the session reaches the goal, the rests within the final gap, each hole's axis within its pin's play,
    the states in the insertion's order."""
    from fixplan.interactive.session import HapticSession
    from fixplan.locating import axis_offsets_m, inserts
    from fixplan.settings import HAPTIC

    fx = fixplan.load(PROBLEMS / "housing-2-pins-load.toml")
    assert fx.start.distance_to(fx.goal)[0] > 0.01  # starts off the pins
    result = HapticSession(fx, None, realtime=False, synchronous=True, until_goal=True, duration_s=8.0).run()
    assert result.reached, result.reason
    assert all(abs(result.final_gaps_m[n]) <= HAPTIC.verification.final_gap_m for n in ("B1", "B2", "B3"))
    pose = result.trace.poses[-1]  # the last sample, at rest on the goal
    for i in inserts(fx):
        assert max(axis_offsets_m(fx, pose, i)) <= i.play_m * (1.0 + HAPTIC.insertion.axis_play_rel) + 1e-9
    first = [set(s) for _t, s in result.states]
    engaged = [k for k, s in enumerate(first) if {"P1", "P2"} & s]
    rests = [k for k, s in enumerate(first) if {"B1", "B2", "B3"} <= s]
    assert engaged and rests and engaged[0] < rests[0]  # on the pins before the rests


def test_haptic_session_guides_a_shaft_into_its_bore() -> None:
    """A shaft located by its bore alone (no locator: no full fixture) takes a session; guided, it is seated.

    problems/shaft-into-bore.toml: the 0.5 kg shaft starts tilted 2° in the bore's 1 mm chamfer. The
    goal is the insertion's last state, the bore and its bottom (``B1``, ``B1.bottom``), at rest with the
    axis within the radial play (D − d)/2 = 2e-5 m. Located pose: upright, centre at z = −0.04 + 0.05 = 0.01 m.
    """
    from fixplan.interactive.session import HapticSession
    from fixplan.locating import axis_offsets_m, bottom_gap_m, inserts
    from fixplan.settings import HAPTIC

    fx = fixplan.load(PROBLEMS / "shaft-into-bore.toml")
    assert not fx.is_full and not fx.locators  # refused before: "a haptic session needs a full fixture"
    s = HapticSession(fx, None, realtime=False, synchronous=True, until_goal=True, duration_s=8.0)
    assert s.names == ("B1",) and s.goal_names == frozenset({"B1", "B1.bottom"})
    result = s.run()
    assert result.reached, result.reason
    assert result.reason.startswith("seated in B1 (its bottom closed, the axis within the play), at rest")
    states = [set(st) for _t, st in result.states]
    assert states[-1] == {"B1", "B1.bottom"} and all("B1.bottom" not in st for st in states[:-1])
    pose = result.trace.poses[-1]  # the last sample, at rest on the bottom
    (bore,), (ins,) = fx.bores, inserts(fx)
    play = 0.5 * (0.02004 - 0.02)
    assert ins.play_m == pytest.approx(play, abs=1e-15)
    tol = fx.tolerances.touch_m + HAPTIC.execution.contact_gap_m
    assert abs(bottom_gap_m(fx, pose, bore)) <= tol  # the bottom closed
    assert max(axis_offsets_m(fx, pose, ins)) <= play  # the axis within the play, at the mouth and the end
    assert pose.p_world[2] == pytest.approx(0.01, abs=1e-6)
    z = pose.R_world_body[:, 2]
    assert math.degrees(math.acos(min(abs(float(z[2])), 1.0))) < 1e-4  # upright (the 2° start tilt gone)
    assert result.max_penetration_m < 1e-5
    assert result.final_gaps_m["B1"] == pytest.approx(0.0, abs=tol)


def test_haptic_session_still_refuses_a_part_nothing_locates() -> None:
    """Pins without rests enough (and no bore) locate nothing the session can aim for: refused in one line."""
    import dataclasses

    from fixplan.errors import InfeasibleError
    from fixplan.interactive.session import HapticSession

    fx = fixplan.load(HOUSING)
    one_rest = dataclasses.replace(fx, locators=fx.locators[:1], goal_pose=None)
    with pytest.raises(InfeasibleError, match="a haptic session needs a full fixture"):
        HapticSession(one_rest, None, realtime=False, synchronous=True, guidance=False)


def test_haptic_app_draws_pins_and_colours_the_pressed_one() -> None:
    """The live scene has a mesh per pin (world frame) beside the locators; P1, pressed at the goal, turns red."""
    from fixplan.interactive.app import LOCATOR, PRESSED, HapticApp
    from fixplan.interactive.session import HapticSession

    fx = fixplan.load(HOUSING)
    s = HapticSession(fx, None, realtime=False, synchronous=True, until_goal=True, duration_s=1.0, guidance=False)
    app = HapticApp(s, port=0)
    app.start()
    app._stop.set()  # the test draws itself, between ticks
    app._thread.join()
    app.always_draw = True
    try:
        assert set(app.locators) == {"B1", "B2", "B3", "P1", "P2"}
        s._warm_up()
        for _ in range(200):
            s.tick(0.0)
        app.draw()
        assert app._colors["P1"] == PRESSED and app._colors["P2"] == LOCATOR
        forces = np.asarray(app.forces.points)
        assert forces.shape[0] == 5  # one arrow per name: the pins' at their contacts
    finally:
        app.stop()
