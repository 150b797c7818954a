"""Frames: SO(3) against pinocchio, wrench/twist shifts against their definitions, the numba twin pinned."""

import numpy as np
import pinocchio as pin
import pytest

from fixplan import _spatial_kernels as kernels
from fixplan.spatial import (
    Pose,
    cross2,
    exp_so3,
    log_so3,
    matrix_from_quaternion_wxyz,
    matrix_from_rpy,
    pose_between,
    quaternion_wxyz_from_matrix,
    rpy_from_matrix,
    shift_twist,
    shift_twist_by,
    shift_wrench,
    shift_wrench_by,
    tangent_basis,
)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    return exp_so3(rng.normal(size=3) * rng.uniform(0.1, 3.0))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray | float:
    return np.cross(a, b) if a.shape[0] == 3 else cross2(a, b)


def test_pose_helpers_match_pinocchio(rng):
    for _ in range(20):
        rpy = rng.uniform(-1.5, 1.5, 3)
        assert np.allclose(matrix_from_rpy(rpy), pin.rpy.rpyToMatrix(*rpy), atol=1e-14)
        w = rng.normal(size=3)
        assert np.allclose(exp_so3(w), pin.exp3(w), atol=1e-14)
        assert np.allclose(log_so3(exp_so3(w)), pin.log3(pin.exp3(w)), atol=1e-10)
        q = pin.Quaternion(matrix_from_rpy(rpy))
        ours = quaternion_wxyz_from_matrix(matrix_from_rpy(rpy))
        ref = np.array([q.w, q.x, q.y, q.z]) * np.sign(q.w)
        assert np.allclose(ours, ref, atol=1e-12)


def test_rotation_round_trips(rng):
    for _ in range(50):
        R = _random_rotation(rng)
        assert np.allclose(matrix_from_rpy(rpy_from_matrix(R)), R, atol=1e-12)
        assert np.allclose(matrix_from_quaternion_wxyz(quaternion_wxyz_from_matrix(R)), R, atol=1e-12)
        assert np.allclose(exp_so3(log_so3(R)), R, atol=1e-10)
    # near π the axis comes from the symmetric part and keeps its sign
    axis = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    w = (np.pi - 1e-8) * axis
    assert np.allclose(log_so3(exp_so3(w)), w, atol=1e-6)


@pytest.mark.parametrize("d", [2, 3])
def test_tangent_basis_is_a_right_handed_frame(d, rng):
    normals = [rng.normal(size=d) for _ in range(30)] + [np.eye(d)[0], -np.eye(d)[0]]
    for n in normals:
        n = n / np.linalg.norm(n)
        frame = np.vstack([n, tangent_basis(n)])
        assert np.allclose(frame @ frame.T, np.eye(d), atol=1e-12)
        assert np.linalg.det(frame) == pytest.approx(1.0, abs=1e-12)


def _wrench_about(points: np.ndarray, forces: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The wrench about ``p`` of ``forces[i]`` acting at ``points[i]``: (Σ f_i, Σ (x_i − p) × f_i)."""
    m = sum(_cross(xi - p, fi) for xi, fi in zip(points, forces, strict=True))
    return np.concatenate([forces.sum(axis=0), np.atleast_1d(m)])


@pytest.mark.parametrize("d", [2, 3])
def test_shift_wrench_is_the_moment_about_the_new_point(d, rng):
    """w_b from the definition: forces f_i at points x_i, moments Σ (x_i − point) × f_i."""
    for _ in range(20):
        x = rng.normal(size=(4, d))
        f = rng.normal(size=(4, d))
        a, b = rng.normal(size=d), rng.normal(size=d)

        w_a, w_b = _wrench_about(x, f, a), _wrench_about(x, f, b)
        assert np.allclose(shift_wrench(w_a, a, b), w_b, atol=1e-12)
        assert np.allclose(shift_wrench_by(w_a, b - a), w_b, atol=1e-12)


@pytest.mark.parametrize("d", [2, 3])
def test_shift_twist_is_the_velocity_of_the_new_point(d, rng):
    """t_b from the definition: the velocity of a point carried by the rigid motion, by finite differences."""
    for _ in range(20):
        if d == 3:
            pose = Pose(_random_rotation(rng), rng.normal(size=3))
        else:
            pose = Pose.from_angle_deg(rng.normal(size=2), rng.uniform(-180.0, 180.0))
        a_body, b_body = rng.normal(size=d), rng.normal(size=d)
        a, b = pose.point_world_from_body(a_body), pose.point_world_from_body(b_body)
        t_a = rng.normal(size=6 if d == 3 else 3)
        eps = 1e-7
        # retract moves the point a_body by v (the twist is "of" a_body)
        plus, minus = pose.retract(eps * t_a, a_body), pose.retract(-eps * t_a, a_body)
        v_b = (plus.point_world_from_body(b_body) - minus.point_world_from_body(b_body)) / (2 * eps)
        t_b = shift_twist(t_a, a, b)
        assert np.allclose(t_b[:d], v_b, atol=1e-7)
        assert np.allclose(t_b[d:], t_a[d:])
        assert np.allclose(shift_twist_by(t_a, b - a), t_b, atol=1e-15)


@pytest.mark.parametrize("d", [2, 3])
def test_power_is_the_same_at_every_point(d, rng):
    """w·t is invariant when both are moved consistently; and moving there and back is the identity."""
    n = 6 if d == 3 else 3
    for _ in range(50):
        w_a, t_a = rng.normal(size=n), rng.normal(size=n)
        a, b = rng.normal(size=d) * 3, rng.normal(size=d) * 3
        assert shift_wrench(w_a, a, b) @ shift_twist(t_a, a, b) == pytest.approx(w_a @ t_a, rel=1e-12, abs=1e-12)
        assert np.allclose(shift_wrench(shift_wrench(w_a, a, b), b, a), w_a, atol=1e-12)
        assert np.allclose(shift_twist(shift_twist(t_a, a, b), b, a), t_a, atol=1e-12)


# -------------------------------------------------------------------------------------------------
# the compiled twin gives the numpy answers
# -------------------------------------------------------------------------------------------------


def test_compiled_so3_matches_numpy(rng):
    R_out = np.empty((3, 3))
    q_out = np.empty(4)
    ws = [rng.normal(size=3) * s for s in (1e-10, 1e-5, 0.3, 1.0, 3.0) for _ in range(10)]
    ws.append((np.pi - 1e-9) * np.array([0.0, 0.6, 0.8]))
    for w in ws:
        kernels.exp_so3_into(w[0], w[1], w[2], R_out)
        R = exp_so3(w)
        assert np.allclose(R_out, R, rtol=0, atol=1e-14)
        assert np.allclose(kernels.log_so3(R), log_so3(R), rtol=0, atol=1e-12)
        kernels.quat_into(R, q_out)
        assert np.allclose(q_out, quaternion_wxyz_from_matrix(R), rtol=0, atol=1e-14)


def test_compiled_tangents_match_numpy(rng):
    normals = [rng.normal(size=3) for _ in range(50)] + [np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, -1.0])]
    for n in normals:
        n = n / np.linalg.norm(n)
        t = np.array(kernels.tangents3(n[0], n[1], n[2])).reshape(2, 3)
        assert np.allclose(t, tangent_basis(n), rtol=0, atol=1e-15)


def test_compiled_shifts_match_numpy(rng):
    for _ in range(50):
        w3, t3, r3 = rng.normal(size=6), rng.normal(size=6), rng.normal(size=3)
        assert np.allclose(kernels.shifted_moment3(*w3, *r3), shift_wrench_by(w3, r3)[3:], rtol=0, atol=1e-14)
        assert np.allclose(kernels.shifted_velocity3(*t3, *r3), shift_twist_by(t3, r3)[:3], rtol=0, atol=1e-14)
        w2, t2, r2 = rng.normal(size=3), rng.normal(size=3), rng.normal(size=2)
        assert kernels.shifted_moment2(*w2, *r2) == pytest.approx(shift_wrench_by(w2, r2)[2], abs=1e-14)
        assert np.allclose(kernels.shifted_velocity2(*t2, *r2), shift_twist_by(t2, r2)[:2], rtol=0, atol=1e-14)


def test_pose_between_runs_the_line_and_turns_about_one_axis() -> None:
    """From a to b: the ends are a and b; at f the origin is a + f (b − a) and the turn from a is f times a's turn to b."""
    rng = np.random.default_rng(0)
    for _ in range(20):
        a = Pose(exp_so3(rng.normal(size=3)), rng.normal(size=3))
        b = Pose(exp_so3(0.8 * rng.normal(size=3)) @ a.R_world_body, rng.normal(size=3))
        turn = log_so3(b.R_world_body @ a.R_world_body.T)
        for f in (0.0, 0.25, 0.5, 1.0):
            q = pose_between(a, b, f)
            np.testing.assert_allclose(q.p_world, a.p_world + f * (b.p_world - a.p_world), atol=1e-12)
            np.testing.assert_allclose(log_so3(q.R_world_body @ a.R_world_body.T), f * turn, atol=1e-9)
        np.testing.assert_allclose(pose_between(a, b, 1.0).R_world_body, b.R_world_body, atol=1e-12)


def test_translated_keeps_the_orientation() -> None:
    a = Pose(exp_so3([0.1, -0.2, 0.3]), [1.0, 2.0, 3.0])
    d = np.array([0.0, 0.0, 0.004])
    moved = a.translated(d)
    np.testing.assert_array_equal(moved.R_world_body, a.R_world_body)
    np.testing.assert_allclose(moved.p_world - a.p_world, d, atol=1e-15)
