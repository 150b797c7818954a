"""The approach from free space: carry the part to a staging pose before the first contact.

A part that starts in free space — centimetres away, tilted about every axis — would otherwise
make its first contact wherever its tilt brings it: which locator touches first then depends on
millimetres and fractions of a degree, and the contact states that follow are far from the
goal's. A robot (or a person) first carries the part to an *approach pose* and only then goes in.

The staging pose is the free state's pre-image near the goal (:func:`~fixplan.planner.policy.
representative_pose` of the empty state): the located pose backed off along the motion that opens
every locator by the same small gap, with the goal's orientation. From there the first contacts
are the near-nominal ones the coarse plan and the policy are built for.

The path there is free motion (no contact to keep): the straight line in ``(c, R)`` from the
start to the staging pose when every locator stays clear along it, else a detour through a
*waypoint* on the staging pose's back-off line, far enough out that every locator is at least as
far as at the start (the part is taken back, turned, and brought in along the back-off motion).
Every pose of the path is checked with the exact gaps, and against the collision-only bodies
(``[[obstacle]]``: no collision point of the part deeper than at the start); None when neither
path is clear.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fixplan.locating import contact_set, locator_gaps
from fixplan.settings import DEFAULT, PolicySettings
from fixplan.spatial import Pose

if TYPE_CHECKING:
    from fixplan.model import Fixture


@dataclass(frozen=True)
class Approach:
    """A free path from the start to the staging pose, every pose clear of every locator."""

    poses: tuple[Pose, ...]  # the first the start, the last the staging pose
    least_gap_m: float  # the smallest exact locator gap along the path [m]
    length_m: float  # mass-weighted length [m]
    via_waypoint: bool

    @property
    def staging(self) -> Pose:
        return self.poses[-1]


def _line(start: Pose, end: Pose, com_body: np.ndarray, n: int) -> list[Pose]:
    from fixplan.planner.fine import pose_from_twist, twist_from_pose

    xi = twist_from_pose(start, end, com_body)
    return [pose_from_twist(start, s * xi, com_body) for s in np.linspace(0.0, 1.0, n + 1)]


def _length(fixture: Fixture, poses: list[Pose]) -> float:
    from fixplan.planner.execute import mass_speed
    from fixplan.planner.fine import twist_from_pose

    wp = fixture.workpiece
    cs = contact_set(fixture, poses[0], [])
    return float(
        sum(
            mass_speed(twist_from_pose(a, b, wp.com_body), cs.mass_matrix, wp.mass_kg)
            for a, b in zip(poses[:-1], poses[1:], strict=True)
        )
    )


def _obstacle_gaps(fixture: Fixture, pose: Pose) -> np.ndarray:
    """The part's least gap to each collision-only body at ``pose`` [m] (:mod:`fixplan.geometry.collision`)."""
    from fixplan.geometry.collision import BOX, PLANE, collision_points, obstacle_gap

    pts, radii = collision_points(fixture.workpiece.shape, DEFAULT.engine.rim_points)
    X = pts @ pose.R_world_body.T + pose.p_world
    return np.array(
        [
            min(
                obstacle_gap(PLANE if ob.is_plane else BOX, ob.R_world_obstacle, ob.o_world, ob.half_m, x, r)[0]
                for x, r in zip(X, radii, strict=True)
            )
            for ob in fixture.obstacles
        ]
    )


def plan_approach(fixture: Fixture, settings: PolicySettings = DEFAULT.policy) -> Approach | None:
    """The free path from ``fixture.start`` to the staging pose (see the module docstring)."""
    from fixplan.planner.policy import representative_pose

    wp = fixture.workpiece
    start = fixture.start
    goal = fixture.goal
    staging = representative_pose(fixture, goal, frozenset(), settings)
    if staging is None:
        return None
    start_gaps = locator_gaps(wp, start, fixture.locators)
    if np.min(start_gaps) <= fixture.tolerances.touch_m:
        return None  # not a free start
    # every pose of the path keeps every locator at least this far (half the smaller of the start's
    # and the staging pose's least gaps)
    stage_gap = float(np.min(locator_gaps(wp, staging, fixture.locators)))
    clear = 0.5 * min(float(np.min(start_gaps)), stage_gap)
    n = settings.approach_samples

    floor = np.minimum(_obstacle_gaps(fixture, start), 0.0) - fixture.tolerances.penetration_m

    def least(poses: list[Pose]) -> float:
        """The least locator gap along ``poses``; −inf where one goes into an obstacle."""
        if fixture.obstacles and any(np.any(_obstacle_gaps(fixture, p) < floor) for p in poses):
            return -np.inf
        return float(min(np.min(locator_gaps(wp, p, fixture.locators)) for p in poses))

    direct = _line(start, staging, wp.com_body, n)
    g = least(direct)
    if g >= clear:
        return Approach(tuple(direct), g, _length(fixture, direct), False)
    # a detour through a waypoint on the staging pose's back-off line
    from fixplan.planner.fine import pose_from_twist, twist_from_pose

    back = twist_from_pose(goal, staging, wp.com_body)
    need = float(np.min(start_gaps))
    for scale in settings.approach_waypoint_scales:
        way = pose_from_twist(goal, scale * back, wp.com_body)
        if float(np.min(locator_gaps(wp, way, fixture.locators))) < need:
            continue
        legs = _line(start, way, wp.com_body, n) + _line(way, staging, wp.com_body, n)[1:]
        g = least(legs)
        if g >= clear:
            return Approach(tuple(legs), g, _length(fixture, legs), True)
    return None


__all__ = ["Approach", "plan_approach"]
