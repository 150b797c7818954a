"""The ``auto`` contact solver: stages that hand over on stagnation, within one time limit.

Stages, in order, each started from the best iterate so far (lowest FCLib residual):

1. **nsgs** — compiled nonsmooth Gauss–Seidel (cheap sweeps; solves most problems alone);
2. **socp** — the SOCP fixed point on the friction offset ``s = μ‖u_t‖`` (Clarabel, no NSGS
   polish: the next stage polishes), which escapes where NSGS crawls on redundant contacts;
3. **nsn** — nonsmooth (semismooth) Newton on the natural map with a line search
   (:mod:`fixplan.engine.newton`): quadratic convergence from a good start;
4. **prox** — the proximal point method with Newton inner solves, for singular ``W`` where
   plain Newton stalls.

A stage ends when it converges, when its iteration cap is reached, when its share of the time
left is spent, or when it *stalls*: its best residual gained less than 10 % over a window
(:data:`STAGES` gives the windows and shares). Then the next stage starts; a stage that
converges ends the solve. The answer is the best iterate of all stages, never the last one;
``extras["stages"]`` records, for every stage, its method, iterations, best residual, time and
why it ended.

``max_iter`` (when given) caps the iterations of *every* stage: sweeps, SOCP rounds, Newton
steps, proximal rounds. ``time_limit`` bounds the whole solve (default 60 s); each stage gets a
share of the time left when it starts (the last one all of it), and the time limit is checked
inside every stage (see :mod:`fixplan.engine.budget`).

Why this order (measured on the 33 shared FCLib problems and 16 more of Siconos' test
problems, see ``benchmarks/bench_fclib.py``): NSGS alone reaches 1e-8 on 43 of 49, in
microseconds to a second when it does; where it stalls the SOCP fixed point costs a few
interior-point solves and unlocks redundant stacks (BoxesStack1: 2.6e-5 → 8.7e-9); Newton from
the best iterate then converges in 2–25 steps on all but the singular cases, which PROX solves.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from fixplan.engine.budget import DEFAULT_TIME_LIMIT_S, Budget, check_time_limit
from fixplan.engine.nsgs import error_kernel
from fixplan.engine.problem import (
    DEFAULT_TOL,
    ContactProblem,
    ContactSolution,
    ContactSolver,
    check_settings,
    initial_scaled,
    kernel_arrays,
)


@dataclass(frozen=True)
class StagePlan:
    """One stage of :func:`solve_auto`.

    Attributes
    ----------
    method : str
        ``"nsgs"``, ``"socp"``, ``"nsn"`` or ``"prox"``.
    share : float
        Fraction of the time left at the stage's start that it may use.
    stall_window : int
        Iterations over which a 10 % gain is required.
    max_iter : int
        Iteration cap when the caller gives none.
    """

    method: str
    share: float
    stall_window: int
    max_iter: int


STAGES: tuple[StagePlan, ...] = (
    StagePlan("nsgs", 0.05, 200, 100_000),
    StagePlan("socp", 0.15, 3, 30),
    StagePlan("nsn", 0.3, 12, 100),
    StagePlan("prox", 1.0, 30, 200),
)
"""The stages of ``auto`` (NSGS gets 5 % of the time: 3 s of the default 60 s).

PROX's window is 30 rounds, not 12: on the 2 020-contact granular flow of Siconos' tests it
lingers at 2.8e-7 for about 14 rounds, then converges (1.9e-9 after 20 rounds); with a
12-round window it was stopped just before."""


@dataclass(frozen=True)
class StageRecord:
    """What one stage did.

    Attributes
    ----------
    method : str
        The stage's solver.
    iterations : int
        Its iterations (sweeps, rounds or steps).
    start_error, error : float
        Best FCLib residual before and after the stage.
    time_s : float
        Its wall time [s].
    status : str
        Why it ended (``converged``, ``stalled: ...``, ``max_iter ...``, ``time limit ...``).
    """

    method: str
    iterations: int
    start_error: float
    error: float
    time_s: float
    status: str

    def as_dict(self) -> dict[str, Any]:
        """Plain form for JSON and ``extras``."""
        return {
            "method": self.method,
            "iterations": self.iterations,
            "start_error": self.start_error,
            "error": self.error,
            "time_s": self.time_s,
            "status": self.status,
        }


def _run_stage(
    plan: StagePlan,
    problem: ContactProblem,
    r0: np.ndarray,
    tol: float,
    max_iter: int,
    limit: float | None,
    step_s: float = 0.0,
) -> ContactSolution:
    if plan.method == "nsgs":
        from fixplan.engine.nsgs import solve_nsgs

        return solve_nsgs(problem, r0=r0, tol=tol, max_iter=max_iter, time_limit=limit, stall_window=plan.stall_window)
    if plan.method == "socp":
        from fixplan.engine.socp import solve_socp

        return solve_socp(
            problem,
            r0=r0,
            tol=tol,
            max_iter=max_iter,
            polish_sweeps=0,
            time_limit=limit,
            stall_window=plan.stall_window,
        )
    from fixplan.engine.newton import solve_newton, solve_prox

    solve = solve_newton if plan.method == "nsn" else solve_prox
    return solve(
        problem, r0=r0, tol=tol, max_iter=max_iter, time_limit=limit, stall_window=plan.stall_window, step_s=step_s
    )


def immobile_contact_violation(problem: ContactProblem) -> str | None:
    """Why the problem has no solution, when a contact cannot move and its free velocity breaks the law.

    A contact whose rows of ``W`` are all zero keeps ``u_j = q_j`` whatever the impulses. Then
    ``r_j = 0`` is its only hope, which needs ``q_j`` in the dual cone
    (``q_n ≥ μ ‖q_t‖``). Otherwise no ``r`` solves the problem, yet the FCLib residual,
    relative to ``‖r‖``, can be driven towards 0 by letting ``r_j`` grow without bound: this
    check refuses that made-up convergence up front.

    Parameters
    ----------
    problem : ContactProblem
        The problem.

    Returns
    -------
    str or None
        The reason, or ``None`` when no immobile contact is violated.
    """
    W, q = problem.scaled()
    row_norm = np.asarray(abs(W).sum(axis=1)).reshape(-1)
    for j in range(problem.n_contacts):
        o, d = int(problem.offsets[j]), int(problem.dims[j])
        if np.any(row_norm[o : o + d] > 0):
            continue
        qn, qt = float(q[o]), float(np.linalg.norm(q[o + 1 : o + d]))
        if qn < float(problem.mu[j]) * qt:
            return (
                f"no solution: contact {j} cannot move (its rows of W are zero) and its free velocity "
                f"breaks the contact law (q_n = {qn:.3g} < μ‖q_t‖ = {float(problem.mu[j]) * qt:.3g})"
            )
    return None


RUNAWAY_RATIO = 1e6
"""An answer with ``‖r‖ · W_nn > RUNAWAY_RATIO · ‖q‖`` is a runaway, not a solution.

``‖q‖ / W_nn`` (median positive normal diagonal entry of ``W``) is the natural scale of the impulses;
on the 49 FCLib/Siconos problems of the benchmark the solutions have ``‖r‖ W_nn / ‖q‖ ≤ 11``."""


def runaway_reason(problem: ContactProblem, reaction: np.ndarray) -> str | None:
    """Why ``reaction`` is not a credible answer although its relative residual may be small.

    The FCLib residual is relative to ``max(‖q‖, ‖r‖, ‖u‖)``: on a singular or indefinite
    ``W`` a solver can let ``r`` grow along a direction that ``W`` does not resist and the
    residual shrinks like ``1/‖r‖`` without any solution nearby.

    Parameters
    ----------
    problem : ContactProblem
        The problem.
    reaction : ndarray
        The answer.

    Returns
    -------
    str or None
        The reason when ``‖r‖`` exceeds :data:`RUNAWAY_RATIO` times its natural scale.
    """
    d = problem.W.diagonal()
    positive = d[problem.offsets][d[problem.offsets] > 0] if problem.n_contacts else d[:0]
    if not positive.size:  # no normal mobility at all: the tangential diagonal sets the scale
        positive = d[d > 0]
    if not positive.size:
        return None
    scale = float(np.median(positive))
    r_norm = float(np.linalg.norm(reaction))
    q_norm = float(np.linalg.norm(problem.q))
    if r_norm * scale > RUNAWAY_RATIO * max(q_norm, np.finfo(float).tiny):
        return (
            f"the impulses ran away (‖r‖ = {r_norm:.3g}, over {RUNAWAY_RATIO:.0e} × the scale ‖q‖/W_nn = "
            f"{q_norm / scale:.3g}): W is singular or indefinite along them and the small relative residual "
            "is no evidence of a solution"
        )
    return None


def solve_auto(
    problem: ContactProblem,
    r0: Any = None,
    tol: float = DEFAULT_TOL,
    max_iter: int | None = None,
    time_limit: float | None = DEFAULT_TIME_LIMIT_S,
    stages: tuple[StagePlan, ...] = STAGES,
) -> ContactSolution:
    """Solve ``u = W r + q`` with the contact laws by NSGS → SOCP → NSN → PROX on stagnation.

    A :class:`~fixplan.engine.problem.ContactSolver` (the shared parameters are documented
    there): ``r0`` starts the first stage; ``max_iter`` caps the iterations of every stage
    (each stage's own default when ``None``); ``time_limit`` bounds the whole solve (default
    60 s). The answer is the best iterate of all stages: ``solver`` is
    ``"auto(" + "+".join(stages run) + ")"`` (``"auto(nsgs)"`` when NSGS sufficed);
    ``iterations`` sums the stages' iterations; ``extras["stages"]`` has one
    :meth:`StageRecord.as_dict` per stage run and ``extras["reason"]`` says why the solve ended
    unconverged (no stage runs when :func:`immobile_contact_violation` finds the problem
    unsolvable; an answer that :func:`runaway_reason` rejects is not converged whatever its
    residual).

    Parameters
    ----------
    stages : tuple of StagePlan
        The stages (default :data:`STAGES`).
    """
    check_settings(tol, 0 if max_iter is None else max_iter, 1.0)
    check_time_limit(time_limit)
    budget = Budget.start(time_limit)
    t0 = time.perf_counter()
    arrays = kernel_arrays(problem)
    r_scaled = initial_scaled(problem, r0)
    best_error = error_kernel(*arrays, r_scaled, np.empty(problem.size))  # type: ignore[call-arg]  # numba dispatcher
    best_error = best_error if math.isfinite(best_error) else math.inf
    best_r = problem.row_scale * r_scaled
    best: ContactSolution | None = None
    records: list[StageRecord] = []
    impossible = immobile_contact_violation(problem)
    step_s = 0.0  # a Newton step's duration, once a Newton stage has timed one (PROX starts no step that cannot end)
    for k, plan in enumerate(() if impossible else stages):
        if best_error <= tol and records:
            break
        if budget.expired():
            break
        share = 1.0 if k == len(stages) - 1 else plan.share
        limit = budget.share(share).limit_s()
        t_stage = time.perf_counter()
        sol = _run_stage(
            plan, problem, best_r, tol, plan.max_iter if max_iter is None else int(max_iter), limit, step_s
        )
        step_s = float(sol.extras.get("step_s", step_s)) or step_s
        records.append(
            StageRecord(
                plan.method,
                int(sol.iterations),
                float(best_error),
                float(min(sol.error, best_error)),
                time.perf_counter() - t_stage,
                str(sol.extras.get("status", "")),
            )
        )
        if best is None or sol.error < best_error:
            best, best_error, best_r = sol, float(sol.error), np.asarray(sol.reaction)
        if sol.converged:
            break
    if best is None:  # time limit ≤ 0 cannot happen (checked); keep the start for safety
        from fixplan.engine.nsgs import solve_nsgs

        best = solve_nsgs(problem, r0=r0, tol=tol, max_iter=0)
    runaway = runaway_reason(problem, np.asarray(best.reaction))
    converged = best.error <= tol and runaway is None
    extras = dict(best.extras)
    extras["stages"] = [rec.as_dict() for rec in records]
    extras["tol"] = float(tol)
    extras["max_iter"] = max_iter
    extras["time_limit"] = time_limit
    extras["best_stage"] = best.solver
    if converged:
        extras["status"] = "converged"
        extras.pop("reason", None)
    else:
        if impossible:
            why = impossible
        elif runaway:
            why = runaway
        elif budget.expired():
            why = f"time limit reached after {time.perf_counter() - t0:.3g} s"
        elif len(records) == len(stages):
            why = "every stage stopped (" + ", ".join(f"{r.method}: {r.status}" for r in records) + ")"
        else:
            why = "stopped"
        extras["status"] = why
        extras["reason"] = f"{why}; best error {best.error:.3g}, tol {tol:g} (from {best.solver})"
    return replace(
        best,
        solver="auto(" + "+".join(rec.method for rec in records) + ")",
        iterations=sum(rec.iterations for rec in records),
        converged=converged,
        time_s=time.perf_counter() - t0,
        extras=extras,
    )


if TYPE_CHECKING:  # the registry's one signature (engine.SOLVERS), checked by mypy
    _SOLVERS: tuple[ContactSolver, ...] = (solve_auto,)
