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

:func:`wrench_search_program` builds the wrench search's program (docs/math.md program 2, solved
by :mod:`fixplan.jamming.search`): the push of largest kept-contact margin, or of least effort,
that produces a motion without jamming.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from fixplan.jamming.hand_set import TorqueBox, torque_rows
from fixplan.kinematics import Contact, ContactSet
from fixplan.settings import DEFAULT
from fixplan.spatial import skew

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


def wrench_search_program(
    cs: ContactSet,
    a_hat: FloatArray,
    roles: dict[str, str],
    directions: dict[str, FloatArray],
    w_g: FloatArray,
    about: FloatArray,
    F_max: float,
    T_max: float,
    effort_margin_N: float | None = None,
    *,
    cert: FloatArray | None,
    jam: float,
    s_max: float = math.inf,
    least: Literal["effort", "force", "torque"] = "effort",
    shared: dict[str, Any] | None = None,
    hand_sets: tuple[TorqueBox, ...] = (),
    hand_frac: float | None = 1.0,
) -> tuple[ConeProgram, dict]:
    """The wrench search's cone program (:mod:`fixplan.jamming.search`, program 2 of docs/math.md).

    Variables x = (w [n], f_n sliding [ks], f sticking [reduced], s, τ[, e]).

    Without ``effort_margin_N`` the program maximises τ. With it, it minimises ``e`` subject to
    ``τ ≥ effort_margin_N``: the effort ``e ≥ ‖(F, T_c / L)‖`` (``least="effort"``), the force
    ``e ≥ ‖F‖`` or the torque about the user's point ``e ≥ ‖T‖``. All keep the total wrench
    ``w_e = w + w_g`` a relative distance ``jam`` from static balance, certified by the motion
    ``cert`` (``ŷ``, ``‖ŷ‖_M = 1``, ``J_i ŷ ∈ K_i*``): ``ŷᵀ w_e ≥ jam ‖w_e‖_{M⁻¹}``.
    ``shared``: a dictionary kept by the caller across builds with the same ``cs`` and ``roles``
    (one search), which then computes the sticking contacts' layout and ``L⁻¹`` once.
    ``hand_sets``: the arm's joint-torque boxes, kept within ``hand_frac`` of the effort limits
    (None: left out, for the diagnoses), as ``A w ≤ b`` with ``w`` about the centre of mass.
    """
    n, d = cs.ndof, cs.dimension
    shared = {} if shared is None else shared
    slide = [i for i, c in enumerate(cs.contacts) if roles[c.name] == "sliding"]
    stick = [i for i, c in enumerate(cs.contacts) if roles[c.name] == "sticking"]
    if "stick_cs" not in shared:
        stick_cs = ContactSet(tuple(cs.contacts[i] for i in stick), cs.com_world, cs.mass_matrix, cs.body_origin_world)
        shared["stick_cs"] = stick_cs
        # unscaled cones (the earlier form): the search's answers are confirmed by the
        # classifier, whose programs are scaled; with scaled cones here the optimum moved by
        # 1e-4 N·m and cylinder-5's spin landed where the pivot witness is not found
        shared["lay"] = force_layout(stick_cs, scaled=False) if stick else None
    stick_cs, lay = shared["stick_cs"], shared["lay"]
    nf_stick = lay.nf if lay else 0
    ks = len(slide)
    i_w, i_fn, i_fs = 0, n, n + ks
    i_s, i_tau = n + ks + nf_stick, n + ks + nf_stick + 1
    effort = effort_margin_N is not None
    i_e = i_tau + 1
    nx = i_tau + 1 + (1 if effort else 0)
    J = cs.J
    # sliding contact wrench columns J_iᵀ φ_i
    phis = []
    for i in slide:
        c = cs.contacts[i]
        dvec = directions[c.name]  # unit slip (torsion scaled to metres for soft fingers)
        phi = np.zeros(c.size)
        phi[0] = 1.0
        if c.friction > 0:
            if c.soft:
                phi[1:3] = -c.friction * dvec[:2]
                phi[3] = -c.friction * c.torsion_m * dvec[2]
            else:
                phi[1 : 1 + dvec.shape[0]] = -c.friction * dvec
        phis.append(phi)
    rows_A: list[FloatArray] = []
    rows_b: list[FloatArray] = []
    cones: list[tuple[str, int]] = []
    # dynamics: s M â − w − Σ f_n J_iᵀ φ_i − B_stick f = w_g   (zero cone: b − A x = 0)
    A_dyn = np.zeros((n, nx))
    A_dyn[:, i_s] = cs.mass_matrix @ a_hat
    A_dyn[:, i_w : i_w + n] = -np.eye(n)
    for k, i in enumerate(slide):
        off, c = cs.offsets[i], cs.contacts[i]
        A_dyn[:, i_fn + k] = -(J[off : off + c.size].T @ phis[k])
    if lay is not None:
        A_dyn[:, i_fs : i_fs + nf_stick] = -(stick_cs.J.T @ lay.S)
    rows_A.append(A_dyn)
    rows_b.append(w_g.copy())
    cones.append(("zero", n))
    # s ≥ 1 ; f_n,i − τ ≥ 0 for kept contacts ; τ ≥ 0
    lin = []
    e = np.zeros(nx)
    e[i_s] = -1.0
    lin.append((e, -1.0))  # b − A x = s − 1 ≥ 0
    if math.isfinite(s_max):
        e = np.zeros(nx)
        e[i_s] = 1.0
        lin.append((e, s_max))  # s_max − s ≥ 0: no more than s_max times the requested acceleration
    for k in range(ks):
        e = np.zeros(nx)
        e[i_fn + k] = -1.0
        e[i_tau] = 1.0
        lin.append((e, 0.0))
    if lay is not None:
        for idx in lay.normal_index:
            e = np.zeros(nx)
            e[i_fs + idx] = -1.0
            e[i_tau] = 1.0
            lin.append((e, 0.0))
    e = np.zeros(nx)
    e[i_tau] = -1.0
    lin.append((e, -effort_margin_N if effort_margin_N is not None else 0.0))  # τ ≥ τ_req (effort) or τ ≥ 0
    rows_A.append(np.array([r for r, _ in lin]))
    rows_b.append(np.array([b for _, b in lin]))
    cones.append(("nonneg", len(lin)))
    # friction cones of sticking contacts
    if lay is not None:
        A_c = np.zeros((lay.cone_rows.shape[0], nx))
        A_c[:, i_fs : i_fs + nf_stick] = -lay.cone_rows
        rows_A.append(A_c)
        rows_b.append(np.zeros(lay.cone_rows.shape[0]))
        cones.extend(lay.cones)
    # ‖F‖ ≤ F_max
    A_f = np.zeros((d + 1, nx))
    A_f[1:, i_w : i_w + d] = -np.eye(d)
    rows_A.append(A_f)
    rows_b.append(np.concatenate([[F_max], np.zeros(d)]))
    cones.append(("soc", d + 1))
    # ‖T about the user's point‖ ≤ T_max: T_p = T_c + (c − p) × F
    off = cs.com_world - about
    if d == 3:
        Kx = skew(off)  # the linear map F ↦ (c − p) × F of spatial.shift_wrench
        A_t = np.zeros((4, nx))
        A_t[1:, 3:6] = -np.eye(3)
        A_t[1:, 0:3] = -Kx
        rows_A.append(A_t)
        rows_b.append(np.array([T_max, 0.0, 0.0, 0.0]))
        cones.append(("soc", 4))
    else:
        row = np.zeros(nx)
        row[2] = 1.0
        row[0] = -off[1]
        row[1] = off[0]
        rows_A.append(np.vstack([row, -row]))
        rows_b.append(np.array([T_max, T_max]))
        cones.append(("nonneg", 2))
    if hand_sets and hand_frac is not None:
        # the arm: |τ_g + Jᵀ S w| ≤ s τ_max at every box (b − A x ≥ 0)
        A_arm, b_arm = torque_rows(hand_sets, cs.com_world, hand_frac)
        A_h = np.zeros((A_arm.shape[0], nx))
        A_h[:, i_w : i_w + n] = A_arm
        rows_A.append(A_h)
        rows_b.append(b_arm)
        cones.append(("nonneg", A_arm.shape[0]))
    if cert is not None:
        # not jamming: (ŷᵀ w_e / jam, C w_e) ∈ SOC, C = L⁻¹ (‖C x‖ = ‖x‖_{M⁻¹})
        if "C" not in shared:
            shared["C"] = np.linalg.inv(np.linalg.cholesky(cs.mass_matrix))
        C = shared["C"]
        A_j = np.zeros((n + 1, nx))
        A_j[0, i_w : i_w + n] = -cert / jam
        A_j[1:, i_w : i_w + n] = -C
        rows_A.append(A_j)
        rows_b.append(np.concatenate([[float(cert @ w_g) / jam], C @ w_g]))
        cones.append(("soc", n + 1))
    c_vec = np.zeros(nx)
    if effort and least == "effort":
        # e ≥ ‖(F, T_c / L)‖ with the moment about the centre of mass (w is about the com)
        L = max(cs.max_lever_m, 1e-9)
        A_e = np.zeros((n + 1, nx))
        A_e[0, i_e] = -1.0
        A_e[1 : 1 + d, i_w : i_w + d] = -np.eye(d)
        A_e[1 + d :, i_w + d : i_w + n] = -np.eye(n - d) / L
        rows_A.append(A_e)
        rows_b.append(np.zeros(n + 1))
        cones.append(("soc", n + 1))
        c_vec[i_e] = 1.0
    elif effort:
        # e ≥ ‖F‖, or e ≥ ‖T about the user's point‖ (the moment the torque limit bounds)
        T_rows = np.zeros((n - d, nx))
        if d == 3:
            T_rows[:, 3:6] = np.eye(3)
            T_rows[:, 0:3] = skew(off)
        else:
            T_rows[0] = row
        A_e = np.zeros((1 + (d if least == "force" else n - d), nx))
        A_e[0, i_e] = -1.0
        if least == "force":
            A_e[1:, i_w : i_w + d] = -np.eye(d)
        else:
            A_e[1:] = -T_rows
        rows_A.append(A_e)
        rows_b.append(np.zeros(A_e.shape[0]))
        cones.append(("soc", A_e.shape[0]))
        c_vec[i_e] = 1.0
    else:
        c_vec[i_tau] = -1.0
    A = np.vstack(rows_A)
    b = np.concatenate(rows_b)

    def expand(x: FloatArray) -> FloatArray:
        lam = np.zeros(J.shape[0])
        for k, i in enumerate(slide):
            off_i, c = cs.offsets[i], cs.contacts[i]
            lam[off_i : off_i + c.size] = x[i_fn + k] * phis[k]
        if lay is not None:
            lam_stick = lay.S @ x[i_fs : i_fs + nf_stick]
            for j, i in enumerate(stick):
                off_i, c = cs.offsets[i], cs.contacts[i]
                o = stick_cs.offsets[j]
                lam[off_i : off_i + c.size] = lam_stick[o : o + c.size]
        return lam

    return ConeProgram(c_vec, A, b, tuple(cones), "wrench-search", 0), {"s": i_s, "tau": i_tau, "expand": expand}
