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
start to the staging pose when it keeps clear of every locator, else a detour through a
*waypoint* on the staging pose's back-off line, far enough out that every locator is at least as
far as at the start (the part is taken back, turned, and brought in along the back-off motion),
else the same detours lifted against gravity first.

*Clear* is a funnel: far from the staging pose every locator stays ``approach_clearance_m +
R × approach_clearance_deg`` away (``R`` the part's bounding radius; at most half the start's
least gap), the order of the start's pose error and of the tracking error; only in the last
``approach_funnel_share`` of the way (of the part's farthest point) does the clearance asked
shrink, linearly, to half the staging pose's gap. A tall slab started 1° off its nominal start
swept its edge past a locator the straight line kept 2.3 mm from and met it on the wrong face. Where no candidate holds the funnel
(a start too close to a locator), the first one clear by half the least gaps is taken. Every
pose of the path is checked with the exact gaps, and against the collision-only bodies
(``[[obstacle]]``: no collision point of the part deeper than at the start); None when no path
is clear.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from fixplan.locating import contact_set, locator_gaps
from fixplan.settings import DEFAULT, PolicySettings
from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]

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

    def least_gaps(poses: list[Pose]) -> FloatArray:
        """Each pose's least locator gap; −inf where the part goes into an obstacle."""
        gaps = np.array([float(np.min(locator_gaps(wp, p, fixture.locators))) for p in poses])
        if fixture.obstacles:
            gaps[[bool(np.any(_obstacle_gaps(fixture, p) < floor)) for p in poses]] = -np.inf
        return gaps

    # far from the staging pose every locator stays this far: the start's pose error and the
    # tracking error are of this order (a tall slab started 1° off swept its bottom edge 1 mm past
    # B2 and met it on the wrong face); never more than half the start's least gap
    far = min(
        settings.approach_clearance_m + wp.shape.bounding_radius * math.radians(settings.approach_clearance_deg),
        0.5 * float(np.min(start_gaps)),
    )

    share = settings.approach_funnel_share

    def funnel(poses: list[Pose], gaps: FloatArray) -> bool:
        """Every pose keeps ``far``, but in the last ``share`` of the way, where it shrinks linearly to ``clear``.

        The way is that of the part's farthest point (the centre of mass's travel plus the bounding
        radius times the turn); ``gaps`` are the poses' least gaps (:func:`least_gaps`).
        """
        com = [p.point_world_from_body(wp.com_body) for p in poses]
        steps = [
            float(np.linalg.norm(c1 - c0)) + wp.shape.bounding_radius * a.distance_to(b)[1]
            for a, b, c0, c1 in zip(poses[:-1], poses[1:], com[:-1], com[1:], strict=True)
        ]
        left = np.concatenate([np.cumsum(steps[::-1])[::-1], [0.0]])
        total = float(left[0]) if left[0] > 0.0 else 1.0
        return bool(np.all(gaps >= np.minimum(far, clear + (far - clear) * (left / total) / share)))

    from fixplan.planner.fine import pose_from_twist, twist_from_pose

    back = twist_from_pose(goal, staging, wp.com_body)
    need = float(np.min(start_gaps))
    ways = [
        way
        for way in (pose_from_twist(goal, scale * back, wp.com_body) for scale in settings.approach_waypoint_scales)
        if float(np.min(locator_gaps(wp, way, fixture.locators))) >= need
    ]

    def candidates() -> Iterator[tuple[list[Pose], bool]]:
        """The candidate paths, roughly shortest first.

        The straight line, detours through a waypoint on the staging pose's back-off line, and the
        same detours lifted against gravity first (the part never sweeps sideways past a locator
        at the height it started at).
        """
        yield _line(start, staging, wp.com_body, n), False
        for way in ways:
            yield _line(start, way, wp.com_body, n) + _line(way, staging, wp.com_body, n)[1:], True
        g_vec = np.asarray(fixture.gravity, dtype=float)
        if not np.any(g_vec):
            return
        up = -g_vec / float(np.linalg.norm(g_vec))
        for k in range(settings.approach_lift_steps):
            lifted = start.translated(far * 2.0**k * up)
            if float(np.min(locator_gaps(wp, lifted, fixture.locators))) < need:
                continue
            for way in ways:
                legs = _line(start, lifted, wp.com_body, n) + _line(lifted, way, wp.com_body, n)[1:]
                yield legs + _line(way, staging, wp.com_body, n)[1:], True

    # the first clear within the funnel; where none is, the first clear by half the least gaps
    # (a start close to a locator may leave no room for the funnel)
    fallback: tuple[list[Pose], bool, float] | None = None
    for poses, via in candidates():
        gaps = least_gaps(poses)
        g = float(np.min(gaps))
        if g < clear:
            continue
        if funnel(poses, gaps):
            return Approach(tuple(poses), g, _length(fixture, poses), via)
        if fallback is None:
            fallback = (poses, via, g)
    if fallback is None:
        return None
    poses, via, g = fallback
    return Approach(tuple(poses), g, _length(fixture, poses), via)


__all__ = ["Approach", "plan_approach"]
