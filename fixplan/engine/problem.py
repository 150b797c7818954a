"""The local frictional contact problem ``u = W r + q``, its solution and its residual: what every solver shares.

The problem (docs/math.md, "Transfer equations" and "Contact laws"; FCLib's "local" problem): find
the impulses ``r`` and velocities ``u = W r + q`` such that every contact ``j`` obeys its law
``K_μj ∋ r_j ⊥ ũ_j ∈ K_μj*``. Contact ``j`` occupies rows ``offset[j] : offset[j] + dim[j]``,
ordered ``(normal, tangent1[, tangent2[, spin]])``; ``dim`` is 2 (planar Coulomb), 3 (Coulomb)
or 4 (soft finger with torsion radius ``e_r``).

Soft-finger contacts are solved in the scaled variables of :mod:`fixplan.engine.local`:
with ``s = 1`` on every row except ``s = e_r`` on spin rows, ``W̃ = diag(s) W diag(s)``,
``q̃ = s ∘ q``, ``r = s ∘ r̃``, ``ũ = s ∘ u``. The scaled problem has only second-order cones,
so the sweep, the residual and the SOCP solver see one kind of cone.

Every solver stops on the Siconos/FCLib residual (natural map, ``ρ = 1``), in the scaled
variables::

    err = sqrt(Σ_j ‖r̃_j − Proj_{K_μj}(r̃_j − ũ_j − μ_j‖ũ_t,j‖ e_n)‖²) / max(‖q̃‖, ‖r̃‖, ‖ũ‖)

(0 when the denominator is 0, i.e. ``q = 0`` and ``r = 0``). :func:`fclib_error` is its plain
NumPy version, the independent check of every solver; the compiled one the sweeps stop on is
:func:`fixplan.engine.residual.fclib_error_rows`.

Here: :class:`ContactProblem` and its builder :func:`build_problem`, :class:`ContactSolution`,
:class:`ContactSolver` (the one signature of the solvers, with their shared parameters' meaning),
:func:`fclib_error`, and the helpers every solver (:mod:`.nsgs`, :mod:`.socp`, :mod:`.newton`,
:mod:`.auto`) uses: :func:`check_settings`, :func:`initial_scaled`, :func:`kernel_arrays`,
:func:`stalled` and :func:`finish`, which turns a solver's scaled iterate and
:mod:`~fixplan.engine.status` code into a :class:`ContactSolution`. No numba.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import scipy.sparse as sp

from fixplan.engine.status import STATUS_CONVERGED, STATUS_NONFINITE, STATUS_TEXT
from fixplan.errors import InputError

DEFAULT_TOL = 1e-8
"""Default stopping tolerance on the FCLib residual (relative, dimensionless)."""
DEFAULT_STALL_RATIO = 0.9
"""A run stalls when its best residual did not drop below this fraction of the best residual
``window`` iterations earlier (a 10 % gain per window)."""


def stalled(marks: list[float], error: float, window: int | None, ratio: float = DEFAULT_STALL_RATIO) -> bool:
    """Stagnation: ``error`` has not dropped below ``ratio`` × the mark ``window`` rounds back."""
    return window is not None and 0 < window < len(marks) and error > ratio * marks[-1 - window]


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


class ContactSolver(Protocol):
    """The signature every solver of :data:`fixplan.engine.SOLVERS` shares, and what its parameters mean.

    ``solver(problem, r0=None, tol=..., max_iter=..., time_limit=..., **its own options)``. Each
    solver's docstring documents only what differs: what ``max_iter`` counts, where
    ``time_limit`` is checked, and its own options.

    Parameters
    ----------
    problem : ContactProblem
        From :func:`build_problem`.
    r0 : array_like, shape (m,), optional
        Warm start (e.g. the previous time step's impulses, or another solver's answer); zeros
        by default.
    tol : float
        Stop when the FCLib residual is ``≤ tol``.
    max_iter : int
        Cap on the solver's iterations (sweeps, rounds or steps: each solver says which).
    time_limit : float, optional
        Wall-clock limit [s] (``None``: no limit); each solver says where it checks it.

    Returns
    -------
    ContactSolution
        The best iterate seen (lowest residual, not necessarily the last), with its residual.
        ``converged`` is ``False`` (with ``extras["reason"]``) when a cap, the time limit,
        stagnation or a non-finite value stopped the solver.

    Notes
    -----
    Every solver but ``auto`` also takes ``stall_window`` (int, optional): stop when the best
    residual gained less than 10 % (:data:`DEFAULT_STALL_RATIO`) over this many iterations.
    """

    def __call__(
        self,
        problem: ContactProblem,
        r0: Any = None,
        *,
        tol: float = ...,
        max_iter: int = ...,
        time_limit: float | None = ...,
    ) -> ContactSolution: ...


def fclib_error(problem: ContactProblem, reaction: np.ndarray) -> float:
    """FCLib/Siconos residual (natural map, ``ρ = 1``) of ``reaction``, plain NumPy.

    Parameters
    ----------
    problem : ContactProblem
        The problem.
    reaction : ndarray, shape (m,)
        Impulses ``r`` in the problem's own (unscaled) variables.

    Returns
    -------
    float
        ``sqrt(Σ_j ‖r̃_j − Proj(r̃_j − ũ_j^mod)‖²) / max(‖q̃‖, ‖r̃‖, ‖ũ‖)``, computed in the
        scaled variables (identical to the unscaled ones without soft fingers).
    """
    r = np.asarray(reaction, dtype=float)
    s = problem.row_scale
    u_tilde = s * (problem.W @ r + problem.q)
    r_tilde = np.divide(r, s, out=np.zeros_like(r), where=s > 0)
    q_tilde = s * problem.q
    total = 0.0
    for j in range(problem.n_contacts):
        o, d, mu = problem.offsets[j], problem.dims[j], problem.mu[j]
        rj, uj = r_tilde[o : o + d], u_tilde[o : o + d]
        x = rj - uj
        x[0] -= mu * np.linalg.norm(uj[1:])
        xn, nt = x[0], np.linalg.norm(x[1:])
        if mu * nt <= -xn:
            proj = np.zeros(d)
        elif nt <= mu * xn:
            proj = x
        else:
            pn = (xn + mu * nt) / (1.0 + mu * mu)
            proj = np.concatenate(([pn], mu * pn * x[1:] / nt))
        total += float(np.sum((rj - proj) ** 2))
    scale = max(np.linalg.norm(q_tilde), np.linalg.norm(r_tilde), np.linalg.norm(u_tilde))
    return math.sqrt(total) / float(scale) if scale > 0 else math.sqrt(total)


# --------------------------------------------------------------------------- shared by the solvers


def csr_arrays(W: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
        *csr_arrays(Wt),
        np.array(qt, dtype=np.float64),
        np.array(problem.mu, dtype=np.float64),
        np.array(problem.offsets, dtype=np.int64),
        np.array(problem.dims, dtype=np.int64),
    )


def initial_scaled(problem: ContactProblem, r0: Any) -> np.ndarray:
    """A solver's start ``r̃ = r0 / s`` in the scaled variables (zeros without ``r0``), validated.

    Raises
    ------
    InputError
        When ``r0`` has the wrong length or is not finite.
    """
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


def check_settings(tol: float, max_iter: int, omega: float) -> None:
    """Validate a solver's common options: ``tol ≥ 0`` finite, ``max_iter ≥ 0``, ``0 < ω < 2``.

    Raises
    ------
    InputError
        Naming the option and what was expected.
    """
    if not (tol >= 0 and math.isfinite(tol)):
        raise InputError(f"expected a finite tol ≥ 0, got {tol}")
    if int(max_iter) < 0:
        raise InputError(f"expected max_iter ≥ 0, got {max_iter}")
    if not (0.0 < omega < 2.0):
        raise InputError(f"expected relaxation 0 < ω < 2, got {omega}")


def finish(
    problem: ContactProblem,
    r_tilde: np.ndarray,
    error: float,
    iterations: int,
    status: int,
    t0: float,
    solver: str,
    extras: dict,
) -> ContactSolution:
    """The :class:`ContactSolution` of a solver's scaled iterate ``r̃`` that ended with ``status``.

    ``r = s ∘ r̃`` and ``u = W r + q`` in the problem's own variables (read-only), ``converged``
    when ``status`` is :data:`~fixplan.engine.status.STATUS_CONVERGED`, ``extras["status"]`` its
    words and ``extras["reason"]`` why not otherwise; a non-finite ``error`` reads as ``inf``.
    ``t0`` is the solve's start on :func:`time.perf_counter`.
    """
    s = problem.row_scale
    r = s * r_tilde
    with np.errstate(all="ignore"):
        u = problem.W @ r + problem.q
    extras = dict(extras)
    extras["status"] = STATUS_TEXT[status]
    if not math.isfinite(error):
        error = math.inf  # never NaN: an overflowed residual reads as "infinitely wrong"
    if not np.all(np.isfinite(u)):
        extras["velocity_overflow"] = True
        u = np.nan_to_num(u, nan=np.inf)
    converged = status == STATUS_CONVERGED
    if status == STATUS_NONFINITE:
        extras["reason"] = "NaN/inf during the sweep; reaction is the best finite iterate"
    elif not converged:
        extras["reason"] = (
            f"{STATUS_TEXT.get(status, 'not converged')}: error {error:.3g} > tol after {iterations} iterations"
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
