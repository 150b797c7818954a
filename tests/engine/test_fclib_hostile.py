"""Hostile FCLib files: every bad array is refused (exit 2) with its HDF5 path, before anything compiled runs.

Before the reader checked every array, a column index of −1 or non-monotone row pointers used to crash the process
(glibc double free); an index of 99 in a 3×3 matrix was accepted; a dense ``W``, an empty or
string ``m`` and string ``x`` gave internal errors (exit 3). The abort cases run the CLI in a
subprocess so that a crash cannot take pytest down with it.
"""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import run_cli

from fixplan.engine.fclib import read_fclib
from fixplan.errors import InputError


def fixplan(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return run_cli(*args, timeout=timeout)


def write_csr(path: Path, indptr, indices, data, size: int, q=None, mu=None, **overrides) -> Path:
    """A local 3D problem whose W is given as raw CSR arrays (nz = -2), written as is.

    ``overrides`` replaces a dataset of the W group by name (any value h5py can store).
    """
    with h5py.File(path, "w") as fh:
        root = fh.create_group("fclib_local")
        root["spacedim"] = np.array([3], np.int32)
        W = root.create_group("W")
        fields = {
            "m": np.array([size], np.int32),
            "n": np.array([size], np.int32),
            "nz": np.array([-2], np.int32),
            "nzmax": np.array([len(data)], np.int32),
            "p": np.asarray(indptr, np.int32),
            "i": np.asarray(indices, np.int32),
            "x": np.asarray(data, float),
        }
        fields.update(overrides)
        for name, value in fields.items():
            W[name] = value
        vec = root.create_group("vectors")
        vec["q"] = np.asarray(q if q is not None else [-1.0] + [0.0] * (size - 1), float)
        vec["mu"] = np.asarray(mu if mu is not None else [0.3] * (size // 3), float)
    return path


def identity_csr(m: int) -> tuple[list[int], list[int], list[float]]:
    return list(range(m + 1)), list(range(m)), [1.0] * m


def _column_minus_one(p: Path) -> Path:
    indptr, indices, data = identity_csr(3)
    indices[1] = -1
    return write_csr(p, indptr, indices, data, 3)


def _pointers_not_monotone(p: Path) -> Path:
    return write_csr(p, [0, 2, 1, 3], [0, 1, 2], [1.0, 1.0, 1.0], 3)


def _index_99(p: Path) -> Path:
    indptr, indices, data = identity_csr(3)
    indices[2] = 99
    return write_csr(p, indptr, indices, data, 3)


def _pointer_past_entries(p: Path) -> Path:
    return write_csr(p, [0, 1, 2, 30], [0, 1, 2], [1.0, 1.0, 1.0], 3)


def _pointer_not_from_zero(p: Path) -> Path:
    return write_csr(p, [1, 1, 2, 3], [0, 1, 2], [1.0, 1.0, 1.0], 3)


def _dense_w(p: Path) -> Path:
    with h5py.File(p, "w") as fh:
        root = fh.create_group("fclib_local")
        root["spacedim"] = np.array([3], np.int32)
        root["W"] = np.eye(3)
        vec = root.create_group("vectors")
        vec["q"], vec["mu"] = np.array([-1.0, 0, 0]), np.array([0.3])
    return p


def _m_empty(p: Path) -> Path:
    return write_csr(p, *identity_csr(3), 3, m=np.array([], np.int32))


def _m_string(p: Path) -> Path:
    return write_csr(p, *identity_csr(3), 3, m=np.bytes_("three"))


def _x_strings(p: Path) -> Path:
    return write_csr(p, *identity_csr(3), 3, x=np.array([b"1", b"1", b"1"]))


def _x_nan(p: Path) -> Path:
    return write_csr(p, [0, 1, 2, 3], [0, 1, 2], [1.0, np.nan, 1.0], 3)


def _nz_unknown(p: Path) -> Path:
    return write_csr(p, *identity_csr(3), 3, nz=np.array([-7], np.int32))


def _w_minus_identity(p: Path) -> Path:
    return write_csr(p, [0, 1, 2, 3], [0, 1, 2], [-1.0, -1.0, -1.0], 3)


def _q_too_short(p: Path) -> Path:
    return write_csr(p, *identity_csr(6), 6, q=[-1.0, 0, 0, 0, 0])


def _q_strings(p: Path) -> Path:
    path = write_csr(p, *identity_csr(3), 3)
    with h5py.File(path, "a") as fh:
        del fh["fclib_local/vectors/q"]
        fh["fclib_local/vectors/q"] = np.array([b"a", b"b", b"c"])
    return path


def _mu_negative(p: Path) -> Path:
    return write_csr(p, *identity_csr(3), 3, mu=[-0.5])


def _m_not_matching(p: Path) -> Path:
    return write_csr(p, *identity_csr(3), 3, n=np.array([4], np.int32))


def _vectors_is_dataset(p: Path) -> Path:
    path = write_csr(p, *identity_csr(3), 3)
    with h5py.File(path, "a") as fh:
        del fh["fclib_local/vectors"]
        fh["fclib_local/vectors"] = np.zeros(3)
    return path


def _triplet_out_of_shape(p: Path) -> Path:
    return write_csr(
        p, [0, 1, 7], [0, 1, 2], [1.0, 1.0, 1.0], 3, nz=np.array([3], np.int32), p=np.array([0, 1, 7], np.int32)
    )


# (writer, HDF5 path that must be named, words of the reason)
HOSTILE: dict[str, tuple[Callable[[Path], Path], str, str]] = {
    "column index -1": (_column_minus_one, "/fclib_local/W/i", "index -1 outside"),
    "pointers not monotone": (_pointers_not_monotone, "/fclib_local/W/p", "must not decrease"),
    "index 99 in 3x3": (_index_99, "/fclib_local/W/i", "index 99 outside [0, 3)"),
    "pointer past entries": (_pointer_past_entries, "/fclib_local/W/p", "exceeds the 3 stored entries"),
    "pointer not from 0": (_pointer_not_from_zero, "/fclib_local/W/p", "start at 0"),
    "W dense dataset": (_dense_w, "/fclib_local/W", "found a dense dataset"),
    "m empty": (_m_empty, "/fclib_local/W/m", "expected one integer, got 0"),
    "m string": (_m_string, "/fclib_local/W/m", "expected integers"),
    "x strings": (_x_strings, "/fclib_local/W/x", "expected real numbers"),
    "x NaN": (_x_nan, "/fclib_local/W/x", "finite"),
    "nz unknown": (_nz_unknown, "/fclib_local/W/nz", "unknown sparse layout"),
    "W = -I": (_w_minus_identity, "/fclib_local/W", "not positive semidefinite"),
    "q too short": (_q_too_short, "/fclib_local/vectors/q", "with 6 entries"),
    "q strings": (_q_strings, "/fclib_local/vectors/q", "expected real numbers"),
    "mu negative": (_mu_negative, "/fclib_local/vectors/mu", "is -0.5 (expected a friction coefficient in [0, 10])"),
    "n not matching": (_m_not_matching, "/fclib_local/W/m", "expected shape 3×3"),
    "vectors a dataset": (_vectors_is_dataset, "/fclib_local/vectors", "found a dataset"),
    "triplet out of shape": (_triplet_out_of_shape, "/fclib_local/W/p", "column index 7 outside [0, 3)"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_file_is_refused_naming_the_hdf5_path(tmp_path, case):
    writer, hdf5_path, reason = HOSTILE[case]
    path = writer(tmp_path / "bad.hdf5")
    with pytest.raises(InputError) as info:
        read_fclib(path)
    message = str(info.value)
    assert f"{path}:{hdf5_path}" in message and reason in message, message
    assert "\n" not in message


@pytest.mark.parametrize(
    "case", ["column index -1", "pointers not monotone", "index 99 in 3x3", "x strings", "m empty"]
)
def test_cli_refuses_hostile_file_with_exit_2_not_a_crash(tmp_path, case):
    writer, hdf5_path, reason = HOSTILE[case]
    path = writer(tmp_path / "bad.hdf5")
    proc = fixplan("fclib", str(path))
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{path}:{hdf5_path}" in lines[0] and reason in lines[0], proc.stderr
    assert "internal error" not in proc.stderr and proc.stdout == ""


def test_valid_csr_of_the_same_shape_is_read(tmp_path):
    # the writer itself is sound: the identity with the same arrays passes
    fc = read_fclib(write_csr(tmp_path / "ok.hdf5", *identity_csr(3), 3))
    np.testing.assert_array_equal(fc.problem.W.toarray(), np.eye(3))
