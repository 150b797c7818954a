"""Motion witnesses: a consistent acceleration with each contact sliding, sticking or opening.

Unknowns: the acceleration ``a`` (twist rate of the centre of mass, world axes) and the
contact forces. Each contact has a role:

- *sliding*: kept (``G_i a = 0``) with friction at its limit opposing the slip (docs/math.md [13],
  [14], [19], [20]): ``λ_i = f_n,i (1, −μ_i D d_i)``, ``d_i = s_i/‖s_i‖``, ``s_i = D T_i a``
  (``T_i`` its tangent [and spin] rows; ``D = diag(1, 1, e_r)`` for a soft finger, else 1);
- *sticking*: no relative acceleration (``J_i a = 0``), force ``λ_i`` free, checked to lie in
  its cone afterwards;
- *open*: no force; its normal acceleration must come out strictly positive.

With the roles fixed the system ``M a − w_e − Σ J_iᵀ λ_i = 0`` plus the role equations is
square; Newton's method with its analytic Jacobian solves it (compiled kernels in
:mod:`._witness_kernels`); in 2D every role pattern is a linear system and is solved exactly.

- every contact sliding → Theorem 1's witness (``slides``);
- all kept, some sticking → the body pivots (``pivots``), or rolls when all stick;
- some open → an opening motion consistent with every contact law (``separates``).

A root is accepted only if every normal force is ≥ 0, every sticking force lies in its cone,
every sliding contact really slips, every open contact really opens, and the dynamics residual
is below tolerance. One exception: a "sliding" contact that neither slips nor carries force is
*idle* (zero force obeys Coulomb's law for any slip direction) and is accepted as it is. Such a
contact sits on the motion's fixed axis — an end stop on the axis of a cylinder spinning in a
V-block. Calling it sticking instead gives a singular system (its stick rows repeat the other
contacts' normal rows) whose Newton root carries round-off tangential forces at zero normal
force, just outside its cone, so no witness would be found at all.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fixplan.aot import kernel
from fixplan.jamming._roles import ROLE_OPENING, ROLE_SLIDING, ROLE_STICKING
from fixplan.kinematics import ContactSet
from fixplan.settings import DEFAULT, WitnessSettings

FloatArray = NDArray[np.float64]
_KERNELS = "fixplan.jamming._witness_kernels"
_system = kernel(_KERNELS, "system")
_newton = kernel(_KERNELS, "newton")
_fixed_point = kernel(_KERNELS, "fixed_point")
Roles = tuple[tuple[int, ...], tuple[int, ...]]  # (sticking indices, open indices)


@dataclass(frozen=True)
class MotionWitness:
    """A consistent motion: acceleration, full contact forces, roles and quality."""

    acceleration: FloatArray
    forces: FloatArray  # stacked λ_i (contact frames)
    sticking: tuple[int, ...]  # indices of sticking contacts
    opened: tuple[int, ...]  # indices of opening contacts
    residual: float  # ‖M a − w_e − Jᵀλ‖_{M⁻¹} / ‖w_e‖_{M⁻¹}
    min_slip: float  # least slip speed over sliding frictional contacts, relative
    idle: tuple[int, ...] = ()  # "sliding" contacts that neither slip nor carry force


class Rows:
    """Per-contact data in the compiled kernels' layout, precomputed once per contact set."""

    def __init__(self, cs: ContactSet):
        self.cs = cs
        k = len(cs)
        self.M = np.ascontiguousarray(cs.mass_matrix)
        self.Jall = np.ascontiguousarray(cs.J)
        self.off = np.ascontiguousarray(cs.offsets, dtype=np.int64)
        self.size = np.ascontiguousarray(cs.sizes, dtype=np.int64)
        self.mu_arr = np.array([c.friction for c in cs.contacts], dtype=float)
        self.Dm = np.ones((k, 3))
        for i, c in enumerate(cs.contacts):
            if c.soft:
                self.Dm[i, 2] = c.torsion_m
        self.lever = cs.max_lever_m

    def code(self, roles: Roles) -> NDArray[np.int64]:
        """Role codes for the kernels (:mod:`._roles`): sliding unless sticking or opening."""
        m = np.full(len(self.cs), ROLE_SLIDING, dtype=np.int64)
        m[list(roles[0])] = ROLE_STICKING
        m[list(roles[1])] = ROLE_OPENING
        return m

    def system(self, w_e: FloatArray, z: FloatArray, roles: Roles) -> tuple[FloatArray, FloatArray, FloatArray]:
        return _system(self.M, self.Jall, self.off, self.size, self.mu_arr, self.Dm, w_e, z, self.code(roles))

    def newton(self, w_e: FloatArray, z0: FloatArray, roles: Roles, iterations: int = 30) -> FloatArray:
        return _newton(
            self.M, self.Jall, self.off, self.size, self.mu_arr, self.Dm, w_e, z0, self.code(roles), iterations
        )

    def fixed_point(self, w_e: FloatArray, z0: FloatArray, sweeps: int = 4) -> FloatArray:
        """All-slide start: freeze slip directions at the current a, solve the linear system, repeat."""
        return _fixed_point(self.M, self.Jall, self.off, self.size, self.mu_arr, self.Dm, w_e, z0, sweeps)


def _accept(
    rows: Rows,
    w_e: FloatArray,
    z: FloatArray,
    roles: Roles,
    C: FloatArray,
    slip_rel: float,
    res_tol: float,
    witness: WitnessSettings,
) -> MotionWitness | None:
    cs = rows.cs
    n = cs.ndof
    if not np.all(np.isfinite(z)):
        return None
    stick, opened = roles
    a = z[:n]
    _, _, lam = rows.system(w_e, z, roles)
    scale = max(float(np.linalg.norm(C @ w_e)), 1e-300)
    dyn = float(np.linalg.norm(C @ (cs.mass_matrix @ a - w_e - cs.J.T @ lam))) / scale
    acc_ref = float(np.linalg.norm(a[: cs.dimension])) + float(np.linalg.norm(a[cs.dimension :])) * max(
        rows.lever, 1e-12
    )
    if acc_ref <= 0.0 or dyn > res_tol:
        return None
    # force scale: the largest contact force, floored by the push itself so that forces that
    # vanish (a free spin among frictionless contacts) are judged against it, not against round-off
    d = cs.dimension
    push_scale = float(np.linalg.norm(w_e[:d])) + float(np.linalg.norm(w_e[d:])) / max(rows.lever, 1e-12)
    f_scale = max(float(np.abs(lam).max()) if lam.size else 0.0, push_scale, 1e-300)
    slips = []
    idle: list[int] = []
    for i, (c, off) in enumerate(zip(cs.contacts, cs.offsets, strict=True)):
        un = float(cs.J[off] @ a)
        if i in opened:
            if un <= witness.normal_rel * acc_ref:
                return None
            continue
        if abs(un) > witness.normal_rel * acc_ref:
            return None
        li = lam[off : off + c.size]
        if li[0] < -witness.force_rel * f_scale:
            return None
        if i in stick:
            tang = li[1:].copy()
            if c.soft:
                tang[-1] /= c.torsion_m
            if float(np.linalg.norm(tang)) > c.friction * li[0] + witness.force_rel * f_scale:
                return None
        elif c.friction > 0.0:
            s = rows.Dm[i, : c.size - 1] * (cs.J[off + 1 : off + c.size] @ a)
            slip = float(np.linalg.norm(s)) / acc_ref
            if slip <= slip_rel and li[0] <= witness.force_rel * f_scale:
                # idle: kept, no slip and no force (a point on the motion's axis, e.g. an end stop
                # on a spinning cylinder's axis). Zero force satisfies Coulomb's law whatever the
                # slip direction, so it does not stop the others from sliding.
                idle.append(i)
                continue
            slips.append(slip)
    min_slip = min(slips) if slips else float("inf")
    if slips and min_slip <= slip_rel:
        return None
    return MotionWitness(a.copy(), lam, tuple(stick), tuple(opened), dyn, min_slip, tuple(idle))


def frictionless_start(cs: ContactSet, w_e: FloatArray) -> FloatArray:
    """``(a, f_n)`` of the frictionless all-kept problem (a Newton start)."""
    n, k = cs.ndof, len(cs)
    K = np.zeros((n + k, n + k))
    K[:n, :n] = cs.mass_matrix
    K[:n, n:] = -cs.G.T
    K[n:, :n] = cs.G
    rhs = np.concatenate([w_e, np.zeros(k)])
    return np.linalg.lstsq(K, rhs, rcond=None)[0]


def _start_for(cs: ContactSet, base: FloatArray, roles: Roles, seed_force: float) -> FloatArray:
    """A Newton start for ``roles`` from ``base`` ``(a, f_n)``: every kept contact's normal force at least ``seed_force``."""
    n = cs.ndof
    stick, opened = roles
    parts = [base[:n]]
    for i, c in enumerate(cs.contacts):
        if i in opened:
            continue
        fn = abs(base[n + i]) + seed_force
        parts.append(np.concatenate([[fn], np.zeros(c.size - 1)]) if i in stick else np.array([fn]))
    return np.concatenate(parts)


def kept_patterns(k: int, allow_stick: bool = True) -> list[Roles]:
    """All sliding, then one sticking, then two sticking (k > 2)."""
    out: list[Roles] = [((), ())]
    if allow_stick:
        out += [((i,), ()) for i in range(k)]
        if k > 2:
            out += [(pair, ()) for pair in itertools.combinations(range(k), 2)]
    return out


def opening_patterns(k: int) -> list[Roles]:
    """Proper subsets opened (smallest first); the kept rest all sliding, or one of them sticking."""
    out: list[Roles] = []
    for size in range(1, k):
        for opened in itertools.combinations(range(k), size):
            rest = [i for i in range(k) if i not in opened]
            out.append(((), opened))
            out += [((i,), opened) for i in rest]
    return out


class WitnessSearch:
    """Searches role patterns for a consistent motion; one per contact set, reused per wrench."""

    def __init__(
        self,
        cs: ContactSet,
        C: FloatArray,
        null_G: FloatArray,
        *,
        slip_rel: float = DEFAULT.tolerances.slip_rel,
        res_tol: float | None = None,
        rng_seed: int = 0,
        settings: WitnessSettings = DEFAULT.witness,
    ):
        """The search over ``cs``; ``settings`` says when a root counts as a witness.

        ``res_tol`` (the largest dynamics residual accepted) defaults to
        ``DEFAULT.tolerances.balance_rel × settings.residual_fraction``.
        """
        if res_tol is None:
            res_tol = DEFAULT.tolerances.balance_rel * settings.residual_fraction
        self.settings = settings
        self.cs = cs
        self.C = C
        self.rows = Rows(cs)
        self.N = null_G
        self.slip_rel = slip_rel
        self.res_tol = res_tol
        # the random starts are drawn afresh for every wrench from the same seed: one generator
        # shared across a batch made a wrench's verdict depend on how many came before it (the demo
        # map said indeterminate where classifying that push alone said slides)
        self.rng_seed = rng_seed

    def kept(self, w_e: FloatArray, allow_stick: bool = True) -> MotionWitness | None:
        """An all-sliding witness, else a pivoting (or rolling) one, else None."""
        k = len(self.cs)
        if k == 0:
            return None
        if self.cs.dimension == 2 and k <= 6:
            return self._enumerate_2d(w_e, kept=True, allow_stick=allow_stick)
        return self._search(w_e, kept_patterns(k, allow_stick), with_random=self.N.shape[1] > 0)

    def opening(self, w_e: FloatArray) -> MotionWitness | None:
        """A motion in which some contacts open and the others slide or stick, else None."""
        k = len(self.cs)
        if k < 1:
            return None
        if self.cs.dimension == 2 and k <= 5:
            return self._enumerate_2d(w_e, kept=False, allow_stick=True)
        return self._search(w_e, opening_patterns(k), with_random=False)

    def _search(self, w_e: FloatArray, patterns: list[Roles], with_random: bool) -> MotionWitness | None:
        cs, rows = self.cs, self.rows
        n = cs.ndof
        base = frictionless_start(cs, w_e)
        starts = [rows.fixed_point(w_e, base), base]
        if with_random:
            rng = np.random.default_rng(self.rng_seed)
            for _ in range(2):
                a = self.N @ rng.standard_normal(self.N.shape[1])
                a *= max(float(np.linalg.norm(base[:n])), 1e-3) / max(float(np.linalg.norm(a)), 1e-300)
                starts.append(np.concatenate([a, np.abs(base[n:]) + self.settings.seed_force_open]))
        w_norm = max(float(np.linalg.norm(w_e)), 1e-300)
        for roles in patterns:
            for z0 in starts if roles == ((), ()) else starts[:2]:
                z = rows.newton(w_e, _start_for(cs, z0, roles, self.settings.seed_force), roles)
                F, _, _ = rows.system(w_e, z, roles)
                if not float(np.linalg.norm(F)) <= self.settings.root_rel * w_norm:  # not a root (or NaN)
                    continue
                witness = _accept(rows, w_e, z, roles, self.C, self.slip_rel, self.res_tol, self.settings)
                if witness is not None:
                    return witness
        return None

    def _enumerate_2d(self, w_e: FloatArray, *, kept: bool, allow_stick: bool) -> MotionWitness | None:
        """2D: each role pattern (slide +, slide −, stick, open) is a linear system."""
        cs, rows = self.cs, self.rows
        n, k = cs.ndof, len(cs)
        J = cs.J
        solve_rel = self.settings.solve_rel
        choices: tuple[str, ...] = ("+", "-", "s") if allow_stick else ("+", "-")
        if not kept:
            choices = (*choices, "o")
        patterns = sorted(itertools.product(choices, repeat=k), key=lambda p: (p.count("o"), p.count("s")))
        for pat in patterns:
            if not kept and "o" not in pat:
                continue
            if "o" in pat and pat.count("o") == k:
                continue
            stick = tuple(i for i, r in enumerate(pat) if r == "s")
            opened = tuple(i for i, r in enumerate(pat) if r == "o")
            rows_eq: list[FloatArray] = []
            cols: list[FloatArray] = []
            for i, r in enumerate(pat):
                off = cs.offsets[i]
                if r == "o":
                    continue
                if r == "s":
                    for q in range(2):
                        cols.append(-J[off + q])
                        rows_eq.append(J[off + q])
                else:
                    sign = 1.0 if r == "+" else -1.0
                    cols.append(-(J[off] - rows.mu_arr[i] * sign * J[off + 1]))
                    rows_eq.append(J[off])
            m = len(cols)
            K = np.zeros((n + m, n + m))
            K[:n, :n] = cs.mass_matrix
            if m:
                K[:n, n:] = np.array(cols).T
                K[n:, :n] = np.array(rows_eq)
            rhs = np.concatenate([w_e, np.zeros(m)])
            try:
                z = np.linalg.solve(K, rhs)
            except np.linalg.LinAlgError:
                z = None
            if (
                z is None
                or not np.all(np.isfinite(z))
                or float(np.linalg.norm(K @ z - rhs)) > solve_rel * max(float(np.linalg.norm(rhs)), 1e-300)
            ):
                # singular (rank-deficient G, e.g. concurrent normals): the least-norm solution is
                # one of many consistent motions; _accept checks its residual like any other
                z = np.linalg.lstsq(K, rhs, rcond=None)[0]
            a = z[:n]
            if not all(
                r not in "+-"
                or rows.mu_arr[i] <= 0.0
                or (1.0 if r == "+" else -1.0) * float(J[cs.offsets[i] + 1] @ a) > 0
                for i, r in enumerate(pat)
            ):
                continue
            witness = _accept(rows, w_e, z, (stick, opened), self.C, self.slip_rel, self.res_tol, self.settings)
            if witness is not None:
                return witness
        return None
