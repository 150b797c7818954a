"""Nonsmooth Gauss–Seidel (NSGS) for the local frictional contact problem ``u = W r + q``.

The problem (docs/math.md, "Transfer equations" and "Contact laws"; FCLib's "local" problem): find
the impulses ``r`` and velocities ``u = W r + q`` such that every contact ``j`` obeys its law
``K_μj ∋ r_j ⊥ ũ_j ∈ K_μj*``. Contact ``j`` occupies rows ``offset[j] : offset[j] + dim[j]``,
ordered ``(normal, tangent1[, tangent2[, spin]])``; ``dim`` is 2 (planar Coulomb), 3 (Coulomb)
or 4 (soft finger with torsion radius ``e_r``).

Soft-finger contacts are solved in the scaled variables of :mod:`fixplan.engine.local`:
with ``s = 1`` on every row except ``s = e_r`` on spin rows, ``W̃ = diag(s) W diag(s)``,
``q̃ = s ∘ q``, ``r = s ∘ r̃``, ``ũ = s ∘ u``. The scaled problem has only second-order cones,
so the sweep, the residual and the SOCP solver see one kind of cone.

Stopping rule: the Siconos/FCLib residual (natural map, ``ρ = 1``), in the scaled variables::

    err = sqrt(Σ_j ‖r̃_j − Proj_{K_μj}(r̃_j − ũ_j − μ_j‖ũ_t,j‖ e_n)‖²) / max(‖q̃‖, ‖r̃‖, ‖ũ‖)

(0 when the denominator is 0, i.e. ``q = 0`` and ``r = 0``). ``max_iter`` only caps the sweeps.

A sweep visits the contacts in order; contact ``j`` gets ``α̂_j = q_j + Σ_{k≠j} W_jk r_k`` from
the current ``r`` and solves its one-contact problem exactly, then
``r_j ← ω P_j + (1 − ω) r_j`` (``ω = 1``: plain Gauss–Seidel, the default; a convex combination
of two cone points stays in the cone). The compiled sweep works on ``W`` in CSR form, so a
sweep costs ``O(nnz(W))``; so does the residual, computed after every sweep.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

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
from fixplan.engine.residual import fclib_error, fclib_error_rows
from fixplan.errors import InputError

DEFAULT_TOL = 1e-8
"""Default stopping tolerance on the FCLib residual (relative, dimensionless)."""
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

STATUS_CONVERGED = 0
STATUS_MAX_ITER = 1
STATUS_NAN = 2
STATUS_TIME_LIMIT = 3
STATUS_STALLED = 4
_STATUS_TEXT = {
    STATUS_CONVERGED: "converged",
    STATUS_MAX_ITER: "max_iter reached before tol",
    STATUS_NAN: "a non-finite value appeared; returned the best finite iterate",
    STATUS_TIME_LIMIT: "time limit reached before tol",
    STATUS_STALLED: "stalled: the residual stopped improving",
}
DEFAULT_STALL_RATIO = 0.9


def stalled(marks: list[float], error: float, window: int | None, ratio: float = DEFAULT_STALL_RATIO) -> bool:
    """Stagnation: ``error`` has not dropped below ``ratio`` × the mark ``window`` rounds back."""
    return window is not None and 0 < window < len(marks) and error > ratio * marks[-1 - window]


"""A run stalls when its best residual did not drop below this fraction of the best residual
``window`` iterations earlier (a 10 % gain per window)."""


# --------------------------------------------------------------------------- the problem


@dataclass(frozen=True, eq=False)
class ContactProblem:
    """A local frictional contact problem ``u = W r + q`` (read-only copies of the data).

    Build it with :func:`build_problem`, which validates every argument.

    Attributes
    ----------
    W : scipy.sparse.csr_matrix, shape (m, m)
        Delassus operator ``J M⁻¹ Jᵀ`` [m/s per N·s]; symmetric PSD in mechanics (FCLib
        files may carry a slightly non-symmetric one, which is accepted).
    q : ndarray, shape (m,)
        Free velocity [m/s].
    mu : ndarray, shape (n_c,)
        Friction coefficient per contact.
    dims : ndarray of int, shape (n_c,)
        Rows per contact: 2, 3 or 4.
    offsets : ndarray of int, shape (n_c,)
        First row of each contact.
    torsion_radius : ndarray, shape (n_c,)
        ``e_r`` [m] of soft-finger (``dim = 4``) contacts; 0 elsewhere.
    """

    W: sp.csr_matrix
    q: np.ndarray
    mu: np.ndarray
    dims: np.ndarray
    offsets: np.ndarray
    torsion_radius: np.ndarray

    @property
    def n_contacts(self) -> int:
        """Number of contacts."""
        return int(self.mu.shape[0])

    @property
    def size(self) -> int:
        """Number of rows ``m``."""
        return int(self.q.shape[0])

    @property
    def row_scale(self) -> np.ndarray:
        """``s``: 1 on every row, ``e_r`` on soft-finger spin rows."""
        s = np.ones(self.size)
        spin = self.dims == 4
        s[self.offsets[spin] + 3] = self.torsion_radius[spin]
        return s

    def scaled(self) -> tuple[sp.csr_matrix, np.ndarray]:
        """``(W̃, q̃)`` of the scaled problem (the same arrays when there is no soft finger)."""
        if not np.any(self.dims == 4):
            return self.W, self.q
        s = self.row_scale
        S = sp.diags(s)
        return sp.csr_matrix(S @ self.W @ S), s * self.q


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


def build_problem(
    W: Any,
    q: Any,
    mu: Any,
    dims: Any = 3,
    torsion_radius: Any = None,
) -> ContactProblem:
    """Validate and copy the data of ``u = W r + q`` into a :class:`ContactProblem`.

    Parameters
    ----------
    W : array_like or scipy.sparse matrix, shape (m, m)
        Delassus operator.
    q : array_like, shape (m,)
        Free velocity.
    mu : float or array_like, shape (n_c,)
        Friction coefficients (a scalar is used for every contact).
    dims : int or array_like of int, shape (n_c,)
        Rows per contact, each 2, 3 or 4 (an int is used for every contact).
    torsion_radius : float or array_like, optional
        ``e_r ≥ 0`` [m] per contact, required for ``dim = 4`` contacts, ignored elsewhere.

    Returns
    -------
    ContactProblem
        The validated problem.

    Raises
    ------
    InputError
        When shapes disagree, a value is not finite, ``μ < 0`` or ``e_r`` is missing/negative.
    """
    q_arr = np.asarray(q, dtype=float).reshape(-1)
    m = q_arr.shape[0]
    if sp.issparse(W):
        W_csr = sp.csr_matrix(W, dtype=float)
    else:
        W_arr = np.asarray(W, dtype=float)
        if W_arr.ndim != 2:
            raise InputError(f"expected W with shape ({m}, {m}), got shape {W_arr.shape}")
        W_csr = sp.csr_matrix(W_arr)
    if W_csr.shape != (m, m):
        raise InputError(f"expected W with shape ({m}, {m}) to match q, got {W_csr.shape}")
    W_csr.sort_indices()
    W_csr.sum_duplicates()
    if not (np.all(np.isfinite(W_csr.data)) and np.all(np.isfinite(q_arr))):
        raise InputError("W and q must be finite (found NaN or inf)")
    dims_in = np.asarray(dims)
    if dims_in.ndim == 0:
        d = int(dims_in)
        if d not in (2, 3, 4) or m % d:
            raise InputError(f"expected contact dimension 2, 3 or 4 dividing m={m}, got {d}")
        dims_arr = np.full(m // d, d, dtype=np.int64)
    else:
        dims_arr = dims_in.astype(np.int64).reshape(-1)
    if not np.all(np.isin(dims_arr, (2, 3, 4))):
        raise InputError(f"expected every contact dimension in (2, 3, 4), got {set(dims_arr)}")
    if int(dims_arr.sum()) != m:
        raise InputError(f"contact dimensions sum to {int(dims_arr.sum())}, expected m={m}")
    nc = dims_arr.shape[0]
    offsets = np.zeros(nc, dtype=np.int64)
    if nc:
        offsets[1:] = np.cumsum(dims_arr)[:-1]
    mu_arr = np.broadcast_to(np.asarray(mu, dtype=float), (nc,)).copy()
    if mu_arr.shape != (nc,) or not np.all(np.isfinite(mu_arr)) or np.any(mu_arr < 0):
        raise InputError(f"expected {nc} finite friction coefficients μ ≥ 0")
    e_r = np.zeros(nc)
    if np.any(dims_arr == 4):
        if torsion_radius is None:
            raise InputError("soft-finger contacts (dim 4) need torsion_radius [m]")
        e_in = np.broadcast_to(np.asarray(torsion_radius, dtype=float), (nc,))
        e_r = np.where(dims_arr == 4, e_in, 0.0)
        if not np.all(np.isfinite(e_r)) or np.any(e_r < 0):
            raise InputError("expected finite torsion_radius ≥ 0 [m] for every dim-4 contact")
    W_csr.data.setflags(write=False)
    return ContactProblem(
        W=W_csr,
        q=_readonly(q_arr),
        mu=_readonly(mu_arr),
        dims=_readonly(dims_arr),
        offsets=_readonly(offsets),
        torsion_radius=_readonly(e_r),
    )


# --------------------------------------------------------------------------- the solution


@dataclass(frozen=True, eq=False)
class ContactSolution:
    """Answer of a contact solver, with its quality.

    Attributes
    ----------
    reaction : ndarray, shape (m,)
        Impulses ``r`` [N·s] (spin rows [N·m·s]).
    velocity : ndarray, shape (m,)
        ``u = W r + q`` [m/s] (spin rows [rad/s]).
    error : float
        FCLib residual of ``reaction`` (module docstring).
    iterations : int
        Sweeps (NSGS) or Newton steps.
    converged : bool
        ``error ≤ tol`` was reached.
    time_s : float
        Wall time of the solve [s].
    solver : str
        Name of the method.
    extras : dict
        Backend details: ``status`` text, ``history`` of errors, settings, ``reason`` when not
        converged.
    problem : ContactProblem
        The problem solved (for :meth:`residual`).
    """

    reaction: np.ndarray
    velocity: np.ndarray
    error: float
    iterations: int
    converged: bool
    time_s: float
    solver: str
    extras: dict = field(default_factory=dict)
    problem: ContactProblem | None = field(default=None, repr=False)

    def residual(self, W: Any = None, q: Any = None) -> float:
        """Recompute the FCLib residual of :attr:`reaction` from ``(W, q)`` in plain NumPy.

        Parameters
        ----------
        W, q : optional
            Data to check against; default the solved problem's.

        Returns
        -------
        float
            The residual, independent of the solver's own bookkeeping.
        """
        prob = self.problem
        if prob is None:
            raise InputError("this solution carries no problem; pass W and q")
        if W is not None or q is not None:
            prob = build_problem(
                prob.W if W is None else W,
                prob.q if q is None else q,
                prob.mu,
                prob.dims,
                prob.torsion_radius,
            )
        return fclib_error(prob, self.reaction)


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
def _spmv(indptr, indices, data, x, q, out):
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

    ``u`` by :func:`_spmv`, the residual by :func:`~fixplan.engine.residual.fclib_error_rows`
    (the one compiled residual, shared with the time step's dense sweep).
    """
    _spmv(indptr, indices, data, r, q, u)
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
    last iterate; ``status``: 0 converged, 1 cap reached, 2 non-finite value (``r`` is then
    restored to the last finite iterate).
    """
    m = q.shape[0]
    u = np.empty(m)
    r_prev = np.empty(m)
    failures = 0
    it = 0
    status = 1
    err = math.inf
    while it < max_iter:
        r_prev[:] = r
        failures += sweep_kernel(indptr, indices, data, q, mu, offsets, dims, diag, r, omega)
        it += 1
        err_new = error_kernel(indptr, indices, data, q, mu, offsets, dims, r, u)
        if not (math.isfinite(err_new) and _all_finite(r)):
            r[:] = r_prev
            status = 2
            break
        err = err_new
        if it - 1 < history.shape[0]:
            history[it - 1] = err
        if err < best[0]:
            best[0] = err
            best_r[:] = r
        if err <= tol:
            status = 0
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


def _csr_arrays(W: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Writable int64/float64 copies of the CSR arrays (one compiled signature for all)."""
    return (
        np.array(W.indptr, dtype=np.int64),
        np.array(W.indices, dtype=np.int64),
        np.array(W.data, dtype=np.float64),
    )


def kernel_arrays(problem: ContactProblem) -> tuple[np.ndarray, ...]:
    """``(indptr, indices, data, q̃, μ, offsets, dims)`` of the scaled problem, for the kernels."""
    Wt, qt = problem.scaled()
    return (
        *_csr_arrays(Wt),
        np.array(qt, dtype=np.float64),
        np.array(problem.mu, dtype=np.float64),
        np.array(problem.offsets, dtype=np.int64),
        np.array(problem.dims, dtype=np.int64),
    )


def _initial_scaled(problem: ContactProblem, r0: Any) -> np.ndarray:
    m = problem.size
    if r0 is None:
        return np.zeros(m)
    r0_arr = np.asarray(r0, dtype=float).reshape(-1)
    if r0_arr.shape != (m,):
        raise InputError(f"expected r0 with {m} entries, got {r0_arr.shape[0]}")
    if not np.all(np.isfinite(r0_arr)):
        raise InputError("r0 must be finite")
    s = problem.row_scale
    return np.divide(r0_arr, s, out=np.zeros(m), where=s > 0)


def _check_settings(tol: float, max_iter: int, omega: float) -> None:
    if not (tol >= 0 and math.isfinite(tol)):
        raise InputError(f"expected a finite tol ≥ 0, got {tol}")
    if int(max_iter) < 0:
        raise InputError(f"expected max_iter ≥ 0, got {max_iter}")
    if not (0.0 < omega < 2.0):
        raise InputError(f"expected relaxation 0 < ω < 2, got {omega}")


def _finish(
    problem: ContactProblem,
    r_tilde: np.ndarray,
    error: float,
    iterations: int,
    status: int,
    t0: float,
    solver: str,
    extras: dict,
) -> ContactSolution:
    s = problem.row_scale
    r = s * r_tilde
    with np.errstate(all="ignore"):
        u = problem.W @ r + problem.q
    extras = dict(extras)
    extras["status"] = _STATUS_TEXT[status]
    if not math.isfinite(error):
        error = math.inf  # never NaN: an overflowed residual reads as "infinitely wrong"
    if not np.all(np.isfinite(u)):
        extras["velocity_overflow"] = True
        u = np.nan_to_num(u, nan=np.inf)
    converged = status == STATUS_CONVERGED
    if status == STATUS_NAN:
        extras["reason"] = "NaN/inf during the sweep; reaction is the best finite iterate"
    elif not converged:
        extras["reason"] = (
            f"{_STATUS_TEXT.get(status, 'not converged')}: error {error:.3g} > tol after {iterations} iterations"
        )
    r.setflags(write=False)
    u.setflags(write=False)
    return ContactSolution(
        reaction=r,
        velocity=u,
        error=float(error),
        iterations=int(iterations),
        converged=converged,
        time_s=time.perf_counter() - t0,
        solver=solver,
        extras=extras,
        problem=problem,
    )


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
        if st == STATUS_NAN:
            status = STATUS_NAN
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

    Parameters
    ----------
    problem : ContactProblem
        From :func:`build_problem`.
    r0 : array_like, shape (m,), optional
        Warm start (e.g. the previous time step's impulses); zeros by default.
    tol : float
        Stop when the FCLib residual is ``≤ tol``.
    max_iter : int
        Cap on sweeps.
    omega : float
        Sweep relaxation ``0 < ω < 2``.
    time_limit : float, optional
        Wall-clock limit [s] (checked between chunks of sweeps; ``None``: no limit).
    stall_window : int, optional
        Stop when the best residual gained less than 10 % over this many sweeps.

    Returns
    -------
    ContactSolution
        The best iterate seen (lowest residual, not necessarily the last). ``converged`` is
        ``False`` (with ``extras["reason"]``) when the cap, the time limit or stagnation
        stopped the sweeps, or a non-finite value appeared.
    """
    _check_settings(tol, max_iter, omega)
    budget = Budget.start(time_limit)
    t0 = time.perf_counter()
    arrays = kernel_arrays(problem)
    r = _initial_scaled(problem, r0)
    u = np.empty(problem.size)
    err = error_kernel(*arrays, r, u)  # type: ignore[call-arg]  # numba dispatcher
    if not math.isfinite(err):  # the warm start overflows: report it rather than sweep from it
        run = NsgsRun(r, math.inf, 0, STATUS_NAN, 0, np.zeros(0))
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
    if status == STATUS_NAN and math.isfinite(run.best_err) and run.best_err <= tol:
        status = STATUS_CONVERGED
    return _finish(problem, run.best_r, run.best_err, run.iterations, status, t0, "nsgs", extras)


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

    Parameters
    ----------
    problem, r0, tol, max_iter, omega
        As :func:`solve_nsgs`.
    time_limit : float, optional
        Wall-clock limit [s], checked before every contact of a sweep (a sweep of a large problem
        takes seconds here); a sweep cut short is dropped. ``None``: no limit.

    Returns
    -------
    ContactSolution
        With ``solver == "nsgs-numpy"``: the best iterate after a whole sweep (lowest residual).
    """
    _check_settings(tol, max_iter, omega)
    budget = Budget.start(time_limit)
    t0 = time.perf_counter()
    Wt_sparse, qt = problem.scaled()
    Wt = sp.csr_matrix(Wt_sparse)
    s = problem.row_scale
    r = _initial_scaled(problem, r0)
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
            status = STATUS_NAN
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
    return _finish(problem, best_r, best, it, status, t0, "nsgs-numpy", extras)
