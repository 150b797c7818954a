"""The reference path: the jamming questions written as ordinary cvxpy models.

Written from the mechanics directly (contact forces as vectors per contact, friction cones
with ``cp.SOC``), not from :mod:`.programs`' matrices, so agreement between the two paths is
a real check of both.
"""

from __future__ import annotations

import time

import numpy as np
from numpy.typing import NDArray

from fixplan.jamming.backends import ConeSolution
from fixplan.jamming.programs import force_cone_violation
from fixplan.kinematics import ContactSet
from fixplan.settings import DEFAULT_TOLERANCES

FloatArray = NDArray[np.float64]


def least_residual(
    cs: ContactSet, w_hat: FloatArray, P: FloatArray, C: FloatArray, eps: float = DEFAULT_TOLERANCES.cone_eps
) -> tuple[ConeSolution, FloatArray]:
    """``min ‖P C (ŵ + Σ J_iᵀ λ_i)‖`` over ``λ_i`` in the exact friction cones.

    Returns the solution (``x`` = stacked full contact vectors λ) and λ itself.
    """
    import cvxpy as cp

    lambdas = []
    constraints = []
    total = 0
    for contact in cs.contacts:
        lam = cp.Variable(contact.size)
        lambdas.append(lam)
        mu = contact.friction
        if contact.dimension == 2:
            constraints += [lam[0] >= 0, cp.abs(lam[1]) <= mu * lam[0]]
        elif contact.soft:
            constraints += [cp.SOC(mu * lam[0], cp.hstack([lam[1], lam[2], lam[3] / contact.torsion_m]))]
        else:
            constraints += [cp.SOC(mu * lam[0], lam[1:3])]
        if contact.dimension == 3:
            constraints += [lam[0] >= 0]
        total += contact.size
    J = cs.J
    expr = np.asarray(w_hat, dtype=float)
    for lam, offset, contact in zip(lambdas, cs.offsets, cs.contacts, strict=True):
        expr = expr + J[offset : offset + contact.size].T @ lam
    t = cp.Variable()
    problem = cp.Problem(cp.Minimize(t), [cp.SOC(t, P @ C @ expr), *constraints])
    t0 = time.perf_counter()
    problem.solve(solver=cp.CLARABEL, tol_gap_abs=eps, tol_gap_rel=eps, tol_feas=eps)
    elapsed = time.perf_counter() - t0
    status = str(problem.status)
    solved = status in ("optimal", "optimal_inaccurate")
    lam_full = (
        np.concatenate(
            [np.asarray(lam.value if lam.value is not None else np.zeros(lam.shape)).ravel() for lam in lambdas]
        )
        if lambdas
        else np.zeros(0)
    )
    value = float(t.value) if t.value is not None else float("inf")
    iters = int(problem.solver_stats.num_iters or 0) if problem.solver_stats else 0
    known = solved and t.value is not None and all(lam.value is not None for lam in lambdas)
    violation = (
        cone_violation(cs, lam_full, value, P @ C @ (np.asarray(w_hat, dtype=float) + J.T @ lam_full))
        if known
        else None
    )
    return ConeSolution(lam_full, value, solved, status, iters, elapsed, violation), lam_full


def cone_violation(cs: ContactSet, lam: FloatArray, t: float, residual: FloatArray) -> float:
    """Largest violation of the model's cones at its answer: each friction cone, and ``‖residual‖ ≤ t``.

    Written from the mechanics like the model (``λ_n ≥ 0``, ``‖λ_t‖ ≤ μ λ_n``, the soft finger's
    spin scaled by its torsion radius), not from :mod:`.programs`' cone rows.
    """
    worst = float(np.linalg.norm(residual)) - t
    return max(worst, force_cone_violation(cs, lam), 0.0)
