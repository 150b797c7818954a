"""Hostile mesh files behind ``shape = "mesh"``: each is refused in one line naming workpiece.file, or loads.

The named cases are the bad meshes of the mesh work (open, non-manifold, self-intersecting,
degenerate, empty, not a mesh, non-finite, oversized headers; a missing file, a directory, a
named pipe, a file outside the fixture's folder). Hypothesis then mutates the bytes of a valid
part's STL (binary and ASCII), OBJ and PLY: flipped, cut, inserted or repeated bytes, and changed
vertex coordinates. Every run keeps the harness's contract (exit 0, 1 or 2, no traceback, bounded
time); a refusal is a ``workpiece.file`` line. The named pipe runs in a subprocess (a read that
blocked would hang pytest).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from harness import assert_contract, budget, run_in_process, run_subprocess
from hypothesis import given
from hypothesis import strategies as st

from fixplan.geometry.cells import cell_surface, l_bracket_cells
from fixplan.geometry.mesh import stl_bytes

FIXTURE = """format = 1
[scene]
name = "fuzz-mesh"
[workpiece]
shape = "mesh"
file = "{file}"
mass = 0.5
start = {{ position = [0.0, 0.0, 0.3] }}
[[locator]]
name = "B1"
position = [0.05, 0.02, 0.0]
friction = 0.3
"""


def l_part() -> tuple[np.ndarray, np.ndarray]:
    return cell_surface(*l_bracket_cells(0.1, 0.04, 0.06, 0.01))


def valid_bytes(kind: str) -> bytes:
    V, F = l_part()
    if kind == "stl":
        return stl_bytes(V, F)
    if kind == "stl-ascii":
        return stl_bytes(V, F, ascii=True)
    if kind == "obj":
        lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in V] + [
            f"f {a + 1} {b + 1} {c + 1}" for a, b, c in F
        ]
        return ("\n".join(lines) + "\n").encode()
    header = ["ply", "format ascii 1.0", f"element vertex {len(V)}", "property double x", "property double y"]
    header += ["property double z", f"element face {len(F)}", "property list uchar int vertex_indices", "end_header"]
    body = [f"{float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in V] + [f"3 {a} {b} {c}" for a, b, c in F]
    return ("\n".join(header + body) + "\n").encode()


SUFFIX = {"stl": "stl", "stl-ascii": "stl", "obj": "obj", "ply": "ply"}


def write(folder: Path, file: str, data: bytes | None) -> Path:
    if data is not None:
        (folder / file).write_bytes(data)
    path = folder / "f.toml"
    path.write_text(FIXTURE.format(file=file))
    return path


def assert_refused_or_loaded(folder: Path, path: Path, timeout_s: float = 60.0) -> None:
    before = {p: p.read_bytes() for p in folder.iterdir() if p.is_file()}
    outcome = run_in_process(["validate", str(path)], timeout_s=timeout_s)
    assert_contract(outcome, before)
    if outcome.code == 2:
        lines = outcome.stderr.strip().splitlines()
        assert any("workpiece.file" in line or "locator" in line or "workpiece" in line for line in lines), (
            outcome.stderr
        )


@pytest.mark.parametrize("kind", sorted(SUFFIX))
def test_the_valid_part_loads(kind: str, tmp_path: Path) -> None:
    """The unmutated part loads in every format (exit 0), so a refusal below is the mutation's."""
    path = write(tmp_path, f"part.{SUFFIX[kind]}", valid_bytes(kind))
    outcome = run_in_process(["validate", str(path)])
    assert_contract(outcome)
    assert outcome.code == 0, outcome.stderr


def _named_cases() -> dict[str, bytes]:
    V, F = l_part()
    far = V + np.array([0.3, 0.0, 0.0])
    nan = V.copy()
    nan[0, 0] = np.nan
    return {
        "open.stl": stl_bytes(V, F[:-2]),
        "doubled-edge.stl": stl_bytes(np.vstack([V, V]), np.vstack([F, F])),
        "self-intersecting.stl": stl_bytes(np.vstack([V, V + 0.005]), np.vstack([F, F + len(V)])),
        # a second L whose corner is the first's base corner (0.1, 0.04, 0.01): one vertex, two fans
        "corner-touch.stl": stl_bytes(np.vstack([V, V + [0.1, 0.04, 0.01]]), np.vstack([F, F + len(V)])),
        # a second L standing on the first's base: faces touching over an area
        "face-touch.stl": stl_bytes(np.vstack([V, V + [0.05, 0.02, 0.01]]), np.vstack([F, F + len(V)])),
        "degenerate.stl": stl_bytes(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]), np.array([[0, 1, 2]]), ascii=True),
        "empty.stl": b"",
        "text.stl": b"hello\n" * 50,
        "nan.stl": stl_bytes(nan, F, ascii=True),
        "huge-header.stl": b"\x00" * 80 + np.uint32(10**7).tobytes() + b"\x00" * 100,
        "huge-ply.ply": b"ply\nformat ascii 1.0\nelement vertex 4000000000\nproperty float x\nend_header\n",
        "two-parts.stl": stl_bytes(np.vstack([V, far]), np.vstack([F, F + len(V)])),  # fine: two solids
        "png.stl": b"\x89PNG\r\n\x1a\n" + b"\x00" * 200,
    }


@pytest.mark.parametrize("name", sorted(_named_cases()))
def test_named_bad_meshes(name: str, tmp_path: Path) -> None:
    data = _named_cases()[name]
    assert_refused_or_loaded(tmp_path, write(tmp_path, name, data))
    outcome = run_in_process(["validate", str(tmp_path / "f.toml")])
    if name != "two-parts.stl":
        assert outcome.code == 2
        (line,) = outcome.stderr.strip().splitlines()
        assert "workpiece.file" in line


def test_paths(tmp_path: Path) -> None:
    (tmp_path / "d.stl").mkdir()
    for file in ("missing.stl", "d.stl", "../outside.stl", "/etc/passwd.stl"):
        outcome = run_in_process(["validate", str(write(tmp_path, file, None))])
        assert_contract(outcome)
        assert outcome.code == 2 and "workpiece.file" in outcome.stderr


def test_a_named_pipe_does_not_hang(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "pipe.stl")
    outcome = run_subprocess(["validate", str(write(tmp_path, "pipe.stl", None))], timeout_s=60)
    assert_contract(outcome)
    assert outcome.code == 2 and "named pipe" in outcome.stderr


@st.composite
def mutated(draw: st.DrawFn) -> tuple[str, bytes]:
    kind = draw(st.sampled_from(sorted(SUFFIX)))
    data = bytearray(valid_bytes(kind))
    for _ in range(draw(st.integers(1, 4))):
        how = draw(st.sampled_from(["flip", "cut", "insert", "repeat", "zero"]))
        at = draw(st.integers(0, max(len(data) - 1, 0)))
        if how == "flip" and data:
            data[at] ^= 1 << draw(st.integers(0, 7))
        elif how == "cut":
            del data[at : at + draw(st.integers(1, 400))]
        elif how == "insert":
            data[at:at] = draw(st.binary(min_size=1, max_size=40))
        elif how == "repeat":
            data[at:at] = data[at : at + draw(st.integers(1, 400))] * draw(st.integers(1, 3))
        else:
            data[at : at + 8] = b"\x00" * 8
    return kind, bytes(data)


@budget(12)
@given(case=mutated())
def test_mutated_mesh_files(case: tuple[str, bytes], tmp_path_factory: pytest.TempPathFactory) -> None:
    kind, data = case
    folder = tmp_path_factory.mktemp("m")
    assert_refused_or_loaded(folder, write(folder, f"part.{SUFFIX[kind]}", data))


@budget(8)
@given(
    moves=st.lists(
        st.tuples(st.integers(0, 15), st.integers(0, 2), st.floats(-0.2, 0.2, allow_nan=False)), min_size=1, max_size=4
    )
)
def test_moved_vertices(moves: list[tuple[int, int, float]], tmp_path_factory: pytest.TempPathFactory) -> None:
    """Vertices moved anywhere: the part folds, crosses itself or stays valid; never a crash."""
    V, F = l_part()
    V = V.copy()
    for vertex, axis, delta in moves:
        V[vertex % len(V), axis] += delta
    folder = tmp_path_factory.mktemp("v")
    assert_refused_or_loaded(folder, write(folder, "part.stl", stl_bytes(V, F, ascii=True)))
