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

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fixplan.engine.budget import DEFAULT_TIME_LIMIT_S, Budget
from fixplan.engine.problem import DEFAULT_TOL, ContactProblem, build_problem
from fixplan.errors import InputError, shorten
from fixplan.limits import (
    FCLIB_ENTRY,
    FCLIB_MAX_CHUNKS,
    FCLIB_MAX_CONTACTS,
    FCLIB_MAX_DEPTH,
    FCLIB_MAX_DOFS,
    FCLIB_MAX_LINKS,
    FCLIB_MAX_NNZ,
    FCLIB_MAX_TEXT_BYTES,
    FRICTION,
    Range,
)


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
    elapsed_s : float
        Reading plus solving [s]: what ``time_limit`` bounds (loading the compiled kernels, timed
        in ``extras["warm_up_s"]``, is not counted).
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
    elapsed_s: float = 0.0

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
            "elapsed_s": float(self.elapsed_s),
            "reason": self.extras.get("reason", ""),
            "stages": list(self.stages),
            "reaction": [float(x) for x in self.reaction],
            "velocity": [float(x) for x in self.velocity],
        }


_MAX_DIM = 2**31 - 1  # FCLib stores indices as int32
_MAX_ROWS = max(FCLIB_MAX_DOFS, 3 * FCLIB_MAX_CONTACTS)  # rows or columns of any matrix (M, H, W)

_HDF5_ERRORS: tuple[type[Exception], ...] = (OSError, KeyError, RuntimeError, ValueError, TypeError)
"""What h5py raises when HDF5 fails: h5py turns the HDF5 error stack into one of these by its minor error
code (``NotImplementedError`` is a ``RuntimeError``). A corrupt header, heap or B-tree, a broken link, a
chunk that does not decompress: each surfaces as one of them, from any call that touches the file."""


def _hdf5_reason(exc: BaseException) -> str:
    """h5py's message (``Unable to synchronously open object (bad heap free list)``), cut to a readable length."""
    text = str(exc.args[0]) if exc.args else type(exc).__name__
    return text if len(text) <= 160 else text[:159] + "…"


@contextmanager
def _hdf5(where: str) -> Iterator[None]:
    """Run HDF5 calls; a failure becomes an :class:`InputError` naming the file and the HDF5 path."""
    try:
        yield
    except _HDF5_ERRORS as exc:
        raise InputError(f"{where}: unreadable, the HDF5 file is corrupt ({_hdf5_reason(exc)})") from exc


def check_links(fh: Any, path: str) -> int:
    """Refuse every soft, external or user-defined link in the file, before any object is opened through one.

    Links are read with ``group.get(name, getlink=True)``, which looks at the link itself: a soft
    link that dangles or loops, or an external link to another file (``/etc/passwd``), is named
    and refused without being followed. FCLib writes plain groups and datasets only. Groups are
    visited through their hard links, at most :data:`~fixplan.limits.FCLIB_MAX_DEPTH` deep (a
    group hard-linked into itself stops there) and at most :data:`~fixplan.limits.FCLIB_MAX_LINKS`
    links in all.

    Parameters
    ----------
    fh : h5py.File
        The open file.
    path : str
        The file's name, for messages.

    Returns
    -------
    int
        The number of links visited.

    Raises
    ------
    InputError
        Naming the HDF5 path of the first link refused, or of the first unreadable group.
    """
    import h5py

    count = 0
    stack: list[tuple[Any, str, int]] = [(fh, "", 0)]
    while stack:
        group, name, depth = stack.pop()
        with _hdf5(f"{path}:{name or '/'}"):
            children = list(group)  # link names only: nothing is opened
        for child in children:
            where = f"{path}:{name}/{child}"
            count += 1
            if count > FCLIB_MAX_LINKS:
                raise InputError(f"{where}: more than {FCLIB_MAX_LINKS} links in the file (an FCLib file has about 30)")
            with _hdf5(where):
                link = group.get(child, getlink=True)
            if isinstance(link, h5py.SoftLink):
                raise InputError(
                    f"{where}: a soft link to {shorten(str(link.path))} (links are refused: an FCLib file holds "
                    "groups and datasets only)"
                )
            if isinstance(link, h5py.ExternalLink):
                raise InputError(
                    f"{where}: an external link to {shorten(str(link.filename))}:{shorten(str(link.path))} "
                    "(links are refused: an FCLib file holds groups and datasets only)"
                )
            if not isinstance(link, h5py.HardLink):
                raise InputError(
                    f"{where}: a user-defined link (links are refused: an FCLib file holds groups and datasets only)"
                )
            with _hdf5(where):
                node = group[child]  # a hard link: no link is followed
            if isinstance(node, h5py.Group):
                if depth + 1 >= FCLIB_MAX_DEPTH:
                    raise InputError(
                        f"{where}: groups nested deeper than {FCLIB_MAX_DEPTH} (FCLib nests 3; a group linked into itself?)"
                    )
                stack.append((node, f"{name}/{child}", depth + 1))
    return count


def _node(group: Any, name: str, where: str) -> Any:
    """``group[name]``, or an :class:`InputError` naming the missing HDF5 path."""
    with _hdf5(f"{where}/{name}"):
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


@dataclass(frozen=True)
class _Declared:
    """A numeric dataset whose declared shape, type and storage were checked; nothing read yet."""

    ds: Any
    path: str
    count: int  # entries the dataspace declares
    integer: bool


def _declared(
    group: Any, name: str, where: str, *, integer: bool, at_most: int, exactly: tuple[int, str] | None = None
) -> _Declared:
    """Open a dataset and check what it declares, before any of its data is read.

    Refused: a non-numeric type; more than ``at_most`` entries (a 9 KB file can declare 10⁹
    unwritten chunks, and reading them would allocate 7.45 GiB); more than
    :data:`~fixplan.limits.FCLIB_MAX_CHUNKS` chunks, or one chunk larger than the dataset may be;
    data stored in other files (external storage, virtual datasets). ``exactly = (n, what)``: the
    dataset must declare ``n`` entries ("expected {what}, got ...").
    """
    ds = _dataset(group, name, where)
    path = f"{where}/{name}"
    with _hdf5(path):
        dtype, shape, chunks = ds.dtype, ds.shape, ds.chunks
        external, virtual = ds.external, ds.is_virtual
    if dtype.kind not in "iuf" or dtype.subdtype is not None:
        expected = "integers" if integer else "real numbers"
        raise InputError(f"{path}: expected {expected}, got HDF5 type {dtype}")
    if external or virtual:
        raise InputError(f"{path}: its data are stored in other files (refused: an FCLib file holds its own data)")
    count = math.prod(shape) if shape is not None else 0
    if exactly is not None and count != exactly[0]:
        raise InputError(f"{path}: expected {exactly[1]}, got {count} {'value' if count == 1 else 'values'}")
    if count > at_most:
        raise InputError(
            f"{path}: declares {count} entries, more than the {at_most} a problem within fixplan's limits can have "
            f"(at most {FCLIB_MAX_CONTACTS} contacts, {FCLIB_MAX_NNZ} stored entries per matrix)"
        )
    if chunks is not None:
        n_chunks = math.prod(-(-s // c) for s, c in zip(shape, chunks, strict=True))
        chunk_entries = math.prod(chunks)
        if n_chunks > FCLIB_MAX_CHUNKS or chunk_entries > max(at_most, 1):
            raise InputError(
                f"{path}: stored in {n_chunks} chunks of {chunk_entries} entries (expected at most "
                f"{FCLIB_MAX_CHUNKS} chunks of at most {max(at_most, 1)} entries)"
            )
    return _Declared(ds, path, count, integer)


def _read(d: _Declared, entries: Range | None = None) -> np.ndarray:
    """The values of a checked dataset, flat; integers are checked to be integral and in the int32 range.

    ``entries``: the range of every real value (each must be finite and inside it); the message
    names the entry and quotes its value as stored.
    """
    path = d.path
    with _hdf5(path):
        raw = d.ds[()] if d.count else np.zeros(0, d.ds.dtype)
    values = np.asarray(raw).reshape(-1)
    if values.shape[0] != d.count:  # pragma: no cover - h5py returns what the dataspace declares
        raise InputError(f"{path}: declares {d.count} entries, read {values.shape[0]}")
    kind = values.dtype.kind
    if d.integer:
        if kind == "f":
            if not np.all(np.isfinite(values)):
                raise InputError(f"{path}: expected finite numbers, found NaN or inf")
            if np.any(values != np.round(values)) or np.any(np.abs(values) > _MAX_DIM):
                raise InputError(f"{path}: expected integers, found non-integral values")
        elif values.size and (int(values.max()) > _MAX_DIM or int(values.min()) < -_MAX_DIM):
            raise InputError(f"{path}: integers out of the int32 range")
        return values.astype(np.int64)
    values = values.astype(np.float64)
    if entries is not None:
        _check_entries(values, path, entries)
    return values


def _check_entries(values: np.ndarray, path: str, entries: Range, what: str = "entry") -> None:
    """Every value finite and inside ``entries``; else an :class:`InputError` quoting the first bad one."""
    bad = ~np.isfinite(values) | (values < entries.low) | (values > entries.high)
    if np.any(bad):
        k = int(np.argmax(bad))
        value = float(values[k])
        finite = "" if math.isfinite(value) else ", not a finite number"
        raise InputError(f"{path}: {what} {k} is {value!r}{finite} (expected {entries.expected()})")


def _scalar_int(group: Any, name: str, where: str) -> int:
    return int(_read(_declared(group, name, where, integer=True, at_most=1, exactly=(1, "one integer")))[0])


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
    ``p``, ``i``; real ``x``, each finite and inside :data:`~fixplan.limits.FCLIB_ENTRY`;
    pointers starting at 0, non-decreasing, ending within the stored entries; every index inside
    the shape. (SciPy's own check skips index bounds, and an out-of-range index in a compiled loop
    reads or writes outside its arrays.) The declared sizes of ``p``, ``i`` and ``x`` are checked
    against the shape and :data:`~fixplan.limits.FCLIB_MAX_NNZ` before they are read.

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
    if max(m, n) > _MAX_ROWS:
        raise InputError(
            f"{where}/m: shape {m}×{n} is larger than fixplan accepts (at most {_MAX_ROWS} rows or columns)"
        )
    nz = _scalar_int(group, "nz", where)
    if nz >= 0:
        if nz > FCLIB_MAX_NNZ:
            raise InputError(f"{where}/nz: {nz} triplets, more than the {FCLIB_MAX_NNZ} stored entries fixplan accepts")
        declared = {k: _declared(group, k, where, integer=k != "x", at_most=FCLIB_MAX_NNZ) for k in ("p", "i", "x")}
        for name, d in declared.items():
            if d.count < nz:
                raise InputError(f"{where}/{name}: expected nz={nz} triplet entries, got {d.count}")
        p, i = _read(declared["p"])[:nz], _read(declared["i"])[:nz]
        x = _read(declared["x"], FCLIB_ENTRY)[:nz]
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
    what = "column" if nz == -1 else "row"
    dp = _declared(
        group, "p", where, integer=True, at_most=_MAX_ROWS + 1, exactly=(outer + 1, f"{outer + 1} {what} pointers")
    )
    di = _declared(group, "i", where, integer=True, at_most=FCLIB_MAX_NNZ)
    dx = _declared(group, "x", where, integer=False, at_most=FCLIB_MAX_NNZ)
    p = _read(dp)
    nnz = _check_pointers(p, min(di.count, dx.count), f"{where}/p")
    i, x = _read(di)[:nnz], _read(dx, FCLIB_ENTRY)[:nnz]
    _check_indices(i, inner, f"{where}/i", "row" if nz == -1 else "column")
    if nz == -1:
        return sp.csr_matrix(sp.csc_matrix((x, i, p), shape=(m, n)))
    return sp.csr_matrix((x, i, p), shape=(m, n))


def _vector(
    group: Any, name: str, size: int | None, where: str, entries: Range = FCLIB_ENTRY, at_most: int = 0
) -> np.ndarray:
    """A real vector of ``size`` entries (declared size checked before reading), each inside ``entries``."""
    exactly = None if size is None else (size, f"'{name}' with {size} entries")
    return _read(_declared(group, name, where, integer=False, at_most=at_most or _MAX_ROWS, exactly=exactly), entries)


def _text(group: Any, name: str, where: str) -> str:
    """``info/title`` and the like: a short string, or ``""`` when absent or not a string."""
    import h5py

    if group is None:
        return ""
    with _hdf5(f"{where}/{name}"):
        if not isinstance(group, h5py.Group) or name not in group:
            return ""
        node = group[name]
        if not isinstance(node, h5py.Dataset) or node.dtype.kind not in "SUO" or node.size != 1:
            return ""
        if node.dtype.itemsize > FCLIB_MAX_TEXT_BYTES:
            return ""
        value = node[()]
    value = np.asarray(value).reshape(-1)[0]
    if isinstance(value, bytes):
        text = value.decode("utf-8", "replace")
    else:
        text = str(value)
    return text[:FCLIB_MAX_TEXT_BYTES].strip()


def _solve_mass(M: sp.csr_matrix, rhs: sp.spmatrix | np.ndarray, where: str) -> Any:
    """``M⁻¹ rhs`` for a diagonal (fast path) or general sparse SPD ``M``."""
    if _is_diagonal(M):
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


def _is_diagonal(M: sp.csr_matrix) -> bool:
    return bool((M - sp.diags(M.diagonal())).count_nonzero() == 0)


def _condense(
    M: sp.csr_matrix, H: sp.csr_matrix, f: np.ndarray, w: np.ndarray, where: str
) -> tuple[sp.csr_matrix, np.ndarray]:
    """``W = Hᵀ M⁻¹ H`` and ``q = Hᵀ M⁻¹ f + w``, the work bounded before it is done.

    With a diagonal ``M`` the product costs ``Σ_k nnz(row k of H)²`` multiplications, which also
    bounds ``nnz(W)``; with a general ``M``, ``M⁻¹ H`` may be dense (``n_dof × m`` entries). Either
    must stay within :data:`~fixplan.limits.FCLIB_MAX_NNZ`. The results are checked like stored
    entries (finite, inside :data:`~fixplan.limits.FCLIB_ENTRY`): a near-singular ``M`` can push
    them out.
    """
    n_dof, m = H.shape
    if _is_diagonal(M):
        products = int(np.sum(np.diff(H.indptr).astype(np.int64) ** 2))
        if products > FCLIB_MAX_NNZ:
            raise InputError(
                f"{where}/H: condensing Hᵀ M⁻¹ H takes {products} products (Σ over the rows of H of their "
                f"entries squared), more than the {FCLIB_MAX_NNZ} fixplan accepts"
            )
    elif n_dof * m > FCLIB_MAX_NNZ:
        raise InputError(
            f"{where}/M: M is not diagonal, so M⁻¹ H ({n_dof}×{m}) may have {n_dof * m} entries, more than "
            f"the {FCLIB_MAX_NNZ} fixplan accepts"
        )
    Minv_H = _solve_mass(M, H.tocsc(), f"{where}/M")
    Minv_f = _solve_mass(M, f, f"{where}/M")
    W = sp.csr_matrix(H.T @ Minv_H)
    q = np.asarray(H.T @ Minv_f).reshape(-1) + w
    for what, values in (("W = Hᵀ M⁻¹ H", W.data), ("q = Hᵀ M⁻¹ f + w", q)):
        bad = ~np.isfinite(values) | (np.abs(values) > FCLIB_ENTRY.high)
        if np.any(bad):
            value = float(values[int(np.argmax(bad))])
            raise InputError(
                f"{where}/M: condensing with M⁻¹ gives {what} an entry {value!r} (expected "
                f"{FCLIB_ENTRY.expected()}; M is near singular)"
            )
    return W, q


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


def _has(group: Any, name: str, where: str) -> bool:
    with _hdf5(f"{where}/{name}"):
        return name in group


def _contacts(m: int, spacedim: int, path: str) -> int:
    """Contacts of ``m`` rows: a multiple of ``spacedim``, at most :data:`~fixplan.limits.FCLIB_MAX_CONTACTS`."""
    if m < 0 or m % spacedim:
        raise InputError(f"{path}: expected a multiple of spacedim={spacedim} rows, got {m}")
    if m // spacedim > FCLIB_MAX_CONTACTS:
        raise InputError(
            f"{path}: {m} rows are {m // spacedim} contacts, more than the {FCLIB_MAX_CONTACTS} fixplan accepts"
        )
    return m // spacedim


def read_fclib(path: str | Path) -> FclibProblem:
    """Read and validate an FCLib HDF5 file (local or global problem) as a local problem.

    First every link in the file is looked at without being followed (:func:`check_links`): soft
    and external links are refused. Then every dataset's declared shape and storage are checked
    against the sizes fixplan accepts (:mod:`fixplan.limits`, ``FCLIB_*``) and against each other
    (``len(q) = m``, ``len(mu) = m / spacedim``, ``W`` is ``m × m``) before any of its data is
    read. Every array read is checked (type, finite values inside their range, index bounds,
    pointer order) before anything is built from it. A bad item, and a corrupt file (any error
    HDF5 reports), is named by its HDF5 path, e.g.
    ``file.hdf5:/fclib_local/W/p: pointers must not decrease, ...``.

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
        Missing file, not HDF5, a corrupt file, a link, not FCLib, mixed/equality-constrained
        problems, sizes beyond the limits or inconsistent, bad arrays, a ``W`` with a negative
        diagonal entry, a singular mass matrix.
    """
    import h5py  # optional at import time: only the FCLib reader needs it

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such FCLib file")
    try:
        fh = h5py.File(path, "r")
    except _HDF5_ERRORS as exc:
        raise InputError(f"{path}: not an HDF5 file, or a corrupt one ({_hdf5_reason(exc)})") from exc
    try:
        fc = _read_open(fh, str(path))
    finally:
        with _hdf5(f"{path}:/"):
            fh.close()
    return fc


def _read_open(fh: Any, path: str) -> FclibProblem:
    """:func:`read_fclib` on the open file."""
    check_links(fh, path)
    if _has(fh, "fclib_local", f"{path}:"):
        kind = "local"
    elif _has(fh, "fclib_global", f"{path}:"):
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
    info = _subgroup(root, "info", where, "the info") if _has(root, "info", where) else None
    title, description = _text(info, "title", f"{where}/info"), _text(info, "description", f"{where}/info")
    if kind == "local":
        if _has(root, "V", where) or _has(root, "R", where):
            raise InputError(f"{where}: mixed problems (V, R) are not supported")
        W_group = _matrix_group(_node(root, "W", where), f"{where}/W")
        m = _scalar_int(W_group, "m", f"{where}/W")
        n_contacts = _contacts(m, spacedim, f"{where}/W/m")
        q = _vector(vectors, "q", m, vwhere)
        mu = _vector(vectors, "mu", n_contacts, vwhere, FRICTION)
        W = read_matrix(W_group, f"{where}/W", shape=(m, m))
    else:
        if _has(root, "G", where):
            raise InputError(f"{where}: equality constraints (G, b) are not supported")
        df = _declared(vectors, "f", vwhere, integer=False, at_most=FCLIB_MAX_DOFS)
        dw = _declared(vectors, "w", vwhere, integer=False, at_most=_MAX_ROWS)
        n_dof, m = df.count, dw.count
        n_contacts = _contacts(m, spacedim, f"{vwhere}/w")
        mu = _vector(vectors, "mu", n_contacts, vwhere, FRICTION)
        f, w = _read(df, FCLIB_ENTRY), _read(dw, FCLIB_ENTRY)
        M = read_matrix(_node(root, "M", where), f"{where}/M", shape=(n_dof, n_dof))
        H = read_matrix(_node(root, "H", where), f"{where}/H", shape=(n_dof, m))
        W, q = _condense(M, H, f, w, where)
    _check_delassus(W, f"{where}/W" if kind == "local" else f"{where}/M")
    problem = build_problem(W, q, mu, dims=spacedim)
    return FclibProblem(problem, kind, spacedim, title, description, path)


def _warm_up(dims: np.ndarray) -> None:
    """Load the compiled kernels (NSGS, NSN, one-contact solves) and Clarabel, outside the timed solve.

    The kernels run once on a one-contact problem. They are cached on disk (``cache=True``), so this costs milliseconds after the first
    run on a machine.
    """
    import clarabel  # noqa: F401 - loaded here, not inside the SOCP solver's time

    from fixplan.engine.newton import solve_newton
    from fixplan.engine.nsgs import solve_nsgs, solve_nsgs_reference

    d = int(np.max(dims)) if len(dims) else 3
    tiny = build_problem(np.eye(d), -np.ones(d) * 0.1, np.array([0.3]), dims=d)
    solve_nsgs(tiny, tol=1e-8, max_iter=3)
    solve_nsgs_reference(tiny, tol=1e-8, max_iter=1)  # its one-contact solver is compiled too
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
        Bound on reading plus solving [s] (default 60 s; ``None``: none), for every solver. At the
        limit the best iterate found so far is returned with ``converged = False``; the answer
        comes within ``fclib_time_factor × time_limit + fclib_time_slack_s``
        (:class:`fixplan.settings.EngineSettings`), ``elapsed_s`` says how long it took.

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
    t_start = time.perf_counter()
    fc = read_fclib(path)
    read_s = time.perf_counter() - t_start
    kwargs: dict[str, Any] = {"tol": tol}
    if max_iter is not None:
        kwargs["max_iter"] = int(max_iter)
    t_warm = time.perf_counter()
    _warm_up(fc.problem.dims)
    warm_up_s = time.perf_counter() - t_warm
    budget = Budget(budget.deadline + warm_up_s)  # loading the compiled kernels is not reading or solving
    kwargs["time_limit"] = budget.limit_s()  # every registered solver takes one
    sol = solve(fc.problem, **kwargs)
    elapsed_s = time.perf_counter() - t_start - warm_up_s
    extras = dict(sol.extras)
    extras["read_s"] = read_s
    extras["warm_up_s"] = warm_up_s
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
        elapsed_s=elapsed_s,
    )
