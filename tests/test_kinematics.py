"""Contact kinematics: Jacobians against finite differences on SE(3)/SE(2)."""

import numpy as np
import pytest

import fixplan
from fixplan.geometry import Box, Cylinder, Disk, Polygon, Rectangle, Sphere
from fixplan.kinematics import com_world
from fixplan.locating import locator_contact
from fixplan.model import Locator, Workpiece
from fixplan.spatial import Pose, log_so3


def _workpiece(shape, mass=1.3):
    return Workpiece(shape, mass, shape.inertia_body(mass), shape.com_body)


SHAPES_3D = [Box((0.2, 0.1, 0.05)), Cylinder(0.04, 0.12), Sphere(0.05)]
SHAPES_2D = [Rectangle((0.2, 0.1)), Disk(0.05), Polygon(((0.0, 0.0), (0.2, 0.0), (0.15, 0.1), (0.02, 0.08)))]


@pytest.mark.parametrize("shape", SHAPES_3D + SHAPES_2D, ids=lambda s: s.name)
def test_contact_jacobian_matches_finite_differences(shape, rng):
    """u = J ν: the contact-frame velocity of the workpiece's material point, checked by FD on the group."""
    wp = _workpiece(shape)
    d = shape.dimension
    for _ in range(5):
        pose = (
            Pose.from_rpy_deg(rng.normal(size=3) * 0.05, rng.uniform(-30, 30, 3))
            if d == 3
            else Pose.from_angle_deg(rng.normal(size=2) * 0.05, rng.uniform(-30, 30))
        )
        # a locator tip outside the part, 1 cm from its surface
        direction = rng.normal(size=d)
        direction /= np.linalg.norm(direction)
        p_world = pose.point_world_from_body(direction * (shape.bounding_radius + 0.01))
        loc = Locator("L", p_world, 0.002, 0.3, 0.003 if d == 3 else 0.0)
        contact = locator_contact(wp, pose, loc)
        c = com_world(pose, wp.com_body)
        J = contact.jacobian(c)
        nu = rng.normal(size=6 if d == 3 else 3)
        # material point of the body at the contact, followed along the retraction
        p_body = pose.point_body_from_world(contact.point_world)
        eps = 1e-7
        plus = pose.retract(eps * nu, wp.com_body)
        minus = pose.retract(-eps * nu, wp.com_body)
        v_point = (plus.point_world_from_body(p_body) - minus.point_world_from_body(p_body)) / (2 * eps)
        frame = np.vstack([contact.normal_world, contact.tangents_world])
        assert np.allclose(J[:d] @ nu, frame @ v_point, atol=1e-7)
        # the gap opens at the normal rate G ν
        g_plus = locator_contact(wp, plus, loc).gap_m
        g_minus = locator_contact(wp, minus, loc).gap_m
        assert (g_plus - g_minus) / (2 * eps) == pytest.approx(J[0] @ nu, abs=1e-6)
        if d == 3:
            # spin row: angular velocity about the normal
            assert J[3] @ nu == pytest.approx(contact.normal_world @ nu[3:], abs=1e-12)
            R_plus = plus.R_world_body @ pose.R_world_body.T
            assert np.allclose(log_so3(R_plus) / eps, nu[3:], atol=1e-6)


def test_normal_points_from_locator_into_workpiece():
    f = fixplan.load(fixplan.default_fixture_path())
    cs = fixplan.contact_set(f, "goal")
    by = {c.name: c for c in cs.contacts}
    assert np.allclose(by["B1"].normal_world, [0, 0, 1])
    assert np.allclose(by["S1"].normal_world, [0, 1, 0])
    assert np.allclose(by["E1"].normal_world, [1, 0, 0])


def test_goal_pose_touches_every_locator():
    f = fixplan.load(fixplan.default_fixture_path())
    gaps = [locator_contact(f.workpiece, f.goal, loc).gap_m for loc in f.locators]
    assert np.max(np.abs(gaps)) < 1e-12
    assert np.allclose(f.goal.p_world, [0.1, 0.05, 0.025], atol=1e-12)
    assert np.allclose(f.goal.R_world_body, np.eye(3), atol=1e-12)


def test_polygon_inertia_equals_rectangle_closed_form():
    m = 2.5
    rect = Rectangle((0.3, 0.1)).inertia_body(m)[0, 0]
    poly = Polygon(((1.0, 1.0), (1.3, 1.0), (1.3, 1.1), (1.0, 1.1)))
    assert poly.inertia_body(m)[0, 0] == pytest.approx(rect, rel=1e-12)
    assert np.allclose(poly.com_body, [1.15, 1.05])
    assert rect == pytest.approx(m * (0.3**2 + 0.1**2) / 12)


def test_inertia_closed_forms():
    assert np.allclose(
        Cylinder(0.1, 0.4).inertia_body(2.0), np.diag([2 * (3 * 0.01 + 0.16) / 12] * 2 + [0.5 * 2 * 0.01])
    )
    assert np.allclose(Sphere(0.1).inertia_body(2.0), np.eye(3) * 0.4 * 2 * 0.01)
    assert np.allclose(
        Box((0.2, 0.1, 0.05)).inertia_body(2.0),
        np.diag([2 * (0.01 + 0.0025) / 12, 2 * (0.04 + 0.0025) / 12, 2 * (0.04 + 0.01) / 12]),
    )
