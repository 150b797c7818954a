"""Nonsmooth Newton (NSN) on the natural map, with a line search, and its proximal variant (PROX).

The natural map (De Saxcé's modified velocity, the map whose norm is the FCLib residual) with
one weight ``ρ_j > 0`` per contact::

    Φ_j(r) = r_j − Proj_{K_μj}(x_j),   x_j = r_j − ρ_j (u_j + μ_j ‖u_t,j‖ e_n),   u = W r + q,

is zero exactly at the solutions of the frictional contact problem, for any ``ρ > 0``. Here
``ρ_j = 1 / W_nn,j`` (the normal diagonal entry), so that every contact's map has unit scale.
Contacts are in the scaled variables of :mod:`fixplan.engine.problem` (standard second-order
cones only).

Newton step
-----------
An element of the generalized Jacobian is::

    J = blockdiag(I − P'_j) + blockdiag(ρ_j P'_j B_j) W,    B_j = I + μ_j e_n ĝ_jᵀ,

with ``P'_j`` the derivative of the projection at ``x_j`` (``I`` inside the cone, ``0`` in its
polar, the closed form below on the boundary region) and ``ĝ_j = (0, u_t,j / ‖u_t,j‖)`` (0 when
``u_t,j = 0``). ``J`` has the sparsity of ``W`` plus its diagonal blocks and is factored by
SuperLU (sparse ``W`` throughout; no dense matrix is formed).

Where contacts stick (``P'_j = I``) the rows of ``J`` are rows of ``ρ W``, singular when ``W`` is
rank deficient (redundant contacts). The step therefore solves ``(J + λ I) d = −Φ`` with a
Levenberg-like ``λ``: divided by 10 after a full step, multiplied by 10 when the line search
fails (a large ``λ`` turns the step into a short damped fixed-point step ``d ≈ −Φ/λ``).

Line search: backtracking (``t = 1, ½, ¼, …, 2⁻¹²``) with the Armijo condition on ``½‖Φ‖²``,
``‖Φ(r + t d)‖² ≤ (1 − 2σ t) ‖Φ(r)‖²``, ``σ = 1e-4``.

Projection derivative on the boundary region (``t = ‖x_t‖ > 0``, ``ê = x_t / t``)::

    ∂p_n/∂x_n = 1/(1+μ²),           ∂p_n/∂x_t = μ êᵀ/(1+μ²),
    ∂p_t/∂x_n = μ ê/(1+μ²),         ∂p_t/∂x_t = μ² ê êᵀ/(1+μ²) + (μ p_n / t)(I − ê êᵀ).

PROX
----
:func:`solve_prox` is the proximal point method: it solves the well-conditioned problems
``W + σ D``, ``q − σ D r_k`` (``D`` the diagonal of ``W``, so each contact is regularized at its
own scale) with the Newton iteration above, from ``r_k``, and sets ``r_{k+1}`` to their
solution; a fixed point solves the original problem. ``σ`` shrinks when an inner solve succeeds
and grows when it fails.

Every solver returns its best iterate (lowest FCLib residual), stops at ``max_iter`` steps, at
the time limit (checked before every factorization) or when ``stall_window`` steps gained less
than 10 %.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fixplan.engine.budget import Budget
from fixplan.engine.nsgs import error_kernel, spmv
from fixplan.engine.polish import (  # the Jacobian blocks and the natural map, shared with the step's dense polish
    jacobian_blocks,
    natural_map_rows,
)
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
from fixplan.engine.status import (
    STATUS_CONVERGED,
    STATUS_MAX_ITER,
    STATUS_NONFINITE,
    STATUS_STALLED,
    STATUS_TIME_LIMIT,
)

DEFAULT_MAX_STEPS = 100
"""Default cap on Newton steps."""
DEFAULT_STALL_STEPS = 12
"""Default stagnation window of the Newton iteration [steps]."""
LAMBDA_START = 1e-8
"""Initial regularization ``λ`` of ``J + λ I`` (the map has unit scale per contact)."""
LAMBDA_MAX = 1e4
"""Above this ``λ`` the iteration is declared stalled (steps shorter than ``1e-4 ‖Φ‖``)."""
ARMIJO = 1e-4
"""Armijo constant ``σ``."""
MIN_STEP = 2.0**-12
"""Shortest line-search step."""


# --------------------------------------------------------------------------- compiled kernels


@numba.njit(cache=True, error_model="numpy")
def natural_map_kernel(indptr, indices, data, q, mu, offsets, dims, rho, r, u, phi):
    """``Φ_ρ(r)`` into ``phi`` and ``u = W r + q`` into ``u``; returns ``‖Φ_ρ(r)‖₂``."""
    spmv(indptr, indices, data, r, q, u)
    return natural_map_rows(mu, offsets, dims, rho, r, u, phi, np.empty(4), np.empty(4))


# --------------------------------------------------------------------------- the iteration


@dataclass
class _Pattern:
    """Row/column indices of the block-diagonal pattern, built once per problem."""

    rows: np.ndarray
    cols: np.ndarray
    j: np.ndarray
    a: np.ndarray
    b: np.ndarray
    size: int

    @classmethod
    def of(cls, offsets: np.ndarray, dims: np.ndarray, size: int) -> _Pattern:
        js, as_, bs = [], [], []
        for d in np.unique(dims):
            sel = np.flatnonzero(dims == d)
            aa, bb = np.meshgrid(np.arange(d), np.arange(d), indexing="ij")
            js.append(np.repeat(sel, d * d))
            as_.append(np.tile(aa.reshape(-1), sel.shape[0]))
            bs.append(np.tile(bb.reshape(-1), sel.shape[0]))
        j = np.concatenate(js) if js else np.zeros(0, np.int64)
        a = np.concatenate(as_) if as_ else np.zeros(0, np.int64)
        b = np.concatenate(bs) if bs else np.zeros(0, np.int64)
        return cls(offsets[j] + a, offsets[j] + b, j, a, b, size)

    def matrix(self, blocks: np.ndarray) -> sp.csr_matrix:
        data = blocks[self.j, self.a, self.b]
        return sp.csr_matrix((data, (self.rows, self.cols)), shape=(self.size, self.size))


@dataclass
class NewtonRun:
    """Outcome of :func:`run_newton` (scaled variables)."""

    best_r: np.ndarray
    best_err: float
    iterations: int
    status: int
    history: list[float] = field(default_factory=list)
    factorizations: int = 0
    line_search_failures: int = 0
    reason: str = ""
    step_s: float = 0.0  # duration of the last step (Jacobian, factorization, line search) [s]


def contact_weights(arrays: tuple[np.ndarray, ...]) -> np.ndarray:
    """``ρ_j = 1 / W_nn,j`` (1 / the mean positive normal diagonal where ``W_nn,j ≤ 0``)."""
    indptr, indices, data, _, _, offsets, _ = arrays
    W = sp.csr_matrix((data, indices, indptr), shape=(indptr.shape[0] - 1,) * 2)
    wnn = W.diagonal()[offsets] if offsets.shape[0] else np.zeros(0)
    positive = wnn[wnn > 0]
    fallback = float(np.mean(positive)) if positive.size else 1.0
    return 1.0 / np.where(wnn > 0, wnn, fallback)


def run_newton(
    arrays: tuple[np.ndarray, ...],
    r: np.ndarray,
    tol: float,
    max_iter: int,
    budget: Budget,
    stall_window: int | None = DEFAULT_STALL_STEPS,
    error_arrays: tuple[np.ndarray, ...] | None = None,
    lam: float = LAMBDA_START,
    step_s: float = 0.0,
) -> NewtonRun:
    """Regularized semismooth Newton steps with a line search from ``r`` (scaled variables).

    Parameters
    ----------
    arrays : tuple
        :func:`~fixplan.engine.problem.kernel_arrays` of the problem whose natural map is zeroed.
    r : ndarray
        Start; not modified.
    tol : float
        Target FCLib residual, measured on ``error_arrays``.
    max_iter : int
        Cap on Newton steps (factorizations).
    budget : Budget
        Deadline, checked before every factorization (also against the last one's duration).
    stall_window : int, optional
        Stop when the best residual gained less than 10 % over this many steps.
    error_arrays : tuple, optional
        The problem whose FCLib residual is tracked (default: ``arrays``; PROX passes the
        original problem while Newton zeroes the regularized one).
    lam : float
        Initial regularization.
    step_s : float
        Expected duration of a step [s] (PROX passes the last one of its previous round): no
        step (Jacobian, factorization, line search) starts when less time than the last one took
        is left.

    Returns
    -------
    NewtonRun
        Best iterate by the residual on ``error_arrays``.
    """
    indptr, indices, data, q, mu, offsets, dims = arrays
    err_arrays = arrays if error_arrays is None else error_arrays
    m = q.shape[0]
    W = sp.csr_matrix((data, indices, indptr), shape=(m, m))
    rho = contact_weights(arrays)
    pattern = _Pattern.of(offsets, dims, m)
    eye = sp.identity(m, format="csr")
    nc = offsets.shape[0]
    A = np.zeros((nc, 4, 4))
    C = np.zeros((nc, 4, 4))
    r = np.array(r, dtype=float)
    u = np.empty(m)
    phi = np.empty(m)
    u_err = np.empty(m)
    trial_u = np.empty(m)
    trial_phi = np.empty(m)
    norm = natural_map_kernel(indptr, indices, data, q, mu, offsets, dims, rho, r, u, phi)
    err = error_kernel(*err_arrays, r, u_err)  # type: ignore[call-arg]  # numba dispatcher
    run = NewtonRun(r.copy(), err if math.isfinite(err) else math.inf, 0, STATUS_MAX_ITER, step_s=step_s)
    if not (math.isfinite(norm) and math.isfinite(err)):
        run.status, run.reason = STATUS_NONFINITE, "the start overflows"
        return run
    if err <= tol:
        run.status = STATUS_CONVERGED
        return run
    marks: list[float] = [run.best_err]
    while run.iterations < max_iter:
        if budget.remaining_s() <= run.step_s:
            run.status = STATUS_TIME_LIMIT
            break
        t0 = time.perf_counter()
        jacobian_blocks(mu, offsets, dims, rho, r, u, A, C)
        J = pattern.matrix(A) + pattern.matrix(C) @ W
        try:
            lu = spla.splu(sp.csc_matrix(J + lam * eye), permc_spec="COLAMD")
            d = lu.solve(-phi)
        except RuntimeError:  # exactly singular even with λ: regularize more
            d = np.full(m, np.nan)
        run.factorizations += 1
        run.iterations += 1
        step = 1.0
        accepted = False
        if np.all(np.isfinite(d)):
            while step >= MIN_STEP:
                trial = r + step * d
                n_trial = natural_map_kernel(
                    indptr, indices, data, q, mu, offsets, dims, rho, trial, trial_u, trial_phi
                )
                if math.isfinite(n_trial) and n_trial * n_trial <= (1.0 - 2.0 * ARMIJO * step) * norm * norm:
                    accepted = True
                    break
                step *= 0.5
        if accepted:
            r = trial
            u, trial_u = trial_u, u
            phi, trial_phi = trial_phi, phi
            norm = n_trial
            lam = max(lam * 0.1, 1e-14) if step == 1.0 else lam
            err = error_kernel(*err_arrays, r, u_err)  # type: ignore[call-arg]  # numba dispatcher
            if err < run.best_err:
                run.best_err = err
                run.best_r = r.copy()
        else:
            run.line_search_failures += 1
            lam = max(lam * 10.0, 1e-6)
        run.step_s = time.perf_counter() - t0
        run.history.append(run.best_err)
        marks.append(run.best_err)
        if run.best_err <= tol:
            run.status = STATUS_CONVERGED
            break
        if lam > LAMBDA_MAX:
            run.status, run.reason = STATUS_STALLED, f"no descent even with λ = {lam:.0e}"
            break
        if stalled(marks, run.best_err, stall_window):
            run.status = STATUS_STALLED
            break
    return run


def solve_newton(
    problem: ContactProblem,
    r0: Any = None,
    tol: float = DEFAULT_TOL,
    max_iter: int = DEFAULT_MAX_STEPS,
    time_limit: float | None = None,
    stall_window: int | None = DEFAULT_STALL_STEPS,
    step_s: float = 0.0,
) -> ContactSolution:
    """Solve ``u = W r + q`` with the contact laws by semismooth Newton on the natural map.

    A :class:`~fixplan.engine.problem.ContactSolver` (the shared parameters are documented
    there): ``max_iter`` caps Newton steps and ``stall_window`` counts them; ``time_limit`` is
    checked before every step: a step starts only when the last one (or ``step_s``, before the
    first) fits in the time left. Newton converges fast from a good ``r0`` (e.g. NSGS's).
    ``extras`` has ``history``, ``factorizations``, ``line_search_failures`` and ``step_s``
    (the last step's duration).

    Parameters
    ----------
    step_s : float
        Expected duration of one step [s] (``auto`` passes what the Newton stages before took).
    """
    check_settings(tol, max_iter, 1.0)
    budget = Budget.start(time_limit)
    t0 = time.perf_counter()
    arrays = kernel_arrays(problem)
    run = run_newton(arrays, initial_scaled(problem, r0), tol, int(max_iter), budget, stall_window, step_s=step_s)
    extras: dict[str, Any] = {
        "history": np.array(run.history),
        "factorizations": run.factorizations,
        "line_search_failures": run.line_search_failures,
        "step_s": run.step_s,
        "tol": float(tol),
        "max_iter": int(max_iter),
        "time_limit": time_limit,
    }
    solution = finish(problem, run.best_r, run.best_err, run.iterations, run.status, t0, "nsn", extras)
    if run.reason and not solution.converged:
        solution.extras["reason"] += f" ({run.reason})"
    return solution


# --------------------------------------------------------------------------- PROX


DEFAULT_PROX_ROUNDS = 50
"""Default cap on proximal rounds."""
PROX_INNER_STEPS = 15
"""Newton steps per proximal round."""


def run_prox(
    arrays: tuple[np.ndarray, ...],
    r: np.ndarray,
    tol: float,
    max_iter: int,
    budget: Budget,
    stall_window: int | None = DEFAULT_STALL_STEPS,
    sigma: float = 1.0,
    step_s: float = 0.0,
) -> NewtonRun:
    """Proximal point rounds from ``r`` (scaled variables): Newton on ``W + σD``, ``q − σD r_k``.

    ``max_iter`` caps the rounds; the inner Newton iterations are capped at
    ``min(PROX_INNER_STEPS, max_iter)`` each. Returns the best iterate of the original problem.
    ``step_s``: the expected duration of a Newton step [s] before the first one is timed.
    """
    indptr, indices, data, q, mu, offsets, dims = arrays
    m = q.shape[0]
    W = sp.csr_matrix((data, indices, indptr), shape=(m, m))
    diag = W.diagonal()
    positive = diag[diag > 0]
    D = np.where(diag > 0, diag, float(np.mean(positive)) if positive.size else 1.0)
    u = np.empty(m)
    r = np.array(r, dtype=float)
    err = error_kernel(*arrays, r, u)  # type: ignore[call-arg]  # numba dispatcher
    run = NewtonRun(r.copy(), err if math.isfinite(err) else math.inf, 0, STATUS_MAX_ITER, step_s=step_s)
    if err <= tol:
        run.status = STATUS_CONVERGED
        return run
    marks = [run.best_err]
    while run.iterations < max_iter:
        if budget.remaining_s() <= run.step_s:  # not even one Newton step fits
            run.status = STATUS_TIME_LIMIT
            break
        W_sigma = sp.csr_matrix(W + sp.diags(sigma * D))
        W_sigma.sort_indices()
        inner_arrays = (
            np.asarray(W_sigma.indptr, np.int64),
            np.asarray(W_sigma.indices, np.int64),
            np.asarray(W_sigma.data, np.float64),
            q - sigma * D * r,
            mu,
            offsets,
            dims,
        )
        inner_tol = max(tol * 0.1, 1e-16)
        inner = run_newton(
            inner_arrays,
            r,
            inner_tol,
            min(PROX_INNER_STEPS, max_iter),
            budget,
            stall_window=None,
            step_s=run.step_s,
        )
        run.iterations += 1
        run.factorizations += inner.factorizations
        run.step_s = inner.step_s
        # the inner problem's best iterate, judged on the original problem
        r_new = inner.best_r
        err_new = error_kernel(*arrays, r_new, u)  # type: ignore[call-arg]  # numba dispatcher
        if math.isfinite(err_new):
            r = r_new
            if err_new < run.best_err:
                run.best_err, run.best_r = err_new, r_new.copy()
        sigma = sigma * 0.3 if inner.status == STATUS_CONVERGED else sigma * 3.0
        sigma = min(max(sigma, 1e-10), 1e6)
        run.history.append(run.best_err)
        marks.append(run.best_err)
        if run.best_err <= tol:
            run.status = STATUS_CONVERGED
            break
        if inner.status == STATUS_TIME_LIMIT:
            run.status = STATUS_TIME_LIMIT
            break
        if stalled(marks, run.best_err, stall_window):
            run.status = STATUS_STALLED
            break
    return run


def solve_prox(
    problem: ContactProblem,
    r0: Any = None,
    tol: float = DEFAULT_TOL,
    max_iter: int = DEFAULT_PROX_ROUNDS,
    time_limit: float | None = None,
    stall_window: int | None = DEFAULT_STALL_STEPS,
    step_s: float = 0.0,
) -> ContactSolution:
    """Solve ``u = W r + q`` with the contact laws by the proximal point method (PROX).

    A :class:`~fixplan.engine.problem.ContactSolver` (the shared parameters are documented
    there): ``max_iter`` caps proximal rounds (each at most :data:`PROX_INNER_STEPS` Newton
    steps) and ``stall_window`` counts them; ``time_limit`` is checked before every Newton step
    as in :func:`solve_newton`. ``extras`` has ``history``, ``factorizations`` and ``step_s``.

    Parameters
    ----------
    step_s : float
        Expected duration of one Newton step [s], as in :func:`solve_newton`.
    """
    check_settings(tol, max_iter, 1.0)
    budget = Budget.start(time_limit)
    t0 = time.perf_counter()
    arrays = kernel_arrays(problem)
    run = run_prox(arrays, initial_scaled(problem, r0), tol, int(max_iter), budget, stall_window, step_s=step_s)
    extras: dict[str, Any] = {
        "history": np.array(run.history),
        "factorizations": run.factorizations,
        "step_s": run.step_s,
        "tol": float(tol),
        "max_iter": int(max_iter),
        "time_limit": time_limit,
    }
    return finish(problem, run.best_r, run.best_err, run.iterations, run.status, t0, "prox", extras)


if TYPE_CHECKING:  # the registry's one signature (engine.SOLVERS), checked by mypy
    _SOLVERS: tuple[ContactSolver, ...] = (solve_newton, solve_prox)
