"""What the arm can exert along a transition: its joint-torque box at every knot, for the wrench search.

The planner's wrench search (:func:`fixplan.jamming.search.search_wrench_in`) takes the arm's
own set of exertable pushes, ``|τ_g(q) + J(q)ᵀ w| ≤ τ_max`` (:meth:`Arm.torque_box`), at the
poses a push must be exerted from. :func:`knot_boxes` gives one box per knot of a transition's
path: the arm's joints there by inverse kinematics, the first knot from the configuration at the
fixture's start (the branch :func:`~fixplan.robot.check.first_configuration` picks, once per
process and robot), each later knot from the one before, as :func:`~fixplan.robot.check_plan`
does along the whole plan. A knot the arm does not reach has no box (None): the plan check refuses
the plan there, naming the knot.

The arm and its start configuration are kept per process, keyed by the fixture's ``[robot]``
and gravity: the fine planner asks for every transition it tries.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from fixplan.jamming.hand_set import TorqueBox
from fixplan.robot.arm import Arm

if TYPE_CHECKING:
    from fixplan.model import Fixture
    from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]

# id(fixture.robot) -> (the spec itself, its gravity, the arm, the joints at the fixture's start)
_ARMS: dict[int, tuple[object, tuple[float, ...], Arm, FloatArray | None]] = {}


def arm_at_start(fixture: Fixture) -> tuple[Arm, FloatArray | None]:
    """The fixture's arm and its joints at the part's start pose (None: not reached), kept per process."""
    spec = fixture.robot
    if spec is None:
        raise ValueError("the fixture has no [robot]")
    g = tuple(float(x) for x in fixture.gravity)
    hit = _ARMS.get(id(spec))
    if hit is not None and hit[0] is spec and hit[1] == g:
        return hit[2], hit[3]
    from fixplan.robot.check import first_configuration

    arm = Arm(spec, np.asarray(fixture.gravity, dtype=float))
    q, err = first_configuration(arm, fixture, fixture.start)
    q_start = q if err <= arm.settings.reach_tol_m else None
    if len(_ARMS) > 8:
        _ARMS.clear()
    _ARMS[id(spec)] = (spec, g, arm, q_start)
    return arm, q_start


def knot_boxes(fixture: Fixture, poses: Sequence[Pose]) -> list[TorqueBox | None]:
    """The arm's joint-torque box at every pose of ``poses`` (a transition's knots), None where it does not reach."""
    arm, q_start = arm_at_start(fixture)
    tol = arm.settings.reach_tol_m
    out: list[TorqueBox | None] = []
    q_prev = q_start
    for k, pose in enumerate(poses):
        R, p = arm.tool_target(pose)
        if q_prev is None:
            from fixplan.robot.check import first_configuration

            q, err = first_configuration(arm, fixture, pose)
        else:
            q, err = arm.ik(R, p, q_prev)
        if err > tol:
            out.append(None)
            continue
        q_prev = q
        out.append(arm.torque_box(q, f"knot {k}"))
    return out


__all__ = ["arm_at_start", "knot_boxes"]
