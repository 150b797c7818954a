"""The least clamp forces that hold every process load: one second-order cone program.

A clamp ``k`` pushes the part with a force ``F_k d_k`` at its tip's contact point ``p_k`` (the
point of the located part nearest the tip's centre), ``d_k`` its ``direction``. Its tip's
friction is not counted on: a clamp whose direction lies within its tip's friction cone does
not slide while it clamps (a direction outside it, or pointing out of the surface, is refused
with the reason), and the forces found hold without the tip's friction reserve (conservative:
the closed form of a box pressed by one clamp, ``μ (F + m g)``, has the base's ``μ`` only).

For the cases ``j`` (the part clamped under gravity alone, then each ``[[load]]`` in addition)
the program finds the clamp forces ``F`` (shared) and locator forces ``f_j`` (one set per case)::

    minimise   Σ_k F_k
    subject to w_g + w_j + Σ_k F_k W_k + Jᵀ S f_j = 0          (balance, per case)
               f_j in the locators' exact friction cones           (programs.force_layout)
               f_0 normal only (the clamped part, no load: seated by normal forces, see ``seat``)
               each locator's normal force ≥ preload               (per case)
               0 ≤ F_k ≤ max_force_k,  F_k = force_k for a fixed clamp

with ``W_k = (d_k, (p_k − c) × d_k)`` about the centre of mass ``c``. The cones are the jamming
programs' (:func:`fixplan.jamming.programs.force_layout`), solved by Clarabel through
:class:`~fixplan.jamming.backends.ClarabelProgram` (``min cᵀx s.t. b − A x ∈ K``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from fixplan.jamming.backends import ClarabelProgram, ConeSolution
from fixplan.jamming.programs import ConeProgram, ForceLayout, force_cone_violation, force_layout
from fixplan.kinematics import ContactSet
from fixplan.locating import contact_set, locator_contact
from fixplan.model import Clamp, Fixture, Locator
from fixplan.settings import DEFAULT, Settings
from fixplan.spatial import cross2

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ClampContact:
    """A clamp at the located pose: where its force acts and what one newton of it does."""

    clamp: Clamp
    point_world: FloatArray  # the part's point under the tip [m]
    normal_world: FloatArray  # unit, from the clamp into the part (the surface's inward normal)
    wrench_per_N: FloatArray  # (ndof,) the wrench about the centre of mass of 1 N along the direction

    @property
    def name(self) -> str:
        return self.clamp.name

    @property
    def cos_normal(self) -> float:
        """Cosine of the angle between the direction and the inward normal (≤ 0: the clamp pulls)."""
        return float(self.clamp.direction_world @ self.normal_world)


@dataclass(frozen=True)
class ClampScene:
    """The located part, its locators' contact set and its clamps: what every program here is built on."""

    fixture: Fixture
    cs: ContactSet
    layout: ForceLayout
    B: FloatArray  # (ndof × nf): the wrench about the centre of mass per reduced locator force
    clamps: tuple[ClampContact, ...]
    gravity_com: FloatArray
    owners: tuple[str, ...]  # the locators in fixture order, then the pins and bores touching at the located pose
    owner_rows: tuple[NDArray[np.int64], ...]  # per locator: the indices in f of its normal forces

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.clamps]

    def clamp(self, name: str) -> ClampContact:
        return next(c for c in self.clamps if c.name == name)

    def load_com(self, wrench: FloatArray) -> FloatArray:
        """A ``[[load]]``'s wrench (about the body origin) about the centre of mass."""
        return self.cs.wrench_about_com(wrench)

    def clamp_wrench(self, forces_N: dict[str, float]) -> FloatArray:
        """The clamps' total wrench about the centre of mass for ``forces_N`` (name → N)."""
        w = np.zeros(self.cs.ndof)
        for c in self.clamps:
            w = w + forces_N.get(c.name, 0.0) * c.wrench_per_N
        return w


def clamp_scene(fixture: Fixture) -> ClampScene:
    """The scene at the located pose (``fixture.goal``): every locator's contact and every clamp's."""
    pose = fixture.goal
    cylinders = [p.name for p in fixture.pins] + [b.name for b in fixture.bores]
    cs = contact_set(fixture, pose, [loc.name for loc in fixture.locators] + cylinders)
    if cylinders:  # a pin or bore takes part where it touches at the located pose (see the module docstring)
        tol = fixture.tolerances.touch_m
        kept = tuple(c for c in cs.contacts if c.kind not in ("pin", "bore") or c.gap_m <= tol)
        cs = ContactSet(kept, cs.com_world, cs.mass_matrix, cs.body_origin_world)
    layout = force_layout(cs)
    B = cs.J.T @ layout.S
    clamps = []
    for k in fixture.clamps:
        touch = locator_contact(fixture.workpiece, pose, Locator(k.name, k.p_world, k.radius_m, k.friction))
        r = touch.point_world - cs.com_world
        d = k.direction_world
        w = np.concatenate([d, np.cross(r, d)]) if fixture.dimension == 3 else np.array([d[0], d[1], cross2(r, d)])
        clamps.append(ClampContact(k, touch.point_world, touch.normal_world, w))
    # the locators, then the pins and bores touching at the located pose
    owners = tuple(dict.fromkeys([*(loc.name for loc in fixture.locators), *(c.owner for c in cs.contacts)]))
    rows = tuple(
        np.array([layout.normal_index[i] for i, c in enumerate(cs.contacts) if c.owner == name], dtype=np.int64)
        for name in owners
    )
    return ClampScene(fixture, cs, layout, B, tuple(clamps), fixture.gravity_wrench(), owners, rows)


def refused_direction(scene: ClampScene, settings: Settings = DEFAULT) -> str | None:
    """Why a clamp's direction cannot clamp (it pulls, or its tip would slide), or None when every one can."""
    for c in scene.clamps:
        d, n, mu = c.clamp.direction_world, c.normal_world, c.clamp.friction
        along = c.cos_normal
        angle = float(np.degrees(np.arccos(np.clip(along, -1.0, 1.0))))
        if along <= 0.0:
            return (
                f"{c.name} pulls: its direction points out of the part's surface ({angle:.3g}° from the inward "
                "normal; a clamp's tip can only push)"
            )
        tangential = float(np.linalg.norm(d - along * n))
        if tangential > mu * along + settings.clamp.direction_rel:
            return (
                f"{c.name} pushes {angle:.3g}° from the surface normal, beyond its tip's friction angle "
                f"atan({mu:g}) = {np.degrees(np.arctan(mu)):.3g}°: the tip would slide along the surface while clamping"
            )
    return None


@dataclass(frozen=True)
class Case:
    """One situation the clamped part must hold: gravity alone (``"clamped"``) or with a ``[[load]]``."""

    name: str
    wrench_com: FloatArray  # the load's wrench about the centre of mass (0 for "clamped")
    seated: bool = False  # the clamped part without load: balanced by normal forces alone (see build_force_program)


def cases_of(scene: ClampScene) -> tuple[Case, ...]:
    """``clamped`` (gravity alone), then each ``[[load]]`` in file order."""
    zero = np.zeros(scene.cs.ndof)
    return (
        Case("clamped", zero, seated=True),
        *(Case(ld.name, scene.load_com(ld.wrench)) for ld in scene.fixture.loads),
    )


@dataclass(frozen=True)
class ForceProgram:
    """The least-forces program, built (inspectable), with how to read its answer."""

    program: ConeProgram
    free: tuple[str, ...]  # the clamps whose force is a variable, in x's first entries
    fixed: dict[str, float]  # the fixed clamps' forces
    cases: tuple[Case, ...]
    nf: int  # reduced locator forces per case

    def forces_N(self, x: FloatArray) -> dict[str, float]:
        out = {name: float(max(x[i], 0.0)) for i, name in enumerate(self.free)}
        return out | dict(self.fixed)

    def locator_forces(self, x: FloatArray, j: int) -> FloatArray:
        start = len(self.free) + j * self.nf
        return np.asarray(x[start : start + self.nf], dtype=float)


def build_force_program(
    scene: ClampScene,
    cases: tuple[Case, ...],
    preload_N: float | FloatArray,
    *,
    given: dict[str, float] | None = None,
    maxmin: bool = False,
    seat: bool = True,
) -> ForceProgram:
    """The program of the module's docstring (``min Σ F``), or with ``maxmin`` the largest least locator force.

    ``preload_N``: one number, or one per case and locator (``(cases, locators)``).
    ``given`` fixes clamp forces (name → N) besides the fixed clamps'. With ``maxmin`` the last
    variable is ``t`` and each locator's normal force is ``≥ t`` instead of ``≥ preload``; the
    objective is ``max t`` (the best least locator force those clamps allow).

    ``seat``: a ``seated`` case (``clamped``, no load) is balanced by the locators' normal forces
    alone (the clamps seat the part on every locator; the classifier's ``held``). With friction
    allowed there, a rigid body's indeterminacy would let the base's friction "press" the part
    onto a side locator that no clamp pushes it towards (a wedging force nothing drives, which
    the engine does not reproduce). The loads are held with friction: a cutting force is resisted
    by it.
    """
    fixed = {c.name: float(c.clamp.force_N) for c in scene.clamps if c.clamp.force_N is not None}
    fixed |= dict(given or {})
    free = tuple(c.name for c in scene.clamps if c.name not in fixed)
    nc, nf, n = len(free), scene.layout.nf, scene.cs.ndof
    nx = nc + nf * len(cases) + (1 if maxmin else 0)
    W_free = np.array([scene.clamp(k).wrench_per_N for k in free]).reshape(nc, n).T
    w_fixed = scene.clamp_wrench(fixed)
    blocks: list[tuple[FloatArray, FloatArray, tuple[str, int]]] = []  # (A rows, b rows, cone)
    R = scene.layout.cone_rows
    for j, case in enumerate(cases):
        cols = slice(nc + j * nf, nc + (j + 1) * nf)
        A = np.zeros((n, nx))
        A[:, :nc] = W_free
        A[:, cols] = scene.B
        blocks.append((A, -(scene.gravity_com + case.wrench_com + w_fixed), ("zero", n)))
        A = np.zeros((R.shape[0], nx))
        A[:, cols] = -R
        row = 0
        for kind, dim in scene.layout.cones:
            blocks.append((A[row : row + dim], np.zeros(dim), (kind, dim)))
            row += dim
        if case.seated and seat:  # the clamped part is seated by normal forces alone: no tangential force
            tangential = np.setdiff1d(np.arange(nf), scene.layout.normal_index)
            if len(tangential):
                A = np.zeros((len(tangential), nx))
                A[np.arange(len(tangential)), nc + tangential] = 1.0
                blocks.append((A, np.zeros(len(tangential)), ("zero", len(tangential))))
        A = np.zeros((len(scene.owners), nx))
        for i, idx in enumerate(scene.owner_rows):
            A[i, nc + j * nf + idx] = -1.0
            if maxmin:
                A[i, -1] = 1.0
        need = np.broadcast_to(np.asarray(preload_N, dtype=float), (len(cases), len(scene.owners)))[j]
        blocks.append((A, np.zeros(len(scene.owners)) if maxmin else -need, ("nonneg", len(scene.owners))))
    if nc:
        A = np.zeros((2 * nc, nx))
        A[:nc, :nc] = -np.eye(nc)
        A[nc:, :nc] = np.eye(nc)
        tops = np.array([scene.clamp(k).clamp.max_force_N for k in free])
        blocks.append((A, np.concatenate([np.zeros(nc), tops]), ("nonneg", 2 * nc)))
    c = np.zeros(nx)
    if maxmin:
        c[-1] = -1.0
    else:
        c[:nc] = 1.0
    program = ConeProgram(
        c,
        np.vstack([b[0] for b in blocks]),
        np.concatenate([b[1] for b in blocks]),
        tuple(b[2] for b in blocks),
        "clamp-maxmin" if maxmin else "clamp-forces",
        nx,
    )
    return ForceProgram(program, free, fixed, cases, nf)


@dataclass(frozen=True)
class ForceAnswer:
    """The answer of a force program, checked in the mechanics' own terms."""

    found: bool
    forces_N: dict[str, float]
    min_locator_force_N: dict[str, float]  # per case: the least locator normal force in the answer
    weakest_locator: dict[str, str]  # per case: the locator with that force
    balance_residual: float  # largest |w_g + w_j + Σ F W + Jᵀλ| over the cases [N, N·m]
    cone_violation: float  # largest violation of a locator's friction cone [N]
    value: float
    status: str
    extras: dict[str, float] = field(default_factory=dict)
    # per case: each locator's (and touching pin's) normal force in the answer [N], the scene's owners
    locator_forces_N: dict[str, dict[str, float]] = field(default_factory=dict)


def solve_force_program(scene: ClampScene, fp: ForceProgram, settings: Settings = DEFAULT) -> ForceAnswer:
    """Solve with Clarabel and check the answer: balance residual and cones recomputed from the forces."""
    sol: ConeSolution = ClarabelProgram(fp.program, eps=settings.tolerances.cone_eps).solve(fp.program.b)
    x = sol.x
    forces = fp.forces_N(x)
    w_clamps = scene.clamp_wrench(forces)
    worst_res, worst_cone = 0.0, 0.0
    least: dict[str, float] = {}
    weakest: dict[str, str] = {}
    per_owner: dict[str, dict[str, float]] = {}
    for j, case in enumerate(fp.cases):
        f = fp.locator_forces(x, j)
        lam = scene.layout.S @ f
        res = scene.gravity_com + case.wrench_com + w_clamps + scene.cs.J.T @ lam
        worst_res = max(worst_res, float(np.abs(res).max()))
        worst_cone = max(worst_cone, force_cone_violation(scene.cs, lam))
        per = [(float(f[idx].sum()), name) for idx, name in zip(scene.owner_rows, scene.owners, strict=True)]
        least[case.name], weakest[case.name] = min(per)
        per_owner[case.name] = {name: force for force, name in per}
    scale = max(
        1.0,
        float(np.abs(scene.gravity_com).max()),
        max((float(np.abs(c.wrench_com).max()) for c in fp.cases), default=0.0),
        max(forces.values(), default=0.0),
    )
    tol = settings.clamp.residual_N * scale
    found = sol.solved and worst_res <= tol and worst_cone <= tol
    return ForceAnswer(
        found,
        forces,
        least,
        weakest,
        worst_res,
        worst_cone,
        sol.value,
        sol.status,
        {"solve_time_s": sol.solve_time_s},
        per_owner,
    )
