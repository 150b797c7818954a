"""The pin's tip on the part's face around its hole: a pin that misses its hole holds the part up.

Closed forms (:func:`fixplan.geometry.pins.tip_face_contacts`): a box's bottom face at z = −15 mm
(outward normal −z, the hole's axis), a hole of R = 5 mm with a 0.5 mm mouth chamfer in it, a
pin of r = 4.9 mm, L = 12 mm with a 1 mm tip chamfer standing under it (axis +z):

- the capture of the chamfers is (R − r) + c_h + c_p = 1.6 mm; the tip's face (radius r − c_p)
  lies wholly outside the mouth's outer edge (R + c_h) once the axes are more than
  R + c_h + r − c_p = 9.4 mm apart;
- upright, its tip ``h`` below the face: one contact, gap exactly ``h``, normal +z (along the hole's
  axis ``−a``, from the pin into the part), at the tip face's edge farthest from the hole;
- tilted by θ about x: the deepest point of the tip face's edge is ``(r − c_p) sin θ`` nearer;
- off the part's extent, or over the hole, or below the face nearer the mouth's edge: none.

The compiled kernel gives the reference's rows; in the engine the housing lowered 12 mm beside its
pins rests on their tips (it fell onto its rests through them before), and one lowered 3 mm off
(beyond the capture, the mouth's edge still over the tip) rests there still.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import PROBLEMS

import fixplan
from fixplan.aot import kernel
from fixplan.engine.simulator import Simulator
from fixplan.geometry import Box, Cylinder, Sphere
from fixplan.geometry.pins import HoleBody, PinBody, mouth_face, tip_face_contacts
from fixplan.settings import DEFAULT
from fixplan.spatial import Pose, exp_so3

HOUSING = PROBLEMS / "housing-2-pins.toml"
PART = Box((0.12, 0.08, 0.03))
R_HOLE, C_HOLE, R_PIN, L_PIN, C_PIN = 0.005, 0.0005, 0.0049, 0.012, 0.001
MOUTH = np.array([-0.04, 0.0, -0.015])  # the hole's mouth on the bottom face (body = world here)
DOWN = np.array([0.0, 0.0, -1.0])  # the hole's axis: out of the part through the mouth
UP = -DOWN
_face_contacts = kernel("fixplan.geometry._pin_kernels", "face_contacts")


def _hole(mouth: np.ndarray = MOUTH) -> HoleBody:
    face = mouth_face(PART, mouth, DOWN, 1e-9, DEFAULT.pins.axis_angle_rad)
    assert face is not None
    return HoleBody(mouth, DOWN, R_HOLE, 0.03, C_HOLE, False, face)


def _pin(offset_xy: tuple[float, float], below_m: float, tilt_rad: float = 0.0) -> PinBody:
    """An upright pin (tilted about x by ``tilt_rad`` about its tip's centre) whose tip's centre is ``below_m`` under the face."""
    u = exp_so3(np.array([tilt_rad, 0.0, 0.0])) @ UP
    tip = MOUTH + np.array([offset_xy[0], offset_xy[1], -below_m])
    return PinBody(tip - L_PIN * u, u, R_PIN, L_PIN, C_PIN)


# -- the face of a primitive part --------------------------------------------------------------------
def test_mouth_face_of_a_box_and_a_cylinder_in_closed_form() -> None:
    face = mouth_face(PART, MOUTH, DOWN, 1e-9, 0.01)
    np.testing.assert_array_equal(face.centre, [0.0, 0.0, -0.015])
    np.testing.assert_array_equal(face.normal, DOWN)
    assert face.half_m == (0.06, 0.04) and not face.disk  # the box's x and y half extents
    assert face.inside_m(np.array([0.05, 0.0, -0.015])) == pytest.approx(0.01)
    side = mouth_face(PART, np.array([0.06, 0.01, 0.0]), np.array([1.0, 0.0, 0.0]), 1e-9, 0.01)
    assert side.half_m == (0.04, 0.015) and side.centre[0] == 0.06  # the +x face: y and z half extents
    end = mouth_face(Cylinder(0.02, 0.1), np.array([0.005, 0.0, 0.05]), np.array([0.0, 0.0, 1.0]), 1e-9, 0.01)
    assert end.disk and end.half_m[0] == 0.02 and end.centre[2] == 0.05
    assert mouth_face(Cylinder(0.02, 0.1), np.array([0.02, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]), 1e-9, 0.01) is None
    assert mouth_face(Sphere(0.02), np.array([0.0, 0.0, 0.02]), UP, 1e-9, 0.01) is None
    # a mouth off the face's plane, or an axis not along its normal: no face
    assert mouth_face(PART, MOUTH + [0.0, 0.0, 1e-6], DOWN, 1e-9, 0.01) is None
    assert mouth_face(PART, MOUTH, exp_so3(np.array([0.02, 0.0, 0.0])) @ DOWN, 1e-9, 0.01) is None


# -- closed forms ------------------------------------------------------------------------------------
@pytest.mark.parametrize("below", [0.002, 1e-5, 0.0, -3e-6])
@pytest.mark.parametrize("heading", [0.0, 1.1, -2.5])
def test_a_pin_beyond_the_capture_rests_on_the_face_with_its_tips_height(below: float, heading: float) -> None:
    """Axes 12 mm apart: the tip's face wholly over the material; gap = its height, normal +z, farthest from the hole."""
    d = np.array([math.cos(heading), math.sin(heading), 0.0])
    pin = _pin(tuple(0.012 * d[:2]), below)
    (c,) = tip_face_contacts(pin, _hole())
    assert c.kind == "face"
    assert c.gap_m == pytest.approx(below, abs=1e-16)
    np.testing.assert_array_equal(c.normal_world, UP)  # along the hole's axis, from the pin into the part
    np.testing.assert_allclose(c.point_hole_world[2], -0.015, atol=1e-17)  # on the face
    tip_centre = MOUTH + np.array([*(0.012 * d[:2]), -below])
    np.testing.assert_allclose(c.point_pin_world, tip_centre + (R_PIN - C_PIN) * d, atol=1e-15)


def test_the_engines_points_of_a_flat_tip_are_its_edge_at_right_angles() -> None:
    """Four points (``face_points``): the tip face's edge every 90° from the farthest, each at the tip's height."""
    pin = _pin((0.0, -0.012), 0.0005)
    found = tip_face_contacts(pin, _hole(), points=4)
    assert len(found) == 4
    tip_centre = MOUTH + np.array([0.0, -0.012, -0.0005])
    for c in found:
        assert c.gap_m == pytest.approx(0.0005, abs=1e-16)
        assert np.linalg.norm(c.point_pin_world - tip_centre) == pytest.approx(R_PIN - C_PIN, abs=1e-15)
    np.testing.assert_allclose(found[0].point_pin_world, tip_centre + [0.0, -(R_PIN - C_PIN), 0.0], atol=1e-15)


@pytest.mark.parametrize("theta", [1e-3, 0.01, 0.2])
def test_a_tilted_tip_touches_at_its_deepest_point(theta: float) -> None:
    """Tilted by θ about x, the tip face's centre ``h`` below the face: the gap is ``h − (r − c_p) sin θ``."""
    h = 0.001
    pin = _pin((0.0, -0.012), h, theta)
    (c,) = tip_face_contacts(pin, _hole())
    assert c.gap_m == pytest.approx(h - (R_PIN - C_PIN) * math.sin(theta), abs=1e-15)
    np.testing.assert_array_equal(c.normal_world, UP)


def test_beyond_45_degrees_the_chamfers_base_is_the_nearer_circle() -> None:
    """Tilted 60°: the chamfer's base circle (radius r, c_p behind the tip) reaches nearer the face than the tip's face."""
    theta, h = math.radians(60.0), 0.004
    pin = _pin((0.0, -0.02), h, theta)
    (c,) = tip_face_contacts(pin, _hole())
    u = pin.axis_world
    tip_face = h - (R_PIN - C_PIN) * math.sin(theta)
    base = h + C_PIN * float(u @ UP) - R_PIN * math.sin(theta)  # its centre c_p back along u, then r toward the face
    assert base < tip_face
    assert c.gap_m == pytest.approx(base, abs=1e-15)


def test_no_face_contact_over_the_hole_or_off_the_part() -> None:
    hole = _hole()
    # within the capture (1.6 mm): the tip is over the mouth (the chamfers' contacts' business)
    assert tip_face_contacts(_pin((0.0015, 0.0), 0.0005), hole, points=4) == []
    # coaxial, deep in the hole: nothing of the face
    assert tip_face_contacts(_pin((0.0, 0.0), -0.005), hole, points=4) == []
    # the pin 20 mm beyond the part's -x edge (x = -0.06 + 0.02 + 0.0039): its tip wholly off the face
    assert tip_face_contacts(_pin((-0.044, 0.0), 0.0005), hole, points=4) == []
    # straddling the edge (its axis 1 mm beyond it): of its four points, only the one over the part
    (inner,) = tip_face_contacts(_pin((-0.021, 0.0), 0.0005), hole, points=4)
    assert inner.point_hole_world[0] == pytest.approx(-0.061 + (R_PIN - C_PIN), abs=1e-15)


def test_partly_over_the_mouth_the_point_over_the_material_holds() -> None:
    """Axes 3 mm apart (beyond the 1.6 mm capture, the mouth's edge over the tip): the face's farthest point holds, gap h."""
    (c,) = tip_face_contacts(_pin((0.003, 0.0), 0.0002), _hole())
    assert c.gap_m == pytest.approx(0.0002, abs=1e-16)
    assert c.point_pin_world[0] - MOUTH[0] == pytest.approx(0.003 + R_PIN - C_PIN, abs=1e-15)


def test_below_the_face_nearer_the_mouths_edge_is_not_the_faces() -> None:
    """A tip 1 mm into the material, 0.2 mm beyond the mouth's outer edge: nearer the hole, so not a face contact.

    Only 0.05 mm in, the face is the nearer surface: a contact, gap −0.05 mm.
    """
    e = R_HOLE + C_HOLE + 0.0002 - (R_PIN - C_PIN)  # the tip face's farthest point 0.2 mm beyond the mouth's edge
    assert tip_face_contacts(_pin((e, 0.0), -0.001), _hole()) == []
    (c,) = tip_face_contacts(_pin((e, 0.0), -5e-5), _hole())
    assert c.gap_m == pytest.approx(-5e-5, abs=1e-16)


# -- the compiled kernel -----------------------------------------------------------------------------
def _arrays(pin: PinBody, hole: HoleBody) -> tuple[np.ndarray, np.ndarray]:
    land = pin.land_direction_world if pin.land_direction_world is not None else np.zeros(3)
    p = np.array([*pin.base_world, *pin.axis_world, pin.radius_m, pin.length_m, pin.chamfer_m, *land,
                  pin.land_width_m, 0.0 if pin.land_direction_world is None else 1.0])  # fmt: skip
    f = hole.face
    h = np.array([*hole.mouth_world, *hole.axis_world, hole.radius_m, hole.depth_m, hole.chamfer_m, float(hole.blind),
                  2.0 if f.disk else 1.0, *f.centre, *f.normal, *f.e1, *f.half_m])  # fmt: skip
    return p, h


def test_compiled_face_contacts_are_the_reference() -> None:
    """300 seeded pins around a turned part's faced hole (boxes and cylinders' ends): the same rows, to 1e-15 m."""
    from fixplan.engine.pin_slots import FACE_COLUMNS as SLOT_COLUMNS
    from fixplan.engine.pin_slots import MAX_CONTACTS as SLOT_ROWS
    from fixplan.geometry._pin_kernels import FACE, FACE_COLUMNS, MAX_CONTACTS

    assert (SLOT_COLUMNS, SLOT_ROWS) == (FACE_COLUMNS, MAX_CONTACTS)
    rng = np.random.default_rng(7)
    out = np.zeros((MAX_CONTACTS, 11))
    counts = []
    for k in range(300):
        R, t = exp_so3(rng.normal(size=3)), rng.normal(size=3) * 0.05
        if k % 3:
            shape: Box | Cylinder = Box(tuple(rng.uniform(0.02, 0.1, 3)))
            axis_body = np.zeros(3)
            j = int(rng.integers(3))
            axis_body[j] = rng.choice([-1.0, 1.0])
            mouth_body = rng.uniform(-0.5, 0.5, 3) * np.asarray(shape.size) * 0.6
            mouth_body[j] = axis_body[j] * shape.size[j] / 2
        else:
            shape = Cylinder(float(rng.uniform(0.01, 0.05)), float(rng.uniform(0.02, 0.1)))
            axis_body = np.array([0.0, 0.0, rng.choice([-1.0, 1.0])])
            mouth_body = np.array([*rng.uniform(-0.4, 0.4, 2) * shape.radius, axis_body[2] * shape.length / 2])
        R_hole = float(rng.uniform(0.003, 0.008))
        face = mouth_face(shape, mouth_body, axis_body, 1e-12, 0.01)
        assert face is not None
        hole = HoleBody(t + R @ mouth_body, R @ axis_body, R_hole, 0.02, float(rng.uniform(0.0, 0.001)), False,
                        face.moved(R, t))  # fmt: skip
        a = hole.axis_world
        u = exp_so3(rng.normal(size=3) * rng.choice([0.0, 0.02, 0.5])) @ -a
        across = (np.eye(3) - np.outer(a, a)) @ rng.normal(size=3)
        tip = hole.mouth_world + across / np.linalg.norm(across) * rng.uniform(0.0, 0.03) + a * rng.uniform(-1e-3, 3e-3)
        r = R_hole * float(rng.uniform(0.9, 0.99))
        length = float(rng.uniform(0.01, 0.03))
        pin = PinBody(tip - length * u, u, r, length, float(rng.uniform(0.0, 0.4)) * r)
        for points in (1, 4):
            ref = tip_face_contacts(pin, hole, points=points)
            s = DEFAULT.pins
            n = _face_contacts(*_arrays(pin, hole), points, s.coaxial_rel, s.rim_samples, s.golden_steps,
                               s.face_arc_inset, out, 0)  # fmt: skip
            assert n == len(ref)
            for row, c in zip(out[:n], ref, strict=True):
                assert row[0] == FACE
                np.testing.assert_allclose(row[1:4], c.point_pin_world, atol=1e-15)
                np.testing.assert_allclose(row[4:7], c.point_hole_world, atol=1e-15)
                np.testing.assert_allclose(row[7:10], c.normal_world, atol=1e-15)
                assert row[10] == pytest.approx(c.gap_m, abs=1e-15)
        counts.append(len(ref))
    assert 0 in counts and 4 in counts and any(0 < c < 4 for c in counts)  # none, all and some were compared


# -- the engine --------------------------------------------------------------------------------------
def _lowered(offset: np.ndarray, without_face: bool = False) -> Simulator:
    """The housing 1 mm above its pins' tips, moved by ``offset`` across them, pushed down 20 N for 0.5 s."""
    fixture = fixplan.load(HOUSING)
    goal = fixture.goal
    sim = Simulator(fixture)
    if without_face:  # the pins' contacts as before the face was modelled (a hole's first 10 columns)
        sim._pins._holes_body = np.ascontiguousarray(sim._pins._holes_body[:, :10])
    sim.set_state(Pose(goal.R_world_body, goal.p_world + np.array([*offset, 0.013])))
    sim.run(0.5, np.array([0.0, 0.0, -20.0, 0.0, 0.0, 0.0]))
    return sim


def test_a_part_lowered_beside_its_pins_rests_on_their_tips() -> None:
    """12 mm off along x (beyond the 1.6 mm capture, each tip wholly under the bottom face): held at the pins' height.

    The bottom face on the tips (z = L = 12 mm, the centre at 27 mm), at rest, the penetration within
    1e-9 m; the tips carry the weight and the push, split by the moments about the two tips' centres
    (x = −40.1 mm and 40 mm, the centre of mass at 12 mm): F1 = 39.62 · 28 / 80.1 N about their centres,
    within the bounds of each centre of pressure anywhere on its 3.9 mm tip face. Before, the part
    fell through the pins' tips onto its rests, its holes' walls snapping it sideways over the pins.
    """
    sim = _lowered(np.array([0.012, 0.0]))
    goal_z = 0.015
    assert sim.pose.p_world[2] == pytest.approx(goal_z + 0.012, abs=1e-9)
    np.testing.assert_allclose(sim.pose.p_world[:2], [0.012, 0.0], atol=1e-9)  # not drawn over the holes
    assert sim.max_penetration_m < 1e-9
    assert np.linalg.norm(sim.twist) < 1e-8
    reports = {r.name: r for r in sim.contacts()}
    total = 2.0 * 9.81 + 20.0
    assert reports["P1"].force_world[2] + reports["P2"].force_world[2] == pytest.approx(total, rel=1e-6)
    rho = R_PIN - C_PIN  # each tip's centre of pressure lies within its face: the split's bounds
    low = total * (0.04 - rho - 0.012) / ((0.04 - rho) - (-0.0401 - rho))
    high = total * (0.04 + rho - 0.012) / ((0.04 + rho) - (-0.0401 + rho))
    assert low <= reports["P1"].force_world[2] <= high
    assert reports["P1"].force_world[2] == pytest.approx(total * 0.028 / 0.0801, rel=0.01)  # measured: 0.2 %
    assert all(reports[n].normal_force_N == 0.0 for n in ("B1", "B2", "B3"))  # the rests 12 mm below
    before = _lowered(np.array([0.012, 0.0]), without_face=True)
    assert (
        before.pose.p_world[2] < goal_z + 0.012 - 0.005
    )  # through the tips (5.3 mm; 7.5 before the diamond's tip was its lands only): what the face stops


def test_a_part_beyond_the_capture_with_the_mouth_over_the_tip_rests_on_it() -> None:
    """3 mm off along x (capture 1.6 mm; the tips' faces partly under the mouths): held still on the tips.

    The face under each tip's far edge and the mouth's edge across its face share the load. (Without
    the face the mouths' edges alone held it, sliding: 0.6 mm back along x in the 0.5 s. Off along
    y instead, the centre of mass lies outside the supports, beside the line of the pins: the part
    rolls off them, with the face or without.)
    """
    sim = _lowered(np.array([0.003, 0.0]))
    assert sim.pose.p_world[2] == pytest.approx(0.015 + 0.012, abs=1e-9)
    np.testing.assert_allclose(sim.pose.p_world[:2], [0.003, 0.0], atol=1e-9)
    assert sim.max_penetration_m < 1e-9
    # still: 5e-8 rad/s about x at the end (the diamond's tip is its lands only, so P2 holds it on
    # two arcs), while the position stays within 1e-9 m
    assert np.linalg.norm(sim.twist) < 1e-7
    reports = {r.name: r for r in sim.contacts()}
    assert reports["P1"].force_world[2] + reports["P2"].force_world[2] == pytest.approx(2.0 * 9.81 + 20.0, rel=1e-6)


# -- another hole's mouth in the face --------------------------------------------------------------
def _slots_at(offset: np.ndarray) -> list[tuple[str, str, float, np.ndarray]]:
    """The housing's pin contacts within 1 mm at the located pose moved by ``offset``: (pin, kind, gap, normal)."""
    from fixplan.engine.pin_slots import PinGeometry
    from fixplan.geometry._pin_kernels import ALL_KINDS

    fixture = fixplan.load(HOUSING)
    geometry = PinGeometry(fixture)
    pose = fixture.goal.translated(offset)
    s = geometry.slots(pose.R_world_body, pose.p_world, 1e-3)
    return [
        (geometry.names[o], ALL_KINDS[k], float(g), n)
        for (o, k, _), g, n in zip(s.keys, s.gap_m, s.normal_world, strict=True)
    ]


def test_a_pin_under_its_neighbours_mouth_is_not_held_by_the_face_and_enters_it() -> None:
    """P1 (x = −40.1 mm) under H2 (body x = +40 mm): the housing moved 80.1 mm along −x.

    Coaxial, its tip 0.1 mm into H2: no contact (the face held it there, 0.1 mm deep at 4 points,
    over the hole's mouth where there is no material). 5 mm in and 0.05 mm off H2's axis: H2's wall
    at the rim and the mouth, gap (D − d)/2 − e = 0.05 mm, normals radial; no row of P1's own hole
    (80 mm away: its side's closed forms gave walls 80 mm deep) nor of P2's, off the part.
    On H2's rim (6 mm off): the face under the tip's points over the material, H2's mouth edge on the tip.
    """
    assert _slots_at(np.array([-0.0801, 0.0, 0.012 - 1e-4])) == []
    rows = _slots_at(np.array([-0.0801 + 5e-5, 0.0, 0.012 - 0.005]))
    assert [(p, k) for p, k, _g, _n in rows] == [("P1", "rim"), ("P1", "mouth")]
    for _p, _k, gap, normal in rows:
        assert gap == pytest.approx(0.5 * (0.010 - 0.0098) - 5e-5, abs=1e-12)
        np.testing.assert_allclose(np.abs(normal), [1.0, 0.0, 0.0], atol=1e-12)
    rim = _slots_at(np.array([-0.0801 + 0.006, 0.0, 0.012 - 1e-4]))
    kinds = [k for p, k, _g, _n in rim if p == "P1"]
    assert kinds.count("face") == 3 and "tip" in kinds  # the 4th point lies over H2's mouth
    assert all(g == pytest.approx(-1e-4, abs=1e-12) for _p, k, g, _n in rim if k == "face")


def test_at_the_located_pose_the_pins_have_their_own_holes_contacts_only() -> None:
    """The other holes' rows add nothing where the pins are in their own holes (P1 touching, P2 centred in its play)."""
    rows = _slots_at(np.zeros(3))
    assert [(p, k) for p, k, _g, _n in rows] == [("P1", "rim"), ("P1", "mouth")] + [("P2", "rim"), ("P2", "mouth")] * 2
    assert min(g for _p, _k, g, _n in rows) >= -1e-15
