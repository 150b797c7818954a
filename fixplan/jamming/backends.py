"""Solving :class:`~fixplan.jamming.programs.ConeProgram` objects.

Two paths that must agree (``tests/test_jamming_backends.py``):

- ``"clarabel"``: the program's matrices go to Clarabel directly; a solver object is built once
  per program and later wrenches only update ``b`` (Clarabel's ``update``), which removes the
  modelling layer's overhead from batch classification;
- ``"cvxpy"``: the same question written as an ordinary cvxpy model (see :mod:`.cvx`), solved
  by cvxpy with Clarabel.

Backends' statuses and exceptions never leak: a failed solve is reported in
:class:`ConeSolution` (``solved = False`` with the raw status kept in ``status``).
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fixplan.jamming.programs import ConeProgram, cone_violation_of
from fixplan.settings import DEFAULT

FloatArray = NDArray[np.float64]

BACKENDS = ("clarabel", "cvxpy")


@dataclass(frozen=True)
class ConeSolution:
    """The answer of one cone program, with its quality."""

    x: FloatArray
    value: float
    solved: bool
    status: str
    iterations: int
    solve_time_s: float
    cone_violation: float | None  # largest violation of the program's cones at x; None: no answer to measure


@functools.lru_cache(maxsize=256)
def _clarabel_cones(cones: tuple[tuple[str, int], ...]) -> list:
    """Clarabel's cone objects for a program's ``cones`` (shared: Clarabel copies them into each solver)."""
    import clarabel

    out = []
    for kind, dim in cones:
        if kind == "nonneg":
            out.append(clarabel.NonnegativeConeT(dim))
        elif kind == "soc":
            out.append(clarabel.SecondOrderConeT(dim))
        else:
            out.append(clarabel.ZeroConeT(dim))
    return out


@functools.lru_cache(maxsize=8)
def clarabel_settings(eps: float):
    """Clarabel settings for the jamming programs (quiet, tight tolerances).

    One object per ``eps``, shared: Clarabel copies the settings into each solver it builds.
    """
    import clarabel

    s = clarabel.DefaultSettings()
    s.verbose = False
    s.tol_gap_abs = eps
    s.tol_gap_rel = eps
    s.tol_feas = eps
    s.tol_ktratio = DEFAULT.numerics.clarabel_ktratio
    s.presolve_enable = False  # keeps the data layout fixed so ``update`` is allowed
    s.max_iter = DEFAULT.numerics.clarabel_max_iter
    return s


class CscArrays:
    """A compressed-sparse-column matrix as Clarabel reads it: ``data``, ``indices``, ``indptr``, ``shape``.

    The arrays ``scipy.sparse.csc_matrix`` would hold (canonical: sorted, no duplicates), without
    building one: scipy's constructor checks were the largest share of a tiny program's set-up
    (the search builds five programs per call, hundreds of calls per plan), and not importing
    ``scipy.sparse`` saves a tenth of a second per process.
    """

    __slots__ = ("data", "indices", "indptr", "shape")
    has_canonical_format = True

    def __init__(self, data: FloatArray, indices: NDArray[np.int32], indptr: NDArray[np.int32], shape: tuple[int, int]):
        self.data, self.indices, self.indptr, self.shape = data, indices, indptr, shape


@functools.lru_cache(maxsize=64)
def _zero_csc(n: int) -> CscArrays:
    """The ``n × n`` zero matrix (the programs are linear: ``P = 0``); shared, never modified."""
    return CscArrays(np.zeros(0), np.zeros(0, dtype=np.int32), np.zeros(n + 1, dtype=np.int32), (n, n))


def csc_from_dense(A: FloatArray) -> CscArrays:
    """The arrays of ``scipy.sparse.csc_matrix(A)`` for a dense ``A``, built directly (same arrays, bit for bit)."""
    At = A.T
    nonzero = At != 0.0
    indptr = np.zeros(A.shape[1] + 1, dtype=np.int32)
    np.cumsum(nonzero.sum(axis=1), out=indptr[1:])
    indices = np.nonzero(nonzero)[1].astype(np.int32)
    return CscArrays(At[nonzero], indices, indptr, (int(A.shape[0]), int(A.shape[1])))


class ClarabelProgram:
    """One program handed to Clarabel once; :meth:`solve` takes a new ``b`` each time."""

    def __init__(self, program: ConeProgram, eps: float = DEFAULT.tolerances.cone_eps):
        import clarabel

        self.program = program
        n = program.A.shape[1]
        self._P = _zero_csc(n)
        self._A = csc_from_dense(np.asarray(program.A, dtype=np.float64))
        self._cones = _clarabel_cones(tuple(program.cones))
        self._settings = clarabel_settings(eps)
        self._solver = clarabel.DefaultSolver(
            self._P, program.c, self._A, program.b.copy(), self._cones, self._settings
        )
        self._fresh = True

    def solve(self, b: FloatArray) -> ConeSolution:
        import clarabel

        t0 = time.perf_counter()
        if not self._fresh:
            try:
                self._solver.update(b=b)
            except Exception:  # noqa: BLE001 - fall back to a fresh solver, same data otherwise
                self._solver = clarabel.DefaultSolver(self._P, self.program.c, self._A, b, self._cones, self._settings)
        else:
            self._solver.update(b=b)
        self._fresh = False
        sol = self._solver.solve()
        elapsed = time.perf_counter() - t0
        status = str(sol.status)
        solved = status in ("Solved", "AlmostSolved")
        x = np.asarray(sol.x, dtype=float)
        prog = self.program
        violation: float | None = None
        if not np.all(np.isfinite(x)):
            x = np.zeros_like(self.program.c)
            solved = False
        else:
            violation = cone_violation_of(b - prog.A @ x, prog.cones)
        return ConeSolution(x, float(prog.c @ x), solved, status, int(sol.iterations), elapsed, violation)
