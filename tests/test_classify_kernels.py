"""The classifier's compiled NNLS against fixplan.nnls (Lawson–Hanson in NumPy) and its KKT conditions."""

import numpy as np
import pytest

import fixplan
from fixplan.jamming import _classify_kernels as kernels
from fixplan.jamming.classify import Classifier
from fixplan.locating import contact_set
from fixplan.nnls import nnls


def _tol(A):
    return 10.0 * np.finfo(float).eps * max(A.shape) * max(float(np.abs(A).sum(axis=0).max()), 1.0)


@pytest.mark.parametrize("shape", [(6, 6), (6, 3), (3, 3), (6, 10), (12, 5)])
def test_compiled_nnls_matches_the_numpy_one_and_kkt(rng, shape):
    m, n = shape
    for _ in range(200):
        A = rng.normal(size=(m, n))
        b = rng.normal(size=m) * 10.0 ** rng.uniform(-3, 3)
        x, res, ok = kernels.nnls(A, b, 3 * n, _tol(A))
        x_ref, res_ref = nnls(A, b)
        if not ok:  # only for dependent columns (n > m), where the caller falls back
            assert n > m
            continue
        scale = np.linalg.norm(b)
        assert np.all(x >= 0.0)
        assert res == pytest.approx(res_ref, rel=1e-9, abs=1e-12 * scale)
        if n <= m:  # full column rank: the minimizer is unique
            assert np.allclose(x, x_ref, rtol=1e-8, atol=1e-10 * max(1.0, np.abs(x_ref).max()))
        g = A.T @ (A @ x - b)  # KKT: gradient ≥ 0 on the free set, 0 on the positive one
        assert np.all(g >= -1e-9 * scale * np.abs(A).max())
        assert np.all(np.abs(g[x > 0]) <= 1e-9 * scale * np.abs(A).max())


def test_classifier_normal_balance_uses_the_same_answer():
    """On the default fixture's six contacts the compiled NNLS gives fixplan.nnls's residual."""
    fx = fixplan.load(fixplan.default_fixture_path())
    clf = Classifier(contact_set(fx, "goal", None), fx.gravity_wrench(), tolerances=fx.tolerances)
    rng = np.random.default_rng(3)
    for _ in range(300):
        w = np.r_[rng.uniform(-40, 40, 3), rng.uniform(-1, 1, 3)]
        rhs = -(clf.builder.C @ (w / np.linalg.norm(w)))
        x, res, ok = kernels.nnls(clf._normal_matrix, rhs, 50 * 6 + 50, clf._nnls_tol)
        x_ref, res_ref = nnls(clf._normal_matrix, rhs, maxiter=50 * 6 + 50)
        assert ok
        assert res == pytest.approx(res_ref, rel=1e-9, abs=1e-13)
        assert np.allclose(x, x_ref, rtol=1e-9, atol=1e-12)
