"""Nonsmooth Gauss–Seidel (NSGS) for the local frictional contact problem ``u = W r + q``.

The problem, its scaled variables (soft fingers) and the FCLib residual the sweeps stop on are
those of :mod:`fixplan.engine.problem`; ``max_iter`` only caps the sweeps, and how a run ended is
a code of :mod:`fixplan.engine.status`.

A sweep visits the contacts in order; contact ``j`` gets ``α̂_j = q_j + Σ_{k≠j} W_jk r_k`` from
the current ``r`` and solves its one-contact problem exactly, then
``r_j ← ω P_j + (1 − ω) r_j`` (``ω = 1``: plain Gauss–Seidel, the default; a convex combination
of two cone points stays in the cone). The compiled sweep works on ``W`` in CSR form, so a
sweep costs ``O(nnz(W))``; so does the residual, computed after every sweep.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numba
import numpy as np
import scipy.sparse as sp

from fixplan.engine.budget import CHUNK_S, Budget
from fixplan.engine.linalg import invert_small
from fixplan.engine.local import (
    FAILED,
    WORKSPACE_SIZE,
    cone_solve_ws,
    coulomb_2d_ws,
    open_or_stick,
    slide3_newton,
)
from fixplan.engine.problem import (
    DEFAULT_STALL_RATIO,
    DEFAULT_TOL,
    ContactProblem,
    ContactSolution,
    ContactSolver,
    check_settings,
    fclib_error,
    finish,
    initial_scaled,
    kernel_arrays,
)
from fixplan.engine.residual import fclib_error_rows
from fixplan.engine.status import STATUS_CONVERGED, STATUS_MAX_ITER, STATUS_NONFINITE, STATUS_STALLED, STATUS_TIME_LIMIT

DEFAULT_MAX_ITER = 10_000
"""Default cap on NSGS sweeps (a cap, never the stopping rule)."""
DEFAULT_OMEGA = 1.0
"""Default sweep relaxation ``ω``.

Measured (tol 1e-8, cap 5 000 sweeps) on 48 problems — the 4 FCLib files, 24 box stacks and
20 random rank-deficient problems: ω = 1.0 / 1.2 / 1.3 / 1.5 / 1.7 converged on 31 / 33 / 34 /
32 / 21 of them. Over-relaxation speeds up Capsules (2 302 → 1 691 → 1 377 → 773 sweeps for
ω = 1, 1.2, 1.3, 1.5) but slows LMGC_PerioBox (34 → 86 → 98 → 134) and, at 1.5–1.7, loses
problems that ω = 1 solves. Plain Gauss–Seidel is kept as the default: never the worst, no
failure of its own; pass ``omega`` to tune a known family of problems."""

_HISTORY_CAP = 100_000  # errors recorded per run (the sweeps themselves are not capped by it)


# --------------------------------------------------------------------------- compiled kernels


@numba.njit(cache=True, error_model="numpy")
def diagonal_blocks(indptr, indices, data, offsets, dims):
    """Diagonal blocks ``W_jj`` of a CSR matrix, padded to shape ``(n_c, 4, 4)``."""
    nc = offsets.shape[0]
    out = np.zeros((nc, 4, 4))
    for j in range(nc):
        o = offsets[j]
        d = dims[j]
        for a in range(d):
            row = o + a
            for p in range(indptr[row], indptr[row + 1]):
                c = indices[p]
                if c >= o and c < o + d:
                    out[j, a, c - o] += data[p]
    return out


@numba.njit(cache=True, error_model="numpy")
def spmv(indptr, indices, data, x, q, out):
    """``out = W x + q`` for CSR ``W``."""
    m = q.shape[0]
    for i in range(m):
        s = q[i]
        for p in range(indptr[i], indptr[i + 1]):
            s += data[p] * x[indices[p]]
        out[i] = s


@numba.njit(cache=True, error_model="numpy")
def error_kernel(indptr, indices, data, q, mu, offsets, dims, r, u):
    """FCLib residual of ``r`` for CSR ``W`` (standard cones); fills ``u = W r + q``.

    ``u`` by :func:`spmv`, the residual by :func:`~fixplan.engine.residual.fclib_error_rows`
    (the one compiled residual, shared with the time step's dense sweep).
    """
    spmv(indptr, indices, data, r, q, u)
    return fclib_error_rows(q, mu, offsets, dims, offsets.shape[0], q.shape[0], r, u, np.empty(4), np.empty(4))


@numba.njit(cache=True, error_model="numpy")
def local_solve_into(A, alpha, mu, d, P):
    """One-contact solve in a standard cone of dimension ``d`` (closed form for ``d = 2``)."""
    return local_solve_ws(A, alpha, mu, d, P, np.empty(WORKSPACE_SIZE))


@numba.njit(cache=True, error_model="numpy")
def local_solve_ws(A, alpha, mu, d, P, ws):
    """:func:`local_solve_into` with a caller-owned workspace (``WORKSPACE_SIZE`` floats)."""
    if d == 2:
        return coulomb_2d_ws(A, alpha, mu, P, ws)
    return cone_solve_ws(A, alpha, mu, P, ws)


@numba.njit(cache=True, error_model="numpy")
def sweep_kernel(indptr, indices, data, q, mu, offsets, dims, diag, r, omega):
    """One Gauss–Seidel sweep in place on ``r``; returns the number of failed local solves."""
    nc = offsets.shape[0]
    alpha = np.empty(4)
    P = np.empty(4)
    ws = np.empty(WORKSPACE_SIZE)
    failures = 0
    for j in range(nc):
        o = offsets[j]
        d = dims[j]
        for a in range(d):
            row = o + a
            s = q[row]
            for p in range(indptr[row], indptr[row + 1]):
                c = indices[p]
                if c < o or c >= o + d:
                    s += data[p] * r[c]
            alpha[a] = s
        st, _ = local_solve_ws(diag[j, :d, :d], alpha[:d], mu[j], d, P[:d], ws)
        if st == FAILED:
            failures += 1
        for a in range(d):
            r[o + a] = omega * P[a] + (1.0 - omega) * r[o + a]
    return failures


@numba.njit(cache=True, error_model="numpy")
def _all_finite(x):
    for i in range(x.shape[0]):
        if not math.isfinite(x[i]):
            return False
    return True


@numba.njit(cache=True, error_model="numpy")
def nsgs_kernel(indptr, indices, data, q, mu, offsets, dims, diag, r, tol, max_iter, omega, history, best_r, best):
    """At most ``max_iter`` NSGS sweeps on ``r``, stopping when the FCLib residual is ``≤ tol``.

    One chunk of a solve: the caller checks its deadline between chunks. ``diag`` are the
    diagonal blocks (:func:`diagonal_blocks`). ``history[k]`` receives the error after sweep
    ``k + 1`` (while ``k < len(history)``). ``best_r`` and ``best[0]`` hold the lowest-residual
    iterate seen so far and its error; they are updated in place whenever a sweep beats them.

    Returns ``(iterations, error, status, local_failures)`` with ``error`` the residual of the
    last iterate; ``status`` a code of :mod:`fixplan.engine.status`: ``STATUS_CONVERGED``,
    ``STATUS_MAX_ITER`` (cap reached) or ``STATUS_NONFINITE`` (``r`` is then restored to the last
    finite iterate).
    """
    m = q.shape[0]
    u = np.empty(m)
    r_prev = np.empty(m)
    failures = 0
    it = 0
    status = STATUS_MAX_ITER
    err = math.inf
    while it < max_iter:
        r_prev[:] = r
        failures += sweep_kernel(indptr, indices, data, q, mu, offsets, dims, diag, r, omega)
        it += 1
        err_new = error_kernel(indptr, indices, data, q, mu, offsets, dims, r, u)
        if not (math.isfinite(err_new) and _all_finite(r)):
            r[:] = r_prev
            status = STATUS_NONFINITE
            break
        err = err_new
        if it - 1 < history.shape[0]:
            history[it - 1] = err
        if err < best[0]:
            best[0] = err
            best_r[:] = r
        if err <= tol:
            status = STATUS_CONVERGED
            break
    return it, err, status, failures


@numba.njit(cache=True)
def nsgs_dense(W, q, mu, offsets, sizes, nc, m, P, tol, max_iter, diag, inv, has_inv, u, scratch):
    """NSGS on a dense ``W`` (the time step's Delassus matrix) in caller-owned buffers: no allocation.

    The leading ``nc`` contacts / ``m`` rows of the buffers are used (``diag``, ``inv``:
    ``(≥nc, 4, 4)``; ``has_inv``: ``(≥nc,)``; ``u``: ``(≥m,)``; ``scratch``:
    ``WORKSPACE_SIZE + 16`` floats). Sweeps until :func:`fclib_error_rows` ≤ ``tol``, at most
    ``max_iter``; returns ``(error, sweeps, converged, failed local solves in the last sweep)``.
    Every contact first tries the closed-form open and strict-stick regimes
    (:func:`~fixplan.engine.local.open_or_stick`); a 3D contact whose test fails then tries
    :func:`~fixplan.engine.local.slide3_newton` from its current impulse, then the general exact
    solver of :mod:`.local`. The sparse :func:`nsgs_kernel` is the same sweep for FCLib problems
    (CSR ``W``, relaxation ``ω``, best iterate kept).
    """
    err = math.inf
    failures = 0
    if m == 0:
        return 0.0, 0, True, 0
    ws = scratch[0:WORKSPACE_SIZE]
    alpha = scratch[WORKSPACE_SIZE : WORKSPACE_SIZE + 4]
    Pj = scratch[WORKSPACE_SIZE + 4 : WORKSPACE_SIZE + 8]
    xbuf = scratch[WORKSPACE_SIZE + 8 : WORKSPACE_SIZE + 12]
    prbuf = scratch[WORKSPACE_SIZE + 12 : WORKSPACE_SIZE + 16]
    for j in range(nc):
        o, d = offsets[j], sizes[j]
        for a in range(d):
            for b in range(d):
                diag[j, a, b] = W[o + a, o + b]
        has_inv[j] = invert_small(diag[j, :d, :d], inv[j, :d, :d])
    it = 0
    for it in range(1, max_iter + 1):
        failures = 0
        for j in range(nc):
            o, d = offsets[j], sizes[j]
            if d == 3:
                # the 3D contact in scalars: α (same summation order as below), then the
                # closed-form open and strict-stick regimes of open_or_stick
                s0, s1, s2 = q[o], q[o + 1], q[o + 2]
                for c in range(o):
                    pc = P[c]
                    s0 += W[o, c] * pc
                    s1 += W[o + 1, c] * pc
                    s2 += W[o + 2, c] * pc
                for c in range(o + 3, m):
                    pc = P[c]
                    s0 += W[o, c] * pc
                    s1 += W[o + 1, c] * pc
                    s2 += W[o + 2, c] * pc
                if s0 >= 0.0:
                    P[o] = 0.0
                    P[o + 1] = 0.0
                    P[o + 2] = 0.0
                    continue
                if has_inv[j]:
                    iv = inv[j]
                    x0 = -iv[0, 0] * s0 - iv[0, 1] * s1 - iv[0, 2] * s2
                    x1 = -iv[1, 0] * s0 - iv[1, 1] * s1 - iv[1, 2] * s2
                    x2 = -iv[2, 0] * s0 - iv[2, 1] * s1 - iv[2, 2] * s2
                    if x0 > 0.0 and math.sqrt(x1 * x1 + x2 * x2) < mu[j] * x0 * (1.0 - 1e-9):
                        P[o] = x0
                        P[o + 1] = x1
                        P[o + 2] = x2
                        continue
                alpha[0] = s0
                alpha[1] = s1
                alpha[2] = s2
                Pj[0] = P[o]
                Pj[1] = P[o + 1]
                Pj[2] = P[o + 2]
                if not slide3_newton(diag[j, :3, :3], alpha[:3], mu[j], Pj[:3]):
                    st, _ = local_solve_ws(diag[j, :3, :3], alpha[:3], mu[j], 3, Pj[:3], ws)
                    if st == FAILED:
                        failures += 1
                P[o] = Pj[0]
                P[o + 1] = Pj[1]
                P[o + 2] = Pj[2]
                continue
            for a in range(d):
                s = q[o + a]
                for c in range(m):
                    if c < o or c >= o + d:
                        s += W[o + a, c] * P[c]
                alpha[a] = s
            if not open_or_stick(alpha, mu[j], d, inv[j], has_inv[j], Pj):
                for a in range(d):
                    Pj[a] = P[o + a]
                if not (d == 3 and slide3_newton(diag[j, :3, :3], alpha[:3], mu[j], Pj[:3])):
                    st, _ = local_solve_ws(diag[j, :d, :d], alpha[:d], mu[j], d, Pj[:d], ws)
                    if st == FAILED:
                        failures += 1
            for a in range(d):
                P[o + a] = Pj[a]
        for r in range(m):
            s = q[r]
            for c in range(m):
                s += W[r, c] * P[c]
            u[r] = s
        err = fclib_error_rows(q, mu, offsets, sizes, nc, m, P, u, xbuf, prbuf)
        if not math.isfinite(err):
            return err, it, False, failures
        if err <= tol:
            return err, it, True, failures
    return err, it, False, failures


# --------------------------------------------------------------------------- drivers


@dataclass
class NsgsRun:
    """Outcome of :func:`run_nsgs` (the kernels' arrays, in scaled variables)."""

    best_r: np.ndarray
    best_err: float
    iterations: int
    status: int
    failures: int
    history: np.ndarray


def run_nsgs(
    arrays: tuple[np.ndarray, ...],
    r: np.ndarray,
    err: float,
    tol: float,
    max_iter: int,
    omega: float,
    budget: Budget,
    stall_window: int | None = None,
    stall_ratio: float = DEFAULT_STALL_RATIO,
    diag: np.ndarray | None = None,
) -> NsgsRun:
    """NSGS sweeps from ``r`` (residual ``err``) in compiled chunks, within ``budget``.

    Chunks are sized to take about :data:`~fixplan.engine.budget.CHUNK_S`; between chunks the
    deadline is checked and, with ``stall_window``, stagnation: the run stops (status
    ``STATUS_STALLED``) when the best residual after ``k`` sweeps is above ``stall_ratio`` times
    the best after ``k − stall_window`` sweeps.

    Parameters
    ----------
    arrays : tuple
        :func:`kernel_arrays` of the problem.
    r : ndarray
        Start (scaled variables); overwritten by the last iterate.
    err : float
        Residual of ``r``.
    tol, max_iter, omega
        As :func:`solve_nsgs`.
    budget : Budget
        Deadline.
    stall_window : int, optional
        Sweeps over which progress is judged (``None``: never stop for stagnation).
    stall_ratio : float
        Required gain per window.
    diag : ndarray, optional
        :func:`diagonal_blocks` (computed when not given).

    Returns
    -------
    NsgsRun
        The best iterate (lowest residual; ``r`` itself when no sweep improved on it).
    """
    indptr, indices, data, q, mu, offsets, dims = arrays
    if diag is None:
        diag = diagonal_blocks(indptr, indices, data, offsets, dims)
    best_r = r.copy()
    best = np.array([err if math.isfinite(err) else math.inf])
    history = np.full(min(max(int(max_iter), 1), _HISTORY_CAP), np.nan)
    status = STATUS_CONVERGED if err <= tol else STATUS_MAX_ITER
    done = 0
    failures = 0
    chunk = 1
    marks: list[tuple[int, float]] = [(0, float(best[0]))]  # (sweeps, best error) after each chunk
    per_sweep = 0.0
    while status != STATUS_CONVERGED and done < max_iter:
        left = budget.remaining_s()
        if left <= per_sweep:  # not even one more sweep (as long as the last ones) fits
            status = STATUS_TIME_LIMIT
            break
        n = min(chunk, int(max_iter) - done)
        if per_sweep > 0 and math.isfinite(left):
            n = min(n, max(int(left / per_sweep), 1))  # the chunk ends before the deadline
        if stall_window:
            n = min(n, max(stall_window // 2, 1))
        t0 = time.perf_counter()
        hist = history[done:] if done < history.shape[0] else history[:0]
        it, _, st, fails = nsgs_kernel(  # type: ignore[call-arg]  # numba dispatcher
            indptr, indices, data, q, mu, offsets, dims, diag, r, float(tol), n, float(omega), hist, best_r, best
        )
        elapsed = time.perf_counter() - t0
        done += it
        failures += fails
        if st == STATUS_CONVERGED:
            status = STATUS_CONVERGED
            break
        if st == STATUS_NONFINITE:
            status = STATUS_NONFINITE
            break
        # next chunk: about CHUNK_S of work, at most 4× the last one
        per_sweep = elapsed / max(it, 1)
        chunk = int(max(1, min(4 * n, CHUNK_S / max(per_sweep, 1e-9))))
        marks.append((done, float(best[0])))
        if stall_window and done >= stall_window:
            then = [b for k, b in marks if k <= done - stall_window]
            if then and best[0] > stall_ratio * then[-1]:
                status = STATUS_STALLED
                break
    if status == STATUS_MAX_ITER and done < max_iter:  # pragma: no cover - loop exits otherwise
        status = STATUS_TIME_LIMIT
    return NsgsRun(best_r, float(best[0]), done, status, failures, history[: min(done, history.shape[0])].copy())


def solve_nsgs(
    problem: ContactProblem,
    r0: Any = None,
    tol: float = DEFAULT_TOL,
    max_iter: int = DEFAULT_MAX_ITER,
    omega: float = DEFAULT_OMEGA,
    time_limit: float | None = None,
    stall_window: int | None = None,
) -> ContactSolution:
    """Solve ``u = W r + q`` with the contact laws by compiled nonsmooth Gauss–Seidel.

    A :class:`~fixplan.engine.problem.ContactSolver` (the shared parameters are documented
    there): ``max_iter`` caps sweeps, ``time_limit`` is checked between chunks of sweeps,
    ``stall_window`` counts sweeps.

    Parameters
    ----------
    omega : float
        Sweep relaxation ``0 < ω < 2``.
    """
    check_settings(tol, max_iter, omega)
    budget = Budget.start(time_limit)
    t0 = time.perf_counter()
    arrays = kernel_arrays(problem)
    r = initial_scaled(problem, r0)
    u = np.empty(problem.size)
    err = error_kernel(*arrays, r, u)  # type: ignore[call-arg]  # numba dispatcher
    if not math.isfinite(err):  # the warm start overflows: report it rather than sweep from it
        run = NsgsRun(r, math.inf, 0, STATUS_NONFINITE, 0, np.zeros(0))
    else:
        run = run_nsgs(arrays, r, err, tol, max_iter, omega, budget, stall_window)
    extras = {
        "history": run.history,
        "omega": float(omega),
        "tol": float(tol),
        "max_iter": int(max_iter),
        "time_limit": time_limit,
        "local_failures": int(run.failures),
    }
    status = run.status
    if status == STATUS_NONFINITE and math.isfinite(run.best_err) and run.best_err <= tol:
        status = STATUS_CONVERGED
    return finish(problem, run.best_r, run.best_err, run.iterations, status, t0, "nsgs", extras)


def solve_nsgs_reference(
    problem: ContactProblem,
    r0: Any = None,
    tol: float = DEFAULT_TOL,
    max_iter: int = DEFAULT_MAX_ITER,
    omega: float = DEFAULT_OMEGA,
    time_limit: float | None = None,
) -> ContactSolution:
    """Plain NumPy NSGS: the same sweep as :func:`solve_nsgs`, written for reading and testing.

    Works on the rows of the CSR ``W`` with NumPy (``α̂_j`` and the diagonal block ``W_jj`` of
    each contact from its rows) and uses :func:`fclib_error` for the residual; only the
    one-contact solves are the shared compiled ones of :mod:`fixplan.engine.local`. Slow (a
    Python loop over contacts): meant for small problems and for checking the compiled kernel.

    A :class:`~fixplan.engine.problem.ContactSolver` with :func:`solve_nsgs`'s ``omega``;
    ``time_limit`` is checked before every contact of a sweep (a sweep of a large problem takes
    seconds here), and a sweep cut short is dropped. The answer (``solver == "nsgs-numpy"``) is
    the best iterate after a whole sweep.
    """
    check_settings(tol, max_iter, omega)
    budget = Budget.start(time_limit)
    t0 = time.perf_counter()
    Wt_sparse, qt = problem.scaled()
    Wt = sp.csr_matrix(Wt_sparse)
    s = problem.row_scale
    r = initial_scaled(problem, r0)
    history: list[float] = []

    def error_of(r_tilde: np.ndarray) -> float:
        return fclib_error(problem, s * r_tilde)

    err = error_of(r)
    best_r, best = r.copy(), err if math.isfinite(err) else math.inf
    status = STATUS_CONVERGED if err <= tol else STATUS_MAX_ITER
    it = 0
    while status != STATUS_CONVERGED and it < max_iter:
        for j in range(problem.n_contacts):
            if budget.expired():  # inside the sweep: one sweep may take seconds in Python
                status = STATUS_TIME_LIMIT
                break
            o, d = int(problem.offsets[j]), int(problem.dims[j])
            lo, hi = int(Wt.indptr[o]), int(Wt.indptr[o + d])
            cols, vals = Wt.indices[lo:hi], Wt.data[lo:hi]
            row = np.repeat(np.arange(d), np.diff(Wt.indptr[o : o + d + 1]))  # row of each entry in the contact
            inside = (cols >= o) & (cols < o + d)
            block = np.zeros((d, d))
            np.add.at(block, (row[inside], cols[inside] - o), vals[inside])
            # α̂_j = q̃_j + Σ_{k≠j} W̃_jk r̃_k
            alpha = qt[o : o + d] + np.bincount(row[~inside], weights=vals[~inside] * r[cols[~inside]], minlength=d)
            P = np.empty(d)
            local_solve_into(block, alpha, float(problem.mu[j]), d, P)
            r[o : o + d] = omega * P + (1.0 - omega) * r[o : o + d]
        if status == STATUS_TIME_LIMIT:
            break
        it += 1
        if not np.all(np.isfinite(r)):
            status = STATUS_NONFINITE
            break
        err = error_of(r)
        history.append(err)
        if err < best:
            best_r, best = r.copy(), err
        if err <= tol:
            status = STATUS_CONVERGED
    extras = {
        "history": np.array(history),
        "omega": float(omega),
        "tol": float(tol),
        "max_iter": int(max_iter),
        "time_limit": time_limit,
    }
    return finish(problem, best_r, best, it, status, t0, "nsgs-numpy", extras)


if TYPE_CHECKING:  # the registry's one signature (engine.SOLVERS), checked by mypy
    _SOLVERS: tuple[ContactSolver, ...] = (solve_nsgs, solve_nsgs_reference)
