"""FCLib files with links, oversized declarations, out-of-range values or random corruption: exit 2, never 3.

Before these checks a dangling or looping soft link gave ``KeyError … component not found`` or
``RuntimeError … too many links`` (exit 3), an external link was followed to ``/etc/passwd``, a
corrupt heap gave ``bad heap free list`` (exit 3), a 9 KB file declaring 10⁹ unwritten gzip chunks
made the reader allocate 7.45 GiB, and ``q = 1e308`` reached the JSON encoder as "a numerical
failure inside the valid ranges". Each case is refused with one line naming the file and the HDF5
path (and the value as stored, for a value out of range).
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import CLI, run_cli
from test_fclib import random_global, write_global, write_local

from fixplan import limits
from fixplan.engine.fclib import read_fclib, solve_fclib_file
from fixplan.errors import InputError


def fixplan(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return run_cli(*args, timeout=timeout)


def valid_local(path: Path, contacts: int = 2) -> Path:
    """A valid local 3D problem: W = I + a seeded SPD part, pressed contacts."""
    rng = np.random.default_rng(3)
    m = 3 * contacts
    B = rng.standard_normal((m, m))
    q = np.zeros(m)
    q[0::3] = -1.0
    return write_local(path, B @ B.T / m + np.eye(m), q, [0.3] * contacts)


def replace(path: Path, name: str, value) -> Path:  # type: ignore[no-untyped-def]
    """Replace the link ``name`` by ``value`` (a link object, an array, or a callable making the dataset)."""
    with h5py.File(path, "a") as fh:
        del fh[name]
        if callable(value):
            value(fh, name)
        else:
            fh[name] = value
    return path


def assert_refused(path: Path, hdf5_path: str, *words: str) -> str:
    with pytest.raises(InputError) as info:
        read_fclib(path)
    message = str(info.value)
    assert f"{path}:{hdf5_path}" in message, message
    for word in words:
        assert word in message, message
    assert "\n" not in message
    return message


# --------------------------------------------------------------------------- D2, D3: links


def _dangling(p: Path) -> Path:
    return replace(valid_local(p), "fclib_local/vectors/q", h5py.SoftLink("/nowhere"))


def _self_loop(p: Path) -> Path:
    return replace(valid_local(p), "fclib_local/vectors/q", h5py.SoftLink("/fclib_local/vectors/q"))


def _two_link_loop(p: Path) -> Path:
    path = replace(valid_local(p), "fclib_local/W", h5py.SoftLink("/a"))
    with h5py.File(path, "a") as fh:
        fh["a"] = h5py.SoftLink("/fclib_local/W")
    return path


def _external_passwd(p: Path) -> Path:
    return replace(valid_local(p), "fclib_local/vectors/q", h5py.ExternalLink("/etc/passwd", "/q"))


def _external_valid_problem(p: Path) -> Path:
    # the link leads to a valid FCLib problem: followed, it would be read and solved
    target = valid_local(p.with_name("target.hdf5"))
    with h5py.File(p, "w") as fh:
        fh["fclib_local"] = h5py.ExternalLink(str(target), "/fclib_local")
    return p


def _soft_to_valid_data(p: Path) -> Path:
    path = valid_local(p)
    with h5py.File(path, "a") as fh:
        fh["copy_of_q"] = fh["fclib_local/vectors/q"][()]
    return replace(path, "fclib_local/vectors/q", h5py.SoftLink("/copy_of_q"))


def _dangling_outside_the_problem(p: Path) -> Path:
    path = valid_local(p)
    with h5py.File(path, "a") as fh:
        fh.create_group("solution")["r"] = h5py.SoftLink("/gone")
    return path


def _hard_link_cycle(p: Path) -> Path:
    path = valid_local(p)
    with h5py.File(path, "a") as fh:
        fh["fclib_local/info/again"] = fh["fclib_local"]  # a hard link to an ancestor
    return path


def _too_many_links(p: Path) -> Path:
    path = valid_local(p)
    with h5py.File(path, "a") as fh:
        g = fh.create_group("guesses")
        for k in range(limits.FCLIB_MAX_LINKS + 1):
            g.create_group(f"g{k}")
    return path


LINKS: dict[str, tuple[Callable[[Path], Path], str, str]] = {
    "dangling soft link": (_dangling, "/fclib_local/vectors/q", "a soft link to '/nowhere'"),
    "soft link to itself": (_self_loop, "/fclib_local/vectors/q", "a soft link to '/fclib_local/vectors/q'"),
    "two soft links in a loop": (_two_link_loop, "/", "a soft link to '/"),
    "external link to /etc/passwd": (_external_passwd, "/fclib_local/vectors/q", "an external link to '/etc/passwd'"),
    "external link to a valid problem": (_external_valid_problem, "/fclib_local", "an external link to"),
    "soft link to valid data": (_soft_to_valid_data, "/fclib_local/vectors/q", "a soft link to '/copy_of_q'"),
    "dangling link outside the problem": (_dangling_outside_the_problem, "/solution/r", "a soft link to '/gone'"),
    "hard-link cycle": (_hard_link_cycle, "/fclib_local/info/again", f"nested deeper than {limits.FCLIB_MAX_DEPTH}"),
    "too many links": (_too_many_links, "/guesses/g", f"more than {limits.FCLIB_MAX_LINKS} links"),
}


@pytest.mark.parametrize("case", sorted(LINKS))
def test_links_are_refused_without_being_followed(tmp_path, case):
    writer, hdf5_path, reason = LINKS[case]
    path = writer(tmp_path / "bad.hdf5")
    message = assert_refused(path, hdf5_path, reason)
    assert "root:" not in message  # nothing of /etc/passwd is read, let alone quoted


def test_a_valid_problem_has_no_link_and_is_read(tmp_path):
    fc = read_fclib(valid_local(tmp_path / "ok.hdf5"))
    assert fc.n_contacts == 2 and fc.title == "test problem"


@pytest.mark.parametrize("case", ["dangling soft link", "two soft links in a loop", "external link to /etc/passwd"])
def test_cli_refuses_links_with_exit_2(tmp_path, case):
    writer, hdf5_path, reason = LINKS[case]
    path = writer(tmp_path / "bad.hdf5")
    proc = fixplan("fclib", str(path), "--json")
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{path}:{hdf5_path}" in lines[0] and reason in lines[0], proc.stderr
    assert proc.stdout == ""


def test_data_stored_in_another_file_is_refused(tmp_path):
    # HDF5's external storage reads a dataset's bytes from any file, and a virtual dataset maps another file's
    secret = tmp_path / "secret.bin"
    secret.write_bytes(np.arange(6, dtype="<f8").tobytes())
    path = replace(
        valid_local(tmp_path / "ext.hdf5"),
        "fclib_local/vectors/q",
        lambda fh, name: fh.create_dataset(name, shape=(6,), dtype="<f8", external=[(str(secret), 0, 48)]),
    )
    assert_refused(path, "/fclib_local/vectors/q", "stored in other files")

    source = valid_local(tmp_path / "source.hdf5")
    layout = h5py.VirtualLayout(shape=(6,), dtype="f8")
    layout[:] = h5py.VirtualSource(str(source), "fclib_local/vectors/q", shape=(6,))
    path = replace(
        valid_local(tmp_path / "vds.hdf5"),
        "fclib_local/vectors/q",
        lambda fh, name: fh.create_virtual_dataset(name, layout),
    )
    assert_refused(path, "/fclib_local/vectors/q", "stored in other files")


# --------------------------------------------------------------------------- D4: declared sizes


def _huge_chunked(n: int, dtype: str = "f8") -> Callable[[h5py.File, str], None]:
    """A dataset of ``n`` entries in unwritten gzip chunks: a few bytes on disk, ``8 n`` bytes to read."""
    return lambda fh, name: fh.create_dataset(name, shape=(n,), dtype=dtype, chunks=(1000,), compression="gzip")


GIGA = 10**9
OVERSIZED = {
    "q of 10⁹ entries": ("fclib_local/vectors/q", _huge_chunked(GIGA), "expected 'q' with 6 entries, got 1000000000"),
    "W/x of 10⁹ entries": ("fclib_local/W/x", _huge_chunked(GIGA), "declares 1000000000 entries"),
    "W/i of 10⁹ entries": ("fclib_local/W/i", _huge_chunked(GIGA, "i4"), "declares 1000000000 entries"),
    "W/p of 10⁹ entries": ("fclib_local/W/p", _huge_chunked(GIGA, "i4"), "expected 7 row pointers, got 1000000000"),
    "mu of 10⁹ entries": (
        "fclib_local/vectors/mu",
        _huge_chunked(GIGA),
        "expected 'mu' with 2 entries, got 1000000000",
    ),
    "W/m of 10⁹ values": ("fclib_local/W/m", _huge_chunked(GIGA, "i4"), "expected one integer, got 1000000000 values"),
    "spacedim of 10⁹ values": ("fclib_local/spacedim", _huge_chunked(GIGA, "i4"), "expected one integer"),
    "W/x in 20 000 chunks": (
        "fclib_local/W/x",
        lambda fh, name: fh.create_dataset(name, shape=(20_000,), dtype="f8", chunks=(1,)),
        "stored in 20000 chunks",
    ),
    "q with one chunk of 10⁸ entries": (
        "fclib_local/vectors/q",
        lambda fh, name: fh.create_dataset(name, shape=(6,), maxshape=(None,), dtype="f8", chunks=(10**8,)),
        "chunks of 100000000 entries",
    ),
    "q of 5 entries for 6 rows": ("fclib_local/vectors/q", np.zeros(5), "expected 'q' with 6 entries, got 5 values"),
    "mu of 3 entries for 2 contacts": (
        "fclib_local/vectors/mu",
        np.full(3, 0.3),
        "expected 'mu' with 2 entries, got 3 values",
    ),
}


@pytest.mark.parametrize("case", sorted(OVERSIZED))
def test_declared_sizes_are_checked_before_reading(tmp_path, case):
    name, value, reason = OVERSIZED[case]
    path = replace(valid_local(tmp_path / "big.hdf5"), name, value)
    assert path.stat().st_size < 64 * 1024  # a small file ...
    tracemalloc.start()
    try:
        assert_refused(path, "/" + name, reason)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 16 * 2**20, peak  # ... refused without allocating what it declares (7.45 GiB for 10⁹ floats)


def test_contacts_beyond_the_limit_are_refused_before_the_vectors_are_read(tmp_path):
    rows = 3 * (limits.FCLIB_MAX_CONTACTS + 1)
    path = replace(valid_local(tmp_path / "many.hdf5"), "fclib_local/W/m", np.array([rows], np.int32))
    assert_refused(path, "/fclib_local/W/m", f"more than the {limits.FCLIB_MAX_CONTACTS} fixplan accepts")


def test_condensing_is_bounded_before_it_is_done(tmp_path):
    # one velocity seen by 1 055 contacts: Hᵀ M⁻¹ H has 3 165² ≈ 1.0e7 entries (> FCLIB_MAX_NNZ)
    contacts = 1055
    m = 3 * contacts
    H = np.ones((1, m))
    path = write_global(tmp_path / "dense.hdf5", np.eye(1), H, np.ones(1), np.zeros(m), np.full(contacts, 0.3), "csr")
    assert m * m > limits.FCLIB_MAX_NNZ
    assert_refused(path, "/fclib_global/H", f"takes {m * m} products")
    # a non-diagonal M: M⁻¹ H may be dense, n_dof × m entries
    n_dof = limits.FCLIB_MAX_NNZ // m + 1
    M = np.eye(n_dof)
    M[0, 1] = M[1, 0] = 0.1
    H = np.zeros((n_dof, m))
    H[0, 0] = 1.0
    path = write_global(tmp_path / "full.hdf5", M, H, np.zeros(n_dof), np.zeros(m), np.full(contacts, 0.3), "csr")
    assert_refused(path, "/fclib_global/M", "M is not diagonal", f"may have {n_dof * m} entries")


# --------------------------------------------------------------------------- D22: values out of range


def _set(name: str, index: int, value: float) -> Callable[[Path], Path]:
    def writer(p: Path) -> Path:
        path = valid_local(p) if name.startswith("fclib_local") else _global(p)
        with h5py.File(path, "a") as fh:
            fh[name][index] = value
        return path

    return writer


def _global(p: Path) -> Path:
    return write_global(p, *random_global(np.random.default_rng(1), n_dof=6, n_contacts=2), "csr")


OUT_OF_RANGE = {  # case: (dataset, index, value, words of the message)
    "q = 1e308": ("fclib_local/vectors/q", 0, 1e308, "entry 0 is 1e+308"),
    "q = -1e308": ("fclib_local/vectors/q", 3, -1e308, "entry 3 is -1e+308"),
    "q = 1.0000001e20": ("fclib_local/vectors/q", 1, 1.0000001e20, "entry 1 is 1.0000001e+20"),
    "q NaN": ("fclib_local/vectors/q", 2, np.nan, "entry 2 is nan, not a finite number"),
    "W/x inf": ("fclib_local/W/x", 4, np.inf, "entry 4 is inf, not a finite number"),
    "W/x = -1e21": ("fclib_local/W/x", 0, -1e21, "entry 0 is -1e+21"),
    "mu = 10.5": ("fclib_local/vectors/mu", 1, 10.5, "entry 1 is 10.5"),
    "mu NaN": ("fclib_local/vectors/mu", 0, np.nan, "entry 0 is nan"),
    "f = 1e308": ("fclib_global/vectors/f", 5, 1e308, "entry 5 is 1e+308"),
    "w = -inf": ("fclib_global/vectors/w", 0, -np.inf, "entry 0 is -inf"),
    "M/x = 1e300": ("fclib_global/M/x", 0, 1e300, "entry 0 is 1e+300"),
    "H/x = 3e25": ("fclib_global/H/x", 2, 3e25, "entry 2 is 3e+25"),
}


@pytest.mark.parametrize("case", sorted(OUT_OF_RANGE))
def test_values_out_of_range_are_refused_with_the_value_as_stored(tmp_path, case):
    dataset, index, value, words = OUT_OF_RANGE[case]
    path = _set(dataset, index, value)(tmp_path / "v.hdf5")
    expected = limits.FRICTION if dataset.endswith("mu") else limits.FCLIB_ENTRY
    assert_refused(path, "/" + dataset, words, f"(expected {expected.expected()})")


def test_q_1e308_exits_2_naming_the_dataset_and_the_value(tmp_path):
    path = _set("fclib_local/vectors/q", 0, 1e308)(tmp_path / "q.hdf5")
    proc = fixplan("fclib", str(path), "--json")
    assert proc.returncode == 2 and proc.stdout == "", proc.stderr
    assert proc.stderr.strip() == (
        f"fixplan: {path}:/fclib_local/vectors/q: entry 0 is 1e+308 "
        "(expected an FCLib matrix or vector entry in [-1e+20, 1e+20])"
    )
    assert "numerical failure" not in proc.stderr


def test_condensing_with_a_near_singular_mass_is_refused(tmp_path):
    M, H, f, w, mu = random_global(np.random.default_rng(1), n_dof=6, n_contacts=2)
    M = np.diag(np.full(6, 1e-19))  # inside the range, but M⁻¹ = 1e19 turns H's entries into 1e20+
    path = write_global(tmp_path / "s.hdf5", M, H * 1e5, f, w, mu, "csr")
    assert_refused(path, "/fclib_global/M", "condensing with M⁻¹ gives W = Hᵀ M⁻¹ H an entry", "near singular")


@pytest.mark.parametrize(
    ("scale_w", "scale_q"), [(1.0, 1e20), (1.0, 1e-20), (1e20, 1e20), (1e-20, 1e20), (1e20, 1e-20)]
)
def test_the_edges_of_the_range_are_solved(tmp_path, scale_w, scale_q):
    """Inside the ranges every answer is finite: W and q with entries up to 1e20 or down to 1e-20 solve.

    With ``W`` unscaled the problem is homogeneous in ``q`` (``r(W, βq) = β r(W, q)``, and the
    FCLib residual is relative), so the answer is also compared with the unscaled one.
    """
    rng = np.random.default_rng(7)
    m = 9
    B = rng.standard_normal((m, m))
    W = B @ B.T / m + np.eye(m)
    W *= scale_w / np.max(np.abs(W))
    q = rng.standard_normal(m)
    q *= scale_q / np.max(np.abs(q))
    path = write_local(tmp_path / "edge.hdf5", W, q, [0.5] * 3)
    proc = fixplan("fclib", str(path), "--tol", "1e-10", "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout, parse_constant=lambda name: pytest.fail(f"non-finite {name} in the JSON"))
    assert out["converged"] and out["error"] <= 1e-10
    assert np.all(np.isfinite(out["reaction"])) and np.all(np.isfinite(out["velocity"]))
    if scale_w == 1.0:
        base = solve_fclib_file(write_local(tmp_path / "one.hdf5", W, q / scale_q, [0.5] * 3), tol=1e-12)
        np.testing.assert_allclose(np.array(out["reaction"]) / scale_q, base.reaction, rtol=1e-6, atol=1e-8)


# --------------------------------------------------------------------------- random corruption of real files

CORRUPTION_SCRIPT = textwrap.dedent(
    """
    import json, sys
    from pathlib import Path
    import numpy as np
    from fixplan.engine.fclib import read_fclib
    from fixplan.errors import InputError

    files, out, n, seed = [Path(p) for p in sys.argv[1].split(",")], Path(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
    rng = np.random.default_rng(seed)
    counts = {"read": 0, "refused": 0}
    for k in range(n):
        data = bytearray(files[k % len(files)].read_bytes())
        how = k % 4
        if how == 0:  # a few bytes flipped anywhere
            for _ in range(int(rng.integers(1, 16))):
                data[int(rng.integers(len(data)))] ^= int(rng.integers(1, 256))
        elif how == 1:  # truncated
            data = data[: int(rng.integers(len(data)))]
        elif how == 2:  # a burst of random bytes in the first 4 KiB (superblock, root group, headers)
            at, size = int(rng.integers(0, 4096)), int(rng.integers(1, 64))
            data[at : at + size] = rng.integers(0, 256, size=len(data[at : at + size]), dtype=np.uint8).tobytes()
        else:  # one byte flipped in the metadata
            data[int(rng.integers(0, min(len(data), 8192)))] ^= int(rng.integers(1, 256))
        path = out / f"c{k}.hdf5"
        path.write_bytes(bytes(data))
        try:
            read_fclib(path)
            counts["read"] += 1
        except InputError as exc:
            message = str(exc)
            if str(path) not in message or "\\n" in message:
                raise AssertionError(f"case {k}: the message does not name the file on one line: {message!r}")
            counts["refused"] += 1
        path.unlink()
    print(json.dumps(counts))
    """
)


def _real_files(shared_dir: Path) -> list[Path]:
    files = sorted((shared_dir / "data").glob("fclib*/*.hdf5"))
    if not files:
        pytest.skip(f"no FCLib problems in {shared_dir / 'data'}/fclib*")
    return [p for p in files if p.stat().st_size < 2 * 2**20]


def test_random_corruption_of_real_files_is_read_or_refused(shared_dir, tmp_path):
    """400 seeded corruptions of the shared FCLib files: each is read or refused with an InputError naming it.

    Run in a child process: a crash in HDF5's C code (or a hang, killed by the timeout) must fail
    this test, not end pytest.
    """
    files = _real_files(shared_dir)
    proc = subprocess.run(
        [sys.executable, "-c", CORRUPTION_SCRIPT, ",".join(map(str, files)), str(tmp_path), "400", "22"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    counts = json.loads(proc.stdout)
    assert counts["read"] + counts["refused"] == 400 and counts["refused"] >= 100, counts


def test_cli_on_corrupt_copies_exits_0_1_or_2(shared_dir, tmp_path):
    """A few corrupt copies through the command: exit 0/1 (solved or not within the limit) or 2, never 3, never a hang."""
    files = _real_files(shared_dir)
    rng = np.random.default_rng(5)
    codes = []
    for k in range(6):
        data = bytearray(files[int(rng.integers(len(files)))].read_bytes())
        if k % 2:
            data = data[: int(rng.integers(len(data) // 2, len(data)))]
        else:
            for _ in range(8):
                data[int(rng.integers(len(data)))] ^= int(rng.integers(1, 256))
        path = tmp_path / f"c{k}.hdf5"
        path.write_bytes(bytes(data))
        proc = subprocess.run(
            [*CLI, "fclib", str(path), "--time-limit", "5", "--json"], capture_output=True, text=True, timeout=120
        )
        assert proc.returncode in (0, 1, 2), proc.stderr
        assert "Traceback" not in proc.stderr and "internal error" not in proc.stderr, proc.stderr
        if proc.returncode == 2:
            assert len(proc.stderr.strip().splitlines()) == 1 and str(path) in proc.stderr, proc.stderr
        codes.append(proc.returncode)
    assert 2 in codes, codes
