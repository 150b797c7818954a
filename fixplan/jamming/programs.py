"""The jamming analysis' cone programs, built as plain matrices (build apart from solve).

Every program here has the form (Clarabel's standard form)::

    minimise  cᵀx   subject to   b − A x ∈ K

with ``K`` a product of non-negative orthants and second-order cones, so it can be printed,
tested, and solved either by handing the matrices to Clarabel directly (the fast path) or by
the independent cvxpy model in :mod:`fixplan.jamming.cvx` (the reference path).

Contact forces are the reduced variables ``f``: per contact the normal force ``f_n``, then —
only when ``μ > 0`` — the scaled tangential components ``s`` (``f_t = μ s``) and, for a soft
finger, the scaled spin moment (``f_s = μ e_r s_s``). ``λ = S f`` expands them to the full
contact vectors of :class:`~fixplan.kinematics.ContactSet` (``S`` holds the μ's).

Friction cones are exact (docs/math.md [9], [10]), written on the scaled variables so that
every cone has unit coefficients whatever μ (a tiny μ is then as exact as μ = 0):

- 3D point contact: ``(f_n, s_1, s_2) ∈ SOC³``  (``‖f_t‖ ≤ μ f_n``);
- 3D soft finger: ``(f_n, s_1, s_2, s_s) ∈ SOC⁴``  (``‖(f_t, f_s / e_r)‖ ≤ μ f_n``);
- 2D: ``f_n ± s ≥ 0`` (the planar cone *is* this pair of half-planes: nothing linearised);
- ``μ = 0``: only ``f_n ≥ 0``.

The residual programs all minimise ``t`` subject to ``‖P C (ŵ + Jᵀ S f)‖ ≤ t``, where
``C = L⁻¹`` with ``M = L Lᵀ`` (so ``‖C x‖ = ‖x‖_{M⁻¹}``) and ``P`` projects out the motions
allowed by the question:

- static balance (margin): ``P = I`` — no motion allowed;
- maintained motion: ``P`` removes ``Lᵀ·null(G)`` — motions that keep every contact;
- rolling: ``P`` removes ``Lᵀ·null(J)`` — motions with no slip at any contact.

The optimum is the least ``M⁻¹``-weighted residual: 0 exactly when the question's motion
(or rest) is consistent with forces in the cones.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from fixplan.kinematics import Contact, ContactSet
from fixplan.settings import DEFAULT

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ForceLayout:
    """How the reduced force variables ``f`` map to the stacked contact vectors ``λ``."""

    S: FloatArray  # (Σ sizes × nf): λ = S f
    normal_index: NDArray[np.int64]  # index in f of each contact's normal force
    cones: tuple[tuple[str, int], ...]  # ("nonneg"|"soc", dim) per contact block
    cone_rows: FloatArray  # (Σ cone dims × nf): s = cone_rows @ f must lie in the cones

    @property
    def nf(self) -> int:
        return int(self.S.shape[1])


def force_layout(cs: ContactSet, *, scaled: bool = True) -> ForceLayout:
    """The reduced force variables and their exact friction cones for ``cs``.

    ``scaled=False``: the tangential variables are the forces themselves and the cones read
    ``(μ f_n, f_t)`` (the earlier form; kept for the wrench search, whose answers
    the classifier confirms, so that its plans stay as they were).
    """
    cols: list[FloatArray] = []
    normal_index: list[int] = []
    cones: list[tuple[str, int]] = []
    rows: list[list[tuple[int, float]]] = []
    total = int(cs.sizes.sum()) if len(cs) else 0
    for contact, offset in zip(cs.contacts, cs.offsets, strict=True):
        base = len(cols)
        normal_index.append(base)
        e = np.zeros(total)
        e[offset] = 1.0
        cols.append(e)
        mu = contact.friction
        if mu <= 0.0:
            cones.append(("nonneg", 1))
            rows.append([(base, 1.0)])
            continue
        # tangential (and spin) variables s scaled by μ: λ_t = μ s, λ_spin = μ e_r s_spin, so
        # that every cone reads (f_n, s) with unit coefficients. With the cone written on
        # (μ f_n, λ_t) a tiny μ made the normal force's own sign a 1e-12-weighted constraint:
        # at μ = 1e-12 the solver returned f_n = -1 N as "balanced"
        for k in range(1, contact.size):
            e = np.zeros(total)
            e[offset + k] = mu * (contact.torsion_m if k == 3 else 1.0) if scaled else 1.0
            cols.append(e)
        # the cone rows: (f_n, s) scaled, (μ f_n, f_t[, f_s / e_r]) not
        n_coef, spin_coef = (1.0, 1.0) if scaled else (mu, 1.0 / contact.torsion_m if contact.soft else 1.0)
        if contact.dimension == 2:
            cones.append(("nonneg", 2))
            rows.append([(base, n_coef), (base + 1, -1.0)])
            rows.append([(base, n_coef), (base + 1, 1.0)])
        else:
            cones.append(("soc", contact.size))
            rows.append([(base, n_coef)])
            rows.append([(base + 1, 1.0)])
            rows.append([(base + 2, 1.0)])
            if contact.soft:
                rows.append([(base + 3, spin_coef)])
    nf = len(cols)
    S = np.array(cols).T if cols else np.zeros((total, 0))
    R = np.zeros((len(rows), nf))
    for i, entries in enumerate(rows):
        for j, v in entries:
            R[i, j] = v
    return ForceLayout(S, np.array(normal_index, dtype=np.int64), tuple(cones), R)


def force_cone_violation(cs: ContactSet, lam: FloatArray) -> float:
    """Largest violation of the friction cones by the full contact vectors ``λ`` (0 inside).

    Written from the mechanics (``λ_n ≥ 0``, ``‖λ_t‖ ≤ μ λ_n``, a soft finger's spin scaled by
    its torsional radius), not from a program's cone rows: a certificate is checked in the
    forces it claims, whatever scaling the program used.
    """
    worst = 0.0
    for offset, contact in zip(cs.offsets, cs.contacts, strict=True):
        lam_c = lam[offset : offset + contact.size]
        worst = max(worst, -float(lam_c[0]), _tangential(contact, lam_c) - contact.friction * float(lam_c[0]))
    return max(worst, 0.0)


def _tangential(contact: Contact, lam_c: FloatArray) -> float:
    """``‖λ_t‖`` of one contact (with a soft finger's spin over its torsional radius)."""
    if contact.dimension == 2:
        return abs(float(lam_c[1]))
    if contact.soft:
        return float(np.sqrt(lam_c[1] ** 2 + lam_c[2] ** 2 + (lam_c[3] / contact.torsion_m) ** 2))
    return float(np.sqrt(lam_c[1] ** 2 + lam_c[2] ** 2))


def into_cones(cs: ContactSet, lam: FloatArray) -> FloatArray:
    """``λ`` moved into the friction cones: a negative normal force to 0, a tangential part beyond ``μ λ_n`` shrunk onto it.

    Exact for an answer already inside (returned unchanged); a solver's answer a round-off
    outside moves by that round-off. The caller recomputes the residual with what is returned,
    so a verdict rests on forces that are in the cones.
    """
    out = np.array(lam, dtype=float, copy=True)
    for offset, contact in zip(cs.offsets, cs.contacts, strict=True):
        lam_c = out[offset : offset + contact.size]  # a view: edited in place
        if lam_c[0] < 0.0:
            lam_c[0] = 0.0
        t = _tangential(contact, lam_c)
        limit = contact.friction * lam_c[0]
        if t > limit:
            lam_c[1:] *= limit / t
    return out


def null_basis(A: FloatArray, tol: float = DEFAULT.numerics.rcond) -> FloatArray:
    """Orthonormal basis (columns) of the null space of ``A``."""
    if A.shape[0] == 0:
        return np.eye(A.shape[1])
    # as scipy.linalg.null_space(A, rcond=tol), with numpy's SVD (scipy.linalg is not imported
    # on the planner's path for this one call)
    _, s, vh = np.linalg.svd(A, full_matrices=True)
    rank = int(np.sum(s > (s.max(initial=0.0) * tol)))
    return np.ascontiguousarray(vh[rank:].T)


@dataclass(frozen=True)
class ConeProgram:
    """``min cᵀx  s.t.  b − A x ∈ K``, with ``K`` listed in ``cones`` (in row order)."""

    c: FloatArray
    A: FloatArray
    b: FloatArray
    cones: tuple[tuple[str, int], ...]
    name: str
    nf: int  # the first nf entries of x are the reduced forces f

    def slack(self, x: FloatArray) -> FloatArray:
        return self.b - self.A @ x

    def cone_violation(self, x: FloatArray) -> float:
        """Largest violation of ``b − A x ∈ K`` (0 when feasible)."""
        return cone_violation_of(self.slack(x), self.cones)


def cone_violation_of(s: FloatArray, cones: tuple[tuple[str, int], ...]) -> float:
    """Largest violation of ``s ∈ K`` for a product of cones listed in row order."""
    worst, row = 0.0, 0
    for kind, dim in cones:
        if kind == "nonneg":
            worst = max(worst, -float(s[row : row + dim].min()))
        elif kind == "soc":
            block = s[row : row + dim]
            worst = max(worst, float(np.sqrt(block[1:] @ block[1:])) - float(block[0]))
        else:  # "zero"
            worst = max(worst, float(np.abs(s[row : row + dim]).max()))
        row += dim
    return worst


class ProgramBuilder:
    """Builds the residual programs of one contact set; the wrench enters only through ``b``.

    That split is what makes batch classification fast: the matrices are built once per
    contact set and each wrench only updates ``b``.
    """

    def __init__(self, cs: ContactSet):
        self.cs = cs
        self.layout = force_layout(cs)
        L = np.linalg.cholesky(cs.mass_matrix)
        # L⁻¹ (a ≤ 6×6 triangle: np.linalg.inv takes ~10 µs, scipy's solve_triangular 0.1–6 ms)
        self.C = np.linalg.inv(L)
        self.L = L
        self.B = cs.J.T @ self.layout.S if len(cs) else np.zeros((cs.ndof, 0))  # wrench per f

    @cached_property
    def N_maintain(self) -> FloatArray:
        """Basis of accelerations keeping every contact (``G a = 0``)."""
        return null_basis(self.cs.G)

    @cached_property
    def N_roll(self) -> FloatArray:
        """Basis of accelerations with no slip at any contact (``J a = 0``)."""
        return null_basis(self.cs.J)

    def projector(self, N: FloatArray | None) -> FloatArray:
        """``P`` removing ``Lᵀ·span(N)`` in the ``C``-weighted space (identity for ``N = None``)."""
        n = self.cs.ndof
        if N is None or N.shape[1] == 0:
            return np.eye(n)
        Q, _ = np.linalg.qr(self.L.T @ N)
        return np.eye(n) - Q @ Q.T

    def residual_program(self, name: str, P: FloatArray) -> ConeProgram:
        """``min t  s.t. ‖P C (ŵ + B f)‖ ≤ t, f ∈ K`` with ``b`` left at ŵ = 0 (see :meth:`rhs`)."""
        lay, n = self.layout, self.cs.ndof
        nf = lay.nf
        nx = nf + 1
        c = np.zeros(nx)
        c[-1] = 1.0
        A_soc = np.zeros((n + 1, nx))
        A_soc[0, -1] = -1.0
        A_soc[1:, :nf] = -(P @ self.C @ self.B)
        A_cone = np.zeros((lay.cone_rows.shape[0], nx))
        A_cone[:, :nf] = -lay.cone_rows
        A = np.vstack([A_soc, A_cone])
        b = np.zeros(A.shape[0])
        cones = (("soc", n + 1), *lay.cones)
        return ConeProgram(c, A, b, cones, name, nf)

    def rhs(self, program: ConeProgram, P: FloatArray, w_hat: FloatArray) -> FloatArray:
        """``b`` of a residual program for the (normalised) wrench ``ŵ``."""
        b = np.zeros(program.A.shape[0])
        b[1 : self.cs.ndof + 1] = P @ self.C @ w_hat
        return b

    def residual(self, P: FloatArray, w_hat: FloatArray, f: FloatArray) -> float:
        """``‖P C (ŵ + B f)‖`` evaluated directly (the program's value, recomputed)."""
        return float(np.linalg.norm(P @ self.C @ (w_hat + self.B @ f)))

    def m_inv_norm(self, w: FloatArray) -> float:
        """``‖w‖_{M⁻¹}``."""
        return float(np.linalg.norm(self.C @ w))
