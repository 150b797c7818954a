"""Frames: rigid poses, SO(3), tangent bases, and moving wrenches and twists between points.

The one home of fixplan's spatial algebra; :mod:`fixplan._spatial_kernels` is its compiled twin
(the same formulas for numba kernels, pinned to these by ``tests/test_spatial.py``).

Conventions (used everywhere in fixplan):

- ``rpy_deg = [roll, pitch, yaw]`` in files means ``R = Rz(yaw) · Ry(pitch) · Rx(roll)``
  (fixed-axis X-Y-Z, as in URDF and pinocchio's ``rpy.rpyToMatrix``).
- A 2D pose is ``(x, y, θ)`` with ``θ`` counter-clockwise.
- Twists are ``(v, ω)`` in **world axes** about the centre of mass ``c`` (docs/math.md); a pose is
  moved by a twist with the left (world-frame) retraction
  ``c⁺ = c + v,  R⁺ = exp(ω̂) R`` (3D) or ``θ⁺ = θ + ω`` (2D).
- A wrench ``w = (f, m)`` or twist ``t = (v, ω)`` is only meaningful with the point it is taken
  at; names say which: ``w_com``, ``w_origin``, ``v_com``, ``nu_com`` (world axes always).

Moving a wrench or a twist from point ``a`` to point ``b`` (world axes, lever ``r = b − a``):

- wrench: the moment about ``b`` of forces ``f_i`` at ``x_i`` is
  ``m_b = Σ (x_i − b) × f_i = Σ (x_i − a) × f_i + (a − b) × Σ f_i``, so
  ``w_b = (f, m_a + (a − b) × f) = (f, m_a + f × r)``;
- twist: a rigid velocity field is ``v(x) = v_a + ω × (x − a)``, so
  ``t_b = (v_a + ω × r, ω)``;
- in 2D the same with the scalar cross product: ``m_b = m_a + f_x r_y − f_y r_x`` and
  ``v_b = v_a + ω (−r_y, r_x)``.

The power ``w · t = f·v + m·ω`` is the same at every point:
``f·(ω × r) + (f × r)·ω = 0`` (a triple product with two equal factors, up to sign).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def rot2(theta_rad: float) -> FloatArray:
    """2×2 rotation by ``theta_rad`` counter-clockwise."""
    c, s = np.cos(theta_rad), np.sin(theta_rad)
    return np.array([[c, -s], [s, c]])


def matrix_from_rpy(rpy_rad: ArrayLike) -> FloatArray:
    """``Rz(yaw) Ry(pitch) Rx(roll)`` from ``[roll, pitch, yaw]`` in radians."""
    r, p, y = np.asarray(rpy_rad, dtype=float)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def rpy_from_matrix(R: ArrayLike) -> FloatArray:
    """Inverse of :func:`matrix_from_rpy` (pitch in [-π/2, π/2])."""
    R = np.asarray(R, dtype=float)
    pitch = np.arctan2(-R[2, 0], np.hypot(R[0, 0], R[1, 0]))
    roll = np.arctan2(R[2, 1], R[2, 2])
    yaw = np.arctan2(R[1, 0], R[0, 0])
    return np.array([roll, pitch, yaw])


def exp_so3(omega: ArrayLike) -> FloatArray:
    """Rodrigues' formula: the rotation ``exp(ω̂)``."""
    w = np.asarray(omega, dtype=float)
    theta = float(np.linalg.norm(w))
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if theta < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + np.sin(theta) / theta * K + (1.0 - np.cos(theta)) / theta**2 * K @ K


def log_so3(R: ArrayLike) -> FloatArray:
    """The rotation vector ``ω`` with ``exp(ω̂) = R``.

    Scalar arithmetic on Python floats (the haptic loop asks for it twice a tick, and NumPy's
    per-call cost on a 3 × 3 matrix was ten times the arithmetic); the branch near π uses NumPy.
    """
    R = np.asarray(R, dtype=float)
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R.tolist()
    cos_t = min(max((r00 + r11 + r22 - 1.0) / 2.0, -1.0), 1.0)
    theta = math.acos(cos_t)
    vx, vy, vz = r21 - r12, r02 - r20, r10 - r01
    if theta < 1e-8:
        return np.array([0.5 * vx, 0.5 * vy, 0.5 * vz])
    if math.pi - theta < 1e-6:
        # Near π: take the axis from the symmetric part.
        v = np.array([vx, vy, vz])
        B = (R + np.eye(3)) / 2.0
        k = int(np.argmax(np.diag(B)))
        axis = B[:, k] / np.sqrt(max(B[k, k], 1e-300))
        axis /= np.linalg.norm(axis)
        if axis @ v < 0:
            axis = -axis
        return theta * axis
    c = theta / (2.0 * math.sin(theta))
    return np.array([c * vx, c * vy, c * vz])


def quaternion_wxyz_from_matrix(R: ArrayLike) -> FloatArray:
    """Unit quaternion ``(w, x, y, z)`` with ``w ≥ 0``."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s])
    else:
        k = int(np.argmax(np.diag(R)))
        i, j, m = k, (k + 1) % 3, (k + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[m, m])
        q = np.empty(4)
        q[0] = (R[m, j] - R[j, m]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + m] = (R[m, i] + R[i, m]) / s
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def matrix_from_quaternion_wxyz(q: ArrayLike) -> FloatArray:
    """Rotation matrix of a (normalised) quaternion ``(w, x, y, z)``."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def cross2(a: ArrayLike, b: ArrayLike) -> float:
    """Scalar planar cross product ``a_x b_y − a_y b_x``."""
    u = np.asarray(a, dtype=float)
    v = np.asarray(b, dtype=float)
    return float(u[0] * v[1] - u[1] * v[0])


def skew(v: ArrayLike) -> FloatArray:
    """The matrix ``[v]×`` with ``[v]× x = v × x``."""
    w = np.asarray(v, dtype=float)
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def tangent_seed(normal: ArrayLike) -> FloatArray:
    """The axis projected onto the tangent plane of a 3D ``normal`` to give its first tangent."""
    return np.array([1.0, 0.0, 0.0]) if abs(float(np.asarray(normal)[0])) < 0.9 else np.array([0.0, 1.0, 0.0])


def tangent_basis(normal: ArrayLike) -> FloatArray:
    """Unit tangents completing ``normal`` to a right-handed frame: (1, 2) in 2D, (2, 3) in 3D.

    2D: ``t = (−n_y, n_x)``. 3D: ``t1`` is :func:`tangent_seed` projected off ``n`` and
    normalised, ``t2 = n × t1``.
    """
    n = np.asarray(normal, dtype=float)
    if n.shape[0] == 2:
        return np.array([[-n[1], n[0]]])
    a = tangent_seed(n)
    t1 = a - (a @ n) * n
    t1 /= np.linalg.norm(t1)
    t2 = skew(n) @ t1  # n × t1 (np.cross costs ~50 µs a call here: it is on the search's hot path)
    return np.stack([t1, t2])


def shift_wrench_by(wrench: ArrayLike, lever: ArrayLike) -> FloatArray:
    """A wrench ``(f, m_a)`` at point ``a`` as the wrench at ``b = a + lever``: ``(f, m_a + f × r)``.

    See the module docstring for the derivation; 2D wrenches are ``(f_x, f_y, m_z)``.
    """
    w = np.asarray(wrench, dtype=float)
    r = np.asarray(lever, dtype=float)
    if r.shape[0] == 3:
        # f × r written out (np.cross costs tens of µs a call: this is on the executor's per-tick path)
        f0, f1, f2 = float(w[0]), float(w[1]), float(w[2])
        r0, r1, r2 = float(r[0]), float(r[1]), float(r[2])
        return np.array([f0, f1, f2, w[3] + f1 * r2 - f2 * r1, w[4] + f2 * r0 - f0 * r2, w[5] + f0 * r1 - f1 * r0])
    return np.array([w[0], w[1], w[2] - w[1] * r[0] + w[0] * r[1]])


def shift_wrench(wrench: ArrayLike, from_point: ArrayLike, to_point: ArrayLike) -> FloatArray:
    """A wrench given at ``from_point`` as the same wrench at ``to_point`` (world points and axes).

    ``w_b = (f, m_a + (a − b) × f)`` with ``a = from_point``, ``b = to_point``.
    """
    return shift_wrench_by(wrench, np.asarray(to_point, dtype=float) - np.asarray(from_point, dtype=float))


def shift_twist_by(twist: ArrayLike, lever: ArrayLike) -> FloatArray:
    """A twist ``(v_a, ω)`` of point ``a`` as the twist of ``b = a + lever``: ``(v_a + ω × r, ω)``.

    The same for a twist rate (accelerations in the first-order sense the planner uses: the
    centripetal term is not added). 2D twists are ``(v_x, v_y, ω)``.
    """
    t = np.asarray(twist, dtype=float)
    r = np.asarray(lever, dtype=float)
    if r.shape[0] == 3:
        # ω × r written out (see shift_wrench_by)
        w0, w1, w2 = float(t[3]), float(t[4]), float(t[5])
        r0, r1, r2 = float(r[0]), float(r[1]), float(r[2])
        return np.array([t[0] + w1 * r2 - w2 * r1, t[1] + w2 * r0 - w0 * r2, t[2] + w0 * r1 - w1 * r0, w0, w1, w2])
    return np.array([t[0] - t[2] * r[1], t[1] + t[2] * r[0], t[2]])


def shift_twist(twist: ArrayLike, from_point: ArrayLike, to_point: ArrayLike) -> FloatArray:
    """A twist of ``from_point`` as the twist of ``to_point``: ``v_b = v_a + ω × (b − a)``."""
    return shift_twist_by(twist, np.asarray(to_point, dtype=float) - np.asarray(from_point, dtype=float))


@dataclass(frozen=True)
class Pose:
    """``T_world_body``: rotation ``R_world_body`` (d×d) and body-origin position ``p_world`` (d,)."""

    R_world_body: FloatArray
    p_world: FloatArray

    def __post_init__(self) -> None:
        object.__setattr__(self, "R_world_body", np.array(self.R_world_body, dtype=float))
        object.__setattr__(self, "p_world", np.array(self.p_world, dtype=float))
        self.R_world_body.setflags(write=False)
        self.p_world.setflags(write=False)

    @property
    def dimension(self) -> int:
        return int(self.p_world.shape[0])

    @staticmethod
    def identity(dimension: int) -> Pose:
        return Pose(np.eye(dimension), np.zeros(dimension))

    @staticmethod
    def from_rpy_deg(position: ArrayLike, rpy_deg: ArrayLike) -> Pose:
        return Pose(matrix_from_rpy(np.radians(np.asarray(rpy_deg, dtype=float))), np.asarray(position))

    @staticmethod
    def from_angle_deg(position: ArrayLike, angle_deg: float) -> Pose:
        return Pose(rot2(np.radians(angle_deg)), np.asarray(position))

    @property
    def angle_rad(self) -> float:
        """Planar angle (2D poses only)."""
        return float(np.arctan2(self.R_world_body[1, 0], self.R_world_body[0, 0]))

    def point_world_from_body(self, p_body: ArrayLike) -> FloatArray:
        return self.R_world_body @ np.asarray(p_body, dtype=float) + self.p_world

    def point_body_from_world(self, p_world: ArrayLike) -> FloatArray:
        return self.R_world_body.T @ (np.asarray(p_world, dtype=float) - self.p_world)

    def translated(self, d_world: ArrayLike) -> Pose:
        """The same orientation, the body origin moved by ``d_world``."""
        return Pose(self.R_world_body, self.p_world + np.asarray(d_world, dtype=float))

    def retract(self, twist: ArrayLike, com_body: ArrayLike) -> Pose:
        """Move by a world-axes twist ``(v, ω)`` of the centre of mass (displacement, not rate).

        The centre of mass ``c = p + R com_body`` moves by ``v``; the body turns by ``ω`` about it.
        """
        xi = np.asarray(twist, dtype=float)
        d = self.dimension
        com_body = np.asarray(com_body, dtype=float)
        c = self.point_world_from_body(com_body)
        if d == 3:
            R_new = exp_so3(xi[3:6]) @ self.R_world_body
        else:
            R_new = rot2(xi[2]) @ self.R_world_body
        c_new = c + xi[:d]
        return Pose(R_new, c_new - R_new @ com_body)

    def to_json(self) -> dict:
        """The fixture spec's JSON pose form."""
        if self.dimension == 3:
            return {
                "position": [float(x) for x in self.p_world],
                "quaternion_wxyz": [float(x) for x in quaternion_wxyz_from_matrix(self.R_world_body)],
            }
        return {"position": [float(x) for x in self.p_world], "angle_deg": float(np.degrees(self.angle_rad))}

    def distance_to(self, other: Pose) -> tuple[float, float]:
        """(translation distance [m], rotation angle [rad]) between two poses."""
        dp = float(np.linalg.norm(self.p_world - other.p_world))
        if self.dimension == 3:
            ang = float(np.linalg.norm(log_so3(self.R_world_body.T @ other.R_world_body)))
        else:
            ang = abs((other.angle_rad - self.angle_rad + np.pi) % (2 * np.pi) - np.pi)
        return dp, ang


def pose_between(a: Pose, b: Pose, f: float) -> Pose:
    """The pose a fraction ``f`` of the way from ``a`` to ``b`` (3D): the origin on the line, the turn about one axis."""
    rel = log_so3(b.R_world_body @ a.R_world_body.T)
    return Pose(exp_so3(f * rel) @ a.R_world_body, a.p_world + f * (b.p_world - a.p_world))
