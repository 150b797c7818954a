"""How close the arm's links come to the fixture and to the part, through coal on the URDF's collision geometry.

At each knot the links' collision geometry (pinocchio's ``GeometryModel`` of the URDF, placed at
``q``, then at the base) is measured against every locator tip (a sphere of its radius), every
``[[obstacle]]`` (a plane is the half-space behind it, a box a box) and the part at its knot pose
(box, cylinder, sphere, or its mesh as a BVH). Not measured: the links fixed to the robot's root
(a base mounted on the floor touches it), and against the part, the links that move with the
tool frame (the hand holds the part there). A negative distance is a penetration depth.
"""

from __future__ import annotations

from collections.abc import Sequence
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
    geom = arm.loaded.collision
    if geom is None or geom.ngeoms == 0:
        return None
    import coal
    import pinocchio as pin

    gdata = geom.createData()
    tool_joint = int(arm.model.frames[arm.tool_id].parentJoint)
    fixed = _fixture_objects(coal, fixture)
    part = _part_geometry(coal, fixture.workpiece.shape)
    request, best = coal.DistanceRequest(), None
    for j, (pose, q) in enumerate(knots):
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
    return best


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


__all__ = ["Clearance", "least_clearance"]
