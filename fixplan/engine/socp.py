"""Robust contact solver: successive SOCPs (Clarabel) alternated with NSGS polishing.

For problems where NSGS stalls (rank-deficient ``W`` from redundant contacts, tall stacks,
large mass ratios) this solver reaches the tolerance; ``solver="auto"``
(:mod:`fixplan.engine.auto`) runs its pure fixed point (no polish) as the stage after NSGS.

Method
------
With the friction "offset" ``s_j = μ_j ‖u_t,j‖`` frozen, the contact law
``K ∋ r ⊥ W r + q + s ∈ K*`` is exactly the optimality condition of the convex cone program
(Acary, Cadoux, Lemaréchal, Malick, ZAMM 2011; the "De Saxcé" fixed point)::

    minimize  ½ rᵀ W_sym r + (q + s)ᵀ r   subject to  r_j ∈ K_μj (second-order cones),

solved by Clarabel's interior point method, which is indifferent to a rank-deficient ``W``.
Updating ``s`` from the new ``u`` and solving again is a fixed-point iteration on ``s``. Each
round is one SOCP then a short NSGS polish (``polish_sweeps`` sweeps) from the current ``r``:
NSGS converges fast close to the solution, and when it stalls the next SOCP restarts from its
result. The iteration is monotone: an SOCP iterate is kept only if it lowers the residual, and
when it does not, the polish budget of the following rounds is multiplied by 4 (up to
``MAX_POLISH_SWEEPS``: the uncapped growth once ran for minutes). ``max_iter`` caps the
rounds, ``time_limit`` the wall time (Clarabel's own limit, and checks between rounds and
between chunks of polishing sweeps); the best iterate is returned.
``W_sym = (W + Wᵀ)/2``: a non-symmetric ``W`` (one FCLib file has a relative asymmetry of
1.3e-3) only slows the fixed point; the NSGS polish and the residual use the true ``W``.
Cones are exact (``μ = 0``: ``r_n ≥ 0``, ``r_t = 0``); soft-finger contacts are solved in the
scaled variables of :mod:`fixplan.engine.problem`. No cone is linearized.

Why this solver (measured, 2-core x86-64, numba 0.68, Clarabel 0.11, tol 1e-8)
-------------------------------------------------------------------------------
Candidates were prototyped and run on 24 synthetic box stacks (3 or 8 boxes, 4 corner
contacts per interface, so ``W`` has rank 18/36 and 48/96; mass ratio 1 or 10 between
boxes; μ ∈ {0.3, 1}; resting, pushed, and moving) and on the four FCLib files:

=============================  ==========  ========  ======================================
method                         stacks      FCLib     notes
=============================  ==========  ========  ======================================
NSGS (cap 20 000 sweeps)       18/24       4/4       fails on all six 8-box ratio-10 stacks
                                                     (error stuck at 5e-6 .. 9e-5 after
                                                     20 000 sweeps, 1.4–2.6 s); ratio-10
                                                     3-box stacks need 3 000–14 000 sweeps
semismooth Newton on           0/7 (*)     1/4       Jacobian exactly singular (stick rows
Alart–Curnier, Armijo                                of a rank-deficient W); only Spheres
                                                     (full-rank W) converges, in 7 steps
Levenberg–Marquardt on AC,     9/24        1/4       λ = min(1, ‖Φ‖); fails on every ratio-10
Armijo on ½‖Φ‖²                                      stack (error 1e-4 .. 2e-1 after 100
                                                     steps, 0.3–2.7 s); FCLib: Box_Stacks only
successive SOCP + NSGS         24/24       4/4       1–30 SOCPs of 13–34 IPM iterations;
polish (this module)                                 the stuck 8-box stacks in 3–8 SOCPs,
                                                     ≤ 0.05 s
=============================  ==========  ========  ======================================

(*) on the 7 stacks of a first, smaller set. On FCLib, successive SOCP alone stagnates
(60 rounds: Box_Stacks 3e-8, Capsules 2e-5; Spheres reaches 1e-8 after 39): the fixed point on
``s`` converges linearly for μ = 0.3–0.7, and Capsules' non-symmetric ``W`` is only
approximated by ``W_sym``. A short NSGS polish from the SOCP iterate reaches 1e-8 in 2–131
sweeps (Capsules: 131 sweeps instead of 2 302 from a cold start). Per-problem timings are in
``benchmarks/bench_fclib.py``'s report.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp

from fixplan.engine.budget import Budget
from fixplan.engine.nsgs import diagonal_blocks, error_kernel, run_nsgs
from fixplan.engine.problem import (
    DEFAULT_TOL,
    ContactProblem,
    ContactSolution,
    ContactSolver,
    check_settings,
    finish,
    initial_scaled,
    kernel_arrays,
    stalled,
)
from fixplan.engine.status import STATUS_CONVERGED, STATUS_MAX_ITER, STATUS_STALLED, STATUS_TIME_LIMIT
from fixplan.errors import SolverError

DEFAULT_MAX_ROUNDS = 30
"""Default cap on SOCP rounds."""
DEFAULT_POLISH_SWEEPS = 50
"""Default NSGS sweeps after each SOCP (×4 each time an SOCP fails to improve).

Measured total time over the 4 FCLib files and 24 stacks of the module docstring (all reach
1e-8 with every setting but 20): 20 → 8.4 s (fails none, but many rounds), 50 → 1.3 s,
200 → 1.8 s, 500 → 2.2 s."""
IPM_TOL = 1e-12
"""Clarabel gap/feasibility tolerance of each SOCP (relative)."""


@dataclass(frozen=True, eq=False)
class SocpStep:
    """The cone program of one fixed-point step, built once and re-solved with new ``s``.

    ``minimize ½ r̃ᵀ P r̃ + (q̃ + s)ᵀ r̃  s.t.  A r̃ + slack = 0, slack ∈ cones``.

    Attributes
    ----------
    P : scipy.sparse.csc_matrix
        Upper triangle of ``(W̃ + W̃ᵀ)/2``.
    A : scipy.sparse.csc_matrix
        ``−diag(μ_j, 1, …)`` per contact (so that ``slack_j = (μ_j r̃_n, r̃_t) ∈ SOC``).
    cones : list
        Clarabel cones, one SOC per frictional contact; ``μ = 0``: ``r̃_n ≥ 0`` and
        ``r̃_t = 0``.
    asymmetry : float
        ``max|W̃ − W̃ᵀ| / max|W̃|`` (0 for a symmetric ``W``).
    """

    P: sp.csc_matrix
    A: sp.csc_matrix
    cones: list
    asymmetry: float


def build_socp_step(problem: ContactProblem) -> SocpStep:
    """Build the cone program of the fixed-point step (Clarabel data).

    Parameters
    ----------
    problem : ContactProblem
        The contact problem.

    Returns
    -------
    SocpStep
        Matrices and cones; ``s`` enters only the linear cost.
    """
    import clarabel  # heavy optional backend: imported when used

    Wt, _ = problem.scaled()
    Wt = sp.csr_matrix(Wt)
    asym = Wt - Wt.T
    wmax = abs(Wt).max() if Wt.nnz else 0.0
    asymmetry = float(abs(asym).max() / wmax) if (wmax and asym.nnz) else 0.0
    W_sym = (Wt + Wt.T) * 0.5
    P = sp.triu(W_sym, format="csc")
    diag = np.ones(problem.size)
    cones: list = []
    for j in range(problem.n_contacts):
        o, d, mu = int(problem.offsets[j]), int(problem.dims[j]), float(problem.mu[j])
        if mu > 0.0:
            diag[o] = mu
            cones.append(clarabel.SecondOrderConeT(d))
        else:
            cones.append(clarabel.NonnegativeConeT(1))
            cones.append(clarabel.ZeroConeT(d - 1))
    A = sp.diags(-diag, format="csc")
    return SocpStep(P=P, A=A, cones=cones, asymmetry=asymmetry)


def _settings() -> Any:
    import clarabel

    st = clarabel.DefaultSettings()
    st.verbose = False
    st.tol_gap_abs = IPM_TOL
    st.tol_gap_rel = IPM_TOL
    st.tol_feas = IPM_TOL
    st.tol_ktratio = 1e-10
    st.static_regularization_constant = 1e-10
    st.max_iter = 200
    st.max_threads = 1
    return st


def _offsets_s(u: np.ndarray, problem: ContactProblem) -> np.ndarray:
    """``s``: ``μ_j ‖ũ_t,j‖`` on normal rows, 0 elsewhere (scaled variables)."""
    s = np.zeros(problem.size)
    if problem.n_contacts == 0:
        return s
    tangential_sq = u * u
    tangential_sq[problem.offsets] = 0.0  # drop the normal rows
    s[problem.offsets] = problem.mu * np.sqrt(np.add.reduceat(tangential_sq, problem.offsets))
    return s


MAX_POLISH_SWEEPS = 20_000
"""Ceiling of the growing polish budget (``polish_sweeps · 4ᵏ``) of one round."""


@dataclass
class _ClarabelClock:
    """Keeps Clarabel within the deadline: its setup is timed, its iterations are watched.

    Clarabel checks its own ``time_limit`` only between interior-point iterations (one of a dense
    ``W`` with 900 rows takes 0.03–0.6 s on a busy machine), and its setup (scaling, ordering)
    holds the interpreter. So a setup is started only when the last one fits in the time left,
    and the iterations run in a worker thread (Clarabel releases the interpreter while it
    iterates): at the deadline the solve is abandoned, the callback stops Clarabel at its next
    iteration, and the caller goes on with its best iterate.
    """

    budget: Budget
    setup_s: float = 0.0
    abandoned: bool = False

    def setup_fits(self) -> bool:
        """Whether a new solver's setup (as long as the last one) ends before the deadline."""
        return self.budget.remaining_s() > self.setup_s

    def on_iteration(self, info: Any) -> bool:  # noqa: ARG002 - Clarabel's callback signature
        """Clarabel's termination callback: ``True`` stops the solve (once it has been abandoned)."""
        return self.abandoned or self.budget.expired()


def _clarabel_solve(
    step: SocpStep, cost: np.ndarray, settings: Any, rounds: int, err: float, clock: _ClarabelClock
) -> Any | None:
    """One SOCP; ``None`` when the deadline came first (the solve is abandoned, see :class:`_ClarabelClock`)."""
    import threading

    import clarabel

    b = np.zeros(step.A.shape[0])
    outcome: dict[str, Any] = {}
    try:
        t0 = time.perf_counter()
        solver = clarabel.DefaultSolver(step.P, cost, step.A, b, step.cones, settings)
        clock.setup_s = time.perf_counter() - t0
        set_callback = getattr(solver, "set_termination_callback", None)  # Clarabel ≥ 0.10
        if set_callback is not None:
            set_callback(clock.on_iteration)
        left = clock.budget.remaining_s()
        if math.isinf(left):
            return solver.solve()

        def iterate() -> None:
            try:
                outcome["result"] = solver.solve()
            except Exception as exc:  # noqa: BLE001 - re-raised below, as ours
                outcome["error"] = exc

        worker = threading.Thread(target=iterate, name="clarabel", daemon=True)
        worker.start()
        worker.join(timeout=left)
        if worker.is_alive():
            clock.abandoned = True
            return None
        if "error" in outcome:
            raise outcome["error"]
        return outcome["result"]
    except Exception as exc:  # noqa: BLE001 - any backend failure becomes ours
        raise SolverError(
            f"Clarabel failed in SOCP round {rounds}: {exc}",
            extras={"round": rounds, "error": err},
        ) from exc


def solve_socp(
    problem: ContactProblem,
    r0: Any = None,
    tol: float = DEFAULT_TOL,
    max_iter: int = DEFAULT_MAX_ROUNDS,
    polish_sweeps: int = DEFAULT_POLISH_SWEEPS,
    time_limit: float | None = None,
    stall_window: int | None = None,
) -> ContactSolution:
    """Solve ``u = W r + q`` with the contact laws by successive SOCPs and NSGS polishing.

    A :class:`~fixplan.engine.problem.ContactSolver` (the shared parameters are documented
    there): the first ``s`` is computed from ``u = W r0 + q``; ``max_iter`` caps rounds (one
    SOCP + a polish of at most :data:`MAX_POLISH_SWEEPS` sweeps each), which ``iterations`` and
    ``stall_window`` count; ``time_limit`` is passed to Clarabel and checked before every SOCP
    and between chunks of polishing sweeps. ``extras`` holds ``ipm_iterations``,
    ``nsgs_sweeps``, ``history`` (error after each SOCP and after each polish) and
    ``asymmetry``.

    Parameters
    ----------
    polish_sweeps : int
        NSGS sweeps after each SOCP that did not reach ``tol`` (0: pure fixed point); ×4 each
        time an SOCP fails to improve, up to :data:`MAX_POLISH_SWEEPS`.

    Raises
    ------
    SolverError
        When Clarabel itself raises (the message and the round are in ``extras``).
    """
    check_settings(tol, max_iter, 1.0)
    if polish_sweeps < 0:
        raise SolverError(f"expected polish_sweeps ≥ 0, got {polish_sweeps}")
    budget = Budget.start(time_limit)
    t0 = time.perf_counter()
    arrays = kernel_arrays(problem)
    r = initial_scaled(problem, r0)
    u = np.empty(problem.size)
    err = error_kernel(*arrays, r, u)  # type: ignore[call-arg]  # numba dispatcher
    if not math.isfinite(err):
        err = math.inf
    step = build_socp_step(problem)
    settings = _settings()
    diag = diagonal_blocks(*arrays[:3], arrays[5], arrays[6])  # type: ignore[call-arg]  # numba dispatcher
    history: list[float] = []
    steps: list[str] = []
    ipm_total = 0
    sweeps_total = 0
    ipm_status: list[str] = []
    status = STATUS_CONVERGED if err <= tol else STATUS_MAX_ITER
    rounds = 0
    polish = int(polish_sweeps)
    marks = [err]
    clock = _ClarabelClock(budget)
    while status != STATUS_CONVERGED and rounds < max_iter:
        if budget.expired() or not clock.setup_fits():
            status = STATUS_TIME_LIMIT
            break
        rounds += 1
        limit = budget.limit_s()
        settings.time_limit = math.inf if limit is None else limit
        result = _clarabel_solve(step, arrays[3] + _offsets_s(u, problem), settings, rounds, err, clock)
        if result is None:  # abandoned at the deadline
            status = STATUS_TIME_LIMIT
            break
        ipm_total += int(result.iterations)
        ipm_status.append(str(result.status))
        x = np.asarray(result.x, dtype=float)
        err_new = math.inf
        if x.shape == r.shape and np.all(np.isfinite(x)):
            u_new = np.empty_like(u)
            err_new = error_kernel(*arrays, x, u_new)  # type: ignore[call-arg]  # numba dispatcher
            history.append(err_new)
            steps.append("socp")
        if err_new < err:
            r, u, err = x, u_new, err_new
        else:
            # the fixed point does not improve on the polished iterate: polish longer
            polish = min(4 * polish, MAX_POLISH_SWEEPS)
        if err <= tol:
            status = STATUS_CONVERGED
            break
        if polish and not budget.expired():
            run = run_nsgs(arrays, r.copy(), err, tol, polish, 1.0, budget, diag=diag)
            sweeps_total += run.iterations
            if run.best_err < err:
                r = run.best_r
                err = error_kernel(*arrays, r, u)  # type: ignore[call-arg]  # numba dispatcher
            history.append(err)
            steps.append("nsgs")
            if err <= tol:
                status = STATUS_CONVERGED
        marks.append(err)
        if stalled(marks, err, stall_window):
            status = STATUS_STALLED
            break
    if status == STATUS_MAX_ITER and rounds < max_iter:
        status = STATUS_TIME_LIMIT
    extras = {
        "history": np.array(history),
        "steps": steps,
        "ipm_iterations": ipm_total,
        "ipm_status": ipm_status,
        "nsgs_sweeps": sweeps_total,
        "polish_sweeps": int(polish_sweeps),
        "asymmetry": step.asymmetry,
        "tol": float(tol),
        "max_iter": int(max_iter),
        "time_limit": time_limit,
    }
    return finish(problem, r, err, rounds, status, t0, "socp", extras)


if TYPE_CHECKING:  # the registry's one signature (engine.SOLVERS), checked by mypy
    _SOLVERS: tuple[ContactSolver, ...] = (solve_socp,)
