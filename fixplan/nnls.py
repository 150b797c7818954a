"""Non-negative least squares for small dense problems: ``min ‖A x − b‖  s.t.  x ≥ 0``.

The Lawson–Hanson active-set method (Lawson & Hanson, *Solving Least Squares Problems*, 1974,
ch. 23), for the few dozen unknowns of a contact set (normal forces of the locators, the hold
push). It is here rather than ``scipy.optimize.nnls`` because importing ``scipy.optimize``
costs 0.3–1 s per process (it pulls in ``scipy.fft``, ``scipy.special``, ``scipy.stats``…), a
fifth of a whole ``fixplan solve`` of a 2D fixture; the answers agree to rounding
(``tests/test_nnls.py``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def nnls(A: ArrayLike, b: ArrayLike, maxiter: int | None = None, tol: float | None = None) -> tuple[FloatArray, float]:
    """The solution ``x ≥ 0`` and the residual norm ``‖A x − b‖`` (as ``scipy.optimize.nnls``).

    ``maxiter`` bounds the outer iterations (default ``3 n``); ``tol`` is the dual feasibility
    tolerance (default ``10 ε max(m, n) ‖A‖₁``). On reaching ``maxiter`` the current feasible
    iterate is returned: it is never worse than ``x = 0``.
    """
    A = np.asarray(A, dtype=float)
    b = np.asarray(b, dtype=float)
    if A.ndim != 2 or b.shape != (A.shape[0],):
        raise ValueError(f"nnls expects A (m, n) and b (m,), got {A.shape} and {b.shape}")
    m, n = A.shape
    x = np.zeros(n)
    if n == 0:
        return x, float(np.linalg.norm(b))
    if tol is None:
        tol = 10.0 * np.finfo(float).eps * max(m, n) * max(float(np.abs(A).sum(axis=0).max()), 1.0)
    maxiter = 3 * n if maxiter is None else int(maxiter)
    passive = np.zeros(n, dtype=bool)
    w = A.T @ (b - A @ x)
    for _ in range(maxiter):
        free = ~passive
        if not free.any() or float(w[free].max()) <= tol:
            break
        j = int(np.argmax(np.where(free, w, -np.inf)))
        passive[j] = True
        while True:
            z = np.zeros(n)
            z[passive] = np.linalg.lstsq(A[:, passive], b, rcond=None)[0]
            if np.all(z[passive] > 0.0):
                x = z
                break
            # step back to the boundary: the largest α keeping x + α (z − x) ≥ 0
            blocking = passive & (z <= 0.0)
            alpha = float(np.min(x[blocking] / (x[blocking] - z[blocking])))
            x = x + alpha * (z - x)
            passive &= x > tol
            x[~passive] = 0.0
            if not passive.any():
                break
        w = A.T @ (b - A @ x)
    return x, float(np.linalg.norm(A @ x - b))


__all__ = ["nnls"]
