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

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

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
        Solver details (status, history, read time).
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


def _text(group: Any, name: str) -> str:
    if name not in group:
        return ""
    value = group[name][()]
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace").strip()
    return str(value).strip()


def _scalar_int(group: Any, name: str, where: str) -> int:
    if name not in group:
        raise InputError(f"{where}: missing '{name}' (not an FCLib matrix)")
    return int(np.asarray(group[name][()]).reshape(-1)[0])


def read_matrix(group: Any, where: str) -> sp.csr_matrix:
    """Read an FCLib matrix group (CSC, CSR or triplet) as a CSR matrix.

    Parameters
    ----------
    group : h5py.Group
        The matrix group (holding ``m``, ``n``, ``nz``, ``p``, ``i``, ``x``).
    where : str
        Name used in error messages, e.g. ``"file.hdf5:/fclib_global/H"``.

    Returns
    -------
    scipy.sparse.csr_matrix
        The matrix.

    Raises
    ------
    InputError
        When a field is missing or the indices do not fit the shape.
    """
    m = _scalar_int(group, "m", where)
    n = _scalar_int(group, "n", where)
    nz = _scalar_int(group, "nz", where)
    for name in ("p", "i", "x"):
        if name not in group:
            raise InputError(f"{where}: missing '{name}' (not an FCLib matrix)")
    p = np.asarray(group["p"][()], dtype=np.int64).reshape(-1)
    i = np.asarray(group["i"][()], dtype=np.int64).reshape(-1)
    x = np.asarray(group["x"][()], dtype=float).reshape(-1)
    try:
        if nz >= 0:
            p, i, x = p[:nz], i[:nz], x[:nz]
            if len(p) != nz or len(i) != nz or len(x) != nz:
                raise InputError(f"{where}: triplet arrays shorter than nz={nz}")
            fits_csparse = nz == 0 or (i.max() < m and p.max() < n and min(i.min(), p.min()) >= 0)
            fits_header = nz == 0 or (p.max() < m and i.max() < n and min(i.min(), p.min()) >= 0)
            if fits_csparse:
                mat = sp.coo_matrix((x, (i, p)), shape=(m, n))
            elif fits_header:
                mat = sp.coo_matrix((x, (p, i)), shape=(m, n))
            else:
                raise InputError(f"{where}: triplet indices exceed the shape ({m}, {n})")
            return sp.csr_matrix(mat)
        if nz == -1:
            if len(p) != n + 1:
                raise InputError(f"{where}: CSC needs {n + 1} column pointers, got {len(p)}")
            return sp.csr_matrix(sp.csc_matrix((x[: p[-1]], i[: p[-1]], p), shape=(m, n)))
        if nz == -2:
            if len(p) != m + 1:
                raise InputError(f"{where}: CSR needs {m + 1} row pointers, got {len(p)}")
            return sp.csr_matrix((x[: p[-1]], i[: p[-1]], p), shape=(m, n))
    except ValueError as exc:
        raise InputError(f"{where}: inconsistent sparse matrix ({exc})") from exc
    raise InputError(f"{where}: unknown sparse layout nz={nz} (expected -1, -2 or ≥ 0)")


def _vector(group: Any, name: str, size: int, where: str) -> np.ndarray:
    if name not in group:
        raise InputError(f"{where}: missing vector '{name}'")
    v = np.asarray(group[name][()], dtype=float).reshape(-1)
    if v.shape[0] != size:
        raise InputError(f"{where}: expected '{name}' with {size} entries, got {v.shape[0]}")
    return v


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


def read_fclib(path: str | Path) -> FclibProblem:
    """Read an FCLib HDF5 file (local or global problem) as a local problem.

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
        Missing file, not HDF5, not FCLib, mixed/equality-constrained problems, bad shapes.
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
            kind, root = "local", fh["fclib_local"]
        elif "fclib_global" in fh:
            kind, root = "global", fh["fclib_global"]
        else:
            raise InputError(f"{path}: not an FCLib problem (no /fclib_local or /fclib_global)")
        where = f"{path}:/fclib_{kind}"
        spacedim = _scalar_int(root, "spacedim", where)
        if spacedim not in (2, 3):
            raise InputError(f"{where}: spacedim must be 2 or 3, got {spacedim}")
        if "vectors" not in root:
            raise InputError(f"{where}: missing group 'vectors'")
        vectors = root["vectors"]
        info = root["info"] if "info" in root else {}
        title, description = _text(info, "title"), _text(info, "description")
        if kind == "local":
            if "V" in root or "R" in root:
                raise InputError(f"{where}: mixed problems (V, R) are not supported")
            if "W" not in root:
                raise InputError(f"{where}: missing matrix 'W'")
            W = read_matrix(root["W"], f"{where}/W")
            m = W.shape[0]
            if W.shape != (m, m) or m % spacedim:
                raise InputError(f"{where}: W must be square with rows divisible by {spacedim}")
            q = _vector(vectors, "q", m, where)
        else:
            if "G" in root:
                raise InputError(f"{where}: equality constraints (G, b) are not supported")
            for name in ("M", "H"):
                if name not in root:
                    raise InputError(f"{where}: missing matrix '{name}'")
            M = read_matrix(root["M"], f"{where}/M")
            H = read_matrix(root["H"], f"{where}/H")
            n_dof, m = H.shape
            if M.shape != (n_dof, n_dof) or m % spacedim:
                raise InputError(
                    f"{where}: expected M {n_dof}×{n_dof} and H columns divisible by "
                    f"{spacedim}, got M {M.shape}, H {H.shape}"
                )
            f = _vector(vectors, "f", n_dof, where)
            w = _vector(vectors, "w", m, where)
            Minv_H = _solve_mass(M, H.tocsc(), where)
            Minv_f = _solve_mass(M, f, where)
            W = sp.csr_matrix(H.T @ Minv_H)
            q = np.asarray(H.T @ Minv_f).reshape(-1) + w
        mu = _vector(vectors, "mu", m // spacedim, where)
    problem = build_problem(W, q, mu, dims=spacedim)
    return FclibProblem(problem, kind, spacedim, title, description, str(path))


def _warm_up(solve: Any, dims: np.ndarray) -> None:
    """Run the solver once on a one-contact problem so compile time is not counted as solve time."""
    from fixplan.engine.nsgs import build_problem

    d = int(np.max(dims)) if len(dims) else 3
    tiny = build_problem(np.eye(d), -np.ones(d) * 0.1, np.array([0.3]), dims=d)
    solve(tiny, tol=1e-8)


def solve_fclib_file(
    path: str | Path,
    tol: float = DEFAULT_TOL,
    max_iter: int | None = None,
    solver: str = "auto",
) -> FclibResult:
    """Read an FCLib file and solve it.

    Parameters
    ----------
    path : str or Path
        The ``.hdf5`` file.
    tol : float
        Target FCLib residual.
    max_iter : int, optional
        Iteration cap for the chosen solver (its own default when ``None``).
    solver : str
        A name from :data:`fixplan.engine.SOLVERS` (``"auto"``, ``"nsgs"``, ``"newton"``, ...).

    Returns
    -------
    FclibResult
        The answer and its residual.

    Raises
    ------
    InputError
        Bad file (see :func:`read_fclib`) or unknown solver name.
    """
    from fixplan.engine import get_solver

    solve = get_solver(solver)  # unknown names fail before the file is read
    t_read = time.perf_counter()
    fc = read_fclib(path)
    read_s = time.perf_counter() - t_read
    kwargs: dict[str, Any] = {"tol": tol}
    if max_iter is not None:
        kwargs["max_iter"] = int(max_iter)
    _warm_up(solve, fc.problem.dims)
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
    )
