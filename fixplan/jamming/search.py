"""The non-jamming wrench for a desired motion (MATH.md "As cone programs", program 2).

Given the desired acceleration ``â`` of the workpiece (a twist rate of the body-frame origin,
world axes), every contact is sorted by what ``â`` does to it:

- kept and sliding (``G_i â = 0``, tangential ``â_t,i ≠ 0``): friction is at its limit and
  opposes the slip, ``λ_i = f_n,i (1, −μ_i â_t,i/‖â_t,i‖)`` — one unknown ``f_n,i ≥ 0``;
- kept without slip (rolling/sticking, ``J_i â = 0``): ``λ_i`` anywhere in its exact cone;
- opening (``G_i â > 0``): ``λ_i = 0``;
- penetrating (``G_i â < 0``): the motion is impossible — an input error.

With ``a = s â`` the dynamics ``M a = w + w_g + Σ J_iᵀ λ_i`` is linear in the unknowns
``(w, f_n, λ_stick, s)``, and the manipulator limits ``‖F‖ ≤ F_max``, ``‖T‖ ≤ T_max`` are
second-order cones. The program maximises the least normal force ``τ`` over the kept contacts
(the margin against losing a contact) subject to ``s ≥ 1`` (at least the requested
acceleration). The wrench found is then checked with the static-balance program: it must not
be balanced (else it would jam instead of moving).

Without manipulator limits in the file the search bounds the wrench by ``F_max = 5 m |g|``
(``5 m·9.81`` in zero gravity) and ``T_max = F_max ×`` the part's bounding radius, and says so.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fixplan.errors import InputError
from fixplan.jamming.backends import ClarabelProgram
from fixplan.jamming.classify import Classification, Classifier
from fixplan.jamming.programs import ConeProgram, force_layout
from fixplan.kinematics import ContactSet
from fixplan.locating import contact_set
from fixplan.pose import cross2

if TYPE_CHECKING:
    from fixplan.fixture import Fixture
    from fixplan.pose import Pose

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class WrenchSearch:
    """The result of :func:`search_wrench`."""

    found: bool
    wrench: FloatArray | None  # applied, about the body origin (or ``at``), world axes
    margin_N: float  # least normal force over the kept contacts [N]
    acceleration: FloatArray | None  # achieved centre-of-mass twist rate (s · â)
    contact_roles: dict[str, str]  # name → "sliding" | "sticking" | "opening"
    contact_forces: dict[str, FloatArray]
    check: Classification | None  # static-balance check of the wrench found
    reason: str
    binding: list[str] = field(default_factory=list)  # active limits at the optimum
    limits: tuple[float, float] = (float("inf"), float("inf"))

    def to_json(self) -> dict[str, Any]:
        return {
            "found": self.found,
            "wrench": None if self.wrench is None else [float(x) for x in self.wrench],
            "margin": float(self.margin_N),
            "acceleration": None if self.acceleration is None else [float(x) for x in self.acceleration],
            "contact_roles": dict(self.contact_roles),
            "contact_forces": {k: [float(x) for x in v] for k, v in self.contact_forces.items()},
            "check_mode": None if self.check is None else self.check.mode,
            "check_margin": None if self.check is None else float(self.check.margin),
            "reason": self.reason,
            "binding": list(self.binding),
            "limits": {"max_force": self.limits[0], "max_torque": self.limits[1]},
        }


def twist_at_com(cs: ContactSet, twist: FloatArray, about_world: FloatArray) -> FloatArray:
    """A twist of the point ``about_world`` re-expressed as the twist of the centre of mass."""
    d = cs.dimension
    off = cs.com_world - about_world
    if d == 3:
        return np.concatenate([twist[:3] + np.cross(twist[3:], off), twist[3:]])
    return np.array([twist[0] - twist[2] * off[1], twist[1] + twist[2] * off[0], twist[2]])


def _roles(cs: ContactSet, a_hat: FloatArray, tol: float) -> dict[str, str]:
    scale = float(np.linalg.norm(a_hat[: cs.dimension])) + float(np.linalg.norm(a_hat[cs.dimension :])) * cs.max_lever_m
    roles: dict[str, str] = {}
    for c, off in zip(cs.contacts, cs.offsets, strict=True):
        u = cs.J[off : off + c.size] @ a_hat
        if u[0] < -tol * scale:
            raise InputError(
                f"the motion pushes the workpiece into contact {c.name} (normal rate {u[0]:.3g}); expected a motion that keeps or opens it"
            )
        if u[0] > tol * scale:
            roles[c.name] = "opening"
        elif float(np.linalg.norm(u[1:3] if c.dimension == 3 else u[1:2])) > tol * scale or (
            c.soft and abs(u[3]) * c.torsion_m > tol * scale
        ):
            roles[c.name] = "sliding"
        else:
            roles[c.name] = "sticking"
    return roles


def search_wrench(
    fixture: Fixture,
    motion: ArrayLike,
    contacts: list[str] | None = None,
    *,
    pose: Pose | str | None = None,
    at: ArrayLike | None = None,
    objective: str = "margin",
    min_margin_N: float | None = None,
) -> WrenchSearch:
    """The applied wrench that moves the part with acceleration ≥ ``motion``.

    ``motion`` is the desired acceleration of the body-frame origin (or of ``at``) as a twist
    rate in world axes: ``ax,ay,az,αx,αy,αz`` (2D ``ax,ay,α``) [m/s², rad/s²].

    ``objective="margin"`` (default) returns the wrench with the largest least normal force τ*
    within the limits. ``objective="effort"`` then solves a second program: the least push
    ``‖(F, T_c / L)‖`` (``T_c`` about the centre of mass, ``L`` the largest contact lever) that
    keeps every kept contact pressed by at least ``min(min_margin_N, τ*)`` (default
    ``min_margin_N = m |g|``, the part's weight): a push an operator or a compliant robot can follow
    without the large forces that turn small tracking errors into large disturbances.
    """
    m = np.asarray(motion, dtype=float)
    if m.shape != (fixture.ndof,) or not np.all(np.isfinite(m)):
        raise InputError(f"--motion expects {fixture.ndof} finite numbers, got {list(np.atleast_1d(m))}")
    if float(np.linalg.norm(m)) == 0.0:
        raise InputError("--motion is zero (expected the desired acceleration of the part)")
    cs = contact_set(fixture, pose, contacts)
    if len(cs) == 0:
        raise InputError("no contacts to analyse (the workpiece touches no locator here; name contacts explicitly)")
    about = cs.body_origin_world if at is None else np.asarray(at, dtype=float)
    a_hat = twist_at_com(cs, m, about)
    roles = _roles(cs, a_hat, 1e-9)
    wp = fixture.workpiece
    g = float(np.linalg.norm(fixture.gravity)) or 9.81
    F_max, T_max = fixture.manipulator.max_force_N, fixture.manipulator.max_torque_Nm
    notes = ""
    if not np.isfinite(F_max):
        F_max = 5.0 * wp.mass_kg * g
        notes += f" (no manipulator.max_force: bounded at 5 m|g| = {F_max:.3g} N)"
    if not np.isfinite(T_max):
        T_max = F_max * wp.shape.bounding_radius
        notes += f" (no manipulator.max_torque: bounded at {T_max:.3g} N·m)"

    prog, meta = _build(cs, a_hat, roles, fixture.gravity_wrench(), about, F_max, T_max)
    sol = ClarabelProgram(prog).solve(prog.b)
    n = cs.ndof
    if not sol.solved or -sol.value <= 1e-9 * F_max:
        # Diagnose: is it the limits, or the motion itself?
        prog_free, _ = _build(cs, a_hat, roles, fixture.gravity_wrench(), about, 1e3 * F_max, 1e3 * T_max)
        free = ClarabelProgram(prog_free).solve(prog_free.b)
        if free.solved and -free.value > 1e-9 * F_max:
            w_free = free.x[:n]
            F_need = float(np.linalg.norm(w_free[: cs.dimension]))
            reason = f"the manipulator is too weak: this motion needs more than max_force {F_max:.3g} N or max_torque {T_max:.3g} N·m (unbounded search used ‖F‖ = {F_need:.3g} N){notes}"
            binding = ["max_force", "max_torque"]
        else:
            reason = (
                "no wrench moves the part this way while keeping the contacts (every such push jams or opens a contact)"
            )
            binding = []
        return WrenchSearch(False, None, 0.0, None, roles, {}, None, reason, binding, (F_max, T_max))

    x = sol.x
    tau = float(-sol.value)
    if objective == "effort":
        tau_req = min(wp.mass_kg * g if min_margin_N is None else float(min_margin_N), tau)
        prog_e, meta_e = _build(
            cs, a_hat, roles, fixture.gravity_wrench(), about, F_max, T_max, effort_margin_N=tau_req * (1 - 1e-6)
        )
        sol_e = ClarabelProgram(prog_e).solve(prog_e.b)
        if sol_e.solved:
            x, meta = sol_e.x, meta_e
            tau = float(x[meta["tau"]])
        else:
            notes += " (the least-effort program did not solve: the best-margin push is returned)"
    elif objective != "margin":
        raise InputError(f"unknown search objective {objective!r} (expected 'margin' or 'effort')")
    w_com = x[:n]
    s = float(x[meta["s"]])
    lam = meta["expand"](x)
    forces = {c.name: lam[o : o + c.size] for c, o in zip(cs.contacts, cs.offsets, strict=True)}
    # the applied wrench about the user's point
    w_user = _about_point(cs, w_com, about)
    binding = []
    if abs(float(np.linalg.norm(w_com[: cs.dimension])) - F_max) <= 1e-6 * F_max:
        binding.append("max_force")
    if abs(float(np.linalg.norm(w_user[cs.dimension :])) - T_max) <= 1e-6 * T_max:
        binding.append("max_torque")
    clf = Classifier(cs, fixture.gravity_wrench(), tolerances=fixture.tolerances)
    check = clf.classify(w_com, w_user)
    ok = not check.balanced
    reason = (
        f"moves as asked with every kept contact pressed by ≥ {tau:.3g} N{notes}"
        if ok
        else f"the wrench found is statically balanced ({check.mode}): it would not move the part"
    )
    return WrenchSearch(ok, w_user, tau, s * a_hat, roles, forces, check, reason, binding, (F_max, T_max))


def _about_point(cs: ContactSet, w_com: FloatArray, point: FloatArray) -> FloatArray:
    """Re-express a wrench about the centre of mass as one about ``point``."""
    d = cs.dimension
    off = cs.com_world - point
    if d == 3:
        return np.concatenate([w_com[:3], w_com[3:] + np.cross(off, w_com[:3])])
    return np.array([w_com[0], w_com[1], w_com[2] + cross2(off, w_com[:2])])


def _build(
    cs: ContactSet,
    a_hat: FloatArray,
    roles: dict[str, str],
    w_g: FloatArray,
    about: FloatArray,
    F_max: float,
    T_max: float,
    effort_margin_N: float | None = None,
) -> tuple[ConeProgram, dict]:
    """Variables x = (w [n], f_n sliding [ks], f sticking [reduced], s, τ[, e]).

    Without ``effort_margin_N`` the program maximises τ. With it, it minimises the effort
    ``e ≥ ‖(F, T_c / L)‖`` subject to ``τ ≥ effort_margin_N``.
    """
    n, d = cs.ndof, cs.dimension
    slide = [i for i, c in enumerate(cs.contacts) if roles[c.name] == "sliding"]
    stick = [i for i, c in enumerate(cs.contacts) if roles[c.name] == "sticking"]
    stick_cs = ContactSet(tuple(cs.contacts[i] for i in stick), cs.com_world, cs.mass_matrix, cs.body_origin_world)
    lay = force_layout(stick_cs) if stick else None
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
        c, off = cs.contacts[i], cs.offsets[i]
        u = J[off : off + c.size] @ a_hat
        phi = np.zeros(c.size)
        phi[0] = 1.0
        if c.friction > 0:
            if c.soft:
                scaled = np.array([u[1], u[2], c.torsion_m * u[3]])
                dvec = scaled / np.linalg.norm(scaled)
                phi[1:3] = -c.friction * dvec[:2]
                phi[3] = -c.friction * c.torsion_m * dvec[2]
            else:
                t = u[1:3] if d == 3 else u[1:2]
                phi[1 : 1 + t.shape[0]] = -c.friction * t / np.linalg.norm(t)
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
        Kx = np.array([[0, -off[2], off[1]], [off[2], 0, -off[0]], [-off[1], off[0], 0]])
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
    c_vec = np.zeros(nx)
    if effort:
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
