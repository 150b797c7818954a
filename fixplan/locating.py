"""Locator contacts at a pose, and the located (goal) pose where every locator touches.

A locator is a sphere of radius ρ centred at ``p_world`` fixed in the world. Its gap to the
workpiece is the shape's signed distance from the tip centre minus ρ, its contact point is the
closest point on the workpiece surface, and its normal is the surface's inward normal.

The goal pose solves ``gap_i(T) = 0`` for all locators with a damped Gauss–Newton iteration
on SE(3) (SE(2) in 2D): the derivative of ``gap_i`` along the world twist ``ν`` of the centre
of mass is the contact's normal row ``G_i`` (a gap opens at the rate ``n_i·(v + ω × r_i)``), so
each step solves ``G Δ = −g`` in the least-squares sense and retracts the pose by ``Δ``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import InfeasibleError, InputError
from fixplan.kinematics import Contact, ContactSet, com_world, mass_matrix
from fixplan.model import Fixture, Locator, Workpiece, require_full
from fixplan.settings import DEFAULT
from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]


def locator_contact(workpiece: Workpiece, pose: Pose, locator: Locator) -> Contact:
    """The contact a locator would make with the workpiece at ``pose`` (with its gap)."""
    p_body = pose.point_body_from_world(locator.p_world)
    proj = workpiece.shape.project(p_body)
    point_world = pose.point_world_from_body(proj.point_body)
    normal_world = -(pose.R_world_body @ proj.normal_body)
    return Contact(
        name=locator.name,
        point_world=point_world,
        normal_world=normal_world,
        friction=locator.friction,
        torsion_m=locator.torsion_m,
        gap_m=proj.distance - locator.radius_m,
        kind="locator",
    )


def locator_gaps(workpiece: Workpiece, pose: Pose, locators: Sequence[Locator]) -> FloatArray:
    """Signed gaps [m] of the locators at ``pose`` (negative: penetration)."""
    return np.array([locator_contact(workpiece, pose, loc).gap_m for loc in locators])


def contact_set(
    fixture: Fixture,
    pose: Pose | str | None = None,
    names: Sequence[str] | None = None,
) -> ContactSet:
    """The contacts of ``fixture`` at ``pose`` (default: the start pose).

    Parameters
    ----------
    pose : Pose or "start" or "goal", optional
        Configuration of the workpiece. Explicit ``[[contact]]`` entries are given at the start
        pose and are used as they are.
    names : sequence of str, optional
        Contacts to use, by locator or contact name, in this order. A named locator that does
        not touch is used all the same (a hypothetical contact state; its gap is reported).
        Default: the locators touching at ``pose`` plus every explicit contact.
    """
    if pose is None or pose == "start":
        pose = fixture.start
    elif pose == "goal":
        pose = fixture.goal
    if not isinstance(pose, Pose):
        raise InputError(f"pose must be 'start', 'goal' or a Pose, got {pose!r}")
    wp = fixture.workpiece
    all_contacts = [locator_contact(wp, pose, loc) for loc in fixture.locators]
    all_contacts += [
        Contact(c.name, c.point_world, c.normal_world, c.friction, c.torsion_m, 0.0, "explicit")
        for c in fixture.contacts
    ]
    if names is None:
        tol = fixture.tolerances.touch_m
        chosen = [c for c in all_contacts if c.kind == "explicit" or c.gap_m <= tol]
    else:
        by_name = {c.name: c for c in all_contacts}
        unknown = [n for n in names if n not in by_name]
        if unknown:
            raise InputError(f"unknown contact {unknown[0]!r} (known: {', '.join(by_name)})")
        if len(set(names)) != len(names):
            raise InputError(f"contact names repeat: {', '.join(names)}")
        chosen = [by_name[n] for n in names]
    c = com_world(pose, wp.com_body)
    M = mass_matrix(wp.mass_kg, wp.inertia_body, pose.R_world_body)
    return ContactSet(tuple(chosen), c, M, pose.p_world.copy())


@dataclass(frozen=True)
class GoalResult:
    """The located pose and how well every locator touches there."""

    pose: Pose
    max_gap_m: float  # largest |gap| over the locators at ``pose``
    iterations: int
    rank: int  # rank of G at the goal: 6 (3D) / 3 (2D) for a deterministic location
    converged: bool


def solve_goal(
    workpiece: Workpiece,
    locators: Sequence[Locator],
    start: Pose,
    *,
    tol_m: float = 1e-12,
    max_iterations: int = 100,
) -> GoalResult:
    """Damped Gauss–Newton for the pose where every locator touches (see module docstring)."""
    pose = start
    scale = max(workpiece.shape.bounding_radius, 1e-9)

    def gaps_at(p: Pose) -> FloatArray:
        return np.array([locator_contact(workpiece, p, loc).gap_m for loc in locators])

    def residual(p: Pose) -> tuple[FloatArray, FloatArray]:
        contacts = [locator_contact(workpiece, p, loc) for loc in locators]
        gaps = np.array([c.gap_m for c in contacts])
        # the normal rows [n, r × n] of the contact Jacobians (written out: np.cross per row is slow)
        n = np.array([c.normal_world for c in contacts]).reshape(len(contacts), -1)
        r = np.array([c.point_world for c in contacts]).reshape(len(contacts), -1) - com_world(p, workpiece.com_body)
        if n.shape[1] == 2:
            moment = (r[:, 0] * n[:, 1] - r[:, 1] * n[:, 0])[:, None]
        else:
            moment = np.cross(r, n)
        return gaps, np.hstack([n, moment])

    gaps, G = residual(pose)
    it = 0
    for it in range(1, max_iterations + 1):  # noqa: B007 - used after the loop
        if np.max(np.abs(gaps)) <= tol_m:
            break
        step = -np.linalg.lstsq(G, gaps, rcond=DEFAULT.numerics.rcond)[0]
        # Limit rotations per step to keep far starts on the right faces.
        d = start.dimension
        ang = float(np.linalg.norm(step[d:]))
        lin = float(np.linalg.norm(step[:d]))
        limit = max(ang / 0.2, lin / (0.5 * scale), 1.0)
        step /= limit
        f0 = float(gaps @ gaps)
        alpha = 1.0
        while True:
            trial = pose.retract(alpha * step, workpiece.com_body)
            g_trial = gaps_at(trial)
            if float(g_trial @ g_trial) < f0 or alpha < DEFAULT.numerics.line_search_min_step:
                break
            alpha /= 2.0
        f1 = float(g_trial @ g_trial)
        if not f1 < f0:
            break  # no step decreases the gaps: a least-squares minimum, not a pose touching every locator
        pose = trial
        gaps, G = residual(pose)
        if f1 > (1.0 - DEFAULT.numerics.stall_rel) * f0 and f1 > tol_m**2:
            break  # stalled at a least-squares minimum (more locators than the pose can satisfy)
    max_gap = float(np.max(np.abs(gaps))) if len(gaps) else 0.0
    rank = int(np.linalg.matrix_rank(G, tol=DEFAULT.numerics.rank_tol)) if len(gaps) else 0
    return GoalResult(pose, max_gap, it, rank, converged=max_gap <= max(tol_m, 1e-10))


def with_goal(fixture: Fixture) -> Fixture:
    """``fixture`` with its located pose set again, for a model changed after loading.

    The given goal when there is one (``goal_given``, unchecked here), else the pose that
    :func:`solve_goal` finds from the start pose; :class:`InfeasibleError` when no pose touches
    every locator or the fixture is not full.
    """
    require_full(fixture, "the goal pose")
    if fixture.goal_given is not None:
        return replace(fixture, goal_pose=fixture.goal_given)
    result = solve_goal(fixture.workpiece, fixture.locators, fixture.start)
    if not result.converged:
        raise InfeasibleError(f"{fixture.source}: no pose touches all locators (largest gap {result.max_gap_m:.3g} m)")
    return replace(fixture, goal_pose=result.pose)


__all__ = ["GoalResult", "contact_set", "locator_contact", "locator_gaps", "require_full", "solve_goal", "with_goal"]
