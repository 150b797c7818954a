"""fixplan.nnls against scipy.optimize.nnls and the KKT conditions of the problem."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import nnls as scipy_nnls

from fixplan.nnls import nnls


@pytest.mark.parametrize("seed", range(200))
def test_agrees_with_scipy_and_satisfies_kkt(seed):
    rng = np.random.default_rng(seed)
    m, n = int(rng.integers(1, 13)), int(rng.integers(1, 13))
    A = rng.normal(size=(m, n))
    if seed % 3 == 0 and n > 1:
        A[:, -1] = A[:, 0]  # rank-deficient: duplicate columns, as two locators on one face
    b = rng.normal(size=m) * 10.0 ** rng.uniform(-3, 3)
    x, res = nnls(A, b)
    assert np.all(x >= 0.0)
    assert res == pytest.approx(float(np.linalg.norm(A @ x - b)), rel=1e-12, abs=1e-14)
    # KKT: the gradient w = Aᵀ(b − A x) is ≤ 0 everywhere and 0 where x > 0
    w = A.T @ (b - A @ x)
    scale = np.abs(A).sum() * (np.abs(b).max() + 1e-300)
    assert w.max() <= 1e-9 * scale
    assert np.abs(w[x > 1e-12 * (np.abs(x).max() + 1e-300)]).max(initial=0.0) <= 1e-9 * scale
    x_ref, res_ref = scipy_nnls(A, b)
    assert res == pytest.approx(res_ref, rel=1e-8, abs=1e-12 * scale)


def test_closed_forms():
    # unconstrained optimum feasible: the least-squares solution
    A = np.array([[1.0, 0.0], [0.0, 2.0], [0.0, 0.0]])
    x, res = nnls(A, np.array([3.0, 4.0, 1.0]))
    assert np.allclose(x, [3.0, 2.0]) and res == pytest.approx(1.0)
    # a negative least-squares component is clamped to 0
    x, res = nnls(np.eye(2), np.array([1.0, -2.0]))
    assert np.allclose(x, [1.0, 0.0]) and res == pytest.approx(2.0)
    # no unknowns
    x, res = nnls(np.zeros((2, 0)), np.array([3.0, 4.0]))
    assert x.shape == (0,) and res == pytest.approx(5.0)


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError):
        nnls(np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError):
        nnls(np.zeros((3, 2)), np.zeros(2))
