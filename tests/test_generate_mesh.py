"""The mesh family (``fixplan generate mesh-321``): CAD-like parts whose locators touch the real surface.

Every fixture of a seeded set loads beside its STL file, and at its goal (written in the file, or
computed by the loader on the real surface when it is left out) every locator touches exactly
one face with a gap below 1e-9 m; E1's centre lies inside the part's convex hull, so the hull
would put the tip inside the part (a concave region: the L's inner wall, a slot wall, the
pocket's inner wall). At the start the base locators touch and the others are clear. The parts
have whole-millimetre dimensions, and their volume and mass follow from the cells' closed form.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import run_cli
from scipy.spatial import ConvexHull

from fixplan import generate as gen
from fixplan.fixture import load
from fixplan.locating import locator_gaps

SEED, N = 2026, 15


@pytest.fixture(scope="module")
def parts(tmp_path_factory) -> list[tuple[gen.GeneratedFixture, Path]]:
    folder = tmp_path_factory.mktemp("mesh-321")
    out = []
    for g in gen.generate("mesh-321", N, SEED):
        for name, data in g.files:
            (folder / name).write_bytes(data)
        path = folder / f"{g.name}.toml"
        path.write_text(g.toml_text)
        out.append((g, path))
    return out


def test_every_fixture_validates_and_its_locators_touch_the_real_surface_at_the_goal(parts) -> None:
    kinds, written = set(), set()
    for g, path in parts:
        fx = load(path)
        assert fx.is_full and fx.workpiece.shape.name == "mesh"
        kinds.add(g.params["part"])
        written.add(g.params["goal_in_file"])
        mesh = fx.workpiece.shape
        gaps = locator_gaps(fx.workpiece, fx.goal, fx.locators)
        assert np.max(np.abs(gaps)) < 1e-9, (g.name, gaps)
        # the goal is the file's frame (the identity), also where the loader computed it
        assert float(np.abs(fx.goal.p_world).max()) < 1e-9, g.name
        assert float(np.abs(fx.goal.R_world_body - np.eye(3)).max()) < 1e-9, g.name
        for loc in fx.locators:
            found = mesh.contacts(fx.goal.point_body_from_world(loc.p_world))
            assert len(found) == 1 and abs(found[0].distance - loc.radius_m) < 1e-9, (g.name, loc.name, found)
        hull = ConvexHull(np.asarray(mesh.vertices))
        e1 = fx.goal.point_body_from_world(fx.locator("E1").p_world)
        outside = float(np.max(hull.equations[:, :3] @ e1 + hull.equations[:, 3]))  # > 0: outside the hull
        assert outside < 0.0, g.name  # E1's centre inside the hull: the hull would be wrong there
        start = dict(
            zip([loc.name for loc in fx.locators], locator_gaps(fx.workpiece, fx.start, fx.locators), strict=True)
        )
        assert all(abs(start[n]) <= gen.EXACT_M for n in ("B1", "B2", "B3")), (g.name, start)
        assert all(start[n] >= gen.CLEARANCE_M for n in ("S1", "S2", "E1")), (g.name, start)
    assert kinds == set(gen.MESH_PARTS) and written == {True, False}


def test_parts_are_whole_millimetres_with_the_closed_form_mass(parts) -> None:
    for g, path in parts:
        fx = load(path)
        mesh = fx.workpiece.shape
        doubled = 2e3 * np.asarray(mesh.vertices)  # half millimetres: a centred odd dimension
        assert np.max(np.abs(doubled - np.round(doubled))) < 1e-9, g.name
        density = g.params["density_kg_m3"]
        assert fx.workpiece.mass_kg == pytest.approx(density * mesh.volume_m3, rel=1e-3)


def test_generation_is_deterministic_per_seed_and_index() -> None:
    a = gen.generate("mesh-321", 3, 11)
    longer = gen.generate("mesh-321", 4, 11)
    assert [(x.toml_text, x.files) for x in a] == [(x.toml_text, x.files) for x in longer[:3]]
    assert gen.generate_one("mesh-321", 11, 3).files == longer[3].files
    assert all(x.files[0][0] == f"{x.name}.stl" and f'file = "{x.name}.stl"' in x.toml_text for x in a)
    other = gen.generate("mesh-321", 3, 12)
    assert all(x.toml_text != y.toml_text for x, y in zip(a, other, strict=True))


def test_cli_writes_each_fixture_beside_its_mesh_and_refuses_to_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "gen"
    proc = run_cli("generate", "mesh-321", "--count", "2", "--seed", "5", "--out", str(out), "--json", check_rc=0)
    report = json.loads(proc.stdout)
    expected = gen.generate("mesh-321", 2, 5)
    for f, g in zip(report["files"], expected, strict=True):
        assert Path(f["path"]).read_text() == g.toml_text
        assert f["files"] == [str(out / f"{g.name}.stl")]
        assert (out / f"{g.name}.stl").read_bytes() == g.files[0][1]
    run_cli("validate", *(f["path"] for f in report["files"]), check_rc=0)
    stl = out / f"{expected[0].name}.stl"
    stl.write_bytes(b"mine")
    again = run_cli("generate", "mesh-321", "--count", "2", "--seed", "5", "--out", str(out), check_rc=2)
    assert "exists" in again.stderr and "--force" in again.stderr and again.stderr.strip().count("\n") == 0
    assert stl.read_bytes() == b"mine"
