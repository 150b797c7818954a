"""One robot arm at its base, holding the part at its grasp: kinematics, inverse kinematics, torques.

Frames. pinocchio computes in the URDF's root frame; :class:`Arm` answers in the world frame of
the fixture: the root sits at ``base`` (``T_world_root``), gravity is the fixture's, turned into
the root's axes. The part's world pose ``X`` puts the tool frame at ``X · grasp``.

Inverse kinematics is damped least squares on the tool's pose error ``e = log(X_tool⁻¹ X_target)``
(local axes, metres and radians; pinocchio's ``Jlog6`` makes the step exact to first order),
``Δq = −Jₑᵀ (Jₑ Jₑᵀ + λ² ‖e‖ I)⁻¹ e`` (the damping fades near the target), each step halved
until the error drops and clipped to the joint limits. Torques use the
recursive Newton-Euler algorithm and the tool's Jacobian at its origin in world axes.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from fixplan.jamming.hand_set import TorqueBox
from fixplan.model import RobotSpec
from fixplan.robot_file import LoadedRobot, load_robot
from fixplan.settings import DEFAULT, RobotSettings
from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]


class Arm:
    """A URDF arm at its world base, holding the part at ``grasp`` (see the module docstring).

    Parameters
    ----------
    spec : RobotSpec
        The fixture's ``[robot]``.
    gravity_world : (3,) array
        The fixture's gravity [m/s²], world frame.
    """

    def __init__(self, spec: RobotSpec, gravity_world: FloatArray, settings: RobotSettings = DEFAULT.robot) -> None:
        import pinocchio as pin

        self._pin = pin
        self.loaded: LoadedRobot = load_robot(spec)
        self.model = pin.Model(self.loaded.model)  # a copy: this arm's gravity is set below
        self.spec = spec
        self.settings = settings
        self.R_world_root = np.asarray(spec.base.R_world_body, dtype=float)
        self.p_world_root = np.asarray(spec.base.p_world, dtype=float)
        self.model.gravity.linear = self.R_world_root.T @ np.asarray(gravity_world, dtype=float)
        self.data = self.model.createData()
        self.tool_id = self.loaded.tool_frame_id
        self.joint_names: tuple[str, ...] = tuple(self.model.names[1:])
        self.lower = np.asarray(self.model.lowerPositionLimit, dtype=float).copy()
        self.upper = np.asarray(self.model.upperPositionLimit, dtype=float).copy()
        self.effort_Nm = np.asarray(self.model.effortLimit, dtype=float).copy()
        self.velocity_limit = np.asarray(self.model.velocityLimit, dtype=float).copy()

    @property
    def nq(self) -> int:
        return int(self.model.nq)

    # -- frames ------------------------------------------------------------------------------
    def tool_target(self, part_pose: Pose) -> tuple[FloatArray, FloatArray]:
        """``(R, p)``: the tool frame's world pose when the part is at ``part_pose`` (``X · grasp``)."""
        R_p, p_p = part_pose.R_world_body, part_pose.p_world
        g = self.spec.grasp
        return R_p @ g.R_world_body, p_p + R_p @ g.p_world

    def part_pose_of(self, q: FloatArray) -> Pose:
        """The part's world pose when the arm is at ``q`` (``X_tool · grasp⁻¹``)."""
        R_t, p_t = self.tool_pose(q)
        g = self.spec.grasp
        R = R_t @ g.R_world_body.T
        return Pose(R, p_t - R @ g.p_world)

    def _root_target(self, R_world: FloatArray, p_world: FloatArray) -> Any:
        pin = self._pin
        return pin.SE3(self.R_world_root.T @ R_world, self.R_world_root.T @ (p_world - self.p_world_root))

    def tool_pose(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(R, p)``: the tool frame's world pose at ``q`` (forward kinematics)."""
        pin = self._pin
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        M = self.data.oMf[self.tool_id]
        return self.R_world_root @ M.rotation, self.p_world_root + self.R_world_root @ M.translation

    def skeleton_world(self, q: FloatArray) -> FloatArray:
        """(nq + 2, 3): the root, every joint's origin and the tool frame's origin, world frame (a stick figure)."""
        pin = self._pin
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        pts = [np.zeros(3)] + [np.asarray(M.translation, dtype=float) for M in self.data.oMi[1:]]
        pts.append(np.asarray(self.data.oMf[self.tool_id].translation, dtype=float))
        return self.p_world_root + np.array(pts) @ self.R_world_root.T

    def jacobian_world(self, q: FloatArray) -> FloatArray:
        """(6, nq): ``q̇`` ↦ the tool origin's velocity and the angular velocity, world axes."""
        pin = self._pin
        J = pin.computeFrameJacobian(
            self.model, self.data, np.asarray(q, dtype=float), self.tool_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )
        out = np.empty_like(J)
        out[:3] = self.R_world_root @ J[:3]
        out[3:] = self.R_world_root @ J[3:]
        return out

    # -- inverse kinematics ------------------------------------------------------------------
    def ik(self, R_world: FloatArray, p_world: FloatArray, q0: FloatArray) -> tuple[FloatArray, float]:
        """``(q, error)``: damped least squares from ``q0`` toward the tool pose ``(R, p)`` within the limits.

        ``error`` is ``‖log(X_tool(q)⁻¹ X_target)‖`` (metres and radians) where it stopped.
        """
        pin, s = self._pin, self.settings
        target = self._root_target(R_world, p_world)
        q = np.clip(np.asarray(q0, dtype=float).copy(), self.lower, self.upper)
        e, err = self._pose_error(q, target)
        for _ in range(s.ik_max_iter):
            if err <= s.ik_tol:
                break
            iMd = self.data.oMf[self.tool_id].actInv(target)
            J = pin.computeFrameJacobian(self.model, self.data, q, self.tool_id, pin.ReferenceFrame.LOCAL)
            J = -pin.Jlog6(iMd.inverse()) @ J
            # damping that fades with the error (Levenberg-Marquardt): robust far away, Newton near the target
            dq = -J.T @ np.linalg.solve(J @ J.T + s.ik_damping * min(err, 1.0) * np.eye(6), e)
            # the step, halved until the error drops (a full step overshoots far from the target)
            for _half in range(s.ik_halvings):
                q_new = np.clip(pin.integrate(self.model, q, dq), self.lower, self.upper)
                e_new, err_new = self._pose_error(q_new, target)
                if err_new < err:
                    break
                dq = 0.5 * dq
            else:
                self._pose_error(q, target)  # leave the data at q
                break  # no step lowers the error: a local minimum (or held at the limits)
            q, e, err = q_new, e_new, err_new
        return q, err

    def _pose_error(self, q: FloatArray, target: Any) -> tuple[FloatArray, float]:
        """``(e, ‖e‖)``, ``e = log(X_tool(q)⁻¹ X_target)`` in the tool's axes (updates the kinematics to ``q``)."""
        pin = self._pin
        pin.framesForwardKinematics(self.model, self.data, q)
        e = np.asarray(pin.log6(self.data.oMf[self.tool_id].actInv(target)).vector, dtype=float)
        return e, float(np.linalg.norm(e))

    def ik_starts(self, R_world: FloatArray, p_world: FloatArray) -> list[tuple[FloatArray, float]]:
        """``(q, error)`` from the neutral start and seeded random ones: the reaching ones first, by joint-limit margin.

        Distinct branches (elbow up or down, wrist flipped) come from distinct starts; the caller
        picks among them (:func:`fixplan.robot.check.check_plan` takes the first clear of the fixture).
        """
        pin, s = self._pin, self.settings
        rng = np.random.default_rng(s.ik_seed)
        lo = np.where(np.isfinite(self.lower), self.lower, -np.pi)
        hi = np.where(np.isfinite(self.upper), self.upper, np.pi)
        starts = [np.clip(pin.neutral(self.model), self.lower, self.upper)]
        starts += [rng.uniform(lo, hi) for _ in range(max(s.ik_starts - 1, 0))]
        found = [self.ik(R_world, p_world, q0) for q0 in starts]
        return sorted(found, key=lambda qe: (qe[1] > s.reach_tol_m, qe[1] if qe[1] > s.reach_tol_m else 0.0,
                                             -self.limit_margin(qe[0])))  # fmt: skip

    def limit_margin(self, q: FloatArray) -> float:
        """The least distance of any joint from its limits [rad or m] (negative: beyond one)."""
        return float(np.min(np.minimum(q - self.lower, self.upper - q)))

    # -- dynamics ----------------------------------------------------------------------------
    def torques(self, q: FloatArray, v: FloatArray, a: FloatArray, wrench_tool_world: FloatArray) -> FloatArray:
        """``τ = RNEA(q, q̇, q̈) + J(q)ᵀ w``: the joint torques that move the arm and push the part with ``w``.

        ``w = (f, m)`` is the wrench the hand exerts on the part at the tool frame's origin, world
        axes; the part pushes back with ``−w``, which the joints hold.
        """
        pin = self._pin
        tau = np.asarray(pin.rnea(self.model, self.data, q, v, a), dtype=float).copy()
        J = self.jacobian_world(q)
        return tau + J.T @ np.asarray(wrench_tool_world, dtype=float)

    def exertable_scale(self, q: FloatArray, lever_m: float, force_N: float, torque_Nm: float) -> tuple[float, int]:
        """``(s, joint)``: the largest ``s ≤ 1`` with every push ``‖f‖ ≤ s F``, ``‖m‖ ≤ s T`` within the effort limits.

        ``m`` is the push's moment about the part's body origin, ``lever_m`` that origin's distance
        from the tool frame's origin (there the moment is at most ``‖m‖ + lever ‖f‖``). Joint
        ``i`` carries ``|J_iᵀ w + g_i|`` ≤ ``(‖J_v,i‖ + lever ‖J_ω,i‖) ‖f‖ + ‖J_ω,i‖ ‖m‖ + |g_i|``
        (``g``: the arm's own weight), which must stay within its effort limit: the ball of pushes
        inscribed in the arm's zonotope of wrenches at ``q``. ``joint`` binds (-1: none does). ``s``
        is 0 where the arm cannot hold itself.
        """
        J = self.jacobian_world(q)
        g = np.abs(self.gravity_torques(q))
        a = np.linalg.norm(J[:3], axis=0) + lever_m * np.linalg.norm(J[3:], axis=0)
        b = np.linalg.norm(J[3:], axis=0)
        need = a * force_N + b * torque_Nm
        room = self.effort_Nm - g
        best, joint = 1.0, -1
        for i in range(self.nq):
            if room[i] <= 0.0:
                return 0.0, i
            if need[i] > 0.0 and room[i] / need[i] < best:
                best, joint = float(room[i] / need[i]), i
        return best, joint

    def torque_box(self, q: FloatArray, label: str = "") -> TorqueBox:
        """The pushes the arm can exert at ``q``: ``|τ_g(q) + J(q)ᵀ w| ≤ τ_max`` (``w`` at the tool origin, world axes).

        The box the wrench search takes as linear inequalities (:mod:`fixplan.jamming.hand_set`):
        the arm's zonotope of wrenches itself, where :meth:`exertable_scale` gives its inscribed ball.
        """
        q = np.asarray(q, dtype=float)
        J = self.jacobian_world(q)
        _, p = self.tool_pose(q)
        return TorqueBox(J.T.copy(), self.gravity_torques(q), self.effort_Nm.copy(), p, self.joint_names, label)

    def gravity_torques(self, q: FloatArray) -> FloatArray:
        """The joint torques that hold the arm still against gravity."""
        return np.asarray(self._pin.computeGeneralizedGravity(self.model, self.data, q), dtype=float).copy()

    def potential_energy(self, q: FloatArray) -> float:
        """The arm's potential energy in the fixture's gravity [J] (for finite-difference checks)."""
        return float(self._pin.computePotentialEnergy(self.model, self.data, q))


__all__ = ["Arm"]
