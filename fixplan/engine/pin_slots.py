"""Pins in the part's holes and the part in bores, as contact slots of the compiled step: detected each step.

The pin/hole and bore contacts are closed forms of two cylinders with chamfers
(:mod:`fixplan.geometry.pins`; compiled in :mod:`fixplan.geometry._pin_kernels`): the side's
one- and two-point contact (the rim and the mouth or exit), the tip or its chamfer on the mouth,
the tip face on a blind hole's bottom, a diamond pin's lands only. The compiled step
(:mod:`.step`) solves for locator tips against the part's shape and for *collision slots*
(:func:`fixplan.engine.detect.obstacle_query3`): a material point of the part against a fixed
plane. So, as for a mesh part's locators (:mod:`.mesh_slots`), before each step every contact of
every pin and bore within the step's detection margin is handed to the step as a slot: the part's
material point at the contact (body frame, radius 0) against the fixed plane through the fixture's
point of the contact, with the contact's normal (from the fixture into the part). At the step's
start the slot has the contact's gap, normal, point and Jacobian rows exactly; within the step the
plane stands for the pin's surface (second order in the step's motion; the next step detects
afresh).

For a ``[[pin]]`` the part's point is on its hole and the fixture's on the pin; for a ``[[bore]]``
the part is the peg (its end deeper in the bore leads) and the fixture's point is on the bore.
A hole whose mouth lies in a planar face of the part (a box's face, a cylinder's end, a mesh
part's rectangular face: :func:`fixplan.geometry.pins.mouth_face`) also brings the pin's tip on that face, at
``face_points`` points of the tip's edge (:func:`fixplan.geometry.pins.tip_face_contacts`): a part
lowered beside its pin, beyond the chamfers' capture, rests on the pin's tip instead of passing
through it. A bore brings the fixture's face around its mouth likewise
(:func:`fixplan.geometry.pins.bore_face`, world frame): a shaft that misses its bore rests on it.
A slot's identity from one step to the next (the warm start) is ``(owner, kind, ordinal)``:
owners are numbered pins first, then bores, as :attr:`PinGeometry.names`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fixplan.aot import kernel
from fixplan.errors import InputError
from fixplan.geometry.collision import PLANE, plane_frame
from fixplan.geometry.pins import bore_face, mouth_face
from fixplan.geometry.shapes import Cylinder
from fixplan.model import Bore, Fixture, Hole, Workpiece
from fixplan.settings import DEFAULT, PinSettings

FloatArray = NDArray[np.float64]
_pose_contacts = kernel("fixplan.geometry._pin_kernels", "pose_contacts")
_pin_slots = kernel("fixplan.engine._pin_slot_kernels", "pin_slots")
MAX_CONTACTS = 28  # rows of the kernel's output per pin (fixplan.geometry._pin_kernels.MAX_CONTACTS)
FACE_COLUMNS = 22  # a hole's row with the face around its mouth (fixplan.geometry._pin_kernels.FACE_COLUMNS)
OTHER_HOLES = 3  # other holes' mouths in that face a row carries (fixplan.geometry._pin_kernels.OTHER_HOLES)
HOLE_COLUMNS = FACE_COLUMNS + 1 + 10 * OTHER_HOLES  # fixplan.geometry._pin_kernels.HOLE_COLUMNS


@dataclass(frozen=True)
class PinSlots:
    """Every pin's and bore's contacts within the band at one pose, as obstacle rows and collision-point slots."""

    obs: FloatArray  # (n, 16): [PLANE, o_world (3), R_world_plane row-major (9), 0, 0, 0]
    slots: FloatArray  # (n, 5): [x_body (3), radius 0, row in obs]
    owner: NDArray[np.int64]  # (n,) index of each slot's pin or bore (PinGeometry.names)
    keys: list[tuple[int, int, int]]  # (owner, kind code, ordinal among the owner's contacts of that kind)
    gap_m: FloatArray  # (n,) each contact's gap at the pose [m]
    normal_world: FloatArray  # (n, 3) from the fixture into the part
    least_gap_m: FloatArray  # (owners,) each owner's least gap over all its contacts (inf: none) [m]

    def __len__(self) -> int:
        return int(self.owner.shape[0])


class PinGeometry:
    """A fixture's pins and bores as the compiled contact kernel reads them (fixed data, built once)."""

    def __init__(self, fixture: Fixture, settings: PinSettings = DEFAULT.pins):
        wp = fixture.workpiece
        self.settings = settings
        self.names = [p.name for p in fixture.pins] + [b.name for b in fixture.bores]
        self.friction = np.array([p.friction for p in fixture.pins] + [b.friction for b in fixture.bores])
        self.n_pins = len(fixture.pins)
        pins, holes = [], []
        for pin in fixture.pins:
            land = pin.land_direction_world if pin.land_direction_world is not None else np.zeros(3)
            pins.append([*pin.p_world, *pin.axis_world, 0.5 * pin.diameter_m, pin.length_m, pin.chamfer_m, *land,
                         pin.land_width_m, 1.0 if pin.kind == "diamond" else 0.0])  # fmt: skip
            hole = wp.hole(pin.hole)
            holes.append([*hole.p_body, *hole.axis_body, 0.5 * hole.diameter_m, hole.depth_m, hole.chamfer_m,
                          0.0 if hole.through else 1.0, *_face_row(wp, hole, fixture.tolerances.touch_m, settings)])  # fmt: skip
        self._pins = np.array(pins, dtype=float).reshape(-1, 14)
        self._holes_body = np.array(holes, dtype=float).reshape(-1, HOLE_COLUMNS)
        self._bores = np.array(
            [[*b.p_world, *b.axis_world, 0.5 * b.diameter_m, b.depth_m, b.chamfer_m, 1.0, *_bore_face_row(b)]
             for b in fixture.bores],
            dtype=float,
        ).reshape(-1, FACE_COLUMNS)  # fmt: skip
        self._peg = np.zeros(2)
        if fixture.bores:
            shape = wp.shape
            if not isinstance(shape, Cylinder):  # fixture.load refuses it first; kept for models built by hand
                raise InputError(f"bore {fixture.bores[0].name}: a bore takes a cylindrical part")
            self._peg = np.array([shape.radius, shape.length])
        self._out = np.zeros((MAX_CONTACTS * len(self.names), 13))
        self._scratch: tuple[FloatArray, FloatArray, FloatArray, FloatArray] | None = None

    @property
    def kernel_inputs(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, int, int, int, float, int, float]:
        """The fixed arguments of the compiled contacts, in their order: the pins, the holes (body frame), the bores, the peg, then the settings' numbers."""
        s = self.settings
        return (self._pins, self._holes_body, self._bores, self._peg, s.rim_samples, s.newton_steps, s.golden_steps,
                s.coaxial_rel, s.face_points, s.face_arc_inset)  # fmt: skip

    def _rows(self, R: FloatArray, p: FloatArray) -> FloatArray:
        """The compiled kernel's rows at the pose ``(R, p)`` (a view of the scratch array)."""
        s = self.settings
        n = _pose_contacts(
            self._pins, self._holes_body, self._bores, self._peg, np.ascontiguousarray(R, dtype=float),
            np.ascontiguousarray(p, dtype=float), s.rim_samples, s.newton_steps, s.golden_steps, s.coaxial_rel,
            s.face_points, s.face_arc_inset, self._out,
        )  # fmt: skip
        return self._out[:n]

    def least_gaps_m(self, R: FloatArray, p: FloatArray) -> FloatArray:
        """Each pin's and bore's least gap at the pose ``(R, p)`` [m] (inf: no contact possible)."""
        rows = self._rows(R, p)
        out = np.full(len(self.names), np.inf)
        np.minimum.at(out, rows[:, 0].astype(np.int64), rows[:, 12])
        return out

    def slots(self, R: FloatArray, p: FloatArray, band_m: float) -> PinSlots:
        """The contacts at the pose ``(R, p)`` whose gap is at most ``band_m``, as slots (module text); compiled."""
        s, k = self.settings, self._out.shape[0]
        scratch = self._scratch
        if scratch is None:
            scratch = self._scratch = (np.zeros((k, 16)), np.zeros((k, 5)), np.zeros((k, 4)), np.zeros((k, 3)))
        obs, slots, meta, normals = scratch
        least = np.empty(len(self.names))
        m = _pin_slots(
            self._pins, self._holes_body, self._bores, self._peg, np.ascontiguousarray(R, dtype=float),
            np.ascontiguousarray(p, dtype=float), s.rim_samples, s.newton_steps, s.golden_steps, s.coaxial_rel,
            s.face_points, s.face_arc_inset, float(band_m), self._out, obs, slots, meta, normals, least,
        )  # fmt: skip
        keys = [(int(a), int(b), int(c)) for a, b, c in meta[:m, :3].tolist()]
        return PinSlots(obs[:m].copy(), slots[:m].copy(), meta[:m, 0].astype(np.int64), keys, meta[:m, 3].copy(),
                        normals[:m].copy(), least)  # fmt: skip

    def slots_reference(self, R: FloatArray, p: FloatArray, band_m: float) -> PinSlots:
        """:meth:`slots` in NumPy (the compiled kernel's reference, for the tests)."""
        rows = self._rows(R, p)
        owner_all = rows[:, 0].astype(np.int64)
        least = np.full(len(self.names), np.inf)
        np.minimum.at(least, owner_all, rows[:, 12])
        # the warm start's key: (owner, kind, ordinal among the owner's contacts of that kind)
        keys_all: list[tuple[int, int, int]] = []
        seen: dict[tuple[int, int], int] = {}
        for o, k in zip(owner_all.tolist(), rows[:, 2].astype(np.int64).tolist(), strict=True):
            ordinal = seen.get((o, k), 0)
            seen[(o, k)] = ordinal + 1
            keys_all.append((o, k, ordinal))
        keep = np.flatnonzero(rows[:, 12] <= band_m)
        rows = rows[keep]
        bore = rows[:, 1:2] != 0.0
        # a pin: the part's point is on its hole, pushed along the normal; a bore: the part is the
        # peg, its point is the pin's, pushed against the normal
        x_part = np.where(bore, rows[:, 3:6], rows[:, 6:9])
        o_world = np.where(bore, rows[:, 6:9], rows[:, 3:6])
        n_world = np.where(bore, -rows[:, 9:12], rows[:, 9:12])
        m = rows.shape[0]
        obs = np.zeros((m, 16))
        obs[:, 0] = float(PLANE)
        obs[:, 1:4] = o_world
        obs[:, 4:13] = np.stack([plane_frame(o, n)[0] for o, n in zip(o_world, n_world, strict=True)]).reshape(m, 9)
        slots = np.zeros((m, 5))
        slots[:, 0:3] = (x_part - p) @ R  # Rᵀ (x − p), row by row
        slots[:, 4] = np.arange(m)
        return PinSlots(obs, slots, owner_all[keep], [keys_all[j] for j in keep.tolist()], rows[:, 12].copy(),
                        n_world, least)  # fmt: skip


def _bore_face_row(bore: Bore) -> list[float]:
    """The fixture's face around ``bore``'s mouth as the kernel's 12 columns (world frame): a disk about its axis."""
    face = bore_face(bore.p_world, bore.axis_world)
    return [2.0, *face.centre, *face.normal, *face.e1, *face.half_m]


def _face_row(workpiece: Workpiece, hole: Hole, tol_m: float, settings: PinSettings) -> list[float]:
    """The face around ``hole``'s mouth and the other holes' mouths in it, as the kernel's columns past the hole's 10.

    Body frame; zeros: no face. The other holes: those whose mouth lies in the face (its plane within
    ``tol_m``, its axis the face's normal within ``settings.axis_angle_rad``, within the face's extent),
    the nearest :data:`OTHER_HOLES` of them.
    """
    face = mouth_face(workpiece.shape, hole.p_body, hole.axis_body, tol_m, settings.axis_angle_rad)
    if face is None:
        return [0.0] * (HOLE_COLUMNS - 10)
    cos_min = math.cos(settings.axis_angle_rad)
    others = sorted(
        (h for h in workpiece.holes
         if h.name != hole.name and abs(float((h.p_body - face.centre) @ face.normal)) <= tol_m
         and float(h.axis_body @ face.normal) >= cos_min and face.inside_m(h.p_body) >= 0.0),
        key=lambda h: float(np.linalg.norm(h.p_body - hole.p_body)),
    )[:OTHER_HOLES]  # fmt: skip
    row = [2.0 if face.disk else 1.0, *face.centre, *face.normal, *face.e1, *face.half_m, float(len(others))]
    for h in others:
        row += [*h.p_body, *h.axis_body, 0.5 * h.diameter_m, h.depth_m, h.chamfer_m, 0.0 if h.through else 1.0]
    return row + [0.0] * (HOLE_COLUMNS - 10 - len(row))


__all__ = ["MAX_CONTACTS", "PinGeometry", "PinSlots"]
