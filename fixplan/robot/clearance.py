"""How close the arm's links come to the fixture and to the part, through coal on the URDF's collision geometry.

At each knot the links' collision geometry (pinocchio's ``GeometryModel`` of the URDF, placed at
``q``, then at the base) is measured against every locator tip (a sphere of its radius), every
``[[obstacle]]`` (a plane is the half-space behind it, a box a box) and the part at its knot pose
(box, cylinder, sphere, or its mesh as a BVH). Not measured: the links fixed to the robot's root
(a base mounted on the floor touches it), and against the part, the links that move with the
tool frame (the hand holds the part there). A negative distance is a penetration depth.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fixplan.geometry import Box, Cylinder, Sphere
from fixplan.geometry.mesh import Mesh
from fixplan.model import Fixture
from fixplan.robot.arm import Arm
from fixplan.settings import DEFAULT
from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Clearance:
    """The least distance found: between ``link`` and ``other`` at knot ``knot`` [m] (negative: overlap)."""

    distance_m: float
    knot: int
    link: str
    other: str


def _part_geometry(coal: Any, shape: Any) -> Any | None:
    if isinstance(shape, Box):
        return coal.Box(*[float(x) for x in shape.size])
    if isinstance(shape, Cylinder):
        return coal.Cylinder(float(shape.radius), float(shape.length))
    if isinstance(shape, Sphere):
        return coal.Sphere(float(shape.radius))
    if isinstance(shape, Mesh):
        bvh = coal.BVHModelOBBRSS()
        bvh.beginModel(len(shape.faces), len(shape.vertices))
        bvh.addVertices(np.asarray(shape.vertices, dtype=float))
        bvh.addTriangles(np.asarray(shape.faces, dtype=np.int64))
        bvh.endModel()
        return bvh
    return None


def _fixture_objects(coal: Any, fixture: Fixture) -> list[tuple[str, Any, Any]]:
    """``(name, geometry, world transform)`` of the locator tips and the obstacles."""
    out = []
    tiny = DEFAULT.robot.point_radius_m
    for loc in fixture.locators:
        tf = coal.Transform3s(np.eye(3), np.asarray(loc.p_world, dtype=float))
        out.append((f"locator {loc.name}", coal.Sphere(max(float(loc.radius_m), tiny)), tf))
    for ob in fixture.obstacles:
        if ob.is_plane:
            n = np.asarray(ob.R_world_obstacle[:, -1], dtype=float)
            out.append(
                (
                    f"obstacle {ob.name}",
                    coal.Halfspace(n, float(n @ ob.o_world)),
                    coal.Transform3s(np.eye(3), np.zeros(3)),
                )
            )
        else:
            tf = coal.Transform3s(np.asarray(ob.R_world_obstacle, dtype=float), np.asarray(ob.o_world, dtype=float))
            out.append((f"obstacle {ob.name}", coal.Box(*[2.0 * float(x) for x in ob.half_m]), tf))
    return out


def least_clearance(arm: Arm, fixture: Fixture, knots: Sequence[tuple[Pose, FloatArray]]) -> Clearance | None:
    """The least link distance over ``knots`` (part pose, joints), or None without collision geometry."""
    best = None
    for c in per_knot(arm, fixture, knots):
        if best is None or c.distance_m < best.distance_m:
            best = c
    return best


def per_knot(arm: Arm, fixture: Fixture, knots: Sequence[tuple[Pose, FloatArray]]) -> Iterator[Clearance]:
    """The least link distance at each of ``knots`` in turn (nothing without collision geometry)."""
    geom = arm.loaded.collision
    if geom is None or geom.ngeoms == 0:
        return
    import coal
    import pinocchio as pin

    gdata = geom.createData()
    tool_joint = int(arm.model.frames[arm.tool_id].parentJoint)
    fixed = _fixture_objects(coal, fixture)
    part = _part_geometry(coal, fixture.workpiece.shape)
    request = coal.DistanceRequest()
    for j, (pose, q) in enumerate(knots):
        best: Clearance | None = None
        pin.updateGeometryPlacements(arm.model, arm.data, geom, gdata, np.asarray(q, dtype=float))
        part_tf = coal.Transform3s(np.asarray(pose.R_world_body, dtype=float), np.asarray(pose.p_world, dtype=float))
        for g, obj in enumerate(geom.geometryObjects):
            if obj.parentJoint == 0:
                continue  # fixed to the robot's root
            M = gdata.oMg[g]
            tf = coal.Transform3s(arm.R_world_root @ M.rotation, arm.p_world_root + arm.R_world_root @ M.translation)
            others = list(fixed)
            if part is not None and not _moves_with(arm, obj.parentJoint, tool_joint):
                others.append(("the part", part, part_tf))
            for name, other, other_tf in others:
                result = coal.DistanceResult()
                d = float(coal.distance(obj.geometry, tf, other, other_tf, request, result))
                if best is None or d < best.distance_m:
                    best = Clearance(d, j, f"link {obj.name}", name)
        if best is not None:
            yield best


def _moves_with(arm: Arm, joint: int, tool_joint: int) -> bool:
    """Whether ``joint`` is the tool frame's joint or one after it (a finger, the flange)."""
    j = tool_joint
    parents = arm.model.parents
    k = joint
    while k > 0:
        if k == j:
            return True
        k = parents[k]
    return False


@dataclass(frozen=True)
class TrajectoryClearance:
    """The links' clearance along a trajectory of the part (:func:`along_trajectory`).

    ``least`` is the least distance over the samples measured (its ``knot`` the sample's index),
    ``least_time_s`` when; ``first_hit`` and ``first_hit_time_s`` the first sample where a link
    penetrates (None: none does). ``samples`` were measured, ``unreached`` of them the arm does
    not reach (left out), every ``every_s`` seconds.
    """

    least: Clearance | None
    least_time_s: float | None
    first_hit: Clearance | None
    first_hit_time_s: float | None
    samples: int
    unreached: int
    every_s: float

    def to_json(self) -> dict[str, Any]:
        def one(c: Clearance | None, t: float | None) -> dict[str, Any] | None:
            if c is None:
                return None
            return {"distance_m": c.distance_m, "time_s": t, "link": c.link, "other": c.other}

        return {
            "min_clearance_m": None if self.least is None else self.least.distance_m,
            "least": one(self.least, self.least_time_s),
            "first_hit": one(self.first_hit, self.first_hit_time_s),
            "samples": self.samples,
            "unreached": self.unreached,
            "every_s": self.every_s,
        }


def along_trajectory(
    fixture: Fixture, samples: Sequence[tuple[float, Pose]], every_s: float
) -> TrajectoryClearance | None:
    """The links' clearance at the part's poses ``(time [s], pose)``, one every ``every_s`` at most.

    The joints follow the part by inverse kinematics, each sample from the one before (the first
    from the arm's configuration at the fixture's start, :func:`fixplan.robot.exertable.arm_at_start`).
    None without collision geometry.
    """
    from fixplan.robot.exertable import arm_at_start

    arm, q_start = arm_at_start(fixture)
    if arm.loaded.collision is None or arm.loaded.collision.ngeoms == 0:
        return None
    picked: list[tuple[float, Pose]] = []
    for k, (t, pose) in enumerate(samples):
        gap = float(t) - picked[-1][0] if picked else math.inf
        if gap >= every_s or math.isclose(gap, every_s) or k == len(samples) - 1:
            picked.append((float(t), pose))
    knots: list[tuple[Pose, FloatArray]] = []
    times: list[float] = []
    q_prev, unreached = q_start, 0
    for t, pose in picked:
        R, p = arm.tool_target(pose)
        if q_prev is None:
            from fixplan.robot.check import first_configuration

            q, err = first_configuration(arm, fixture, pose)
        else:
            q, err = arm.ik(R, p, q_prev)
        if err > arm.settings.reach_tol_m:
            unreached += 1
            continue
        q_prev = q
        knots.append((pose, q))
        times.append(t)
    least, first = None, None
    for c in per_knot(arm, fixture, knots):
        if least is None or c.distance_m < least.distance_m:
            least = c
        if first is None and c.distance_m < 0.0:
            first = c
    return TrajectoryClearance(
        least, None if least is None else times[least.knot], first, None if first is None else times[first.knot],
        len(knots), unreached, every_s,
    )  # fmt: skip


__all__ = ["Clearance", "TrajectoryClearance", "along_trajectory", "least_clearance", "per_knot"]
