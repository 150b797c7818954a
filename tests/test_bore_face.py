"""A shaft at a bore's mouth: the fixture's face around it, and which surface a point inside the material is on.

Closed forms (:mod:`fixplan.geometry.pins`) for a shaft of r = 10 mm in a bore of R = 10.01 mm
(radial play 10 µm), mouth at the origin, axis +z, no chamfer (``shaft-in-bore.toml``'s bore):

- **nearest surface.** Upright, its axis ``e`` off the bore's, the shaft's side overlaps the wall by
  ``o = e − (R − r)``. With its end ``d`` past the mouth that overlap is the wall's only where the
  wall is the nearer surface (``o ≤ d``); nearer the mouth's plane, the point is under the face,
  and the mouth's edge on the end face holds it with gap ``−d``, along the axis. Before, the rim
  and mouth contacts counted ``−o`` as their gap (−20 µm for ``e`` = 30 µm, the end 0.1 µm past the
  mouth) and threw the shaft sideways into the bore: ``fixplan robust shaft-in-bore`` failed 15 of
  20 worlds on it;
- **the face around the bore's mouth** (:func:`~fixplan.geometry.pins.bore_face`: the plane of the
  mouth, normal the axis): a shaft beside the bore, its end ``h`` above the plane, touches it with
  gap ``h`` at its end's edge; resting there under gravity it carries ``m g``. Before, a shaft that
  missed its bore fell through the fixture;
- **a crescent.** Partly over the mouth (its axis 30 µm off, beyond the play), the end's edge lies
  over the face on the arc ``|φ| < Δ`` about the direction away from the bore, ``cos Δ = (R² − r² −
  e²) / (2 r e)``; the engine's points include ``±(1 − 2·face_arc_inset) Δ`` (the arc's ends, a
  tenth of it in), so the end does not tip about one point of the crescent.
"""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest

import fixplan
from fixplan.aot import kernel
from fixplan.engine.simulator import Simulator
from fixplan.geometry.pins import HoleBody, PinBody, bore_face, pin_hole_contacts, tip_face_contacts
from fixplan.settings import DEFAULT

R, r, L = 0.01001, 0.01, 0.1
UP = np.array([0.0, 0.0, 1.0])
_pose_contacts = kernel("fixplan.geometry._pin_kernels", "pose_contacts")


def _bore(chamfer: float = 0.0) -> HoleBody:
    return HoleBody(np.zeros(3), UP.copy(), R, 0.04, chamfer, True, bore_face(np.zeros(3), UP))


def _shaft(e: float, end_z: float, heading: float = 0.0) -> PinBody:
    """Upright, its axis ``e`` off the bore's toward ``heading``, its leading end's centre at height ``end_z``."""
    tip = np.array([e * math.cos(heading), e * math.sin(heading), end_z])
    return PinBody(tip + L * UP, -UP, r, L)


def _compiled(pin: PinBody, hole: HoleBody) -> np.ndarray:
    """The compiled kernel's rows for a part that is ``pin`` in ``hole`` as a [[bore]] (the body frame is the world)."""
    s = DEFAULT.pins
    bore = np.array([[*hole.mouth_world, *hole.axis_world, hole.radius_m, hole.depth_m, hole.chamfer_m, 1.0,
                      2.0, *hole.face.centre, *hole.face.normal, *hole.face.e1, *hole.face.half_m]])  # fmt: skip
    centre = pin.base_world + 0.5 * L * pin.axis_world  # the part's body frame: its centre, z along the shaft (up)
    out = np.zeros((28, 13))
    k = _pose_contacts(np.zeros((0, 14)), np.zeros((0, 22)), bore, np.array([r, L]), np.eye(3),
                       centre, s.rim_samples, s.newton_steps, s.golden_steps, s.coaxial_rel, s.face_points,
                       s.face_arc_inset, out)  # fmt: skip
    return out[:k]


# -- the nearest surface -----------------------------------------------------------------------------
@pytest.mark.parametrize("heading", [0.0, 2.0, -2.7])
def test_just_past_a_sharp_mouth_beside_the_play_the_end_is_on_the_mouths_edge(heading: float) -> None:
    """Axis 30 µm off (overlap 20 µm), end 0.1 µm past the mouth: no wall contact; the least gap is −0.1 µm, along the axis."""
    found = pin_hole_contacts(_shaft(3e-5, -1e-7, heading), _bore())
    assert not [c for c in found if c.kind in ("rim", "mouth")]
    least = min(found, key=lambda c: c.gap_m)
    assert least.kind == "tip"
    assert least.gap_m == pytest.approx(-1e-7, abs=1e-15)
    np.testing.assert_allclose(least.normal_world, -UP, atol=1e-12)  # from the shaft into the fixture: down
    rows = _compiled(_shaft(3e-5, -1e-7, heading), _bore())
    assert min(rows[:, 12]) == pytest.approx(-1e-7, abs=1e-15)
    assert not [row for row in rows if row[2] in (0.0, 1.0)]  # no rim, no mouth


@pytest.mark.parametrize("depth", [2.5e-5, 1e-3])
def test_deeper_than_its_overlap_the_side_is_the_walls(depth: float) -> None:
    """The same overlap with the end deeper than 20 µm: the wall is the nearer surface, gap (R − r) − e = −20 µm."""
    found = {c.kind: c for c in pin_hole_contacts(_shaft(3e-5, -depth), _bore())}
    assert found["rim"].gap_m == pytest.approx(-2e-5, abs=1e-12)
    assert found["mouth"].gap_m == pytest.approx(-2e-5, abs=1e-12)


def test_within_the_play_the_side_is_the_walls_at_any_depth() -> None:
    """Axis 4 µm off, end 1 nm in: both ends of the side 6 µm from the wall (R − r − e), as before."""
    found = {c.kind: c for c in pin_hole_contacts(_shaft(4e-6, -1e-9), _bore())}
    assert found["rim"].gap_m == pytest.approx(6e-6, abs=1e-12)
    assert found["mouth"].gap_m == pytest.approx(6e-6, abs=1e-12)


def test_a_chamfered_mouth_claims_a_point_nearer_its_chamfer() -> None:
    """0.5 mm chamfer, axis 0.3 mm off, the end 0.52 mm down (20 µm past the chamfer): the rim's overlap 0.29 mm is
    nearer the chamfer ((d − c + o)/√2 = 0.219 mm), so not the wall's; 1.5 mm down, it is (o = 0.29 mm)."""
    c, e = 5e-4, 3e-4
    assert not [x for x in pin_hole_contacts(_shaft(e, -(c + 2e-5)), _bore(c)) if x.kind == "rim"]
    (rim,) = [x for x in pin_hole_contacts(_shaft(e, -1.5e-3), _bore(c)) if x.kind == "rim"]
    assert rim.gap_m == pytest.approx(R - r - e, abs=1e-12)


# -- the face around the bore ------------------------------------------------------------------------
@pytest.mark.parametrize("h", [1e-3, 1e-6, 0.0])
def test_a_shaft_beside_its_bore_touches_the_face_at_its_height(h: float) -> None:
    """25 mm off (its end wholly over the face): the deepest point of the end's edge, gap h, normal −z into the fixture."""
    pin, bore = _shaft(0.025, h, 0.5), _bore()
    (c,) = tip_face_contacts(pin, bore)
    assert c.kind == "face" and c.gap_m == pytest.approx(h, abs=1e-16)
    np.testing.assert_array_equal(c.normal_world, -UP)
    assert c.point_hole_world[2] == 0.0
    assert len(tip_face_contacts(pin, bore, points=4)) == 4  # the engine's: the edge at right angles
    face = [row for row in _compiled(pin, bore) if row[2] == 5.0]
    assert len(face) == 4 and all(row[12] == pytest.approx(h, abs=1e-16) for row in face)


def test_the_face_is_unbounded_and_absent_over_the_mouth() -> None:
    assert len(tip_face_contacts(_shaft(5.0, 1e-3), _bore(), points=4)) == 4  # 5 m away: still the fixture's face
    assert tip_face_contacts(_shaft(0.0, 1e-3), _bore(), points=4) == []  # coaxial over the mouth
    assert tip_face_contacts(_shaft(5e-6, 1e-3), _bore(), points=4) == []  # within the play: over the mouth


def test_a_crescent_over_the_face_brings_its_arcs_ends() -> None:
    """Axis 30 µm off along −x, end 0.2 mm up: over the face on |φ| < Δ about −x; points at 0, ±0.8 Δ, gap 0.2 mm."""
    e, h = 3e-5, 2e-4
    pin = _shaft(e, h, math.pi)
    delta = math.acos((R * R - r * r - e * e) / (2.0 * r * e))
    found = tip_face_contacts(pin, _bore(), points=4)
    angles = sorted(math.atan2(c.point_pin_world[1], -c.point_pin_world[0] - e) for c in found)
    inset = DEFAULT.pins.face_arc_inset
    assert angles == pytest.approx([-(1 - 2 * inset) * delta, 0.0, (1 - 2 * inset) * delta], abs=1e-9)
    for c in found:
        assert c.gap_m == pytest.approx(h, abs=1e-16)
        assert math.hypot(*c.point_pin_world[:2]) > R  # over the material
    rows = _compiled(pin, _bore())
    face = rows[rows[:, 2] == 5.0]
    assert len(face) == 3 and all(row[12] == pytest.approx(h, abs=1e-16) for row in face)


# -- the engine --------------------------------------------------------------------------------------
BESIDE = textwrap.dedent(
    """
    format = 1
    [scene]
    name = "shaft-beside-bore"
    [workpiece]
    shape = "cylinder"
    radius = 0.01
    length = 0.06
    mass = 0.1
    start = { position = [-0.025, 0.0, 0.031], rpy_deg = [0.0, 0.0, 0.0] }
    [[bore]]
    name = "B1"
    position = [0.0, 0.0, 0.0]
    axis = [0.0, 0.0, 1.0]
    diameter = 0.02002
    depth = 0.03
    friction = 0.2
    """
)


def test_a_shaft_dropped_beside_its_bore_rests_on_the_fixture() -> None:
    """Dropped 1 mm beside the mouth: at rest on the face (its end at z = 0), the bore carrying m g, not through it."""
    sim = Simulator(fixplan.loads(BESIDE))
    sim.run(0.5, np.zeros(6))
    assert sim.pose.p_world[2] == pytest.approx(0.03, abs=1e-9)
    np.testing.assert_allclose(sim.pose.p_world[:2], [-0.025, 0.0], atol=1e-9)
    assert sim.max_penetration_m < 1e-9
    assert np.linalg.norm(sim.twist) < 1e-6
    (report,) = [c for c in sim.contacts() if c.name == "B1"]
    assert report.force_world[2] == pytest.approx(0.1 * 9.81, rel=1e-6)
