"""A mesh part's locator contacts as the compiled step reads them: tangent planes, detected each step.

The compiled step (:mod:`.step`) cannot call coal, and a locator on a mesh part may touch it at
several places (a tip in a concave corner touches two faces). So before each step the simulator
asks the mesh for every contact of every locator (:meth:`fixplan.geometry.Mesh.contacts`, every
local minimum of the distance within the step's detection margin of the nearest), and hands each
one to the step as a *contact slot* of the kind the step already solves for collision-only
bodies (:func:`fixplan.engine.detect.obstacle_query3`): the part's material point ``x_b`` at the
contact (body frame, radius 0) against the fixed plane through the tip's point nearest the part,
``o = x − g n``, with normal ``n`` (from the locator into the part). At the step's start this
slot has the locator's gap ``g``, normal ``n``, contact point ``x`` and therefore its Jacobian
rows exactly; within the step the plane stands for the tip (the difference is second order in
the step's motion, and the next step detects afresh). A soft finger's spin row is not applied to
mesh parts (the slots carry none).

Slots are ordered locator by locator, nearest contact first; a slot's identity from one step to
the next (for the warm start) is ``(locator, rank)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fixplan.geometry.collision import PLANE, plane_frame
from fixplan.geometry.mesh import Mesh
from fixplan.model import Locator

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class MeshSlots:
    """Every locator's contacts at one pose, as obstacle rows and collision-point slots (module docstring)."""

    obs: FloatArray  # (n, 16): [PLANE, o_world (3), R_world_plane row-major (9), 0, 0, 0]
    slots: FloatArray  # (n, 5): [x_body (3), radius 0, row in obs]
    locator: NDArray[np.int64]  # (n,) index of each slot's locator
    rank: NDArray[np.int64]  # (n,) 0 for a locator's nearest contact, 1 for the next ...
    gap_m: FloatArray  # (n,) each contact's gap at the pose [m]

    def __len__(self) -> int:
        return int(self.locator.shape[0])

    @property
    def keys(self) -> list[tuple[int, int]]:
        return list(zip(self.locator.tolist(), self.rank.tolist(), strict=True))


def mesh_slots(
    mesh: Mesh, locators: tuple[Locator, ...], R_world_body: FloatArray, p_world: FloatArray, band_m: float
) -> MeshSlots:
    """The contacts of ``locators`` on ``mesh`` at the pose ``(R, p)``, within ``band_m`` of each one's nearest."""
    obs: list[list[float]] = []
    slots: list[list[float]] = []
    owner: list[int] = []
    rank: list[int] = []
    gaps: list[float] = []
    for i, loc in enumerate(locators):
        p_body = R_world_body.T @ (np.asarray(loc.p_world, dtype=float) - p_world)
        found = mesh.contacts(p_body, band_m=band_m)
        found = found[:1] + [c for c in found[1:] if c.distance > 0.0]  # a face seen from behind is no contact
        for k, proj in enumerate(found):
            n_world = -(R_world_body @ proj.normal_body)  # from the locator into the part
            x_world = p_world + R_world_body @ proj.point_body
            gap = float(proj.distance - loc.radius_m)
            R_plane, o_world = plane_frame(x_world - gap * n_world, n_world)
            slots.append([*proj.point_body, 0.0, float(len(obs))])
            obs.append([float(PLANE), *o_world, *R_plane.reshape(-1), 0.0, 0.0, 0.0])
            owner.append(i)
            rank.append(k)
            gaps.append(gap)
    return MeshSlots(
        np.array(obs, dtype=float).reshape(-1, 16),
        np.array(slots, dtype=float).reshape(-1, 5),
        np.array(owner, dtype=np.int64),
        np.array(rank, dtype=np.int64),
        np.array(gaps, dtype=float),
    )


__all__ = ["MeshSlots", "mesh_slots"]
