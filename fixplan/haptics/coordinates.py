"""Device coordinates: how a pose of the part reads on the haptic device, and back.

The device and the part are coupled in the same generalised coordinates: the body origin's
position and, in 3D, the rotation vector of ``R R0ᵀ`` relative to the start orientation ``R0``
(``x = (p, log(R R0ᵀ))``, 6 numbers); in 2D the origin and the planar angle (``x = (p_x, p_y, θ)``).
Their rates are the body origin's velocity and the angular velocity. This module is the one
place that says so: the rig's start, the loop's coupling, the interactive session's answer to a
device and the display's gizmo all read it from here. The 3D coordinates and rates of the
simulated part have a compiled twin (:func:`fixplan.haptics._kernels.coordinates3`, the
interactive loop's), pinned to :func:`workpiece_coordinates` by a test.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from fixplan.aot import kernel
from fixplan.spatial import Pose, exp_so3, log_so3, rot2, shift_twist

if TYPE_CHECKING:
    from fixplan.engine.simulator import Simulator

FloatArray = NDArray[np.float64]

_coordinates3 = kernel("fixplan.haptics._kernels", "coordinates3")  # imported on first call


def coordinates_from_pose(pose: Pose, R0: FloatArray) -> FloatArray:
    """Device coordinates of a workpiece pose: body origin (+ rotation vector of R R0ᵀ in 3D)."""
    if pose.dimension == 3:
        return np.concatenate([pose.p_world, log_so3(pose.R_world_body @ R0.T)])
    return np.array([pose.p_world[0], pose.p_world[1], pose.angle_rad])


def pose_from_coordinates(x: FloatArray, R0: FloatArray, dimension: int) -> Pose:
    """The pose whose device coordinates are ``x`` (inverse of :func:`coordinates_from_pose`)."""
    if dimension == 3:
        return Pose(exp_so3(x[3:6]) @ R0, np.array(x[:3], dtype=float))
    return Pose(rot2(float(x[2])), np.array(x[:2], dtype=float))


def workpiece_coordinates(sim: Simulator, R0: FloatArray, *, compiled: bool = False) -> tuple[FloatArray, FloatArray]:
    """The simulated part's device coordinates and their rates (the body origin's twist).

    ``compiled``: in 3D, the compiled twin (the interactive loop's, a few µs cheaper; equal to
    rounding); in 2D both are this NumPy code.
    """
    if compiled and sim.dimension == 3:
        pose = sim.pose
        return _coordinates3(pose.R_world_body, pose.p_world, sim.com_world, sim.twist, R0)
    pose, nu_com = sim.state
    return coordinates_from_pose(pose, R0), shift_twist(nu_com, sim.com_world, pose.p_world)


__all__ = ["coordinates_from_pose", "pose_from_coordinates", "workpiece_coordinates"]
