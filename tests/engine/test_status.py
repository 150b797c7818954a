"""One status vocabulary: the compiled sweep, the time step and the Python drivers say how a solve
ended with the codes of ``fixplan.engine.status``, and nothing else in the engine defines them."""

from __future__ import annotations

import ast

import numpy as np
from conftest import ROOT

from fixplan.engine import local, status
from fixplan.engine.nsgs import diagonal_blocks, nsgs_kernel, solve_nsgs
from fixplan.engine.problem import build_problem, kernel_arrays


def _two_coupled_contacts():
    """Two frictionless-looking planar contacts pushed in (q_n = −1) whose normals couple (W_n1n2 = 0.9).

    Closed form (both close, no slip): r_n = −W_nn⁻¹ q_n = (1, 1) / 1.9 on the normal rows."""
    W = np.eye(4)
    W[0, 2] = W[2, 0] = 0.9
    return build_problem(W, [-1.0, 0.0, -1.0, 0.0], mu=0.5, dims=2)


def _kernel(problem, max_iter):
    arrays = kernel_arrays(problem)
    indptr, indices, data, q, mu, offsets, dims = arrays
    diag = diagonal_blocks(indptr, indices, data, offsets, dims)
    r = np.zeros(problem.size)
    best_r, best = r.copy(), np.array([np.inf])
    it, err, st, _ = nsgs_kernel(*arrays, diag, r, 1e-12, max_iter, 1.0, np.empty(max_iter), best_r, best)
    return it, err, st, r


def test_the_compiled_sweep_returns_the_engines_codes():
    """One Gauss–Seidel sweep cannot solve the coupled pair (cap: STATUS_MAX_ITER); many reach r_n = 1/1.9."""
    problem = _two_coupled_contacts()
    it, err, st, _ = _kernel(problem, 1)
    assert (it, st) == (1, status.STATUS_MAX_ITER) and err > 1e-12
    it, err, st, r = _kernel(problem, 500)
    assert st == status.STATUS_CONVERGED and err <= 1e-12 and it < 500
    np.testing.assert_allclose(r, [1 / 1.9, 0.0, 1 / 1.9, 0.0], atol=1e-10)


def test_the_python_driver_words_the_same_codes():
    problem = _two_coupled_contacts()
    capped = solve_nsgs(problem, tol=1e-12, max_iter=1)
    assert not capped.converged and capped.extras["status"] == status.STATUS_TEXT[status.STATUS_MAX_ITER]
    done = solve_nsgs(problem, tol=1e-12)
    assert done.converged and done.extras["status"] == status.STATUS_TEXT[status.STATUS_CONVERGED]
    np.testing.assert_allclose(done.reaction[[0, 2]], 1 / 1.9, rtol=1e-9)


def test_status_codes_have_one_home_and_regimes_another_name():
    """No engine module but status.py assigns a STATUS_ constant; the local solvers' codes are regimes."""
    homes = {}
    for path in sorted((ROOT / "fixplan" / "engine").glob("*.py")):
        for node in ast.parse(path.read_text()).body:
            targets = (
                node.targets
                if isinstance(node, ast.Assign)
                else [node.target]
                if isinstance(node, ast.AnnAssign)
                else []
            )
            for t in targets:
                for name in [e.id for e in ast.walk(t) if isinstance(e, ast.Name)]:
                    if name.startswith("STATUS_"):
                        homes.setdefault(name, []).append(path.name)
    assert {name: files for name, files in homes.items() if files != ["status.py"]} == {}
    assert set(status.STATUS_TEXT) == {0, 1, 2, 3, 4}
    assert local.REGIME_NAMES == {
        local.OPEN: "open",
        local.STICK: "stick",
        local.SLIDE: "slide",
        local.FAILED: "failed",
    }
