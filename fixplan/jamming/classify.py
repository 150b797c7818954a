"""Classify what a wrench does to a workpiece at rest in contact (docs/math.md, "As cone programs").

For the total wrench ``w_e`` (applied + gravity, about the centre of mass) the verdict is the
first certificate found, in this order:

1. ``held`` — normal forces alone balance ``w_e`` (a non-negative least-squares problem);
2. ``jammed`` — the static-balance SOCP is feasible: balance needs friction;
3. ``separates`` — not balanced, and no forces in the cones keep every contact
   (the maintained-motion SOCP has a positive residual): some contact must open;
4. ``rolls`` — a motion with no slip at any contact is consistent with forces in the cones;
5. ``slides`` — Theorem 1's witness: every contact kept and sliding with friction at its limit;
6. ``pivots`` — every contact kept, some sticking while the others slide (the body turns about
   the sticking contacts). Beyond the modes the paper names: added because it is a definite outcome, and
   by Theorem 1 it is *not* a non-jamming motion for n ≥ 3 (a contact's tangential constraint
   is active while the body moves);
7. ``indeterminate`` — no certificate either way (say which, e.g. mixed stick–slip, or a
   residual within tolerance of a boundary).

Every program is solved on the wrench scaled to unit ``M⁻¹``-norm, so verdicts do not depend
on the wrench's magnitude (1e-6 N and 1e6 N give the same answer in a gravity-free scene) and
tolerances are relative. The margin reported is the least ``M⁻¹``-weighted residual of static
balance, ``min_f ‖w_e + Jᵀ f‖_{M⁻¹}`` over the cones, in the wrench's own units
([N/√kg] = [√kg·m/s²]): 0 when balanced, else the size of the smallest acceleration the wrench
can cause, weighted by the mass matrix.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal, get_args

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fixplan.aot import kernel
from fixplan.errors import InputError
from fixplan.jamming.backends import BACKENDS, ClarabelProgram, ConeSolution
from fixplan.jamming.programs import ProgramBuilder, force_cone_violation, into_cones
from fixplan.jamming.sliding import WitnessSearch
from fixplan.kinematics import ContactSet
from fixplan.nnls import nnls
from fixplan.settings import DEFAULT as DEFAULT_SETTINGS
from fixplan.settings import DEFAULT_TOLERANCES as DEFAULT
from fixplan.settings import Tolerances, WitnessSettings

_nnls_kernel = kernel("fixplan.jamming._classify_kernels", "nnls")

FloatArray = NDArray[np.float64]

Mode = Literal["held", "jammed", "separates", "slides", "pivots", "rolls", "indeterminate"]
MODES: tuple[Mode, ...] = get_args(Mode)  # in this order (the interactive protocol sends the index)


def _finite_or_none(x: float | None) -> float | None:
    """``x`` as a float, or None when it is unknown (None) or undefined (NaN, infinite)."""
    if x is None:
        return None
    x = float(x)
    return x if np.isfinite(x) else None


@dataclass(frozen=True)
class Classification:
    """What one wrench does: the mode, the balance residual, the contact forces and how it was decided.

    ``balance_residual`` is the least ``M⁻¹``-weighted static-balance residual ``‖L⁻¹(w + Jᵀλ)‖``
    [N/√kg] (0 when balanced; NaN when a program failed). It was called ``margin``; that name
    stays as a read-only alias and as the JSON key ``"margin"``. Not to be confused with a
    search's ``margin_N`` (least normal force [N]) or ``friction_margin`` (relative friction δ).
    """

    wrench: tuple[float, ...]  # applied wrench as given (about the body origin or ``at``)
    mode: Mode
    balance_residual: float  # [N/√kg] least M⁻¹-weighted static-balance residual; 0 when balanced
    contact_forces: dict[str, FloatArray]  # λ_i in the contact frame (n, t1, t2[, spin])
    certificate: str  # which program decided
    reason: str  # one line for a person
    solve_time_s: float
    acceleration: FloatArray | None = None  # centre-of-mass twist rate, world axes (moving modes)
    residuals: dict[str, float | None] = field(default_factory=dict)  # None: not measured
    contact_frames: dict[str, FloatArray] = field(default_factory=dict)  # rows n, t1[, t2] (world)
    # a locator with several contacts (a tip in a mesh part's concave corner): its contacts' names
    # in ``contact_forces``; empty when every locator has one contact (the JSON key is then absent)
    locators: dict[str, list[str]] = field(default_factory=dict)

    @property
    def margin(self) -> float:
        """Deprecated alias of :attr:`balance_residual` [N/√kg] (the JSON key stays ``"margin"``)."""
        return self.balance_residual

    @property
    def balanced(self) -> bool:
        return self.mode in ("held", "jammed")

    def force_world(self, name: str) -> FloatArray:
        """The contact force on the workpiece at contact ``name``, world axes [N]."""
        lam = self.contact_forces[name]
        frame = self.contact_frames[name]
        d = frame.shape[1]
        return frame[:d].T @ lam[:d] if d == 2 else frame.T @ lam[:3]

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dictionary; an undefined number (NaN) is ``None``, never NaN or Infinity."""
        # plain Python floats through tolist(): one conversion per array, not per number (the
        # CLI's --json builds one of these per wrench)
        forces = {}
        for name, lam in self.contact_forces.items():
            frame = self.contact_frames[name]
            nt = 1 if frame.shape[1] == 2 else 2
            values = lam.tolist()
            entry: dict[str, Any] = {"normal": values[0], "tangential": values[1 : 1 + nt]}
            if len(values) == 4:
                entry["spin"] = values[3]
            entry["force_world"] = self.force_world(name).tolist()
            forces[name] = entry
        return {
            "wrench": list(self.wrench),
            "mode": self.mode,
            "margin": _finite_or_none(self.balance_residual),  # None: undefined (a program failed; see reason)
            "contact_forces": forces,
            "certificate": self.certificate,
            "reason": self.reason,
            "acceleration": None if self.acceleration is None else self.acceleration.tolist(),
            "residuals": {k: _finite_or_none(v) for k, v in self.residuals.items()},
            "solve_time_s": float(self.solve_time_s),
        } | ({"locators": {k: list(v) for k, v in self.locators.items()}} if self.locators else {})

    def locator_force_world(self, locator: str) -> FloatArray:
        """The total force of a locator on the workpiece, every one of its contacts together, world axes [N]."""
        names = self.locators.get(locator, [locator])
        return np.sum([self.force_world(n) for n in names], axis=0)


class Classifier:
    """Classifies many wrenches for one contact set; programs are built once and reused."""

    def __init__(
        self,
        cs: ContactSet,
        gravity_wrench: ArrayLike,
        *,
        tolerances: Tolerances = DEFAULT,
        backend: str = "clarabel",
        witness: WitnessSettings = DEFAULT_SETTINGS.witness,
    ):
        """``tolerances`` say what balanced and slipping mean, ``witness`` when a motion witness is accepted."""
        if backend not in BACKENDS:
            raise InputError(f"unknown backend {backend!r} (expected one of: {', '.join(BACKENDS)})")
        if len(cs) == 0:
            raise InputError("no contacts to analyse (the workpiece touches no locator here; name contacts explicitly)")
        self.cs = cs
        self.gravity = np.asarray(gravity_wrench, dtype=float)
        self.tol = tolerances
        self.backend = backend
        self.builder = ProgramBuilder(cs)
        b = self.builder
        self._normal_matrix = np.ascontiguousarray(b.C @ cs.G.T)  # NNLS: min ‖C(w + Gᵀ f_n)‖, f_n ≥ 0
        A = self._normal_matrix  # fixplan.nnls's default dual tolerance, once
        self._nnls_tol = 10.0 * np.finfo(float).eps * max(A.shape) * max(float(np.abs(A).sum(axis=0).max()), 1.0)
        # the programs' projectors, each built on first use: a wrench classified "held" needs none,
        # a moving one (the search's check) only "balance" (an SVD and a QR saved per contact set)
        self._projectors: dict[str, FloatArray] = {}
        self._programs: dict[str, ClarabelProgram] = {}
        self._witness = WitnessSearch(
            cs,
            b.C,
            b.N_maintain,
            slip_rel=tolerances.slip_rel,
            res_tol=max(tolerances.balance_rel * witness.residual_fraction, 1e-12),
            settings=witness,
        )
        self.frames = {c.name: np.vstack([c.normal_world, c.tangents_world]) for c in cs.contacts}
        self._names = cs.names
        self._locators = cs.per_locator() if cs.several else {}
        self._sizes = [int(k) for k in cs.sizes]
        self._offsets = [int(o) for o in cs.offsets]
        self._loaded: dict[tuple[int, ...], Classifier] = {}  # the loaded contacts' classifiers (see _wedging)

    def _wedging(self, f_n: FloatArray, wrench_com: FloatArray) -> tuple[list[str], Mode] | None:
        """The other reading of a jam that rests on forces nothing presses, or None.

        The contacts the push and gravity press are those the normal-force fit of step 1 loads
        (``f_n > 0``). When a static balance exists but the others carry normal force in it, the
        balance rests on internal (wedging) forces — a rigid body's indeterminacy: a 5 kg block
        pushed along its side locators by 10 N (μ m g = 9.81 N) "balanced" with 0.7 N and 1.2 N on
        the side locators. The same wrench is then classified on the loaded contacts alone; if
        that does not jam, both readings are returned: the contacts left unloaded and the mode of
        the push without them (the mode stays ``jammed``: the planner avoids such pushes, a
        preloaded part may wedge).
        """
        k = len(self.cs)
        if k < 2:
            return None
        big = float(np.max(f_n, initial=0.0))
        loaded = tuple(i for i in range(k) if f_n[i] > DEFAULT_SETTINGS.numerics.zero_rel * max(big, 1.0))
        if not loaded or len(loaded) == k:
            return None
        other = self._loaded_classifier(loaded).classify(wrench_com).mode
        if other in ("jammed", "held"):
            return None
        return [self._names[i] for i in range(k) if i not in loaded], other

    def _loaded_classifier(self, loaded: tuple[int, ...]) -> Classifier:
        """The classifier of the contacts ``loaded`` (indices into this set), built once."""
        sub = self._loaded.get(loaded)
        if sub is None:
            cs = self.cs
            sub_cs = ContactSet(
                tuple(cs.contacts[i] for i in loaded), cs.com_world, cs.mass_matrix, cs.body_origin_world
            )
            sub = Classifier(
                sub_cs, self.gravity, tolerances=self.tol, backend=self.backend, witness=self._witness.settings
            )
            self._loaded[loaded] = sub
        return sub

    # -- programs ------------------------------------------------------------------------------
    def _projector(self, kind: str) -> FloatArray:
        """The projector of program ``kind``: identity for "balance", else off the kept or rolling motions."""
        P = self._projectors.get(kind)
        if P is None:
            b = self.builder
            P = b.projector({"balance": None, "maintain": b.N_maintain, "roll": b.N_roll}[kind])
            self._projectors[kind] = P
        return P

    def _solve(self, kind: str, w_hat: FloatArray) -> tuple[ConeSolution, FloatArray]:
        """Least residual of program ``kind`` for ŵ; returns the solution and the full λ, in the cones.

        The backend's forces are checked in the mechanics' own terms and moved into the cones
        (:func:`~fixplan.jamming.programs.into_cones`: a negative normal force is never part of a
        balance), and the solution's ``cone_violation`` is the violation of the forces the
        backend returned, in those terms. The caller recomputes the residual from the λ returned.
        """
        P = self._projector(kind)
        if self.backend == "cvxpy":
            from fixplan.jamming.cvx import least_residual

            sol, lam = least_residual(self.cs, w_hat, P, self.builder.C, eps=self.tol.cone_eps)
        else:
            prog = self._programs.get(kind)
            if prog is None:
                prog = ClarabelProgram(self.builder.residual_program(kind, P), eps=self.tol.cone_eps)
                self._programs[kind] = prog
            sol = prog.solve(self.builder.rhs(prog.program, P, w_hat))
            lam = self.builder.layout.S @ sol.x[: prog.program.nf]
        if not sol.solved:
            return sol, lam
        violation = force_cone_violation(self.cs, lam)
        return replace(sol, cone_violation=max(violation, sol.cone_violation or 0.0)), into_cones(self.cs, lam)

    def _residual_of(self, kind: str, w_hat: FloatArray, lam: FloatArray) -> float:
        """The program's value recomputed from the forces (never trust a solver's own number)."""
        P = self._projector(kind)
        return float(np.linalg.norm(P @ self.builder.C @ (w_hat + self.cs.J.T @ lam)))

    # -- the verdict ---------------------------------------------------------------------------
    def classify(self, wrench_com: ArrayLike, wrench_given: ArrayLike | None = None) -> Classification:
        """Classify the applied wrench ``wrench_com`` (about the centre of mass, world axes)."""
        t0 = time.perf_counter()
        cs, tol = self.cs, self.tol
        w_applied = np.asarray(wrench_com, dtype=float)
        given = tuple(float(x) for x in (w_applied if wrench_given is None else np.asarray(wrench_given, dtype=float)))
        w_e = w_applied + self.gravity
        scale = self.builder.m_inv_norm(w_e)
        names, sizes, offsets = self._names, self._sizes, self._offsets

        def result(
            mode: Mode,
            balance_residual: float,
            lam: FloatArray | None,
            certificate: str,
            reason: str,
            accel: FloatArray | None = None,
            **res: float | None,
        ) -> Classification:
            if lam is None:
                forces = {n: np.zeros(k) for n, k in zip(names, sizes, strict=True)}
            else:
                forces = {n: lam[o : o + k] * scale for n, o, k in zip(names, offsets, sizes, strict=True)}
            return Classification(
                given,
                mode,
                balance_residual,
                forces,
                certificate,
                reason,
                time.perf_counter() - t0,
                accel,
                dict(res),
                self.frames,
                self._locators,
            )

        if not np.all(np.isfinite(w_e)):
            raise InputError(f"wrench has non-finite components: {list(given)}")
        if scale == 0.0:
            return result("held", 0.0, None, "zero-wrench", "no net wrench: nothing to balance")
        w_hat = w_e / scale

        # 1. held: normal forces alone (NNLS on the M⁻¹-weighted residual)
        rhs = -(self.builder.C @ w_hat)
        f_n, normal_res, ok = _nnls_kernel(self._normal_matrix, rhs, 50 * len(cs) + 50, self._nnls_tol)
        if not ok:  # the compiled QR met dependent columns: the NumPy version (SVD least squares)
            f_n, normal_res = nnls(self._normal_matrix, rhs, maxiter=50 * len(cs) + 50)
        if normal_res <= tol.balance_rel:
            lam = np.zeros(cs.J.shape[0])
            lam[cs.offsets] = f_n
            return result(
                "held",
                normal_res * scale,
                lam,
                "normal-balance",
                "normal forces alone balance the wrench",
                normal_balance=normal_res,
            )

        # 2. jammed: static balance with friction
        sol, lam = self._solve("balance", w_hat)
        margin = self._residual_of("balance", w_hat, lam) if sol.solved else float("nan")
        residuals: dict[str, Any] = {
            "normal_balance": normal_res,
            "balance": margin,
            "cone_violation": sol.cone_violation,
        }
        if not sol.solved:
            return result(
                "indeterminate",
                float("nan"),
                None,
                "none",
                f"static-balance program failed ({sol.status})",
                **residuals,
            )
        if margin <= tol.balance_rel:
            wedged = self._wedging(f_n, w_applied)
            if wedged is not None:
                unloaded, other = wedged
                return result(
                    "jammed",
                    margin * scale,
                    lam,
                    "wedging",
                    f"balanced only with friction and with normal forces at {', '.join(unloaded)} that the push and "
                    f"gravity do not press (internal, wedging forces of a rigid body: indeterminate); with "
                    f"{'it' if len(unloaded) == 1 else 'them'} unloaded the push {other}",
                    **residuals,
                )
            return result(
                "jammed",
                margin * scale,
                lam,
                "static-balance",
                "balanced, but only with friction: the push jams",
                **residuals,
            )
        lam_balance = lam

        # 3. slides (Theorem 1's witness), else pivots (some contacts stick, the rest slide).
        #    A witness proves a kept-contact motion exists, so it needs no maintained-motion program.
        witness = None
        if self.builder.N_maintain.shape[1] > 0:
            witness = self._witness.kept(w_hat)
        if witness is not None:
            residuals["motion"] = witness.residual
            accel = witness.acceleration * scale
            if len(witness.sticking) == len(cs):
                return result(
                    "rolls",
                    margin * scale,
                    witness.forces,
                    "rolling",
                    "the contacts are kept without slip while the body turns",
                    accel,
                    **residuals,
                )
            if not witness.sticking:
                idle = (
                    " ("
                    + ", ".join(names[i] for i in witness.idle)
                    + " on the motion's axis: kept with neither slip nor force)"
                    if witness.idle
                    else ""
                )
                return result(
                    "slides",
                    margin * scale,
                    witness.forces,
                    "sliding-witness",
                    "every contact is kept and slides (Theorem 1)" + idle,
                    accel,
                    **residuals,
                )
            stuck = ", ".join(names[i] for i in witness.sticking)
            return result(
                "pivots",
                margin * scale,
                witness.forces,
                "pivot-witness",
                f"every contact is kept; {stuck} sticks while the others slide: the body turns about it",
                accel,
                **residuals,
            )

        # 4. separates: no motion keeps every contact
        if self.builder.N_maintain.shape[1] == 0:
            maintain = margin  # G has full column rank: keeping every contact means rest
        else:
            sol_m, lam_m = self._solve("maintain", w_hat)
            maintain = self._residual_of("maintain", w_hat, lam_m) if sol_m.solved else float("nan")
            if not sol_m.solved:
                return result(
                    "indeterminate",
                    margin * scale,
                    lam_balance,
                    "none",
                    f"maintained-motion program failed ({sol_m.status})",
                    **residuals,
                )
        residuals["maintain"] = maintain
        if maintain > tol.balance_rel:
            return result(
                "separates",
                margin * scale,
                lam_balance,
                "no-maintained-motion",
                "no forces in the cones keep every contact: some contact opens",
                **residuals,
            )

        # 5. rolls: a motion with no slip at any contact
        if self.builder.N_roll.shape[1] > 0:
            sol_r, lam_r = self._solve("roll", w_hat)
            roll = self._residual_of("roll", w_hat, lam_r) if sol_r.solved else float("nan")
            residuals["roll"] = roll
            if sol_r.solved and roll <= tol.balance_rel:
                accel = cs.M_inv @ (w_hat + cs.J.T @ lam_r) * scale
                return result(
                    "rolls",
                    margin * scale,
                    lam_r,
                    "rolling",
                    "the contacts are kept without slip while the body turns",
                    accel,
                    **residuals,
                )

        # 6. separates after all: a motion that opens some contacts, consistent with every law
        opening = self._witness.opening(w_hat)
        if opening is not None:
            residuals["motion"] = opening.residual
            opened = ", ".join(names[i] for i in opening.opened)
            return result(
                "separates",
                margin * scale,
                opening.forces,
                "opening-witness",
                f"{opened} {'opens' if len(opening.opened) == 1 else 'open'} while the other contacts slide or stick: "
                "a motion consistent with every contact law (none keeping every contact was found)",
                opening.acceleration * scale,
                **residuals,
            )

        near = (
            " (static-balance residual within 100× tolerance: near a boundary)"
            if margin <= 100 * tol.balance_rel
            else ""
        )
        return result(
            "indeterminate",
            margin * scale,
            lam_balance,
            "none",
            "the body moves keeping its contacts, but no sliding, pivoting or rolling motion was found" + near,
            **residuals,
        )


def wrench_array(wrenches: ArrayLike | Sequence[Sequence[float]], ndof: int) -> FloatArray:
    """Wrenches as an (N, ndof) array, with a clear error for the wrong shape."""
    try:
        W = np.asarray(wrenches, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"wrenches must be numbers ({exc})") from None
    if W.ndim == 1:
        W = W[None, :]
    if W.ndim != 2 or W.shape[1] != ndof:
        what = "Fx,Fy,Fz,Tx,Ty,Tz" if ndof == 6 else "Fx,Fy,Mz"
        raise InputError(f"expected wrenches of {ndof} numbers ({what}), got shape {W.shape}")
    if not np.all(np.isfinite(W)):
        raise InputError("wrenches must be finite numbers")
    return W
