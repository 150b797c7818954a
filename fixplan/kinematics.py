"""Contact frames, contact Jacobians and the mass matrix of a contact configuration.

Conventions (docs/math.md):

- twist ``ν = (v, ω)`` of the centre of mass ``c`` in world axes (3D: 6 numbers; 2D:
  ``(vx, vy, ω)``);
- contact ``i`` at the workpiece's material point ``p_i`` (world), lever ``r_i = p_i − c``,
  unit normal ``n_i`` **from the locator into the workpiece**, tangents so that
  ``(n, t1, t2)`` is right-handed (2D: ``t = (−n_y, n_x)``);
- ``u_i = J_i ν`` with rows ``[nᵀ, (r×n)ᵀ]``, ``[t1ᵀ, (r×t1)ᵀ]``, ``[t2ᵀ, (r×t2)ᵀ]`` and, for a
  soft-finger contact (``torsion_m > 0``), the spin row ``[0, nᵀ]``;
- ``J_iᵀ λ_i`` is the wrench about ``c`` of the contact force ``λ_i = (λ_n, λ_t1, λ_t2[, λ_s])``.

The paper's ``G`` [11] is the stack of normal rows, ``H_x``/``H_y`` the tangent rows
(the paper's normal is ``−n``, so its ``G`` is ours negated).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fixplan.spatial import Pose, cross2, shift_wrench, skew, tangent_basis

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Contact:
    """One point contact between a fixture element and the workpiece, in world coordinates."""

    name: str
    point_world: FloatArray  # material point of the workpiece [m]
    normal_world: FloatArray  # unit, from the fixture into the workpiece
    friction: float  # Coulomb μ
    torsion_m: float = 0.0  # soft-finger torsional radius e_r [m]; 0 = no spin row
    gap_m: float = 0.0  # signed distance at this configuration [m]
    # "locator", "explicit", "pin" (a [[pin]] in the part's hole) or "bore" (the part in a [[bore]])
    kind: str = "locator"
    # the locator this contact belongs to, when it is one of several of that locator (a tip in a
    # mesh part's concave corner touches two faces: ``"E1"`` and ``"E1#2"``, both of ``"E1"``);
    # None: the contact is its locator's only one, and ``owner`` is its name
    locator: str | None = None

    @property
    def owner(self) -> str:
        """The locator (or explicit contact) this contact belongs to."""
        return self.name if self.locator is None else self.locator

    def __post_init__(self) -> None:
        n = np.array(self.normal_world, dtype=float)
        object.__setattr__(self, "normal_world", n / math.sqrt(float(n @ n)))
        object.__setattr__(self, "point_world", np.array(self.point_world, dtype=float))

    @property
    def dimension(self) -> int:
        return int(self.point_world.shape[0])

    @cached_property
    def soft(self) -> bool:
        """A soft-finger contact (3D with a torsional radius): it has a spin row."""
        return self.dimension == 3 and self.torsion_m > 0.0

    @cached_property
    def size(self) -> int:
        """Number of force components: 2 (2D), 3 (3D point), 4 (3D soft finger)."""
        return 2 if self.dimension == 2 else (4 if self.soft else 3)

    @cached_property
    def tangents_world(self) -> FloatArray:
        return tangent_basis(self.normal_world)

    def jacobian(self, com_world: ArrayLike) -> FloatArray:
        """``J_i`` (size × ndof): the contact-frame velocity of the material point from ``ν``."""
        r = self.point_world - np.asarray(com_world, dtype=float)
        n = self.normal_world
        if self.dimension == 2:
            t = self.tangents_world[0]
            return np.array([[n[0], n[1], cross2(r, n)], [t[0], t[1], cross2(r, t)]])
        frame = np.vstack([n, self.tangents_world])  # rows n, t1, t2
        J = np.zeros((self.size, 6))
        J[:3, :3] = frame
        J[:3, 3:] = frame @ skew(r).T  # row x: (r × x)ᵀ = xᵀ [r]×ᵀ
        if self.soft:
            J[3, 3:] = n
        return J


def numbered(contacts: Sequence[Contact], owner: str) -> list[Contact]:
    """The contacts of one owner (a pin, a bore) named ``owner``, ``owner#2`` ...; each carries its owner when there are several."""
    several = len(contacts) > 1
    return [
        replace(c, name=owner if k == 0 else f"{owner}#{k + 1}", locator=owner if several else None)
        for k, c in enumerate(contacts)
    ]


@dataclass(frozen=True)
class ContactSet:
    """Contacts at one configuration of the workpiece, with its mass matrix.

    All matrices are in world axes about the centre of mass ``com_world``.
    """

    contacts: tuple[Contact, ...]
    com_world: FloatArray
    mass_matrix: FloatArray  # M = diag(m I, R I_b Rᵀ)
    body_origin_world: FloatArray = field(default_factory=lambda: np.zeros(3))

    @property
    def dimension(self) -> int:
        return int(self.com_world.shape[0])

    @property
    def ndof(self) -> int:
        return 6 if self.dimension == 3 else 3

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.contacts]

    def __len__(self) -> int:
        return len(self.contacts)

    @property
    def owners(self) -> list[str]:
        """The locator (or explicit contact) of each contact: a name repeats for a locator with several contacts."""
        return [c.owner for c in self.contacts]

    @cached_property
    def several(self) -> bool:
        """Some locator has more than one contact here (a mesh part's concave corner)."""
        return any(c.locator is not None for c in self.contacts)

    def rows_of(self, owners: Sequence[str]) -> NDArray[np.int64]:
        """Indices of the contacts that belong to ``owners``, in this set's order."""
        keep = set(owners)
        return np.array([i for i, c in enumerate(self.contacts) if c.owner in keep], dtype=np.int64)

    def subset(self, owners: Sequence[str]) -> ContactSet:
        """The contacts of ``owners`` (every contact of each), same configuration and mass matrix."""
        if not self.several:
            keep = set(owners)
            chosen = tuple(c for c in self.contacts if c.name in keep)
        else:
            chosen = tuple(self.contacts[i] for i in self.rows_of(owners))
        return ContactSet(chosen, self.com_world, self.mass_matrix, self.body_origin_world)

    def touching(self, gap_m: float) -> ContactSet:
        """The contacts whose gap is at most ``gap_m``, same configuration and mass matrix."""
        chosen = tuple(c for c in self.contacts if c.gap_m <= gap_m)
        return ContactSet(chosen, self.com_world, self.mass_matrix, self.body_origin_world)

    def nearest_of(self, owner: str) -> ContactSet:
        """The set with only the nearest (first) contact of ``owner`` (itself when no locator has several).

        A transition's target is closed along its nearest contact's normal; its kept contacts keep
        every one of theirs. Built as ``contact_set(..., [*kept, target]).nearest_of(target)``, the
        target's row is the last and the kept contacts are the ones before it.
        """
        if not self.several:
            return self
        seen = False
        chosen = []
        for c in self.contacts:
            if c.owner == owner:
                if seen:
                    continue
                seen = True
            chosen.append(c)
        return ContactSet(tuple(chosen), self.com_world, self.mass_matrix, self.body_origin_world)

    def nearest_only(self) -> ContactSet:
        """The set with one contact per owner, its nearest (itself when no locator has several)."""
        if not self.several:
            return self
        kept: dict[str, Contact] = {}
        for c in self.contacts:
            kept.setdefault(c.owner, c)
        return ContactSet(tuple(kept.values()), self.com_world, self.mass_matrix, self.body_origin_world)

    def per_locator(self) -> dict[str, list[str]]:
        """Each owner's contact names, in this set's order (JSON: a locator's several contacts)."""
        out: dict[str, list[str]] = {}
        for c in self.contacts:
            out.setdefault(c.owner, []).append(c.name)
        return out

    @cached_property
    def max_lever_m(self) -> float:
        """Largest distance from the centre of mass to a contact point [m] (0 without contacts)."""
        return max((float(np.linalg.norm(c.point_world - self.com_world)) for c in self.contacts), default=0.0)

    @cached_property
    def sizes(self) -> NDArray[np.int64]:
        return np.array([c.size for c in self.contacts], dtype=np.int64)

    @cached_property
    def offsets(self) -> NDArray[np.int64]:
        return np.concatenate([[0], np.cumsum(self.sizes)[:-1]]).astype(np.int64)

    @cached_property
    def J(self) -> FloatArray:
        """Stacked contact Jacobian (Σ sizes × ndof)."""
        if not self.contacts:
            return np.zeros((0, self.ndof))
        return np.vstack([c.jacobian(self.com_world) for c in self.contacts])

    @cached_property
    def G(self) -> FloatArray:
        """Normal rows (n × ndof): ``G ν`` is the rate at which each gap opens."""
        return self.J[self.offsets] if self.contacts else np.zeros((0, self.ndof))

    @cached_property
    def H(self) -> FloatArray:
        """Tangent rows: (n × ndof) in 2D; in 3D the pair ``(H_x, H_y)`` stacked (2n × ndof)."""
        if self.dimension == 2:
            return self.J[self.offsets + 1]
        return np.vstack([self.J[self.offsets + 1], self.J[self.offsets + 2]])

    @cached_property
    def M_inv(self) -> FloatArray:
        return np.asarray(np.linalg.inv(self.mass_matrix), dtype=np.float64)

    @cached_property
    def mu(self) -> FloatArray:
        return np.array([c.friction for c in self.contacts])

    @cached_property
    def torsion(self) -> FloatArray:
        return np.array([c.torsion_m for c in self.contacts])

    def wrench_about_com(self, wrench: ArrayLike, about_world: ArrayLike | None = None) -> FloatArray:
        """Re-express a wrench given about a world point (default: body origin) about ``c``."""
        point = self.body_origin_world if about_world is None else about_world
        return shift_wrench(wrench, point, self.com_world)

    def wrench_about(self, wrench_com: ArrayLike, about_world: ArrayLike | None = None) -> FloatArray:
        """Re-express a wrench given about ``c`` about a world point (default: body origin): :meth:`wrench_about_com` undone."""
        point = self.body_origin_world if about_world is None else about_world
        return shift_wrench(wrench_com, self.com_world, point)


def mass_matrix(mass_kg: float, inertia_body: ArrayLike, R_world_body: ArrayLike) -> FloatArray:
    """``M = diag(m I, R I_b Rᵀ)`` (3D) or ``diag(m, m, I_zz)`` (2D)."""
    I_b = np.asarray(inertia_body, dtype=float)
    R = np.asarray(R_world_body, dtype=float)
    if R.shape[0] == 2:
        return np.diag([mass_kg, mass_kg, float(I_b.reshape(-1)[0])])
    M = np.zeros((6, 6))
    M[:3, :3] = mass_kg * np.eye(3)
    M[3:, 3:] = R @ I_b @ R.T
    return M


def com_world(pose: Pose, com_body: ArrayLike) -> FloatArray:
    """The centre of mass in world coordinates."""
    return pose.point_world_from_body(com_body)
