"""The mesh parts of ``problems/meshes/`` (made by ``tools/mesh_parts.py``): verdicts derived by hand.

Each part is located at its start; E1 sits in a concave region, where the convex hull would put
it inside the part (``[[hull]]``: its gap there, derived by hand). The verdicts of
``problems/meshes/expected.toml`` are checked with ``classify`` at the located pose.
"""

from __future__ import annotations

import sys
import tomllib

import numpy as np
import pytest
from conftest import PROBLEMS, ROOT

from fixplan.cli import main
from fixplan.fixture import load
from fixplan.geometry import Mesh
from fixplan.jamming import classify

MESHES = PROBLEMS / "meshes"
EXPECTED = tomllib.loads((MESHES / "expected.toml").read_text(encoding="utf-8"))
FILES = sorted(p.name for p in MESHES.glob("*.toml") if p.name != "expected.toml")


def test_the_script_writes_the_files_in_the_repository() -> None:
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        import mesh_parts
    finally:
        sys.path.pop(0)
    assert mesh_parts.main(["--check"]) == 0
    assert len(FILES) >= 3


@pytest.mark.parametrize("name", FILES)
def test_each_part_is_located_at_its_start(name: str, capsys) -> None:
    fixture = load(MESHES / name)
    assert isinstance(fixture.workpiece.shape, Mesh)
    np.testing.assert_allclose(fixture.goal.p_world, 0.0, atol=1e-12)
    np.testing.assert_allclose(fixture.goal.R_world_body, np.eye(3), atol=1e-12)
    assert main(["validate", "--verbose", str(MESHES / name)]) == 0
    out, err = capsys.readouterr()
    assert "rank of G at the goal: 6 of 6: the locators determine the pose" in out
    assert err == ""  # no warning (a plausible density)


@pytest.mark.parametrize("entry", EXPECTED["hull"], ids=[e["file"] for e in EXPECTED["hull"]])
def test_the_convex_hull_would_be_wrong(entry: dict) -> None:
    from scipy.spatial import ConvexHull

    fixture = load(MESHES / entry["file"])
    mesh = fixture.workpiece.shape
    assert isinstance(mesh, Mesh)
    e1 = fixture.locator("E1")
    hull = ConvexHull(mesh.vertices)
    hull_gap = float((hull.equations[:, :3] @ e1.p_world + hull.equations[:, 3]).max()) - e1.radius_m
    assert hull_gap == pytest.approx(entry["gap"], abs=1e-12)
    assert mesh.project(e1.p_world).distance - e1.radius_m == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize(
    "entry", EXPECTED["case"], ids=[f"{e['file']}:{e['mode']}:{i}" for i, e in enumerate(EXPECTED["case"])]
)
def test_hand_derived_verdicts(entry: dict) -> None:
    fixture = load(MESHES / entry["file"])
    (result,) = classify(fixture, np.array([entry["wrench"]]), pose="goal", jobs=1)
    assert result.mode == entry["mode"], entry["why"]


def test_validate_says_when_a_tip_in_a_corner_touches_two_faces(tmp_path, capsys) -> None:
    """E1 moved into the L's concave corner (0.013, 0.02, 0.013) touches the wall and the base: two contacts."""
    text = (MESHES / "l-bracket.toml").read_text(encoding="utf-8")
    text = text.replace("position = [0.013, 0.02, 0.035]", "position = [0.013, 0.02, 0.013]")
    (tmp_path / "l-bracket.stl").write_bytes((MESHES / "l-bracket.stl").read_bytes())
    (tmp_path / "corner.toml").write_text(text, encoding="utf-8")
    fixture = load(tmp_path / "corner.toml")
    mesh = fixture.workpiece.shape
    assert isinstance(mesh, Mesh)
    touches = mesh.contacts(fixture.locator("E1").p_world)
    assert sorted(tuple(np.round(t.normal_body, 12)) for t in touches) == [(0.0, 0.0, 1.0), (1.0, 0.0, 0.0)]
    assert main(["validate", "--verbose", str(tmp_path / "corner.toml")]) == 0
    out = capsys.readouterr().out
    assert "E1 touches the mesh at 2 places at the goal (a concave corner)" in out
