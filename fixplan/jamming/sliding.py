"""Motion witnesses: every contact kept, each either sliding or sticking.

Unknowns: the acceleration ``a`` (twist rate of the centre of mass, world axes) and the
contact forces. A *sliding* contact is kept (``G_i a = 0``) with friction at its limit opposing
the slip (MATH.md [13], [14], [19], [20]): ``λ_i = f_n,i (1, −μ_i D d_i)``, ``d_i = s_i/‖s_i‖``,
``s_i = D T_i a`` (``T_i`` its tangent [and spin] rows, ``D = diag(1, 1, e_r)`` for a soft
finger, the identity otherwise). A *sticking* contact has no relative acceleration
(``J_i a = 0``) and a free force ``λ_i``, checked afterwards to lie in its cone. With roles
fixed the system

    M a − w_e − Σ_i J_iᵀ λ_i = 0,    G_i a = 0 (sliding),    J_i a = 0 (sticking)

is square; it is solved by Newton's method with its analytic Jacobian (2D: the slip signs are
enumerated and each role pattern is a linear system, solved exactly).

- all contacts sliding → Theorem 1's witness (``slides``);
- some sticking, the others sliding → the body pivots about the sticking contacts (``pivots``).

A root is accepted only if every normal force is ≥ 0, every sticking force lies in its cone,
every sliding contact really slips, and the dynamics residual is below tolerance.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fixplan.jamming import _witness_kernels as kernels
from fixplan.kinematics import ContactSet

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class MotionWitness:
    """A kept-contact motion: acceleration, full contact forces, roles and quality."""

    acceleration: FloatArray
    forces: FloatArray  # stacked λ_i (contact frames)
    sticking: tuple[int, ...]  # indices of sticking contacts (empty: all slide)
    residual: float  # ‖M a − w_e − Jᵀλ‖_{M⁻¹} / ‖w_e‖_{M⁻¹}
    min_slip: float  # least slip speed over sliding frictional contacts, relative


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
        self.Jn = [self.Jall[o] for o in cs.offsets]
        self.T = [self.Jall[o + 1 : o + c.size] for c, o in zip(cs.contacts, cs.offsets, strict=True)]
        self.D = [self.Dm[i, : c.size - 1] for i, c in enumerate(cs.contacts)]
        self.J = [self.Jall[o : o + c.size] for c, o in zip(cs.contacts, cs.offsets, strict=True)]
        self.mu = list(self.mu_arr)

    def mask(self, stick: tuple[int, ...]) -> NDArray[np.bool_]:
        m = np.zeros(len(self.cs), dtype=np.bool_)
        m[list(stick)] = True
        return m


def _layout(cs: ContactSet, stick: tuple[int, ...]) -> list[tuple[int, int]]:
    """Start index and length of each contact's unknowns after the ndof entries of ``a``."""
    out, k = [], cs.ndof
    for i, c in enumerate(cs.contacts):
        size = c.size if i in stick else 1
        out.append((k, size))
        k += size
    return out


def _system(rows: Rows, w_e: FloatArray, z: FloatArray, stick: tuple[int, ...]) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Residual, Jacobian and full λ for unknowns ``z = (a, per-contact unknowns)`` (compiled)."""
    return kernels.system(rows.M, rows.Jall, rows.off, rows.size, rows.mu_arr, rows.Dm, w_e, z, rows.mask(stick))


def _newton(rows: Rows, w_e: FloatArray, z0: FloatArray, stick: tuple[int, ...], iterations: int = 30) -> FloatArray:
    return kernels.newton(rows.M, rows.Jall, rows.off, rows.size, rows.mu_arr, rows.Dm, w_e, z0, rows.mask(stick), iterations)


def _accept(rows: Rows, w_e: FloatArray, z: FloatArray, stick: tuple[int, ...], C: FloatArray, slip_rel: float, res_tol: float) -> MotionWitness | None:
    cs = rows.cs
    n = cs.ndof
    if not np.all(np.isfinite(z)):
        return None
    a = z[:n]
    _, _, lam = _system(rows, w_e, z, stick)
    scale = max(float(np.linalg.norm(C @ w_e)), 1e-300)
    dyn = float(np.linalg.norm(C @ (cs.mass_matrix @ a - w_e - cs.J.T @ lam))) / scale
    lever = max(float(np.linalg.norm(c.point_world - cs.com_world)) for c in cs.contacts)
    acc_ref = float(np.linalg.norm(a[: cs.dimension])) + float(np.linalg.norm(a[cs.dimension :])) * max(lever, 1e-12)
    if acc_ref <= 0.0 or dyn > res_tol:
        return None
    if float(np.linalg.norm(cs.G @ a)) > 1e-8 * acc_ref:
        return None
    f_scale = max(float(np.abs(lam).max()), 1e-300)
    slips = []
    for i, (c, off) in enumerate(zip(cs.contacts, cs.offsets, strict=True)):
        li = lam[off : off + c.size]
        if li[0] < -1e-9 * f_scale:
            return None
        if i in stick:
            tang = li[1:].copy()
            if c.soft:
                tang[-1] /= c.torsion_m
            if float(np.linalg.norm(tang)) > c.friction * li[0] + 1e-9 * f_scale:
                return None
        elif c.friction > 0.0:
            slips.append(float(np.linalg.norm(rows.D[i] * (rows.T[i] @ a))) / acc_ref)
    min_slip = min(slips) if slips else float("inf")
    if slips and min_slip <= slip_rel:
        return None
    return MotionWitness(a.copy(), lam, tuple(stick), dyn, min_slip)


def frictionless_start(cs: ContactSet, w_e: FloatArray) -> FloatArray:
    """``(a, f_n)`` of the frictionless all-kept problem (a Newton start)."""
    n, k = cs.ndof, len(cs)
    K = np.zeros((n + k, n + k))
    K[:n, :n] = cs.mass_matrix
    K[:n, n:] = -cs.G.T
    K[n:, :n] = cs.G
    rhs = np.concatenate([w_e, np.zeros(k)])
    return np.linalg.lstsq(K, rhs, rcond=None)[0]


def fixed_point_start(rows: Rows, w_e: FloatArray, z0: FloatArray, sweeps: int = 4) -> FloatArray:
    """Freeze the slip directions at the current ``a``, solve the linear all-slide system, repeat."""
    return kernels.fixed_point(rows.M, rows.Jall, rows.off, rows.size, rows.mu_arr, rows.Dm, w_e, z0, sweeps)


def _start_for(cs: ContactSet, base: FloatArray, stick: tuple[int, ...]) -> FloatArray:
    n = cs.ndof
    parts = [base[:n]]
    for i, c in enumerate(cs.contacts):
        fn = abs(base[n + i]) + 1e-6
        parts.append(np.concatenate([[fn], np.zeros(c.size - 1)]) if i in stick else np.array([fn]))
    return np.concatenate(parts)


def motion_witness(
    cs: ContactSet,
    w_e: FloatArray,
    C: FloatArray,
    *,
    allow_stick: bool = True,
    slip_rel: float = 1e-6,
    res_tol: float = 1e-9,
    rng_seed: int = 0,
    rows: Rows | None = None,
    null_G: FloatArray | None = None,
) -> MotionWitness | None:
    """An all-sliding witness if one exists, else (``allow_stick``) a pivoting one, else None.

    ``rows`` and ``null_G`` may be passed in when many wrenches share one contact set.
    """
    k = len(cs)
    if k == 0:
        return None
    rows = rows if rows is not None else Rows(cs)
    if cs.dimension == 2 and k <= 6:
        return _enumerate_2d(rows, w_e, C, allow_stick, slip_rel, res_tol)
    base = frictionless_start(cs, w_e)
    n = cs.ndof
    from fixplan.jamming.programs import null_basis

    N = null_G if null_G is not None else null_basis(cs.G)
    rng = np.random.default_rng(rng_seed)
    starts = [fixed_point_start(rows, w_e, base), base]
    for _ in range(2 if N.shape[1] else 0):
        a = N @ rng.standard_normal(N.shape[1])
        a *= max(float(np.linalg.norm(base[:n])), 1e-3) / max(float(np.linalg.norm(a)), 1e-300)
        starts.append(np.concatenate([a, np.abs(base[n:]) + 1e-3]))
    w_norm = max(float(np.linalg.norm(w_e)), 1e-300)
    patterns: list[tuple[int, ...]] = [()]
    if allow_stick:
        patterns += [(i,) for i in range(k)]
        if k > 2:
            patterns += list(itertools.combinations(range(k), 2))
    for stick in patterns:
        for z0 in starts if not stick else starts[:2]:
            z = _newton(rows, w_e, _start_for(cs, z0, stick), stick)
            F, _, _ = _system(rows, w_e, z, stick)
            if not float(np.linalg.norm(F)) <= 1e-9 * w_norm:  # not a root (or NaN): skip the checks
                continue
            witness = _accept(rows, w_e, z, stick, C, slip_rel, res_tol)
            if witness is not None:
                return witness
    return None


def _enumerate_2d(rows: Rows, w_e: FloatArray, C: FloatArray, allow_stick: bool, slip_rel: float, res_tol: float) -> MotionWitness | None:
    """2D: every role pattern (slide +, slide −, stick) is a linear system; all-slide first."""
    cs = rows.cs
    n, k = cs.ndof, len(cs)
    choices = (1.0, -1.0, 0.0) if allow_stick else (1.0, -1.0)
    patterns = sorted(itertools.product(choices, repeat=k), key=lambda p: sum(1 for s in p if s == 0.0))
    for signs in patterns:
        stick = tuple(i for i, s in enumerate(signs) if s == 0.0)
        lay = _layout(cs, stick)
        nz = lay[-1][0] + lay[-1][1]
        K = np.zeros((nz, nz))
        rhs = np.zeros(nz)
        K[:n, :n] = cs.mass_matrix
        rhs[:n] = w_e
        row = n
        for i in range(k):
            start, size = lay[i]
            if signs[i] == 0.0:
                K[:n, start : start + size] = -rows.J[i].T
                K[row : row + size, :n] = rows.J[i]
                row += size
            else:
                K[:n, start] = -(rows.Jn[i] - rows.mu[i] * signs[i] * rows.T[i][0])
                K[row, :n] = rows.Jn[i]
                row += 1
        try:
            z = np.linalg.solve(K, rhs)
        except np.linalg.LinAlgError:
            continue
        a = z[:n]
        if not all(rows.mu[i] <= 0.0 or signs[i] == 0.0 or signs[i] * float(rows.T[i][0] @ a) > 0 for i in range(k)):
            continue
        witness = _accept(rows, w_e, z, stick, C, slip_rel, res_tol)
        if witness is not None:
            return witness
    return None
