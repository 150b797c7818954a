"""The arm holding the part wherever the device takes it: inverse kinematics frame by frame, for the display.

``fixplan haptic`` draws the arm at the part's pose, which the device drives through the virtual
coupling. :class:`ArmFollower` keeps the joints of the last frame and solves each new one by
damped least squares from them (:meth:`Arm.ik`, warm-started: a few steps between frames), the
first from the arm's configuration at the fixture's start (the branch
:func:`~fixplan.robot.check.first_configuration` picks). It runs at the display rate, in the
display thread, never in the 1 kHz loop. A pose the arm does not reach keeps the last reached
joints and says so (``reached`` false, ``error`` how far the tool stays from its target).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

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

    def skeleton_world(self) -> FloatArray | None:
        """The stick figure at the last reached joints (:meth:`Arm.skeleton_world`), or None."""
        return None if self.q is None else self.arm.skeleton_world(self.q)


__all__ = ["ArmFollower"]
