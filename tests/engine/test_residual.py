"""The one compiled FCLib residual against the one NumPy residual.

:func:`fixplan.engine.residual.fclib_error_rows` (what every compiled sweep stops on, through
:func:`fixplan.engine.nsgs.error_kernel` for sparse ``W``) must give the number
:func:`fixplan.engine.problem.fclib_error` gives, on the FCLib library's problems (with ``../shared``)
and on random problems of every cone kind, at the origin, at random impulses and near a solution.
The residual is relative (divided by ``max(‖q‖, ‖r‖, ‖u‖)``), so near a solution the two agree to
rounding of the O(1) terms (``abs=1e-14``), elsewhere to ``rel=1e-12``.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from fixplan.engine.fclib import read_fclib
from fixplan.engine.nsgs import error_kernel, solve_nsgs
from fixplan.engine.problem import build_problem, fclib_error, kernel_arrays
from fixplan.engine.residual import fclib_error_rows


def _compiled(problem, reaction):
    """The compiled residual of ``reaction`` (unscaled), through the sparse kernel."""
    arrays = kernel_arrays(problem)
    s = problem.row_scale
    r_scaled = np.divide(reaction, s, out=np.zeros(problem.size), where=s > 0)
    return error_kernel(*arrays, r_scaled, np.empty(problem.size))


def _reactions(problem, rng):
    m = problem.size
    yield np.zeros(m)
    yield rng.normal(size=m)
    yield solve_nsgs(problem, tol=1e-10, max_iter=300).reaction  # near a solution: small residual


def _random_problem(rng, dim):
    n_c = 5
    m = dim * n_c
    A = rng.normal(size=(m, 2 * m))
    W = A @ A.T / m + 1e-3 * np.eye(m)
    return build_problem(sp.csr_matrix(W), rng.normal(size=m), rng.uniform(0.1, 0.9, n_c), dims=dim,
                         torsion_radius=0.02 if dim == 4 else None)  # fmt: skip


@pytest.mark.parametrize("dim", [2, 3, 4])
def test_compiled_residual_equals_numpy_on_random_problems(rng, dim):
    problem = _random_problem(rng, dim)
    for r in _reactions(problem, rng):
        assert _compiled(problem, r) == pytest.approx(fclib_error(problem, r), rel=1e-12, abs=1e-14)


def test_compiled_residual_equals_numpy_on_the_fclib_library(fclib_dir, rng):
    files = sorted(fclib_dir.glob("*.hdf5"))
    assert files
    for path in files:
        problem = read_fclib(path).problem
        for r in _reactions(problem, rng):
            assert _compiled(problem, r) == pytest.approx(fclib_error(problem, r), rel=1e-12, abs=1e-14), path.name


def test_dense_rows_of_a_workspace_give_the_same_residual(rng):
    """The dense sweep's call: leading rows of larger buffers, ``u`` given."""
    problem = _random_problem(rng, 3)
    r = rng.normal(size=problem.size)
    W = problem.W.toarray()
    u = W @ r + problem.q
    pad = 6
    got = fclib_error_rows(
        np.r_[problem.q, np.zeros(pad)], np.r_[problem.mu, 0.5], np.r_[problem.offsets, 0], np.r_[problem.dims, 3],
        problem.n_contacts, problem.size, np.r_[r, np.ones(pad)], np.r_[u, np.ones(pad)], np.empty(4), np.empty(4),
    )  # fmt: skip
    assert got == pytest.approx(fclib_error(problem, r), rel=1e-12)


def test_residual_is_zero_at_a_solution_and_scale_free():
    """One frictionless contact pressed by q = -1 with W = 1: r = 1 solves it; r = 0 has residual 1 / 1."""
    problem = build_problem(sp.csr_matrix(np.eye(3)), np.array([-1.0, 0.0, 0.0]), 0.5, dims=3)
    assert fclib_error(problem, np.array([1.0, 0.0, 0.0])) == 0.0
    assert _compiled(problem, np.array([1.0, 0.0, 0.0])) == 0.0
    assert _compiled(problem, np.zeros(3)) == pytest.approx(1.0, rel=1e-15)
    assert fclib_error(problem, np.zeros(3)) == pytest.approx(1.0, rel=1e-15)
