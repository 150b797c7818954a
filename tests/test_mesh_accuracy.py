"""A box as a mesh gives the primitive box's answers.

The same box of ``problems/`` written as a 12-triangle binary STL in millimetres and as a
10 092-triangle ASCII STL in metres (29 cells a side, every coordinate with all its digits): the
located pose agrees with the primitive box's to 1e-12 m, and ``classify`` gives identical verdicts
on seeded random wrenches at it, and ``search`` the same push. The box's own frame is its
centre, as the cell grid's is.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from conftest import PROBLEMS

from fixplan.fixture import load
from fixplan.geometry import Mesh
from fixplan.geometry.cells import box_cells, cell_surface
from fixplan.geometry.mesh import stl_bytes
from fixplan.jamming import classify, search_wrench
from fixplan.model import Fixture

# a start turned and lifted off the located pose (the locators as in box-3-2-1): goal finding works
FAR_START = "start = { position = [0.125, 0.075, 0.05], rpy_deg = [4.0, -3.0, 12.0] }"


def as_meshes(text: str, folder: Path) -> list[Path]:
    """The fixture ``text`` with its box as a 12-triangle STL in mm and a ~10⁴-triangle STL in m."""
    found = re.search(r'shape = "box"\nsize = \[([^\]]*)\]', text)
    assert found is not None
    size = tuple(float(x) for x in found.group(1).split(","))
    body = "\n".join(line for line in text.splitlines() if not line.startswith("face = "))  # a mesh has no faces
    V, F = cell_surface(*box_cells(tuple(1000.0 * s for s in size), 1))  # type: ignore[arg-type]
    (folder / "box12.stl").write_bytes(stl_bytes(V, F))
    V, F = cell_surface(*box_cells(size, 29))  # type: ignore[arg-type]
    (folder / "box10k.stl").write_bytes(stl_bytes(V, F, ascii=True))
    paths = []
    for name, keys in (("mm12", 'file = "box12.stl"\nunits = "mm"'), ("m10k", 'file = "box10k.stl"')):
        path = folder / f"{name}.toml"
        path.write_text(body.replace(found.group(0), f'shape = "mesh"\n{keys}'))
        paths.append(path)
    return paths


def assert_same_answers(box: Fixture, mesh: Fixture) -> None:
    assert isinstance(mesh.workpiece.shape, Mesh)
    assert box.goal_pose is not None and mesh.goal_pose is not None
    np.testing.assert_allclose(mesh.goal.p_world, box.goal.p_world, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(mesh.goal.R_world_body, box.goal.R_world_body, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(mesh.workpiece.inertia_body, box.workpiece.inertia_body, rtol=1e-12, atol=1e-18)
    rng = np.random.default_rng(2026)
    W = rng.normal(size=(40, 6)) * np.array([20.0, 20.0, 20.0, 1.0, 1.0, 1.0])
    modes_box = [r.mode for r in classify(box, W, pose="goal", jobs=1)]
    modes_mesh = [r.mode for r in classify(mesh, W, pose="goal", jobs=1)]
    assert modes_mesh == modes_box
    assert len(set(modes_box)) >= 2  # the wrenches reach more than one verdict
    push_box = search_wrench(box, np.array([0.0, 0.0, 0.1, 0.0, 0.0, 0.0]), pose="goal")
    push_mesh = search_wrench(mesh, np.array([0.0, 0.0, 0.1, 0.0, 0.0, 0.0]), pose="goal")
    assert push_mesh.found == push_box.found
    if push_box.wrench is not None and push_mesh.wrench is not None:
        np.testing.assert_allclose(push_mesh.wrench, push_box.wrench, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("problem", ["box-3-2-1", "box-tilted-start"])
def test_a_box_mesh_locates_and_classifies_as_the_primitive_box(problem: str, tmp_path: Path) -> None:
    text = (PROBLEMS / f"{problem}.toml").read_text()
    box = load(PROBLEMS / f"{problem}.toml")
    for path in as_meshes(text, tmp_path):
        assert_same_answers(box, load(path))


def test_the_goal_from_a_far_start_is_the_primitive_box_s(tmp_path: Path) -> None:
    text = (PROBLEMS / "box-3-2-1.toml").read_text()
    text = "\n".join(line for line in text.splitlines() if not line.startswith("face = "))
    text = re.sub(r"start = \{[^}]*\}", FAR_START, text, count=1)
    (tmp_path / "box.toml").write_text(text)
    box = load(tmp_path / "box.toml")
    np.testing.assert_allclose(box.goal.p_world, [0.1, 0.05, 0.025], atol=1e-12)  # box-3-2-1's located pose
    for path in as_meshes(text, tmp_path):
        assert_same_answers(box, load(path))
