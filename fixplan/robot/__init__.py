"""The robot arm that carries the part: inverse kinematics along a plan, joint torques, limits, clearance.

A fixture's ``[robot]`` names a URDF (:mod:`fixplan.robot_file` loads it into pinocchio), the
world pose of its base and the grasp (the tool frame in the part's body frame). :class:`Arm` is
that arm at its base: forward kinematics of the tool, its Jacobian in world axes, damped
least-squares inverse kinematics within the joint limits, and the joint torques
``τ = RNEA(q, q̇, q̈) + J(q)ᵀ w`` that carry a push ``w`` (the wrench the hand exerts on the part,
at the tool frame's origin, world axes). :func:`check_plan` runs them along a plan's knots and
answers :class:`RobotReport`: can this arm, at this base, carry the plan out; which joint
saturates first; how close any link comes to the fixture or the part.
"""

from fixplan.robot.arm import Arm
from fixplan.robot.check import RobotKnot, RobotReport, check_plan

__all__ = ["Arm", "RobotKnot", "RobotReport", "check_plan"]
