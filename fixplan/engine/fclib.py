"""Read FCLib HDF5 frictional contact problems and solve them with the engine's solvers.

FCLib (https://frictionalcontactlibrary.github.io) stores one problem per HDF5 file:

- ``/fclib_local``: ``W`` (matrix group), ``vectors/q``, ``vectors/mu``, ``spacedim`` (2 or 3),
  optional ``info/{title,description,math_info}``; a mixed problem adds ``V``, ``R``,
  ``vectors/s`` (not supported here). The problem is ``u = W r + q`` with the Coulomb law.
- ``/fclib_global``: ``M``, ``H`` (matrix groups), ``vectors/{f,w,mu}``, ``spacedim``; with
  ``M v = H r + f`` and ``u = Hᵀ v + w``. Eliminating ``v``: ``W = Hᵀ M⁻¹ H`` and
  ``q = Hᵀ M⁻¹ f + w``. Equality constraints ``G``, ``b`` are not supported.
- ``/solution`` and ``/guesses`` may hold reference ``r``, ``u``, ``v`` (in the files at hand
  they are zeros, so they are not used).

A matrix group holds ``m``, ``n`` (rows, columns), ``nz``, ``nzmax``, ``p``, ``i``, ``x``
(FCLib's ``fclib_matrix``, a CSparse layout):

- ``nz == -1``: compressed columns — ``p`` column pointers (``n + 1``), ``i`` row indices;
- ``nz == -2``: compressed rows — ``p`` row pointers (``m + 1``), ``i`` column indices;
- ``nz >= 0``: triplets, ``nz`` entries. FCLib's header says ``p`` = rows and ``i`` = columns,
  but Siconos (which wrote the files distributed by FCLib) follows CSparse: ``i`` = rows and
  ``p`` = columns. In ``Box_Stacks-i0122-82-5.hdf5`` ``H`` is ``450 × 246`` with
  ``max(i) = 389`` and ``max(p) = 245``, so only the CSparse reading fits; it is used, and the
  other reading is taken only when the CSparse one does not fit the shape.

Contact vectors are ordered ``(normal, tangent1, tangent2)`` per contact, as in the engine.
"""

from __future__ import annotations

import inspect
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fixplan.engine.budget import DEFAULT_TIME_LIMIT_S, Budget
from fixplan.engine.nsgs import DEFAULT_TOL, ContactProblem, build_problem
from fixplan.errors import InputError


@dataclass(frozen=True, eq=False)
class FclibProblem:
    """An FCLib problem read from disk, as a local problem ``u = W r + q``.

    Attributes
    ----------
    problem : ContactProblem
        The local problem (global files are condensed).
    kind : str
        ``"local"`` or ``"global"`` (what the file stored).
    spacedim : int
        2 or 3.
    title : str
        ``info/title`` or ``""``.
    description : str
        ``info/description`` or ``""``.
    path : str
        Source file.
    """

    problem: ContactProblem
    kind: str
    spacedim: int
    title: str
    description: str
    path: str

    @property
    def n_contacts(self) -> int:
        """Number of contacts."""
        return self.problem.n_contacts


@dataclass(frozen=True, eq=False)
class FclibResult:
    """Outcome of :func:`solve_fclib_file`.

    Attributes
    ----------
    reaction : ndarray, shape (m,)
        Impulses ``r``.
    velocity : ndarray, shape (m,)
        ``u = W r + q``.
    error : float
        FCLib residual of ``reaction`` (natural map, ``ρ = 1``, relative).
    iterations : int
        Iterations of the solver that produced the answer (for ``auto``: all stages).
    converged : bool
        ``error ≤ tol``.
    time_s : float
        Solve time [s], reading excluded.
    solver : str
        Solver that produced the answer.
    n_contacts : int
        Number of contacts.
    kind : str
        ``"local"`` or ``"global"``.
    path : str
        The file.
    extras : dict
        Solver details (status, history, read time, ``reason`` when not converged).
    stages : tuple of dict
        For ``auto``: one entry per stage run (``method``, ``iterations``, ``start_error``,
        ``error``, ``time_s``, ``status``), in order; empty for the other solvers.
    """

    reaction: np.ndarray
    velocity: np.ndarray
    error: float
    iterations: int
    converged: bool
    time_s: float
    solver: str
    n_contacts: int
    kind: str
    path: str
    extras: dict
    stages: tuple = ()

    def to_json(self) -> dict[str, Any]:
        """The answer of ``fixplan fclib --json`` (without the file): quality, stages, reaction, velocity."""
        return {
            "kind": self.kind,
            "contacts": self.n_contacts,
            "solver": self.solver,
            "error": float(self.error),
            "iterations": int(self.iterations),
            "converged": bool(self.converged),
            "time_s": float(self.time_s),
            "reason": self.extras.get("reason", ""),
            "stages": list(self.stages),
            "reaction": [float(x) for x in self.reaction],
            "velocity": [float(x) for x in self.velocity],
        }


_MAX_DIM = 2**31 - 1  # FCLib stores indices as int32


def _node(group: Any, name: str, where: str) -> Any:
    """``group[name]``, or an :class:`InputError` naming the missing HDF5 path."""
    if name not in group:
        raise InputError(f"{where}/{name}: missing")
    return group[name]


def _dataset(group: Any, name: str, where: str) -> Any:
    import h5py

    node = _node(group, name, where)
    if not isinstance(node, h5py.Dataset):
        raise InputError(f"{where}/{name}: expected a dataset, found a group")
    return node


def _subgroup(group: Any, name: str, where: str, what: str) -> Any:
    import h5py

    node = _node(group, name, where)
    if not isinstance(node, h5py.Group):
        raise InputError(f"{where}/{name}: expected {what} (an HDF5 group), found a dataset")
    return node


def _numbers(group: Any, name: str, where: str, *, integer: bool) -> np.ndarray:
    """A dataset's values as a flat array, checked to be numeric and finite.

    ``integer``: the values must be integers (an integer dtype, or floats that are integral).
    Strings, compound types, complex numbers, NaN and inf are refused with the HDF5 path.
    """
    ds = _dataset(group, name, where)
    path = f"{where}/{name}"
    kind = ds.dtype.kind
    if kind not in "iuf" or ds.dtype.subdtype is not None:
        expected = "integers" if integer else "real numbers"
        raise InputError(f"{path}: expected {expected}, got HDF5 type {ds.dtype}")
    try:
        values = np.asarray(ds[()]).reshape(-1)
    except (OSError, ValueError, TypeError) as exc:
        raise InputError(f"{path}: unreadable ({exc})") from exc
    if kind == "f":
        if not np.all(np.isfinite(values)):
            raise InputError(f"{path}: expected finite numbers, found NaN or inf")
        if integer:
            if np.any(values != np.round(values)) or np.any(np.abs(values) > _MAX_DIM):
                raise InputError(f"{path}: expected integers, found non-integral values")
            return values.astype(np.int64)
        return values.astype(np.float64)
    if integer:
        if values.size and (int(values.max()) > _MAX_DIM or int(values.min()) < -_MAX_DIM):
            raise InputError(f"{path}: integers out of the int32 range")
        return values.astype(np.int64)
    return values.astype(np.float64)


def _scalar_int(group: Any, name: str, where: str) -> int:
    values = _numbers(group, name, where, integer=True)
    if values.shape[0] != 1:
        raise InputError(f"{where}/{name}: expected one integer, got {values.shape[0]} values")
    return int(values[0])


def _check_indices(values: np.ndarray, bound: int, path: str, what: str) -> None:
    if values.size and (int(values.min()) < 0 or int(values.max()) >= bound):
        bad = int(values.min()) if int(values.min()) < 0 else int(values.max())
        raise InputError(f"{path}: {what} index {bad} outside [0, {bound})")


def _check_pointers(p: np.ndarray, n_entries: int, path: str) -> int:
    """Compressed pointers: start at 0, never decrease, end within the stored entries."""
    if p[0] != 0:
        raise InputError(f"{path}: pointers must start at 0, got {int(p[0])}")
    steps = np.diff(p)
    if np.any(steps < 0):
        k = int(np.argmax(steps < 0))
        raise InputError(f"{path}: pointers must not decrease, got p[{k}]={int(p[k])} > p[{k + 1}]={int(p[k + 1])}")
    nnz = int(p[-1])
    if nnz > n_entries:
        raise InputError(f"{path}: last pointer {nnz} exceeds the {n_entries} stored entries")
    return nnz


def _matrix_group(node: Any, where: str) -> Any:
    import h5py

    if not isinstance(node, h5py.Group):
        raise InputError(f"{where}: expected an FCLib matrix group (m, n, nz, p, i, x), found a dense dataset")
    return node


def read_matrix(group: Any, where: str, shape: tuple[int, int] | None = None) -> sp.csr_matrix:
    """Read and validate an FCLib matrix group (CSC, CSR or triplet) as a CSR matrix.

    Every array is checked before SciPy builds the matrix: integer ``m``, ``n``, ``nz``,
    ``p``, ``i``; finite real ``x``; pointers starting at 0, non-decreasing, ending within the
    stored entries; every index inside the shape. (SciPy's own check skips index bounds, and
    an out-of-range index in a compiled loop reads or writes outside its arrays.)

    Parameters
    ----------
    group : h5py.Group
        The matrix group (holding ``m``, ``n``, ``nz``, ``p``, ``i``, ``x``).
    where : str
        Its name in error messages, e.g. ``"file.hdf5:/fclib_global/H"``.
    shape : tuple of int, optional
        The shape the caller expects (known from stored vectors): checked before any array
        of that size is allocated.

    Returns
    -------
    scipy.sparse.csr_matrix
        The matrix (duplicate triplets are summed).

    Raises
    ------
    InputError
        Naming the HDF5 path of the first bad item.
    """
    group = _matrix_group(group, where)
    m = _scalar_int(group, "m", where)
    n = _scalar_int(group, "n", where)
    if m < 0 or n < 0:
        raise InputError(f"{where}/m: expected a shape ≥ 0, got ({m}, {n})")
    if shape is not None and (m, n) != tuple(shape):
        raise InputError(f"{where}/m: expected shape {shape[0]}×{shape[1]} to match the vectors, got {m}×{n}")
    nz = _scalar_int(group, "nz", where)
    p = _numbers(group, "p", where, integer=True)
    i = _numbers(group, "i", where, integer=True)
    x = _numbers(group, "x", where, integer=False)
    if nz >= 0:
        for name, arr in (("p", p), ("i", i), ("x", x)):
            if arr.shape[0] < nz:
                raise InputError(f"{where}/{name}: expected nz={nz} triplet entries, got {arr.shape[0]}")
        p, i, x = p[:nz], i[:nz], x[:nz]
        # CSparse/Siconos: i rows, p columns; FCLib's header: p rows, i columns (module docstring)
        if nz == 0 or (i.min() >= 0 and p.min() >= 0 and i.max() < m and p.max() < n):
            rows, cols = i, p
        elif p.max() < m and i.max() < n and min(i.min(), p.min()) >= 0:
            rows, cols = p, i
        else:
            _check_indices(i, m, f"{where}/i", "row")
            _check_indices(p, n, f"{where}/p", "column")
            raise InputError(f"{where}: triplet indices exceed the shape ({m}, {n})")  # pragma: no cover
        return sp.csr_matrix(sp.coo_matrix((x, (rows, cols)), shape=(m, n)))
    if nz not in (-1, -2):
        raise InputError(f"{where}/nz: unknown sparse layout nz={nz} (expected -1 CSC, -2 CSR or ≥ 0 triplets)")
    outer, inner = (n, m) if nz == -1 else (m, n)
    if p.shape[0] != outer + 1:
        what = "column" if nz == -1 else "row"
        raise InputError(f"{where}/p: expected {outer + 1} {what} pointers, got {p.shape[0]}")
    nnz = _check_pointers(p, min(i.shape[0], x.shape[0]), f"{where}/p")
    i, x = i[:nnz], x[:nnz]
    _check_indices(i, inner, f"{where}/i", "row" if nz == -1 else "column")
    if nz == -1:
        return sp.csr_matrix(sp.csc_matrix((x, i, p), shape=(m, n)))
    return sp.csr_matrix((x, i, p), shape=(m, n))


def _vector(group: Any, name: str, size: int | None, where: str) -> np.ndarray:
    v = _numbers(group, name, where, integer=False)
    if size is not None and v.shape[0] != size:
        raise InputError(f"{where}/{name}: expected '{name}' with {size} entries, got {v.shape[0]}")
    return v


def _text(group: Any, name: str) -> str:
    import h5py

    if not isinstance(group, h5py.Group) or name not in group:
        return ""
    node = group[name]
    if not isinstance(node, h5py.Dataset) or node.dtype.kind not in "SUO" or node.size != 1:
        return ""
    try:
        value = node[()]
    except (OSError, ValueError, TypeError):
        return ""
    value = np.asarray(value).reshape(-1)[0]
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace").strip()
    return str(value).strip()


def _solve_mass(M: sp.csr_matrix, rhs: sp.spmatrix | np.ndarray, where: str) -> Any:
    """``M⁻¹ rhs`` for a diagonal (fast path) or general sparse SPD ``M``."""
    off_diagonal = M - sp.diags(M.diagonal())
    if off_diagonal.count_nonzero() == 0:
        d = M.diagonal()
        if np.any(d <= 0):
            raise InputError(f"{where}: mass matrix M has a non-positive diagonal entry")
        return sp.diags(1.0 / d) @ rhs
    try:
        lu = spla.splu(sp.csc_matrix(M))
    except RuntimeError as exc:
        raise InputError(f"{where}: mass matrix M is singular ({exc})") from exc
    if sp.issparse(rhs):
        cols = []
        dense = sp.csc_matrix(rhs)
        for start in range(0, dense.shape[1], 256):  # bounded memory: 256 columns at a time
            cols.append(sp.csr_matrix(lu.solve(dense[:, start : start + 256].toarray())))
        return sp.hstack(cols).tocsr()
    return lu.solve(np.asarray(rhs))


def _check_delassus(W: sp.csr_matrix, where: str) -> None:
    """Refuse a ``W`` with a negative diagonal entry: no ``J M⁻¹ Jᵀ`` has one (beyond rounding)."""
    d = W.diagonal()
    if d.size == 0:
        return
    floor = -1e-10 * max(float(np.max(np.abs(d))), np.finfo(float).tiny)
    if np.any(d < floor):
        k = int(np.argmin(d))
        raise InputError(
            f"{where}: diagonal entry W[{k},{k}] = {d[k]:.3g} < 0, so W is not positive semidefinite "
            "(a Delassus operator J M⁻¹ Jᵀ never has a negative diagonal)"
        )


def read_fclib(path: str | Path) -> FclibProblem:
    """Read and validate an FCLib HDF5 file (local or global problem) as a local problem.

    Every array is checked (type, shape, finiteness, index bounds, pointer order, sizes that
    agree with each other) before anything is built from it; a bad item is named by its HDF5
    path, e.g. ``file.hdf5:/fclib_local/W/p: pointers must not decrease, ...``.

    Parameters
    ----------
    path : str or Path
        The ``.hdf5`` file.

    Returns
    -------
    FclibProblem
        The problem, with ``kind`` telling what the file stored.

    Raises
    ------
    InputError
        Missing file, not HDF5, not FCLib, mixed/equality-constrained problems, bad arrays, a
        ``W`` with a negative diagonal entry, a singular mass matrix.
    """
    import h5py  # optional at import time: only the FCLib reader needs it

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such FCLib file")
    try:
        fh = h5py.File(path, "r")
    except OSError as exc:
        raise InputError(f"{path}: not an HDF5 file ({exc.__class__.__name__})") from exc
    with fh:
        if "fclib_local" in fh:
            kind = "local"
        elif "fclib_global" in fh:
            kind = "global"
        else:
            raise InputError(f"{path}: not an FCLib problem (no /fclib_local or /fclib_global)")
        root = _subgroup(fh, f"fclib_{kind}", f"{path}:", "the problem")
        where = f"{path}:/fclib_{kind}"
        spacedim = _scalar_int(root, "spacedim", where)
        if spacedim not in (2, 3):
            raise InputError(f"{where}/spacedim: spacedim must be 2 or 3, got {spacedim}")
        vectors = _subgroup(root, "vectors", where, "the vectors")
        vwhere = f"{where}/vectors"
        info = root["info"] if "info" in root else None
        title, description = _text(info, "title"), _text(info, "description")
        if kind == "local":
            if "V" in root or "R" in root:
                raise InputError(f"{where}: mixed problems (V, R) are not supported")
            W_group = _matrix_group(_node(root, "W", where), f"{where}/W")
            m = _scalar_int(W_group, "m", f"{where}/W")
            if m < 0 or m % spacedim:
                raise InputError(f"{where}/W/m: expected a multiple of spacedim={spacedim} rows, got {m}")
            q = _vector(vectors, "q", m, vwhere)
            mu = _vector(vectors, "mu", m // spacedim, vwhere)
            W = read_matrix(W_group, f"{where}/W", shape=(m, m))
        else:
            if "G" in root:
                raise InputError(f"{where}: equality constraints (G, b) are not supported")
            f = _vector(vectors, "f", None, vwhere)
            w = _vector(vectors, "w", None, vwhere)
            n_dof, m = f.shape[0], w.shape[0]
            if m % spacedim:
                raise InputError(f"{vwhere}/w: expected a multiple of spacedim={spacedim} entries, got {m}")
            mu = _vector(vectors, "mu", m // spacedim, vwhere)
            M = read_matrix(_node(root, "M", where), f"{where}/M", shape=(n_dof, n_dof))
            H = read_matrix(_node(root, "H", where), f"{where}/H", shape=(n_dof, m))
            Minv_H = _solve_mass(M, H.tocsc(), f"{where}/M")
            Minv_f = _solve_mass(M, f, f"{where}/M")
            W = sp.csr_matrix(H.T @ Minv_H)
            q = np.asarray(H.T @ Minv_f).reshape(-1) + w
            if not (np.all(np.isfinite(W.data)) and np.all(np.isfinite(q))):
                raise InputError(f"{where}/M: condensing with M⁻¹ overflowed (M is near singular)")
        if np.any(mu < 0):
            raise InputError(f"{vwhere}/mu: expected friction coefficients ≥ 0, got {float(mu.min()):g}")
        _check_delassus(W, f"{where}/W" if kind == "local" else f"{where}/M")
    problem = build_problem(W, q, mu, dims=spacedim)
    return FclibProblem(problem, kind, spacedim, title, description, str(path))


def _warm_up(dims: np.ndarray) -> None:
    """Compile the numba kernels (NSGS, NSN) on a one-contact problem, outside the timed solve.

    The kernels are cached on disk (``cache=True``), so this costs milliseconds after the first
    run on a machine.
    """
    from fixplan.engine.newton import solve_newton
    from fixplan.engine.nsgs import build_problem, solve_nsgs

    d = int(np.max(dims)) if len(dims) else 3
    tiny = build_problem(np.eye(d), -np.ones(d) * 0.1, np.array([0.3]), dims=d)
    solve_nsgs(tiny, tol=1e-8, max_iter=3)
    solve_newton(tiny, tol=1e-8, max_iter=3)


def solve_fclib_file(
    path: str | Path,
    tol: float = DEFAULT_TOL,
    max_iter: int | None = None,
    solver: str = "auto",
    time_limit: float | None = DEFAULT_TIME_LIMIT_S,
) -> FclibResult:
    """Read an FCLib file and solve it, within a time limit.

    Parameters
    ----------
    path : str or Path
        The ``.hdf5`` file.
    tol : float
        Target FCLib residual.
    max_iter : int, optional
        Iteration cap for the chosen solver (its own default when ``None``); for ``"auto"`` it
        caps every stage.
    solver : str
        A name from :data:`fixplan.engine.SOLVERS` (``"auto"``, ``"nsgs"``, ``"nsn"``,
        ``"prox"``, ``"socp"``, ...).
    time_limit : float, optional
        Bound on reading plus solving [s] (default 60 s; ``None``: none). At the limit the best
        iterate found so far is returned with ``converged = False``. (``"nsgs-numpy"``, the slow
        reference, takes no time limit.)

    Returns
    -------
    FclibResult
        The answer and its residual; ``stages`` lists what ``auto`` ran.

    Raises
    ------
    InputError
        Bad file (see :func:`read_fclib`), unknown solver name, bad limits.
    """
    from fixplan.engine import get_solver

    solve = get_solver(solver)  # unknown names fail before the file is read
    budget = Budget.start(time_limit)
    t_read = time.perf_counter()
    fc = read_fclib(path)
    read_s = time.perf_counter() - t_read
    kwargs: dict[str, Any] = {"tol": tol}
    if max_iter is not None:
        kwargs["max_iter"] = int(max_iter)
    _warm_up(fc.problem.dims)
    if "time_limit" in inspect.signature(solve).parameters:
        kwargs["time_limit"] = budget.limit_s()
    sol = solve(fc.problem, **kwargs)
    extras = dict(sol.extras)
    extras["read_s"] = read_s
    extras["title"] = fc.title
    return FclibResult(
        reaction=sol.reaction,
        velocity=sol.velocity,
        error=sol.error,
        iterations=sol.iterations,
        converged=sol.converged,
        time_s=sol.time_s,
        solver=sol.solver,
        n_contacts=fc.n_contacts,
        kind=fc.kind,
        path=str(path),
        extras=extras,
        stages=tuple(extras.get("stages", ())) if solver == "auto" else (),
    )
