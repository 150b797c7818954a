"""The arm holding the part wherever it goes: inverse kinematics frame by frame, for the display and the executor.

``fixplan haptic`` draws the arm at the part's pose, which the device drives through the virtual
coupling; the executor (:class:`fixplan.planner.execute.Executor`) searches every push within the
arm's joint-torque box at the pose the part is at (:meth:`ArmFollower.torque_box`). :class:`ArmFollower` keeps the joints of the last frame and solves each new one by
damped least squares from them (:meth:`Arm.ik`, warm-started: a few steps between frames), the
first from the arm's configuration at the fixture's start (the branch
:func:`~fixplan.robot.check.first_configuration` picks). It runs at the display rate, in the
display thread, or at the executor's control rate (200 Hz: about 0.2 ms a call with the box, the
search it feeds 2–3 ms), never per tick of the 1 kHz loop. A pose the arm does not reach keeps the last reached
joints and says so (``reached`` false, ``error`` how far the tool stays from its target).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from fixplan.jamming.hand_set import TorqueBox
from fixplan.robot.arm import Arm

if TYPE_CHECKING:
    from fixplan.model import Fixture
    from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]


class ArmFollower:
    """The fixture's arm following the part's pose frame by frame (see the module docstring).

    Its own :class:`Arm` (its own pinocchio data): the display thread may use it while the
    planner's arm serves another thread.
    """

    def __init__(self, fixture: Fixture) -> None:
        from fixplan.robot.exertable import arm_at_start

        if fixture.robot is None:
            raise ValueError("the fixture has no [robot]")
        shared, q_start = arm_at_start(fixture)
        self.fixture = fixture
        self.arm = Arm(fixture.robot, np.asarray(fixture.gravity, dtype=float), shared.settings)
        self.q: FloatArray | None = None if q_start is None else q_start.copy()
        self.error = 0.0 if q_start is not None else float("inf")
        self.reached = q_start is not None
        self._box: tuple[FloatArray, FloatArray, TorqueBox | None] | None = None  # (p, R, box) of the last pose

    def follow(self, pose: Pose) -> FloatArray | None:
        """The joints that put the part at ``pose`` (warm-started from the last frame's); None before any reach."""
        arm = self.arm
        if self.q is None:
            from fixplan.robot.check import first_configuration

            q, err = first_configuration(arm, self.fixture, pose)
        else:
            q, err = arm.ik(*arm.tool_target(pose), self.q)
        self.error = err
        self.reached = err <= arm.settings.reach_tol_m
        if self.reached:
            self.q = q
        return self.q

    def torque_box(self, pose: Pose, label: str = "") -> TorqueBox | None:
        """The arm's joint-torque box with the part at ``pose`` (:meth:`Arm.torque_box`); None where it does not reach.

        The joints are :meth:`follow`'s (warm-started from the last pose's); the box of the same
        pose asked again is the one already built.
        """
        last = self._box
        if last is not None and np.array_equal(last[0], pose.p_world) and np.array_equal(last[1], pose.R_world_body):
            return last[2]
        q = self.follow(pose)
        box = self.arm.torque_box(q, label) if self.reached and q is not None else None
        self._box = (pose.p_world.copy(), pose.R_world_body.copy(), box)
        return box

    def skeleton_world(self) -> FloatArray | None:
        """The stick figure at the last reached joints (:meth:`Arm.skeleton_world`), or None."""
        return None if self.q is None else self.arm.skeleton_world(self.q)


__all__ = ["ArmFollower"]
