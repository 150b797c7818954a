"""FCLib files: layouts, global → local condensation, bad files, and the four real problems."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.sparse as sp

from fixplan.engine.fclib import read_fclib, read_matrix, solve_fclib_file
from fixplan.engine.problem import fclib_error
from fixplan.errors import InputError

REAL_PROBLEMS = [
    "Box_Stacks-i0122-82-5.hdf5",
    "Capsules-i125-1213.hdf5",
    "LMGC_100_PR_PerioBox-i00361-60-03000.hdf5",
    "Spheres-i099-356-679.hdf5",
]


# --------------------------------------------------------------------------- writers


def write_matrix(group: h5py.Group, A: np.ndarray, layout: str) -> None:
    """Write ``A`` in FCLib's matrix layout: ``csc`` (nz=-1), ``csr`` (nz=-2), ``triplet``.

    ``triplet`` follows CSparse/Siconos (``i`` rows, ``p`` columns); ``triplet-header`` the
    FCLib header's wording (``p`` rows, ``i`` columns).
    """
    m, n = A.shape
    group["m"], group["n"] = np.array([m], np.int32), np.array([n], np.int32)
    if layout == "csc":
        S = sp.csc_matrix(A)
        p, i, nz = S.indptr, S.indices, -1
    elif layout == "csr":
        S = sp.csr_matrix(A)
        p, i, nz = S.indptr, S.indices, -2
    else:
        S = sp.coo_matrix(A)
        rows, cols = S.row, S.col
        p, i = (cols, rows) if layout == "triplet" else (rows, cols)
        nz = S.nnz
    group["nz"], group["nzmax"] = np.array([nz], np.int32), np.array([S.nnz], np.int32)
    group["p"], group["i"] = np.asarray(p, np.int32), np.asarray(i, np.int32)
    group["x"] = np.asarray(S.data, float)


def write_local(path: Path, W, q, mu, spacedim=3, layout="csr") -> Path:
    with h5py.File(path, "w") as fh:
        root = fh.create_group("fclib_local")
        root["spacedim"] = np.array([spacedim], np.int32)
        write_matrix(root.create_group("W"), np.asarray(W), layout)
        vec = root.create_group("vectors")
        vec["q"], vec["mu"] = np.asarray(q, float), np.asarray(mu, float)
        root.create_group("info")["title"] = np.bytes_("test problem")
    return path


def random_global(rng, n_dof=12, n_contacts=3):
    B = rng.standard_normal((n_dof, n_dof))
    M = B @ B.T + n_dof * np.eye(n_dof)  # a full SPD mass matrix (not diagonal)
    H = rng.standard_normal((n_dof, 3 * n_contacts))
    f, w = rng.standard_normal(n_dof), rng.standard_normal(3 * n_contacts)
    return M, H, f, w, np.full(n_contacts, 0.4)


def write_global(path: Path, M, H, f, w, mu, layout="triplet") -> Path:
    with h5py.File(path, "w") as fh:
        root = fh.create_group("fclib_global")
        root["spacedim"] = np.array([3], np.int32)
        write_matrix(root.create_group("M"), M, layout)
        write_matrix(root.create_group("H"), H, layout)
        vec = root.create_group("vectors")
        vec["f"], vec["w"], vec["mu"] = f, w, mu
    return path


# --------------------------------------------------------------------------- layouts


@pytest.mark.parametrize("layout", ["csc", "csr", "triplet", "triplet-header"])
def test_every_matrix_layout_reads_back(tmp_path, rng, layout):
    A = rng.standard_normal((5, 7)) * (rng.random((5, 7)) < 0.5)
    with h5py.File(tmp_path / "m.hdf5", "w") as fh:
        write_matrix(fh.create_group("A"), A, layout)
    with h5py.File(tmp_path / "m.hdf5", "r") as fh:
        np.testing.assert_array_equal(read_matrix(fh["A"], "A").toarray(), A)


def test_global_problem_is_condensed(tmp_path, rng):
    M, H, f, w, mu = random_global(rng)
    fc = read_fclib(write_global(tmp_path / "g.hdf5", M, H, f, w, mu))
    assert fc.kind == "global" and fc.n_contacts == 3
    Minv = np.linalg.inv(M)
    np.testing.assert_allclose(fc.problem.W.toarray(), H.T @ Minv @ H, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(fc.problem.q, H.T @ Minv @ f + w, rtol=1e-12, atol=1e-14)
    # and the condensed solution satisfies the global equations M v = H r + f, u = Hᵀ v + w
    res = solve_fclib_file(tmp_path / "g.hdf5", tol=1e-12, solver="nsgs")
    v = np.linalg.solve(M, H @ res.reaction + f)
    np.testing.assert_allclose(H.T @ v + w, res.velocity, rtol=1e-10, atol=1e-12)


def test_two_dimensional_file_solves(tmp_path, rng):
    B = rng.standard_normal((8, 8))
    W = B @ B.T + np.eye(8)
    path = write_local(tmp_path / "p2.hdf5", W, rng.standard_normal(8), [0.3] * 4, spacedim=2)
    res = solve_fclib_file(path, tol=1e-10)
    assert res.converged and res.error <= 1e-10 and res.n_contacts == 4 and res.kind == "local"


# --------------------------------------------------------------------------- bad files


def test_bad_files_raise_one_clear_line(tmp_path):
    with pytest.raises(InputError, match="no such FCLib file"):
        read_fclib(tmp_path / "missing.hdf5")
    text = tmp_path / "notes.hdf5"
    text.write_text("not hdf5\n")
    with pytest.raises(InputError, match="not an HDF5 file"):
        read_fclib(text)
    with h5py.File(tmp_path / "other.hdf5", "w") as fh:
        fh["data"] = np.zeros(3)
    with pytest.raises(InputError, match="not an FCLib problem"):
        read_fclib(tmp_path / "other.hdf5")
    path = write_local(tmp_path / "d4.hdf5", np.eye(4), np.zeros(4), [0.3], spacedim=4)
    with pytest.raises(InputError, match="spacedim must be 2 or 3"):
        read_fclib(path)
    path = write_local(tmp_path / "mixed.hdf5", np.eye(3), np.zeros(3), [0.3])
    with h5py.File(path, "a") as fh:
        fh["fclib_local"].create_group("V")
    with pytest.raises(InputError, match="mixed problems"):
        read_fclib(path)
    path = write_local(tmp_path / "short.hdf5", np.eye(6), np.zeros(5), [0.3, 0.3])
    with pytest.raises(InputError, match="expected 'q' with 6 entries"):
        read_fclib(path)
    for err in (read_fclib, solve_fclib_file):
        try:
            err(tmp_path / "missing.hdf5")
        except InputError as exc:
            assert "\n" not in str(exc)


def test_unknown_solver_is_rejected_before_reading(tmp_path):
    with pytest.raises(InputError, match="known solvers: auto, nsgs, nsgs-numpy, nsn, prox, socp"):
        solve_fclib_file(tmp_path / "missing.hdf5", solver="lemke")


# --------------------------------------------------------------------------- real problems


@pytest.mark.parametrize("name", REAL_PROBLEMS)
@pytest.mark.parametrize("solver", ["auto", "nsgs", "socp", "nsn", "prox"])
def test_real_fclib_problem_reaches_1e_8(fclib_dir, name, solver):
    path = fclib_dir / name
    res = solve_fclib_file(path, tol=1e-8, solver=solver)
    assert res.converged and res.error <= 1e-8, (name, solver, res.error, res.iterations)
    # checked independently of the solver's own bookkeeping
    fc = read_fclib(path)
    assert fclib_error(fc.problem, res.reaction) <= 1e-8
    assert np.all(np.isfinite(res.reaction)) and res.n_contacts == fc.n_contacts
    assert res.kind == ("global" if name.startswith(("Box", "Spheres")) else "local")
