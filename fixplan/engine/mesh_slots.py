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
the step's motion, and the next step detects afresh). A soft finger (a locator with a torsion
arm) gives each of its slots a spin row about the slot's normal, as it gives a primitive part's
contact one.

Slots are ordered locator by locator, nearest contact first; a slot's identity from one step to
the next (for the warm start) is ``(locator, rank)``.

A mesh part with ``[[workpiece.hole]]``s on ``[[pin]]``s: the holes stay analytic (a hole is a
cylinder in the body frame, whether or not the mesh models its bore). Each step also hands over
every pin's contacts with its hole in closed form, as for a primitive part (:mod:`.pin_slots`),
after the locators' slots, the pin's tip on the face around its hole's mouth included (the
mesh's coplanar triangles there, as a rectangle found once, in :class:`.pin_slots.PinGeometry`:
:func:`fixplan.geometry.pins.mouth_face`); the pins are never tested against the mesh's triangles
(and the locators never against the holes), so a mesh without a modelled bore is as good as one with.

:func:`mesh_slots` is the reference, in Python (with
:meth:`fixplan.engine.simulator.Simulator._step_mesh_reference`). The engine steps a mesh part
through :class:`MeshStepper`: the arrays are set up here once per simulator, and each step is one
compiled call (:func:`fixplan.engine._mesh_slot_kernels.mesh_step3`: detection, the pins' closed
forms, slots, the fixture's collision points near their obstacles, warm starts, the step and its
write-back), with no Python object made per step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fixplan.aot import kernel
from fixplan.engine.pin_slots import HOLE_COLUMNS, MAX_CONTACTS, PinGeometry
from fixplan.errors import InputError
from fixplan.geometry.collision import PLANE, plane_frame
from fixplan.geometry.mesh import Mesh
from fixplan.model import Locator
from fixplan.settings import DEFAULT

FloatArray = NDArray[np.float64]
_KERNELS = "fixplan.engine._mesh_slot_kernels"
_mesh_step3 = kernel(_KERNELS, "mesh_step3")
_STATE_COLUMNS = 18  # fixplan.engine._mesh_slot_kernels.STATE
_PIN_STATE_COLUMNS = _STATE_COLUMNS + 3  # fixplan.engine._mesh_slot_kernels.PIN_STATE: then (pin, kind, ordinal)


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


class MeshStepper:
    """A simulator's mesh part as the compiled step reads it: arrays set up once, one call a step.

    Holds the part's query arrays, the locators as ``[p_world (3), radius, μ, torsion arm]`` rows,
    the pins and their holes as the compiled closed forms read them (``pins``; none: empty arrays),
    the fixture's collision points with their μ and an AABB tree of them, and the state carried
    from step to step (:mod:`fixplan.engine._mesh_slot_kernels` says what each array holds).
    """

    def __init__(
        self,
        mesh: Mesh,
        locators: tuple[Locator, ...],
        obs: FloatArray,
        slots: FloatArray,
        slot_mu: FloatArray,
        pins: PinGeometry | None = None,
    ) -> None:
        self.mesh = mesh
        self.loc = np.ascontiguousarray(
            [[*loc.p_world, loc.radius_m, loc.friction, loc.torsion_m] for loc in locators], dtype=float
        ).reshape(-1, 6)
        self.obs = np.ascontiguousarray(obs, dtype=float).reshape(-1, 16)
        self.points = np.ascontiguousarray(np.column_stack([slots, slot_mu]), dtype=float).reshape(-1, 6)
        m = self.points.shape[0]
        boxes, nodes, order = np.zeros((max(2 * m, 1), 6)), np.zeros((max(2 * m, 1), 4), dtype=np.int64), np.arange(m)
        if m:  # the points as degenerate triangles: the mesh's own tree builder
            build = kernel("fixplan.geometry._mesh_kernels", "build_tree")
            tri = np.ascontiguousarray(np.tile(self.points[:, :3], (1, 3)))
            count = int(build(tri, mesh.settings.tree_leaf_triangles, boxes, nodes, order))
            boxes, nodes = boxes[:count].copy(), nodes[:count].copy()
        rho_max = float(self.points[:, 3].max(initial=0.0))
        self.tree = (boxes, nodes, np.ascontiguousarray(order, dtype=np.int64), rho_max)
        k = self.loc.shape[0]
        self.state = np.zeros((4 * k + 8, _STATE_COLUMNS))
        self.loc_slots = np.zeros((k, 2), dtype=np.int64)
        self.near = np.zeros(2 * m + 1, dtype=np.int64)
        # each locator's remembered triangles (contacts_near): the last full query's point, count and reach; the ids
        self.radius = float(mesh.settings.query_cache_radius_m)
        self.cache_q = np.zeros((k, 5))
        self.cache_ids = np.zeros((k, mesh.settings.query_cache_triangles), dtype=np.int64)
        # the pins' closed forms (PinGeometry.kernel_inputs less the bores: a mesh part has none), their μ, and
        # the state of their slots (without pins: empty)
        s = DEFAULT.pins
        self.pin_inputs: tuple[Any, ...] = (np.zeros((0, 14)), np.zeros((0, HOLE_COLUMNS)), np.zeros(0), s.rim_samples,
                                            s.newton_steps, s.golden_steps, s.coaxial_rel, s.face_points,
                                            s.face_arc_inset)  # fmt: skip
        owners = 0
        if pins is not None:
            arrays, numbers = pins.kernel_inputs[:4], pins.kernel_inputs[4:]
            if arrays[2].shape[0]:  # pragma: no cover - the loader refuses a bore for a part that is no cylinder
                raise InputError(f"bore {pins.names[pins.n_pins]}: a bore takes a cylindrical part, not a mesh")
            self.pin_inputs = (arrays[0], arrays[1], np.ascontiguousarray(pins.friction, dtype=float), *numbers)
            owners = len(pins.names)
        self.pin_state = np.zeros((MAX_CONTACTS * owners, _PIN_STATE_COLUMNS))
        self.pin_count = np.zeros(1, dtype=np.int64)
        # the arguments that never change, in the kernel's order
        self._part = (*mesh.query_arrays, mesh.same_point_m, self.loc, self.obs, self.points, *self.tree,
                      *self.pin_inputs)  # fmt: skip
        self.reset()

    def reset(self) -> None:
        """A new state: no warm start for the next step, every collision point's row reset by it."""
        self.loc_slots[:] = 0
        self.pin_count[0] = 0
        self.near[0] = -1
        self.cache_q[:, 3] = -1.0  # geometry only, but a reset starts from full queries
        # the compiled step, its arrays' checks done at the next step and then by identity (the
        # simulator's and this stepper's arrays are updated in place; a new state brings new arrays)
        self._step3: Any = None

    def step(
        self, sim: Any, f_ext: FloatArray, tau_ext: FloatArray, margin: float
    ) -> tuple[float, int, int, int, float]:
        """One step of ``sim`` (a :class:`~fixplan.engine.simulator.Simulator`): its arrays updated in place.

        Returns ``(error, iterations, status, failed local solves, penetration)``.
        """
        while True:
            args = (
                sim._R, sim._p, sim._v, sim._w, sim._mass, sim._Ib, sim._Ib_inv, sim._com_b, *self._part, sim.dt,
                f_ext, tau_ext, sim.restitution, margin, sim.tolerance, sim.max_iterations, sim.polish_after, sim.polish_steps,
                sim._bound, sim._P, sim._active, sim._P_prev, sim._active_prev, sim._gap, sim._u, sim._nw,
                self.state, self.loc_slots, self.near, self.radius, self.cache_q, self.cache_ids, self.pin_state,
                self.pin_count,
            )  # fmt: skip
            if self._step3 is None:  # f_ext and tau_ext are new arrays each step: not fixed
                fixing = getattr(_mesh_step3, "fixing", None)
                part = range(8, 8 + len(self._part))  # the part's arguments, numbers included, never change
                fixed = {
                    i: a
                    for i, a in enumerate(args)
                    if (isinstance(a, np.ndarray) and a is not f_ext and a is not tau_ext) or i in part
                }
                self._step3 = _mesh_step3 if fixing is None else fixing(fixed)
            out = self._step3(*args)
            err, iters, status, failures, pen, n = out
            if n >= 0:
                return float(err), int(iters), int(status), int(failures), float(pen)
            self.state = np.zeros((2 * self.state.shape[0] - int(n), _STATE_COLUMNS))  # room for every slot
            self._step3 = None  # a new array: checked and fixed anew

    def slots_of(self, i: int) -> FloatArray:
        """Locator ``i``'s slots in the last step: rows of ``[P (4), P_prev (4), u (4), n_world (3), gap, active, active_prev]``."""
        start, count = (int(x) for x in self.loc_slots[i])
        return self.state[start : start + count]

    def pin_slots_of(self, i: int) -> FloatArray:
        """Pin ``i``'s slots in the last step: rows of :meth:`slots_of`'s columns, then ``(pin, kind, ordinal)``."""
        rows = self.pin_state[: int(self.pin_count[0])]
        return rows[rows[:, _STATE_COLUMNS] == float(i)]


__all__ = ["MeshSlots", "MeshStepper", "mesh_slots"]
